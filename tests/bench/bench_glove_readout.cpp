#include <benchmark/benchmark.h>

#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/stretch_glove/calibration.hpp"
#include "proprio/stretch_glove/readout.hpp"
#include "proprio/sim/stretch_glove_sim.hpp"
#include "proprio/sim/subjects.hpp"

using namespace proprio;

namespace {

// One full cycle of noisy measurements of the thesis glove on a relaxed
// hand, replayed in a loop.
std::vector<double> one_cycle() {
  auto sim = sim::StretchGloveSimulator::create(StretchGloveLayout::thesis_default(),
                                                *sim::sim_subject(7)->shape(), sim::StretchGloveSimOptions{});
  std::vector<double> cm;
  for (std::size_t k = 0; k < sim->layout().measurement_count(); ++k) {
    cm.push_back(sim->measure(sim::ExplorationMotion::relaxed()).capacitance_pf);
  }
  return cm;
}

// Per measurement as the board delivers them (960/s): store the value, and
// every 16th push the mean filter and solve. Arg: solve_every (16 = the
// thesis; 1 = a solve on every push, i.e. the cost of one solve).
void BM_ReadoutPush(benchmark::State& state) {
  stretch_glove::ReadoutOptions o;
  o.solve_every = static_cast<int>(state.range(0));
  auto readout = stretch_glove::make_readout(StretchGloveLayout::thesis_default(), o);
  const auto cm = one_cycle();
  stretch_glove::CellFrame frame = readout->make_frame();
  for (std::size_t k = 0; k < 2 * cm.size(); ++k) readout->push(k % cm.size(), cm[k % cm.size()], 0, frame);
  std::size_t k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(readout->push(k, cm[k], 0, frame));
    k = k + 1 == cm.size() ? 0 : k + 1;
  }
  state.SetItemsProcessed(state.iterations());
  state.SetLabel(state.range(0) == 1 ? "a mean-filtered solve on every push" : "thesis schedule: solve every 16");
}
BENCHMARK(BM_ReadoutPush)->Arg(16)->Arg(1);

// A whole C_m vector solved at once (no window), fault-free and with one
// NaN row (the cached reduced factorisation).
void BM_ReadoutSolveBatch(benchmark::State& state) {
  auto readout = stretch_glove::make_readout(StretchGloveLayout::thesis_default());
  auto cm = one_cycle();
  if (state.range(0) == 1) cm[40] = std::nan("");
  stretch_glove::CellFrame frame = readout->make_frame();
  for (auto _ : state) {
    benchmark::DoNotOptimize(readout->solve(cm, 0, frame).ok());
    benchmark::ClobberMemory();
  }
  state.SetLabel(state.range(0) == 1 ? "one NaN row" : "all rows");
}
BENCHMARK(BM_ReadoutSolveBatch)->Arg(0)->Arg(1);

// What runs per frame before inference: min-max normalisation of 44 cells
// and filling the 2 x 5 x 5 input grid.
void BM_NormalizeAndFillGrid(benchmark::State& state) {
  const auto layout = StretchGloveLayout::thesis_default();
  stretch_glove::MinMaxCalibration cal;
  Rng rng(1);
  std::vector<float> cells;
  for (const auto& c : layout.cells) {
    cal.min_pf.push_back(static_cast<float>(c.rest_capacitance_pf));
    cal.max_pf.push_back(static_cast<float>(2.0 * c.rest_capacitance_pf));
    cells.push_back(static_cast<float>(c.rest_capacitance_pf * rng.uniform(0.9, 2.1)));
  }
  const stretch_glove::InputGrid grid(layout);
  std::vector<float> normalized(cells.size());
  std::vector<float> input(kStretchInputSize);
  for (auto _ : state) {
    cal.normalize(cells, normalized);
    grid.fill(normalized, input);
    benchmark::DoNotOptimize(input.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_NormalizeAndFillGrid);

// The simulator per measurement, with the hand-motion generator: the cost
// of making datasets (realtime_x = simulated seconds per CPU second).
void BM_StretchSessionMeasurement(benchmark::State& state) {
  auto sim = sim::StretchGloveSimulator::create(StretchGloveLayout::thesis_default(), *sim::sim_subject(7)->shape(),
                                                sim::StretchGloveSimOptions{});
  sim::StretchSessionOptions so;
  so.exploration_s = 30.0;
  so.task_s = 1e6;
  sim::StretchGloveSession session(std::move(*sim), so);
  sim::StretchSample s;
  for (auto _ : state) benchmark::DoNotOptimize(session.next(s));
  state.counters["realtime_x"] =
      benchmark::Counter(static_cast<double>(state.iterations()) / 960.0, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_StretchSessionMeasurement)->Unit(benchmark::kMicrosecond);

}  // namespace
