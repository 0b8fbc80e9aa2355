#include "proprio/ftm_board/ftm_protocol.hpp"

#include <cmath>
#include <cstdio>

#include "proprio/hid/report_codec.hpp"

namespace proprio::devices {

namespace {

namespace info_layout {
constexpr std::size_t version = 1;
constexpr std::size_t firmware = 2;  // 3 bytes
constexpr std::size_t state = 5;
constexpr std::size_t imu_rate_hz = 6;   // u16
constexpr std::size_t bend_rate_hz = 8;  // u16
constexpr std::size_t mag_rate_hz = 10;
constexpr std::size_t ranges = 11;
constexpr std::size_t imus_present = 12;
constexpr std::size_t bends_present = 13;
constexpr std::size_t last_token = 14;
constexpr std::size_t last_result = 15;
constexpr std::size_t timestamp_us = 16;  // u32
constexpr std::size_t crc = 30;
}  // namespace info_layout
namespace command_layout {
constexpr std::size_t version = 1;
constexpr std::size_t opcode = 2;
constexpr std::size_t token = 3;
constexpr std::size_t imu_rate_hz = 4;   // u16
constexpr std::size_t bend_rate_hz = 6;  // u16
constexpr std::size_t ranges = 8;
constexpr std::size_t crc = 14;
}  // namespace command_layout

constexpr double kPi = 3.14159265358979323846;

using hid::get_i16;
using hid::get_u16;
using hid::get_u32;
using hid::put_u16;
using hid::put_u32;

std::uint8_t pack_ranges(FtmAccelRange a, FtmGyroRange g) noexcept {
  return static_cast<std::uint8_t>((static_cast<std::uint8_t>(a) & 0x3) | (static_cast<std::uint8_t>(g) & 0x3) << 4);
}
FtmAccelRange accel_of(std::uint8_t ranges) noexcept { return static_cast<FtmAccelRange>(ranges & 0x3); }
FtmGyroRange gyro_of(std::uint8_t ranges) noexcept { return static_cast<FtmGyroRange>(ranges >> 4 & 0x3); }

FtmDecodeStatus check_frame(std::span<const std::uint8_t> bytes, FtmReportId id, std::size_t size,
                            std::size_t version_at, std::size_t crc_at) noexcept {
  return hid::to_decode_status<FtmDecodeStatus>(
      hid::check_frame(bytes, static_cast<std::uint8_t>(id), size, version_at, crc_at, kFtmProtocolMajor));
}

const char* report_name(FtmReportId id) noexcept {
  switch (id) {
    case FtmReportId::imu: return "FTM board IMU report (ID 0x51)";
    case FtmReportId::bend: return "FTM board bend-sensor report (ID 0x52)";
    case FtmReportId::device_info: return "FTM board device info report (ID 0x53)";
    case FtmReportId::command: return "FTM board command report (ID 0x58)";
  }
  return "FTM board report";
}

const char* guess_report(std::uint32_t id) noexcept {
  switch (id) {
    case 0x01:
    case 0x02:
    case 0x10: return " (an IMU glove report ID: wrong device or capture file?)";
    case 0x21:
    case 0x22:
    case 0x30: return " (a stretch board report ID: wrong device or capture file?)";
    case 0x41:
    case 0x42:
    case 0x43: return " (a fingertip device report ID: wrong device or capture file?)";
    case 0x51: return " (the FTM board's IMU report)";
    case 0x52: return " (the FTM board's bend-sensor report)";
    case 0x53: return " (the FTM board's device info report)";
    case 0x58: return " (the FTM board's command report)";
    default: return "";
  }
}

// Rounds and clamps one axis to int16; true when it sits at a rail.
std::int16_t to_count(double v, double per_count, bool& at_rail) noexcept {
  const double c = std::nearbyint(v / per_count);
  if (c >= 32767.0) {
    at_rail = true;
    return 32767;
  }
  if (c <= -32768.0) {
    at_rail = true;
    return -32768;
  }
  return static_cast<std::int16_t>(c);
}

bool at_rail(const std::array<std::int16_t, 3>& v) noexcept {
  for (const std::int16_t c : v) {
    if (c == 32767 || c == -32768) return true;
  }
  return false;
}

bool all_finite(const Vec3& v) noexcept { return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z()); }

}  // namespace

double accel_mps2_per_count(FtmAccelRange range) noexcept {
  const double lsb_per_g = 16384.0 / static_cast<double>(1u << (static_cast<unsigned>(range) & 0x3));
  return kFtmStandardGravity / lsb_per_g;
}

double gyro_radps_per_count(FtmGyroRange range) noexcept {
  // The datasheet's sensitivities (rounded there, and the firmware's LSB is what it is).
  constexpr double kLsbPerDps[4] = {131.0, 65.5, 32.8, 16.4};
  return (kPi / 180.0) / kLsbPerDps[static_cast<unsigned>(range) & 0x3];
}

const char* to_string(FtmDecodeErrc code) noexcept {
  switch (code) {
    case FtmDecodeErrc::ok: return "ok";
    case FtmDecodeErrc::empty: return "empty";
    case FtmDecodeErrc::bad_length: return "bad_length";
    case FtmDecodeErrc::unknown_report_id: return "unknown_report_id";
    case FtmDecodeErrc::unsupported_version: return "unsupported_version";
    case FtmDecodeErrc::crc_mismatch: return "crc_mismatch";
    case FtmDecodeErrc::bad_count: return "bad_count";
    case FtmDecodeErrc::bad_first_imu: return "bad_first_imu";
    case FtmDecodeErrc::bad_period: return "bad_period";
    case FtmDecodeErrc::unknown_command: return "unknown_command";
  }
  return "unknown";
}

std::string describe(const FtmDecodeStatus& s) {
  char buf[360];
  switch (s.code) {
    case FtmDecodeErrc::ok: return "ok";
    case FtmDecodeErrc::empty:
    case FtmDecodeErrc::bad_length:
    case FtmDecodeErrc::unknown_report_id:
    case FtmDecodeErrc::unsupported_version:
    case FtmDecodeErrc::crc_mismatch:
      return hid::describe_frame_fault({hid::frame_fault_of(s.code), s.expected, s.actual}, "FTM board protocol",
                                       guess_report(s.actual));
    case FtmDecodeErrc::bad_count:
      std::snprintf(buf, sizeof buf, "bad sample count %u: a bend-sensor report carries 1 to %zu samples", s.actual,
                    kFtmBendSamplesPerReport);
      break;
    case FtmDecodeErrc::bad_first_imu:
      std::snprintf(buf, sizeof buf, "bad first IMU %u: an IMU report carries IMUs 0-1 or 2-3 (first 0 or 2)",
                    s.actual);
      break;
    case FtmDecodeErrc::bad_period:
      std::snprintf(buf, sizeof buf,
                    "bad period or rate %u: periods are at least 1 us, the IMU rate is %u-%u Hz and the bend rate "
                    "%u-%u Hz",
                    s.actual, kFtmMinImuRateHz, kFtmMaxImuRateHz, kFtmMinBendRateHz, kFtmMaxBendRateHz);
      break;
    case FtmDecodeErrc::unknown_command:
      std::snprintf(buf, sizeof buf, "unknown command opcode 0x%02x", s.actual);
      break;
    default:
      std::snprintf(buf, sizeof buf, "decode error %u", static_cast<unsigned>(s.code));
      break;
  }
  return buf;
}

Error to_error(const FtmDecodeStatus& s) {
  const Errc code = s.code == FtmDecodeErrc::unsupported_version ? Errc::unsupported : Errc::parse_error;
  return make_error(code, "FTM board HID protocol: " + describe(s));
}

std::size_t ftm_report_size_for_id(std::uint8_t id) noexcept {
  switch (static_cast<FtmReportId>(id)) {
    case FtmReportId::imu:
    case FtmReportId::bend: return kFtmDataReportSize;
    case FtmReportId::device_info: return kFtmInfoReportSize;
    case FtmReportId::command: return kFtmCommandReportSize;
  }
  return 0;
}

// ---------------------------------------------------------------------------
// IMU report

std::array<std::uint8_t, kFtmDataReportSize> encode_ftm_imu_report(const FtmImuReport& r) noexcept {
  namespace L = ftm_imu_layout;
  std::array<std::uint8_t, kFtmDataReportSize> b{};
  b[L::report_id] = static_cast<std::uint8_t>(FtmReportId::imu);
  b[L::version] = r.version;
  put_u32(&b[L::sequence], r.sequence);
  put_u32(&b[L::timestamp_us], r.timestamp_us);
  b[L::flags] = r.flags;
  b[L::first_imu] = r.first_imu;
  b[L::ranges] = pack_ranges(r.accel_range, r.gyro_range);
  put_u16(&b[L::period_us], r.period_us);
  for (std::size_t i = 0; i < kFtmImusPerReport; ++i) {
    std::uint8_t* p = &b[L::imus + i * L::imu_size];
    const FtmImuRaw& m = r.imus[i];
    p[0] = m.status;
    for (std::size_t a = 0; a < 3; ++a) {
      put_u16(p + 1 + 2 * a, static_cast<std::uint16_t>(m.accel[a]));
      put_u16(p + 7 + 2 * a, static_cast<std::uint16_t>(m.gyro[a]));
      put_u16(p + 13 + 2 * a, static_cast<std::uint16_t>(m.mag[a]));
    }
  }
  hid::seal_crc(b, L::crc);
  return b;
}

FtmDecodeStatus decode_ftm_imu_report(std::span<const std::uint8_t> b, FtmImuReport& out) noexcept {
  namespace L = ftm_imu_layout;
  if (auto s = check_frame(b, FtmReportId::imu, kFtmDataReportSize, L::version, L::crc); !s) return s;
  const std::uint8_t first = b[L::first_imu];
  if (first != 0 && first != 2) return {FtmDecodeErrc::bad_first_imu, 0, first};
  const std::uint16_t period = get_u16(b, L::period_us);
  if (period == 0) return {FtmDecodeErrc::bad_period, 1, 0};
  out.version = b[L::version];
  out.sequence = get_u32(b, L::sequence);
  out.timestamp_us = get_u32(b, L::timestamp_us);
  out.flags = b[L::flags];
  out.first_imu = first;
  out.accel_range = accel_of(b[L::ranges]);
  out.gyro_range = gyro_of(b[L::ranges]);
  out.period_us = period;
  for (std::size_t i = 0; i < kFtmImusPerReport; ++i) {
    const std::size_t at = L::imus + i * L::imu_size;
    FtmImuRaw& m = out.imus[i];
    m.status = b[at] & ftm_wire_status::imu_mask;
    for (std::size_t a = 0; a < 3; ++a) {
      m.accel[a] = get_i16(b, at + 1 + 2 * a);
      m.gyro[a] = get_i16(b, at + 7 + 2 * a);
      m.mag[a] = get_i16(b, at + 13 + 2 * a);
    }
  }
  return {};
}

// ---------------------------------------------------------------------------
// Bend report

std::array<std::uint8_t, kFtmDataReportSize> encode_ftm_bend_report(const FtmBendReport& r) noexcept {
  namespace L = ftm_bend_layout;
  std::array<std::uint8_t, kFtmDataReportSize> b{};
  b[L::report_id] = static_cast<std::uint8_t>(FtmReportId::bend);
  b[L::version] = r.version;
  put_u32(&b[L::sequence], r.sequence);
  put_u32(&b[L::timestamp_us], r.timestamp_us);
  b[L::flags] = r.flags;
  b[L::count] = r.count;
  put_u16(&b[L::period_us], r.period_us);
  for (std::size_t i = 0; i < kFtmBendSamplesPerReport; ++i) {
    for (std::size_t k = 0; k < ftm::kFtmBendCount; ++k) {
      std::uint8_t* p = &b[L::samples + (i * ftm::kFtmBendCount + k) * L::sensor_size];
      put_u16(p, r.samples[i][k].value);
      p[2] = r.samples[i][k].status;
    }
  }
  hid::seal_crc(b, L::crc);
  return b;
}

FtmDecodeStatus decode_ftm_bend_report(std::span<const std::uint8_t> b, FtmBendReport& out) noexcept {
  namespace L = ftm_bend_layout;
  if (auto s = check_frame(b, FtmReportId::bend, kFtmDataReportSize, L::version, L::crc); !s) return s;
  const std::uint8_t count = b[L::count];
  if (count == 0 || count > kFtmBendSamplesPerReport) return {FtmDecodeErrc::bad_count, 0, count};
  const std::uint16_t period = get_u16(b, L::period_us);
  if (period == 0) return {FtmDecodeErrc::bad_period, 1, 0};
  out.version = b[L::version];
  out.sequence = get_u32(b, L::sequence);
  out.timestamp_us = get_u32(b, L::timestamp_us);
  out.flags = b[L::flags];
  out.count = count;
  out.period_us = period;
  out.samples = {};
  for (std::size_t i = 0; i < count; ++i) {
    for (std::size_t k = 0; k < ftm::kFtmBendCount; ++k) {
      const std::size_t at = L::samples + (i * ftm::kFtmBendCount + k) * L::sensor_size;
      out.samples[i][k].value = get_u16(b, at);
      out.samples[i][k].status = b[at + 2] & ftm_wire_status::bend_mask;
    }
  }
  return {};
}

// ---------------------------------------------------------------------------
// Info and command reports

std::array<std::uint8_t, kFtmInfoReportSize> encode_ftm_info_report(const FtmDeviceInfo& info) noexcept {
  namespace L = info_layout;
  std::array<std::uint8_t, kFtmInfoReportSize> b{};
  b[0] = static_cast<std::uint8_t>(FtmReportId::device_info);
  b[L::version] = info.version;
  for (std::size_t i = 0; i < 3; ++i) b[L::firmware + i] = info.firmware[i];
  b[L::state] = info.streaming ? 1 : 0;
  put_u16(&b[L::imu_rate_hz], info.imu_rate_hz);
  put_u16(&b[L::bend_rate_hz], info.bend_rate_hz);
  b[L::mag_rate_hz] = info.mag_rate_hz;
  b[L::ranges] = pack_ranges(info.accel_range, info.gyro_range);
  b[L::imus_present] = info.imus_present & 0x0F;
  b[L::bends_present] = info.bends_present & 0x07;
  b[L::last_token] = info.last_command_token;
  b[L::last_result] = static_cast<std::uint8_t>(info.last_command_result);
  put_u32(&b[L::timestamp_us], info.timestamp_us);
  hid::seal_crc(b, L::crc);
  return b;
}

FtmDecodeStatus decode_ftm_info_report(std::span<const std::uint8_t> b, FtmDeviceInfo& out) noexcept {
  namespace L = info_layout;
  if (auto s = check_frame(b, FtmReportId::device_info, kFtmInfoReportSize, L::version, L::crc); !s) return s;
  const std::uint16_t imu_rate = get_u16(b, L::imu_rate_hz);
  const std::uint16_t bend_rate = get_u16(b, L::bend_rate_hz);
  if (imu_rate < kFtmMinImuRateHz || imu_rate > kFtmMaxImuRateHz) return {FtmDecodeErrc::bad_period, 0, imu_rate};
  if (bend_rate < kFtmMinBendRateHz || bend_rate > kFtmMaxBendRateHz) {
    return {FtmDecodeErrc::bad_period, 0, bend_rate};
  }
  out.version = b[L::version];
  for (std::size_t i = 0; i < 3; ++i) out.firmware[i] = b[L::firmware + i];
  out.streaming = (b[L::state] & 1) != 0;
  out.imu_rate_hz = imu_rate;
  out.bend_rate_hz = bend_rate;
  out.mag_rate_hz = b[L::mag_rate_hz];
  out.accel_range = accel_of(b[L::ranges]);
  out.gyro_range = gyro_of(b[L::ranges]);
  out.imus_present = b[L::imus_present] & 0x0F;
  out.bends_present = b[L::bends_present] & 0x07;
  out.last_command_token = b[L::last_token];
  out.last_command_result = static_cast<FtmCommandResult>(b[L::last_result]);
  out.timestamp_us = get_u32(b, L::timestamp_us);
  return {};
}

std::array<std::uint8_t, kFtmCommandReportSize> encode_ftm_command(const FtmCommand& c) noexcept {
  namespace L = command_layout;
  std::array<std::uint8_t, kFtmCommandReportSize> b{};
  b[0] = static_cast<std::uint8_t>(FtmReportId::command);
  b[L::version] = kFtmProtocolVersion;
  b[L::opcode] = static_cast<std::uint8_t>(c.op);
  b[L::token] = c.token;
  put_u16(&b[L::imu_rate_hz], c.imu_rate_hz);
  put_u16(&b[L::bend_rate_hz], c.bend_rate_hz);
  b[L::ranges] = pack_ranges(c.accel_range, c.gyro_range);
  hid::seal_crc(b, L::crc);
  return b;
}

FtmDecodeStatus decode_ftm_command(std::span<const std::uint8_t> b, FtmCommand& out) noexcept {
  namespace L = command_layout;
  if (auto s = check_frame(b, FtmReportId::command, kFtmCommandReportSize, L::version, L::crc); !s) return s;
  const std::uint8_t op = b[L::opcode];
  if (op < static_cast<std::uint8_t>(FtmCommandOp::start_streaming) ||
      op > static_cast<std::uint8_t>(FtmCommandOp::set_ranges)) {
    return {FtmDecodeErrc::unknown_command, 0, op};
  }
  out.op = static_cast<FtmCommandOp>(op);
  out.token = b[L::token];
  out.imu_rate_hz = get_u16(b, L::imu_rate_hz);
  out.bend_rate_hz = get_u16(b, L::bend_rate_hz);
  out.accel_range = accel_of(b[L::ranges]);
  out.gyro_range = gyro_of(b[L::ranges]);
  return {};
}

Result<FtmImuReport> decode_ftm_imu_report(std::span<const std::uint8_t> bytes) {
  FtmImuReport r;
  return hid::decode_result(decode_ftm_imu_report(bytes, r), r, report_name(FtmReportId::imu));
}
Result<FtmBendReport> decode_ftm_bend_report(std::span<const std::uint8_t> bytes) {
  FtmBendReport r;
  return hid::decode_result(decode_ftm_bend_report(bytes, r), r, report_name(FtmReportId::bend));
}
Result<FtmDeviceInfo> decode_ftm_info_report(std::span<const std::uint8_t> bytes) {
  FtmDeviceInfo info;
  return hid::decode_result(decode_ftm_info_report(bytes, info), info, report_name(FtmReportId::device_info));
}
Result<FtmCommand> decode_ftm_command(std::span<const std::uint8_t> bytes) {
  FtmCommand c;
  return hid::decode_result(decode_ftm_command(bytes, c), c, report_name(FtmReportId::command));
}

// ---------------------------------------------------------------------------
// Units

FtmImuRaw quantise_imu(const ftm::FtmImuSample& s, FtmAccelRange accel_range, FtmGyroRange gyro_range) noexcept {
  namespace st = ftm::sample_status;
  FtmImuRaw m;
  m.status = s.status & (st::stale | st::sensor_error);
  // A failed bus read gives zeros, never a half-converted value.
  if ((s.status & st::sensor_error) || !all_finite(s.accel_mps2) || !all_finite(s.gyro_radps) ||
      !all_finite(s.mag_uT)) {
    m.status = static_cast<std::uint8_t>(m.status | st::sensor_error);
    return m;
  }
  const double a_lsb = accel_mps2_per_count(accel_range);
  const double g_lsb = gyro_radps_per_count(gyro_range);
  bool accel_rail = false, gyro_rail = false;
  for (int a = 0; a < 3; ++a) {
    m.accel[static_cast<std::size_t>(a)] = to_count(s.accel_mps2[a], a_lsb, accel_rail);
    m.gyro[static_cast<std::size_t>(a)] = to_count(s.gyro_radps[a], g_lsb, gyro_rail);
  }
  if (accel_rail) m.status |= st::accel_saturated;
  if (gyro_rail) m.status |= st::gyro_saturated;
  // The AK8963's die axes: x along the accelerometer's y, y along its x, z opposite (MPU-9250 datasheet, §9.1).
  const double die[3] = {s.mag_uT.y(), s.mag_uT.x(), -s.mag_uT.z()};
  bool overflow = (s.status & st::mag_overflow) != 0;
  for (std::size_t a = 0; a < 3; ++a) {
    double c = std::nearbyint(die[a] / kFtmMagUtPerCount);
    if (c > kFtmMagMaxCount || c < -kFtmMagMaxCount) {
      overflow = true;
      c = c > 0 ? kFtmMagMaxCount : -kFtmMagMaxCount;
    }
    m.mag[a] = static_cast<std::int16_t>(c);
  }
  if (overflow) m.status |= st::mag_overflow;
  if (s.mag_fresh) m.status |= ftm_wire_status::mag_fresh;
  return m;
}

ftm::FtmImuSample imu_sample_from_wire(const FtmImuRaw& raw, FtmAccelRange accel_range,
                                       FtmGyroRange gyro_range) noexcept {
  namespace st = ftm::sample_status;
  ftm::FtmImuSample s;
  s.status = raw.status & static_cast<std::uint8_t>(ftm_wire_status::imu_mask & ~ftm_wire_status::mag_fresh);
  s.mag_fresh = (raw.status & ftm_wire_status::mag_fresh) != 0;
  if (at_rail(raw.accel)) s.status |= st::accel_saturated;
  if (at_rail(raw.gyro)) s.status |= st::gyro_saturated;
  for (const std::int16_t c : raw.mag) {
    if (c > kFtmMagMaxCount || c < -kFtmMagMaxCount) s.status |= st::mag_overflow;
  }
  const double a_lsb = accel_mps2_per_count(accel_range);
  const double g_lsb = gyro_radps_per_count(gyro_range);
  s.accel_mps2 = Vec3(raw.accel[0] * a_lsb, raw.accel[1] * a_lsb, raw.accel[2] * a_lsb);
  s.gyro_radps = Vec3(raw.gyro[0] * g_lsb, raw.gyro[1] * g_lsb, raw.gyro[2] * g_lsb);
  s.mag_uT = Vec3(raw.mag[1] * kFtmMagUtPerCount, raw.mag[0] * kFtmMagUtPerCount, -raw.mag[2] * kFtmMagUtPerCount);
  return s;
}

FtmBendRaw quantise_bend(double pf, std::uint8_t status) noexcept {
  namespace st = ftm::sample_status;
  FtmBendRaw m;
  m.status = status & (st::stale | st::sensor_error);
  if ((status & st::sensor_error) || !std::isfinite(pf)) {
    m.status |= st::sensor_error;
    return m;
  }
  // Compare before converting: a double beyond the integer range converted to one is undefined.
  const double c = std::nearbyint(pf / kFtmBendPfPerCount);
  if (c >= static_cast<double>(kFtmBendRailCount)) {
    m.value = kFtmBendRailCount;
    m.status |= ftm_wire_status::over_range;
  } else if (c < 0.0) {
    m.status |= st::sensor_error;  // below the converter's offset: a broken lead
  } else {
    m.value = static_cast<std::uint16_t>(c);
  }
  return m;
}

ftm::FtmBendSample bend_sample_from_wire(const FtmBendRaw& raw) noexcept {
  namespace st = ftm::sample_status;
  ftm::FtmBendSample s;
  s.capacitance_pF = raw.value * kFtmBendPfPerCount;
  s.status = raw.status & (st::stale | st::sensor_error);
  if ((raw.status & ftm_wire_status::over_range) || raw.value == kFtmBendRailCount) s.status |= st::sensor_error;
  return s;
}

}  // namespace proprio::devices
