#pragma once
// The state of a driver's link to its device, as every HID driver reports it
// (state callbacks, stats, `proprio glove monitor` and friends print it).
#include <cstdint>

namespace proprio::hid {

enum class LinkState : std::uint8_t {
  stopped,       // start() not called, or stop()ped
  connecting,    // trying to open the transport
  streaming,     // open and reading
  disconnected,  // lost or not found; retrying after a backoff
};
const char* to_string(LinkState state) noexcept;

}  // namespace proprio::hid
