// Detection-level stereo marker simulation: cost of one stereo frame of the
// default 37-marker glove on a free-moving hand (docs/benchmarks.md).
#include <benchmark/benchmark.h>

#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/sim/stereo_sim.hpp"
#include "proprio/sim/subjects.hpp"

using namespace proprio;

namespace {

// Poses sampled up front so only the stereo simulation is timed: 20 s of free
// motion at the rig's 30 Hz.
std::vector<sim::HandMotionFrame> free_motion_at_30hz(const HandShape& shape) {
  sim::HandMotionGenerator gen(HandModel(shape), sim::HandMotionOptions{});
  std::vector<sim::HandMotionFrame> motion;
  for (int k = 0; k < 600; ++k) motion.push_back(gen.sample(k * 33'333'333LL));
  return motion;
}

// Arg 0: occlusion off, 1: on.
void BM_StereoSimulateFrame(benchmark::State& state) {
  const HandShape shape = *sim::sim_subject(3)->shape();
  sim::StereoSimOptions o;
  o.occlusion = state.range(0) != 0;
  auto simulator = sim::StereoMarkerSimulator::create(ImuGloveDescription::vist_default(), shape, o);
  if (!simulator.ok()) {
    state.SkipWithError(simulator.error().message.c_str());
    return;
  }
  const std::vector<sim::HandMotionFrame> motion = free_motion_at_30hz(shape);
  std::size_t i = 0;
  std::size_t seen = 0;
  for (auto _ : state) {
    const auto& m = motion[i];
    const sim::StereoFrame f = simulator->simulate(m.pose, m.T_world_head, m.time_ns);
    seen += f.cameras[0].markers.size() + f.cameras[1].markers.size();
    benchmark::DoNotOptimize(f);
    i = (i + 1) % motion.size();
  }
  state.counters["markers_seen_per_frame"] =
      benchmark::Counter(static_cast<double>(seen) / static_cast<double>(state.iterations()));
  state.SetLabel(o.occlusion ? "37 markers, occlusion on" : "37 markers, occlusion off");
}
BENCHMARK(BM_StereoSimulateFrame)->Arg(1)->Arg(0);

// With ground truth filled in, as a session recorder does.
void BM_StereoSimulateFrameWithTruth(benchmark::State& state) {
  const HandShape shape = *sim::sim_subject(3)->shape();
  auto simulator = sim::StereoMarkerSimulator::create(ImuGloveDescription::vist_default(), shape, {});
  if (!simulator.ok()) {
    state.SkipWithError(simulator.error().message.c_str());
    return;
  }
  const std::vector<sim::HandMotionFrame> motion = free_motion_at_30hz(shape);
  std::size_t i = 0;
  sim::StereoGroundTruth truth;
  for (auto _ : state) {
    const auto& m = motion[i];
    benchmark::DoNotOptimize(simulator->simulate(m.pose, m.T_world_head, m.time_ns, &truth));
    i = (i + 1) % motion.size();
  }
}
BENCHMARK(BM_StereoSimulateFrameWithTruth);

}  // namespace
