// The servo loop: forces flow from the contact simulation through the safety
// gates and device models to the sinks; study conditions; shutdown zeroes.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <thread>

#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/haptics/servo_loop.hpp"
#include "proprio/haptics/touch_script.hpp"

namespace proprio::haptics {
namespace {

std::shared_ptr<const FingertipDeviceModel> shipped_device(const char* name) {
  auto m = load_device_model(std::string(PROPRIO_SOURCE_DIR "/config/haptics/") + name + ".toml");
  EXPECT_TRUE(m) << m.error().message;
  return std::shared_ptr<const FingertipDeviceModel>(std::move(*m));
}
std::shared_ptr<const FingertipDeviceModel> force_vector_device() { return shipped_device("force_vector"); }

struct Rig {
  HandModel model{*HandShape::from_measurements(0.19, 0.09)};
  std::unique_ptr<ServoLoop> loop;
  std::shared_ptr<RecordingSink> index_sink = std::make_shared<RecordingSink>();
  std::unique_ptr<TouchScript> script;

  explicit Rig(ServoLoopOptions options = {}, std::shared_ptr<const FingertipDeviceModel> device = force_vector_device(),
               std::shared_ptr<FingertipSink> sink = nullptr) {
    // A table whose top is where the script presses.
    HapticScene scene;
    scene.floor_height_m.reset();
    scene.objects.push_back(SceneObject::box("table", Vec3(0.4, 0.02, 0.4), Pose{Quat::Identity(), Vec3(0, 0.98, -0.55)}));
    auto sim = ContactSimulation::create(model, Handedness::right, scene);
    EXPECT_TRUE(sim) << sim.error().message;
    TouchScriptOptions to;
    to.p_surface_in_world = Vec3(0, 1.0, -0.55);
    to.press_depth_m = 0.01;  // deep enough that the press is well above the noise
    script = std::make_unique<TouchScript>(sim->hand_model(), Handedness::right, to);
    Pose T;
    HandAngles a;
    script->at(0.0, T, a);
    sim->reset_hand(T, a);
    ServoChannel c;
    c.finger = Finger::index;
    c.model = std::move(device);
    c.sink = sink ? std::move(sink) : index_sink;
    std::vector<ServoChannel> channels;
    channels.push_back(c);
    auto l = ServoLoop::create(std::move(*sim), std::move(channels), options);
    EXPECT_TRUE(l) << l.error().message;
    loop = std::move(*l);
  }

  // Runs the touch script for [t0, t1) seconds of simulated time, 1 kHz.
  void run(double t0, double t1) {
    for (double t = t0; t < t1; t += 1e-3) {
      const TimeNs now = static_cast<TimeNs>(t * 1e9) + kNsPerSecond;
      Pose T;
      HandAngles a;
      script->at(t, T, a);
      loop->submit_tracked_hand(now, T, a);
      loop->tick(now);
    }
  }
};

TEST(ServoLoop, PressingTheTableReachesTheDeviceThroughTheGate) {
  Rig rig;
  rig.loop->engage(kNsPerSecond);
  rig.run(0.0, 2.5);  // approach, press, slide halfway
  const ServoSnapshot* snap = rig.loop->latest();
  ASSERT_NE(snap, nullptr);
  EXPECT_GT(snap->hands[0].contact[1].normal_n, 0.3) << "index presses the table";
  EXPECT_NEAR(rig.index_sink->measured().normal_n, snap->hands[0].on_pad[1].normal_n, 0.05 * snap->hands[0].on_pad[1].normal_n + 0.02)
      << "the device gets the simulation's force as the pad feels it, ramped in";
  EXPECT_TRUE(rig.index_sink->last_enabled());
  EXPECT_EQ(snap->channels[0].gate, GateState::active);
  EXPECT_LE(rig.index_sink->measured().normal_n, rig.loop->gate(0).limits().max_normal_n);
  // Sliding along +x: the finger is dragged back, shear opposes the motion.
  EXPECT_GT(snap->hands[0].proxy.joint(HandJoint::index_tip).p.y(), 0.999) << "the proxy stays on the table";
}

TEST(ServoLoop, WithoutHapticsTheDeviceGetsZeroWhileTheSimulationRuns) {
  ServoLoopOptions o;
  o.haptics_enabled = false;
  Rig rig(o);
  rig.loop->engage(kNsPerSecond);
  rig.run(0.0, 2.0);
  EXPECT_GT(rig.loop->latest()->hands[0].contact[1].normal_n, 0.3);
  EXPECT_EQ(rig.index_sink->measured().normal_n, 0.0);
}

TEST(ServoLoop, ForceScaleScalesWhatTheDeviceGetsNotTheSimulation) {
  ServoLoopOptions o;
  o.force_scale = 0.5;
  Rig half(o);
  Rig full;
  half.loop->engage(kNsPerSecond);
  full.loop->engage(kNsPerSecond);
  half.run(0.0, 2.0);
  full.run(0.0, 2.0);
  const double simulated = half.loop->latest()->hands[0].on_pad[1].normal_n;
  EXPECT_NEAR(simulated, full.loop->latest()->hands[0].on_pad[1].normal_n, 1e-9) << "the simulation does not see the scale";
  ASSERT_GT(simulated, 0.3);
  ASSERT_LT(simulated, 2.0 * half.loop->gate(0).limits().max_normal_n) << "else the clamp hides the scale";
  EXPECT_NEAR(half.index_sink->measured().normal_n, 0.5 * simulated, 0.03 * simulated + 0.01);
  o.force_scale = 0.0;
  EXPECT_FALSE(o.validate());
}

TEST(ServoLoop, WithoutAbductionTheFingersDoNotSpread) {
  ServoLoopOptions o;
  o.remove_finger_abduction = true;
  Rig rig(o);
  HandAngles a{};
  a[first_dof_of(Finger::index) + 1] = 0.3;
  a[first_dof_of(Finger::thumb) + 1] = 0.3;
  const Pose T{Quat::Identity(), Vec3(0, 1.3, -0.3)};
  rig.loop->simulation().reset_hand(T, HandAngles{});
  for (int i = 0; i < 300; ++i) {
    rig.loop->submit_tracked_hand(kNsPerSecond + i * kNsPerMillisecond, T, a);
    rig.loop->tick(kNsPerSecond + i * kNsPerMillisecond);
  }
  const HandAngles proxy = rig.loop->simulation().proxy_angles();
  EXPECT_NEAR(proxy[first_dof_of(Finger::index) + 1], 0.0, 0.01);
  EXPECT_NEAR(proxy[first_dof_of(Finger::thumb) + 1], 0.3, 0.02) << "the thumb keeps its CMC abduction";
}

TEST(ServoLoop, StaleOrBadHandsAreCountedAndTheProxyHolds) {
  Rig rig;
  rig.loop->engage(kNsPerSecond);
  rig.run(0.0, 0.2);
  HandPose inactive;
  rig.loop->submit_tracked_hand(inactive);
  Pose nan_pose{Quat::Identity(), Vec3(std::nan(""), 0, 0)};
  rig.loop->submit_tracked_hand(0, nan_pose, HandAngles{});
  const Pose before = rig.loop->simulation().proxy_wrist();
  for (int i = 0; i < 500; ++i) rig.loop->tick(2 * kNsPerSecond + i * kNsPerMillisecond);
  const ServoTiming t = rig.loop->timing();
  EXPECT_EQ(t.rejected_hands, 2u);
  EXPECT_GE(t.stale_hand_ticks, 300u);
  EXPECT_LT((rig.loop->simulation().proxy_wrist().p - before.p).norm(), 0.01);
}

TEST(ServoLoop, ThreadRunsAndStopZeroesTheDevices) {
  ServoLoopOptions o;
  o.realtime_priority = false;
  Rig rig(o);
  ASSERT_TRUE(rig.loop->start());
  EXPECT_FALSE(rig.loop->start());
  // Feed the pressing pose from this thread, as a tracker would.
  Pose T;
  HandAngles a;
  rig.script->at(1.5, T, a);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (rig.loop->timing().ticks < 300 && std::chrono::steady_clock::now() < deadline) {
    rig.loop->submit_tracked_hand(MonotonicClock::instance().now_ns(), T, a);
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  rig.loop->stop();
  EXPECT_FALSE(rig.loop->running());
  EXPECT_GE(rig.loop->timing().ticks, 300u);
  // The last thing each device heard: disabled, zero force, rest position.
  EXPECT_FALSE(rig.index_sink->last_enabled());
  EXPECT_EQ(rig.index_sink->measured().normal_n, 0.0);
  EXPECT_EQ(rig.index_sink->measured().shear_magnitude_n(), 0.0);
}

TEST(ServoLoop, EmulatedPlatformDeviceRendersTheCommandedForceOnItsSensors) {
  // Closed loop without hardware: the contact force goes through the gate and
  // the platform model's inverse kinematics to motor targets, over the wire
  // encoding to the emulated device, whose motors (PD, gearbox, fingertip
  // stiffness) move the plate; its force sensors read what the plate renders.
  auto platform = shipped_device("platform_3dof");
  auto device = EmulatedFingertip::create(platform);
  ASSERT_TRUE(device) << device.error().message;
  std::shared_ptr<EmulatedFingertip> sink = std::move(*device);
  Rig rig({}, platform, sink);
  rig.loop->engage(kNsPerSecond);
  rig.run(0.0, 1.9);  // approach, press, hold while the slide begins
  const ServoSnapshot* snap = rig.loop->latest();
  ASSERT_NE(snap, nullptr);
  const FingertipForce commanded = snap->channels[0].commanded;
  ASSERT_GT(commanded.normal_n, 0.3) << "the press reaches the device";
  const FingertipForce measured = sink->measured();
  EXPECT_NEAR(measured.normal_n, commanded.normal_n, 0.1 * commanded.normal_n + 0.05);
  EXPECT_NEAR(measured.shear_x_n, commanded.shear_x_n, 0.1 * commanded.shear_magnitude_n() + 0.05);
  EXPECT_NEAR(measured.shear_z_n, commanded.shear_z_n, 0.1 * commanded.shear_magnitude_n() + 0.05);
  EXPECT_EQ(sink->emulator().stats().faults_latched, 0u) << "no device fault on the way";
  EXPECT_EQ(sink->emulator().stats().commands_rejected, 0u);
  EXPECT_GE(sink->emulator().stats().commands_applied, 1800u) << "one command per tick reaches the motors";

  // Stopping disables the device; its motors return to rest.
  rig.loop->disengage_and_zero(3 * kNsPerSecond);
  for (int i = 1; i <= 200; ++i) rig.loop->tick(3 * kNsPerSecond + i * kNsPerMillisecond);
  EXPECT_LT(sink->measured().normal_n, 0.02);
}

// The demo's press (`proprio haptics sim`, default options): the pitched
// index finger meets the study's half cylinder with the end of its tip, the
// net contact force (16 N) runs along the finger's axis and the fingertip
// frame's normal is near zero or negative. The device must render the press
// all the same. TipEndPress runs one period of the script (approach, press,
// slide, lift) and compares, tick by tick, what the gate commands with what
// the device should render: `expected` (clamped to the device's normal limit)
// slewed at the device's rate limit, the gate's own limits, which stay.
struct TipEndPress {
  double max_deficit_n = 0.0, worst_t_s = 0.0;  // largest (reference - rendered) while in contact
  double max_excess_n = 0.0;                    // largest (rendered - reference - what shear may add)
  int pressing_ticks = 0, end_on_ticks = 0;
  double peak_contact_n = 0.0, peak_commanded_n = 0.0;
  std::uint64_t resets = 0;
};

TipEndPress press_the_tip_end(const std::shared_ptr<const FingertipDeviceModel>& device,
                              const std::function<double(const ServoSnapshot&)>& expected,
                              const std::function<double(const FingertipForce&)>& rendered) {
  TipEndPress r;
  const HandModel model(*HandShape::from_measurements(0.19, 0.09));
  const HapticScene scene = HapticScene::half_cylinder_study();
  const SceneObject& cylinder = *scene.find("half_cylinder");
  auto sim = ContactSimulation::create(model, Handedness::right, scene);
  EXPECT_TRUE(sim) << sim.error().message;
  if (!sim) return r;
  TouchScriptOptions to;  // the demo's press depth
  to.p_surface_in_world = cylinder.T_world_object.p + Vec3(0, cylinder.radius_m, 0);
  const TouchScript script(sim->hand_model(), Handedness::right, to);
  Pose T;
  HandAngles a;
  script.at(0.0, T, a);
  sim->reset_hand(T, a);
  const DeviceLimits limits = device->limits();
  std::vector<ServoChannel> channels(1);
  channels[0].finger = Finger::index;
  channels[0].model = device;
  channels[0].sink = std::make_shared<RecordingSink>();
  auto loop = ServoLoop::create(std::move(*sim), std::move(channels));
  EXPECT_TRUE(loop) << loop.error().message;
  if (!loop) return r;
  ServoLoop& servo = **loop;
  const TimeNs t0 = kNsPerSecond;
  servo.engage(t0);  // the ramp-in ends long before the touch
  double reference = 0.0;
  const double dt = 1e-3;
  for (int i = 0; i < static_cast<int>(to.period_s / dt); ++i) {
    const double t = i * dt;
    const TimeNs now = t0 + static_cast<TimeNs>(i) * kNsPerMillisecond;
    script.at(t, T, a);
    servo.submit_tracked_hand(now, T, a);
    servo.tick(now);
    const ServoSnapshot& snap = *servo.latest();
    const FingertipForce contact = snap.hands[0].contact[1];
    const double contact_n = contact.in_tip_frame().norm();
    const FingertipForce commanded = snap.channels[0].commanded;
    const double step = limits.max_rate_n_per_s * dt;
    reference += std::clamp(std::min(expected(snap), limits.max_normal_n) - reference, -step, step);
    r.peak_contact_n = std::max(r.peak_contact_n, contact_n);
    r.peak_commanded_n = std::max(r.peak_commanded_n, commanded.in_tip_frame().norm());
    EXPECT_LE(commanded.normal_n, limits.max_normal_n + 1e-9) << "t " << t;
    EXPECT_LE(commanded.shear_magnitude_n(), limits.max_shear_n + 1e-9) << "t " << t;
    r.max_excess_n = std::max(r.max_excess_n, rendered(commanded) - std::hypot(reference, limits.max_shear_n));
    if (contact_n < 0.05) continue;
    ++r.pressing_ticks;
    if (contact.normal_n <= 0.1 * contact_n && contact_n > 1.0) ++r.end_on_ticks;
    const double deficit = reference - rendered(commanded);
    if (deficit > r.max_deficit_n) r.max_deficit_n = deficit, r.worst_t_s = t;
  }
  r.resets = servo.simulation().stats().instability_resets;
  return r;
}

// A 3-DOF force device renders the vector: its magnitude follows the contact
// force's magnitude up to the device's limit.
TEST(ServoLoop, ATipEndPressIsRenderedAsTheContactForcesMagnitudeThroughout) {
  auto device = force_vector_device();
  const double max_normal = device->limits().max_normal_n;
  const TipEndPress r = press_the_tip_end(
      device, [](const ServoSnapshot& s) { return s.hands[0].contact[1].in_tip_frame().norm(); },
      [](const FingertipForce& f) { return f.in_tip_frame().norm(); });
  ASSERT_GT(r.pressing_ticks, 1500) << "the script presses for most of a period";
  ASSERT_GT(r.end_on_ticks, 100) << "the press is on the tip's end (else this tests nothing new)";
  EXPECT_GT(r.peak_contact_n, 3.0 * max_normal) << "a hard press, well beyond the device's range";
  EXPECT_LT(r.max_deficit_n, 0.05 * max_normal) << "worst at t " << r.worst_t_s << " s";
  EXPECT_LT(r.max_excess_n, 0.05 * max_normal);
  EXPECT_GT(r.peak_commanded_n, 0.99 * max_normal);
  EXPECT_EQ(r.resets, 0u);
}

// The demo's band renders pressure and shear along the finger only: its
// pressure follows the contact's normal force (all of it, wherever on the
// fingertip) up to the device's limit.
TEST(ServoLoop, ATipEndPressIsRenderedAsPadPressureOnTheBand) {
  auto device = shipped_device("band_2dof");
  const double max_normal = device->limits().max_normal_n;
  const TipEndPress r = press_the_tip_end(
      device, [](const ServoSnapshot& s) { return s.hands[0].contact_normal_n[1]; },
      [](const FingertipForce& f) { return f.normal_n; });
  ASSERT_GT(r.end_on_ticks, 100);
  EXPECT_LT(r.max_deficit_n, 0.05 * max_normal) << "worst at t " << r.worst_t_s << " s";
  EXPECT_LT(r.max_excess_n, 0.05 * max_normal);
  EXPECT_EQ(r.resets, 0u);
}

TEST(ServoLoop, RejectsBadChannels) {
  HandModel model{*HandShape::from_measurements(0.19, 0.09)};
  HapticScene scene;
  auto make = [&]() -> ContactSimulation {
    auto sim = ContactSimulation::create(model, Handedness::right, scene);
    return std::move(*sim);
  };
  std::vector<ServoChannel> none(1);
  EXPECT_FALSE(ServoLoop::create(make(), none));
  std::vector<ServoChannel> twice(2);
  twice[0].model = twice[1].model = force_vector_device();
  EXPECT_FALSE(ServoLoop::create(make(), twice));
  ServoLoopOptions o;
  o.period_ns = 0;
  EXPECT_FALSE(ServoLoop::create(make(), {}, o));
}


// Issue 29: one loop, both hands. Tracked hands go to their own proxy by side,
// channels render their own hand's finger, and what an ExtraForces source adds
// (an app's forces) reaches only its channel; switches act at the next tick.
class PerChannelForces final : public ExtraForces {
 public:
  FingertipForce force(std::size_t channel, TimeNs) noexcept override {
    FingertipForce f;
    f.normal_n = channel == 0 ? 0.3 : 0.6;
    return f;
  }
};

TEST(ServoLoop, TwoHandsInOneLoop) {
  const HandModel model(*HandShape::from_measurements(0.19, 0.09));
  const ProxyHandSpec hands[] = {{model, Handedness::left}, {model, Handedness::right}};
  HapticScene scene;
  scene.floor_height_m.reset();
  auto sim = ContactSimulation::create(hands, scene);
  ASSERT_TRUE(sim) << sim.error().message;
  auto left_sink = std::make_shared<RecordingSink>(), right_sink = std::make_shared<RecordingSink>();
  std::vector<ServoChannel> channels;
  channels.push_back({Finger::index, force_vector_device(), left_sink, 0});
  channels.push_back({Finger::index, force_vector_device(), right_sink, 1});
  ServoLoopOptions options;
  options.force_scale = 5.0;  // contact only: the extra forces stay as asked
  auto loop = ServoLoop::create(std::move(*sim), channels, options);
  ASSERT_TRUE(loop) << loop.error().message;
  (*loop)->set_extra_forces(std::make_shared<PerChannelForces>());

  const Pose left_at{Quat::Identity(), Vec3(-0.3, 1.1, -0.3)}, right_at{Quat::Identity(), Vec3(0.3, 1.1, -0.3)};
  TimeNs now = kNsPerSecond;
  (*loop)->engage(now);
  for (int i = 0; i < 700; ++i, now += kNsPerMillisecond) {  // past the 0.4 s ramp-in
    (*loop)->submit_tracked_hand(model.forward(Handedness::left, HandAngles{}, left_at, now));
    (*loop)->submit_tracked_hand(model.forward(Handedness::right, HandAngles{}, right_at, now));
    (*loop)->tick(now);
  }
  const ServoSnapshot* snap = (*loop)->latest();
  ASSERT_NE(snap, nullptr);
  ASSERT_EQ(snap->hand_count, 2u);
  EXPECT_EQ(snap->hands[0].side, Handedness::left);
  EXPECT_LT((snap->hands[0].proxy.joint(HandJoint::wrist).p - left_at.p).norm(), 0.005) << "the left proxy follows the left hand";
  EXPECT_LT((snap->hands[1].proxy.joint(HandJoint::wrist).p - right_at.p).norm(), 0.005);
  EXPECT_NEAR(left_sink->measured().normal_n, 0.3, 1e-9);
  EXPECT_NEAR(right_sink->measured().normal_n, 0.6, 1e-9);
  EXPECT_EQ(snap->channels[1].hand, 1u);

  // Output off: zero at the next tick; on: ramps in from zero again.
  (*loop)->request_output(false);
  (*loop)->tick(now += kNsPerMillisecond);
  EXPECT_FALSE(right_sink->last_enabled());
  EXPECT_EQ(right_sink->measured().normal_n, 0.0);
  (*loop)->request_output(true);
  (*loop)->tick(now += kNsPerMillisecond);
  EXPECT_TRUE(right_sink->last_enabled());
  EXPECT_LT(right_sink->measured().normal_n, 0.05) << "ramping in";
  (*loop)->set_simulation_enabled(false);
  (*loop)->tick(now += kNsPerMillisecond);
  EXPECT_FALSE((*loop)->latest()->simulating);
  const std::uint64_t steps = (*loop)->simulation().stats().steps;
  (*loop)->tick(now += kNsPerMillisecond);
  EXPECT_EQ((*loop)->simulation().stats().steps, steps) << "no MuJoCo step while the simulation is off";

  // A side the world lacks, a hand index past it, a second channel on one finger: refused.
  auto one = ContactSimulation::create(model, Handedness::right, scene);
  ASSERT_TRUE(one);
  auto wrong = channels;
  EXPECT_FALSE(ServoLoop::create(std::move(*one), wrong, options)) << "channel on hand 1 of a one-hand world";
  auto two = ContactSimulation::create(hands, scene);
  ASSERT_TRUE(two);
  wrong[0].hand = 1;
  EXPECT_FALSE(ServoLoop::create(std::move(*two), wrong, options)) << "two channels on the right index";
}
}  // namespace
}  // namespace proprio::haptics
