// Assigning USB fingertip devices to fingers (haptics/hid_channels.hpp),
// against emulated devices that speak the real HID bytes over in-memory links.
#include <gtest/gtest.h>

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "proprio/fingertip_device/fingertip_emulator.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/haptics/hid_channels.hpp"
#include "support/devices.hpp"
#include "support/text.hpp"

namespace proprio::haptics {
namespace {

using testing_support::contains;

const std::filesystem::path kModelDir = std::filesystem::path(PROPRIO_SOURCE_DIR) / "config/haptics";

struct EmulatedBus {
  struct Device {
    std::shared_ptr<hid::FakeHidLink> link;
    std::unique_ptr<devices::FingertipEmulatorServer> server;
  };
  std::vector<hid::HidDeviceInfo> listed;
  std::map<std::string, Device> by_path;
  std::vector<std::string> opened;

  // A device of `kind` at /dev/hidraw<N>, optionally assigned to a finger.
  void add(const std::string& serial, std::optional<Finger> finger = std::nullopt,
           const char* kind = "platform_3dof", std::optional<Handedness> hand = std::nullopt) {
    auto model = load_device_model(kModelDir / (std::string(kind) + ".toml"));
    ASSERT_TRUE(model) << model.error().message;
    std::shared_ptr<const FingertipDeviceModel> shared(std::move(*model));
    auto options = emulator_options_for(*shared);
    options.serial = serial;
    options.finger = finger;
    options.hand = hand;
    auto emulator = make_device_emulator(shared, options);
    ASSERT_TRUE(emulator) << emulator.error().message;
    Device d;
    d.link = std::make_shared<hid::FakeHidLink>();
    d.server = std::make_unique<devices::FingertipEmulatorServer>(std::move(*emulator), d.link);
    d.server->start();
    hid::HidDeviceInfo info;
    info.path = "/dev/hidraw" + std::to_string(listed.size() + 3);
    info.serial = serial;
    listed.push_back(info);
    by_path[info.path] = std::move(d);
  }
  // Listed by the OS but never answers (no emulator behind the link).
  void add_silent(const std::string& serial) {
    hid::HidDeviceInfo info;
    info.path = "/dev/hidraw" + std::to_string(listed.size() + 3);
    info.serial = serial;
    listed.push_back(info);
    by_path[info.path] = Device{std::make_shared<hid::FakeHidLink>(), nullptr};
  }
  HidTransportFactory factory() {
    return [this](const hid::HidDeviceInfo& info) -> std::unique_ptr<hid::HidTransport> {
      opened.push_back(info.path);
      return std::make_unique<hid::FakeHidTransport>(by_path.at(info.path).link);
    };
  }
};

HidChannelOptions options_for(std::vector<Finger> fingers) {
  HidChannelOptions o;
  o.fingers = std::move(fingers);
  o.model_dir = kModelDir;
  o.connect_timeout_ns = 3 * kNsPerSecond;
  return o;
}

std::map<Finger, std::string> serials(const std::vector<HidChannel>& channels) {
  std::map<Finger, std::string> m;
  for (const auto& c : channels) m[c.channel.finger] = std::string(c.info.serial_view());
  return m;
}

TEST(HidChannels, ParsesBindingsAndRejectsBadOnes) {
  auto b = parse_hid_binding("thumb=/dev/hidraw7");
  ASSERT_TRUE(b);
  EXPECT_EQ(b->finger, Finger::thumb);
  EXPECT_EQ(b->device, "/dev/hidraw7");
  EXPECT_FALSE(parse_hid_binding("index"));
  EXPECT_FALSE(parse_hid_binding("index="));
  auto bad = parse_hid_binding("pinky=FT1");
  ASSERT_FALSE(bad);
  EXPECT_TRUE(contains(bad.error().message, "pinky"));
}

TEST(HidChannels, AssignedDevicesGoToTheirFingersAndTheRestInListOrder) {
  EmulatedBus bus;
  bus.add("FREE-A");
  bus.add("MIDDLE", Finger::middle);
  bus.add("FREE-B");
  bus.add("THUMB", Finger::thumb, "platform_3dof", Handedness::right);
  auto channels = open_hid_channels(options_for({Finger::thumb, Finger::index, Finger::middle}), bus.listed,
                                    bus.factory());
  ASSERT_TRUE(channels) << channels.error().message;
  ASSERT_EQ(channels->size(), 3u);
  EXPECT_EQ(serials(*channels), (std::map<Finger, std::string>{
                                    {Finger::thumb, "THUMB"}, {Finger::index, "FREE-A"}, {Finger::middle, "MIDDLE"}}));
  for (const auto& c : *channels) {
    EXPECT_EQ(c.channel.model->kind(), "platform_3dof");
    EXPECT_TRUE(c.channel.sink->connected());
  }
}

TEST(HidChannels, ExplicitBindingsWinBySerialOrPath) {
  EmulatedBus bus;
  bus.add("A");
  bus.add("B", Finger::index);
  bus.add("C");
  auto o = options_for({Finger::index, Finger::middle});
  o.bindings = {{Finger::index, "C"}, {Finger::middle, bus.listed[0].path}};
  auto channels = open_hid_channels(o, bus.listed, bus.factory());
  ASSERT_TRUE(channels) << channels.error().message;
  EXPECT_EQ(serials(*channels), (std::map<Finger, std::string>{{Finger::index, "C"}, {Finger::middle, "A"}}));
}

TEST(HidChannels, ADeviceAssignedToTheOtherHandIsNotUsed) {
  EmulatedBus bus;
  bus.add("LEFT-INDEX", Finger::index, "platform_3dof", Handedness::left);
  auto channels = open_hid_channels(options_for({Finger::index}), bus.listed, bus.factory());
  ASSERT_FALSE(channels);
  EXPECT_EQ(channels.error().code, Errc::not_found);
  EXPECT_TRUE(contains(channels.error().message, "index")) << channels.error().message;
}

TEST(HidChannels, TooFewDevicesIsAnErrorNamingTheFinger) {
  EmulatedBus bus;
  bus.add("ONLY");
  auto channels = open_hid_channels(options_for({Finger::thumb, Finger::index}), bus.listed, bus.factory());
  ASSERT_FALSE(channels);
  EXPECT_TRUE(contains(channels.error().message, "index")) << channels.error().message;
  EXPECT_TRUE(contains(channels.error().message, "1 listed")) << channels.error().message;
}

TEST(HidChannels, NoDevicesAndSilentBoundDevicesAreClearErrors) {
  EmulatedBus none;
  auto empty = open_hid_channels(options_for({Finger::index}), none.listed, none.factory());
  ASSERT_FALSE(empty);
  EXPECT_TRUE(contains(empty.error().message, "proprio haptics devices")) << empty.error().message;

  EmulatedBus bus;
  bus.add_silent("DEAD");
  auto o = options_for({Finger::index});
  o.bindings = {{Finger::index, "DEAD"}};
  o.connect_timeout_ns = 200 * kNsPerMillisecond;
  auto silent = open_hid_channels(o, bus.listed, bus.factory());
  ASSERT_FALSE(silent);
  EXPECT_EQ(silent.error().code, Errc::unavailable);
  EXPECT_TRUE(contains(silent.error().message, "DEAD")) << silent.error().message;
}

TEST(HidChannels, AGivenModelOfAnotherKindIsRefused) {
  EmulatedBus bus;
  bus.add("BAND", std::nullopt, "band_2dof");
  auto o = options_for({Finger::index});
  o.model_file = kModelDir / "platform_3dof.toml";
  auto channels = open_hid_channels(o, bus.listed, bus.factory());
  ASSERT_FALSE(channels);
  EXPECT_TRUE(contains(channels.error().message, "band_2dof")) << channels.error().message;
}

TEST(HidChannels, BadOptionsAreRejectedBeforeAnyDeviceIsOpened) {
  EmulatedBus bus;
  bus.add("A");
  auto twice = options_for({Finger::index, Finger::index});
  EXPECT_FALSE(open_hid_channels(twice, bus.listed, bus.factory()));
  auto unwanted = options_for({Finger::index});
  unwanted.bindings = {{Finger::thumb, "A"}};
  auto r = open_hid_channels(unwanted, bus.listed, bus.factory());
  ASSERT_FALSE(r);
  EXPECT_TRUE(contains(r.error().message, "thumb")) << r.error().message;
  EXPECT_TRUE(bus.opened.empty());
}

TEST(HidChannels, TheSinkDrivesTheDeviceAndReadsItsForceSensors) {
  EmulatedBus bus;
  bus.add("DRIVEN");
  auto channels = open_hid_channels(options_for({Finger::index}), bus.listed, bus.factory());
  ASSERT_TRUE(channels) << channels.error().message;
  const ServoChannel& ch = channels->front().channel;
  FingertipForce wanted;
  wanted.normal_n = 1.0;
  const MotorAngles q = ch.model->inverse(wanted);
  // Commands as the servo loop sends them, until the emulated sensors read the press.
  const bool pressed = testing_support::wait_until(
      [&] {
        ch.sink->send(q, wanted, true, MonotonicClock::instance().now_ns());
        return ch.sink->measured().normal_n > 0.8;
      },
      std::chrono::seconds(5));
  // The device's own counts tell a command that never arrived from one that
  // arrived and did nothing, and a host too busy to run the emulation (stalls).
  const auto st = bus.by_path.begin()->second.server->emulator_stats();
  EXPECT_TRUE(pressed) << "normal force read back: " << ch.sink->measured().normal_n << " N; device: " << st.ticks
                       << " ticks, " << st.stalled_ticks << " skipped in " << st.stalls << " stalls, "
                       << st.commands_applied << " commands applied, " << st.commands_superseded << " superseded, "
                       << st.commands_rejected << " rejected, " << st.watchdog_trips << " watchdog trips, "
                       << st.faults_latched << " faults";
  // Disabled: the device goes back to rest.
  const bool released = testing_support::wait_until(
      [&] {
        ch.sink->send(MotorAngles{}, FingertipForce{}, false, MonotonicClock::instance().now_ns());
        return ch.sink->measured().normal_n < 0.1;
      },
      std::chrono::seconds(5));
  EXPECT_TRUE(released) << "normal force read back: " << ch.sink->measured().normal_n << " N";
}

}  // namespace
}  // namespace proprio::haptics
