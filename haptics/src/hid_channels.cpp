#include "proprio/haptics/hid_channels.hpp"

#include <chrono>
#include <optional>
#include <thread>

#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"

namespace proprio::haptics {
namespace {

bool is_path(std::string_view device) { return device.rfind("/dev/", 0) == 0; }

bool matches(const hid::HidDeviceInfo& listed, const devices::FingertipDeviceInfo* info, std::string_view device) {
  if (is_path(device)) return listed.path == device;
  return listed.serial == device || (info && info->serial_view() == device);
}

std::string name_of(const hid::HidDeviceInfo& listed) {
  return listed.serial.empty() ? listed.path : listed.serial + " (" + listed.path + ")";
}

// A started device and what it reported, while the fingers are assigned.
struct Candidate {
  const hid::HidDeviceInfo* listed = nullptr;
  std::shared_ptr<devices::FingertipDevice> device;
  std::optional<devices::FingertipDeviceInfo> info;  // empty: did not come up in time
  bool taken = false;
};

void wait_for_info(std::vector<Candidate>& candidates, DurationNs timeout_ns) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::nanoseconds(timeout_ns);
  for (;;) {
    bool all = true;
    for (auto& c : candidates) {
      if (c.info) continue;
      const auto stats = c.device->stats();
      if (c.device->state() == devices::FingertipLinkState::streaming && stats.have_info) {
        c.info = stats.info;
      } else {
        all = false;
      }
    }
    if (all || std::chrono::steady_clock::now() >= deadline) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

Result<std::shared_ptr<const FingertipDeviceModel>> model_for(const HidChannelOptions& o,
                                                              const devices::FingertipDeviceInfo& info,
                                                              const std::string& device) {
  const std::string kind = devices::to_string(info.kind);
  const auto file = o.model_file.empty() ? o.model_dir / (kind + ".toml") : o.model_file;
  auto model = load_device_model(file);
  if (!model) return model.error().with_context("device " + device);
  if ((*model)->kind() != kind) {
    return make_error(Errc::invalid_argument, "device " + device + " is a " + kind + " device, but the model " +
                                                  file.string() + " is for " + std::string((*model)->kind()) +
                                                  " devices: give a model of its kind or leave --device out");
  }
  return std::shared_ptr<const FingertipDeviceModel>(std::move(*model));
}

}  // namespace

Result<HidDeviceBinding> parse_hid_binding(std::string_view text) {
  const auto eq = text.find('=');
  if (eq == std::string_view::npos || eq + 1 == text.size()) {
    return make_error(Errc::invalid_argument, "device binding '" + std::string(text) +
                                                  "': expected FINGER=SERIAL or FINGER=/dev/hidrawN, e.g. index=FT0001");
  }
  auto finger = parse_finger(text.substr(0, eq));
  if (!finger) {
    return make_error(Errc::invalid_argument, "device binding '" + std::string(text) + "': unknown finger '" +
                                                  std::string(text.substr(0, eq)) +
                                                  "' (thumb, index, middle, ring, little)");
  }
  return HidDeviceBinding{*finger, std::string(text.substr(eq + 1))};
}

Status HidChannelOptions::validate() const {
  if (fingers.empty()) return make_error(Errc::invalid_argument, "no fingers to render haptics on");
  for (std::size_t i = 0; i < fingers.size(); ++i) {
    for (std::size_t j = 0; j < i; ++j) {
      if (fingers[i] == fingers[j]) {
        return make_error(Errc::invalid_argument, "finger " + std::string(to_string(fingers[i])) + " listed twice");
      }
    }
  }
  for (const auto& b : bindings) {
    bool wanted = false;
    for (Finger f : fingers) wanted = wanted || f == b.finger;
    if (!wanted) {
      return make_error(Errc::invalid_argument, "device " + b.device + " is bound to the " +
                                                    std::string(to_string(b.finger)) +
                                                    " finger, which has no haptics (add it to the fingers)");
    }
    for (const auto& other : bindings) {
      if (&other != &b && other.device == b.device) {
        return make_error(Errc::invalid_argument, "device " + b.device + " is bound to two fingers");
      }
      if (&other != &b && other.finger == b.finger) {
        return make_error(Errc::invalid_argument,
                          "the " + std::string(to_string(b.finger)) + " finger is bound to two devices");
      }
    }
  }
  if (connect_timeout_ns <= 0) return make_error(Errc::invalid_argument, "connect timeout must be positive");
  return {};
}

std::string HidChannelOptions::describe() const {
  std::string s = "HID haptics on the " + std::string(to_string(hand)) + " hand's";
  for (Finger f : fingers) s += " " + std::string(to_string(f));
  for (const auto& b : bindings) s += "; " + std::string(to_string(b.finger)) + " = " + b.device;
  s += "; model: " + (model_file.empty() ? "by each device's kind from " + model_dir.string() : model_file.string());
  return s;
}

std::unique_ptr<hid::HidTransport> open_hidapi_transport(const hid::HidDeviceInfo& info) {
  return std::make_unique<hid::HidapiTransport>(devices::fingertip_device_selector({}, info.path));
}

std::string HidChannel::describe() const {
  return std::string(to_string(channel.finger)) + ": " + name_of(listed) + ", " + devices::describe(info);
}

Result<std::vector<HidChannel>> open_hid_channels(const HidChannelOptions& options,
                                                  std::span<const hid::HidDeviceInfo> available,
                                                  const HidTransportFactory& open) {
  if (auto s = options.validate(); !s) return s.error();
  if (available.empty()) {
    return make_error(Errc::not_found, "no fingertip haptic device is plugged in (list them with 'proprio haptics "
                                       "devices'; check permissions on /dev/hidraw*)");
  }
  for (const auto& b : options.bindings) {
    bool listed = false;
    for (const auto& d : available) listed = listed || matches(d, nullptr, b.device);
    if (!listed && is_path(b.device)) {
      return make_error(Errc::not_found, "no fingertip device at " + b.device + " (list them with 'proprio haptics devices')");
    }
  }

  std::vector<Candidate> candidates;
  candidates.reserve(available.size());
  for (const auto& d : available) {
    auto transport = open(d);
    if (!transport) continue;
    Candidate c;
    c.listed = &d;
    c.device = std::make_shared<devices::FingertipDevice>(std::move(transport), options.device);
    if (auto s = c.device->start(); !s) return s.error().with_context("device " + name_of(d));
    candidates.push_back(std::move(c));
  }
  wait_for_info(candidates, options.connect_timeout_ns);

  auto pick = [&](Finger finger) -> Result<Candidate*> {
    for (const auto& b : options.bindings) {
      if (b.finger != finger) continue;
      for (auto& c : candidates) {
        if (!c.taken && matches(*c.listed, c.info ? &*c.info : nullptr, b.device)) {
          if (!c.info) {
            return make_error(Errc::unavailable, "device " + b.device + " (for the " + std::string(to_string(finger)) +
                                                     " finger) did not report within the timeout; is it powered?");
          }
          return &c;
        }
      }
      return make_error(Errc::not_found, "no fingertip device " + b.device + " for the " +
                                             std::string(to_string(finger)) +
                                             " finger (list them with 'proprio haptics devices')");
    }
    for (auto& c : candidates) {
      if (!c.taken && c.info && c.info->finger == finger && (!c.info->hand || *c.info->hand == options.hand)) return &c;
    }
    for (auto& c : candidates) {
      bool bound = false;
      for (const auto& b : options.bindings) bound = bound || matches(*c.listed, c.info ? &*c.info : nullptr, b.device);
      if (!c.taken && c.info && !c.info->finger && !bound) return &c;
    }
    std::size_t up = 0;
    for (const auto& c : candidates) up += c.info ? 1 : 0;
    return make_error(Errc::not_found, "no fingertip device left for the " + std::string(to_string(finger)) +
                                           " finger: " + std::to_string(available.size()) + " listed, " +
                                           std::to_string(up) + " answered, " +
                                           std::to_string(options.fingers.size()) +
                                           " fingers wanted (devices assigned to other fingers are not reused)");
  };

  std::vector<HidChannel> channels;
  for (Finger finger : options.fingers) {
    auto c = pick(finger);
    if (!c) return c.error();
    Candidate& chosen = **c;
    chosen.taken = true;
    auto model = model_for(options, *chosen.info, name_of(*chosen.listed));
    if (!model) return model.error();
    HidChannel ch;
    ch.channel = {finger, std::move(*model), std::make_shared<HidFingertip>(chosen.device)};
    ch.listed = *chosen.listed;
    ch.info = *chosen.info;
    channels.push_back(std::move(ch));
  }
  // Devices not chosen stop here (their destructors), at rest.
  return channels;
}

}  // namespace proprio::haptics
