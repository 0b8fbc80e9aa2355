#include "proprio/hid/report_codec.hpp"

#include <cstdio>

namespace proprio::hid {

FrameCheck check_frame(std::span<const std::uint8_t> bytes, std::uint8_t id, std::size_t size, std::size_t version_at,
                       std::size_t crc_at, std::uint8_t major) noexcept {
  if (bytes.empty()) return {FrameFault::empty, static_cast<std::uint32_t>(size), 0};
  if (bytes[0] != id) return {FrameFault::unknown_report_id, id, bytes[0]};
  if (bytes.size() != size) {
    return {FrameFault::bad_length, static_cast<std::uint32_t>(size), static_cast<std::uint32_t>(bytes.size())};
  }
  if ((bytes[version_at] >> 4) != major) return {FrameFault::unsupported_version, major, bytes[version_at]};
  const std::uint16_t carried = get_u16(bytes, crc_at);
  const std::uint16_t computed = crc16_ccitt(bytes.first(crc_at));
  if (carried != computed) return {FrameFault::crc_mismatch, carried, computed};
  return {};
}

std::string describe_frame_fault(const FrameCheck& c, const char* protocol_label, const char* id_hint) {
  char buf[360] = "";
  switch (c.fault) {
    case FrameFault::ok: return "ok";
    case FrameFault::empty:
      std::snprintf(buf, sizeof buf, "empty report: 0 bytes where a %u-byte report was expected", c.expected);
      break;
    case FrameFault::bad_length:
      std::snprintf(buf, sizeof buf,
                    "bad length: %u bytes where this report type has exactly %u (a different device or HID "
                    "report descriptor; check --vid/--pid)",
                    c.actual, c.expected);
      break;
    case FrameFault::unknown_report_id:
      std::snprintf(buf, sizeof buf, "unknown report ID 0x%02x where 0x%02x was expected%s", c.actual, c.expected,
                    id_hint);
      break;
    case FrameFault::unsupported_version:
      std::snprintf(buf, sizeof buf,
                    "unsupported protocol version %u.%u: this host speaks major version %u (update the host "
                    "software or flash firmware speaking %s %u.x)",
                    c.actual >> 4, c.actual & 0xF, c.expected, protocol_label, c.expected);
      break;
    case FrameFault::crc_mismatch:
      std::snprintf(buf, sizeof buf,
                    "CRC mismatch: the report carries 0x%04x but its bytes give 0x%04x (corrupted on the way or a "
                    "firmware bug); the report is dropped",
                    c.expected, c.actual);
      break;
  }
  return buf;
}

}  // namespace proprio::hid
