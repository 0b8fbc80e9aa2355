#pragma once
// The IMU glove's USB HID wire protocol, version 1.0: byte layouts, scales and
// pure encode/decode functions. The specification, with the reasons behind
// each choice and a firmware sketch, is docs/glove-hid-protocol.md; the
// constants and layouts here must match it byte for byte.
//
// Three numbered HID reports, all little-endian, each ending in a CRC-16:
//   0x01 IMU data    (input,   64 bytes): one tick of up to 4 IMUs
//   0x02 device info (feature, 32 bytes): firmware, IMU count, rate, ranges
//   0x10 command     (output,  16 bytes): start/stop streaming, rate, ranges
// Report sizes include the report ID byte, which is what hidapi's hid_read,
// hid_get_feature_report and hid_write exchange for numbered reports.
//
// Decoding comes in two forms, like HandSource::lookup and pose_at: the
// noexcept form fills a caller-owned struct and returns a ImuGloveDecodeStatus
// (no allocation; for the reader thread and the fuzzer), the Result form adds
// a message a user can act on.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "proprio/core/recording.hpp"
#include "proprio/core/result.hpp"
#include "proprio/hid/crc16.hpp"
#include "proprio/hid/report_codec.hpp"
#include "proprio/hid/usb_ids.hpp"

namespace proprio::devices {

// pid.codes' open-source vendor ID with one of its test product IDs. A glove
// that ships must get its own PID from pid.codes; hosts then pass --vid/--pid.
inline constexpr std::uint16_t kImuGloveUsbVendorId = hid::kPidCodesVendorId;
inline constexpr std::uint16_t kImuGloveUsbProductId = 0x0001;
// The vendor-defined top-level collection the reports live in (HID usage page
// 0xFF00, usage 0x01), so a composite device's other interfaces are skipped.
inline constexpr std::uint16_t kImuGloveHidUsagePage = hid::kVendorDefinedUsagePage;

// Version byte: major in the high nibble, minor in the low. A host decodes any
// minor of a major it knows (minors only give meaning to reserved bits, which
// senders zero and receivers ignore); a new major is a new layout.
inline constexpr std::uint8_t kImuGloveProtocolMajor = 1;
inline constexpr std::uint8_t kImuGloveProtocolMinor = 0;
inline constexpr std::uint8_t kImuGloveProtocolVersion =
    static_cast<std::uint8_t>(kImuGloveProtocolMajor << 4 | kImuGloveProtocolMinor);

enum class ImuGloveReportId : std::uint8_t {
  imu_data = 0x01,
  device_info = 0x02,
  command = 0x10,
};

inline constexpr std::size_t kImuGloveDataReportSize = 64;  // one full-speed interrupt packet
inline constexpr std::size_t kImuGloveInfoReportSize = 32;
inline constexpr std::size_t kImuGloveCommandReportSize = 16;
inline constexpr std::size_t kImuGloveImusPerReport = 4;  // 4 x 12 raw bytes + header + CRC = 64
inline constexpr std::size_t kImuGloveMaxImus = 16;       // sensor IDs are 0-15
inline constexpr std::size_t kImuGloveMaxReportsPerTick = kImuGloveMaxImus / kImuGloveImusPerReport;
// Highest rate a device may be set to: a full-speed interrupt endpoint polled
// every 1 ms carries 1000 reports/s, and 7 IMUs need 2 reports per tick.
inline constexpr std::uint16_t kImuGloveMaxRateHz = 500;

// Byte offsets in the IMU data report (docs/glove-hid-protocol.md, table 1).
namespace data_layout {
inline constexpr std::size_t report_id = 0;
inline constexpr std::size_t version = 1;
inline constexpr std::size_t first_imu = 2;
inline constexpr std::size_t imu_total = 3;
inline constexpr std::size_t sequence = 4;      // u16
inline constexpr std::size_t timestamp_us = 6;  // u32
inline constexpr std::size_t flags = 10;
inline constexpr std::size_t ranges = 11;
inline constexpr std::size_t imu_status = 12;  // u16, 4 bits per IMU block
inline constexpr std::size_t imu_blocks = 14;  // 4 x 12 bytes
inline constexpr std::size_t imu_block_size = 12;
inline constexpr std::size_t crc = 62;  // u16 over bytes 0-61
}  // namespace data_layout

// MPU-9250 full-scale selections (register codes AFS_SEL and FS_SEL).
enum class AccelRange : std::uint8_t { g2 = 0, g4 = 1, g8 = 2, g16 = 3 };
enum class GyroRange : std::uint8_t { dps250 = 0, dps500 = 1, dps1000 = 2, dps2000 = 3 };

// Sensitivities from the MPU-9250 product specification (PS-MPU-9250A-01,
// tables 1-2): 16384/8192/4096/2048 LSB/g and 131/65.5/32.8/16.4 LSB/(°/s),
// with g the standard gravity 9.80665 m/s². The gyro values are the
// datasheet's rounded ones, not 32768/full-scale, because that is what the
// silicon is trimmed to.
double accel_counts_per_mps2(AccelRange range) noexcept;
double gyro_counts_per_radps(GyroRange range) noexcept;
double accel_full_scale_mps2(AccelRange range) noexcept;  // e.g. 16 g
double gyro_full_scale_radps(GyroRange range) noexcept;   // e.g. 2000 °/s
const char* to_string(AccelRange range) noexcept;         // "±16 g"
const char* to_string(GyroRange range) noexcept;          // "±2000 °/s"
std::uint8_t encode_ranges(AccelRange accel, GyroRange gyro) noexcept;

// Per-IMU status bits (4 per IMU on the wire). Any set bit makes the sample
// unusable for a filter; ImuGloveStreamDecoder counts each kind.
namespace imu_status {
inline constexpr std::uint8_t stale = 0x1;            // no new data-ready since the last tick: values repeat
inline constexpr std::uint8_t accel_saturated = 0x2;  // some accelerometer axis at the rail
inline constexpr std::uint8_t gyro_saturated = 0x4;   // some gyro axis at the rail
inline constexpr std::uint8_t sensor_error = 0x8;     // bus read failed (or non-finite input): values are zero
inline constexpr std::uint8_t mask = 0xF;
}  // namespace imu_status

// Data report flag bits (byte 10).
namespace data_flags {
// First tick after power-up or a START command: the sequence restarted at 0
// and the host must not count the jump as loss.
inline constexpr std::uint8_t stream_start = 0x01;
// The device itself skipped ticks before this one (sensor reads overran the
// period, or its transmit queue was full because the host was not reading).
inline constexpr std::uint8_t overrun = 0x02;
}  // namespace data_flags

// One IMU's raw sample as on the wire: counts in the MPU-9250's own axes.
struct ImuGloveImuRaw {
  std::uint8_t status = 0;  // imu_status bits
  std::array<std::int16_t, 3> accel{};
  std::array<std::int16_t, 3> gyro{};
  bool operator==(const ImuGloveImuRaw&) const = default;
};

// One IMU data report (one tick of up to four IMUs), decoded but unscaled.
struct ImuGloveDataReport {
  std::uint8_t version = kImuGloveProtocolVersion;
  std::uint8_t first_imu = 0;  // sensor ID of block 0: 0, 4, 8 or 12
  std::uint8_t imu_total = 0;  // IMUs the device streams per tick (1-16)
  std::uint16_t sequence = 0;  // tick counter, the same in every report of a tick; wraps
  std::uint32_t timestamp_us = 0;  // device µs counter at the tick's sample instant; wraps
  std::uint8_t flags = 0;          // data_flags bits
  AccelRange accel_range = AccelRange::g16;
  GyroRange gyro_range = GyroRange::dps2000;
  std::array<ImuGloveImuRaw, kImuGloveImusPerReport> imus{};  // block_count() of them are meaningful

  // IMU blocks carried by this report: min(4, imu_total - first_imu).
  std::size_t block_count() const noexcept;
  std::size_t part() const noexcept { return first_imu / kImuGloveImusPerReport; }
  bool operator==(const ImuGloveDataReport&) const = default;
};

enum class ImuGloveCommandOp : std::uint8_t {
  start_streaming = 0x01,  // (re)start: sequence restarts at 0, next tick flagged stream_start
  stop_streaming = 0x02,
  set_rate = 0x03,    // rate_hz (1-500); takes effect at the next tick, restarts the stream
  set_ranges = 0x04,  // accel and gyro full scale; restarts the stream
};

// The device's answer to the last command, reported in the info report.
enum class ImuGloveCommandResult : std::uint8_t {
  none = 0,  // no command since power-up
  ok = 1,
  unknown_command = 2,
  bad_argument = 3,
  bad_report = 4,  // wrong length, version or CRC
};

struct ImuGloveCommand {
  ImuGloveCommandOp op = ImuGloveCommandOp::start_streaming;
  std::uint8_t token = 0;       // echoed in the info report so a host can see it was applied
  std::uint16_t rate_hz = 0;    // set_rate
  AccelRange accel_range = AccelRange::g16;  // set_ranges
  GyroRange gyro_range = GyroRange::dps2000;
  bool operator==(const ImuGloveCommand&) const = default;
};

struct ImuGloveDeviceInfo {
  std::uint8_t version = kImuGloveProtocolVersion;
  std::array<std::uint8_t, 3> firmware{1, 0, 0};  // major, minor, patch
  std::uint8_t imu_count = 0;
  std::uint16_t rate_hz = 0;
  AccelRange accel_range = AccelRange::g16;
  GyroRange gyro_range = GyroRange::dps2000;
  bool streaming = false;
  std::uint8_t last_command_token = 0;
  ImuGloveCommandResult last_command_result = ImuGloveCommandResult::none;
  std::uint32_t timestamp_us = 0;  // device clock when the report was made
  bool operator==(const ImuGloveDeviceInfo&) const = default;
};

// What is wrong with a report. expected/actual carry the numbers a message
// needs (lengths, versions, both CRCs, counts); 0 when not meaningful.
enum class ImuGloveDecodeErrc : std::uint8_t {
  ok = 0,
  empty,                // no bytes at all
  bad_length,           // expected = size of this report type, actual = bytes given
  unknown_report_id,    // actual = the ID byte
  unsupported_version,  // expected = major we speak, actual = version byte
  crc_mismatch,         // expected = CRC in the report, actual = CRC of its bytes
  bad_imu_count,        // imu_total 0 or above 16; actual = imu_total
  bad_first_imu,        // not a multiple of 4 or not below imu_total; expected = imu_total, actual = first_imu
  bad_rate,             // info report rate 0 or above kImuGloveMaxRateHz; actual = rate
  unknown_command,      // actual = opcode
};
inline constexpr std::size_t kImuGloveDecodeErrcCount = 10;
const char* to_string(ImuGloveDecodeErrc code) noexcept;

using ImuGloveDecodeStatus = hid::DecodeStatus<ImuGloveDecodeErrc>;
// "CRC mismatch: the report carries 0x1a2b but its bytes 0-61 give 0x3c4d ..."
std::string describe(const ImuGloveDecodeStatus& status);
Error to_error(const ImuGloveDecodeStatus& status);  // Errc::parse_error or unsupported

// The report ID of a report, or 0 for an empty span.
std::uint8_t report_id_of(std::span<const std::uint8_t> report) noexcept;
// The size of reports with this ID (report ID byte and CRC included), or 0 for
// an ID the protocol does not define. Lets a reader frame a raw byte stream.
std::size_t report_size_for_id(std::uint8_t report_id) noexcept;

// Encoders write every byte (reserved ones zero) and the CRC. They do not
// validate: tests encode invalid field values on purpose to reach the
// decoder's checks behind a valid CRC.
std::array<std::uint8_t, kImuGloveDataReportSize> encode_data_report(const ImuGloveDataReport& report) noexcept;
std::array<std::uint8_t, kImuGloveInfoReportSize> encode_info_report(const ImuGloveDeviceInfo& info) noexcept;
std::array<std::uint8_t, kImuGloveCommandReportSize> encode_command(const ImuGloveCommand& command) noexcept;

// Decoders check, in order: report ID, length, version major, CRC, then
// field ranges. Blocks past block_count() are left zero. No allocation.
ImuGloveDecodeStatus decode_data_report(std::span<const std::uint8_t> bytes, ImuGloveDataReport& out) noexcept;
ImuGloveDecodeStatus decode_info_report(std::span<const std::uint8_t> bytes, ImuGloveDeviceInfo& out) noexcept;
ImuGloveDecodeStatus decode_command(std::span<const std::uint8_t> bytes, ImuGloveCommand& out) noexcept;
// The same with a message (what, which field, what it means for the user).
Result<ImuGloveDataReport> decode_data_report(std::span<const std::uint8_t> bytes);
Result<ImuGloveDeviceInfo> decode_info_report(std::span<const std::uint8_t> bytes);
Result<ImuGloveCommand> decode_command(std::span<const std::uint8_t> bytes);

// Raw counts to SI in the IMU's sensor frame: specific force in m/s², angular
// rate in rad/s. No magnetometer in protocol 1.x, so mag_T stays empty.
ImuSample to_imu_sample(const ImuGloveImuRaw& raw, std::uint16_t sensor_id, AccelRange accel_range,
                        GyroRange gyro_range) noexcept;
// Status bits a host adds on its own: an axis at the int16 rail is saturated
// whether or not the firmware said so.
std::uint8_t host_status(const ImuGloveImuRaw& raw) noexcept;

// SI to raw counts, as the firmware's sensor does: round to nearest, clamp to
// the int16 range. Sets accel_/gyro_saturated when an axis reaches the rail
// and sensor_error (all counts zero) when any input is not finite.
ImuGloveImuRaw quantise_imu(const ImuSample& sample, AccelRange accel_range, GyroRange gyro_range) noexcept;

}  // namespace proprio::devices
