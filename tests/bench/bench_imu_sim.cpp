#include <benchmark/benchmark.h>

#include <cstdio>
#include <string>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/sim/hand_motion.hpp"
#include "proprio/sim/imu_sim.hpp"
#include "proprio/sim/subjects.hpp"

using namespace proprio;

namespace {

// One 100 Hz tick of the thesis's seven-IMU glove on free motion: the hand
// pose is evaluated at each IMU's (jittered) instant and ±1 ms around it, so
// this is dominated by the motion generator's forward kinematics. Arg 0:
// datasheet noise with jitter (every IMU has its own instant, 21 pose
// evaluations per tick); arg 1: ideal sensors (one shared instant, 3 evaluations).
void BM_ImuSimulate7At100Hz(benchmark::State& state) {
  const HandShape shape = *sim::sim_subject(3)->shape();
  sim::HandMotionOptions mo;
  sim::HandMotionGenerator gen(HandModel(shape), mo);
  const bool ideal = state.range(0) == 1;
  const auto options = ideal ? sim::ImuNoiseOptions::ideal() : sim::ImuNoiseOptions{};
  auto sim = sim::ImuSimulator::create(gen, ImuGloveDescription::vist_default().place_imus(shape), options, 1);
  if (!sim.ok()) {
    state.SkipWithError(sim.error().message.c_str());
    return;
  }
  // The generator adds a keyframe every 3 s of simulated time; that growth
  // is a vector push per 300 ticks and does not show in the per-tick time.
  for (auto _ : state) benchmark::DoNotOptimize(sim->next().data());
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(sim->imu_count()));
  // Real-time factor: simulated time per tick (10 ms) over CPU time per tick
  // (Google Benchmark rates divide by CPU time), named in the label.
  state.counters["realtime_x"] =
      benchmark::Counter(1.0 / options.sample_rate_hz * static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate);
  state.SetLabel(ideal ? "ideal sensors, 7 IMUs; realtime_x = simulated s per CPU s"
                       : "datasheet noise + jitter, 7 IMUs; realtime_x = simulated s per CPU s");
}
BENCHMARK(BM_ImuSimulate7At100Hz)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

}  // namespace
