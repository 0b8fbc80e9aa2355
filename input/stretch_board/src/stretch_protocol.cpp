#include "proprio/stretch_board/stretch_protocol.hpp"

#include <cmath>
#include <cstdio>

#include "proprio/hid/report_codec.hpp"

namespace proprio::devices {

namespace {

// Byte offsets of the info and command reports (docs/stretch-glove-hid-protocol.md, tables 2 and 3).
namespace info_layout {
constexpr std::size_t version = 1;
constexpr std::size_t firmware = 2;  // 3 bytes
constexpr std::size_t top_strips = 5;
constexpr std::size_t bottom_strips = 6;
constexpr std::size_t state = 7;  // bit 0 streaming, bit 1 single strips (1.1)
constexpr std::size_t rate_hz = 8;        // u16
constexpr std::size_t full_scale_ff = 10;  // u32
constexpr std::size_t parasitic_ff = 14;   // u32
constexpr std::size_t last_token = 18;
constexpr std::size_t last_result = 19;
constexpr std::size_t timestamp_us = 20;  // u32
constexpr std::size_t crc = 30;
}  // namespace info_layout
constexpr std::uint8_t kStateStreaming = 0x01;
constexpr std::uint8_t kStateSingleStrips = 0x02;
namespace command_layout {
constexpr std::size_t version = 1;
constexpr std::size_t opcode = 2;
constexpr std::size_t token = 3;
constexpr std::size_t rate_hz = 4;  // u16
constexpr std::size_t crc = 14;
}  // namespace command_layout

using hid::get_u16;
using hid::get_u32;
using hid::put_u16;
using hid::put_u32;

bool strips_ok(std::uint8_t n) noexcept { return n >= 1 && n <= kStretchMaxStrips; }

// Strip counts in range and, with single strips, every row addressable by the 10-bit field.
StretchDecodeStatus check_plan(std::uint8_t top, std::uint8_t bottom, bool single_strips) noexcept {
  if (!strips_ok(top) || !strips_ok(bottom)) return {StretchDecodeErrc::bad_strip_count, top, bottom};
  const std::size_t rows = stretch_row_count(top, bottom, single_strips);
  if (rows > kStretchMaxCombinations) {
    return {StretchDecodeErrc::too_many_rows, static_cast<std::uint32_t>(top) << 8 | bottom,
            static_cast<std::uint32_t>(rows)};
  }
  return {};
}

// Length, ID, version and CRC: the checks every report type shares.
StretchDecodeStatus check_frame(std::span<const std::uint8_t> bytes, StretchReportId id, std::size_t size,
                                std::size_t version_at, std::size_t crc_at) noexcept {
  return hid::to_decode_status<StretchDecodeStatus>(
      hid::check_frame(bytes, static_cast<std::uint8_t>(id), size, version_at, crc_at, kStretchProtocolMajor));
}

const char* report_name(StretchReportId id) noexcept {
  switch (id) {
    case StretchReportId::measurements: return "stretch board measurement report (ID 0x21)";
    case StretchReportId::device_info: return "stretch board device info report (ID 0x22)";
    case StretchReportId::command: return "stretch board command report (ID 0x30)";
  }
  return "stretch board report";
}

// What a foreign report ID most likely is, for the message.
const char* guess_report(std::uint32_t id) noexcept {
  switch (id) {
    case 0x01:
    case 0x02:
    case 0x10: return " (an IMU glove report ID: wrong device or capture file?)";
    case 0x21: return " (the stretch board's measurement report)";
    case 0x22: return " (the stretch board's device info report)";
    case 0x30: return " (the stretch board's command report)";
    default: return "";
  }
}

std::uint32_t pack_measurement(const StretchMeasurementRaw& m) noexcept {
  namespace B = stretch_measurement_bits;
  return (m.combination & B::combination_mask) |
         (static_cast<std::uint32_t>(m.status) & B::status_mask) << B::status_shift |
         (m.value & kStretchMaxCapacitanceCount) << B::value_shift;
}

StretchMeasurementRaw unpack_measurement(std::uint32_t v) noexcept {
  namespace B = stretch_measurement_bits;
  StretchMeasurementRaw m;
  m.combination = static_cast<std::uint16_t>(v & B::combination_mask);
  m.status = static_cast<StretchMeasurementStatus>(v >> B::status_shift & B::status_mask);
  m.value = v >> B::value_shift;
  return m;
}

}  // namespace

StretchSources stretch_sources(std::size_t c, std::size_t top_strips, std::size_t bottom_strips) noexcept {
  StretchSources s;
  const std::size_t pairs = top_strips * bottom_strips;
  if (bottom_strips == 0) return s;
  if (c < pairs) {
    s.top_strip = static_cast<std::uint8_t>(c / bottom_strips);
    s.bottom_strip = static_cast<std::uint8_t>(c % bottom_strips);
  } else if (c < pairs + top_strips) {
    s.top_strip = static_cast<std::uint8_t>(c - pairs);
  } else if (c < pairs + top_strips + bottom_strips) {
    s.bottom_strip = static_cast<std::uint8_t>(c - pairs - top_strips);
  }
  return s;
}

const char* to_string(StretchMeasurementStatus status) noexcept {
  switch (status) {
    case StretchMeasurementStatus::ok: return "ok";
    case StretchMeasurementStatus::saturated: return "saturated";
    case StretchMeasurementStatus::below_zero: return "below_zero";
    case StretchMeasurementStatus::no_signal: return "no_signal";
  }
  return "unknown";
}

const char* to_string(StretchDecodeErrc code) noexcept {
  switch (code) {
    case StretchDecodeErrc::ok: return "ok";
    case StretchDecodeErrc::empty: return "empty";
    case StretchDecodeErrc::bad_length: return "bad_length";
    case StretchDecodeErrc::unknown_report_id: return "unknown_report_id";
    case StretchDecodeErrc::unsupported_version: return "unsupported_version";
    case StretchDecodeErrc::crc_mismatch: return "crc_mismatch";
    case StretchDecodeErrc::bad_count: return "bad_count";
    case StretchDecodeErrc::bad_strip_count: return "bad_strip_count";
    case StretchDecodeErrc::bad_combination: return "bad_combination";
    case StretchDecodeErrc::bad_rate: return "bad_rate";
    case StretchDecodeErrc::bad_full_scale: return "bad_full_scale";
    case StretchDecodeErrc::unknown_command: return "unknown_command";
    case StretchDecodeErrc::too_many_rows: return "too_many_rows";
  }
  return "unknown";
}

std::string describe(const StretchDecodeStatus& s) {
  char buf[360];
  switch (s.code) {
    case StretchDecodeErrc::ok: return "ok";
    case StretchDecodeErrc::empty:
    case StretchDecodeErrc::bad_length:
    case StretchDecodeErrc::unknown_report_id:
    case StretchDecodeErrc::unsupported_version:
    case StretchDecodeErrc::crc_mismatch:
      return hid::describe_frame_fault({hid::frame_fault_of(s.code), s.expected, s.actual}, "stretch board protocol",
                                       guess_report(s.actual));
    case StretchDecodeErrc::bad_count:
      std::snprintf(buf, sizeof buf, "bad measurement count %u: a report carries 1 to %zu measurements", s.actual,
                    kStretchMeasurementsPerReport);
      break;
    case StretchDecodeErrc::bad_strip_count:
      std::snprintf(buf, sizeof buf,
                    "bad strip counts %u top x %u bottom: each layer has 1 to %zu strips (firmware not "
                    "configured for a glove?)",
                    s.expected, s.actual, kStretchMaxStrips);
      break;
    case StretchDecodeErrc::bad_combination:
      std::snprintf(buf, sizeof buf,
                    "bad combination %u: the report says the board measures %u combinations (top x bottom strip "
                    "pairs, plus top + bottom single strips when it flags single_strips), so indices run from 0 to "
                    "%u; a board that measures single strips must say so with protocol 1.1's single_strips flag",
                    s.actual, s.expected, s.expected == 0 ? 0u : s.expected - 1);
      break;
    case StretchDecodeErrc::too_many_rows: {
      const unsigned top = s.expected >> 8 & 0xFF, bottom = s.expected & 0xFF;
      std::snprintf(buf, sizeof buf,
                    "too many rows: %u x %u strips with single strips make %u x %u + %u + %u = %u combinations, but "
                    "the 10-bit combination field holds %zu; such a board cannot report single strips (use fewer "
                    "strips, or pairs only)",
                    top, bottom, top, bottom, top, bottom, s.actual, kStretchMaxCombinations);
      break;
    }
    case StretchDecodeErrc::bad_rate:
      std::snprintf(buf, sizeof buf, "bad rate %u measurements/s: a board measures at 1 to %u per second", s.actual,
                    kStretchMaxRateHz);
      break;
    case StretchDecodeErrc::bad_full_scale:
      std::snprintf(buf, sizeof buf, "bad full scale %u fF: it must be 1 to %u fF (20 bits)", s.actual,
                    kStretchMaxCapacitanceCount);
      break;
    case StretchDecodeErrc::unknown_command:
      std::snprintf(buf, sizeof buf, "unknown command opcode 0x%02x", s.actual);
      break;
    default:
      std::snprintf(buf, sizeof buf, "decode error %d", static_cast<int>(s.code));
      break;
  }
  return buf;
}

Error to_error(const StretchDecodeStatus& status) {
  const Errc code = status.code == StretchDecodeErrc::unsupported_version ? Errc::unsupported : Errc::parse_error;
  return make_error(code, "stretch board HID protocol: " + describe(status));
}

std::size_t stretch_report_size_for_id(std::uint8_t report_id) noexcept {
  switch (static_cast<StretchReportId>(report_id)) {
    case StretchReportId::measurements: return kStretchDataReportSize;
    case StretchReportId::device_info: return kStretchInfoReportSize;
    case StretchReportId::command: return kStretchCommandReportSize;
  }
  return 0;
}

std::array<std::uint8_t, kStretchDataReportSize> encode_stretch_data_report(const StretchDataReport& r) noexcept {
  namespace L = stretch_data_layout;
  std::array<std::uint8_t, kStretchDataReportSize> b{};
  b[L::report_id] = static_cast<std::uint8_t>(StretchReportId::measurements);
  b[L::version] = r.version;
  put_u32(&b[L::sequence], r.sequence);
  put_u32(&b[L::timestamp_us], r.timestamp_us);
  b[L::flags] = r.flags;
  b[L::count] = r.count;
  b[L::top_strips] = r.top_strips;
  b[L::bottom_strips] = r.bottom_strips;
  const std::size_t n = r.count < kStretchMeasurementsPerReport ? r.count : kStretchMeasurementsPerReport;
  for (std::size_t i = 0; i < n; ++i) {
    put_u32(&b[L::measurements + i * L::measurement_size], pack_measurement(r.measurements[i]));
  }
  hid::seal_crc(b, L::crc);
  return b;
}

StretchDecodeStatus decode_stretch_data_report(std::span<const std::uint8_t> b, StretchDataReport& out) noexcept {
  namespace L = stretch_data_layout;
  if (auto s = check_frame(b, StretchReportId::measurements, kStretchDataReportSize, L::version, L::crc); !s) {
    return s;
  }
  const std::uint8_t count = b[L::count];
  if (count == 0 || count > kStretchMeasurementsPerReport) return {StretchDecodeErrc::bad_count, 0, count};
  const std::uint8_t top = b[L::top_strips];
  const std::uint8_t bottom = b[L::bottom_strips];
  const bool single_strips = stretch_single_strips(b[L::version], b[L::flags]);
  if (auto s = check_plan(top, bottom, single_strips); !s) return s;
  const auto combinations = static_cast<std::uint32_t>(stretch_row_count(top, bottom, single_strips));
  // Check every measurement before writing any, so a rejected report leaves out untouched.
  for (std::size_t i = 0; i < count; ++i) {
    const std::uint32_t c = get_u32(b, L::measurements + i * L::measurement_size) & stretch_measurement_bits::combination_mask;
    if (c >= combinations) return {StretchDecodeErrc::bad_combination, combinations, c};
  }
  out.version = b[L::version];
  out.sequence = get_u32(b, L::sequence);
  out.timestamp_us = get_u32(b, L::timestamp_us);
  out.flags = b[L::flags];
  out.count = count;
  out.top_strips = top;
  out.bottom_strips = bottom;
  for (std::size_t i = 0; i < kStretchMeasurementsPerReport; ++i) {
    // Slots past count carry nothing, whatever the bytes say.
    out.measurements[i] =
        i < count ? unpack_measurement(get_u32(b, L::measurements + i * L::measurement_size)) : StretchMeasurementRaw{};
  }
  return {};
}

std::array<std::uint8_t, kStretchInfoReportSize> encode_stretch_info_report(const StretchDeviceInfo& info) noexcept {
  namespace L = info_layout;
  std::array<std::uint8_t, kStretchInfoReportSize> b{};
  b[0] = static_cast<std::uint8_t>(StretchReportId::device_info);
  b[L::version] = info.version;
  for (std::size_t i = 0; i < 3; ++i) b[L::firmware + i] = info.firmware[i];
  b[L::top_strips] = info.top_strips;
  b[L::bottom_strips] = info.bottom_strips;
  b[L::state] = static_cast<std::uint8_t>((info.streaming ? kStateStreaming : 0) |
                                          (info.single_strips ? kStateSingleStrips : 0));
  put_u16(&b[L::rate_hz], info.rate_hz);
  put_u32(&b[L::full_scale_ff], info.full_scale_ff);
  put_u32(&b[L::parasitic_ff], info.parasitic_ff);
  b[L::last_token] = info.last_command_token;
  b[L::last_result] = static_cast<std::uint8_t>(info.last_command_result);
  put_u32(&b[L::timestamp_us], info.timestamp_us);
  hid::seal_crc(b, L::crc);
  return b;
}

StretchDecodeStatus decode_stretch_info_report(std::span<const std::uint8_t> b, StretchDeviceInfo& out) noexcept {
  namespace L = info_layout;
  if (auto s = check_frame(b, StretchReportId::device_info, kStretchInfoReportSize, L::version, L::crc); !s) return s;
  const std::uint8_t top = b[L::top_strips];
  const std::uint8_t bottom = b[L::bottom_strips];
  // Bit 1 of the state byte was reserved in 1.0: a 1.0 board's never counts.
  const bool single_strips = (b[L::version] & 0x0F) >= 1 && (b[L::state] & kStateSingleStrips) != 0;
  if (auto s = check_plan(top, bottom, single_strips); !s) return s;
  const std::uint16_t rate = get_u16(b, L::rate_hz);
  if (rate == 0 || rate > kStretchMaxRateHz) return {StretchDecodeErrc::bad_rate, kStretchMaxRateHz, rate};
  const std::uint32_t full_scale = get_u32(b, L::full_scale_ff);
  if (full_scale == 0 || full_scale > kStretchMaxCapacitanceCount) {
    return {StretchDecodeErrc::bad_full_scale, kStretchMaxCapacitanceCount, full_scale};
  }
  out.version = b[L::version];
  for (std::size_t i = 0; i < 3; ++i) out.firmware[i] = b[L::firmware + i];
  out.top_strips = top;
  out.bottom_strips = bottom;
  out.streaming = (b[L::state] & kStateStreaming) != 0;
  out.single_strips = single_strips;
  out.rate_hz = rate;
  out.full_scale_ff = full_scale;
  out.parasitic_ff = get_u32(b, L::parasitic_ff);
  out.last_command_token = b[L::last_token];
  // A result code from a newer minor version reads as "none" rather than failing the whole report.
  const std::uint8_t result = b[L::last_result];
  out.last_command_result = result <= static_cast<std::uint8_t>(StretchCommandResult::bad_report)
                                ? static_cast<StretchCommandResult>(result)
                                : StretchCommandResult::none;
  out.timestamp_us = get_u32(b, L::timestamp_us);
  return {};
}

std::array<std::uint8_t, kStretchCommandReportSize> encode_stretch_command(const StretchCommand& c) noexcept {
  namespace L = command_layout;
  std::array<std::uint8_t, kStretchCommandReportSize> b{};
  b[0] = static_cast<std::uint8_t>(StretchReportId::command);
  b[L::version] = kStretchProtocolVersion;
  b[L::opcode] = static_cast<std::uint8_t>(c.op);
  b[L::token] = c.token;
  put_u16(&b[L::rate_hz], c.rate_hz);
  hid::seal_crc(b, L::crc);
  return b;
}

StretchDecodeStatus decode_stretch_command(std::span<const std::uint8_t> b, StretchCommand& out) noexcept {
  namespace L = command_layout;
  if (auto s = check_frame(b, StretchReportId::command, kStretchCommandReportSize, L::version, L::crc); !s) return s;
  const std::uint8_t op = b[L::opcode];
  if (op < static_cast<std::uint8_t>(StretchCommandOp::start_streaming) ||
      op > static_cast<std::uint8_t>(StretchCommandOp::set_rate)) {
    return {StretchDecodeErrc::unknown_command, 0, op};
  }
  out.op = static_cast<StretchCommandOp>(op);
  out.token = b[L::token];
  out.rate_hz = get_u16(b, L::rate_hz);
  return {};
}

Result<StretchDataReport> decode_stretch_data_report(std::span<const std::uint8_t> bytes) {
  StretchDataReport r;
  return hid::decode_result(decode_stretch_data_report(bytes, r), r, report_name(StretchReportId::measurements));
}
Result<StretchDeviceInfo> decode_stretch_info_report(std::span<const std::uint8_t> bytes) {
  StretchDeviceInfo info;
  return hid::decode_result(decode_stretch_info_report(bytes, info), info, report_name(StretchReportId::device_info));
}
Result<StretchCommand> decode_stretch_command(std::span<const std::uint8_t> bytes) {
  StretchCommand c;
  return hid::decode_result(decode_stretch_command(bytes, c), c, report_name(StretchReportId::command));
}

StretchMeasurementRaw quantise_capacitance(std::uint16_t combination, double capacitance_pf,
                                           std::uint32_t full_scale_ff) noexcept {
  StretchMeasurementRaw m;
  m.combination = combination;
  if (full_scale_ff > kStretchMaxCapacitanceCount) full_scale_ff = kStretchMaxCapacitanceCount;
  if (!std::isfinite(capacitance_pf)) {
    m.status = StretchMeasurementStatus::no_signal;
    return m;
  }
  // Compare before converting: a double beyond the integer range converted to one is undefined.
  const double counts = std::nearbyint(capacitance_pf / kStretchPfPerCount);
  if (counts >= static_cast<double>(full_scale_ff)) {
    m.status = StretchMeasurementStatus::saturated;
    m.value = full_scale_ff;
  } else if (counts < 0.0) {
    m.status = StretchMeasurementStatus::below_zero;
  } else {
    m.value = static_cast<std::uint32_t>(counts);
  }
  return m;
}

StretchMeasurementStatus host_status(const StretchMeasurementRaw& raw) noexcept {
  if (raw.status == StretchMeasurementStatus::ok && raw.value >= kStretchMaxCapacitanceCount) {
    return StretchMeasurementStatus::saturated;
  }
  return raw.status;
}

}  // namespace proprio::devices
