// Fuzzes the glove's HID protocol: the report decoders, the stream decoder
// and the clock alignment behind it. Whatever the bytes, nothing may crash,
// hang or invoke undefined behaviour (the fuzz and ASan builds check), and
// the decoders' own promises must hold. Seeds: corpus/glove_protocol/
// (regenerate with PROPRIO_REGEN_CORPUS=1, see tests/unit/test_glove_emulator.cpp).
//
// The input is read three ways:
//  1. as one report, handed to every decoder;
//  2. as a byte stream framed by report ID (the ID gives the size; unknown
//     IDs take 64 bytes, so that every byte is consumed), fed to
//     GloveStreamDecoder with receive times taken from the bytes, and every
//     data report's timestamp to ClockSync;
//  3. as 2., with every frame's CRC recomputed, so that mutations get past the
//     CRC to the field checks and the sequence and timestamp logic.
#include <cmath>
#include <cstdlib>
#include <vector>

#include "proprio/devices/clock_sync.hpp"
#include "proprio/devices/glove_protocol.hpp"
#include "proprio/devices/glove_stream.hpp"

using namespace proprio;
using namespace proprio::devices;

namespace {

void require(bool ok) {
  if (!ok) std::abort();
}

void check_single(std::span<const std::uint8_t> bytes) {
  GloveDataReport data;
  const GloveDecodeStatus s = decode_data_report(bytes, data);
  if (s) {
    // What decodes re-encodes to something that decodes to the same.
    GloveDataReport again;
    require(decode_data_report(encode_data_report(data), again).ok() && again == data);
    require(data.block_count() >= 1 && data.block_count() <= kGloveImusPerReport);
    for (std::size_t i = 0; i < data.block_count(); ++i) {
      const ImuSample smp = to_imu_sample(data.imus[i], static_cast<std::uint16_t>(data.first_imu + i),
                                          data.accel_range, data.gyro_range);
      require(smp.accel_mps2.allFinite() && smp.gyro_radps.allFinite());
      require(smp.accel_mps2.cwiseAbs().maxCoeff() <= accel_full_scale_mps2(data.accel_range) * 1.01);
    }
  } else {
    require(!describe(s).empty());
  }
  GloveDeviceInfo info;
  if (decode_info_report(bytes, info)) {
    GloveDeviceInfo again;
    require(decode_info_report(encode_info_report(info), again).ok() && again == info);
  }
  GloveCommand command;
  if (decode_command(bytes, command)) {
    GloveCommand again;
    require(decode_command(encode_command(command), again).ok() && again == command);
  }
}

std::vector<std::vector<std::uint8_t>> frames_of(std::span<const std::uint8_t> bytes, bool fix_crc) {
  std::vector<std::vector<std::uint8_t>> frames;
  for (std::size_t at = 0; at < bytes.size();) {
    std::size_t size = report_size_for_id(bytes[at]);
    if (size == 0) size = kGloveDataReportSize;
    size = std::min(size, bytes.size() - at);
    std::vector<std::uint8_t> f(bytes.begin() + static_cast<std::ptrdiff_t>(at),
                                bytes.begin() + static_cast<std::ptrdiff_t>(at + size));
    if (fix_crc && f.size() >= 2) {
      const std::uint16_t crc = crc16_ccitt(std::span(f).first(f.size() - 2));
      f[f.size() - 2] = static_cast<std::uint8_t>(crc);
      f[f.size() - 1] = static_cast<std::uint8_t>(crc >> 8);
    }
    frames.push_back(std::move(f));
    at += size;
  }
  return frames;
}

void check_stream(std::span<const std::uint8_t> bytes, bool fix_crc) {
  GloveStreamDecoder decoder;
  ClockSync clock;
  std::array<GloveSample, kGloveImusPerReport> out;
  TimeNs receive = 1'000'000 * kNsPerSecond;
  for (const auto& f : frames_of(bytes, fix_crc)) {
    // Receive times never go back; how far apart they are comes from the bytes.
    const std::uint32_t gap_us = f.size() >= 2 ? static_cast<std::uint32_t>(f[f.size() - 2] | f[f.size() - 1] << 8) : 1;
    receive += static_cast<TimeNs>(gap_us) * 1000;
    const GlovePushResult r = decoder.push(f, out, receive);
    require(r.sample_count <= out.size());
    for (std::size_t i = 0; i < r.sample_count; ++i) {
      require(out[i].imu.accel_mps2.allFinite() && out[i].imu.gyro_radps.allFinite());
      require(out[i].imu.sensor_id < kGloveMaxImus);
      require(out[i].receive_ns == receive);
    }
    if (r.verdict == GloveReportVerdict::accepted || r.verdict == GloveReportVerdict::duplicate ||
        r.verdict == GloveReportVerdict::late) {
      if (r.device_reset) clock.reset();
      clock.observe(r.timestamp_us, receive);
      const TimeNs mapped = clock.to_host_ns(r.timestamp_us);
      (void)mapped;
      require(std::isfinite(clock.skew_ppm()));
    }
  }
  const GloveStreamStats& s = decoder.stats();
  require(s.accepted + s.duplicates + s.late + s.decode_errors + s.other_reports == s.reports);
  std::uint64_t by_code = 0;
  for (const auto n : s.decode_errors_by_code) by_code += n;
  require(by_code == s.decode_errors);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> bytes(data, size);
  check_single(bytes);
  check_stream(bytes, false);
  check_stream(bytes, true);
  return 0;
}
