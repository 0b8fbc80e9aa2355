#pragma once
// The one fuzz harness every HID protocol instantiates (IMU glove board,
// stretch board, fingertip devices; the next device too). A protocol's
// fuzz_<name>_protocol.cpp supplies a traits struct P and ends with
//
//   extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
//     return proprio::fuzz::fuzz_protocol<P>(data, size);
//   }
//
// Whatever the bytes, nothing may crash, hang or invoke undefined behaviour
// (the libFuzzer and ASan builds check), and the decoders' own promises must
// hold; a broken promise aborts, which both builds report with the input.
//
// The input is read three ways:
//  1. as one report, handed to every decoder form the protocol has (P::check_reports);
//  2. as a byte stream cut into frames (P::frame_size of the frame's first
//     byte, at most P::kMaxFrames), fed to the protocol's streams (P::check_streams);
//  3. as 2., with every frame's CRC recomputed, so that mutations get past the
//     CRC to the field checks and the sequence and timestamp logic; each such
//     frame also goes through 1.
//
// P provides:
//   static void check_reports(std::span<const std::uint8_t> report);  // check_form() per decoder
//   static std::size_t frame_size(std::uint8_t first_byte);            // > 0
//   static constexpr std::size_t kMaxFrames;   // bounds the work a stream check does per input
//   static constexpr bool kFixCrcOfShortFrames; // a truncated last frame gets a CRC too
//   static void check_streams(const Frames& frames, bool crc_fixed);
// optionally
//   static void check_input(std::span<const std::uint8_t> bytes);  // once, the whole input as it came
// and, for a stream decoder that yields samples with device time, what
// check_timed_stream<S>() asks of S (see there).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <utility>
#include <vector>

#include "proprio/core/time.hpp"
#include "proprio/hid/clock_sync.hpp"
#include "proprio/hid/crc16.hpp"

namespace proprio::fuzz {

using Frame = std::vector<std::uint8_t>;
using Frames = std::vector<Frame>;

// abort(), not an exception or a gtest assertion: libFuzzer reports it with
// the input that caused it, and the replay driver dies with a core.
inline void require(bool ok) {
  if (!ok) std::abort();
}

template <typename Array>
std::uint64_t sum(const Array& counts) {
  std::uint64_t total = 0;
  for (const auto n : counts) total += n;
  return total;
}

// What a decoder does with a report it refuses.
enum class OnReject {
  may_write,         // the output holds whatever the decoder got to
  leaves_untouched,  // the protocol promises the output is not written
};

// One decoder form: `decode(bytes, value)` returning a status with ok(),
// describe() and to_error(); `encode(value)` giving the report's bytes. What
// decodes re-encodes to bytes that decode to the same value, which then
// passes `accepted`; what is refused says why, and leaves the output alone
// where the protocol promises that.
template <typename Value, typename Decode, typename Encode, typename Accepted>
void check_form(std::span<const std::uint8_t> bytes, Decode decode, Encode encode, OnReject on_reject,
                Accepted accepted) {
  Value value{};
  const auto status = decode(bytes, value);
  if (status.ok()) {
    Value again{};
    const auto encoded = encode(value);
    require(decode(std::span<const std::uint8_t>(encoded), again).ok() && again == value);
    accepted(value);
  } else {
    require(!describe(status).empty() && !to_error(status).message.empty());
    if (on_reject == OnReject::leaves_untouched) require(value == Value{});
  }
}

// The last two bytes are the CRC-16/CCITT of the rest, little-endian (every
// protocol of the kit frames its reports so).
inline void fix_crc(Frame& frame) {
  if (frame.size() < 2) return;
  const std::uint16_t crc = hid::crc16_ccitt(std::span<const std::uint8_t>(frame).first(frame.size() - 2));
  frame[frame.size() - 2] = static_cast<std::uint8_t>(crc);
  frame[frame.size() - 1] = static_cast<std::uint8_t>(crc >> 8);
}

// Cuts the input into frames of P::frame_size(first byte); the last one may
// be short. Every byte is consumed (an unknown report ID still takes a frame).
template <typename P>
Frames frames_of(std::span<const std::uint8_t> bytes, bool with_fixed_crc) {
  Frames frames;
  for (std::size_t at = 0; at < bytes.size() && frames.size() < P::kMaxFrames;) {
    const std::size_t full = P::frame_size(bytes[at]);
    const std::size_t size = std::min(full, bytes.size() - at);
    Frame f(bytes.begin() + static_cast<std::ptrdiff_t>(at), bytes.begin() + static_cast<std::ptrdiff_t>(at + size));
    if (with_fixed_crc && (size == full || P::kFixCrcOfShortFrames)) fix_crc(f);
    frames.push_back(std::move(f));
    at += size;
  }
  return frames;
}

// A stream decoder that turns reports into samples with device time, fed
// with receive times that never go back (how far apart they are comes from
// the frame's last two bytes), its device times fed to hid::ClockSync as the
// driver does. S provides:
//   using Decoder, Sample, Result, State (default-constructible, per run);
//   static constexpr std::size_t kMaxSamplesPerReport;
//   static bool carries_device_time(const Result&);   // the verdicts the driver clocks
//   static std::uint32_t clock_observe_us(const Result&), clock_map_us(const Result&);
//   static void check_result(const Result&, std::span<const Sample> samples, State&);
//   static void check_stats(const Decoder&);
// Every sample must carry the receive time it was pushed with, and the
// clock's skew must stay finite whatever it was fed. Returns the decoder's
// statistics, for checks particular to the options it was given.
template <typename S, typename... DecoderArgs>
auto check_timed_stream(const Frames& frames, DecoderArgs&&... decoder_args) {
  typename S::Decoder decoder(std::forward<DecoderArgs>(decoder_args)...);
  hid::ClockSync clock;
  std::array<typename S::Sample, S::kMaxSamplesPerReport> out;
  typename S::State state{};
  TimeNs receive = 1'000'000 * kNsPerSecond;
  for (const Frame& f : frames) {
    const std::uint32_t gap_us =
        f.size() >= 2 ? static_cast<std::uint32_t>(f[f.size() - 2] | f[f.size() - 1] << 8) : 1;
    receive += static_cast<TimeNs>(gap_us) * 1000;
    const typename S::Result r = decoder.push(f, out, receive);
    require(r.sample_count <= out.size());
    const std::span<const typename S::Sample> samples(out.data(), r.sample_count);
    for (const auto& smp : samples) require(smp.receive_ns == receive);
    S::check_result(r, samples, state);
    if (S::carries_device_time(r)) {
      if (r.device_reset) clock.reset();
      clock.observe(S::clock_observe_us(r), receive);
      (void)clock.to_host_ns(S::clock_map_us(r));
      require(std::isfinite(clock.skew_ppm()));
    }
  }
  S::check_stats(decoder);
  return decoder.stats();
}

template <typename P>
int fuzz_protocol(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> bytes(data, size);
  P::check_reports(bytes);
  if constexpr (requires { P::check_input(bytes); }) P::check_input(bytes);
  for (const bool crc_fixed : {false, true}) {
    const Frames frames = frames_of<P>(bytes, crc_fixed);
    if (crc_fixed) {
      for (const Frame& f : frames) P::check_reports(f);
    }
    P::check_streams(frames, crc_fixed);
  }
  return 0;
}

}  // namespace proprio::fuzz
