// Matrix read-out: least-squares recovery of the cell capacitances from the
// time-multiplexed measurements (Glauser 2019 eq. 4.6, Sec. 5.2.1), its noise
// behaviour, and its handling of bad readings.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <limits>
#include <numeric>

#include "proprio/core/random.hpp"
#include "proprio/stretch_glove/readout.hpp"
#include "proprio/sim/stretch_glove_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "support/stretch_glove.hpp"

namespace proprio::stretch_glove {
namespace {

using proprio::testing_support::thesis_layout;

MatrixReadout thesis_readout(ReadoutOptions o = {}) {
  auto r = make_readout(thesis_layout(), o);
  EXPECT_TRUE(r.ok()) << r.error().message;
  return std::move(*r);
}

// C_m built cell by cell from the read-out rule (a cell counts when exactly
// one of its strips is a source), independently of measurement_matrix().
std::vector<double> measure_all(const std::vector<double>& cells) {
  const auto& L = thesis_layout();
  std::vector<double> out;
  for (int t = 0; t < L.top_strips; ++t) {
    for (int b = 0; b < L.bottom_strips; ++b) {
      double sum = 0.0;
      for (std::size_t c = 0; c < L.cells.size(); ++c) {
        const bool top_source = L.cells[c].top_strip == t;
        const bool bottom_source = L.cells[c].bottom_strip == b;
        if (top_source != bottom_source) sum += cells[c];
      }
      out.push_back(sum);
    }
  }
  return out;
}

std::vector<double> random_cells(Rng& rng) {
  std::vector<double> c;
  for (const auto& cell : thesis_layout().cells) c.push_back(cell.rest_capacitance_pf * rng.uniform(1.0, 2.5));
  return c;
}

TEST(GloveReadout, NoiselessBatchRecoveryIsExact) {
  auto r = thesis_readout();
  Rng rng(1);
  CellFrame f = r.make_frame();
  for (int trial = 0; trial < 10; ++trial) {
    const auto cells = random_cells(rng);
    ASSERT_TRUE(r.solve(measure_all(cells), 0, f).ok());
    ASSERT_TRUE(f.all_valid());
    EXPECT_EQ(f.rows_used, 182u);
    for (std::size_t c = 0; c < cells.size(); ++c) EXPECT_NEAR(f.cells_pf[c], cells[c], 1e-5 * cells[c]);
  }
}

TEST(GloveReadout, StreamingRecoversAStaticHandAfterOneCycle) {
  auto r = thesis_readout();
  Rng rng(2);
  const auto cells = random_cells(rng);
  const auto cm = measure_all(cells);
  CellFrame f = r.make_frame();
  int frames = 0;
  bool first_frame_incomplete = false;
  for (std::size_t k = 0; k < 3 * cm.size(); ++k) {
    const bool frame = r.push(k % cm.size(), cm[k % cm.size()], static_cast<TimeNs>(k) * 1'041'667, f);
    if (!frame) continue;
    ++frames;
    EXPECT_EQ(f.time_ns, static_cast<TimeNs>(k) * 1'041'667);
    if (frames == 1) first_frame_incomplete = !f.all_valid() && f.rows_excluded == 182 - 16;
    if (k >= cm.size()) {
      ASSERT_TRUE(f.all_valid()) << k;
      for (std::size_t c = 0; c < cells.size(); ++c) EXPECT_NEAR(f.cells_pf[c], cells[c], 1e-5 * cells[c]);
    }
  }
  EXPECT_TRUE(first_frame_incomplete) << "before a full cycle the cells cannot all be known";
  EXPECT_EQ(frames, static_cast<int>(3 * cm.size() / 16));
  EXPECT_EQ(r.updates(), 3 * cm.size());
  // Steady state: the fault-free factorisation is reused, none is added.
  const std::size_t cached = r.cached_factorisation_count();
  for (std::size_t k = 0; k < 2 * cm.size(); ++k) r.push(k % cm.size(), cm[k % cm.size()], 0, f);
  EXPECT_EQ(r.cached_factorisation_count(), cached);
}

// Least squares with white noise sigma on every measurement: the error of
// cell c has standard deviation sigma * |row c of M^+| (M^+ = (M^T M)^-1 M^T).
TEST(GloveReadout, NoisyErrorMatchesLeastSquaresTheory) {
  auto r = thesis_readout();
  const Eigen::MatrixXd M = thesis_layout().measurement_matrix();
  const Eigen::MatrixXd P = (M.transpose() * M).ldlt().solve(M.transpose());
  const double sigma = 0.2;
  Rng rng(3);
  const auto cells = random_cells(rng);
  const auto cm = measure_all(cells);
  const int trials = 400;
  std::vector<double> sq(cells.size(), 0.0);
  CellFrame f = r.make_frame();
  for (int t = 0; t < trials; ++t) {
    auto noisy = cm;
    for (double& v : noisy) v += sigma * rng.normal();
    ASSERT_TRUE(r.solve(noisy, 0, f).ok());
    for (std::size_t c = 0; c < cells.size(); ++c) sq[c] += std::pow(f.cells_pf[c] - cells[c], 2);
  }
  double ratio_sum = 0.0;
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const double theory = sigma * P.row(static_cast<Eigen::Index>(c)).norm();
    const double measured = std::sqrt(sq[c] / trials);
    EXPECT_NEAR(measured, theory, 0.25 * theory) << thesis_layout().cells[c].name;
    ratio_sum += measured / theory;
  }
  EXPECT_NEAR(ratio_sum / static_cast<double>(cells.size()), 1.0, 0.05);
  // Overdetermined (182 rows for 44 cells): better than the raw noise.
  EXPECT_LT(sigma * P.rowwise().norm().maxCoeff(), 0.5 * sigma);
}

TEST(GloveReadout, MeanFilterOverIndependentFramesShrinksNoiseBySqrtN) {
  // Solving once per full cycle makes each frame of C_m independent, so
  // averaging 5 of them cuts the error by sqrt(5).
  auto rms_error = [](int frames_in_filter) {
    ReadoutOptions o;
    o.solve_every = 182;
    o.mean_filter_frames = frames_in_filter;
    auto r = thesis_readout(o);
    Rng rng(4);
    const auto cells = random_cells(rng);
    const auto cm = measure_all(cells);
    CellFrame f = r.make_frame();
    double sq = 0.0;
    int n = 0;
    for (int cycle = 0; cycle < 300; ++cycle) {
      for (std::size_t k = 0; k < cm.size(); ++k) {
        if (!r.push(k, cm[k] + 0.2 * rng.normal(), 0, f) || cycle < frames_in_filter) continue;
        for (std::size_t c = 0; c < cells.size(); ++c) sq += std::pow(f.cells_pf[c] - cells[c], 2);
        n += static_cast<int>(cells.size());
      }
    }
    return std::sqrt(sq / n);
  };
  const double one = rms_error(1), five = rms_error(5);
  // Overlapping windows are correlated, but each frame's error is still the
  // mean of 5 independent ones.
  EXPECT_NEAR(five / one, 1.0 / std::sqrt(5.0), 0.12);
}

TEST(GloveReadout, BadReadingsAreLeftOut) {
  auto r = thesis_readout();
  Rng rng(5);
  const auto cells = random_cells(rng);
  const auto cm = measure_all(cells);
  CellFrame f = r.make_frame();
  for (double bad : {std::nan(""), -3.0, 500.0, 1e9, std::numeric_limits<double>::infinity()}) {
    auto faulty = cm;
    faulty[17] = bad;
    faulty[90] = bad;
    ASSERT_TRUE(r.solve(faulty, 0, f).ok());
    EXPECT_EQ(f.rows_used, 180u) << bad;
    EXPECT_EQ(f.rows_excluded, 2u);
    ASSERT_TRUE(f.all_valid()) << bad;
    for (std::size_t c = 0; c < cells.size(); ++c) {
      EXPECT_TRUE(std::isfinite(f.cells_pf[c]));
      EXPECT_NEAR(f.cells_pf[c], cells[c], 1e-5 * cells[c]) << bad;
    }
  }
}

TEST(GloveReadout, StreamedNanStaysOutUntilMeasuredAgain) {
  auto r = thesis_readout();
  Rng rng(6);
  const auto cells = random_cells(rng);
  const auto cm = measure_all(cells);
  CellFrame f = r.make_frame();
  const std::size_t m = cm.size();
  std::size_t excluded_frames = 0;
  for (std::size_t k = 0; k < 4 * m; ++k) {
    const std::size_t comb = k % m;
    const double v = (k == 2 * m + 7) ? std::nan("") : cm[comb];
    if (!r.push(comb, v, 0, f) || k < m) continue;
    for (std::size_t c = 0; c < cells.size(); ++c) {
      ASSERT_TRUE(std::isfinite(f.cells_pf[c]));
      EXPECT_NEAR(f.cells_pf[c], cells[c], 1e-5 * cells[c]);
    }
    EXPECT_TRUE(f.all_valid());
    excluded_frames += f.rows_excluded == 1;
  }
  // Out for one cycle: until combination 7 comes round again, 182 updates later.
  EXPECT_NEAR(static_cast<double>(excluded_frames), 182.0 / 16.0, 1.0);
  EXPECT_GE(r.cached_factorisation_count(), 2u);
}

TEST(GloveReadout, CellsWithoutRowsAreUnobservable) {
  auto r = thesis_readout();
  Rng rng(7);
  const auto cells = random_cells(rng);
  auto cm = measure_all(cells);
  // Knock out every row that sees cell 33 (index MCP): no row can tell it apart.
  const std::size_t target = 33;
  const auto& L = thesis_layout();
  for (int t = 0; t < L.top_strips; ++t) {
    for (int b = 0; b < L.bottom_strips; ++b) {
      if ((L.cells[target].top_strip == t) != (L.cells[target].bottom_strip == b)) {
        cm[static_cast<std::size_t>(t * L.bottom_strips + b)] = std::nan("");
      }
    }
  }
  CellFrame f = r.make_frame();
  ASSERT_TRUE(r.solve(measure_all(cells), 0, f).ok());
  const float held = f.cells_pf[target];
  ASSERT_TRUE(r.solve(cm, 0, f).ok());
  EXPECT_EQ(f.status[target], CellStatus::unobservable);
  EXPECT_EQ(f.cells_pf[target], held) << "an unobservable cell holds its last good value";
  for (std::size_t c = 0; c < cells.size(); ++c) {
    EXPECT_TRUE(std::isfinite(f.cells_pf[c]));
    if (f.valid(c)) {
      EXPECT_NEAR(f.cells_pf[c], cells[c], 1e-5 * cells[c]) << L.cells[c].name;
    }
  }
}

TEST(GloveReadout, DeadCellIsFlagged) {
  // A simulated open lead: the dead cell reads ~0 in every measurement.
  auto sim = sim::StretchGloveSimulator::create(thesis_layout(), *(*sim::sim_subject(4)).shape(),
                                                sim::StretchGloveSimOptions::ideal());
  ASSERT_TRUE(sim.ok());
  const std::size_t dead = *thesis_layout().find_cell("ring_pip_along");
  sim::StretchFaults faults;
  faults.dead_cells = {dead};
  sim->set_faults(faults);
  auto r = thesis_readout();
  CellFrame f = r.make_frame();
  bool seen = false;
  int first_dead_frame = -1;
  for (int k = 0; k < 4 * 182; ++k) {
    const auto m = sim->measure(sim::ExplorationMotion::relaxed());
    if (!r.push(m.combination, m.capacitance_pf, m.time_ns, f)) continue;
    if (first_dead_frame < 0 && f.status[dead] == CellStatus::dead) first_dead_frame = static_cast<int>(f.sequence);
    if (k < 3 * 182) continue;
    seen = true;
    EXPECT_EQ(f.status[dead], CellStatus::dead);
    EXPECT_NEAR(f.cells_pf[dead], 0.0, 1e-6);
    for (std::size_t c = 0; c < f.status.size(); ++c) {
      if (c != dead) {
        EXPECT_TRUE(f.valid(c)) << thesis_layout().cells[c].name;
      }
    }
  }
  EXPECT_TRUE(seen);
  // Flagged once the cell has been observable and low for more than a cycle
  // plus the window (12 + 5 frames): a spike cannot last that long.
  EXPECT_GE(first_dead_frame, 12 + 5);
  EXPECT_LE(first_dead_frame, 12 + 12 + 5);
  // A single C_m vector is judged at once.
  std::vector<double> cm(182);
  auto sim2 = sim::StretchGloveSimulator::create(thesis_layout(), *(*sim::sim_subject(4)).shape(),
                                                 sim::StretchGloveSimOptions::ideal());
  sim2->set_faults(faults);
  for (auto& v : cm) v = sim2->measure(sim::ExplorationMotion::relaxed()).capacitance_pf;
  ASSERT_TRUE(r.solve(cm, 0, f).ok());
  EXPECT_EQ(f.status[dead], CellStatus::dead);
}

TEST(GloveReadout, SpikeDoesNotKillALiveCell) {
  // A spike on the row that pulls one cell down hardest: for a cycle least
  // squares puts that cell below 20 % of C0, yet it is not declared dead.
  auto r = thesis_readout();
  const Eigen::MatrixXd M = thesis_layout().measurement_matrix();
  const Eigen::MatrixXd P = (M.transpose() * M).ldlt().solve(M.transpose());
  Eigen::Index cell_i = 0, row_i = 0;
  P.minCoeff(&cell_i, &row_i);
  ASSERT_LT(P(cell_i, row_i), 0.0);
  Rng rng(8);
  const auto cells = random_cells(rng);
  const auto cm = measure_all(cells);
  const auto c = static_cast<std::size_t>(cell_i);
  const double spike = -0.95 * cells[c] / P(cell_i, row_i);
  CellFrame f = r.make_frame();
  bool dipped = false;
  for (std::size_t k = 0; k < 4 * cm.size(); ++k) {
    const std::size_t comb = k % cm.size();
    const bool spiked = k == cm.size() + static_cast<std::size_t>(row_i);
    if (!r.push(comb, cm[comb] + (spiked ? spike : 0.0), 0, f) || k < cm.size()) continue;
    dipped = dipped || f.cells_pf[c] < 0.2 * thesis_layout().cells[c].rest_capacitance_pf;
    EXPECT_TRUE(f.all_valid()) << k;
  }
  EXPECT_TRUE(dipped) << "the spike should reach the cell (there is no outlier rejection)";
}

TEST(GloveReadout, FollowsTheSimulatorUnderNoise) {
  // End to end on a static hand with the simulator's default noise: within
  // a few tenths of a pF of the noise-free cells.
  sim::StretchGloveSimOptions o;
  o.enable_outliers = false;
  o.enable_drift = false;
  auto sim = sim::StretchGloveSimulator::create(thesis_layout(), *(*sim::sim_subject(9)).shape(), o);
  ASSERT_TRUE(sim.ok());
  const HandAngles pose = sim::ExplorationMotion::relaxed();
  std::vector<double> truth(thesis_layout().cell_count());
  sim->cell_capacitances(pose, truth);
  auto r = thesis_readout();
  CellFrame f = r.make_frame();
  double worst = 0.0;
  for (int k = 0; k < 4 * 182; ++k) {
    const auto m = sim->measure(pose);
    if (!r.push(m.combination, m.capacitance_pf, m.time_ns, f) || k < 2 * 182) continue;
    for (std::size_t c = 0; c < truth.size(); ++c) worst = std::max(worst, std::abs(f.cells_pf[c] - truth[c]));
  }
  EXPECT_LT(worst, 0.5);
  EXPECT_GT(worst, 0.0);
}

TEST(GloveReadout, RejectsBadInput) {
  ReadoutOptions o;
  o.solve_every = 0;
  auto bad = make_readout(thesis_layout(), o);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("solve_every"), std::string::npos);
  auto r = thesis_readout();
  CellFrame f = r.make_frame();
  EXPECT_FALSE(r.push(182, 10.0, 0, f));
  EXPECT_EQ(r.rejected_updates(), 1u);
  EXPECT_FALSE(r.solve(std::vector<double>(10, 1.0), 0, f).ok());
  EXPECT_NE(ReadoutOptions{}.describe().find("every 16 updates"), std::string::npos);
}


// Bursts of 12 (a board's reports): the frame due at the 16th update is made
// at the end of the burst that holds it, from all 24 measurements, with the
// 24th one's time; record() alone never solves.
TEST(GloveReadout, DeferredSolveUsesTheWholeBurst) {
  auto burst = thesis_readout();
  auto each = thesis_readout();
  Rng rng(7);
  const auto before = measure_all(random_cells(rng));
  const auto after = measure_all(random_cells(rng));
  CellFrame fb = burst.make_frame(), fe = each.make_frame();
  std::size_t k = 0;
  auto value = [&](std::size_t i) { return i < 16 ? before[i % 182] : after[i % 182]; };
  int deferred_frames = 0;
  for (int report = 0; report < 2 * 182 / 12; ++report) {
    bool due = false;
    for (int i = 0; i < 12; ++i, ++k) {
      due = burst.record(k % 182, value(k), static_cast<TimeNs>(k) * 1000);
      if (k + 1 == 16) {
        EXPECT_TRUE(due);
      } else if (k + 1 < 16) {
        EXPECT_FALSE(due);
      }
      each.push(k % 182, value(k), static_cast<TimeNs>(k) * 1000, fe);
    }
    EXPECT_EQ(burst.frame_due(), due);
    if (!burst.solve_due(fb)) continue;
    ++deferred_frames;
    EXPECT_EQ(fb.time_ns, static_cast<TimeNs>(k - 1) * 1000);  // the burst's last measurement
    EXPECT_FALSE(burst.frame_due());
    EXPECT_FALSE(burst.solve_due(fb));
  }
  // Frames fall due every 16 updates; reports end every 12, so 3 of 4 reports end in a solve.
  EXPECT_EQ(deferred_frames, static_cast<int>(k / 16));
  EXPECT_EQ(burst.updates(), each.updates());
  // The first deferred frame held measurements 17-24 (the "after" hand), which the push() frame at 16 did not.
  auto first = thesis_readout();
  CellFrame f1 = first.make_frame(), f2 = first.make_frame();
  for (std::size_t i = 0; i < 24; ++i) first.record(i, value(i), static_cast<TimeNs>(i));
  ASSERT_TRUE(first.solve_due(f1));
  auto pushed = thesis_readout();
  for (std::size_t i = 0; i < 16; ++i) pushed.push(i, value(i), static_cast<TimeNs>(i), f2);
  EXPECT_EQ(f1.rows_used, 24u);
  EXPECT_EQ(f2.rows_used, 16u);
}

}  // namespace
}  // namespace proprio::stretch_glove
