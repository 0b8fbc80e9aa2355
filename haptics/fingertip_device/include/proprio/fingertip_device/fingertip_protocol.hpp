#pragma once
// The USB HID wire protocol of cutaneous fingertip haptic devices (a band
// that presses and shears the fingertip pad with 2 motors, a 3-DOF platform,
// a force-vector device), version 1.0: byte layouts, units and pure
// encode/decode functions. The specification, with the reasons behind each
// choice and a firmware sketch, is docs/fingertip-hid-protocol.md; the
// constants and layouts here must match it byte for byte.
//
// Three numbered HID reports, all 64 bytes (report ID first, as hidapi
// exchanges them), little-endian, each ending in the CRC-16 of
// glove_protocol.hpp over every byte before it:
//   0x41 feedback    (input, at the device's feedback rate, 1 kHz by default):
//                    encoders, force sensors, currents, status, command echo
//   0x42 device info (feature): kind, motors, encoder and gear, rates, limits,
//                    serial, the finger it is assigned to
//   0x50 command     (output): motor output-shaft angles or a force, enable
// The IDs differ from the IMU glove's (0x01/0x02/0x10) and the stretch
// board's (0x21/0x22/0x30), so a capture or a device of one is never decoded
// as another.
//
// Decoding comes in two forms, like the gloves': the noexcept form fills a
// caller-owned struct and returns a FingertipDecodeStatus (no allocation; for
// the I/O thread, the firmware emulator and the fuzzer), the Result form adds
// a message that names the field and says what to do. The decoders trust no
// length, count or enum byte. FingertipFeedbackStream and
// FingertipCommandStream add the sequence bookkeeping each receiving end
// needs (gaps, stale and duplicate reports, restarts) and count every kind of
// failure.
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/result.hpp"
#include "proprio/hid/crc16.hpp"
#include "proprio/hid/usb_ids.hpp"

namespace proprio::devices {

// pid.codes' open-source vendor ID with a third test product ID (the IMU
// glove has 0x0001, the stretch board 0x0002). A device that ships gets its
// own PID; hosts then take --vid/--pid.
inline constexpr std::uint16_t kFingertipUsbVendorId = hid::kPidCodesVendorId;
inline constexpr std::uint16_t kFingertipUsbProductId = 0x0003;
// Vendor-defined top-level collection: usage page 0xFF00, usage 0x03.
inline constexpr std::uint16_t kFingertipHidUsagePage = hid::kVendorDefinedUsagePage;
inline constexpr std::uint16_t kFingertipHidUsage = 0x03;

// Version byte: major in the high nibble, minor in the low, with the gloves'
// rules (any minor of a known major decodes; reserved bits and bytes are zero
// when sent and ignored when received).
inline constexpr std::uint8_t kFingertipProtocolMajor = 1;
inline constexpr std::uint8_t kFingertipProtocolMinor = 0;
inline constexpr std::uint8_t kFingertipProtocolVersion =
    static_cast<std::uint8_t>(kFingertipProtocolMajor << 4 | kFingertipProtocolMinor);

enum class FingertipReportId : std::uint8_t {
  feedback = 0x41,
  device_info = 0x42,
  command = 0x50,
};

// Every report is one full-speed interrupt packet.
inline constexpr std::size_t kFingertipReportSize = 64;
// A device has 1 to 3 motors, force sensors and command values.
inline constexpr std::size_t kFingertipMaxMotors = 3;
inline constexpr std::size_t kFingertipSerialLength = 16;  // ASCII, NUL-padded
// A control loop faster than this has nothing to gain from a 1 kHz USB frame.
inline constexpr std::uint16_t kFingertipMaxControlRateHz = 10000;
inline constexpr std::uint16_t kFingertipDefaultControlRateHz = 1000;

// Wire units: angles in µrad, forces in mN, currents in mA, device time in µs.
inline constexpr double kFingertipUradPerRad = 1e6;
inline constexpr double kFingertipMnPerN = 1e3;
inline constexpr double kFingertipMaPerA = 1e3;

enum class FingertipDeviceKind : std::uint8_t {
  band_2dof = 1,      // a belt around the fingertip: normal press and one shear direction
  platform_3dof = 2,  // a tactor platform moved by three motors (normal and 2-D shear)
  force_vector = 3,   // three independent axes: normal, shear_x, shear_z
};

// What a command asks for, and what the device is rendering.
enum class FingertipMode : std::uint8_t {
  idle = 0,          // feedback only: holding the rest angles (disabled, watchdog or fault)
  motor_angles = 1,  // values are output-shaft angles, µrad, one per motor, 0 = rest
  force = 2,         // values are normal, shear_x, shear_z in mN (the fingertip frame of
                     // proprio/haptics/fingertip_force.hpp); the firmware's model turns them into angles
};

// The device's answer to the newest command it received (feedback byte 15).
enum class FingertipCommandResult : std::uint8_t {
  none = 0,               // no command since power-up
  ok = 1,                 // applied
  bad_report = 2,         // length, ID, version, CRC or a field out of range
  stale_sequence = 3,     // a duplicate, or older than one already applied: ignored
  wrong_value_count = 4,  // motor_angles with a value count other than the motor count
};
inline constexpr std::uint8_t kFingertipCommandResultMax = 4;

// Command flag bits (command byte 5).
namespace fingertip_command_flags {
inline constexpr std::uint8_t enable = 0x01;  // render the values; 0 = go to rest
// Clear latched faults (and the watchdog flag) if their cause is gone.
inline constexpr std::uint8_t clear_faults = 0x02;
// The first command of a host session: accept its sequence whatever the last one was.
inline constexpr std::uint8_t sequence_reset = 0x04;
inline constexpr std::uint8_t defined = 0x07;
}  // namespace fingertip_command_flags

// Feedback status bits (feedback bytes 10-11).
namespace fingertip_status {
inline constexpr std::uint16_t enabled = 0x0001;           // rendering a command
inline constexpr std::uint16_t watchdog_tripped = 0x0002;  // no valid command for the watchdog period: at rest
inline constexpr std::uint16_t clamped = 0x0004;           // the applied command exceeded a limit and was clamped
inline constexpr std::uint16_t fault_overcurrent = 0x0008;  // latched: bridges off
inline constexpr std::uint16_t fault_encoder = 0x0010;      // latched: bridges off
inline constexpr std::uint16_t ramping = 0x0020;            // the output is still ramping in after enable
inline constexpr std::uint16_t fault_stall = 0x0040;        // latched: at the current limit without moving
inline constexpr std::uint16_t device_start = 0x0080;       // first report after power-up: sequences restarted
inline constexpr std::uint16_t faults = fault_overcurrent | fault_encoder | fault_stall;
inline constexpr std::uint16_t defined = 0x00FF;
}  // namespace fingertip_status

// Byte offsets (docs/fingertip-hid-protocol.md, §3-5).
namespace fingertip_command_layout {
inline constexpr std::size_t report_id = 0;
inline constexpr std::size_t version = 1;
inline constexpr std::size_t sequence = 2;  // u16
inline constexpr std::size_t mode = 4;
inline constexpr std::size_t flags = 5;
inline constexpr std::size_t count = 6;          // values carried, 1-3
inline constexpr std::size_t values = 8;         // 3 x i32
inline constexpr std::size_t host_time_ns = 20;  // i64
inline constexpr std::size_t crc = 62;
}  // namespace fingertip_command_layout
namespace fingertip_feedback_layout {
inline constexpr std::size_t report_id = 0;
inline constexpr std::size_t version = 1;
inline constexpr std::size_t sequence = 2;          // u16
inline constexpr std::size_t applied_sequence = 4;  // u16
inline constexpr std::size_t device_time_us = 6;    // u32
inline constexpr std::size_t status = 10;           // u16
inline constexpr std::size_t motor_count = 12;
inline constexpr std::size_t fsr_count = 13;
inline constexpr std::size_t mode = 14;
inline constexpr std::size_t command_result = 15;
inline constexpr std::size_t encoder_counts = 16;     // 3 x i32
inline constexpr std::size_t fsr_force_mn = 28;       // 3 x i32
inline constexpr std::size_t current_ma = 40;         // 3 x i16
inline constexpr std::size_t rejected_commands = 46;  // u16
inline constexpr std::size_t applied_host_time_ns = 48;  // i64
inline constexpr std::size_t ramp_permille = 56;         // u16
inline constexpr std::size_t crc = 62;
}  // namespace fingertip_feedback_layout
namespace fingertip_info_layout {
inline constexpr std::size_t report_id = 0;
inline constexpr std::size_t version = 1;
inline constexpr std::size_t firmware = 2;  // 3 bytes
inline constexpr std::size_t kind = 5;
inline constexpr std::size_t motor_count = 6;
inline constexpr std::size_t fsr_count = 7;
inline constexpr std::size_t hand = 8;
inline constexpr std::size_t finger = 9;
inline constexpr std::size_t control_rate_hz = 10;   // u16
inline constexpr std::size_t feedback_rate_hz = 12;  // u16
inline constexpr std::size_t counts_per_rev = 14;    // u32
inline constexpr std::size_t gear_ratio_milli = 18;  // u32
inline constexpr std::size_t watchdog_ms = 22;       // u16
inline constexpr std::size_t ramp_ms = 24;           // u16
inline constexpr std::size_t max_normal_mn = 26;     // u32
inline constexpr std::size_t max_shear_mn = 30;      // u32
inline constexpr std::size_t min_angle_urad = 34;    // i32
inline constexpr std::size_t max_angle_urad = 38;    // i32
inline constexpr std::size_t max_current_ma = 42;    // u16
inline constexpr std::size_t serial = 44;            // 16 bytes
inline constexpr std::size_t crc = 62;
}  // namespace fingertip_info_layout

// On the wire the hand is 0 unassigned, 1 left, 2 right, and the finger 0-4
// (thumb to little, proprio::Finger's order) or 0xFF unassigned.
inline constexpr std::uint8_t kFingertipUnassignedFinger = 0xFF;

// Host -> device. Integer wire units; fingertip_device.hpp converts from SI.
struct FingertipCommand {
  // The host's running number of commands sent, wrapping; the device ignores
  // one that is not newer than the last it applied (a reordered or repeated
  // report must not undo a newer command).
  std::uint16_t sequence = 0;
  FingertipMode mode = FingertipMode::motor_angles;
  std::uint8_t flags = 0;  // fingertip_command_flags
  std::uint8_t count = 0;  // values carried, 1-3; the decoder zeroes values past it
  // motor_angles: output-shaft angle of each motor, µrad, 0 = rest.
  // force: normal, shear_x, shear_z, mN, in the fingertip frame.
  std::array<std::int32_t, kFingertipMaxMotors> values{};
  // CLOCK_MONOTONIC ns when the host made the command; echoed in the feedback
  // so the host can measure command-to-effect latency. Opaque to the device.
  std::int64_t host_time_ns = 0;

  bool enable() const noexcept { return (flags & fingertip_command_flags::enable) != 0; }
  bool operator==(const FingertipCommand&) const = default;
};

// Device -> host, once per feedback period.
struct FingertipFeedback {
  std::uint8_t version = kFingertipProtocolVersion;
  std::uint16_t sequence = 0;          // running number of feedback reports since power-up, wrapping
  std::uint16_t applied_sequence = 0;  // sequence of the command being applied (0 before any)
  std::uint32_t device_time_us = 0;    // device µs counter at the control tick measured; wraps
  std::uint16_t status = 0;            // fingertip_status bits
  std::uint8_t motor_count = 1;        // 1-3; values past it are zero
  std::uint8_t fsr_count = 0;          // 0-3; readings past it are zero
  FingertipMode mode = FingertipMode::idle;
  FingertipCommandResult command_result = FingertipCommandResult::none;
  // Motor-shaft encoder counts since homing (0 = rest); output-shaft angle =
  // counts * 2π / (counts_per_rev * gear ratio), from the info report.
  std::array<std::int32_t, kFingertipMaxMotors> encoder_counts{};
  std::array<std::int32_t, kFingertipMaxMotors> fsr_force_mn{};  // what each force sensor reads
  std::array<std::int16_t, kFingertipMaxMotors> current_ma{};    // measured motor currents
  std::uint16_t rejected_commands = 0;  // commands refused since power-up, wrapping
  std::int64_t applied_host_time_ns = 0;  // host_time_ns of the applied command (echo)
  std::uint16_t ramp_permille = 0;        // how far the ramp-in has got, 0-1000

  bool has(std::uint16_t status_bit) const noexcept { return (status & status_bit) != 0; }
  bool operator==(const FingertipFeedback&) const = default;
};

// Feature report: what the device is and what it may do.
struct FingertipDeviceInfo {
  std::uint8_t version = kFingertipProtocolVersion;
  std::array<std::uint8_t, 3> firmware{1, 0, 0};  // major, minor, patch
  FingertipDeviceKind kind = FingertipDeviceKind::force_vector;
  std::uint8_t motor_count = 3;  // 1-3
  std::uint8_t fsr_count = 3;    // 0-3
  std::optional<Handedness> hand;  // which fingertip the device is assigned to, if any
  std::optional<Finger> finger;
  std::uint16_t control_rate_hz = kFingertipDefaultControlRateHz;  // 1-10000
  std::uint16_t feedback_rate_hz = kFingertipDefaultControlRateHz;  // 1 to the control rate
  std::uint32_t encoder_counts_per_rev = 1024;                       // motor shaft, >= 1
  std::uint32_t gear_ratio_milli = 16000;  // motor turns per output turn x 1000, >= 1
  std::uint16_t watchdog_ms = 50;          // >= 1: every device has a watchdog
  std::uint16_t ramp_ms = 100;             // ramp-in after enable
  std::uint32_t max_normal_force_mn = 2000;
  std::uint32_t max_shear_force_mn = 1000;
  std::int32_t min_angle_urad = -1'000'000;  // output shaft, below max
  std::int32_t max_angle_urad = 1'000'000;
  std::uint16_t max_current_ma = 600;
  std::array<char, kFingertipSerialLength + 1> serial{};  // printable ASCII, NUL-terminated

  std::string_view serial_view() const noexcept;
  void set_serial(std::string_view s) noexcept;  // truncated to 16 characters
  double gear_ratio() const noexcept { return gear_ratio_milli / 1000.0; }
  // Output-shaft angle of a motor-shaft encoder reading, rad.
  double output_angle_rad(std::int32_t encoder_counts) const noexcept;
  double output_rad_per_count() const noexcept;
  bool operator==(const FingertipDeviceInfo&) const = default;
};
// "force_vector, 3 motors + 3 FSRs, 1024 counts/rev x 16:1, 1000 Hz ..."
std::string describe(const FingertipDeviceInfo& info);

const char* to_string(FingertipDeviceKind kind) noexcept;
const char* to_string(FingertipMode mode) noexcept;
const char* to_string(FingertipCommandResult result) noexcept;
// "enabled|ramping", or "none".
std::string describe_fingertip_status(std::uint16_t status);

// What is wrong with a report. expected/actual carry the numbers a message
// needs; 0 when not meaningful.
enum class FingertipDecodeErrc : std::uint8_t {
  ok = 0,
  empty,                  // no bytes at all
  unknown_report_id,      // expected = the ID this decoder reads, actual = the ID byte
  bad_length,             // expected = 64, actual = bytes given
  unsupported_version,    // expected = major we speak, actual = version byte
  crc_mismatch,           // expected = CRC in the report, actual = CRC of its bytes
  bad_mode,               // actual = mode byte
  bad_value_count,        // command value count not 1-3; actual = count
  bad_motor_count,        // not 1-3; actual = count
  bad_fsr_count,          // not 0-3; actual = count
  bad_command_result,     // actual = result byte
  bad_ramp,               // ramp above 1000 permille; actual = value
  bad_kind,               // actual = kind byte
  bad_rate,               // control rate 0 or above 10000, or feedback rate 0 or above it; expected = limit, actual = rate
  bad_encoder_resolution, // counts per rev 0
  bad_gear_ratio,         // gear ratio 0
  bad_watchdog,           // watchdog period 0
  bad_angle_limits,       // min angle not below max; expected = min, actual = max (µrad)
  bad_serial,             // a byte that is not printable ASCII before the NUL; expected = offset, actual = byte
  bad_assignment,         // hand above 2 (expected = 0) or finger above 4 and not 0xFF (expected = 1); actual = byte
};
inline constexpr std::size_t kFingertipDecodeErrcCount = 20;
static_assert(static_cast<std::size_t>(FingertipDecodeErrc::bad_assignment) + 1 == kFingertipDecodeErrcCount,
              "FingertipLinkCounters::by_error is indexed by the code");
const char* to_string(FingertipDecodeErrc code) noexcept;

struct FingertipDecodeStatus {
  FingertipDecodeErrc code = FingertipDecodeErrc::ok;
  std::int64_t expected = 0;
  std::int64_t actual = 0;
  bool ok() const noexcept { return code == FingertipDecodeErrc::ok; }
  explicit operator bool() const noexcept { return ok(); }
};
// "bad motor count 4 in byte 12: ..." (names the field and what to do).
std::string describe(const FingertipDecodeStatus& status);
Error to_error(const FingertipDecodeStatus& status);  // Errc::parse_error, or unsupported for a version

// Encoders write every byte (reserved ones and values past the counts zero)
// and the CRC. They do not validate: tests encode invalid fields on purpose
// to reach the decoder's checks behind a valid CRC.
std::array<std::uint8_t, kFingertipReportSize> encode_fingertip_command(const FingertipCommand& command) noexcept;
std::array<std::uint8_t, kFingertipReportSize> encode_fingertip_feedback(const FingertipFeedback& feedback) noexcept;
std::array<std::uint8_t, kFingertipReportSize> encode_fingertip_info(const FingertipDeviceInfo& info) noexcept;

// Decoders check, in order: report ID, length (exactly 64), version major,
// CRC, then every field's range. A rejected report leaves out untouched. No allocation.
FingertipDecodeStatus decode_fingertip_command(std::span<const std::uint8_t> bytes, FingertipCommand& out) noexcept;
FingertipDecodeStatus decode_fingertip_feedback(std::span<const std::uint8_t> bytes, FingertipFeedback& out) noexcept;
FingertipDecodeStatus decode_fingertip_info(std::span<const std::uint8_t> bytes, FingertipDeviceInfo& out) noexcept;
// The same with a message (what, which field, what it means for the user).
Result<FingertipCommand> decode_fingertip_command(std::span<const std::uint8_t> bytes);
Result<FingertipFeedback> decode_fingertip_feedback(std::span<const std::uint8_t> bytes);
Result<FingertipDeviceInfo> decode_fingertip_info(std::span<const std::uint8_t> bytes);

// SI to wire: rounds to the nearest unit and saturates to the int32 range.
// Returns false (out untouched) for a non-finite value.
bool fingertip_to_wire(double value_si, double units_per_si, std::int32_t& out) noexcept;

// A command's values from SI, the one encoder the driver and the in-process
// emulated device (proprio::haptics) share: c.values[i] for i < c.count from
// values_si[i] through fingertip_to_wire, in µrad for motor_angles and mN for
// force. Returns false when a value is not finite (its entry stays as it was).
bool set_fingertip_command_values(FingertipCommand& c, std::span<const double> values_si) noexcept;

// ---------------------------------------------------------------------------
// Sequence bookkeeping on the receiving end.

enum class FingertipSequenceVerdict : std::uint8_t {
  first,     // the first report since construction or reset()
  in_order,  // the next number
  gap,       // newer, with numbers missing before it (lost counts them)
  stale,     // a duplicate or older than the newest: to be dropped
  restart,   // the sender said its numbering restarted (device_start / sequence_reset)
  resync,    // after kFingertipResyncAfterStale stale reports in a row: taken as a new start
};
const char* to_string(FingertipSequenceVerdict verdict) noexcept;

// A u16 sequence: newer means 1 to 32767 ahead (mod 2^16). A sender that
// restarts without saying so (or a silence longer than half the number space)
// would look old for ever, so this many stale reports in a row resynchronise.
inline constexpr std::uint32_t kFingertipResyncAfterStale = 16;

struct FingertipSequenceResult {
  FingertipSequenceVerdict verdict = FingertipSequenceVerdict::first;
  std::uint32_t lost = 0;  // numbers skipped before this one (gap only)
  bool accepted() const noexcept { return verdict != FingertipSequenceVerdict::stale; }
};

class FingertipSequenceTracker {
 public:
  FingertipSequenceResult observe(std::uint16_t sequence, bool restart) noexcept;
  void reset() noexcept { have_ = false; stale_run_ = 0; }
  bool have() const noexcept { return have_; }
  std::uint16_t newest() const noexcept { return newest_; }

 private:
  bool have_ = false;
  std::uint16_t newest_ = 0;
  std::uint32_t stale_run_ = 0;
};

// What one receiving end has seen.
struct FingertipLinkCounters {
  std::uint64_t received = 0;      // reports handed in
  std::uint64_t accepted = 0;      // decoded and newer than everything before
  std::uint64_t crc_failures = 0;
  std::uint64_t bad_versions = 0;
  std::uint64_t malformed = 0;     // every other decode error (ID, length, a field out of range)
  std::uint64_t sequence_gaps = 0;  // times numbers were skipped
  std::uint64_t lost = 0;           // numbers skipped in total
  std::uint64_t stale = 0;          // duplicates and reordered old reports, dropped
  std::uint64_t restarts = 0;       // restart and resync verdicts
  std::array<std::uint64_t, kFingertipDecodeErrcCount> by_error{};  // index: FingertipDecodeErrc
};

struct FingertipStreamResult {
  FingertipDecodeStatus decode;
  FingertipSequenceResult sequence;
  bool accepted() const noexcept { return decode.ok() && sequence.accepted(); }
};

// The host's end: feedback reports in, counted. out is written only for an accepted report.
class FingertipFeedbackStream {
 public:
  FingertipStreamResult push(std::span<const std::uint8_t> bytes, FingertipFeedback& out) noexcept;
  void reset() noexcept { tracker_.reset(); }  // after a reconnect: the next report starts afresh
  const FingertipLinkCounters& counters() const noexcept { return counters_; }

 private:
  FingertipSequenceTracker tracker_;
  FingertipLinkCounters counters_;
};

// The device's end: command reports in, counted. out is written only for an accepted report.
class FingertipCommandStream {
 public:
  FingertipStreamResult push(std::span<const std::uint8_t> bytes, FingertipCommand& out) noexcept;
  void reset() noexcept { tracker_.reset(); }
  const FingertipLinkCounters& counters() const noexcept { return counters_; }

 private:
  FingertipSequenceTracker tracker_;
  FingertipLinkCounters counters_;
};

}  // namespace proprio::devices
