#include "proprio/imu_glove_board/imu_glove_protocol.hpp"

#include <cmath>
#include <cstdio>
#include <limits>

#include "proprio/hid/report_codec.hpp"

namespace proprio::devices {

namespace {

constexpr double kStandardGravity = 9.80665;  // the datasheet's g
constexpr double kRadPerDeg = 0.017453292519943295;

// Datasheet sensitivities, indexed by the range code.
constexpr double kAccelCountsPerG[4] = {16384.0, 8192.0, 4096.0, 2048.0};
constexpr double kGyroCountsPerDps[4] = {131.0, 65.5, 32.8, 16.4};
constexpr double kAccelFullScaleG[4] = {2.0, 4.0, 8.0, 16.0};
constexpr double kGyroFullScaleDps[4] = {250.0, 500.0, 1000.0, 2000.0};

// Byte offsets of the info and command reports (docs/glove-hid-protocol.md, tables 2 and 3).
namespace info_layout {
constexpr std::size_t version = 1;
constexpr std::size_t firmware = 2;  // 3 bytes
constexpr std::size_t imu_count = 5;
constexpr std::size_t rate_hz = 6;  // u16
constexpr std::size_t ranges = 8;
constexpr std::size_t state = 9;
constexpr std::size_t last_token = 10;
constexpr std::size_t last_result = 11;
constexpr std::size_t timestamp_us = 12;  // u32
constexpr std::size_t crc = 30;
}  // namespace info_layout
namespace command_layout {
constexpr std::size_t version = 1;
constexpr std::size_t opcode = 2;
constexpr std::size_t token = 3;
constexpr std::size_t rate_hz = 4;  // u16
constexpr std::size_t ranges = 6;
constexpr std::size_t crc = 14;
}  // namespace command_layout

using hid::get_i16;
using hid::get_u16;
using hid::get_u32;
using hid::put_i16;
using hid::put_u16;
using hid::put_u32;

AccelRange accel_range_of(std::uint8_t ranges) noexcept { return static_cast<AccelRange>(ranges & 0x3); }
GyroRange gyro_range_of(std::uint8_t ranges) noexcept { return static_cast<GyroRange>((ranges >> 2) & 0x3); }

// Length, ID, version and CRC: the checks every report type shares.
ImuGloveDecodeStatus check_frame(std::span<const std::uint8_t> bytes, ImuGloveReportId id, std::size_t size,
                              std::size_t version_at, std::size_t crc_at) noexcept {
  return hid::to_decode_status<ImuGloveDecodeStatus>(
      hid::check_frame(bytes, static_cast<std::uint8_t>(id), size, version_at, crc_at, kImuGloveProtocolMajor));
}

const char* report_name(std::uint8_t id) noexcept {
  switch (static_cast<ImuGloveReportId>(id)) {
    case ImuGloveReportId::imu_data: return "IMU data report (ID 0x01)";
    case ImuGloveReportId::device_info: return "device info report (ID 0x02)";
    case ImuGloveReportId::command: return "command report (ID 0x10)";
  }
  return "report";
}

}  // namespace

double accel_counts_per_mps2(AccelRange range) noexcept {
  return kAccelCountsPerG[static_cast<int>(range) & 3] / kStandardGravity;
}
double gyro_counts_per_radps(GyroRange range) noexcept {
  return kGyroCountsPerDps[static_cast<int>(range) & 3] / kRadPerDeg;
}
double accel_full_scale_mps2(AccelRange range) noexcept {
  return kAccelFullScaleG[static_cast<int>(range) & 3] * kStandardGravity;
}
double gyro_full_scale_radps(GyroRange range) noexcept {
  return kGyroFullScaleDps[static_cast<int>(range) & 3] * kRadPerDeg;
}
const char* to_string(AccelRange range) noexcept {
  static const char* const names[4] = {"±2 g", "±4 g", "±8 g", "±16 g"};
  return names[static_cast<int>(range) & 3];
}
const char* to_string(GyroRange range) noexcept {
  static const char* const names[4] = {"±250 °/s", "±500 °/s", "±1000 °/s", "±2000 °/s"};
  return names[static_cast<int>(range) & 3];
}
std::uint8_t encode_ranges(AccelRange accel, GyroRange gyro) noexcept {
  return static_cast<std::uint8_t>((static_cast<unsigned>(accel) & 3) | (static_cast<unsigned>(gyro) & 3) << 2);
}

std::size_t ImuGloveDataReport::block_count() const noexcept {
  if (first_imu >= imu_total) return 0;
  const std::size_t left = static_cast<std::size_t>(imu_total - first_imu);
  return left < kImuGloveImusPerReport ? left : kImuGloveImusPerReport;
}

const char* to_string(ImuGloveDecodeErrc code) noexcept {
  switch (code) {
    case ImuGloveDecodeErrc::ok: return "ok";
    case ImuGloveDecodeErrc::empty: return "empty";
    case ImuGloveDecodeErrc::bad_length: return "bad_length";
    case ImuGloveDecodeErrc::unknown_report_id: return "unknown_report_id";
    case ImuGloveDecodeErrc::unsupported_version: return "unsupported_version";
    case ImuGloveDecodeErrc::crc_mismatch: return "crc_mismatch";
    case ImuGloveDecodeErrc::bad_imu_count: return "bad_imu_count";
    case ImuGloveDecodeErrc::bad_first_imu: return "bad_first_imu";
    case ImuGloveDecodeErrc::bad_rate: return "bad_rate";
    case ImuGloveDecodeErrc::unknown_command: return "unknown_command";
  }
  return "unknown";
}

std::string describe(const ImuGloveDecodeStatus& s) {
  char buf[320];
  switch (s.code) {
    case ImuGloveDecodeErrc::ok: return "ok";
    case ImuGloveDecodeErrc::empty:
    case ImuGloveDecodeErrc::bad_length:
    case ImuGloveDecodeErrc::unknown_report_id:
    case ImuGloveDecodeErrc::unsupported_version:
    case ImuGloveDecodeErrc::crc_mismatch:
      return hid::describe_frame_fault({hid::frame_fault_of(s.code), s.expected, s.actual}, "protocol", "");
    case ImuGloveDecodeErrc::bad_imu_count:
      std::snprintf(buf, sizeof buf, "bad IMU count %u: a glove streams 1 to %zu IMUs", s.actual, kImuGloveMaxImus);
      break;
    case ImuGloveDecodeErrc::bad_first_imu:
      std::snprintf(buf, sizeof buf,
                    "bad first IMU %u: it must be a multiple of %zu below the IMU count %u", s.actual,
                    kImuGloveImusPerReport, s.expected);
      break;
    case ImuGloveDecodeErrc::bad_rate:
      std::snprintf(buf, sizeof buf, "bad rate %u Hz: a glove streams at 1 to %u Hz", s.actual, kImuGloveMaxRateHz);
      break;
    case ImuGloveDecodeErrc::unknown_command:
      std::snprintf(buf, sizeof buf, "unknown command opcode 0x%02x", s.actual);
      break;
    default:
      std::snprintf(buf, sizeof buf, "decode error %d", static_cast<int>(s.code));
      break;
  }
  return buf;
}

Error to_error(const ImuGloveDecodeStatus& status) {
  const Errc code = status.code == ImuGloveDecodeErrc::unsupported_version ? Errc::unsupported : Errc::parse_error;
  return make_error(code, "glove HID protocol: " + describe(status));
}

std::uint8_t report_id_of(std::span<const std::uint8_t> report) noexcept { return report.empty() ? 0 : report[0]; }

std::size_t report_size_for_id(std::uint8_t report_id) noexcept {
  switch (static_cast<ImuGloveReportId>(report_id)) {
    case ImuGloveReportId::imu_data: return kImuGloveDataReportSize;
    case ImuGloveReportId::device_info: return kImuGloveInfoReportSize;
    case ImuGloveReportId::command: return kImuGloveCommandReportSize;
  }
  return 0;
}

std::array<std::uint8_t, kImuGloveDataReportSize> encode_data_report(const ImuGloveDataReport& r) noexcept {
  namespace L = data_layout;
  std::array<std::uint8_t, kImuGloveDataReportSize> b{};
  b[L::report_id] = static_cast<std::uint8_t>(ImuGloveReportId::imu_data);
  b[L::version] = r.version;
  b[L::first_imu] = r.first_imu;
  b[L::imu_total] = r.imu_total;
  put_u16(&b[L::sequence], r.sequence);
  put_u32(&b[L::timestamp_us], r.timestamp_us);
  b[L::flags] = r.flags;
  b[L::ranges] = encode_ranges(r.accel_range, r.gyro_range);
  std::uint16_t status = 0;
  for (std::size_t i = 0; i < kImuGloveImusPerReport; ++i) {
    const ImuGloveImuRaw& imu = r.imus[i];
    status = static_cast<std::uint16_t>(status | (imu.status & imu_status::mask) << (4 * i));
    std::uint8_t* p = &b[L::imu_blocks + i * L::imu_block_size];
    for (std::size_t a = 0; a < 3; ++a) {
      put_i16(p + 2 * a, imu.accel[a]);
      put_i16(p + 6 + 2 * a, imu.gyro[a]);
    }
  }
  put_u16(&b[L::imu_status], status);
  hid::seal_crc(b, L::crc);
  return b;
}

ImuGloveDecodeStatus decode_data_report(std::span<const std::uint8_t> b, ImuGloveDataReport& out) noexcept {
  namespace L = data_layout;
  if (auto s = check_frame(b, ImuGloveReportId::imu_data, kImuGloveDataReportSize, L::version, L::crc); !s) return s;
  const std::uint8_t total = b[L::imu_total];
  const std::uint8_t first = b[L::first_imu];
  if (total == 0 || total > kImuGloveMaxImus) return {ImuGloveDecodeErrc::bad_imu_count, 0, total};
  if (first % kImuGloveImusPerReport != 0 || first >= total) return {ImuGloveDecodeErrc::bad_first_imu, total, first};

  out.version = b[L::version];
  out.first_imu = first;
  out.imu_total = total;
  out.sequence = get_u16(b, L::sequence);
  out.timestamp_us = get_u32(b, L::timestamp_us);
  out.flags = b[L::flags];
  out.accel_range = accel_range_of(b[L::ranges]);
  out.gyro_range = gyro_range_of(b[L::ranges]);
  const std::uint16_t status = get_u16(b, L::imu_status);
  const std::size_t blocks = out.block_count();
  for (std::size_t i = 0; i < kImuGloveImusPerReport; ++i) {
    ImuGloveImuRaw& imu = out.imus[i];
    if (i >= blocks) {
      imu = ImuGloveImuRaw{};  // padding blocks carry nothing, whatever the bytes say
      continue;
    }
    imu.status = static_cast<std::uint8_t>(status >> (4 * i) & imu_status::mask);
    const std::size_t at = L::imu_blocks + i * L::imu_block_size;
    for (std::size_t a = 0; a < 3; ++a) {
      imu.accel[a] = get_i16(b, at + 2 * a);
      imu.gyro[a] = get_i16(b, at + 6 + 2 * a);
    }
  }
  return {};
}

std::array<std::uint8_t, kImuGloveInfoReportSize> encode_info_report(const ImuGloveDeviceInfo& info) noexcept {
  namespace L = info_layout;
  std::array<std::uint8_t, kImuGloveInfoReportSize> b{};
  b[0] = static_cast<std::uint8_t>(ImuGloveReportId::device_info);
  b[L::version] = info.version;
  for (std::size_t i = 0; i < 3; ++i) b[L::firmware + i] = info.firmware[i];
  b[L::imu_count] = info.imu_count;
  put_u16(&b[L::rate_hz], info.rate_hz);
  b[L::ranges] = encode_ranges(info.accel_range, info.gyro_range);
  b[L::state] = info.streaming ? 1 : 0;
  b[L::last_token] = info.last_command_token;
  b[L::last_result] = static_cast<std::uint8_t>(info.last_command_result);
  put_u32(&b[L::timestamp_us], info.timestamp_us);
  hid::seal_crc(b, L::crc);
  return b;
}

ImuGloveDecodeStatus decode_info_report(std::span<const std::uint8_t> b, ImuGloveDeviceInfo& out) noexcept {
  namespace L = info_layout;
  if (auto s = check_frame(b, ImuGloveReportId::device_info, kImuGloveInfoReportSize, L::version, L::crc); !s) return s;
  const std::uint8_t imus = b[L::imu_count];
  if (imus == 0 || imus > kImuGloveMaxImus) return {ImuGloveDecodeErrc::bad_imu_count, 0, imus};
  const std::uint16_t rate = get_u16(b, L::rate_hz);
  if (rate == 0 || rate > kImuGloveMaxRateHz) return {ImuGloveDecodeErrc::bad_rate, kImuGloveMaxRateHz, rate};
  out.version = b[L::version];
  for (std::size_t i = 0; i < 3; ++i) out.firmware[i] = b[L::firmware + i];
  out.imu_count = imus;
  out.rate_hz = rate;
  out.accel_range = accel_range_of(b[L::ranges]);
  out.gyro_range = gyro_range_of(b[L::ranges]);
  out.streaming = (b[L::state] & 1) != 0;
  out.last_command_token = b[L::last_token];
  // A result code from a newer minor version reads as "none" rather than failing the whole report.
  const std::uint8_t result = b[L::last_result];
  out.last_command_result = result <= static_cast<std::uint8_t>(ImuGloveCommandResult::bad_report)
                                ? static_cast<ImuGloveCommandResult>(result)
                                : ImuGloveCommandResult::none;
  out.timestamp_us = get_u32(b, L::timestamp_us);
  return {};
}

std::array<std::uint8_t, kImuGloveCommandReportSize> encode_command(const ImuGloveCommand& c) noexcept {
  namespace L = command_layout;
  std::array<std::uint8_t, kImuGloveCommandReportSize> b{};
  b[0] = static_cast<std::uint8_t>(ImuGloveReportId::command);
  b[L::version] = kImuGloveProtocolVersion;
  b[L::opcode] = static_cast<std::uint8_t>(c.op);
  b[L::token] = c.token;
  put_u16(&b[L::rate_hz], c.rate_hz);
  b[L::ranges] = encode_ranges(c.accel_range, c.gyro_range);
  hid::seal_crc(b, L::crc);
  return b;
}

ImuGloveDecodeStatus decode_command(std::span<const std::uint8_t> b, ImuGloveCommand& out) noexcept {
  namespace L = command_layout;
  if (auto s = check_frame(b, ImuGloveReportId::command, kImuGloveCommandReportSize, L::version, L::crc); !s) return s;
  const std::uint8_t op = b[L::opcode];
  if (op < static_cast<std::uint8_t>(ImuGloveCommandOp::start_streaming) ||
      op > static_cast<std::uint8_t>(ImuGloveCommandOp::set_ranges)) {
    return {ImuGloveDecodeErrc::unknown_command, 0, op};
  }
  out.op = static_cast<ImuGloveCommandOp>(op);
  out.token = b[L::token];
  out.rate_hz = get_u16(b, L::rate_hz);
  out.accel_range = accel_range_of(b[L::ranges]);
  out.gyro_range = gyro_range_of(b[L::ranges]);
  return {};
}

Result<ImuGloveDataReport> decode_data_report(std::span<const std::uint8_t> bytes) {
  ImuGloveDataReport r;
  return hid::decode_result(decode_data_report(bytes, r), r,
                            report_name(static_cast<std::uint8_t>(ImuGloveReportId::imu_data)));
}
Result<ImuGloveDeviceInfo> decode_info_report(std::span<const std::uint8_t> bytes) {
  ImuGloveDeviceInfo info;
  return hid::decode_result(decode_info_report(bytes, info), info,
                            report_name(static_cast<std::uint8_t>(ImuGloveReportId::device_info)));
}
Result<ImuGloveCommand> decode_command(std::span<const std::uint8_t> bytes) {
  ImuGloveCommand c;
  return hid::decode_result(decode_command(bytes, c), c,
                            report_name(static_cast<std::uint8_t>(ImuGloveReportId::command)));
}

ImuSample to_imu_sample(const ImuGloveImuRaw& raw, std::uint16_t sensor_id, AccelRange accel_range,
                        GyroRange gyro_range) noexcept {
  ImuSample s;
  s.sensor_id = sensor_id;
  // Multiply by the reciprocal computed once: the decode loop stays division-free.
  const double a = 1.0 / accel_counts_per_mps2(accel_range);
  const double g = 1.0 / gyro_counts_per_radps(gyro_range);
  s.accel_mps2 = Vec3(raw.accel[0] * a, raw.accel[1] * a, raw.accel[2] * a);
  s.gyro_radps = Vec3(raw.gyro[0] * g, raw.gyro[1] * g, raw.gyro[2] * g);
  return s;
}

std::uint8_t host_status(const ImuGloveImuRaw& raw) noexcept {
  auto at_rail = [](const std::array<std::int16_t, 3>& v) {
    for (const std::int16_t x : v) {
      if (x == std::numeric_limits<std::int16_t>::max() || x == std::numeric_limits<std::int16_t>::min()) {
        return true;
      }
    }
    return false;
  };
  std::uint8_t status = raw.status;
  if (at_rail(raw.accel)) status |= imu_status::accel_saturated;
  if (at_rail(raw.gyro)) status |= imu_status::gyro_saturated;
  return status;
}

ImuGloveImuRaw quantise_imu(const ImuSample& sample, AccelRange accel_range, GyroRange gyro_range) noexcept {
  ImuGloveImuRaw raw;
  if (!sample.accel_mps2.allFinite() || !sample.gyro_radps.allFinite()) {
    raw.status = imu_status::sensor_error;
    return raw;
  }
  auto quantise = [](double counts, bool& saturated) {
    // Clamp before converting: a double outside int16's range converted to an integer is undefined.
    const double r = std::nearbyint(counts);
    if (r >= 32767.0) {
      saturated = true;
      return std::int16_t{32767};
    }
    if (r <= -32768.0) {
      saturated = true;
      return std::int16_t{-32768};
    }
    return static_cast<std::int16_t>(r);
  };
  bool accel_sat = false, gyro_sat = false;
  const double ka = accel_counts_per_mps2(accel_range);
  const double kg = gyro_counts_per_radps(gyro_range);
  for (int a = 0; a < 3; ++a) {
    raw.accel[static_cast<std::size_t>(a)] = quantise(sample.accel_mps2[a] * ka, accel_sat);
    raw.gyro[static_cast<std::size_t>(a)] = quantise(sample.gyro_radps[a] * kg, gyro_sat);
  }
  if (accel_sat) raw.status |= imu_status::accel_saturated;
  if (gyro_sat) raw.status |= imu_status::gyro_saturated;
  return raw;
}

}  // namespace proprio::devices
