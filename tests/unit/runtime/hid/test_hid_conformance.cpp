// What every HID driver of the kit (hid::LinkThread under a device's
// LinkHandler) promises, checked once for all of them: each driver runs over
// the fake link against its own emulator, served in real time by
// hid::EmulatorServer. A new device adds a traits struct below and its name
// to Drivers; the tests stay as they are.
//
// Promises: it connects and streams; it survives an unplug mid-stream and
// reconnects (backing off while the cable is out); a corrupted report is
// counted bad and the stream goes on; stop() returns from any state and the
// driver can start again; commands issued while disconnected are handled as
// the driver documents (a trait: the boards queue them, the fingertip device
// refuses them); nothing is read or delivered after stop().
//
// Threads: every wait is for a condition with a generous deadline (20 s, as
// in the per-driver tests, so ASan and TSan on a loaded machine pass);
// nothing asserts how long anything took.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/fingertip_device/fingertip_device.hpp"
#include "proprio/fingertip_device/fingertip_emulator.hpp"
#include "proprio/hid/emulator_server.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/hid/link_state.hpp"
#include "proprio/imu_glove_board/imu_glove_device.hpp"
#include "proprio/imu_glove_board/imu_glove_emulator.hpp"
#include "proprio/ftm_board/ftm_device.hpp"
#include "proprio/ftm_board/ftm_emulator.hpp"
#include "proprio/stretch_board/stretch_device.hpp"
#include "proprio/stretch_board/stretch_emulator.hpp"
#include "support/board_rig.hpp"
#include "support/devices.hpp"

namespace proprio::devices::hid_conformance_test {
namespace {

using namespace std::chrono_literals;
using proprio::testing_support::wait_until;
using Bytes = std::vector<std::uint8_t>;

// How a driver treats a command issued while no device is connected.
enum class CommandsWhileDisconnected {
  queued_until_connected,  // kept, and sent once the device is back (send_command)
  refused,                 // the call says not connected; nothing is sent later
};

using testing_support::quick_link;

// ---------------------------------------------------------------------------
// The IMU glove board. Its emulator runs on ticks of IMU readings, not on
// time: the production server (ImuGloveEmulatorServer) ticks it at its rate,
// here with synthetic readings.

void synthetic_imu_tick(std::int64_t k, TimeNs, std::span<ImuSample> out) {
  for (std::size_t i = 0; i < out.size(); ++i) {
    out[i].accel_mps2 = Vec3(0.5 * static_cast<double>(i) - 1.0, 0.05 * static_cast<double>(k % 100), 9.8);
    out[i].gyro_radps = Vec3(0.1 * static_cast<double>(i), -0.2, std::sin(0.1 * static_cast<double>(k)));
  }
}

// What the two sensor boards have in common: samples go to a callback,
// send_command() queues (it has no answer), the stream decoder counts
// reports, and the test command is START with a token, harmless to a
// streaming board (it restarts the stream). Board supplies Device, Options,
// Command, make_server and decode_command.
template <typename Board>
struct SensorBoard {
  static constexpr CommandsWhileDisconnected kCommandsWhileDisconnected =
      CommandsWhileDisconnected::queued_until_connected;
  template <typename Stats>
  static std::uint64_t accepted_reports(const Stats& s) {
    return s.stream.accepted;
  }
  template <typename Stats>
  static std::uint64_t bad_reports(const Stats& s) {
    return s.stream.decode_errors;
  }
  static auto driver_options() { return quick_link<typename Board::Options>(); }
  template <typename Device>
  static void on_delivery(Device& d, std::function<void()> f) {
    d.set_sample_callback([f = std::move(f)](const auto&) { f(); });
  }
  static auto test_command() {
    typename Board::Command c;
    c.op = decltype(c.op)::start_streaming;
    c.token = 42;
    return c;
  }
  template <typename Device>
  static bool command(Device& d) {
    d.send_command(test_command());
    return true;
  }
  static bool is_test_command(std::span<const std::uint8_t> write) {
    auto c = Board::decode_command(write);
    return c.ok() && *c == test_command();
  }
};

struct ImuGloveBoard : SensorBoard<ImuGloveBoard> {
  static constexpr const char* kName = "ImuGloveBoard";
  using Device = ImuGloveDevice;
  using Stats = ImuGloveDeviceStats;
  using Options = ImuGloveDeviceOptions;
  using Command = ImuGloveCommand;
  using Server = ImuGloveEmulatorServer;
  static std::unique_ptr<Server> make_server(std::shared_ptr<hid::FakeHidLink> link) {
    auto emulator = ImuGloveEmulator::create({});
    EXPECT_TRUE(emulator.ok()) << (emulator.ok() ? "" : emulator.error().message);
    return std::make_unique<Server>(ImuGloveTicker(std::move(*emulator), synthetic_imu_tick), std::move(link));
  }
  static Result<Command> decode_command(std::span<const std::uint8_t> b) { return devices::decode_command(b); }
};

// ---------------------------------------------------------------------------
// The stretch read-out board.

struct StretchBoard : SensorBoard<StretchBoard> {
  static constexpr const char* kName = "StretchBoard";
  using Device = StretchDevice;
  using Stats = StretchDeviceStats;
  using Options = StretchDeviceOptions;
  using Command = StretchCommand;
  using Server = StretchEmulatorServer;
  static std::unique_ptr<Server> make_server(std::shared_ptr<hid::FakeHidLink> link) {
    auto emulator = StretchEmulator::create({}, [](std::size_t c, TimeNs) { return 20.0 + 0.5 * static_cast<double>(c); });
    EXPECT_TRUE(emulator.ok()) << (emulator.ok() ? "" : emulator.error().message);
    return std::make_unique<Server>(std::move(*emulator), std::move(link));
  }
  static Result<Command> decode_command(std::span<const std::uint8_t> b) { return decode_stretch_command(b); }
};

// ---------------------------------------------------------------------------
// The FTM glove's read-out board, fed a hand at rest (its emulator takes any
// ftm::FtmSampleFeed; the production one is the simulated wearer).

class HandAtRestFeed final : public ftm::FtmSampleFeed {
 public:
  void advance(TimeNs t_ns, std::vector<ftm::FtmEvent>& out) override {
    for (; next_imu_ns_ <= t_ns; next_imu_ns_ += 5 * kNsPerMillisecond, ++ticks_) {
      for (std::size_t i = 0; i < ftm::kFtmImuCount; ++i) {
        ftm::FtmEvent e;
        e.kind = ftm::FtmEvent::Kind::imu;
        e.index = static_cast<std::uint8_t>(i);
        e.imu.time_ns = next_imu_ns_;
        e.imu.accel_mps2 = Vec3(0.1 * static_cast<double>(i), 0.0, 9.8);
        e.imu.gyro_radps = Vec3(0.0, 0.01 * static_cast<double>(ticks_ % 7), 0.0);
        e.imu.mag_uT = Vec3(20.0, -5.0, -40.0);
        e.imu.mag_fresh = ticks_ % 2 == 0;
        out.push_back(e);
      }
    }
  }

 private:
  TimeNs next_imu_ns_ = 0;
  std::uint64_t ticks_ = 0;
};

struct FtmBoard : SensorBoard<FtmBoard> {
  static constexpr const char* kName = "FtmBoard";
  using Device = FtmBoardDevice;
  using Stats = FtmDeviceStats;
  using Options = FtmDeviceOptions;
  using Command = FtmCommand;
  using Server = FtmBoardEmulatorServer;
  static std::unique_ptr<Server> make_server(std::shared_ptr<hid::FakeHidLink> link) {
    auto emulator = FtmBoardEmulator::create({}, std::make_unique<HandAtRestFeed>());
    EXPECT_TRUE(emulator.ok()) << (emulator.ok() ? "" : emulator.error().message);
    return std::make_unique<Server>(std::move(*emulator), std::move(link));
  }
  static Result<Command> decode_command(std::span<const std::uint8_t> b) { return decode_ftm_command(b); }
};

// ---------------------------------------------------------------------------
// The fingertip device (fingertip_device.hpp: "When the device is gone,
// command() still returns at once, with not_connected, and nothing queued
// then is sent after a reconnect").

struct FingertipBoard {
  static constexpr const char* kName = "Fingertip";
  using Device = FingertipDevice;
  using Stats = FingertipDeviceStats;
  using Server = FingertipEmulatorServer;
  static constexpr CommandsWhileDisconnected kCommandsWhileDisconnected = CommandsWhileDisconnected::refused;

  static std::unique_ptr<Server> make_server(std::shared_ptr<hid::FakeHidLink> link) {
    auto emulator = FingertipEmulator::create({});
    EXPECT_TRUE(emulator.ok()) << (emulator.ok() ? "" : emulator.error().message);
    return std::make_unique<Server>(std::move(*emulator), std::move(link));
  }
  // Its reads wait poll_interval_ns (1 ms) already.
  static FingertipDeviceOptions driver_options() { return quick_link<FingertipDeviceOptions>(); }
  static void on_delivery(Device& d, std::function<void()> f) {
    d.set_feedback_callback([f = std::move(f)](const FingertipFeedbackSample&) { f(); });
  }
  static std::uint64_t accepted_reports(const Stats& s) { return s.feedback.accepted; }
  static std::uint64_t bad_reports(const Stats& s) {
    return s.feedback.crc_failures + s.feedback.bad_versions + s.feedback.malformed;
  }
  static bool command(Device& d) { return d.command_force(0.5, 0.0, 0.0) == FingertipCommandStatus::queued; }
  static bool is_test_command(std::span<const std::uint8_t> write) {
    FingertipCommand c;
    return decode_fingertip_command(write, c).ok() && c.mode == FingertipMode::force;
  }
};

// ---------------------------------------------------------------------------

// One driver on its own cable, with its device's emulator at the other end.
// Destroyed in reverse: the driver first (its stop() still reaches the
// device), then the emulator.
template <typename T>
struct Rig {
  explicit Rig(hid::FakeHidFaults faults = {})
      : link(std::make_shared<hid::FakeHidLink>(MonotonicClock::instance(), faults)),
        server(T::make_server(link)),
        device(std::make_unique<hid::FakeHidTransport>(link), T::driver_options()) {
    device.set_state_callback([this](hid::LinkState s, std::string_view detail) {
      std::lock_guard lock(mutex);
      states.push_back(s);
      details += std::string(hid::to_string(s)) + ": " + std::string(detail) + "\n";
    });
    T::on_delivery(device, [this] { delivered.fetch_add(1, std::memory_order_relaxed); });
  }
  ~Rig() {
    device.stop();
    server->stop();
  }
  Rig(const Rig&) = delete;
  Rig& operator=(const Rig&) = delete;

  typename T::Stats stats() { return device.stats(); }
  std::uint64_t accepted() { return T::accepted_reports(device.stats()); }
  std::vector<hid::LinkState> state_log() {
    std::lock_guard lock(mutex);
    return states;
  }
  std::string log() {
    std::lock_guard lock(mutex);
    return details;
  }
  // Streaming, and at least `reports` more accepted than `since`.
  bool streams(std::uint64_t since = 0, std::uint64_t reports = 10) {
    return wait_until([&] { return device.state() == hid::LinkState::streaming && accepted() >= since + reports; });
  }

  std::shared_ptr<hid::FakeHidLink> link;
  std::unique_ptr<typename T::Server> server;
  std::mutex mutex;
  std::vector<hid::LinkState> states;
  std::string details;
  std::atomic<std::uint64_t> delivered{0};
  typename T::Device device;
};

// stop() on another thread, so that a driver that hangs fails the test
// instead of the whole binary.
template <typename Device>
bool stops_within_deadline(Device& device) {
  auto done = std::async(std::launch::async, [&] { device.stop(); });
  return done.wait_for(20s) == std::future_status::ready;
}

template <typename T>
class HidDriverConformance : public ::testing::Test {};

struct DriverName {
  template <typename T>
  static std::string GetName(int) {
    return T::kName;
  }
};

using Drivers = ::testing::Types<ImuGloveBoard, StretchBoard, FtmBoard, FingertipBoard>;
TYPED_TEST_SUITE(HidDriverConformance, Drivers, DriverName);

TYPED_TEST(HidDriverConformance, ConnectsAndStreams) {
  Rig<TypeParam> rig;
  rig.server->start();
  ASSERT_TRUE(rig.device.start().ok());
  EXPECT_TRUE(rig.device.running());
  ASSERT_TRUE(rig.streams()) << rig.log();
  ASSERT_TRUE(wait_until([&] { return rig.delivered.load() > 0; }));
  const auto st = rig.stats();
  EXPECT_EQ(st.connects, 1u);
  EXPECT_EQ(st.disconnects, 0u);
  EXPECT_TRUE(st.have_info);
  EXPECT_EQ(TypeParam::bad_reports(st), 0u);
  const auto log = rig.state_log();
  ASSERT_GE(log.size(), 2u) << rig.log();
  EXPECT_EQ(log[0], hid::LinkState::connecting);
  EXPECT_EQ(log[1], hid::LinkState::streaming);
  EXPECT_FALSE(rig.device.start().ok()) << "a second start() while running must be refused";
}

TYPED_TEST(HidDriverConformance, SurvivesAnUnplugMidStreamAndReconnects) {
  Rig<TypeParam> rig;
  rig.server->start();
  ASSERT_TRUE(rig.device.start().ok());
  ASSERT_TRUE(rig.streams()) << rig.log();
  rig.link->unplug_for(300 * kNsPerMillisecond);
  ASSERT_TRUE(wait_until([&] { return rig.stats().disconnects >= 1; })) << rig.log();
  // Back off while the cable is out: open() fails at least once and is tried again.
  ASSERT_TRUE(wait_until([&] { return rig.stats().open_failures >= 1; })) << rig.log();
  ASSERT_TRUE(wait_until([&] { return rig.stats().connects >= 2; })) << rig.log();
  const std::uint64_t after_reconnect = rig.accepted();
  ASSERT_TRUE(rig.streams(after_reconnect)) << rig.log();
  const auto st = rig.stats();
  EXPECT_GE(st.connects, 2u);
  EXPECT_GE(st.disconnects, 1u);
  EXPECT_GE(st.open_failures, 1u);
  const auto log = rig.state_log();
  auto at = std::find(log.begin(), log.end(), hid::LinkState::streaming);
  ASSERT_NE(at, log.end()) << rig.log();
  at = std::find(at, log.end(), hid::LinkState::disconnected);
  ASSERT_NE(at, log.end()) << rig.log();
  EXPECT_NE(std::find(at, log.end(), hid::LinkState::streaming), log.end()) << rig.log();
}

TYPED_TEST(HidDriverConformance, CountsCorruptedReportsAsBadWithoutStopping) {
  hid::FakeHidFaults faults;
  faults.corrupt_probability = 0.05;
  faults.seed = 5;
  Rig<TypeParam> rig(faults);
  rig.server->start();
  ASSERT_TRUE(rig.device.start().ok());
  ASSERT_TRUE(wait_until([&] { return TypeParam::bad_reports(rig.stats()) >= 3; }))
      << "corrupted on the link: " << rig.link->stats().corrupted << "\n"
      << rig.log();
  // The stream goes on past them, on the same connection.
  ASSERT_TRUE(rig.streams(rig.accepted())) << rig.log();
  const auto st = rig.stats();
  EXPECT_EQ(st.connects, 1u);
  EXPECT_EQ(st.disconnects, 0u);
  EXPECT_LE(TypeParam::bad_reports(st), rig.link->stats().corrupted);
}

TYPED_TEST(HidDriverConformance, StopReturnsFromAnyStateAndTheDriverCanStartAgain) {
  {
    SCOPED_TRACE("never started");
    Rig<TypeParam> rig;
    ASSERT_TRUE(stops_within_deadline(rig.device));
    EXPECT_FALSE(rig.device.running());
    EXPECT_EQ(rig.device.state(), hid::LinkState::stopped);
  }
  {
    SCOPED_TRACE("retrying: no device on the cable");
    Rig<TypeParam> rig;
    rig.link->unplug_for(3600 * kNsPerSecond);
    ASSERT_TRUE(rig.device.start().ok());
    ASSERT_TRUE(wait_until([&] { return rig.stats().open_failures >= 3; })) << rig.log();
    ASSERT_TRUE(stops_within_deadline(rig.device));
    EXPECT_FALSE(rig.device.running());
    EXPECT_EQ(rig.device.state(), hid::LinkState::stopped);
    EXPECT_EQ(rig.stats().state, hid::LinkState::stopped);
    ASSERT_TRUE(stops_within_deadline(rig.device)) << "a second stop()";
  }
  {
    SCOPED_TRACE("streaming, then started again");
    Rig<TypeParam> rig;
    rig.server->start();
    ASSERT_TRUE(rig.device.start().ok());
    ASSERT_TRUE(rig.streams()) << rig.log();
    ASSERT_TRUE(stops_within_deadline(rig.device));
    EXPECT_FALSE(rig.device.running());
    EXPECT_EQ(rig.device.state(), hid::LinkState::stopped);
    ASSERT_TRUE(rig.device.start().ok());
    EXPECT_TRUE(rig.device.running());
    ASSERT_TRUE(rig.streams(rig.accepted())) << rig.log();
    ASSERT_TRUE(stops_within_deadline(rig.device));
    EXPECT_EQ(rig.device.state(), hid::LinkState::stopped);
  }
}

TYPED_TEST(HidDriverConformance, CommandsIssuedWhileDisconnectedAreHandledAsDocumented) {
  Rig<TypeParam> rig;
  rig.server->start();
  // Long enough that the command below is certainly issued before the cable is back.
  rig.link->unplug_for(2 * kNsPerSecond);
  ASSERT_TRUE(rig.device.start().ok());
  ASSERT_TRUE(wait_until([&] { return rig.stats().open_failures >= 1; })) << rig.log();
  const bool taken = TypeParam::command(rig.device);
  ASSERT_FALSE(rig.link->plugged()) << "the machine was too slow to issue the command while disconnected";
  ASSERT_NE(rig.device.state(), hid::LinkState::streaming);
  ASSERT_TRUE(rig.streams()) << rig.log();
  const auto sent = [&] {
    const auto writes = rig.link->writes();
    return std::count_if(writes.begin(), writes.end(), [](const Bytes& w) { return TypeParam::is_test_command(w); });
  };
  if constexpr (TypeParam::kCommandsWhileDisconnected == CommandsWhileDisconnected::queued_until_connected) {
    EXPECT_TRUE(taken);
    ASSERT_TRUE(wait_until([&] { return sent() >= 1; })) << "the queued command never reached the device";
    // Sent once, not again on every read.
    ASSERT_TRUE(rig.streams(rig.accepted()));
    EXPECT_EQ(sent(), 1);
  } else {
    EXPECT_FALSE(taken);
    // Many reads of the new connection later, still nothing of it went out.
    ASSERT_TRUE(rig.streams(rig.accepted(), 50)) << rig.log();
    EXPECT_EQ(sent(), 0);
  }
  // Connected, the same command goes out (which also shows sent() sees one).
  const auto before = sent();
  EXPECT_TRUE(TypeParam::command(rig.device));
  EXPECT_TRUE(wait_until([&] { return sent() > before; })) << "a command issued while streaming never went out";
}

TYPED_TEST(HidDriverConformance, NothingIsReadOrDeliveredAfterStop) {
  Rig<TypeParam> rig;
  rig.server->start();
  ASSERT_TRUE(rig.device.start().ok());
  ASSERT_TRUE(rig.streams()) << rig.log();
  ASSERT_TRUE(wait_until([&] { return rig.delivered.load() > 0; }));
  ASSERT_TRUE(stops_within_deadline(rig.device));
  const std::uint64_t delivered = rig.delivered.load();
  const auto st = rig.stats();
  const std::uint64_t link_delivered = rig.link->stats().delivered;
  // The device goes on sending: wait until reports are there for the taking.
  ASSERT_TRUE(wait_until([&] { return rig.link->pending() >= 5; }));
  EXPECT_EQ(rig.delivered.load(), delivered);
  EXPECT_EQ(rig.link->stats().delivered, link_delivered);
  EXPECT_EQ(rig.stats().reports_read, st.reports_read);
  EXPECT_EQ(rig.stats().state, hid::LinkState::stopped);
  EXPECT_EQ(rig.state_log().back(), hid::LinkState::stopped);
}

}  // namespace
}  // namespace proprio::devices::hid_conformance_test
