#include <benchmark/benchmark.h>

#include "proprio/sim/hand_motion.hpp"
#include "proprio/sim/subjects.hpp"

using namespace proprio;

namespace {

void BM_HandMotionSample(benchmark::State& state) {
  sim::HandMotionOptions o;
  o.protocol = static_cast<sim::MotionProtocol>(state.range(0));
  sim::HandMotionGenerator g(HandModel(*sim::sim_subject(3)->shape()), o);
  TimeNs t = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(g.sample(t));
    t += 11'111'111;  // 90 Hz
  }
  state.SetLabel(std::string(sim::to_string(o.protocol)));
}
BENCHMARK(BM_HandMotionSample)->DenseRange(0, 2);

void BM_SolvePinch(benchmark::State& state) {
  const HandModel m(*sim::sim_subject(3)->shape());
  HandAngles start{};
  start[0] = 0.5;
  start[4] = 0.7;
  for (auto _ : state) benchmark::DoNotOptimize(sim::solve_pinch(m, Finger::index, start));
}
BENCHMARK(BM_SolvePinch);

}  // namespace
