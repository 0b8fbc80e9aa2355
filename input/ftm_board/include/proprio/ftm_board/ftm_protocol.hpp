#pragma once
// The FTM glove read-out board's USB HID wire protocol, version 1.0: byte
// layouts, units and pure encode/decode functions. The specification, with the
// reasons behind each choice, is docs/ftm-hid-protocol.md; the constants and
// layouts here must match it byte for byte.
//
// The board (Lee 2021, §3.2.1) reads four MPU-9250 IMUs (accelerometer, gyro,
// AK8963 compass) at 200 Hz and three soft capacitive bend sensors at 1 kHz.
// Four numbered HID reports, little-endian, each ending in hid::crc16_ccitt:
//   0x51 IMU tick    (input,   64 bytes): two of the four IMUs at one tick
//   0x52 bend batch  (input,   64 bytes): up to 5 consecutive samples of all 3 bend sensors
//   0x53 device info (feature, 32 bytes): firmware, rates, ranges, last command
//   0x58 command     (output,  16 bytes): start/stop, rates, ranges
// Four IMUs at 19 bytes each (status, 9 int16) do not fit one 64-byte
// full-speed packet with a header, so a tick goes out as two reports (IMUs
// 0-1 and 2-3), each complete on its own. IDs differ from the other boards'
// (0x01/0x02/0x10, 0x21/0x22/0x30, 0x41-0x43) so captures are never confused.
//
// Decoding has two forms, like the other boards': noexcept into a
// caller-owned struct with an FtmDecodeStatus (no allocation; reader thread,
// fuzzer) and Result with a message a user can act on.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "proprio/core/result.hpp"
#include "proprio/ftm/ftm_glove.hpp"
#include "proprio/hid/crc16.hpp"
#include "proprio/hid/report_codec.hpp"
#include "proprio/hid/usb_ids.hpp"

namespace proprio::devices {

inline constexpr std::uint16_t kFtmUsbVendorId = hid::kPidCodesVendorId;
inline constexpr std::uint16_t kFtmUsbProductId = 0x0004;
inline constexpr std::uint16_t kFtmHidUsagePage = hid::kVendorDefinedUsagePage;
inline constexpr std::uint16_t kFtmHidUsage = 0x04;

// Version byte: major high nibble, minor low nibble; any minor of a known
// major decodes (reserved bytes are zero when sent and ignored when received).
inline constexpr std::uint8_t kFtmProtocolMajor = 1;
inline constexpr std::uint8_t kFtmProtocolMinor = 0;
inline constexpr std::uint8_t kFtmProtocolVersion =
    static_cast<std::uint8_t>(kFtmProtocolMajor << 4 | kFtmProtocolMinor);

enum class FtmReportId : std::uint8_t {
  imu = 0x51,
  bend = 0x52,
  device_info = 0x53,
  command = 0x58,
};

inline constexpr std::size_t kFtmDataReportSize = 64;  // one full-speed interrupt packet
inline constexpr std::size_t kFtmInfoReportSize = 32;
inline constexpr std::size_t kFtmCommandReportSize = 16;
inline constexpr std::size_t kFtmImusPerReport = 2;
inline constexpr std::size_t kFtmBendSamplesPerReport = 5;  // 5 ticks x 3 sensors at 1 kHz: 200 reports/s

// Rates the board may be set to. The AK8963 caps the compass at 100 Hz
// whatever the IMU rate. Each rate alone is bounded here; together they must
// also fit the interrupt endpoint (ftm_reports_per_second).
inline constexpr std::uint16_t kFtmMinImuRateHz = 10;
inline constexpr std::uint16_t kFtmMaxImuRateHz = 500;
inline constexpr std::uint16_t kFtmMinBendRateHz = 10;
inline constexpr std::uint16_t kFtmMaxBendRateHz = 2000;
inline constexpr std::uint16_t kFtmDefaultImuRateHz = 200;
inline constexpr std::uint16_t kFtmDefaultBendRateHz = 1000;
inline constexpr double kFtmMaxMagRateHz = 100.0;
// A full-speed interrupt endpoint with bInterval 1 moves one 64-byte report
// per 1 ms frame. The defaults use 600 of them (2 x 200 IMU + 1000 / 5 bend).
inline constexpr double kFtmMaxReportsPerSecond = 1000.0;
constexpr double ftm_reports_per_second(double imu_rate_hz, double bend_rate_hz) noexcept {
  return 2.0 * imu_rate_hz + bend_rate_hz / static_cast<double>(kFtmBendSamplesPerReport);
}

// Full-scale range codes, as the MPU-9250's ACCEL_FS_SEL and GYRO_FS_SEL.
enum class FtmAccelRange : std::uint8_t { g2 = 0, g4 = 1, g8 = 2, g16 = 3 };
enum class FtmGyroRange : std::uint8_t { dps250 = 0, dps500 = 1, dps1000 = 2, dps2000 = 3 };
inline constexpr FtmAccelRange kFtmDefaultAccelRange = FtmAccelRange::g8;
inline constexpr FtmGyroRange kFtmDefaultGyroRange = FtmGyroRange::dps2000;

inline constexpr double kFtmStandardGravity = 9.80665;
// m/s² per count at a range (2 g: 16384 LSB/g).
double accel_mps2_per_count(FtmAccelRange range) noexcept;
// rad/s per count at a range (the datasheet's 131, 65.5, 32.8, 16.4 LSB/(°/s)).
double gyro_radps_per_count(FtmGyroRange range) noexcept;
// AK8963 in 16-bit mode: 0.15 µT per count, measurement range ±32760 counts
// (±4912 µT); beyond it the chip sets HOFL.
inline constexpr double kFtmMagUtPerCount = 0.15;
inline constexpr std::int32_t kFtmMagMaxCount = 32760;

// Bend capacitance: u16 in units of 0.01 pF, 0 to 655.34 pF; 0xFFFF is the
// rail (over range). A soft capacitive bend sensor reads tens to a few hundred
// pF and changes by a few pF over a joint's range; 0.01 pF is below what a
// capacitance-to-digital converter resolves at 1 kHz.
inline constexpr double kFtmBendPfPerCount = 0.01;
inline constexpr std::uint16_t kFtmBendRailCount = 0xFFFF;
inline constexpr double kFtmBendFullScalePf = (kFtmBendRailCount - 1) * kFtmBendPfPerCount;

// Per-sample status on the wire: ftm::sample_status bits plus these wire-only ones.
namespace ftm_wire_status {
inline constexpr std::uint8_t mag_fresh = 0x20;   // IMU: the compass values are a new AK8963 sample
inline constexpr std::uint8_t over_range = 0x40;  // bend: the converter saturated; value at the rail
inline constexpr std::uint8_t imu_mask = 0x3F;    // bits an IMU status may carry
inline constexpr std::uint8_t bend_mask = 0x49;   // stale | sensor_error | over_range
}  // namespace ftm_wire_status

// Data report flag bits.
namespace ftm_flags {
// First report of its kind after power-up, START or a rate change: the
// sequence restarted at 0 and the host must not count the jump as loss.
inline constexpr std::uint8_t stream_start = 0x01;
// The board discarded reports of this kind before this one (transmit queue full).
inline constexpr std::uint8_t overrun = 0x02;
}  // namespace ftm_flags

// Byte offsets (docs/ftm-hid-protocol.md, tables 1 and 2).
namespace ftm_imu_layout {
inline constexpr std::size_t report_id = 0;
inline constexpr std::size_t version = 1;
inline constexpr std::size_t sequence = 2;      // u32: tick number
inline constexpr std::size_t timestamp_us = 6;  // u32: device µs when the tick was sampled
inline constexpr std::size_t flags = 10;
inline constexpr std::size_t first_imu = 11;  // 0 or 2
inline constexpr std::size_t ranges = 12;     // accel code bits 0-1, gyro code bits 4-5
inline constexpr std::size_t period_us = 14;  // u16: tick period, device µs
inline constexpr std::size_t imus = 16;       // 2 x 19 bytes
inline constexpr std::size_t imu_size = 19;   // status, accel xyz, gyro xyz, mag xyz (i16)
inline constexpr std::size_t crc = 62;
}  // namespace ftm_imu_layout
namespace ftm_bend_layout {
inline constexpr std::size_t report_id = 0;
inline constexpr std::size_t version = 1;
inline constexpr std::size_t sequence = 2;      // u32: number of sample 0
inline constexpr std::size_t timestamp_us = 6;  // u32: device µs of sample 0
inline constexpr std::size_t flags = 10;
inline constexpr std::size_t count = 11;      // samples, 1-5
inline constexpr std::size_t period_us = 12;  // u16: sample period, device µs
inline constexpr std::size_t samples = 14;    // 5 x 3 x (u16 value, u8 status)
inline constexpr std::size_t sensor_size = 3;
inline constexpr std::size_t crc = 62;
}  // namespace ftm_bend_layout

// One IMU as on the wire: raw counts. mag is in the AK8963's die axes; the
// host swaps them into the accelerometer's (imu_sample_from_wire).
struct FtmImuRaw {
  std::uint8_t status = 0;  // ftm::sample_status | ftm_wire_status::mag_fresh
  std::array<std::int16_t, 3> accel{};
  std::array<std::int16_t, 3> gyro{};
  std::array<std::int16_t, 3> mag{};
  bool operator==(const FtmImuRaw&) const = default;
};

struct FtmImuReport {
  std::uint8_t version = kFtmProtocolVersion;
  std::uint32_t sequence = 0;
  std::uint32_t timestamp_us = 0;
  std::uint8_t flags = 0;
  std::uint8_t first_imu = 0;  // 0 or 2
  FtmAccelRange accel_range = kFtmDefaultAccelRange;
  FtmGyroRange gyro_range = kFtmDefaultGyroRange;
  std::uint16_t period_us = 5000;
  std::array<FtmImuRaw, kFtmImusPerReport> imus{};
  bool operator==(const FtmImuReport&) const = default;
};

struct FtmBendRaw {
  std::uint16_t value = 0;  // 0.01 pF
  std::uint8_t status = 0;  // stale | sensor_error | over_range
  bool operator==(const FtmBendRaw&) const = default;
};

struct FtmBendReport {
  std::uint8_t version = kFtmProtocolVersion;
  std::uint32_t sequence = 0;
  std::uint32_t timestamp_us = 0;
  std::uint8_t flags = 0;
  std::uint8_t count = 0;  // 1-5
  std::uint16_t period_us = 1000;
  // samples[i][sensor]; those past count are zero.
  std::array<std::array<FtmBendRaw, ftm::kFtmBendCount>, kFtmBendSamplesPerReport> samples{};
  bool operator==(const FtmBendReport&) const = default;
};

enum class FtmCommandOp : std::uint8_t {
  start_streaming = 0x01,  // (re)start: sequences restart at 0, next reports flagged stream_start
  stop_streaming = 0x02,
  set_rates = 0x03,   // imu_rate_hz, bend_rate_hz; restarts the stream
  set_ranges = 0x04,  // accel_range, gyro_range; takes effect at the next tick
};

enum class FtmCommandResult : std::uint8_t {
  none = 0,
  ok = 1,
  unknown_command = 2,
  bad_argument = 3,
  bad_report = 4,  // wrong length, version or CRC
};

struct FtmCommand {
  FtmCommandOp op = FtmCommandOp::start_streaming;
  std::uint8_t token = 0;
  std::uint16_t imu_rate_hz = 0;   // set_rates
  std::uint16_t bend_rate_hz = 0;  // set_rates
  FtmAccelRange accel_range = kFtmDefaultAccelRange;  // set_ranges
  FtmGyroRange gyro_range = kFtmDefaultGyroRange;     // set_ranges
  bool operator==(const FtmCommand&) const = default;
};

struct FtmDeviceInfo {
  std::uint8_t version = kFtmProtocolVersion;
  std::array<std::uint8_t, 3> firmware{1, 0, 0};
  bool streaming = false;
  std::uint16_t imu_rate_hz = kFtmDefaultImuRateHz;
  std::uint16_t bend_rate_hz = kFtmDefaultBendRateHz;
  std::uint8_t mag_rate_hz = 100;
  FtmAccelRange accel_range = kFtmDefaultAccelRange;
  FtmGyroRange gyro_range = kFtmDefaultGyroRange;
  std::uint8_t imus_present = 0x0F;   // bit i: IMU i answered at boot
  std::uint8_t bends_present = 0x07;  // bit i: bend sensor i
  std::uint8_t last_command_token = 0;
  FtmCommandResult last_command_result = FtmCommandResult::none;
  std::uint32_t timestamp_us = 0;
  bool operator==(const FtmDeviceInfo&) const = default;
};

// What is wrong with a report; expected/actual carry the numbers a message needs.
enum class FtmDecodeErrc : std::uint8_t {
  ok = 0,
  empty,
  bad_length,           // expected = size of this report type, actual = bytes given
  unknown_report_id,    // expected = the ID this decoder reads, actual = the ID byte
  unsupported_version,  // expected = major we speak, actual = version byte
  crc_mismatch,         // expected = CRC in the report, actual = CRC of its bytes
  bad_count,            // bend sample count 0 or above 5; actual = count
  bad_first_imu,        // IMU report first_imu not 0 or 2; actual = it
  bad_period,           // period 0; or info rates out of range; actual = value
  unknown_command,      // actual = opcode
};
inline constexpr std::size_t kFtmDecodeErrcCount = 10;
const char* to_string(FtmDecodeErrc code) noexcept;

using FtmDecodeStatus = hid::DecodeStatus<FtmDecodeErrc>;
std::string describe(const FtmDecodeStatus& status);
Error to_error(const FtmDecodeStatus& status);  // Errc::parse_error or unsupported

// Size of reports with this ID (ID byte and CRC included), 0 for an unknown ID.
std::size_t ftm_report_size_for_id(std::uint8_t report_id) noexcept;

// Encoders write every byte and the CRC; they do not validate (tests encode
// invalid fields on purpose to reach the decoder's checks behind a valid CRC).
std::array<std::uint8_t, kFtmDataReportSize> encode_ftm_imu_report(const FtmImuReport& report) noexcept;
std::array<std::uint8_t, kFtmDataReportSize> encode_ftm_bend_report(const FtmBendReport& report) noexcept;
std::array<std::uint8_t, kFtmInfoReportSize> encode_ftm_info_report(const FtmDeviceInfo& info) noexcept;
std::array<std::uint8_t, kFtmCommandReportSize> encode_ftm_command(const FtmCommand& command) noexcept;

// Decoders check report ID, length, version major, CRC, then field ranges.
// Reserved bits of statuses are masked off. No allocation.
FtmDecodeStatus decode_ftm_imu_report(std::span<const std::uint8_t> bytes, FtmImuReport& out) noexcept;
FtmDecodeStatus decode_ftm_bend_report(std::span<const std::uint8_t> bytes, FtmBendReport& out) noexcept;
FtmDecodeStatus decode_ftm_info_report(std::span<const std::uint8_t> bytes, FtmDeviceInfo& out) noexcept;
FtmDecodeStatus decode_ftm_command(std::span<const std::uint8_t> bytes, FtmCommand& out) noexcept;
Result<FtmImuReport> decode_ftm_imu_report(std::span<const std::uint8_t> bytes);
Result<FtmBendReport> decode_ftm_bend_report(std::span<const std::uint8_t> bytes);
Result<FtmDeviceInfo> decode_ftm_info_report(std::span<const std::uint8_t> bytes);
Result<FtmCommand> decode_ftm_command(std::span<const std::uint8_t> bytes);

// ---------------------------------------------------------------------------
// Units: what the firmware does to a sensor value, and what the host undoes.

// An IMU sample as the board reports it: counts rounded to nearest and
// clamped to int16; an axis at a rail flags accel_/gyro_saturated; a compass
// axis beyond ±32760 counts flags mag_overflow (HOFL); any non-finite value
// makes the whole sample sensor_error with all values zero (what the board
// sends when the bus read fails). mag_uT is in the IMU's (accelerometer's)
// axes and is swapped into the AK8963's. The stale and sensor_error bits of
// sample.status are kept; mag_fresh comes from sample.mag_fresh.
FtmImuRaw quantise_imu(const ftm::FtmImuSample& sample, FtmAccelRange accel_range, FtmGyroRange gyro_range) noexcept;
// The host's side: SI units, compass in the accelerometer's axes, and the
// status the tracker uses (the board's, plus saturation for a value at a rail
// the board did not flag). time_ns is left 0.
ftm::FtmImuSample imu_sample_from_wire(const FtmImuRaw& raw, FtmAccelRange accel_range,
                                       FtmGyroRange gyro_range) noexcept;
// A capacitance as the board reports it: rounded to 0.01 pF; at or above the
// full scale over_range (value at the rail); below zero 0 with sensor_error;
// not finite sensor_error (value 0). The stale and sensor_error bits of
// `status` are kept.
FtmBendRaw quantise_bend(double capacitance_pF, std::uint8_t status = 0) noexcept;
// pF and the tracker's status (over_range, or a value at the rail, is sensor_error).
ftm::FtmBendSample bend_sample_from_wire(const FtmBendRaw& raw) noexcept;

}  // namespace proprio::devices
