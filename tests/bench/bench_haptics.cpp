// The haptics hot path: one MuJoCo step of the hand plus the peg-in-hole
// scene with the hand pressing on the peg, and one whole servo tick (step,
// fingertip forces, three safety gates, three device models).
#include <benchmark/benchmark.h>

#include "proprio/haptics/contact_sim.hpp"
#include "proprio/haptics/device_model.hpp"
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

}  // namespace
