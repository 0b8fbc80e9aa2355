#include "proprio/rig_bus/bus_protocol.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "proprio/hid/crc16.hpp"

namespace proprio::rig_bus {

namespace {

using hid::get_i16;
using hid::get_u16;
using hid::get_u32;
using hid::put_i16;
using hid::put_u16;
using hid::put_u32;

namespace msg {
constexpr std::size_t type = 0;
constexpr std::size_t boot = 1;
constexpr std::size_t creator = 2;
constexpr std::size_t parent = 6;
constexpr std::size_t outlet = 10;
constexpr std::size_t clock = 11;
constexpr std::size_t body = 15;
}  // namespace msg

constexpr double kPi = 3.14159265358979323846;
constexpr double kRadToCdeg = 18000.0 / kPi;

BusDecodeStatus status(BusDecodeErrc code, std::uint32_t expected, std::uint32_t actual) noexcept {
  BusDecodeStatus s;
  s.code = code;
  s.expected = expected;
  s.actual = actual;
  return s;
}

std::size_t size_of_type(BusMessageType t) noexcept {
  switch (t) {
    case BusMessageType::data: return kBusDataMessageSize;
    case BusMessageType::type: return kBusTypeMessageSize;
    case BusMessageType::child: return kBusChildMessageSize;
  }
  return 0;
}

bool outlets_fit_kind(ComponentKind kind, unsigned outlets) noexcept {
  switch (kind) {
    case ComponentKind::base: return outlets >= 1 && outlets <= kMaxOutlets;
    case ComponentKind::joint: return outlets == 1;
    case ComponentKind::splitter: return outlets >= 2 && outlets <= kMaxOutlets;
  }
  return false;
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
    case 0x51:
    case 0x52:
    case 0x53:
    case 0x58: return " (an FTM board report ID: wrong device or capture file?)";
    default: return "";
  }
}

}  // namespace

const char* to_string(ComponentKind kind) noexcept {
  switch (kind) {
    case ComponentKind::base: return "base";
    case ComponentKind::joint: return "joint";
    case ComponentKind::splitter: return "splitter";
  }
  return "unknown";
}

const char* to_string(BusDecodeErrc code) noexcept {
  switch (code) {
    case BusDecodeErrc::ok: return "ok";
    case BusDecodeErrc::empty: return "empty";
    case BusDecodeErrc::bad_length: return "bad_length";
    case BusDecodeErrc::unknown_report_id: return "unknown_report_id";
    case BusDecodeErrc::unsupported_version: return "unsupported_version";
    case BusDecodeErrc::crc_mismatch: return "crc_mismatch";
    case BusDecodeErrc::unknown_message_type: return "unknown_message_type";
    case BusDecodeErrc::bad_id: return "bad_id";
    case BusDecodeErrc::bad_outlet: return "bad_outlet";
    case BusDecodeErrc::bad_angle: return "bad_angle";
    case BusDecodeErrc::bad_kind: return "bad_kind";
    case BusDecodeErrc::bad_name: return "bad_name";
    case BusDecodeErrc::bad_rotation: return "bad_rotation";
    case BusDecodeErrc::bad_count: return "bad_count";
    case BusDecodeErrc::bad_message: return "bad_message";
    case BusDecodeErrc::bad_padding: return "bad_padding";
  }
  return "unknown";
}

std::string describe(const BusDecodeStatus& s) {
  char buf[360];
  switch (s.code) {
    case BusDecodeErrc::ok: return "ok";
    case BusDecodeErrc::empty:
    case BusDecodeErrc::bad_length:
    case BusDecodeErrc::unknown_report_id:
    case BusDecodeErrc::unsupported_version:
    case BusDecodeErrc::crc_mismatch:
      return hid::describe_frame_fault({hid::frame_fault_of(s.code), s.expected, s.actual}, "rig bus protocol",
                                       guess_report(s.actual));
    case BusDecodeErrc::unknown_message_type:
      std::snprintf(buf, sizeof buf, "unknown bus message type %u (1 data, 2 type, 3 child)", s.actual);
      break;
    case BusDecodeErrc::bad_id:
      std::snprintf(buf, sizeof buf,
                    "bad component ID 0x%08x: a creator ID is never 0 and never its own parent (reflash the "
                    "component with a fresh ID)",
                    s.actual);
      break;
    case BusDecodeErrc::bad_outlet:
      std::snprintf(buf, sizeof buf,
                    "bad outlet %u: an empty parent has outlet 0xff, a filled one an outlet below %zu, a child "
                    "message an outlet below its outlet count",
                    s.actual, kMaxOutlets);
      break;
    case BusDecodeErrc::bad_angle:
      std::snprintf(buf, sizeof buf, "bad angle %d centidegrees: angles are wrapped to (-180.00, 180.00] degrees",
                    static_cast<int>(static_cast<std::int16_t>(s.actual)));
      break;
    case BusDecodeErrc::bad_kind:
      std::snprintf(buf, sizeof buf,
                    "bad component kind %u with %u outlets (base 1-8 outlets, joint 1, splitter 2-8)",
                    s.actual >> 8, s.actual & 0xFF);
      break;
    case BusDecodeErrc::bad_name:
      std::snprintf(buf, sizeof buf,
                    "bad kind name: byte %u is not printable ASCII, or a byte after the name's end is not 0",
                    s.actual);
      break;
    case BusDecodeErrc::bad_rotation:
      std::snprintf(buf, sizeof buf, "bad outlet rotation: |q|^2 = %.3f where a unit quaternion was expected",
                    s.actual * 1e-3);
      break;
    case BusDecodeErrc::bad_count:
      std::snprintf(buf, sizeof buf, "bad message count %u: a report carries 0 to %zu messages", s.actual,
                    kRigBusMaxMessagesPerReport);
      break;
    case BusDecodeErrc::bad_message:
      std::snprintf(buf, sizeof buf,
                    "message %u of the report is unreadable (%s): the base forwards only checked messages, so "
                    "its firmware or the report is at fault",
                    s.expected, to_string(static_cast<BusDecodeErrc>(s.actual)));
      break;
    case BusDecodeErrc::bad_padding:
      std::snprintf(buf, sizeof buf, "byte %u after the last message is not 0", s.actual);
      break;
  }
  return buf;
}

Error to_error(const BusDecodeStatus& s) {
  const Errc code = s.code == BusDecodeErrc::unsupported_version ? Errc::unsupported : Errc::parse_error;
  return make_error(code, "rig bus protocol: " + describe(s));
}

std::uint32_t component_id_for(std::uint64_t programming_time_us) noexcept {
  // splitmix64's finaliser: neighbouring timestamps (two components flashed
  // a second apart) land far apart, folded to 32 bits.
  std::uint64_t z = programming_time_us + 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  z ^= z >> 31;
  const auto id = static_cast<std::uint32_t>(z ^ (z >> 32));
  return id == kNoComponent ? 1u : id;
}

std::size_t bus_message_size(std::uint8_t first_byte) noexcept {
  if ((first_byte >> 4) != kBusMessageMajor) return 0;
  return size_of_type(static_cast<BusMessageType>(first_byte & 0xF));
}

std::size_t rig_bus_report_size_for_id(std::uint8_t report_id) noexcept {
  return report_id == kRigBusReportId ? kRigBusReportSize : 0;
}

std::size_t encode_bus_message(const BusMessage& m, std::span<std::uint8_t> out) noexcept {
  const std::size_t size = size_of_type(m.type);
  if (size == 0 || out.size() < size) return 0;
  std::uint8_t* b = out.data();
  std::fill(b, b + size, std::uint8_t{0});
  b[msg::type] = static_cast<std::uint8_t>(kBusMessageMajor << 4 | (static_cast<std::uint8_t>(m.type) & 0xF));
  b[msg::boot] = m.boot;
  put_u32(b + msg::creator, m.creator_id);
  put_u32(b + msg::parent, m.parent_id);
  b[msg::outlet] = m.parent_outlet;
  put_u32(b + msg::clock, m.clock_us);
  std::uint8_t* body = b + msg::body;
  switch (m.type) {
    case BusMessageType::data:
      for (std::size_t i = 0; i < 4; ++i) put_i16(body + 2 * i, m.data.angles_cdeg[i]);
      break;
    case BusMessageType::type:
      body[0] = static_cast<std::uint8_t>(m.type_info.kind);
      body[1] = m.type_info.outlet_count;
      for (std::size_t i = 0; i < 3; ++i) body[2 + i] = m.type_info.colour_rgb[i];
      for (std::size_t i = 0; i < kKindNameBytes; ++i) body[5 + i] = static_cast<std::uint8_t>(m.type_info.name[i]);
      break;
    case BusMessageType::child:
      body[0] = m.child.outlet;
      body[1] = m.child.outlet_count;
      put_u32(body + 2, m.child.child_id);
      for (std::size_t i = 0; i < 4; ++i) put_i16(body + 6 + 2 * i, m.child.q_wxyz[i]);
      break;
  }
  hid::seal_crc(out.first(size), size - 2);
  return size;
}

std::vector<std::uint8_t> encode_bus_message(const BusMessage& message) {
  std::vector<std::uint8_t> out(kBusMaxMessageSize);
  out.resize(encode_bus_message(message, out));
  return out;
}

std::array<std::uint8_t, kRigBusReportSize> encode_rig_bus_report(const RigBusReport& r) noexcept {
  std::array<std::uint8_t, kRigBusReportSize> b{};
  b[0] = kRigBusReportId;
  b[1] = r.version;
  std::size_t at = kRigBusReportPayloadAt;
  std::uint8_t sent = 0;
  const std::size_t n = std::min<std::size_t>(r.count, r.messages.size());
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t size = size_of_type(r.messages[i].type);
    if (size == 0 || at + size > kRigBusReportCrcAt) break;
    at += encode_bus_message(r.messages[i], std::span<std::uint8_t>(b).subspan(at, size));
    ++sent;
  }
  b[2] = r.count > r.messages.size() ? r.count : sent;  // an over-full count stays (for the decoder's tests)
  hid::seal_crc(b, kRigBusReportCrcAt);
  return b;
}

BusDecodeStatus decode_bus_message(std::span<const std::uint8_t> bytes, BusMessage& out) noexcept {
  out = BusMessage{};
  if (bytes.empty()) return status(BusDecodeErrc::empty, static_cast<std::uint32_t>(kBusDataMessageSize), 0);
  const std::uint8_t first = bytes[msg::type];
  if ((first >> 4) != kBusMessageMajor) return status(BusDecodeErrc::unsupported_version, kBusMessageMajor, first);
  const auto type = static_cast<BusMessageType>(first & 0xF);
  const std::size_t size = size_of_type(type);
  if (size == 0) return status(BusDecodeErrc::unknown_message_type, 0, first & 0xFu);
  if (bytes.size() != size) {
    return status(BusDecodeErrc::bad_length, static_cast<std::uint32_t>(size), static_cast<std::uint32_t>(bytes.size()));
  }
  const std::uint16_t carried = get_u16(bytes, size - 2);
  const std::uint16_t computed = hid::crc16_ccitt(bytes.first(size - 2));
  if (carried != computed) return status(BusDecodeErrc::crc_mismatch, carried, computed);

  BusMessage m;
  m.type = type;
  m.boot = bytes[msg::boot];
  m.creator_id = get_u32(bytes, msg::creator);
  m.parent_id = get_u32(bytes, msg::parent);
  m.parent_outlet = bytes[msg::outlet];
  m.clock_us = get_u32(bytes, msg::clock);
  if (m.creator_id == kNoComponent || m.creator_id == m.parent_id) {
    return status(BusDecodeErrc::bad_id, 0, m.creator_id);
  }
  const bool outlet_ok =
      m.parent_id == kNoComponent ? m.parent_outlet == kNoOutlet : m.parent_outlet < kMaxOutlets;
  if (!outlet_ok) return status(BusDecodeErrc::bad_outlet, 0, m.parent_outlet);

  const std::span<const std::uint8_t> body = bytes.subspan(msg::body);
  switch (type) {
    case BusMessageType::data:
      for (std::size_t i = 0; i < 4; ++i) {
        const std::int16_t a = get_i16(body, 2 * i);
        if (a > kMaxAngleCentideg || a <= -kMaxAngleCentideg) {
          return status(BusDecodeErrc::bad_angle, static_cast<std::uint32_t>(kMaxAngleCentideg),
                        static_cast<std::uint16_t>(a));
        }
        m.data.angles_cdeg[i] = a;
      }
      break;
    case BusMessageType::type: {
      const std::uint8_t kind = body[0], outlets = body[1];
      if (kind > static_cast<std::uint8_t>(ComponentKind::splitter) ||
          !outlets_fit_kind(static_cast<ComponentKind>(kind), outlets)) {
        return status(BusDecodeErrc::bad_kind, 0, static_cast<std::uint32_t>(kind) << 8 | outlets);
      }
      m.type_info.kind = static_cast<ComponentKind>(kind);
      m.type_info.outlet_count = outlets;
      for (std::size_t i = 0; i < 3; ++i) m.type_info.colour_rgb[i] = body[2 + i];
      bool ended = false;
      for (std::size_t i = 0; i < kKindNameBytes; ++i) {
        const std::uint8_t c = body[5 + i];
        if (c == 0) {
          ended = true;
        } else if (ended || c < 0x20 || c > 0x7E) {
          return status(BusDecodeErrc::bad_name, 0, static_cast<std::uint32_t>(i));
        }
        m.type_info.name[i] = static_cast<char>(c);
      }
      break;
    }
    case BusMessageType::child: {
      m.child.outlet = body[0];
      m.child.outlet_count = body[1];
      if (m.child.outlet_count < 1 || m.child.outlet_count > kMaxOutlets || m.child.outlet >= m.child.outlet_count) {
        return status(BusDecodeErrc::bad_outlet, m.child.outlet_count, m.child.outlet);
      }
      m.child.child_id = get_u32(body, 2);
      double n2 = 0.0;
      for (std::size_t i = 0; i < 4; ++i) {
        m.child.q_wxyz[i] = get_i16(body, 6 + 2 * i);
        const double v = m.child.q_wxyz[i] / kQuatScale;
        n2 += v * v;
      }
      // Rounding each of four components by half an LSB moves |q|² by far less than 2 %.
      if (!(n2 > 0.98 && n2 < 1.02)) {
        return status(BusDecodeErrc::bad_rotation, 1000, static_cast<std::uint32_t>(std::min(n2, 4.0) * 1000.0));
      }
      break;
    }
  }
  out = m;
  return {};
}

BusDecodeStatus decode_rig_bus_report(std::span<const std::uint8_t> bytes, RigBusReport& out) noexcept {
  out = RigBusReport{};
  const hid::FrameCheck frame =
      hid::check_frame(bytes, kRigBusReportId, kRigBusReportSize, 1, kRigBusReportCrcAt, kRigBusReportMajor);
  if (!frame) return hid::to_decode_status<BusDecodeStatus>(frame);
  RigBusReport r;
  r.version = bytes[1];
  const std::uint8_t count = bytes[2];
  if (count > kRigBusMaxMessagesPerReport) return status(BusDecodeErrc::bad_count, 0, count);
  std::size_t at = kRigBusReportPayloadAt;
  for (std::uint8_t i = 0; i < count; ++i) {
    const std::size_t size = bus_message_size(bytes[at]);
    if (size == 0 || at + size > kRigBusReportCrcAt) {
      BusMessage ignored;
      BusDecodeStatus inner = size == 0 ? decode_bus_message(bytes.subspan(at, 1), ignored)
                                        : status(BusDecodeErrc::bad_length, static_cast<std::uint32_t>(size),
                                                 static_cast<std::uint32_t>(kRigBusReportCrcAt - at));
      return status(BusDecodeErrc::bad_message, i, static_cast<std::uint32_t>(inner.code));
    }
    const BusDecodeStatus s = decode_bus_message(bytes.subspan(at, size), r.messages[i]);
    if (!s) return status(BusDecodeErrc::bad_message, i, static_cast<std::uint32_t>(s.code));
    at += size;
  }
  for (; at < kRigBusReportCrcAt; ++at) {
    if (bytes[at] != 0) return status(BusDecodeErrc::bad_padding, 0, static_cast<std::uint32_t>(at));
  }
  r.count = count;
  out = r;
  return {};
}

Result<BusMessage> decode_bus_message(std::span<const std::uint8_t> bytes) {
  BusMessage m;
  return hid::decode_result(decode_bus_message(bytes, m), m, "rig bus message");
}

Result<RigBusReport> decode_rig_bus_report(std::span<const std::uint8_t> bytes) {
  RigBusReport r;
  return hid::decode_result(decode_rig_bus_report(bytes, r), r, "rig bus report (ID 0x61)");
}

bool bus_newer(std::uint8_t boot_b, std::uint32_t clock_b, std::uint8_t boot_a, std::uint32_t clock_a) noexcept {
  if (boot_b != boot_a) return static_cast<std::int8_t>(static_cast<std::uint8_t>(boot_b - boot_a)) > 0;
  return static_cast<std::int32_t>(clock_b - clock_a) > 0;
}

BusDataBody quantise_angles(const rig_device::JointAngles& a) noexcept {
  const double rad[4] = {a.twist_in_rad, a.bend_x_rad, a.bend_y_rad, a.twist_out_rad};
  BusDataBody b;
  for (std::size_t i = 0; i < 4; ++i) {
    const double w = std::isfinite(rad[i]) ? rig_device::wrap_angle_rad(rad[i]) : 0.0;
    double c = std::clamp(std::nearbyint(w * kRadToCdeg), -double{kMaxAngleCentideg}, double{kMaxAngleCentideg});
    if (c == -double{kMaxAngleCentideg}) c = kMaxAngleCentideg;  // -180° is +180°: one code on the wire
    b.angles_cdeg[i] = static_cast<std::int16_t>(c);
  }
  return b;
}

rig_device::JointAngles angles_from_wire(const BusDataBody& b) noexcept {
  rig_device::JointAngles a;
  a.twist_in_rad = b.angles_cdeg[0] / kRadToCdeg;
  a.bend_x_rad = b.angles_cdeg[1] / kRadToCdeg;
  a.bend_y_rad = b.angles_cdeg[2] / kRadToCdeg;
  a.twist_out_rad = b.angles_cdeg[3] / kRadToCdeg;
  return a;
}

std::array<std::int16_t, 4> quantise_rotation(const Quat& q_in) noexcept {
  Quat q = q_in;
  if (!(q.norm() > 0.0) || !std::isfinite(q.norm())) q = Quat::Identity();
  q.normalize();
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();  // one sign on the wire
  const double c[4] = {q.w(), q.x(), q.y(), q.z()};
  std::array<std::int16_t, 4> out{};
  for (std::size_t i = 0; i < 4; ++i) {
    out[i] = static_cast<std::int16_t>(std::clamp(std::nearbyint(c[i] * kQuatScale), -kQuatScale, kQuatScale));
  }
  return out;
}

Quat rotation_from_wire(const std::array<std::int16_t, 4>& q) noexcept {
  Quat r(q[0] / kQuatScale, q[1] / kQuatScale, q[2] / kQuatScale, q[3] / kQuatScale);
  if (!(r.norm() > 0.0)) return Quat::Identity();
  r.normalize();
  return r;
}

std::string kind_name_of(const BusTypeBody& body) {
  std::string s;
  for (const char c : body.name) {
    if (c == 0) break;
    s.push_back(c);
  }
  return s;
}

void set_kind_name(BusTypeBody& body, std::string_view name) noexcept {
  body.name.fill(0);
  for (std::size_t i = 0; i < std::min(name.size(), kKindNameBytes); ++i) {
    const auto c = static_cast<unsigned char>(name[i]);
    body.name[i] = (c >= 0x20 && c <= 0x7E) ? static_cast<char>(c) : '?';
  }
}

}  // namespace proprio::rig_bus
