// Fuzzes the stretch read-out board's HID protocol: the report decoders, the
// stream decoder and the clock alignment behind it, and the emulator's
// command handler. Whatever the bytes, nothing may crash, hang or invoke
// undefined behaviour (the fuzz and ASan builds check), and the decoders' own
// promises must hold. Seeds: corpus/stretch_protocol/ (regenerate with
// PROPRIO_REGEN_CORPUS=1, see tests/unit/test_stretch_emulator.cpp).
//
// The input is read three ways:
//  1. as one report, handed to every decoder and to the emulator as a command;
//  2. as a byte stream framed by report ID (the ID gives the size; unknown
//     IDs take 64 bytes, so that every byte is consumed), fed to
//     StretchStreamDecoder with receive times taken from the bytes, and every
//     measurement report's last device time to ClockSync;
//  3. as 2., with every frame's CRC recomputed, so that mutations get past the
//     CRC to the field checks and the sequence and timestamp logic.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <vector>

#include "proprio/devices/clock_sync.hpp"
#include "proprio/devices/stretch_emulator.hpp"
#include "proprio/devices/stretch_protocol.hpp"
#include "proprio/devices/stretch_stream.hpp"

using namespace proprio;
using namespace proprio::devices;

namespace {

void require(bool ok) {
  if (!ok) std::abort();
}

void check_single(std::span<const std::uint8_t> bytes) {
  StretchDataReport data;
  const StretchDecodeStatus s = decode_stretch_data_report(bytes, data);
  if (s) {
    // What decodes re-encodes to something that decodes to the same.
    StretchDataReport again;
    require(decode_stretch_data_report(encode_stretch_data_report(data), again).ok() && again == data);
    require(data.count >= 1 && data.count <= kStretchMeasurementsPerReport);
    require(data.top_strips >= 1 && data.top_strips <= kStretchMaxStrips);
    require(data.bottom_strips >= 1 && data.bottom_strips <= kStretchMaxStrips);
    for (std::size_t i = 0; i < kStretchMeasurementsPerReport; ++i) {
      const StretchMeasurementRaw& m = data.measurements[i];
      if (i >= data.count) {
        require(m == StretchMeasurementRaw{});
        continue;
      }
      require(m.combination < data.combination_count());
      require(m.value <= kStretchMaxCapacitanceCount);
      const double pf = stretch_count_to_pf(m.value);
      require(pf >= 0.0 && pf <= kStretchWireFullScalePf);
    }
  } else {
    require(!describe(s).empty());
    require(!to_error(s).message.empty());
  }
  StretchDeviceInfo info;
  if (decode_stretch_info_report(bytes, info)) {
    StretchDeviceInfo again;
    require(decode_stretch_info_report(encode_stretch_info_report(info), again).ok() && again == info);
    require(info.full_scale_ff >= 1 && info.full_scale_ff <= kStretchMaxCapacitanceCount);
  }
  StretchCommand command;
  if (decode_stretch_command(bytes, command)) {
    StretchCommand again;
    require(decode_stretch_command(encode_stretch_command(command), again).ok() && again == command);
  }
}

// The firmware's command handling: any bytes, then the board still measures.
void check_emulator_commands(std::span<const std::uint8_t> bytes) {
  StretchEmulatorOptions o;
  o.top_strips = 2;
  o.bottom_strips = 3;
  auto emulator = StretchEmulator::create(o, [](std::size_t c, TimeNs) { return 10.0 + static_cast<double>(c); });
  require(emulator.ok());
  const StretchCommandResult result = emulator->handle_command(bytes, 0);
  require(static_cast<std::uint8_t>(result) <= static_cast<std::uint8_t>(StretchCommandResult::bad_report));
  std::vector<StretchEmulatedReport> out;
  emulator->advance_to(30 * kNsPerMillisecond, out);
  for (const auto& r : out) require(decode_stretch_data_report(r.bytes).ok());
  require(decode_stretch_info_report(emulator->info_report(0)).ok());
}

std::vector<std::vector<std::uint8_t>> frames_of(std::span<const std::uint8_t> bytes, bool fix_crc) {
  std::vector<std::vector<std::uint8_t>> frames;
  for (std::size_t at = 0; at < bytes.size();) {
    std::size_t size = stretch_report_size_for_id(bytes[at]);
    if (size == 0) size = kStretchDataReportSize;
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

void check_stream(std::span<const std::uint8_t> bytes, bool fix_crc, bool expect_layout) {
  StretchStreamOptions o;
  if (expect_layout) {
    o.expected_top_strips = 13;
    o.expected_bottom_strips = 14;
  }
  StretchStreamDecoder decoder(o);
  ClockSync clock;
  std::array<StretchSample, kStretchMeasurementsPerReport> out;
  TimeNs receive = 1'000'000 * kNsPerSecond;
  std::int64_t newest_sequence_end = 0;
  std::uint32_t newest_epoch = 0;
  bool any = false;
  for (const auto& f : frames_of(bytes, fix_crc)) {
    // Receive times never go back; how far apart they are comes from the bytes.
    const std::uint32_t gap_us =
        f.size() >= 2 ? static_cast<std::uint32_t>(f[f.size() - 2] | f[f.size() - 1] << 8) : 1;
    receive += static_cast<TimeNs>(gap_us) * 1000;
    const StretchPushResult r = decoder.push(f, out, receive);
    require(r.sample_count <= out.size());
    require(r.verdict == StretchReportVerdict::accepted || r.sample_count == 0);
    for (std::size_t i = 0; i < r.sample_count; ++i) {
      const StretchSample& smp = out[i];
      require(std::isfinite(smp.capacitance_pf) && smp.capacitance_pf >= 0.0);
      require(smp.combination < kStretchMaxCombinations);
      require(smp.top_strip < kStretchMaxStrips && smp.bottom_strip < kStretchMaxStrips);
      require(smp.receive_ns == receive);
      require(smp.sequence == r.sequence + static_cast<std::int64_t>(i));
      if (i > 0) require(smp.device_time_us >= out[i - 1].device_time_us);
    }
    if (r.verdict == StretchReportVerdict::accepted) {
      // Accepted reports move forward within an epoch: measurement times never go back.
      if (any && r.epoch == newest_epoch) require(r.sequence >= newest_sequence_end);
      require(r.epoch >= newest_epoch);
      newest_sequence_end = r.sequence + r.count;
      newest_epoch = r.epoch;
      any = true;
    }
    if (r.verdict == StretchReportVerdict::accepted || r.verdict == StretchReportVerdict::duplicate ||
        r.verdict == StretchReportVerdict::late) {
      require(r.last_device_time_us >= r.device_time_us);
      if (r.device_reset) clock.reset();
      clock.observe(static_cast<std::uint32_t>(r.last_device_time_us), receive);
      (void)clock.to_host_ns(static_cast<std::uint32_t>(r.device_time_us));
      require(std::isfinite(clock.skew_ppm()));
    }
  }
  const StretchStreamStats& s = decoder.stats();
  require(s.accepted + s.duplicates + s.late + s.decode_errors + s.other_reports + s.wrong_layout == s.reports);
  std::uint64_t by_code = 0;
  for (const auto n : s.decode_errors_by_code) by_code += n;
  require(by_code == s.decode_errors);
  std::uint64_t by_status = 0;
  for (const auto n : s.by_status) by_status += n;
  require(by_status == s.measurements);
  std::uint64_t flagged = 0;
  for (const auto n : s.flagged_by_combination) flagged += n;
  require(flagged == s.measurements_flagged());
  require(s.measurements <= s.accepted * kStretchMeasurementsPerReport);
  require(std::isfinite(s.measurement_period_us) && s.measurement_period_us > 0.0);
  if (expect_layout) require(s.accepted == 0 || (s.top_strips == 13 && s.bottom_strips == 14) || s.wrong_layout > 0);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> bytes(data, size);
  check_single(bytes);
  check_emulator_commands(bytes);
  check_stream(bytes, false, false);
  check_stream(bytes, true, false);
  check_stream(bytes, true, true);
  return 0;
}
