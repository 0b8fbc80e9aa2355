#include "proprio/hid/link_state.hpp"

namespace proprio::hid {

const char* to_string(LinkState state) noexcept {
  switch (state) {
    case LinkState::stopped: return "stopped";
    case LinkState::connecting: return "connecting";
    case LinkState::streaming: return "streaming";
    case LinkState::disconnected: return "disconnected";
  }
  return "unknown";
}

}  // namespace proprio::hid
