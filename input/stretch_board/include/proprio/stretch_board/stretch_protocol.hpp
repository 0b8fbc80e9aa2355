#pragma once
// The stretch read-out board's USB HID wire protocol, version 1.1: byte
// layouts, units and pure encode/decode functions. The specification, with the
// reasons behind each choice and a firmware sketch, is
// docs/stretch-glove-hid-protocol.md; the constants and layouts here must
// match it byte for byte.
//
// The board time-multiplexes the electrode strips of a glove or a sensor
// array (Glauser 2019, Sec. 4.3.2 and 5.2.1): each measurement connects a set
// of strips as the source electrode, grounds all others and reports one
// capacitance, tagged with its "combination" (its row of the measurement matrix):
//   c < n k:        top strip c / k and bottom strip c % k together (M^I; the
//                   rows of StretchGloveLayout::measurement_matrix() and of
//                   StripArrayLayout::measurement_plan()'s first n k rows);
//   n k <= c < n k + n + k (1.1, boards that say single_strips): one strip
//                   alone, s = c - n k, the n top strips first, then the k
//                   bottom ones (M^II: StripArrayLayout::measurement_plan(true)'s
//                   remaining rows, in the same order).
// n = top strips, k = bottom strips. Three numbered HID reports, all
// little-endian, each ending in the CRC-16 of glove_protocol.hpp:
//   0x21 measurements (input,   64 bytes): up to 12 consecutive measurements
//   0x22 device info  (feature, 32 bytes): firmware, strips, full scale, rate
//   0x30 command      (output,  16 bytes): start/stop streaming, set rate
// Report sizes include the report ID byte, which is what hidapi's hid_read,
// hid_get_feature_report and hid_write exchange for numbered reports. The IDs
// differ from the IMU glove's (0x01/0x02/0x10) so that a capture or a device
// of the one is never mistaken for the other.
//
// Decoding comes in two forms, like the IMU glove's: the noexcept form fills a
// caller-owned struct and returns a StretchDecodeStatus (no allocation; for
// the reader thread and the fuzzer), the Result form adds a message a user
// can act on. Names carry "stretch" because they share proprio::devices with
// the IMU glove's codec.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "proprio/core/result.hpp"
#include "proprio/hid/crc16.hpp"
#include "proprio/hid/report_codec.hpp"
#include "proprio/hid/usb_ids.hpp"

namespace proprio::devices {

// pid.codes' open-source vendor ID with another of its test product IDs (the
// IMU glove has 0x0001). A board that ships gets its own PID; hosts then pass --vid/--pid.
inline constexpr std::uint16_t kStretchUsbVendorId = hid::kPidCodesVendorId;
inline constexpr std::uint16_t kStretchUsbProductId = 0x0002;
// Vendor-defined top-level collection: usage page 0xFF00, usage 0x02.
inline constexpr std::uint16_t kStretchHidUsagePage = hid::kVendorDefinedUsagePage;
inline constexpr std::uint16_t kStretchHidUsage = 0x02;

// Version byte: major in the high nibble, minor in the low, with the IMU
// glove's rules (any minor of a known major decodes; reserved bits and bytes
// are zero when sent and ignored when received). 1.1 added the single-strip
// rows (stretch_flags::single_strips, StretchDeviceInfo::single_strips): bits
// that 1.0 reserved, so a report stamped 1.0 never has them, whatever its bits say.
inline constexpr std::uint8_t kStretchProtocolMajor = 1;
inline constexpr std::uint8_t kStretchProtocolMinor = 1;
inline constexpr std::uint8_t kStretchProtocolVersion =
    static_cast<std::uint8_t>(kStretchProtocolMajor << 4 | kStretchProtocolMinor);

enum class StretchReportId : std::uint8_t {
  measurements = 0x21,
  device_info = 0x22,
  command = 0x30,
};

inline constexpr std::size_t kStretchDataReportSize = 64;  // one full-speed interrupt packet
inline constexpr std::size_t kStretchInfoReportSize = 32;
inline constexpr std::size_t kStretchCommandReportSize = 16;
inline constexpr std::size_t kStretchMeasurementsPerReport = 12;  // 14-byte header + 12 x 4 + CRC = 64
// Strips per layer: 1-32, so that a pair combination fits the 10 bits the
// wire gives it (32 x 32 = 1024; the thesis glove has 13 x 14 = 182).
// kStretchMaxCombinations is what the 10-bit field holds: a board measuring
// single strips too needs n k + n + k <= 1024 (up to 31 x 31, or 12 x 12 =
// 168 rows for the thesis's arrays); more is refused (too_many_rows).
inline constexpr std::size_t kStretchMaxStrips = 32;
inline constexpr std::size_t kStretchMaxCombinations = kStretchMaxStrips * kStretchMaxStrips;
// Rows a board of n x k strips reports: the pairs, plus the single strips when it measures them.
inline constexpr std::size_t stretch_row_count(std::size_t top_strips, std::size_t bottom_strips,
                                               bool single_strips) noexcept {
  return top_strips * bottom_strips + (single_strips ? top_strips + bottom_strips : 0);
}
// Which strips a combination connects as the source. A strip index of
// kStretchNoStrip means that layer has none (a single-strip row).
inline constexpr std::uint8_t kStretchNoStrip = 0xFF;
struct StretchSources {
  std::uint8_t top_strip = kStretchNoStrip;
  std::uint8_t bottom_strip = kStretchNoStrip;
  bool single() const noexcept { return top_strip == kStretchNoStrip || bottom_strip == kStretchNoStrip; }
  bool operator==(const StretchSources&) const = default;
};
// Combination c of an n x k board (c < stretch_row_count(n, k, true); beyond,
// both strips are kStretchNoStrip). k = 0 gives no strips.
StretchSources stretch_sources(std::size_t combination, std::size_t top_strips, std::size_t bottom_strips) noexcept;
// Measurements per second the board may be set to. 1000 reports/s of 12 would
// carry 12000; the charge-time circuit needs a few oscillator periods plus
// switch settling per measurement, which a 4 kHz slot leaves room for.
inline constexpr std::uint16_t kStretchMaxRateHz = 4000;
inline constexpr std::uint16_t kStretchDefaultRateHz = 960;  // 60 solves of 16 measurements per second

// Capacitance on the wire: an unsigned 20-bit count of femtofarads (1 fF =
// 0.001 pF), so 0 to 1048.575 pF. A measurement sums several cells of ~20 pF
// at rest, which stretching can quadruple (C/C0 = (A/A0)^2), so the range
// leaves headroom; 1 fF is below what a 555-timer read-out resolves.
inline constexpr std::uint32_t kStretchMaxCapacitanceCount = (1u << 20) - 1;
inline constexpr double kStretchPfPerCount = 1e-3;
inline constexpr double kStretchWireFullScalePf = kStretchMaxCapacitanceCount * kStretchPfPerCount;

// What the board says about one measurement (2 bits on the wire). Anything
// but ok makes the value unusable for the solve.
enum class StretchMeasurementStatus : std::uint8_t {
  ok = 0,
  // At or above the board's full scale (its period counter overflowed: the
  // capacitance is too large, or the layers touch). The value is the full scale.
  saturated = 1,
  // Below the parasitic capacitance the board subtracts (a broken lead reads
  // like this). The value is 0.
  below_zero = 2,
  // The oscillator gave no edge within the measurement slot (a shorted or
  // disconnected channel, or non-finite input to the emulator). The value is 0.
  no_signal = 3,
};
inline constexpr std::size_t kStretchMeasurementStatusCount = 4;
const char* to_string(StretchMeasurementStatus status) noexcept;

// Byte offsets in the measurement report (docs/stretch-glove-hid-protocol.md, table 1).
namespace stretch_data_layout {
inline constexpr std::size_t report_id = 0;
inline constexpr std::size_t version = 1;
inline constexpr std::size_t sequence = 2;      // u32: running number of measurement 0
inline constexpr std::size_t timestamp_us = 6;  // u32: device µs when measurement 0 was taken
inline constexpr std::size_t flags = 10;
inline constexpr std::size_t count = 11;          // measurements in this report, 1-12
inline constexpr std::size_t top_strips = 12;     // 1-32
inline constexpr std::size_t bottom_strips = 13;  // 1-32
inline constexpr std::size_t measurements = 14;   // 12 x u32
inline constexpr std::size_t measurement_size = 4;
inline constexpr std::size_t crc = 62;  // u16 over bytes 0-61
}  // namespace stretch_data_layout

// The u32 of one measurement: combination in bits 0-9, status in bits 10-11,
// capacitance count in bits 12-31.
namespace stretch_measurement_bits {
inline constexpr std::uint32_t combination_mask = 0x3FF;
inline constexpr int status_shift = 10;
inline constexpr std::uint32_t status_mask = 0x3;
inline constexpr int value_shift = 12;
}  // namespace stretch_measurement_bits

// Measurement report flag bits (byte 10).
namespace stretch_flags {
// First report after power-up, START or SET_RATE: the measurement counter
// restarted at 0 and the host must not count the jump as loss.
inline constexpr std::uint8_t stream_start = 0x01;
// The board discarded measurements before this report itself (its transmit
// queue was full because the host was not reading, or a measurement overran
// its slot). They still used up sequence numbers, so the host sees the gap.
inline constexpr std::uint8_t overrun = 0x02;
// 1.1: the board measures the n + k single strips too, so combinations run
// to n k + n + k - 1. In every report, so that each decodes alone (a capture,
// a host that attached mid-stream); the info report says the same (byte 7, bit 1).
inline constexpr std::uint8_t single_strips = 0x04;
}  // namespace stretch_flags

// Whether a report stamped `version` with these flags carries single-strip
// rows: the flag, from protocol 1.1 on (1.0 reserved the bit).
inline constexpr bool stretch_single_strips(std::uint8_t version, std::uint8_t flags) noexcept {
  return (version & 0x0F) >= 1 && (flags & stretch_flags::single_strips) != 0;
}

// One measurement as on the wire.
struct StretchMeasurementRaw {
  std::uint16_t combination = 0;  // t * bottom_strips + b, or n k + single strip (stretch_sources())
  StretchMeasurementStatus status = StretchMeasurementStatus::ok;
  std::uint32_t value = 0;  // fF, 0 to kStretchMaxCapacitanceCount
  bool operator==(const StretchMeasurementRaw&) const = default;
};

// One measurement report, decoded but unscaled.
struct StretchDataReport {
  std::uint8_t version = kStretchProtocolVersion;
  // Running number of measurement 0 since the stream started; measurement i
  // of this report is sequence + i. Counting measurements rather than reports
  // tells the host exactly how many measurements it lost, and lets it check
  // the sequence against the timestamp whatever the batch sizes. Wraps.
  std::uint32_t sequence = 0;
  // Device µs counter when measurement 0 was taken; measurement i follows
  // i measurement periods later (the board paces measurements by a timer). Wraps.
  std::uint32_t timestamp_us = 0;
  std::uint8_t flags = 0;  // stretch_flags bits
  std::uint8_t count = 0;  // measurements carried, 1-12
  std::uint8_t top_strips = 0;
  std::uint8_t bottom_strips = 0;
  std::array<StretchMeasurementRaw, kStretchMeasurementsPerReport> measurements{};  // count of them meaningful

  bool single_strips() const noexcept { return stretch_single_strips(version, flags); }
  // Combinations this report may carry: the rows of the board's plan.
  std::size_t combination_count() const noexcept {
    return stretch_row_count(top_strips, bottom_strips, single_strips());
  }
  bool operator==(const StretchDataReport&) const = default;
};

enum class StretchCommandOp : std::uint8_t {
  start_streaming = 0x01,  // (re)start: the counter restarts at 0, the next report is flagged stream_start
  stop_streaming = 0x02,
  set_rate = 0x03,  // rate_hz measurements/s (1-4000); restarts the stream
};

// The board's answer to the last command, reported in the info report.
enum class StretchCommandResult : std::uint8_t {
  none = 0,  // no command since power-up
  ok = 1,
  unknown_command = 2,
  bad_argument = 3,
  bad_report = 4,  // wrong length, version or CRC
};

struct StretchCommand {
  StretchCommandOp op = StretchCommandOp::start_streaming;
  std::uint8_t token = 0;     // echoed in the info report so a host can see it was applied
  std::uint16_t rate_hz = 0;  // set_rate
  bool operator==(const StretchCommand&) const = default;
};

struct StretchDeviceInfo {
  std::uint8_t version = kStretchProtocolVersion;
  std::array<std::uint8_t, 3> firmware{1, 0, 0};  // major, minor, patch
  std::uint8_t top_strips = 0;
  std::uint8_t bottom_strips = 0;
  bool streaming = false;
  // 1.1: the board also measures the n + k single strips (byte 7, bit 1;
  // always false in a report stamped 1.0).
  bool single_strips = false;
  std::uint16_t rate_hz = 0;  // measurements per second
  // The largest capacitance the board can report, fF (at most
  // kStretchMaxCapacitanceCount); readings at or above it come flagged saturated.
  std::uint32_t full_scale_ff = kStretchMaxCapacitanceCount;
  // The stray capacitance of the read-out circuit, measured on two unconnected
  // pads and subtracted from every measurement (Glauser 2019, App. B.2), fF.
  std::uint32_t parasitic_ff = 0;
  std::uint8_t last_command_token = 0;
  StretchCommandResult last_command_result = StretchCommandResult::none;
  std::uint32_t timestamp_us = 0;  // device clock when the report was made

  // The rows of the board's plan: pairs, and single strips when it measures them.
  std::size_t combination_count() const noexcept { return stretch_row_count(top_strips, bottom_strips, single_strips); }
  bool operator==(const StretchDeviceInfo&) const = default;
};

// What is wrong with a report. expected/actual carry the numbers a message
// needs (lengths, versions, both CRCs, counts); 0 when not meaningful.
enum class StretchDecodeErrc : std::uint8_t {
  ok = 0,
  empty,                // no bytes at all
  bad_length,           // expected = size of this report type, actual = bytes given
  unknown_report_id,    // expected = the ID this decoder reads, actual = the ID byte
  unsupported_version,  // expected = major we speak, actual = version byte
  crc_mismatch,         // expected = CRC in the report, actual = CRC of its bytes
  bad_count,            // measurement count 0 or above 12; actual = count
  bad_strip_count,      // a layer with 0 or more than 32 strips; expected = top, actual = bottom
  // a combination beyond the board's rows; expected = rows (top x bottom, + top + bottom
  // with single strips), actual = combination
  bad_combination,
  bad_rate,             // info report rate 0 or above kStretchMaxRateHz; actual = rate
  bad_full_scale,       // info report full scale 0 or beyond 20 bits; actual = full scale, fF
  unknown_command,      // actual = opcode
  // 1.1: single strips on, but n k + n + k rows do not fit the 10-bit
  // combination field; expected = top * 256 + bottom, actual = rows
  too_many_rows,
};
inline constexpr std::size_t kStretchDecodeErrcCount = 13;
const char* to_string(StretchDecodeErrc code) noexcept;

using StretchDecodeStatus = hid::DecodeStatus<StretchDecodeErrc>;
// "CRC mismatch: the report carries 0x1a2b but its bytes give 0x3c4d ..."
std::string describe(const StretchDecodeStatus& status);
Error to_error(const StretchDecodeStatus& status);  // Errc::parse_error or unsupported

// The size of reports with this ID (report ID byte and CRC included), or 0 for
// an ID the protocol does not define. Lets a reader frame a raw byte stream.
std::size_t stretch_report_size_for_id(std::uint8_t report_id) noexcept;

// Encoders write every byte (reserved ones and measurements past count zero)
// and the CRC. They do not validate: tests encode invalid field values on
// purpose to reach the decoder's checks behind a valid CRC. Fields wider than
// their wire bits are truncated to them.
std::array<std::uint8_t, kStretchDataReportSize> encode_stretch_data_report(const StretchDataReport& report) noexcept;
std::array<std::uint8_t, kStretchInfoReportSize> encode_stretch_info_report(const StretchDeviceInfo& info) noexcept;
std::array<std::uint8_t, kStretchCommandReportSize> encode_stretch_command(const StretchCommand& command) noexcept;

// Decoders check, in order: report ID, length, version major, CRC, then field
// ranges. Measurements past count are left zero. No allocation.
StretchDecodeStatus decode_stretch_data_report(std::span<const std::uint8_t> bytes, StretchDataReport& out) noexcept;
StretchDecodeStatus decode_stretch_info_report(std::span<const std::uint8_t> bytes, StretchDeviceInfo& out) noexcept;
StretchDecodeStatus decode_stretch_command(std::span<const std::uint8_t> bytes, StretchCommand& out) noexcept;
// The same with a message (what, which field, what it means for the user).
Result<StretchDataReport> decode_stretch_data_report(std::span<const std::uint8_t> bytes);
Result<StretchDeviceInfo> decode_stretch_info_report(std::span<const std::uint8_t> bytes);
Result<StretchCommand> decode_stretch_command(std::span<const std::uint8_t> bytes);

// Wire count to pF.
inline double stretch_count_to_pf(std::uint32_t count) noexcept { return count * kStretchPfPerCount; }

// A capacitance in pF as the board reports it against its full scale (fF,
// at most kStretchMaxCapacitanceCount): rounded to the nearest fF; at or above
// full scale saturated (value = full scale), below zero below_zero (value 0),
// not finite no_signal (value 0).
StretchMeasurementRaw quantise_capacitance(std::uint16_t combination, double capacitance_pf,
                                           std::uint32_t full_scale_ff = kStretchMaxCapacitanceCount) noexcept;
// The status the host uses: the board's, or saturated for a value at the
// wire's rail even when the board did not say so.
StretchMeasurementStatus host_status(const StretchMeasurementRaw& raw) noexcept;

}  // namespace proprio::devices
