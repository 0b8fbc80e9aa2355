#pragma once
// Fingertip devices on USB HID as the servo loop's channels: which device
// renders which finger, and under which device model. Used by
// `proprio run --haptics hid` and the study samples.
//
// Every listed device is started and asked for its info report (kind, motor
// count, the finger it is assigned to). Then, per finger in the order given:
//  1. the device bound to it explicitly ("index=SERIAL", "thumb=/dev/hidraw3");
//  2. else a device whose info report assigns it to that finger (and to the
//     tracked hand, or to either hand);
//  3. else the next device that is assigned to no finger, in the order the
//     OS lists them.
// A finger left without a device, or an explicitly bound device that does not
// answer within the timeout, is an error naming it: a study must not start
// with a finger silently unrendered. Devices not chosen are stopped.
//
// The device model (force to motor angles) is the file given, or the shipped
// model for the kind each device reports (model_dir/<kind>.toml); a given
// model whose kind differs from the device's is an error.
#include <filesystem>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/fingertip_device/fingertip_device.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/haptics/servo_loop.hpp"

namespace proprio::haptics {

struct HidDeviceBinding {
  Finger finger = Finger::index;
  std::string device;  // USB serial number, or a /dev/hidrawN path
};
// "index=SERIAL" or "thumb=/dev/hidraw3".
Result<HidDeviceBinding> parse_hid_binding(std::string_view text);

struct HidChannelOptions {
  std::vector<Finger> fingers{Finger::index};
  std::vector<HidDeviceBinding> bindings;  // fingers not bound here are assigned as above
  Handedness hand = Handedness::right;     // the tracked hand the devices are worn on
  std::filesystem::path model_file;        // empty: model_dir/<kind>.toml per device
  std::filesystem::path model_dir;         // the shipped models (config/haptics)
  DurationNs connect_timeout_ns = 5 * kNsPerSecond;
  devices::FingertipDeviceOptions device;
  Status validate() const;
  std::string describe() const;
};

// Opens one listed device (hidapi for real ones; tests hand in emulators).
using HidTransportFactory = std::function<std::unique_ptr<hid::HidTransport>(const hid::HidDeviceInfo&)>;
std::unique_ptr<hid::HidTransport> open_hidapi_transport(const hid::HidDeviceInfo& info);

struct HidChannel {
  ServoChannel channel;               // its sink forwards to the device
  hid::HidDeviceInfo listed;      // how the OS listed it
  devices::FingertipDeviceInfo info;  // what it reported
  std::string describe() const;
};

// available: the devices to choose from, usually enumerate_fingertip_devices().
Result<std::vector<HidChannel>> open_hid_channels(const HidChannelOptions& options,
                                                  std::span<const hid::HidDeviceInfo> available,
                                                  const HidTransportFactory& open = open_hidapi_transport);

}  // namespace proprio::haptics
