#pragma once
// The rig device's fault-tolerant bus (thesis Appendix A.1), version 1: the
// messages the components pass up the tree, and the HID report the base on
// USB carries them to the host in. Byte layouts, units and reasons:
// docs/rig-bus-protocol.md; the constants here must match it byte for byte.
//
// A bus message (little-endian, 25 to 34 bytes):
//   0      major version (high nibble) | message type (low nibble)
//   1      boot count of the creator (wraps; orders messages across reboots)
//   2-5    creator ID (hash of its programming time; never 0)
//   6-9    parent ID (0 = empty: the first receiver fills in its own)
//   10     parent outlet (the receiver's outlet it arrived on; 0xFF while empty)
//   11-14  creator's clock, µs since its boot (wraps at 2^32)
//   15-    body (data 8, type 17, child 14 bytes)
//   last 2 CRC-16/CCITT of everything before (hid::crc16_ccitt)
// The receiver that fills the parent fields re-seals the CRC; every receiver
// checks it first and drops a message that fails.
//
// The HID input report 0x61 (64 bytes): report ID, version, message count
// (0-2), the messages back to back, zero padding, CRC-16 of bytes 0-61 at 62
// (framed by hid::check_frame like every board of the kit).
//
// Decoding is bounded and allocation-free: each message's size follows from
// its type byte, never from a length field, and nothing is read beyond the span.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/hid/report_codec.hpp"
#include "proprio/hid/usb_ids.hpp"
#include "proprio/rig_device/joint_kinematics.hpp"

namespace proprio::rig_bus {

inline constexpr std::uint16_t kRigBusUsbVendorId = hid::kPidCodesVendorId;
inline constexpr std::uint16_t kRigBusUsbProductId = 0x0005;
inline constexpr std::uint16_t kRigBusHidUsagePage = hid::kVendorDefinedUsagePage;

inline constexpr std::uint8_t kBusMessageMajor = 1;
inline constexpr std::uint8_t kRigBusReportMajor = 1;
inline constexpr std::uint8_t kRigBusReportMinor = 0;
inline constexpr std::uint8_t kRigBusReportVersion =
    static_cast<std::uint8_t>(kRigBusReportMajor << 4 | kRigBusReportMinor);

inline constexpr std::uint32_t kNoComponent = 0;  // an empty ID field
inline constexpr std::uint8_t kNoOutlet = 0xFF;   // the parent outlet while the parent is empty
inline constexpr std::size_t kMaxOutlets = 8;
inline constexpr std::size_t kKindNameBytes = 12;

enum class BusMessageType : std::uint8_t { data = 1, type = 2, child = 3 };
enum class ComponentKind : std::uint8_t { base = 0, joint = 1, splitter = 2 };
const char* to_string(ComponentKind kind) noexcept;

inline constexpr std::size_t kBusHeaderSize = 15;
inline constexpr std::size_t kBusDataMessageSize = kBusHeaderSize + 8 + 2;    // 25
inline constexpr std::size_t kBusTypeMessageSize = kBusHeaderSize + 17 + 2;   // 34
inline constexpr std::size_t kBusChildMessageSize = kBusHeaderSize + 14 + 2;  // 31
inline constexpr std::size_t kBusMaxMessageSize = kBusTypeMessageSize;

// Angles on the wire: int16 centidegrees, each wrapped to (-180°, 180°]
// (-18000 is not sent: it is +18000).
inline constexpr std::int16_t kMaxAngleCentideg = 18000;
// Rotations: unit quaternion w, x, y, z scaled by 32767.
inline constexpr double kQuatScale = 32767.0;

struct BusDataBody {
  // twist_in, bend_x, bend_y, twist_out (rig_device::JointAngles' order).
  std::array<std::int16_t, 4> angles_cdeg{};
  bool operator==(const BusDataBody&) const = default;
};

struct BusTypeBody {
  ComponentKind kind = ComponentKind::joint;
  std::uint8_t outlet_count = 1;  // base 1-8, joint 1, splitter 2-8
  std::array<std::uint8_t, 3> colour_rgb{};
  std::array<char, kKindNameBytes> name{};  // printable ASCII, NUL-padded
  bool operator==(const BusTypeBody&) const = default;
};

struct BusChildBody {
  std::uint8_t outlet = 0;        // < outlet_count
  std::uint8_t outlet_count = 2;  // 1-8
  std::uint32_t child_id = kNoComponent;  // who answers polls on that outlet; 0: nobody
  std::array<std::int16_t, 4> q_wxyz{32767, 0, 0, 0};  // inlet -> outlet rotation
  bool operator==(const BusChildBody&) const = default;
};

// One message. Only the body of its type is meaningful; the decoder leaves
// the other two at their defaults (so decoded messages compare equal).
struct BusMessage {
  BusMessageType type = BusMessageType::data;
  std::uint8_t boot = 0;
  std::uint32_t creator_id = kNoComponent;
  std::uint32_t parent_id = kNoComponent;
  std::uint8_t parent_outlet = kNoOutlet;
  std::uint32_t clock_us = 0;
  BusDataBody data;
  BusTypeBody type_info;
  BusChildBody child;
  bool operator==(const BusMessage&) const = default;
};

// The HID report's contents.
inline constexpr std::uint8_t kRigBusReportId = 0x61;
inline constexpr std::size_t kRigBusReportSize = 64;  // one full-speed interrupt packet
inline constexpr std::size_t kRigBusReportPayloadAt = 3;
inline constexpr std::size_t kRigBusReportCrcAt = 62;
inline constexpr std::size_t kRigBusReportPayloadBytes = kRigBusReportCrcAt - kRigBusReportPayloadAt;  // 59
inline constexpr std::size_t kRigBusMaxMessagesPerReport = kRigBusReportPayloadBytes / kBusDataMessageSize;  // 2

struct RigBusReport {
  std::uint8_t version = kRigBusReportVersion;
  std::uint8_t count = 0;
  std::array<BusMessage, kRigBusMaxMessagesPerReport> messages{};  // those past count are default
  bool operator==(const RigBusReport&) const = default;
};

enum class BusDecodeErrc : std::uint8_t {
  ok = 0,
  empty,
  bad_length,            // expected = size of this report or message type, actual = bytes given
  unknown_report_id,     // expected = 0x61, actual = the ID byte
  unsupported_version,   // expected = major we speak, actual = version byte
  crc_mismatch,          // expected = CRC carried, actual = CRC of the bytes
  unknown_message_type,  // actual = type nibble
  bad_id,                // creator 0, or creator = parent; actual = creator
  bad_outlet,            // parent outlet inconsistent with the parent, or a child outlet >= count; actual = it
  bad_angle,             // angle outside (-180.00°, 180.00°]; actual = raw value (as unsigned)
  bad_kind,              // unknown kind or an outlet count it cannot have; actual = kind << 8 | outlets
  bad_name,              // a kind name byte not printable, or not NUL-padded; actual = byte index
  bad_rotation,          // child rotation not a unit quaternion; actual = |q|² in 1e-3
  bad_count,             // report message count above 2; actual = count
  bad_message,           // report: message `expected` failed with code `actual`
  bad_padding,           // report: a byte after the last message is not 0; actual = offset
};
inline constexpr std::size_t kBusDecodeErrcCount = 16;
const char* to_string(BusDecodeErrc code) noexcept;

using BusDecodeStatus = hid::DecodeStatus<BusDecodeErrc>;
std::string describe(const BusDecodeStatus& status);
Error to_error(const BusDecodeStatus& status);  // Errc::parse_error or unsupported

// A component's global ID: a hash of its programming time (µs since the Unix
// epoch, as the flashing tool stamps it); never 0.
std::uint32_t component_id_for(std::uint64_t programming_time_us) noexcept;

// Size of a message from its first byte; 0 for an unknown type or major.
std::size_t bus_message_size(std::uint8_t first_byte) noexcept;
// Size of a HID report with this ID (ID byte and CRC included), 0 for an unknown ID.
std::size_t rig_bus_report_size_for_id(std::uint8_t report_id) noexcept;

// Encoders write every byte and the CRC; they do not validate (tests encode
// bad fields on purpose). encode_bus_message into `out` returns the size, or 0
// when out is too small.
std::size_t encode_bus_message(const BusMessage& message, std::span<std::uint8_t> out) noexcept;
std::vector<std::uint8_t> encode_bus_message(const BusMessage& message);
// Messages past what fits the payload are left out (count says how many went).
std::array<std::uint8_t, kRigBusReportSize> encode_rig_bus_report(const RigBusReport& report) noexcept;

// Decoders check sizes, version, CRC, then fields. `bytes` is exactly one
// message / report. No allocation.
BusDecodeStatus decode_bus_message(std::span<const std::uint8_t> bytes, BusMessage& out) noexcept;
BusDecodeStatus decode_rig_bus_report(std::span<const std::uint8_t> bytes, RigBusReport& out) noexcept;
Result<BusMessage> decode_bus_message(std::span<const std::uint8_t> bytes);
Result<RigBusReport> decode_rig_bus_report(std::span<const std::uint8_t> bytes);

// Whether message b was created after message a by the same creator: a later
// boot (serial arithmetic on the wrapping counter), or the same boot and a
// later clock (serial arithmetic on the wrapping µs counter).
bool bus_newer(std::uint8_t boot_b, std::uint32_t clock_b, std::uint8_t boot_a, std::uint32_t clock_a) noexcept;

// Units.
BusDataBody quantise_angles(const rig_device::JointAngles& angles) noexcept;
rig_device::JointAngles angles_from_wire(const BusDataBody& body) noexcept;
std::array<std::int16_t, 4> quantise_rotation(const Quat& q) noexcept;
Quat rotation_from_wire(const std::array<std::int16_t, 4>& q_wxyz) noexcept;
// The kind name as text, and setting it (truncated to 12 bytes, unprintable bytes as '?').
std::string kind_name_of(const BusTypeBody& body);
void set_kind_name(BusTypeBody& body, std::string_view name) noexcept;

}  // namespace proprio::rig_bus
