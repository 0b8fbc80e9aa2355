// The haptics hot path: one MuJoCo step of the hand plus the peg-in-hole
// scene with the hand pressing on the peg, and one whole servo tick (step,
// fingertip forces, three safety gates, three device models); and issue 29's
// servo target, one tick with both hands in one world pinching the peg
// (thumb and index of each), six emulated devices.
#include <benchmark/benchmark.h>

#include <algorithm>

#include "proprio/core/data_dir.hpp"
#include "proprio/haptics/contact_sim.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/haptics/servo_loop.hpp"
#include "proprio/haptics/touch_script.hpp"

using namespace proprio;
using namespace proprio::haptics;

namespace {

HandModel bench_hand() { return HandModel(*HandShape::from_measurements(0.19, 0.09)); }

// The index finger pressing down on the top of the standing peg: hand-peg and
// peg-table contacts are active, as in a grasp.
ContactSimulation pressing_on_peg(const HandModel& model, TouchScript*& script_out) {
  const HapticScene scene = HapticScene::peg_in_hole();
  const SceneObject& peg = *scene.find("peg");
  auto sim = ContactSimulation::create(model, Handedness::right, scene);
  if (!sim) throw std::runtime_error(sim.error().message);
  TouchScriptOptions o;
  o.p_surface_in_world = peg.T_world_object.p + Vec3(0.0, peg.half_length_m, 0.0);
  o.slide_m = 0.0;
  o.period_s = 1e9;  // stay in the approach phase: see below
  static std::unique_ptr<TouchScript> script;
  script = std::make_unique<TouchScript>(sim->hand_model(), Handedness::right, o);
  script_out = script.get();
  Pose T;
  HandAngles a;
  script->at(0.0, T, a);
  sim->reset_hand(T, a);
  return std::move(*sim);
}

void BM_ContactSimStepPegInHolePressing(benchmark::State& state) {
  const HandModel model = bench_hand();
  TouchScript* script = nullptr;
  auto sim = pressing_on_peg(model, script);
  // Lower the tracked hand 1 cm into the peg's top and let contacts settle.
  Pose T;
  HandAngles a;
  script->at(0.0, T, a);
  T.p.y() -= 0.07;
  sim.set_target(T, a);
  for (int i = 0; i < 500; ++i) sim.step();
  for (auto _ : state) sim.step();
  state.counters["contacts"] = sim.stats().last_contact_count;
  state.counters["index_normal_N"] = sim.fingertip(Finger::index).force.normal_n;
}
BENCHMARK(BM_ContactSimStepPegInHolePressing)->Unit(benchmark::kMicrosecond);

void BM_ContactSimStepFreeSpace(benchmark::State& state) {
  HapticScene scene;
  scene.floor_height_m.reset();
  auto sim = ContactSimulation::create(bench_hand(), Handedness::right, scene);
  for (auto _ : state) sim->step();
}
BENCHMARK(BM_ContactSimStepFreeSpace)->Unit(benchmark::kMicrosecond);

void BM_ServoTickPegInHolePressing(benchmark::State& state) {
  const HandModel model = bench_hand();
  TouchScript* script = nullptr;
  auto sim = pressing_on_peg(model, script);
  Pose T;
  HandAngles a;
  script->at(0.0, T, a);
  T.p.y() -= 0.07;
  std::vector<ServoChannel> channels;
  for (Finger f : {Finger::thumb, Finger::index, Finger::middle}) {
    auto device = load_device_model(PROPRIO_SOURCE_DIR "/config/haptics/force_vector.toml");
    ServoChannel c;
    c.finger = f;
    c.model = device ? std::shared_ptr<const FingertipDeviceModel>(std::move(*device)) : nullptr;
    c.sink = std::make_shared<RecordingSink>();
    channels.push_back(std::move(c));
  }
  auto loop = ServoLoop::create(std::move(sim), std::move(channels));
  if (!loop) {
    state.SkipWithError(loop.error().message.c_str());
    return;
  }
  TimeNs now = 0;
  (*loop)->engage(now);
  (*loop)->submit_tracked_hand(now, T, a);
  for (int i = 0; i < 500; ++i) (*loop)->tick(now += kNsPerMillisecond);
  for (auto _ : state) {
    (*loop)->tick(now += kNsPerMillisecond);
    // Keep the tracked hand fresh, as a tracker thread would.
    if ((now / kNsPerMillisecond) % 10 == 0) (*loop)->submit_tracked_hand(now, T, a);
  }
}
BENCHMARK(BM_ServoTickPegInHolePressing)->Unit(benchmark::kMicrosecond);

// Issue 29's target: one servo tick with both hands in one world, thumb and
// index of each pinching the standing peg (left hand from -x 3.5 cm below
// the peg's middle, right from +x 3 cm above it), six emulated platform_3dof
// devices (thumb, index, middle per hand) behind the real wire encoding.
// The hands close on the peg over 0.5 s of simulated ticks and settle for
// 1 s; every timed tick must leave all four pinching pads pressed (filtered
// pad force > 0.05 N), or the benchmark fails instead of timing something
// else. The same case is `proprio bench haptics`'s two-hand figure.
void BM_ServoTickTwoHandsPinchingPeg(benchmark::State& state) {
  const HandModel hand(*HandShape::from_measurements(0.19, 0.10));
  const HapticScene scene = HapticScene::peg_in_hole();
  const ProxyHandSpec specs[] = {{hand, Handedness::left}, {hand, Handedness::right}};
  auto world = ContactSimulation::create(specs, scene);
  if (!world) {
    state.SkipWithError(world.error().message.c_str());
    return;
  }
  auto pinches = pinch_peg_with_both_hands(hand, scene);
  if (!pinches) {
    state.SkipWithError(pinches.error().message.c_str());
    return;
  }
  const std::array<CylinderPinch, 2>& pinch = *pinches;
  for (std::size_t h = 0; h < 2; ++h) world->reset_hand(pinch[h].T_world_wrist_start, pinch[h].open, h);
  auto device = load_device_model(data_path("haptics/platform_3dof.toml"));
  if (!device) {
    state.SkipWithError(device.error().message.c_str());
    return;
  }
  const std::shared_ptr<const FingertipDeviceModel> model(std::move(*device));
  std::vector<ServoChannel> channels;
  for (std::size_t h = 0; h < 2; ++h) {
    for (Finger f : {Finger::thumb, Finger::index, Finger::middle}) {
      auto sink = EmulatedFingertip::create(model);
      if (!sink) {
        state.SkipWithError(sink.error().message.c_str());
        return;
      }
      channels.push_back({f, model, std::shared_ptr<FingertipSink>(std::move(*sink)), h});
    }
  }
  ServoLoopOptions options;
  options.realtime_priority = false;  // ticked here, not on the loop's thread
  auto loop = ServoLoop::create(std::move(*world), std::move(channels), options);
  if (!loop) {
    state.SkipWithError(loop.error().message.c_str());
    return;
  }
  ServoLoop& servo = **loop;
  TimeNs now = MonotonicClock::instance().now_ns();
  servo.engage(now);
  const auto submit = [&](double closing) {
    for (std::size_t h = 0; h < 2; ++h) {
      const CylinderPinch& p = pinch[h];
      HandAngles a;
      for (std::size_t d = 0; d < kHandDofCount; ++d) a[d] = p.open[d] + closing * (p.closed[d] - p.open[d]);
      const Pose T{p.T_world_wrist.q, p.T_world_wrist_start.p + closing * (p.T_world_wrist.p - p.T_world_wrist_start.p)};
      servo.submit_tracked_hand(now, T, a, h);
    }
  };
  for (int i = 0; i < 1500; ++i) {
    submit(std::min(1.0, i / 500.0));
    servo.tick(now += kNsPerMillisecond);
  }
  const ContactSimulation& sim = servo.simulation();
  double least_pad_n = 1e9;
  std::int64_t ticks_without_contact = 0;
  std::int64_t ticks = 0;
  for (auto _ : state) {
    // Keep the tracked hands fresh, as a tracker thread would.
    if (++ticks % 10 == 0) submit(1.0);
    servo.tick(now += kNsPerMillisecond);
    for (std::size_t h = 0; h < 2; ++h) {
      for (Finger f : {Finger::thumb, Finger::index}) {
        const FingertipContact& c = sim.fingertip(f, h);
        least_pad_n = std::min(least_pad_n, c.on_pad.normal_n);
        ticks_without_contact += c.contact_count == 0;
      }
    }
  }
  state.counters["least_pad_N"] = least_pad_n;
  state.counters["tips_without_contact"] = static_cast<double>(ticks_without_contact);
  state.counters["contacts"] = sim.stats().last_contact_count;
  if (!(least_pad_n > 0.05)) {
    state.SkipWithError("the two-hand case did not run as specified: a pinching fingertip (thumb or index) left "
                        "the peg during the timed ticks");
  }
}
BENCHMARK(BM_ServoTickTwoHandsPinchingPeg)->Unit(benchmark::kMicrosecond);

}  // namespace
