// The read-out board simulator: each effect on its own, against closed forms
// where there is one, and the per-cell C/C0 error that the resistances cause
// on the 92-cell layout (printed; the issue's <= 5 % target is decided by it).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <set>

#include <Eigen/QR>

#include "deformations.hpp"
#include "proprio/stretch_array/matrix_readout.hpp"
#include "proprio/stretch_array_sim/array_electrical.hpp"

namespace proprio::stretch_array_sim {
namespace {

using stretch_array::StripArrayLayout;
using namespace testing;

Eigen::VectorXd pf(const std::vector<double>& f) {
  Eigen::VectorXd v(static_cast<Eigen::Index>(f.size()));
  for (std::size_t i = 0; i < f.size(); ++i) v[static_cast<Eigen::Index>(i)] = f[i] * 1e12;
  return v;
}
Eigen::VectorXd vec(const std::vector<double>& x) { return Eigen::Map<const Eigen::VectorXd>(x.data(), static_cast<Eigen::Index>(x.size())); }

BoardSimulator board(const ArraySheet& s, const BoardOptions& o) {
  auto b = BoardSimulator::create(s, o);
  EXPECT_TRUE(b) << (b ? "" : b.error().message);
  return std::move(*b);
}

const ArraySheet& proto() {
  static const ArraySheet s = sheet_of(StripArrayLayout::prototype_92());
  return s;
}

TEST(BoardSimulator, IdealBoardReadsMTimesTheCells) {
  BoardSimulator b = board(proto(), BoardOptions::ideal());
  auto st = proto().evaluate(graded_stretch(proto(), 0.25, 0.1));
  ASSERT_TRUE(st);
  auto f = b.measure_static(0.0, *st);
  ASSERT_TRUE(f) << f.error().message;
  ASSERT_EQ(f->rows_pf.size(), StripArrayLayout::prototype_92().measurement_plan(true).size());
  const Eigen::VectorXd expect = b.measurement_matrix() * pf(st->cell_f);
  for (std::size_t r = 0; r < f->rows_pf.size(); ++r) EXPECT_NEAR(f->rows_pf[r], expect[static_cast<Eigen::Index>(r)], 1e-9 * expect[static_cast<Eigen::Index>(r)] + 1e-12);
  EXPECT_EQ(f->open_pads_pf, 0.0);
}

// One cell behind a series resistance Rs: the closed form derived in
// array_electrical.cpp, T/T0 for C behind Rs with no node capacitance.
double lumped_ratio(double rs, double r1, double r2) {
  const double ra = r1 + r2;
  const double tc = (ra + rs) * std::log((2.0 - rs / r2) / (1.0 + rs / ra));
  const double td = (r2 + rs) * std::log((2.0 - rs / ra) / (1.0 + rs / r2));
  return (tc + td) / ((r1 + 2 * r2) * std::numbers::ln2);
}

TEST(BoardSimulator, OneCellBehindResistanceMatchesTheClosedForm) {
  const ArraySheet s = sheet_of(StripArrayLayout::grid("one", 1, 1, 0.012, 0.008));
  for (double lead : {500.0, 3000.0, 8000.0}) {
    BoardOptions o = BoardOptions::ideal();
    o.resistance.enabled = true;
    o.resistance.lead_ohm = lead;
    BoardSimulator b = board(s, o);
    const SheetState& st = s.rest_state();
    // Row 1 (M^II, T1 alone): the lead and strip to the cell, then the bottom strip and its lead.
    const double rs = 2 * lead + b.sheet_ohm_per_square() * (st.top_squares[0] + st.bottom_squares[0]);
    auto c = b.apparent_row_f(1, st, 0.0);
    ASSERT_TRUE(c);
    const double expect = st.cell_f[0] * lumped_ratio(rs, o.timer.r1_ohm, o.timer.r2_ohm);
    EXPECT_NEAR(*c, expect, 2e-4 * expect) << "Rs " << rs;
    EXPECT_LT(*c, st.cell_f[0]);
  }
}

// A strip with many cells is a distributed RC line: to first order it reads
// like its total capacitance behind the Elmore resistance
// R_eff = sum_ij C_i C_j R_ij / C^2 (R_ij: the resistance the paths of cells
// i and j share), and the far cells sit behind more of it.
TEST(BoardSimulator, AStripOfCellsReadsLikeItsElmoreResistance) {
  const StripArrayLayout L = StripArrayLayout::grid("line", 1, 12, 0.012, 0.008);
  const ArraySheet s = sheet_of(L);
  BoardOptions o = BoardOptions::ideal();
  o.resistance.enabled = true;
  o.resistance.sheet_ohm_per_square = 100.0;
  o.resistance.lead_ohm = 200.0;
  BoardSimulator b = board(s, o);
  const SheetState& st = s.rest_state();
  const double r1 = o.timer.r1_ohm, r2 = o.timer.r2_ohm, ra = r1 + r2;
  const double k = (2 - 2 * std::numbers::ln2 + ra / (2 * r2) + r2 / (2 * ra)) / ((r1 + 2 * r2) * std::numbers::ln2);
  // Row 12 (M^II, T1 alone): every cell, along T1, each back through its own bottom strip.
  double ctot = 0.0, m2 = 0.0;
  for (std::size_t i = 0; i < L.cell_count(); ++i) {
    ctot += st.cell_f[i];
    for (std::size_t j = 0; j < L.cell_count(); ++j) {
      double shared = o.resistance.lead_ohm + o.resistance.sheet_ohm_per_square * std::min(st.top_squares[i], st.top_squares[j]);
      if (i == j) shared += o.resistance.lead_ohm + o.resistance.sheet_ohm_per_square * st.bottom_squares[i];
      m2 += st.cell_f[i] * st.cell_f[j] * shared;
    }
  }
  const double r_eff = m2 / (ctot * ctot);
  const double deficit = 1.0 - *b.apparent_row_f(12, st, 0.0) / ctot;
  EXPECT_NEAR(deficit, k * r_eff, 0.05 * k * r_eff);
  // Rows 13-24 (M^II, one bottom strip each): one cell each, farther along T1 each time.
  double last = 0.0;
  for (std::size_t bottom = 0; bottom < 12; ++bottom) {
    const double d = 1.0 - *b.apparent_row_f(13 + bottom, st, 0.0) / st.cell_f[bottom];
    EXPECT_GT(d, last) << "bottom strip " << bottom;
    last = d;
  }
}

TEST(BoardSimulator, ResistanceEffectVanishesAtZeroAndGrowsWithResistanceAndStretch) {
  BoardOptions off = BoardOptions::ideal();
  off.parasitic.enabled = true;
  off.parasitic.drift_std_f = 0.0;
  BoardSimulator ref = board(proto(), off);
  const SheetState& rest = proto().rest_state();
  auto stretched = [&](double l) { return *proto().evaluate(uniform_stretch(proto(), l)); };
  const SheetState s11 = stretched(1.1), s13 = stretched(1.3);

  // Mean over rows of |apparent / resistance-free - 1|, and of the error in the
  // ratio stretched / rest.
  auto effect = [&](BoardSimulator& b, const SheetState& st) {
    double abs_err = 0.0, ratio_err = 0.0;
    for (std::size_t r = 0; r < b.row_count(); r += 7) {
      const double a = *b.apparent_row_f(r, st, 0.0), i = *ref.apparent_row_f(r, st, 0.0);
      const double a0 = *b.apparent_row_f(r, rest, 0.0), i0 = *ref.apparent_row_f(r, rest, 0.0);
      abs_err += std::abs(a / i - 1.0);
      ratio_err += std::abs((a / a0) / (i / i0) - 1.0);
    }
    return std::pair{abs_err, ratio_err};
  };
  BoardOptions on = off;
  on.resistance.enabled = true;
  on.resistance.sheet_ohm_per_square = 1e-3;
  on.resistance.lead_ohm = 1e-3;  // every branch clamped to 1 ohm
  {
    BoardSimulator b = board(proto(), on);
    const auto [abs_err, ratio_err] = effect(b, s13);
    EXPECT_LT(abs_err / 24, 1e-4);
    EXPECT_LT(ratio_err / 24, 1e-5);
  }
  double last_abs = 0.0, last_ratio = 0.0;
  for (double longest : {1e3, 10e3, 50e3}) {
    on.resistance.sheet_ohm_per_square = 1000.0;
    on.resistance.lead_ohm = 1000.0;
    on.resistance.longest_strip_ohm = longest;
    BoardSimulator b = board(proto(), on);
    const auto [abs11, ratio11] = effect(b, s11);
    const auto [abs13, ratio13] = effect(b, s13);
    EXPECT_GT(abs13, last_abs) << longest;
    EXPECT_GT(ratio13, last_ratio) << longest;
    EXPECT_GT(ratio13, ratio11) << "more stretch, more error at " << longest;
    last_abs = abs13;
    last_ratio = ratio13;
  }
}

TEST(BoardSimulator, SubtractingTheRestCalibrationRecoversTheCells) {
  BoardOptions o = BoardOptions::ideal();
  o.parasitic.enabled = true;
  o.parasitic.drift_std_f = 0.0;
  o.donning.enabled = true;
  BoardSimulator b = board(proto(), o);
  auto cal = b.calibrate_at_rest(0.0, 2);
  ASSERT_TRUE(cal) << cal.error().message;
  for (double p : cal->parasitic_pf) {
    EXPECT_GE(p, o.parasitic.board_f * 1e12 - 1e-6);
    EXPECT_LE(p, (o.parasitic.board_f + 2 * o.parasitic.strip_max_f + 8 * o.donning.offset_std_f) * 1e12);
  }
  EXPECT_NEAR(cal->open_pads_pf, (o.parasitic.board_f + 0.5 * (o.parasitic.strip_min_f + o.parasitic.strip_max_f)) * 1e12, 1e-9);
  auto st = proto().evaluate(bump(proto(), {0.05, 0.08}, 0.02, 0.015));
  ASSERT_TRUE(st);
  auto f = b.measure_static(10.0, *st);
  ASSERT_TRUE(f);
  const Eigen::VectorXd rows = vec(f->rows_pf) - vec(cal->parasitic_pf);
  const Eigen::VectorXd cells = b.measurement_matrix().colPivHouseholderQr().solve(rows);
  const Eigen::VectorXd truth = pf(st->cell_f);
  EXPECT_LT((cells - truth).cwiseAbs().maxCoeff(), 1e-6 * truth.maxCoeff());
  // The same through the shared read-out.
  auto readout = stretch_array::make_array_readout(proto().layout());
  ASSERT_TRUE(readout);
  auto frame = readout->make_frame();
  std::vector<double> rows_v(rows.data(), rows.data() + rows.size());
  ASSERT_TRUE(readout->solve(rows_v, 0, frame));
  for (std::size_t c = 0; c < frame.cells_pf.size(); ++c) EXPECT_NEAR(frame.cells_pf[c], truth[static_cast<Eigen::Index>(c)], 1e-4);
  // Without subtracting, the solve is off by the parasitics.
  const Eigen::VectorXd raw = b.measurement_matrix().colPivHouseholderQr().solve(vec(f->rows_pf));
  EXPECT_GT((raw - truth).cwiseAbs().mean(), 0.5);
}

TEST(BoardSimulator, QuantisationStepIsOneReferenceClockCount) {
  BoardOptions o = BoardOptions::ideal();
  o.quantise = true;
  BoardSimulator b = board(proto(), o);
  const double step_pf = o.timer.resolution_f(50e-12) * 1e12;
  std::vector<std::set<long>> counts(b.row_count());
  for (int k = 0; k < 12; ++k) {
    auto f = b.measure_static(k, proto().rest_state());
    ASSERT_TRUE(f);
    for (std::size_t r = 0; r < b.row_count(); ++r) {
      const double n = f->rows_pf[r] / step_pf;
      EXPECT_NEAR(n, std::round(n), 1e-6);
      counts[r].insert(std::lround(n));
    }
  }
  std::size_t two = 0;
  for (const auto& c : counts) {
    EXPECT_LE(c.size(), 2u);
    if (c.size() == 2) {
      EXPECT_EQ(*c.rbegin() - *c.begin(), 1);
      ++two;
    }
  }
  EXPECT_GT(two, b.row_count() / 4) << "the clock phase should vary between frames";
}

TEST(BoardSimulator, JitterMatchesTheComparatorNoise) {
  BoardOptions o = BoardOptions::ideal();
  o.jitter.enabled = true;
  BoardSimulator b = board(proto(), o);
  const std::size_t row = 100;
  std::vector<double> x;
  for (int k = 0; k < 400; ++k) x.push_back(b.measure_static(k, proto().rest_state())->rows_pf[row]);
  double mean = 0.0, var = 0.0;
  for (double v : x) mean += v / x.size();
  for (double v : x) var += (v - mean) * (v - mean) / (x.size() - 1);
  // Linearised: the upper threshold moves the end of the charge (and the
  // start of the discharge), the lower one the end of the discharge.
  const double vcc = o.supply_v, ra = o.timer.r1_ohm + o.timer.r2_ohm, r2 = o.timer.r2_ohm, s = o.jitter.comparator_noise_v;
  const double d_hi = 3 * ra / vcc - 1.5 * r2 / vcc, d_lo = 3 * r2 / vcc;
  const double rel = s * std::hypot(d_hi, d_lo) / ((o.timer.r1_ohm + 2 * r2) * std::numbers::ln2);
  EXPECT_NEAR(std::sqrt(var) / mean, rel, 0.15 * rel);
  EXPECT_GT(rel, 1e-4);
  EXPECT_LT(rel, 1e-3);
}

TEST(BoardSimulator, BrokenLeadGivesLowReadingsOnItsRows) {
  const StripArrayLayout& L = proto().layout();
  BoardOptions o = BoardOptions::ideal();
  o.parasitic.enabled = true;  // a row with nothing connected reads the node's own capacitance
  o.parasitic.drift_std_f = 0.0;
  BoardSimulator healthy = board(proto(), o);
  o.broken_lead = {true, true, 3, 1.0};
  BoardSimulator broken = board(proto(), o);
  const auto plan = L.measurement_plan(true);
  auto before = broken.measure_static(0.0, proto().rest_state());
  auto after = broken.measure_static(2.0, proto().rest_state());
  auto good = healthy.measure_static(2.0, proto().rest_state());
  ASSERT_TRUE(before && after && good);
  for (std::size_t r = 0; r < plan.size(); ++r) {
    EXPECT_DOUBLE_EQ(before->rows_pf[r], good->rows_pf[r]);
    const bool source = std::count(plan[r].top_sources.begin(), plan[r].top_sources.end(), 3u) > 0;
    if (source && plan[r].bottom_sources.empty()) {
      // Only the node's parasitics are left (T4's lead included: it breaks at the sheet).
      const double node_pf = (o.parasitic.board_f + o.parasitic.strip_max_f) * 1e12;
      EXPECT_LE(after->rows_pf[r], node_pf) << "T4 alone";
      EXPECT_LT(after->rows_pf[r], 0.3 * good->rows_pf[r]) << "T4 alone";
    } else if (source) {
      EXPECT_LT(after->rows_pf[r], 0.75 * good->rows_pf[r]) << "row " << r;
    } else if (plan[r].bottom_sources.empty()) {
      EXPECT_DOUBLE_EQ(after->rows_pf[r], good->rows_pf[r]) << "row " << r << " does not involve T4";
    } else {
      // A bottom source charges its T4 cell into the floating strip: less.
      EXPECT_LE(after->rows_pf[r], good->rows_pf[r] + 1e-9);
    }
  }
}

TEST(BoardSimulator, OverStretchChangesTheGainForGood) {
  BoardOptions o = BoardOptions::ideal();
  o.over_stretch.enabled = true;
  BoardSimulator b = board(proto(), o);
  const auto rest0 = b.measure_static(0.0, proto().rest_state())->rows_pf;
  ASSERT_TRUE(b.measure_static(1.0, *proto().evaluate(uniform_stretch(proto(), 2.0))));
  EXPECT_EQ(std::count(b.damaged_cells().begin(), b.damaged_cells().end(), 1), 0);
  EXPECT_EQ(b.measure_static(2.0, proto().rest_state())->rows_pf, rest0);
  // Pulled past 2.25x along x on the high side only.
  ASSERT_TRUE(b.measure_static(3.0, *proto().evaluate(graded_stretch(proto(), 0.8, 0.0))));
  const auto damaged = std::count(b.damaged_cells().begin(), b.damaged_cells().end(), 1);
  EXPECT_GT(damaged, 0);
  EXPECT_LT(damaged, static_cast<long>(proto().cell_count()));
  ASSERT_TRUE(b.measure_static(4.0, *proto().evaluate(uniform_stretch(proto(), 2.4))));
  EXPECT_EQ(std::count(b.damaged_cells().begin(), b.damaged_cells().end(), 1), static_cast<long>(proto().cell_count()));
  const auto rest1 = b.measure_static(5.0, proto().rest_state())->rows_pf;
  for (std::size_t r = 0; r < rest0.size(); ++r) EXPECT_NEAR(rest1[r], rest0[r] * (1 + o.over_stretch.gain_change), 1e-9 * rest0[r] + 1e-12);
}

TEST(BoardSimulator, RowsAreTakenAtTheirOwnInstants) {
  BoardOptions o = BoardOptions::ideal();
  o.timing.enabled = true;
  BoardSimulator b = board(proto(), o);
  std::vector<double> asked;
  // A sheet stretching steadily: 1 + 0.2 t.
  const StateProvider moving = [&](double t) -> Result<SheetState> {
    asked.push_back(t);
    return proto().evaluate(uniform_stretch(proto(), 1.0 + 0.2 * t));
  };
  auto f = b.measure_frame(0.5, moving);
  ASSERT_TRUE(f);
  ASSERT_EQ(asked.size(), b.row_count());
  for (std::size_t r = 0; r < b.row_count(); ++r) {
    EXPECT_DOUBLE_EQ(f->row_time_s[r], 0.5 + r / o.timing.row_rate_hz);
    EXPECT_DOUBLE_EQ(asked[r], f->row_time_s[r]);
    const Eigen::VectorXd cells = pf(proto().evaluate(uniform_stretch(proto(), 1.0 + 0.2 * f->row_time_s[r]))->cell_f);
    EXPECT_NEAR(f->rows_pf[r], b.measurement_matrix().row(static_cast<Eigen::Index>(r)).dot(cells), 1e-9 * f->rows_pf[r]);
  }
  EXPECT_NEAR(b.frame_period_s(), 168.0 / 960.0, 1e-12);
  o.timing.enabled = false;
  BoardSimulator same = board(proto(), o);
  asked.clear();
  auto g = same.measure_frame(0.5, moving);
  ASSERT_TRUE(g);
  for (double t : asked) EXPECT_EQ(t, 0.5);
  // A vertex provider goes through the same path.
  auto h = b.measure_frame(0.5, VertexProvider([&](double t) -> Result<std::vector<Eigen::Vector3d>> { return uniform_stretch(proto(), 1.0 + 0.2 * t); }));
  ASSERT_TRUE(h);
  EXPECT_EQ(h->rows_pf, f->rows_pf);
}

TEST(BoardSimulator, DonningOffsetsAndSeedsAreDeterministic) {
  BoardOptions o;  // everything on
  o.resistance.enabled = false;  // keeps the test quick; the offsets are at the node
  BoardSimulator a = board(proto(), o), b = board(proto(), o);
  const auto st = *proto().evaluate(graded_stretch(proto(), 0.2, 0.1));
  auto fa = a.measure_static(1.0, st), fb = b.measure_static(1.0, st);
  ASSERT_TRUE(fa && fb);
  EXPECT_EQ(fa->rows_pf, fb->rows_pf);
  a.set_donning(1);
  b.set_donning(1);
  auto ga = a.measure_static(1.0, st), gb = b.measure_static(1.0, st);
  EXPECT_EQ(ga->rows_pf, gb->rows_pf);
  double moved = 0.0;
  for (std::size_t r = 0; r < ga->rows_pf.size(); ++r) moved += std::abs(ga->rows_pf[r] - fa->rows_pf[r]) / ga->rows_pf.size();
  EXPECT_GT(moved, 0.1) << "a new donning shifts the rows by its lead offsets (pF)";
  o.seed = 2;
  BoardSimulator c = board(proto(), o);
  EXPECT_NE(c.measure_static(1.0, st)->rows_pf, fa->rows_pf);
}

TEST(BoardOptions, ValidateAndDescribe) {
  BoardOptions o;
  EXPECT_TRUE(o.validate());
  const std::string d = o.describe();
  for (const char* word : {"R1", "resistance", "parasitic", "jitter", "over-stretch", "donning"}) EXPECT_NE(d.find(word), std::string::npos) << word;
  BoardOptions bad = o;
  bad.resistance.lead_ohm = -1;
  EXPECT_FALSE(bad.validate());
  bad = o;
  bad.over_stretch.limit = 0.5;
  EXPECT_FALSE(bad.validate());
  bad = o;
  bad.parasitic.strip_min_f = 2 * bad.parasitic.strip_max_f;
  EXPECT_FALSE(bad.validate());
  bad = o;
  bad.timing.row_rate_hz = 0;
  EXPECT_FALSE(bad.validate());
  bad = o;
  bad.broken_lead = {true, false, 99, 0.0};
  EXPECT_FALSE(BoardSimulator::create(proto(), bad));
}

// The target: mean per-cell |C/C0 measured - eq. 4.8| / eq. 4.8 with
// the resistances on. Printed for the report; asserted only to be finite and
// to grow with the resistance (the numbers are what they are).
TEST(BoardSimulator, PerCellRatioErrorAgainstEq48OnPrototype92) {
  const ArraySheet& s = proto();
  const auto uni = *s.evaluate(uniform_stretch(s, 1.2));
  const auto uniax = *s.evaluate(uniaxial_stretch(s, 1.5));
  const auto graded = *s.evaluate(graded_stretch(s, 0.25, 0.1));
  struct Case {
    const char* name;
    const SheetState* st;
  } cases[] = {{"uniform 1.2x", &uni}, {"uniaxial 1.5x", &uniax}, {"graded 1-1.5x", &graded}};
  const Eigen::MatrixXd M = s.layout().measurement_matrix(true);
  const auto qr = M.colPivHouseholderQr();
  constexpr int kFrames = 3;
  // Host: rows averaged over kFrames, parasitic subtracted, solved; C/C0 is
  // the stretched solve over the rest solve.
  auto cells = [&](BoardSimulator& b, const SheetState& st, double t, const Eigen::VectorXd& parasitic) {
    Eigen::VectorXd rows = Eigen::VectorXd::Zero(M.rows());
    for (int k = 0; k < kFrames; ++k) rows += vec(b.measure_static(t + k * b.frame_period_s(), st)->rows_pf);
    return Eigen::VectorXd(qr.solve(rows / kFrames - parasitic));
  };
  // Mean relative error, and its signed mean (negative: the board under-reads the stretch).
  auto error = [&](const Eigen::VectorXd& c, const Eigen::VectorXd& c0, const SheetState& st) {
    double e = 0.0, signed_e = 0.0;
    for (Eigen::Index i = 0; i < c.size(); ++i) {
      const double truth = st.cell_f[static_cast<std::size_t>(i)] / s.rest_state().cell_f[static_cast<std::size_t>(i)];
      e += std::abs(c[i] / c0[i] - truth) / truth;
      signed_e += (c[i] / c0[i] - truth) / truth;
    }
    return std::pair{e / static_cast<double>(c.size()), signed_e / static_cast<double>(c.size())};
  };
  std::printf("mean per-cell |C/C0 - eq.4.8| / eq.4.8 on prototype_92 (%d-frame means; signed mean in brackets)\n", kFrames);
  std::printf("%-24s %-14s %18s %18s %18s\n", "resistance", "deformation", "R (+node C, cal)", "all + rest cal", "all + open pads");
  double last = -1.0;
  for (double longest : {1e3, 10e3, 0.0, 50e3}) {
    // Resistance with the node's real (static) parasitics, which a rest
    // calibration removes exactly: the resistance effect alone.
    BoardOptions only = BoardOptions::ideal();
    only.resistance.enabled = true;
    only.resistance.longest_strip_ohm = longest;
    only.parasitic.enabled = true;
    only.parasitic.drift_std_f = 0.0;
    BoardOptions all;  // everything on but a broken lead
    all.resistance.longest_strip_ohm = longest;
    BoardSimulator b_only = board(s, only), b_all = board(s, all);
    const Eigen::VectorXd c0_ideal = pf(s.rest_state().cell_f);  // a rest calibration makes the rest solve exact
    const Eigen::VectorXd p_only = vec(b_only.calibrate_at_rest(0.0, 1)->parasitic_pf);
    const auto cal = *b_all.calibrate_at_rest(0.0, kFrames);
    const Eigen::VectorXd p_cal = vec(cal.parasitic_pf);
    const Eigen::VectorXd p_pads = Eigen::VectorXd::Constant(M.rows(), cal.open_pads_pf);
    const Eigen::VectorXd c0_pads = cells(b_all, s.rest_state(), 0.0, p_pads);
    char label[64];
    std::snprintf(label, sizeof label, longest > 0 ? "longest strip %.0f k" : "1 kOhm/sq+1k (%.0f k)",
                  longest > 0 ? longest / 1e3 : (b_only.lead_ohm() + 18 * b_only.sheet_ohm_per_square()) / 1e3);
    for (const Case& c : cases) {
      const auto e_only = error(cells(b_only, *c.st, 1.0, p_only), c0_ideal, *c.st);
      const auto e_cal = error(cells(b_all, *c.st, 10.0, p_cal), c0_ideal, *c.st);
      const auto e_pads = error(cells(b_all, *c.st, 10.0, p_pads), c0_pads, *c.st);
      std::printf("%-24s %-14s %7.2f%% (%+6.2f%%) %7.2f%% (%+6.2f%%) %7.2f%% (%+6.2f%%)\n", label, c.name, 100 * e_only.first,
                  100 * e_only.second, 100 * e_cal.first, 100 * e_cal.second, 100 * e_pads.first, 100 * e_pads.second);
      EXPECT_TRUE(std::isfinite(e_only.first) && std::isfinite(e_cal.first) && std::isfinite(e_pads.first));
      if (longest > 0 && c.st == &graded) {
        EXPECT_GT(e_only.first, last);
        last = e_only.first;
      }
    }
  }
  std::printf("(thesis, measured: 7.7 %%; issue target <= 5 %%)\n");
}

}  // namespace
}  // namespace proprio::stretch_array_sim
