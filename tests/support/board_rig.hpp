#pragma once
// One board driver on the kit's fake HID link with its emulator served in
// real time at the other end: the rig the board drivers' end-to-end tests
// share (stretch board, FTM board). A test derives from it to name its
// emulator and driver options.
#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "proprio/core/time.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/hid/link_state.hpp"
#include "support/devices.hpp"

namespace proprio::testing_support {

// Driver options that notice an unplug and come back quickly, so that the
// tests spend their time on what they check.
template <typename Options>
Options quick_link() {
  Options o;
  if constexpr (requires { o.read_timeout_ns; }) o.read_timeout_ns = 20 * kNsPerMillisecond;
  o.reconnect_backoff_min_ns = 5 * kNsPerMillisecond;
  o.reconnect_backoff_max_ns = 50 * kNsPerMillisecond;
  return o;
}

template <typename Server, typename Device, typename Sample>
struct BoardRig {
  template <typename Emulator, typename DeviceOptions>
  BoardRig(Emulator emulator, const DeviceOptions& device_options, hid::FakeHidFaults faults)
      : link(std::make_shared<hid::FakeHidLink>(MonotonicClock::instance(), faults)),
        server(std::move(emulator), link),
        device(std::make_unique<hid::FakeHidTransport>(link), device_options) {
    device.set_state_callback([this](hid::LinkState s, std::string_view detail) {
      std::lock_guard lock(states_mutex);
      states.push_back(s);
      details.emplace_back(detail);
    });
  }
  // The reader thread calls back into members declared after the device: stop it first.
  ~BoardRig() {
    device.stop();
    server.stop();
  }
  BoardRig(const BoardRig&) = delete;
  BoardRig& operator=(const BoardRig&) = delete;

  // Pops everything available into samples; true once pred holds.
  bool drain_until(const std::function<bool()>& pred, std::chrono::seconds timeout = std::chrono::seconds(20)) {
    return wait_until(
        [&] {
          Sample s;
          while (device.pop(s)) samples.push_back(s);
          return pred();
        },
        timeout);
  }
  // Stops the board and waits until the host has read everything it sent.
  bool quiesce() {
    server.stop();
    link->flush();
    return drain_until([&] { return link->pending() == 0 && device.stats().reports_read == link->stats().delivered; });
  }
  std::vector<hid::LinkState> state_log() {
    std::lock_guard lock(states_mutex);
    return states;
  }

  std::shared_ptr<hid::FakeHidLink> link;
  Server server;
  Device device;
  std::vector<Sample> samples;
  std::mutex states_mutex;
  std::vector<hid::LinkState> states;
  std::vector<std::string> details;
};

}  // namespace proprio::testing_support
