// FingertipDevice end to end over the fake HID link, with the emulated device
// served in real time: commands reach the device and feedback comes back, an
// unplug mid-run is a clean disconnected state and the driver reconnects, two
// devices run side by side, and command()/latest_feedback() neither allocate
// nor block.
//
// Threads: every wait is for a condition with a generous deadline (20 s),
// never a fixed sleep, so the tests also pass under ASan/TSan on a loaded
// machine. Nothing here asserts how fast anything is.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <mutex>
#include <new>
#include <string>
#include <thread>
#include <vector>

#include "proprio/fingertip_device/fingertip_device.hpp"
#include "proprio/fingertip_device/fingertip_emulator.hpp"

// Counts allocations made by the thread that asks for it, to show that the
// servo-thread calls allocate nothing.
namespace {
thread_local bool t_count_allocations = false;
thread_local std::size_t t_allocations = 0;
void* counted_alloc(std::size_t n) {
  if (t_count_allocations) ++t_allocations;
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
}  // namespace
void* operator new(std::size_t n) { return counted_alloc(n); }
void* operator new[](std::size_t n) { return counted_alloc(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace proprio::devices {
namespace {

using namespace std::chrono_literals;

template <typename Pred>
bool wait_until(Pred pred, std::chrono::seconds timeout = 20s) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(1ms);
  }
  return true;
}

FingertipDeviceOptions test_options() {
  FingertipDeviceOptions o;
  o.reconnect_backoff_min_ns = 20 * kNsPerMillisecond;
  o.reconnect_backoff_max_ns = 200 * kNsPerMillisecond;
  return o;
}

FingertipEmulator make_emulator(const FingertipEmulatorOptions& o) {
  auto e = FingertipEmulator::create(o);
  EXPECT_TRUE(e.ok()) << (e.ok() ? "" : e.error().message);
  return std::move(e).value();
}

struct StateLog {
  std::mutex mutex;
  std::vector<FingertipLinkState> states;
  std::vector<std::string> details;
  void add(FingertipLinkState s, std::string_view d) {
    std::lock_guard lock(mutex);
    states.push_back(s);
    details.emplace_back(d);
  }
  std::vector<FingertipLinkState> copy() {
    std::lock_guard lock(mutex);
    return states;
  }
  std::string all_details() {
    std::lock_guard lock(mutex);
    std::string s;
    for (const auto& d : details) s += d + "\n";
    return s;
  }
};

// One fingertip device on its own cable, and the driver for it. Destroyed in
// reverse: the driver first (its stop() still reaches the device), then the device.
struct Rig {
  explicit Rig(FingertipEmulatorOptions device_options = {}, FingertipDeviceOptions driver_options = test_options())
      : server(make_emulator(device_options), link),
        device(std::make_unique<hid::FakeHidTransport>(link), driver_options) {
    device.set_state_callback([this](FingertipLinkState s, std::string_view d) { log.add(s, d); });
    server.start();
  }
  std::shared_ptr<hid::FakeHidLink> link = std::make_shared<hid::FakeHidLink>();
  FingertipEmulatorServer server;
  StateLog log;
  FingertipDevice device;
};

// The 1 kHz servo loop: its own thread, calling command() and nothing else.
class Servo {
 public:
  Servo(FingertipDevice& device, FingertipSetpoint setpoint)
      : thread_([this, &device, setpoint] {
          while (!stop_.load()) {
            const FingertipCommandStatus s = device.command(setpoint);
            counts_[static_cast<std::size_t>(s)].fetch_add(1);
            std::this_thread::sleep_for(1ms);
          }
        }) {}
  ~Servo() { halt(); }
  void halt() {
    stop_.store(true);
    if (thread_.joinable()) thread_.join();
  }
  std::uint64_t count(FingertipCommandStatus s) const { return counts_[static_cast<std::size_t>(s)].load(); }

 private:
  std::atomic<bool> stop_{false};
  std::array<std::atomic<std::uint64_t>, 4> counts_{};
  std::thread thread_;
};

FingertipSetpoint force(double normal_n, double shear_x_n = 0.0, double shear_z_n = 0.0) {
  FingertipSetpoint s;
  s.mode = FingertipMode::force;
  s.values = {normal_n, shear_x_n, shear_z_n};
  return s;
}

// The main thread is the feedback consumer in these tests. Only feedback
// read after `since` counts: after a reconnect the newest sample is the last
// one of the old connection until new ones arrive.
bool wait_for_force(FingertipDevice& d, double normal_n, FingertipFeedbackSample& out, TimeNs since = 0) {
  return wait_until([&] {
    return d.latest_feedback(out) && out.receive_ns > since && out.has(fingertip_status::enabled) &&
           !out.has(fingertip_status::ramping) && std::abs(out.fsr_force_n[0] - normal_n) <= 0.05 * normal_n;
  });
}

TEST(FingertipDevice, SelectorAndEnumerationFindFingertipDevices) {
  const hid::HidDeviceSelector any = fingertip_device_selector();
  EXPECT_EQ(any.vendor_id, 0x1209);
  EXPECT_EQ(any.product_id, 0x0003);
  EXPECT_EQ(any.usage_page, 0xFF00);
  EXPECT_TRUE(any.serial.empty());
  const hid::HidDeviceSelector one = fingertip_device_selector("FT-R-INDEX");
  EXPECT_EQ(one.serial, "FT-R-INDEX");
  EXPECT_NE(one.describe().find("FT-R-INDEX"), std::string::npos);
  EXPECT_EQ(fingertip_device_selector({}, "/dev/hidraw9").path, "/dev/hidraw9");
  // On a machine without the device (or without hidraw access) the list is
  // empty or the error says why; either way nothing else shows up in it.
  auto list = enumerate_fingertip_devices();
  if (list) {
    for (const hid::HidDeviceInfo& d : *list) {
      EXPECT_EQ(d.vendor_id, kFingertipUsbVendorId);
      EXPECT_EQ(d.product_id, kFingertipUsbProductId);
      EXPECT_TRUE(d.usage_page == kFingertipHidUsagePage || d.usage_page == 0);
    }
  } else {
    EXPECT_FALSE(list.error().message.empty());
  }
}

TEST(FingertipDevice, OptionsDescribeThemselvesAndBadOnesAreRefused) {
  FingertipDeviceOptions o;
  o.expected_hand = Handedness::right;
  o.expected_finger = Finger::index;
  EXPECT_NE(o.describe().find("right index"), std::string::npos) << o.describe();
  o.poll_interval_ns = 0;
  FingertipDevice d(std::make_unique<hid::FakeHidTransport>(std::make_shared<hid::FakeHidLink>()), o);
  const Status s = d.start();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("poll_interval_ns"), std::string::npos) << s.error().message;
}

TEST(FingertipDevice, CommandsReachTheDeviceAndFeedbackComesBack) {
  Rig rig;
  ASSERT_TRUE(rig.device.start().ok());
  ASSERT_TRUE(wait_until([&] { return rig.device.state() == FingertipLinkState::streaming; }))
      << rig.log.all_details();
  EXPECT_EQ(rig.device.motor_count(), 3);
  Servo servo(rig.device, force(1.0));
  FingertipFeedbackSample s;
  ASSERT_TRUE(wait_for_force(rig.device, 1.0, s)) << "last force " << s.fsr_force_n[0] << " status "
                                                  << describe_fingertip_status(s.status);
  EXPECT_EQ(s.mode, FingertipMode::force);
  EXPECT_EQ(s.motor_count, 3);
  // On the default 800 N/m pad through a 5 mm lever, 1 N is 0.25 rad. The
  // angle (from encoder counts and the info report's gear and resolution) and
  // the force reading describe the same tick: they agree within the sensor's
  // noise (2 mN σ) and one encoder count (1.5 mN).
  EXPECT_NEAR(s.output_angle_rad[0], 0.25, 0.02);
  EXPECT_NEAR(s.output_angle_rad[0] * 800.0 * 0.005, s.fsr_force_n[0], 0.012);
  EXPECT_NEAR(s.fsr_force_n[1], 0.0, 0.02);
  EXPECT_GT(s.current_a[0], 0.0);
  EXPECT_GT(s.time_ns, 0);
  EXPECT_LE(s.time_ns, s.receive_ns);
  EXPECT_GT(s.applied_host_time_ns, 0);
  EXPECT_LE(s.applied_host_time_ns, s.receive_ns);
  EXPECT_EQ(s.command_result, FingertipCommandResult::ok);
  servo.halt();
  ASSERT_TRUE(wait_until([&] { return rig.device.stats().round_trip_count > 0; }));
  const FingertipDeviceStats st = rig.device.stats();
  EXPECT_TRUE(st.have_info);
  EXPECT_EQ(st.info.serial_view(), "FTEMU-0001");
  EXPECT_EQ(st.info.kind, FingertipDeviceKind::force_vector);
  EXPECT_GT(st.commands_sent, 10u);
  EXPECT_GE(st.commands_published, st.commands_sent);
  EXPECT_GT(st.feedback.accepted, 10u);
  EXPECT_EQ(st.feedback.crc_failures, 0u);
  EXPECT_EQ(st.feedback.stale, 0u);
  EXPECT_EQ(servo.count(FingertipCommandStatus::invalid), 0u);
  // The device applied what the driver sent, in order.
  const FingertipEmulatorStats es = rig.server.emulator_stats();
  EXPECT_GT(es.commands_applied, 10u);
  EXPECT_EQ(es.commands_rejected, 0u);
  EXPECT_EQ(es.link.stale, 0u);
  std::printf("measured: command() to the feedback showing it applied, over the fake link: last %.2f ms, mean %.2f ms, "
              "max %.2f ms (%llu commands)\n",
              st.round_trip_last_ns / 1e6, st.round_trip_sum_ns / static_cast<double>(st.round_trip_count) / 1e6,
              st.round_trip_max_ns / 1e6, static_cast<unsigned long long>(st.round_trip_count));
}

TEST(FingertipDevice, CommandsWithoutADeviceOrWithBadValuesReturnAtOnce) {
  auto link = std::make_shared<hid::FakeHidLink>();
  link->unplug_for(3600 * kNsPerSecond);
  FingertipDevice d(std::make_unique<hid::FakeHidTransport>(link), test_options());
  EXPECT_EQ(d.command_force(1.0, 0, 0), FingertipCommandStatus::not_connected);
  ASSERT_TRUE(d.start().ok());
  ASSERT_TRUE(wait_until([&] { return d.state() == FingertipLinkState::disconnected; }));
  EXPECT_EQ(d.command_force(1.0, 0, 0), FingertipCommandStatus::not_connected);
  EXPECT_EQ(d.command_angles({0.1, 0.1, 0.1}), FingertipCommandStatus::not_connected);
  EXPECT_EQ(d.command_force(std::nan(""), 0, 0), FingertipCommandStatus::invalid);
  FingertipSetpoint idle;
  idle.mode = FingertipMode::idle;
  EXPECT_EQ(d.command(idle), FingertipCommandStatus::invalid);
  FingertipFeedbackSample s;
  EXPECT_FALSE(d.latest_feedback(s));
  ASSERT_TRUE(wait_until([&] { return d.stats().open_failures >= 2; }));  // it keeps trying
  d.stop();
  EXPECT_EQ(d.state(), FingertipLinkState::stopped);
  EXPECT_EQ(d.command_force(1.0, 0, 0), FingertipCommandStatus::not_connected);
}

TEST(FingertipDevice, AnUnplugMidRunIsACleanDisconnectAndItReconnects) {
  Rig rig;
  ASSERT_TRUE(rig.device.start().ok());
  Servo servo(rig.device, force(1.0));
  FingertipFeedbackSample s;
  ASSERT_TRUE(wait_for_force(rig.device, 1.0, s));
  const std::uint64_t not_connected_before = servo.count(FingertipCommandStatus::not_connected);
  rig.link->unplug_for(400 * kNsPerMillisecond);
  ASSERT_TRUE(wait_until([&] { return rig.device.state() == FingertipLinkState::disconnected; }));
  // The servo loop carries on; its commands come back not_connected.
  ASSERT_TRUE(wait_until([&] { return servo.count(FingertipCommandStatus::not_connected) > not_connected_before; }));
  ASSERT_TRUE(wait_until([&] { return rig.device.state() == FingertipLinkState::streaming; }))
      << rig.log.all_details();
  const TimeNs reconnected = MonotonicClock::instance().now_ns();
  // With no commands for 400 ms the device's watchdog returned it to rest;
  // the first command of the new connection (sequence_reset) enables it again.
  ASSERT_TRUE(wait_until([&] { return rig.server.emulator_stats().watchdog_trips >= 1; }));
  ASSERT_TRUE(wait_for_force(rig.device, 1.0, s, reconnected)) << describe_fingertip_status(s.status);
  servo.halt();
  const FingertipDeviceStats st = rig.device.stats();
  EXPECT_GE(st.disconnects, 1u);
  EXPECT_GE(st.connects, 2u);
  const std::vector<FingertipLinkState> states = rig.log.copy();
  auto at = std::find(states.begin(), states.end(), FingertipLinkState::streaming);
  ASSERT_NE(at, states.end());
  at = std::find(at, states.end(), FingertipLinkState::disconnected);
  ASSERT_NE(at, states.end()) << rig.log.all_details();
  EXPECT_NE(std::find(at, states.end(), FingertipLinkState::streaming), states.end()) << rig.log.all_details();
  EXPECT_GE(rig.server.emulator_stats().link.restarts, 1u);  // sequence_reset seen by the device
}

TEST(FingertipDevice, TwoDevicesOnTwoLinksRunSideBySide) {
  FingertipEmulatorOptions index;
  index.serial = "FT-R-INDEX";
  index.hand = Handedness::right;
  index.finger = Finger::index;
  FingertipEmulatorOptions thumb = index;
  thumb.serial = "FT-R-THUMB";
  thumb.finger = Finger::thumb;
  thumb.kind = FingertipDeviceKind::band_2dof;
  thumb.motor_count = 2;
  thumb.fsr_count = 2;
  FingertipDeviceOptions want_index = test_options();
  want_index.expected_hand = Handedness::right;
  want_index.expected_finger = Finger::index;
  FingertipDeviceOptions want_thumb = want_index;
  want_thumb.expected_finger = Finger::thumb;
  Rig a(index, want_index);
  Rig b(thumb, want_thumb);
  ASSERT_TRUE(a.device.start().ok());
  ASSERT_TRUE(b.device.start().ok());
  Servo servo_a(a.device, force(0.5));
  Servo servo_b(b.device, force(1.5, 0.4));
  FingertipFeedbackSample sa, sb;
  ASSERT_TRUE(wait_for_force(a.device, 0.5, sa));
  ASSERT_TRUE(wait_for_force(b.device, 1.5, sb));
  ASSERT_TRUE(wait_until([&] { return b.device.latest_feedback(sb) && std::abs(sb.fsr_force_n[1] - 0.4) < 0.03; }));
  EXPECT_EQ(sa.motor_count, 3);
  EXPECT_EQ(sb.motor_count, 2);
  servo_a.halt();
  servo_b.halt();
  EXPECT_EQ(a.device.stats().info.serial_view(), "FT-R-INDEX");
  EXPECT_EQ(b.device.stats().info.serial_view(), "FT-R-THUMB");
  // Each device rendered its own force, nothing of the other's.
  EXPECT_NEAR(a.server.with_emulator([](const FingertipEmulator& e) { return e.snapshot().fsr_force_n[1]; }), 0.0, 0.02);
}

TEST(FingertipDevice, ADeviceAssignedToAnotherFingertipIsNeverCommanded) {
  FingertipEmulatorOptions thumb;
  thumb.hand = Handedness::left;
  thumb.finger = Finger::thumb;
  FingertipDeviceOptions want_index = test_options();
  want_index.expected_finger = Finger::index;
  Rig rig(thumb, want_index);
  ASSERT_TRUE(rig.device.start().ok());
  ASSERT_TRUE(wait_until([&] { return rig.device.state() == FingertipLinkState::streaming; }));
  EXPECT_EQ(rig.device.command_force(1.0, 0, 0), FingertipCommandStatus::refused);
  FingertipFeedbackSample s;
  ASSERT_TRUE(wait_until([&] { return rig.device.latest_feedback(s); }));  // it is still read
  const FingertipDeviceStats st = rig.device.stats();
  EXPECT_TRUE(st.assignment_mismatch);
  EXPECT_EQ(st.commands_sent, 0u);
  EXPECT_NE(rig.log.all_details().find("WRONG FINGERTIP"), std::string::npos) << rig.log.all_details();
  EXPECT_EQ(rig.server.emulator_stats().commands_applied, 0u);
}

TEST(FingertipDevice, WhenTheServoLoopStopsTheDeviceWatchdogReturnsItToRest) {
  Rig rig;
  ASSERT_TRUE(rig.device.start().ok());
  Servo servo(rig.device, force(1.0));
  FingertipFeedbackSample s;
  ASSERT_TRUE(wait_for_force(rig.device, 1.0, s));
  servo.halt();  // nothing resends the last command on the servo loop's behalf
  ASSERT_TRUE(wait_until([&] {
    return rig.device.latest_feedback(s) && s.has(fingertip_status::watchdog_tripped) && s.fsr_force_n[0] < 0.05;
  })) << describe_fingertip_status(s.status) << " " << s.fsr_force_n[0];
  EXPECT_EQ(s.mode, FingertipMode::idle);
  EXPECT_EQ(rig.device.state(), FingertipLinkState::streaming);
}

TEST(FingertipDevice, StopDisablesTheDeviceAtOnceRatherThanByItsWatchdog) {
  FingertipEmulatorOptions slow_watchdog;
  slow_watchdog.safety.watchdog_ns = 60 * kNsPerSecond;  // so only the disable command can explain rest
  Rig rig(slow_watchdog);
  ASSERT_TRUE(rig.device.start().ok());
  Servo servo(rig.device, force(1.0));
  FingertipFeedbackSample s;
  ASSERT_TRUE(wait_for_force(rig.device, 1.0, s));
  servo.halt();
  rig.device.stop();
  ASSERT_TRUE(wait_until([&] {
    return rig.server.with_emulator([](const FingertipEmulator& e) {
      return !(e.snapshot().status & fingertip_status::enabled) && e.snapshot().fsr_force_n[0] < 0.05;
    });
  }));
  EXPECT_EQ(rig.server.emulator_stats().watchdog_trips, 0u);
}

TEST(FingertipDevice, ADeviceWithoutAnInfoReportIsNotConnectedAndTheReasonSaysWhy) {
  auto link = std::make_shared<hid::FakeHidLink>();  // no device end: no feature report
  StateLog log;
  FingertipDevice d(std::make_unique<hid::FakeHidTransport>(link), test_options());
  d.set_state_callback([&](FingertipLinkState st, std::string_view detail) { log.add(st, detail); });
  ASSERT_TRUE(d.start().ok());
  ASSERT_TRUE(wait_until([&] { return d.stats().info_failures >= 2; }));
  EXPECT_NE(d.state(), FingertipLinkState::streaming);
  EXPECT_EQ(d.command_force(0.5, 0, 0), FingertipCommandStatus::not_connected);
  EXPECT_NE(log.all_details().find("device-info report"), std::string::npos) << log.all_details();
  d.stop();
}

TEST(FingertipDevice, ASilentDeviceIsDroppedAndReconnected) {
  FingertipDeviceOptions o = test_options();
  o.silence_timeout_ns = 200 * kNsPerMillisecond;
  Rig rig({}, o);
  ASSERT_TRUE(rig.device.start().ok());
  FingertipFeedbackSample s;
  ASSERT_TRUE(wait_until([&] { return rig.device.latest_feedback(s); }));
  rig.server.stop();  // the device hangs: no more feedback, the cable still in
  ASSERT_TRUE(wait_until([&] { return rig.device.stats().silences >= 1; }));
  // The cable is still in, so it connects again at once (and, still hearing nothing, drops it again).
  ASSERT_TRUE(wait_until([&] { return rig.device.stats().connects >= 2; }));
}

// A host too busy to run the emulation in real time (a loaded CI machine
// under ASan) must not make each catch-up longer than the last: the device
// stalls instead, and says so in its stats.
TEST(FingertipEmulatorServer, FallingFarBehindStallsTheDeviceInsteadOfCatchingUp) {
  for (const DurationNs max_lag : {DurationNs{100 * kNsPerMillisecond}, DurationNs{0}}) {
    SCOPED_TRACE(max_lag);
    ManualClock clock(1'000 * kNsPerMillisecond);
    auto link = std::make_shared<hid::FakeHidLink>(clock);
    FingertipServeOptions serve;
    serve.max_lag_ns = max_lag;
    FingertipEmulatorServer server(make_emulator({}), link, serve, clock);
    server.start();
    clock.advance(50 * kNsPerMillisecond);
    server.pump();
    EXPECT_EQ(server.emulator_stats().stalls, 0u) << "50 ms behind is within the allowance";
    clock.advance(10'000 * kNsPerMillisecond);
    server.pump();
    const FingertipEmulatorStats stats = server.emulator_stats();
    EXPECT_EQ(server.with_emulator([](const FingertipEmulator& e) { return e.now_ns(); }), 10'050 * kNsPerMillisecond);
    if (max_lag > 0) {
      EXPECT_EQ(stats.stalls, 1u);
      EXPECT_EQ(stats.stalled_ticks, 9'999u) << "every tick but the one at 10.05 s";
      EXPECT_EQ(stats.ticks, 52u);
    } else {
      EXPECT_EQ(stats.stalls, 0u);
      EXPECT_EQ(stats.ticks, 10'051u);
    }
  }
}

TEST(FingertipDevice, CommandAndFeedbackNeitherAllocateNorFail) {
  Rig rig;
  ASSERT_TRUE(rig.device.start().ok());
  ASSERT_TRUE(wait_until([&] { return rig.device.state() == FingertipLinkState::streaming; }));
  FingertipFeedbackSample s;
  ASSERT_TRUE(wait_until([&] { return rig.device.latest_feedback(s); }));
  std::size_t queued = 0;
  t_allocations = 0;
  t_count_allocations = true;
  for (int i = 0; i < 2000; ++i) {
    queued += rig.device.command_force(0.2 + 1e-4 * i, 0.0, 0.0) == FingertipCommandStatus::queued;
    (void)rig.device.latest_feedback(s);
    (void)rig.device.fresh_feedback(s);
  }
  t_count_allocations = false;
  EXPECT_EQ(t_allocations, 0u);
  EXPECT_GT(queued, 0u);
  // The counter itself works.
  t_count_allocations = true;
  void* probe = ::operator new(16);
  t_count_allocations = false;
  ::operator delete(probe);
  EXPECT_GE(t_allocations, 1u);
}

}  // namespace
}  // namespace proprio::devices
