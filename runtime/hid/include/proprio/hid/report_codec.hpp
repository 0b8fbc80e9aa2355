#pragma once
// The byte-level pieces every Proprio HID report protocol shares (IMU glove
// board, stretch board, FTM board, fingertip devices): little-endian fields,
// the CRC-16 trailer, and the frame checks (ID, length, major version, CRC)
// that run before a protocol looks at its own fields. Each protocol keeps its
// own error enum and messages for its own fields; these give it the common
// part once, so the boards cannot drift apart in how they frame a report.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "proprio/core/result.hpp"
#include "proprio/hid/crc16.hpp"

namespace proprio::hid {

// Little-endian fields. Callers have checked the report's length first.
inline std::uint16_t get_u16(std::span<const std::uint8_t> b, std::size_t at) noexcept {
  return static_cast<std::uint16_t>(b[at] | b[at + 1] << 8);
}
// Two's complement by conversion, which C++20 defines.
inline std::int16_t get_i16(std::span<const std::uint8_t> b, std::size_t at) noexcept {
  return static_cast<std::int16_t>(get_u16(b, at));
}
inline std::uint32_t get_u32(std::span<const std::uint8_t> b, std::size_t at) noexcept {
  return static_cast<std::uint32_t>(b[at]) | static_cast<std::uint32_t>(b[at + 1]) << 8 |
         static_cast<std::uint32_t>(b[at + 2]) << 16 | static_cast<std::uint32_t>(b[at + 3]) << 24;
}
inline std::int32_t get_i32(std::span<const std::uint8_t> b, std::size_t at) noexcept {
  return static_cast<std::int32_t>(get_u32(b, at));
}
inline std::int64_t get_i64(std::span<const std::uint8_t> b, std::size_t at) noexcept {
  return static_cast<std::int64_t>(static_cast<std::uint64_t>(get_u32(b, at)) |
                                   static_cast<std::uint64_t>(get_u32(b, at + 4)) << 32);
}
inline void put_u16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
inline void put_i16(std::uint8_t* p, std::int16_t v) noexcept { put_u16(p, static_cast<std::uint16_t>(v)); }
inline void put_u32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
inline void put_u64(std::uint8_t* p, std::uint64_t v) noexcept {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

// Writes the CRC-16/CCITT of report[0, crc_at) little-endian at crc_at: the
// last step of every encoder.
inline void seal_crc(std::span<std::uint8_t> report, std::size_t crc_at) noexcept {
  put_u16(&report[crc_at], crc16_ccitt(std::span<const std::uint8_t>(report).first(crc_at)));
}

// A protocol's decode outcome: its own code enum (ok = 0, the five frame
// faults by name, then its field checks) with the two numbers its message
// needs, meaning per code as that enum documents.
template <typename Code>
struct DecodeStatus {
  Code code = Code::ok;
  std::uint32_t expected = 0;
  std::uint32_t actual = 0;
  bool ok() const noexcept { return code == Code::ok; }
  explicit operator bool() const noexcept { return ok(); }
};

// What the frame checks found. expected/actual as the protocols' own statuses
// carry them: the size, the ID, the major version, or the carried/computed CRC.
enum class FrameFault : std::uint8_t {
  ok = 0,
  empty,
  bad_length,
  unknown_report_id,
  unsupported_version,
  crc_mismatch
};
struct FrameCheck {
  FrameFault fault = FrameFault::ok;
  std::uint32_t expected = 0;
  std::uint32_t actual = 0;
  explicit operator bool() const noexcept { return fault == FrameFault::ok; }
};

// Empty, report ID in byte 0, exact length, major version in the high nibble
// of bytes[version_at], CRC at crc_at over everything before it; in that order,
// so the first fault found is the one reported.
FrameCheck check_frame(std::span<const std::uint8_t> bytes, std::uint8_t id, std::size_t size, std::size_t version_at,
                       std::size_t crc_at, std::uint8_t major) noexcept;

// The frame fault as a protocol's own status type (a struct {code, expected,
// actual} whose code enum names the five frame faults; their numeric values
// may differ between protocols, so this maps by name).
template <typename Status>
Status to_decode_status(const FrameCheck& c) noexcept {
  using Code = decltype(Status{}.code);
  Code code = Code::ok;
  switch (c.fault) {
    case FrameFault::ok: code = Code::ok; break;
    case FrameFault::empty: code = Code::empty; break;
    case FrameFault::bad_length: code = Code::bad_length; break;
    case FrameFault::unknown_report_id: code = Code::unknown_report_id; break;
    case FrameFault::unsupported_version: code = Code::unsupported_version; break;
    case FrameFault::crc_mismatch: code = Code::crc_mismatch; break;
  }
  Status s;
  s.code = code;
  s.expected = c.expected;
  s.actual = c.actual;
  return s;
}

// The inverse for a protocol's own code: FrameFault::ok for every code that is
// not one of the five frame faults.
template <typename Code>
FrameFault frame_fault_of(Code code) noexcept {
  if (code == Code::empty) return FrameFault::empty;
  if (code == Code::bad_length) return FrameFault::bad_length;
  if (code == Code::unknown_report_id) return FrameFault::unknown_report_id;
  if (code == Code::unsupported_version) return FrameFault::unsupported_version;
  if (code == Code::crc_mismatch) return FrameFault::crc_mismatch;
  return FrameFault::ok;
}

// The board protocols' sentence for a frame fault (what happened and what to
// check). protocol_label names the protocol in the version advice ("FTM board
// protocol"); id_hint follows an unknown ID (what that ID most likely is, or "").
std::string describe_frame_fault(const FrameCheck& c, const char* protocol_label, const char* id_hint);

// A status-returning decode as a Result: the protocol's to_error (found by
// argument-dependent lookup) with the report's name as context.
template <typename T, typename Status>
Result<T> decode_result(const Status& status, const T& value, const char* report_name) {
  if (!status) return to_error(status).with_context(report_name);
  return value;
}

}  // namespace proprio::hid
