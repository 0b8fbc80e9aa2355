// The stretch-glove simulator: the capacitance physics (eqs 4.3, 4.8), how
// cells respond to the hand, per-user and per-donning variation, the
// time-multiplexed measurements and their faults, and the motion.
#include <gtest/gtest.h>

#include <cmath>
#include <numeric>

#include "proprio/sim/stretch_glove_sim.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::sim {
namespace {

HandShape shape_of(int subject) { return *(*sim_subject(subject)).shape(); }

StretchGloveSimulator make_sim(StretchGloveSimOptions o = StretchGloveSimOptions::ideal(), int subject = 7) {
  auto s = StretchGloveSimulator::create(StretchGloveLayout::thesis_default(), shape_of(subject), o);
  EXPECT_TRUE(s.ok()) << s.error().message;
  return std::move(*s);
}

std::size_t cell(const char* name) { return *StretchGloveLayout::thesis_default().find_cell(name); }

std::vector<double> capacitances(const StretchGloveSimulator& sim, const HandAngles& a) {
  std::vector<double> c(sim.layout().cell_count());
  sim.cell_capacitances(a, c);
  return c;
}

HandAngles with(HandAngles a, HandDof d, double deg) {
  a[index_of(d)] = deg_to_rad(deg);
  return a;
}

TEST(StretchGloveSim, CapacitanceIsAreaStretchSquared) {
  // One element per cell: uniform stretch, so C/C0 = (A/A0)^2 exactly (eq. 4.3).
  StretchGloveSimOptions o = StretchGloveSimOptions::ideal();
  o.skin.elements_per_cell = 1;
  auto sim = make_sim(o);
  const HandAngles pose = with(with(ExplorationMotion::relaxed(), HandDof::index_mcp_flexion, 70),
                               HandDof::middle_pip_flexion, 80);
  const auto stretch = sim.cell_stretch(pose);
  const auto c = capacitances(sim, pose);
  for (std::size_t i = 0; i < stretch.size(); ++i) {
    const double area = stretch[i].stretch_parallel * stretch[i].stretch_perpendicular;
    EXPECT_NEAR(stretch[i].area_stretch, area, 1e-12);
    EXPECT_NEAR(stretch[i].capacitance_ratio, area * area, 1e-12);
    // Ideal glove: no gain, offset or fabrication spread.
    EXPECT_NEAR(c[i], sim.layout().cells[i].rest_capacitance_pf * area * area, 1e-9);
  }
}

TEST(StretchGloveSim, NonUniformStretchFollowsEq48) {
  // Four elements: C/C0 = (1/A0) sum A_i^2 / A0_i = mean of (A_i/A0_i)^2, which
  // by Jensen is at least the square of the mean area stretch.
  auto sim = make_sim();
  const HandAngles pose = with(ExplorationMotion::relaxed(), HandDof::index_mcp_flexion, 80);
  const auto stretch = sim.cell_stretch(pose);
  bool some_nonuniform = false;
  for (const auto& s : stretch) {
    ASSERT_EQ(s.element_area_stretch.size(), 4u);
    double mean_sq = 0.0;
    for (double a : s.element_area_stretch) mean_sq += a * a / 4.0;
    EXPECT_NEAR(s.capacitance_ratio, mean_sq, 1e-12);
    EXPECT_GE(s.capacitance_ratio, s.area_stretch * s.area_stretch - 1e-12);
    some_nonuniform = some_nonuniform || s.capacitance_ratio > s.area_stretch * s.area_stretch + 1e-6;
  }
  EXPECT_TRUE(some_nonuniform) << "a cell next to a flexed joint should be stretched non-uniformly";
}

TEST(StretchGloveSim, FlexingAJointRaisesItsOwnAlongCells) {
  auto sim = make_sim();
  const HandAngles rest = ExplorationMotion::relaxed();
  const auto c0 = capacitances(sim, rest);
  const auto c1 = capacitances(sim, with(rest, HandDof::index_mcp_flexion, 85));
  auto delta = [&](const char* name) { return c1[cell(name)] - c0[cell(name)]; };
  EXPECT_GT(delta("index_mcp_along"), 0.3 * c0[cell("index_mcp_along")]);
  for (const char* other : {"middle_mcp_along", "ring_mcp_along", "little_mcp_along", "thumb_mcp_along",
                            "middle_pip_along", "ring_dip_along"}) {
    EXPECT_LT(std::abs(delta(other)), 0.05 * delta("index_mcp_along")) << other;
  }
  // Neighbouring joints of the same finger feel it a little (cross-talk), less than the joint's own cell.
  EXPECT_GT(delta("index_pip_along"), 0.0);
  EXPECT_LT(delta("index_pip_along"), 0.5 * delta("index_mcp_along"));

  const auto c2 = capacitances(sim, with(rest, HandDof::ring_pip_flexion, 100));
  EXPECT_GT(c2[cell("ring_pip_along")] - c0[cell("ring_pip_along")],
            5.0 * std::abs(c2[cell("index_pip_along")] - c0[cell("index_pip_along")]));
  // Finger volume: across cells grow too, but less than the along cell.
  const double across = c2[cell("ring_intermediate_across")] - c0[cell("ring_intermediate_across")];
  EXPECT_GT(across, 0.0);
  EXPECT_LT(across, c2[cell("ring_pip_along")] - c0[cell("ring_pip_along")]);
}

TEST(StretchGloveSim, ResponseIsNonlinear) {
  // The cam and eq. 4.3 make equal angle steps give growing capacitance steps.
  auto sim = make_sim();
  const HandAngles rest = ExplorationMotion::relaxed();
  const std::size_t i = cell("middle_mcp_along");
  const double a = capacitances(sim, with(rest, HandDof::middle_mcp_flexion, 0))[i];
  const double b = capacitances(sim, with(rest, HandDof::middle_mcp_flexion, 40))[i];
  const double c = capacitances(sim, with(rest, HandDof::middle_mcp_flexion, 80))[i];
  EXPECT_GT(c - b, 1.2 * (b - a));
}

TEST(StretchGloveSim, SpreadingStretchesTheWebs) {
  auto sim = make_sim();
  const HandAngles rest = ExplorationMotion::relaxed();
  HandAngles spread = with(with(rest, HandDof::index_mcp_abduction, 20), HandDof::middle_mcp_abduction, -10);
  const auto c0 = capacitances(sim, rest);
  const auto c1 = capacitances(sim, spread);
  const std::size_t web = cell("index_middle_web");
  EXPECT_GT(c1[web] - c0[web], 0.1 * c0[web]);
  const auto c2 = capacitances(sim, with(rest, HandDof::thumb_cmc_abduction, 40));
  EXPECT_GT(c2[cell("thumb_index_web")], 1.1 * c0[cell("thumb_index_web")]);
}

TEST(StretchGloveSim, WristFlexionStretchesTheDorsumNearTheStrap) {
  auto sim = make_sim();
  const HandAngles rest = ExplorationMotion::relaxed();
  const auto straight = capacitances(sim, rest);
  std::vector<double> flexed(straight.size());
  sim.cell_capacitances(rest, flexed, WristAngles{deg_to_rad(35.0), 0.0});
  const std::size_t near = cell("dorsum_proximal_along_2"), far = cell("dorsum_distal_along_2");
  EXPECT_GT(flexed[near] - straight[near], 0.03 * straight[near]);
  EXPECT_GT(flexed[near] - straight[near], 2.0 * (flexed[far] - straight[far]));
  // The fingers feel only the glove's tension.
  const std::size_t mcp = cell("index_mcp_along");
  EXPECT_GT(flexed[mcp], straight[mcp]);
  EXPECT_LT(flexed[mcp] - straight[mcp], 0.3 * (flexed[near] - straight[near]));
  // Radial deviation: the ulnar side of the dorsum stretches, the radial side less.
  std::vector<double> radial(straight.size());
  sim.cell_capacitances(rest, radial, WristAngles{0.0, deg_to_rad(18.0)});
  EXPECT_GT(radial[cell("dorsum_across_4")] - straight[cell("dorsum_across_4")],
            radial[cell("dorsum_across_0")] - straight[cell("dorsum_across_0")]);
}

TEST(StretchGloveSim, TheGloveCreepsWithinASession) {
  auto run = [](bool creep) {
    StretchGloveSimOptions o = StretchGloveSimOptions::ideal();
    o.enable_creep = creep;
    o.creep_per_sqrt_s_m = 1e-3;
    auto sim = make_sim(o);
    std::vector<double> first, later;
    for (int k = 0; k < 4 * 960; ++k) {
      const double v = sim.measure(ExplorationMotion::relaxed()).capacitance_pf;
      if (k < 182) first.push_back(v);
      if (k >= 3 * 960 && k < 3 * 960 + 182) later.push_back(v);
    }
    // Compare the same combinations: 3 * 960 is not a multiple of 182.
    std::vector<double> a(182), b(182);
    for (int k = 0; k < 182; ++k) {
      a[static_cast<std::size_t>(k)] = first[static_cast<std::size_t>(k)];
      b[static_cast<std::size_t>((3 * 960 + k) % 182)] = later[static_cast<std::size_t>(k)];
    }
    double diff = 0.0;
    for (int k = 0; k < 182; ++k) diff = std::max(diff, std::abs(a[static_cast<std::size_t>(k)] - b[static_cast<std::size_t>(k)]));
    return diff;
  };
  EXPECT_EQ(run(false), 0.0);
  EXPECT_GT(run(true), 0.01);
}

TEST(StretchGloveSim, BiggerHandStretchesMore) {
  auto small = make_sim(StretchGloveSimOptions::ideal(), 0);
  auto big = make_sim(StretchGloveSimOptions::ideal(), kSimSubjectCount - 1);
  ASSERT_LT(small.shape().hand_length_m, big.shape().hand_length_m);
  const HandAngles rest = ExplorationMotion::relaxed();
  const HandAngles flexed = with(rest, HandDof::index_pip_flexion, 90);
  const std::size_t i = cell("index_pip_along");
  const double small_rest = capacitances(small, rest)[i], big_rest = capacitances(big, rest)[i];
  // Pre-stretched more on the bigger hand...
  EXPECT_GT(big_rest, small_rest * 1.1);
  // ...and the same angle stretches its (thicker) finger's skin more.
  EXPECT_GT(capacitances(big, flexed)[i] - big_rest, capacitances(small, flexed)[i] - small_rest);
}

TEST(StretchGloveSim, DonningRedrawsGainsOffsetsAndSlip) {
  StretchGloveSimOptions o;
  o.seed = 42;
  auto sim = make_sim(o);
  const StretchDonning first = sim.donning();
  const HandAngles rest = ExplorationMotion::relaxed();
  const auto c_first = capacitances(sim, rest);
  sim.don(1);
  const StretchDonning second = sim.donning();
  EXPECT_NE(first.gain, second.gain);
  EXPECT_NE(first.offset_pf, second.offset_pf);
  EXPECT_NE(first.slip_m, second.slip_m);
  EXPECT_NE(capacitances(sim, rest), c_first);
  // Gains scatter by about the configured 4 %.
  double sum = 0.0, sq = 0.0;
  for (double g : second.gain) {
    sum += g;
    sq += (g - 1.0) * (g - 1.0);
  }
  const double n = static_cast<double>(second.gain.size());
  EXPECT_NEAR(sum / n, 1.0, 0.03);
  EXPECT_NEAR(std::sqrt(sq / n), o.donning_gain_sigma, 0.025);
  // The same donning index is the same draw.
  sim.don(0);
  EXPECT_EQ(sim.donning().gain, first.gain);
  EXPECT_EQ(capacitances(sim, rest), c_first);
  // Ideal: nothing varies.
  auto ideal = make_sim();
  ideal.don(3);
  for (double g : ideal.donning().gain) EXPECT_EQ(g, 1.0);
}

TEST(StretchGloveSim, MeasurementsAreTheMatrixTimesTheCells) {
  auto sim = make_sim();
  const auto& L = sim.layout();
  const Eigen::MatrixXd M = L.measurement_matrix();
  const HandAngles pose = with(ExplorationMotion::relaxed(), HandDof::little_mcp_flexion, 60);
  const auto c = capacitances(sim, pose);
  const Eigen::VectorXd Cc = Eigen::Map<const Eigen::VectorXd>(c.data(), static_cast<Eigen::Index>(c.size()));
  const Eigen::VectorXd Cm = M * Cc;
  for (std::size_t k = 0; k < 2 * L.measurement_count(); ++k) {
    const auto m = sim.measure(pose);
    EXPECT_EQ(m.index, k);
    EXPECT_EQ(m.combination, k % L.measurement_count());
    EXPECT_NEAR(m.capacitance_pf, Cm(static_cast<Eigen::Index>(m.combination)), 1e-9);
    EXPECT_FALSE(m.saturated);
  }
}

TEST(StretchGloveSim, MeasurementTimingGivesSixtyHertzFrames) {
  auto sim = make_sim();
  EXPECT_EQ(sim.measurement_time(0), 0);
  EXPECT_EQ(sim.measurement_time(960), kNsPerSecond);
  // 16 measurements per frame at 960 per second: 1/60 s.
  EXPECT_NEAR(static_cast<double>(sim.measurement_time(16 * 60)), 1e9, 1.0);
  EXPECT_EQ(sim.measurement_time(16 * 3), 50'000'000);
}

TEST(StretchGloveSim, NoiseHasTheConfiguredSize) {
  StretchGloveSimOptions o = StretchGloveSimOptions::ideal();
  o.enable_noise = true;
  auto sim = make_sim(o);
  const HandAngles pose = ExplorationMotion::relaxed();
  double sum = 0.0, sq = 0.0, expected_var = 0.0;
  const int n = 4000;
  for (int i = 0; i < n; ++i) {
    StretchMeasurementTruth truth;
    const auto m = sim.measure(pose, &truth);
    const double e = m.capacitance_pf - truth.noise_free_pf;
    sum += e;
    sq += e * e;
    expected_var += std::pow(o.noise_pf, 2) + std::pow(o.noise_relative * truth.noise_free_pf, 2);
  }
  EXPECT_NEAR(sum / n, 0.0, 0.05 * std::sqrt(expected_var / n) * 5);
  EXPECT_NEAR(std::sqrt(sq / n), std::sqrt(expected_var / n), 0.05 * std::sqrt(expected_var / n));
}

TEST(StretchGloveSim, SameSeedSameBytesOtherSeedOtherBytes) {
  auto run = [](std::uint64_t seed) {
    StretchGloveSimOptions o;
    o.seed = seed;
    o.outlier_probability = 0.01;  // so the outlier stream is exercised too
    auto sim = StretchGloveSimulator::create(StretchGloveLayout::thesis_default(), shape_of(3), o, 2);
    StretchSessionOptions so;
    so.exploration_s = 0.5;
    so.task_s = 0.5;
    StretchGloveSession session(std::move(*sim), so);
    std::vector<double> out;
    StretchSample s;
    while (session.next(s)) out.push_back(s.measurement.capacitance_pf);
    return out;
  };
  const auto a = run(5), b = run(5), c = run(6);
  ASSERT_EQ(a.size(), 960u);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
}

TEST(StretchGloveSim, InjectedFaults) {
  auto sim = make_sim();
  const auto& L = sim.layout();
  StretchFaults f;
  f.nan_measurements = {3};
  f.saturated_measurements = {5};
  const std::size_t dead = cell("index_mcp_along");
  f.dead_cells = {dead};
  f.dead_from_ns = sim.measurement_time(L.measurement_count());  // from the second cycle on
  sim.set_faults(f);
  const HandAngles pose = ExplorationMotion::relaxed();
  const auto c = capacitances(sim, pose);
  std::vector<double> first_cycle(L.measurement_count(), 0.0);
  for (std::size_t k = 0; k < 2 * L.measurement_count(); ++k) {
    const auto m = sim.measure(pose);
    if (k == 3) {
      EXPECT_TRUE(std::isnan(m.capacitance_pf));
    } else if (k == 5) {
      EXPECT_TRUE(m.saturated);
      EXPECT_EQ(m.capacitance_pf, sim.options().full_scale_pf);
    } else if (k < L.measurement_count()) {
      first_cycle[m.combination] = m.capacitance_pf;
    } else {
      // The open lead takes the dead cell out of every row that had it.
      const auto cells = sim.cells_in(m.combination);
      double expected = 0.0;
      for (auto i : cells) expected += i == dead ? 0.0 : c[i];
      EXPECT_NEAR(m.capacitance_pf, expected, 1e-9);
      if (m.combination != 3 && m.combination != 5 && std::find(cells.begin(), cells.end(), dead) != cells.end()) {
        EXPECT_NEAR(first_cycle[m.combination] - m.capacitance_pf, c[dead], 1e-9);
      }
    }
  }
}

TEST(StretchGloveSim, FullScaleClipsAndFlags) {
  StretchGloveSimOptions o = StretchGloveSimOptions::ideal();
  o.enable_saturation = true;
  o.full_scale_pf = 40.0;
  auto sim = make_sim(o);
  bool saw_clipped = false, saw_clean = false;
  for (int k = 0; k < 182; ++k) {
    const auto m = sim.measure(ExplorationMotion::relaxed());
    EXPECT_LE(m.capacitance_pf, 40.0);
    (m.saturated ? saw_clipped : saw_clean) = true;
  }
  EXPECT_TRUE(saw_clipped);
  EXPECT_TRUE(saw_clean);
}

TEST(StretchGloveSim, ExplorationReachesTheRangesTaskStaysInside) {
  ExplorationMotion explore(JointLimits::defaults(), ExplorationOptions{}, 11);
  HandAngles lo, hi;
  lo.fill(1e9);
  hi.fill(-1e9);
  const auto lim = JointLimits::defaults();
  for (TimeNs t = 0; t < 60 * kNsPerSecond; t += 20 * kNsPerMillisecond) {
    const HandAngles a = explore.sample(t);
    EXPECT_TRUE(lim.contains(a));
    for (std::size_t d = 0; d < kHandDofCount; ++d) {
      lo[d] = std::min(lo[d], a[d]);
      hi[d] = std::max(hi[d], a[d]);
    }
  }
  for (std::size_t d = 0; d < kHandDofCount; ++d) {
    const double span = lim.max_rad[d] - lim.min_rad[d];
    EXPECT_LT(lo[d] - lim.min_rad[d], 0.2 * span) << to_string(static_cast<HandDof>(d));
    EXPECT_LT(lim.max_rad[d] - hi[d], 0.2 * span) << to_string(static_cast<HandDof>(d));
  }
}

TEST(StretchGloveSim, SessionPhasesJoinSmoothly) {
  StretchSessionOptions so;
  so.exploration_s = 3.0;
  so.task_s = 2.0;
  StretchGloveSession session(make_sim(StretchGloveSimOptions{}), so);
  EXPECT_EQ(session.total_measurements(), 4800u);
  StretchSample s, prev;
  std::size_t n = 0, exploration = 0;
  double max_step = 0.0;
  while (session.next(s)) {
    if (n > 0) {
      for (std::size_t d = 0; d < kHandDofCount; ++d) max_step = std::max(max_step, std::abs(s.angles[d] - prev.angles[d]));
      EXPECT_GE(static_cast<int>(s.phase), static_cast<int>(prev.phase));
    }
    exploration += s.phase == StretchPhase::exploration;
    EXPECT_EQ(s.phase == StretchPhase::exploration, s.measurement.time_ns < 3 * kNsPerSecond);
    prev = s;
    ++n;
  }
  EXPECT_EQ(n, 4800u);
  EXPECT_EQ(exploration, 2880u);
  // About 2 rad/s at most between measurements 1 ms apart: no jumps.
  EXPECT_LT(max_step, deg_to_rad(1.0));
}

TEST(StretchGloveSim, OptionsAreValidated) {
  StretchGloveSimOptions o;
  o.noise_relative = -1.0;
  auto s = StretchGloveSimulator::create(StretchGloveLayout::thesis_default(), shape_of(0), o);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("noise_relative"), std::string::npos);
  EXPECT_NE(StretchGloveSimOptions{}.describe().find("rate=960.0Hz"), std::string::npos);
}

}  // namespace
}  // namespace proprio::sim
