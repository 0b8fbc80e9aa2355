#include "proprio/fingertip_device/fingertip_protocol.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "proprio/hid/report_codec.hpp"

namespace proprio::devices {

namespace {

using hid::get_i32;
using hid::get_i64;
using hid::get_u16;
using hid::get_u32;
using hid::put_u16;
using hid::put_u32;
using hid::put_u64;

// ID, length, version and CRC: the checks every report shares.
FingertipDecodeStatus check_frame(std::span<const std::uint8_t> bytes, FingertipReportId id) noexcept {
  // The version byte is byte 1 and the CRC the last two bytes of every report.
  return hid::to_decode_status<FingertipDecodeStatus>(
      hid::check_frame(bytes, static_cast<std::uint8_t>(id), kFingertipReportSize, 1, kFingertipReportSize - 2,
                       kFingertipProtocolMajor));
}

const char* report_name(FingertipReportId id) noexcept {
  switch (id) {
    case FingertipReportId::feedback: return "fingertip device feedback report (ID 0x41)";
    case FingertipReportId::device_info: return "fingertip device info report (ID 0x42)";
    case FingertipReportId::command: return "fingertip device command report (ID 0x50)";
  }
  return "fingertip device report";
}

// What a foreign report ID most likely is, for the message.
const char* guess_report(std::int64_t id) noexcept {
  switch (id) {
    case 0x01:
    case 0x02:
    case 0x10: return " (an IMU glove report ID: wrong device or capture file?)";
    case 0x21:
    case 0x22:
    case 0x30: return " (a stretch glove board report ID: wrong device or capture file?)";
    case 0x41: return " (the fingertip device's feedback report)";
    case 0x42: return " (the fingertip device's info report)";
    case 0x50: return " (the fingertip device's command report)";
    default: return "";
  }
}

bool printable(std::uint8_t c) noexcept { return c >= 0x20 && c <= 0x7E; }

// Counts one decode outcome into a receiving end's counters.
void count_decode(FingertipLinkCounters& c, const FingertipDecodeStatus& s) noexcept {
  ++c.received;
  ++c.by_error[static_cast<std::size_t>(s.code)];
  switch (s.code) {
    case FingertipDecodeErrc::ok: break;
    case FingertipDecodeErrc::crc_mismatch: ++c.crc_failures; break;
    case FingertipDecodeErrc::unsupported_version: ++c.bad_versions; break;
    default: ++c.malformed; break;
  }
}

void count_sequence(FingertipLinkCounters& c, const FingertipSequenceResult& r) noexcept {
  switch (r.verdict) {
    case FingertipSequenceVerdict::first:
    case FingertipSequenceVerdict::in_order: ++c.accepted; break;
    case FingertipSequenceVerdict::gap:
      ++c.accepted;
      ++c.sequence_gaps;
      c.lost += r.lost;
      break;
    case FingertipSequenceVerdict::stale: ++c.stale; break;
    case FingertipSequenceVerdict::restart:
    case FingertipSequenceVerdict::resync:
      ++c.accepted;
      ++c.restarts;
      break;
  }
}

}  // namespace

std::string_view FingertipDeviceInfo::serial_view() const noexcept {
  std::size_t n = 0;
  while (n < kFingertipSerialLength && serial[n] != '\0') ++n;
  return {serial.data(), n};
}

void FingertipDeviceInfo::set_serial(std::string_view s) noexcept {
  serial.fill('\0');
  for (std::size_t i = 0; i < s.size() && i < kFingertipSerialLength; ++i) serial[i] = s[i];
}

double FingertipDeviceInfo::output_rad_per_count() const noexcept {
  const double counts = static_cast<double>(encoder_counts_per_rev) * gear_ratio();
  return counts > 0.0 ? 2.0 * M_PI / counts : 0.0;
}

double FingertipDeviceInfo::output_angle_rad(std::int32_t encoder_counts) const noexcept {
  return encoder_counts * output_rad_per_count();
}

std::string describe(const FingertipDeviceInfo& info) {
  char buf[400];
  const std::string_view serial = info.serial_view();
  std::string where = "unassigned";
  if (info.hand || info.finger) {
    where = std::string(info.hand ? to_string(*info.hand) : std::string_view("either hand")) + " ";
    where += info.finger ? to_string(*info.finger) : std::string_view("any finger");
  }
  std::snprintf(buf, sizeof buf,
                "%s, firmware %u.%u.%u, %u motor%s + %u force sensor%s, %u counts/rev x %.3g:1, control %u Hz, "
                "feedback %u Hz, watchdog %u ms, ramp %u ms, limits %.3g N normal / %.3g N shear / [%.3f, %.3f] rad / "
                "%u mA, serial '%.*s', %s",
                to_string(info.kind), info.firmware[0], info.firmware[1], info.firmware[2], info.motor_count,
                info.motor_count == 1 ? "" : "s", info.fsr_count, info.fsr_count == 1 ? "" : "s",
                info.encoder_counts_per_rev, info.gear_ratio(), info.control_rate_hz, info.feedback_rate_hz,
                info.watchdog_ms, info.ramp_ms, info.max_normal_force_mn / kFingertipMnPerN,
                info.max_shear_force_mn / kFingertipMnPerN, info.min_angle_urad / kFingertipUradPerRad,
                info.max_angle_urad / kFingertipUradPerRad, info.max_current_ma, static_cast<int>(serial.size()),
                serial.data(), where.c_str());
  return buf;
}

const char* to_string(FingertipDeviceKind kind) noexcept {
  switch (kind) {
    case FingertipDeviceKind::band_2dof: return "band_2dof";
    case FingertipDeviceKind::platform_3dof: return "platform_3dof";
    case FingertipDeviceKind::force_vector: return "force_vector";
  }
  return "unknown";
}

const char* to_string(FingertipMode mode) noexcept {
  switch (mode) {
    case FingertipMode::idle: return "idle";
    case FingertipMode::motor_angles: return "motor_angles";
    case FingertipMode::force: return "force";
  }
  return "unknown";
}

const char* to_string(FingertipCommandResult result) noexcept {
  switch (result) {
    case FingertipCommandResult::none: return "none";
    case FingertipCommandResult::ok: return "ok";
    case FingertipCommandResult::bad_report: return "bad_report";
    case FingertipCommandResult::stale_sequence: return "stale_sequence";
    case FingertipCommandResult::wrong_value_count: return "wrong_value_count";
  }
  return "unknown";
}

std::string describe_fingertip_status(std::uint16_t status) {
  static constexpr std::pair<std::uint16_t, const char*> kBits[] = {
      {fingertip_status::enabled, "enabled"},
      {fingertip_status::watchdog_tripped, "watchdog_tripped"},
      {fingertip_status::clamped, "clamped"},
      {fingertip_status::fault_overcurrent, "fault_overcurrent"},
      {fingertip_status::fault_encoder, "fault_encoder"},
      {fingertip_status::ramping, "ramping"},
      {fingertip_status::fault_stall, "fault_stall"},
      {fingertip_status::device_start, "device_start"},
  };
  std::string s;
  for (const auto& [bit, name] : kBits) {
    if (status & bit) {
      if (!s.empty()) s += '|';
      s += name;
    }
  }
  return s.empty() ? "none" : s;
}

const char* to_string(FingertipDecodeErrc code) noexcept {
  switch (code) {
    case FingertipDecodeErrc::ok: return "ok";
    case FingertipDecodeErrc::empty: return "empty";
    case FingertipDecodeErrc::unknown_report_id: return "unknown_report_id";
    case FingertipDecodeErrc::bad_length: return "bad_length";
    case FingertipDecodeErrc::unsupported_version: return "unsupported_version";
    case FingertipDecodeErrc::crc_mismatch: return "crc_mismatch";
    case FingertipDecodeErrc::bad_mode: return "bad_mode";
    case FingertipDecodeErrc::bad_value_count: return "bad_value_count";
    case FingertipDecodeErrc::bad_motor_count: return "bad_motor_count";
    case FingertipDecodeErrc::bad_fsr_count: return "bad_fsr_count";
    case FingertipDecodeErrc::bad_command_result: return "bad_command_result";
    case FingertipDecodeErrc::bad_ramp: return "bad_ramp";
    case FingertipDecodeErrc::bad_kind: return "bad_kind";
    case FingertipDecodeErrc::bad_rate: return "bad_rate";
    case FingertipDecodeErrc::bad_encoder_resolution: return "bad_encoder_resolution";
    case FingertipDecodeErrc::bad_gear_ratio: return "bad_gear_ratio";
    case FingertipDecodeErrc::bad_watchdog: return "bad_watchdog";
    case FingertipDecodeErrc::bad_angle_limits: return "bad_angle_limits";
    case FingertipDecodeErrc::bad_serial: return "bad_serial";
    case FingertipDecodeErrc::bad_assignment: return "bad_assignment";
  }
  return "unknown";
}

std::string describe(const FingertipDecodeStatus& s) {
  char buf[400];
  const long long e = s.expected;
  const long long a = s.actual;
  switch (s.code) {
    case FingertipDecodeErrc::ok: return "ok";
    case FingertipDecodeErrc::empty:
      std::snprintf(buf, sizeof buf, "empty report: 0 bytes where a %lld-byte report was expected", e);
      break;
    case FingertipDecodeErrc::unknown_report_id:
      std::snprintf(buf, sizeof buf, "unknown report ID 0x%02llx in byte 0 where 0x%02llx was expected%s", a, e,
                    guess_report(a));
      break;
    case FingertipDecodeErrc::bad_length:
      std::snprintf(buf, sizeof buf,
                    "bad length: %lld bytes where every fingertip report has exactly %lld (a different device or HID "
                    "report descriptor; check --vid/--pid)",
                    a, e);
      break;
    case FingertipDecodeErrc::unsupported_version:
      std::snprintf(buf, sizeof buf,
                    "unsupported protocol version %lld.%lld in byte 1: this host speaks major version %lld (update "
                    "the host software or flash firmware speaking fingertip protocol %lld.x)",
                    a >> 4, a & 0xF, e, e);
      break;
    case FingertipDecodeErrc::crc_mismatch:
      std::snprintf(buf, sizeof buf,
                    "CRC mismatch in bytes 62-63: the report carries 0x%04llx but its bytes give 0x%04llx (corrupted on "
                    "the way or a firmware bug); the report is dropped",
                    e, a);
      break;
    case FingertipDecodeErrc::bad_mode:
      std::snprintf(buf, sizeof buf,
                    "bad mode %lld: commands carry 1 (motor_angles) or 2 (force), feedback also 0 (idle)", a);
      break;
    case FingertipDecodeErrc::bad_value_count:
      std::snprintf(buf, sizeof buf, "bad value count %lld in byte 6: a command carries 1 to %zu values", a,
                    kFingertipMaxMotors);
      break;
    case FingertipDecodeErrc::bad_motor_count:
      std::snprintf(buf, sizeof buf, "bad motor count %lld: a fingertip device has 1 to %zu motors (firmware not "
                    "configured?)", a, kFingertipMaxMotors);
      break;
    case FingertipDecodeErrc::bad_fsr_count:
      std::snprintf(buf, sizeof buf, "bad force sensor count %lld: a fingertip device has 0 to %zu", a,
                    kFingertipMaxMotors);
      break;
    case FingertipDecodeErrc::bad_command_result:
      std::snprintf(buf, sizeof buf, "bad command result %lld in byte 15: defined are 0 to %u", a,
                    kFingertipCommandResultMax);
      break;
    case FingertipDecodeErrc::bad_ramp:
      std::snprintf(buf, sizeof buf, "bad ramp level %lld permille in bytes 56-57: it runs from 0 to 1000", a);
      break;
    case FingertipDecodeErrc::bad_kind:
      std::snprintf(buf, sizeof buf,
                    "bad device kind %lld in byte 5: defined are 1 (band_2dof), 2 (platform_3dof), 3 (force_vector)", a);
      break;
    case FingertipDecodeErrc::bad_rate:
      std::snprintf(buf, sizeof buf, "bad rate %lld Hz in bytes 10-13: it must be 1 to %lld Hz (the feedback rate "
                    "at most the control rate)", a, e);
      break;
    case FingertipDecodeErrc::bad_encoder_resolution:
      std::snprintf(buf, sizeof buf, "bad encoder resolution %lld counts/rev in bytes 14-17: it must be at least 1", a);
      break;
    case FingertipDecodeErrc::bad_gear_ratio:
      std::snprintf(buf, sizeof buf, "bad gear ratio %lld/1000 in bytes 18-21: it must be positive", a);
      break;
    case FingertipDecodeErrc::bad_watchdog:
      std::snprintf(buf, sizeof buf,
                    "bad watchdog period %lld ms in bytes 22-23: every fingertip device must have one (at least 1 ms)",
                    a);
      break;
    case FingertipDecodeErrc::bad_angle_limits:
      std::snprintf(buf, sizeof buf,
                    "bad angle limits in bytes 34-41: the minimum %lld µrad is not below the maximum %lld µrad", e, a);
      break;
    case FingertipDecodeErrc::bad_serial:
      std::snprintf(buf, sizeof buf, "bad serial number: byte %lld of it is 0x%02llx, not printable ASCII", e, a);
      break;
    case FingertipDecodeErrc::bad_assignment:
      std::snprintf(buf, sizeof buf, "bad %s %lld in byte %s: defined are %s", e == 0 ? "hand" : "finger", a,
                    e == 0 ? "8" : "9", e == 0 ? "0 (unassigned), 1 (left), 2 (right)" : "0-4 (thumb to little), 255 (unassigned)");
      break;
    default:
      std::snprintf(buf, sizeof buf, "decode error %d", static_cast<int>(s.code));
      break;
  }
  return buf;
}

Error to_error(const FingertipDecodeStatus& status) {
  const Errc code = status.code == FingertipDecodeErrc::unsupported_version ? Errc::unsupported : Errc::parse_error;
  return make_error(code, "fingertip device HID protocol: " + describe(status));
}

bool fingertip_to_wire(double value_si, double units_per_si, std::int32_t& out) noexcept {
  const double v = std::nearbyint(value_si * units_per_si);
  if (!std::isfinite(v)) return false;
  // Compare before converting: a double beyond the integer range converted to one is undefined.
  constexpr double lo = std::numeric_limits<std::int32_t>::min();
  constexpr double hi = std::numeric_limits<std::int32_t>::max();
  out = v <= lo ? std::numeric_limits<std::int32_t>::min()
                : v >= hi ? std::numeric_limits<std::int32_t>::max() : static_cast<std::int32_t>(v);
  return true;
}

bool set_fingertip_command_values(FingertipCommand& c, std::span<const double> values_si) noexcept {
  const double scale = c.mode == FingertipMode::motor_angles ? kFingertipUradPerRad : kFingertipMnPerN;
  const std::size_t n = std::min({static_cast<std::size_t>(c.count), values_si.size(), c.values.size()});
  bool all_finite = true;
  for (std::size_t i = 0; i < n; ++i) all_finite = fingertip_to_wire(values_si[i], scale, c.values[i]) && all_finite;
  return all_finite;
}

// ---------------------------------------------------------------------------
// Command.

std::array<std::uint8_t, kFingertipReportSize> encode_fingertip_command(const FingertipCommand& c) noexcept {
  namespace L = fingertip_command_layout;
  std::array<std::uint8_t, kFingertipReportSize> b{};
  b[L::report_id] = static_cast<std::uint8_t>(FingertipReportId::command);
  b[L::version] = kFingertipProtocolVersion;
  put_u16(&b[L::sequence], c.sequence);
  b[L::mode] = static_cast<std::uint8_t>(c.mode);
  b[L::flags] = c.flags;
  b[L::count] = c.count;
  const std::size_t n = c.count < kFingertipMaxMotors ? c.count : kFingertipMaxMotors;
  for (std::size_t i = 0; i < n; ++i) put_u32(&b[L::values + 4 * i], static_cast<std::uint32_t>(c.values[i]));
  put_u64(&b[L::host_time_ns], static_cast<std::uint64_t>(c.host_time_ns));
  hid::seal_crc(b, L::crc);
  return b;
}

FingertipDecodeStatus decode_fingertip_command(std::span<const std::uint8_t> b, FingertipCommand& out) noexcept {
  namespace L = fingertip_command_layout;
  if (auto s = check_frame(b, FingertipReportId::command); !s) return s;
  const std::uint8_t mode = b[L::mode];
  if (mode != static_cast<std::uint8_t>(FingertipMode::motor_angles) &&
      mode != static_cast<std::uint8_t>(FingertipMode::force)) {
    return {FingertipDecodeErrc::bad_mode, 0, mode};
  }
  const std::uint8_t count = b[L::count];
  if (count == 0 || count > kFingertipMaxMotors) return {FingertipDecodeErrc::bad_value_count, 0, count};
  out.sequence = get_u16(b, L::sequence);
  out.mode = static_cast<FingertipMode>(mode);
  // Reserved flag bits from a newer minor mean nothing to this version.
  out.flags = static_cast<std::uint8_t>(b[L::flags] & fingertip_command_flags::defined);
  out.count = count;
  for (std::size_t i = 0; i < kFingertipMaxMotors; ++i) out.values[i] = i < count ? get_i32(b, L::values + 4 * i) : 0;
  out.host_time_ns = get_i64(b, L::host_time_ns);
  return {};
}

// ---------------------------------------------------------------------------
// Feedback.

std::array<std::uint8_t, kFingertipReportSize> encode_fingertip_feedback(const FingertipFeedback& f) noexcept {
  namespace L = fingertip_feedback_layout;
  std::array<std::uint8_t, kFingertipReportSize> b{};
  b[L::report_id] = static_cast<std::uint8_t>(FingertipReportId::feedback);
  b[L::version] = f.version;
  put_u16(&b[L::sequence], f.sequence);
  put_u16(&b[L::applied_sequence], f.applied_sequence);
  put_u32(&b[L::device_time_us], f.device_time_us);
  put_u16(&b[L::status], f.status);
  b[L::motor_count] = f.motor_count;
  b[L::fsr_count] = f.fsr_count;
  b[L::mode] = static_cast<std::uint8_t>(f.mode);
  b[L::command_result] = static_cast<std::uint8_t>(f.command_result);
  const std::size_t motors = f.motor_count < kFingertipMaxMotors ? f.motor_count : kFingertipMaxMotors;
  const std::size_t fsrs = f.fsr_count < kFingertipMaxMotors ? f.fsr_count : kFingertipMaxMotors;
  for (std::size_t i = 0; i < motors; ++i) {
    put_u32(&b[L::encoder_counts + 4 * i], static_cast<std::uint32_t>(f.encoder_counts[i]));
    put_u16(&b[L::current_ma + 2 * i], static_cast<std::uint16_t>(f.current_ma[i]));
  }
  for (std::size_t i = 0; i < fsrs; ++i) put_u32(&b[L::fsr_force_mn + 4 * i], static_cast<std::uint32_t>(f.fsr_force_mn[i]));
  put_u16(&b[L::rejected_commands], f.rejected_commands);
  put_u64(&b[L::applied_host_time_ns], static_cast<std::uint64_t>(f.applied_host_time_ns));
  put_u16(&b[L::ramp_permille], f.ramp_permille);
  hid::seal_crc(b, L::crc);
  return b;
}

FingertipDecodeStatus decode_fingertip_feedback(std::span<const std::uint8_t> b, FingertipFeedback& out) noexcept {
  namespace L = fingertip_feedback_layout;
  if (auto s = check_frame(b, FingertipReportId::feedback); !s) return s;
  const std::uint8_t motors = b[L::motor_count];
  if (motors == 0 || motors > kFingertipMaxMotors) return {FingertipDecodeErrc::bad_motor_count, 0, motors};
  const std::uint8_t fsrs = b[L::fsr_count];
  if (fsrs > kFingertipMaxMotors) return {FingertipDecodeErrc::bad_fsr_count, 0, fsrs};
  const std::uint8_t mode = b[L::mode];
  if (mode > static_cast<std::uint8_t>(FingertipMode::force)) return {FingertipDecodeErrc::bad_mode, 0, mode};
  const std::uint8_t result = b[L::command_result];
  if (result > kFingertipCommandResultMax) return {FingertipDecodeErrc::bad_command_result, 0, result};
  const std::uint16_t ramp = get_u16(b, L::ramp_permille);
  if (ramp > 1000) return {FingertipDecodeErrc::bad_ramp, 1000, ramp};
  out.version = b[L::version];
  out.sequence = get_u16(b, L::sequence);
  out.applied_sequence = get_u16(b, L::applied_sequence);
  out.device_time_us = get_u32(b, L::device_time_us);
  out.status = static_cast<std::uint16_t>(get_u16(b, L::status) & fingertip_status::defined);
  out.motor_count = motors;
  out.fsr_count = fsrs;
  out.mode = static_cast<FingertipMode>(mode);
  out.command_result = static_cast<FingertipCommandResult>(result);
  for (std::size_t i = 0; i < kFingertipMaxMotors; ++i) {
    // Slots past the counts carry nothing, whatever the bytes say.
    out.encoder_counts[i] = i < motors ? get_i32(b, L::encoder_counts + 4 * i) : 0;
    out.current_ma[i] = i < motors ? static_cast<std::int16_t>(get_u16(b, L::current_ma + 2 * i)) : std::int16_t{0};
    out.fsr_force_mn[i] = i < fsrs ? get_i32(b, L::fsr_force_mn + 4 * i) : 0;
  }
  out.rejected_commands = get_u16(b, L::rejected_commands);
  out.applied_host_time_ns = get_i64(b, L::applied_host_time_ns);
  out.ramp_permille = ramp;
  return {};
}

// ---------------------------------------------------------------------------
// Device info.

std::array<std::uint8_t, kFingertipReportSize> encode_fingertip_info(const FingertipDeviceInfo& info) noexcept {
  namespace L = fingertip_info_layout;
  std::array<std::uint8_t, kFingertipReportSize> b{};
  b[L::report_id] = static_cast<std::uint8_t>(FingertipReportId::device_info);
  b[L::version] = info.version;
  for (std::size_t i = 0; i < 3; ++i) b[L::firmware + i] = info.firmware[i];
  b[L::kind] = static_cast<std::uint8_t>(info.kind);
  b[L::motor_count] = info.motor_count;
  b[L::fsr_count] = info.fsr_count;
  b[L::hand] = info.hand ? static_cast<std::uint8_t>(static_cast<std::uint8_t>(*info.hand) + 1) : std::uint8_t{0};
  b[L::finger] = info.finger ? static_cast<std::uint8_t>(*info.finger) : kFingertipUnassignedFinger;
  put_u16(&b[L::control_rate_hz], info.control_rate_hz);
  put_u16(&b[L::feedback_rate_hz], info.feedback_rate_hz);
  put_u32(&b[L::counts_per_rev], info.encoder_counts_per_rev);
  put_u32(&b[L::gear_ratio_milli], info.gear_ratio_milli);
  put_u16(&b[L::watchdog_ms], info.watchdog_ms);
  put_u16(&b[L::ramp_ms], info.ramp_ms);
  put_u32(&b[L::max_normal_mn], info.max_normal_force_mn);
  put_u32(&b[L::max_shear_mn], info.max_shear_force_mn);
  put_u32(&b[L::min_angle_urad], static_cast<std::uint32_t>(info.min_angle_urad));
  put_u32(&b[L::max_angle_urad], static_cast<std::uint32_t>(info.max_angle_urad));
  put_u16(&b[L::max_current_ma], info.max_current_ma);
  const std::string_view serial = info.serial_view();
  for (std::size_t i = 0; i < serial.size(); ++i) b[L::serial + i] = static_cast<std::uint8_t>(serial[i]);
  hid::seal_crc(b, L::crc);
  return b;
}

FingertipDecodeStatus decode_fingertip_info(std::span<const std::uint8_t> b, FingertipDeviceInfo& out) noexcept {
  namespace L = fingertip_info_layout;
  if (auto s = check_frame(b, FingertipReportId::device_info); !s) return s;
  const std::uint8_t kind = b[L::kind];
  if (kind < static_cast<std::uint8_t>(FingertipDeviceKind::band_2dof) ||
      kind > static_cast<std::uint8_t>(FingertipDeviceKind::force_vector)) {
    return {FingertipDecodeErrc::bad_kind, 0, kind};
  }
  const std::uint8_t motors = b[L::motor_count];
  if (motors == 0 || motors > kFingertipMaxMotors) return {FingertipDecodeErrc::bad_motor_count, 0, motors};
  const std::uint8_t fsrs = b[L::fsr_count];
  if (fsrs > kFingertipMaxMotors) return {FingertipDecodeErrc::bad_fsr_count, 0, fsrs};
  const std::uint8_t hand = b[L::hand];
  if (hand > 2) return {FingertipDecodeErrc::bad_assignment, 0, hand};
  const std::uint8_t finger = b[L::finger];
  if (finger > static_cast<std::uint8_t>(Finger::little) && finger != kFingertipUnassignedFinger) {
    return {FingertipDecodeErrc::bad_assignment, 1, finger};
  }
  const std::uint16_t control = get_u16(b, L::control_rate_hz);
  if (control == 0 || control > kFingertipMaxControlRateHz) {
    return {FingertipDecodeErrc::bad_rate, kFingertipMaxControlRateHz, control};
  }
  const std::uint16_t feedback = get_u16(b, L::feedback_rate_hz);
  if (feedback == 0 || feedback > control) return {FingertipDecodeErrc::bad_rate, control, feedback};
  const std::uint32_t cpr = get_u32(b, L::counts_per_rev);
  if (cpr == 0) return {FingertipDecodeErrc::bad_encoder_resolution, 1, 0};
  const std::uint32_t gear = get_u32(b, L::gear_ratio_milli);
  if (gear == 0) return {FingertipDecodeErrc::bad_gear_ratio, 1, 0};
  const std::uint16_t watchdog = get_u16(b, L::watchdog_ms);
  if (watchdog == 0) return {FingertipDecodeErrc::bad_watchdog, 1, 0};
  const std::int32_t min_angle = get_i32(b, L::min_angle_urad);
  const std::int32_t max_angle = get_i32(b, L::max_angle_urad);
  if (min_angle >= max_angle) return {FingertipDecodeErrc::bad_angle_limits, min_angle, max_angle};
  std::array<char, kFingertipSerialLength + 1> serial{};
  for (std::size_t i = 0; i < kFingertipSerialLength; ++i) {
    const std::uint8_t c = b[L::serial + i];
    if (c == 0) break;  // NUL ends it; what follows is padding
    if (!printable(c)) return {FingertipDecodeErrc::bad_serial, static_cast<std::int64_t>(i), c};
    serial[i] = static_cast<char>(c);
  }
  out.version = b[L::version];
  for (std::size_t i = 0; i < 3; ++i) out.firmware[i] = b[L::firmware + i];
  out.kind = static_cast<FingertipDeviceKind>(kind);
  out.motor_count = motors;
  out.fsr_count = fsrs;
  out.hand = hand == 0 ? std::nullopt : std::optional<Handedness>(static_cast<Handedness>(hand - 1));
  out.finger = finger == kFingertipUnassignedFinger ? std::nullopt : std::optional<Finger>(static_cast<Finger>(finger));
  out.control_rate_hz = control;
  out.feedback_rate_hz = feedback;
  out.encoder_counts_per_rev = cpr;
  out.gear_ratio_milli = gear;
  out.watchdog_ms = watchdog;
  out.ramp_ms = get_u16(b, L::ramp_ms);
  out.max_normal_force_mn = get_u32(b, L::max_normal_mn);
  out.max_shear_force_mn = get_u32(b, L::max_shear_mn);
  out.min_angle_urad = min_angle;
  out.max_angle_urad = max_angle;
  out.max_current_ma = get_u16(b, L::max_current_ma);
  out.serial = serial;
  return {};
}

Result<FingertipCommand> decode_fingertip_command(std::span<const std::uint8_t> bytes) {
  FingertipCommand c;
  return hid::decode_result(decode_fingertip_command(bytes, c), c, report_name(FingertipReportId::command));
}
Result<FingertipFeedback> decode_fingertip_feedback(std::span<const std::uint8_t> bytes) {
  FingertipFeedback f;
  return hid::decode_result(decode_fingertip_feedback(bytes, f), f, report_name(FingertipReportId::feedback));
}
Result<FingertipDeviceInfo> decode_fingertip_info(std::span<const std::uint8_t> bytes) {
  FingertipDeviceInfo info;
  return hid::decode_result(decode_fingertip_info(bytes, info), info, report_name(FingertipReportId::device_info));
}

// ---------------------------------------------------------------------------
// Sequences.

const char* to_string(FingertipSequenceVerdict verdict) noexcept {
  switch (verdict) {
    case FingertipSequenceVerdict::first: return "first";
    case FingertipSequenceVerdict::in_order: return "in_order";
    case FingertipSequenceVerdict::gap: return "gap";
    case FingertipSequenceVerdict::stale: return "stale";
    case FingertipSequenceVerdict::restart: return "restart";
    case FingertipSequenceVerdict::resync: return "resync";
  }
  return "unknown";
}

FingertipSequenceResult FingertipSequenceTracker::observe(std::uint16_t sequence, bool restart) noexcept {
  FingertipSequenceResult r;
  if (!have_ || restart) {
    r.verdict = have_ ? FingertipSequenceVerdict::restart : FingertipSequenceVerdict::first;
    have_ = true;
    newest_ = sequence;
    stale_run_ = 0;
    return r;
  }
  const std::uint16_t ahead = static_cast<std::uint16_t>(sequence - newest_);
  if (ahead == 0 || ahead >= 0x8000) {
    if (++stale_run_ < kFingertipResyncAfterStale) {
      r.verdict = FingertipSequenceVerdict::stale;
      return r;
    }
    r.verdict = FingertipSequenceVerdict::resync;
    newest_ = sequence;
    stale_run_ = 0;
    return r;
  }
  stale_run_ = 0;
  newest_ = sequence;
  if (ahead == 1) {
    r.verdict = FingertipSequenceVerdict::in_order;
  } else {
    r.verdict = FingertipSequenceVerdict::gap;
    r.lost = ahead - 1u;
  }
  return r;
}

FingertipStreamResult FingertipFeedbackStream::push(std::span<const std::uint8_t> bytes,
                                                    FingertipFeedback& out) noexcept {
  FingertipStreamResult r;
  FingertipFeedback f;
  r.decode = decode_fingertip_feedback(bytes, f);
  count_decode(counters_, r.decode);
  if (!r.decode) return r;
  r.sequence = tracker_.observe(f.sequence, f.has(fingertip_status::device_start));
  count_sequence(counters_, r.sequence);
  if (r.sequence.accepted()) out = f;
  return r;
}

FingertipStreamResult FingertipCommandStream::push(std::span<const std::uint8_t> bytes,
                                                   FingertipCommand& out) noexcept {
  FingertipStreamResult r;
  FingertipCommand c;
  r.decode = decode_fingertip_command(bytes, c);
  count_decode(counters_, r.decode);
  if (!r.decode) return r;
  r.sequence = tracker_.observe(c.sequence, (c.flags & fingertip_command_flags::sequence_reset) != 0);
  count_sequence(counters_, r.sequence);
  if (r.sequence.accepted()) out = c;
  return r;
}

}  // namespace proprio::devices
