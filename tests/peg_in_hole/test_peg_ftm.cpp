// Peg-in-hole with the simulated FTM glove (--tracker ftm): the world gets
// the FTM's estimate of the participant's true hand, "without AA" is the
// FTM's abduction removed, and the devices' currents reach the compasses.
#include <gtest/gtest.h>

#include <cmath>

#include "proprio/peg_in_hole/config.hpp"
#include "proprio/peg_in_hole/ftm_glove.hpp"
#include "proprio/peg_in_hole/protocol.hpp"
#include "proprio/peg_in_hole/simulated_user.hpp"
#include "proprio/peg_in_hole/study_runner.hpp"
#include "proprio/peg_in_hole/world.hpp"
#include "proprio/ftm_sim/ftm_wearer_sim.hpp"
#include "proprio/sim/magnetic_field.hpp"

using namespace proprio;
using namespace proprio::peg_in_hole;

namespace {

// A participant's hand held still in front of the body, index spread
// radially by `index_abduction_rad`.
HandCommand pegftm_still_hand(double index_abduction_rad) {
  HandCommand c;
  c.angles.fill(0.0);
  c.angles[index_of(HandDof::index_mcp_flexion)] = 0.4;
  c.angles[index_of(HandDof::index_mcp_abduction)] = index_abduction_rad;
  c.T_world_wrist = Pose{Quat(Eigen::AngleAxisd(-0.3, Vec3::UnitX())), Vec3(0.0, 1.1, -0.2)};
  return c;
}

std::unique_ptr<SimulatedFtmGlove> pegftm_glove(std::uint64_t seed, bool leads = true) {
  auto shape = simulated_participant_hand(SimUserOptions{});
  EXPECT_TRUE(shape.ok());
  SimulatedFtmGloveOptions o;
  o.seed = seed;
  o.device_leads = leads;
  auto g = SimulatedFtmGlove::create(*shape, o);
  EXPECT_TRUE(g.ok()) << (g.ok() ? "" : g.error().message);
  return g.ok() ? std::move(*g) : nullptr;
}

// Runs the glove for `seconds` of world time on a still hand with the given
// device currents; the last tracked command and the trial's figures.
std::pair<HandCommand, FtmTrialFigures> pegftm_run(SimulatedFtmGlove& glove, const HandCommand& truth,
                                                   bool track_abduction, double seconds, double current_a) {
  EXPECT_TRUE(glove.begin_trial(truth, track_abduction).ok());
  HandCommand out;
  std::array<double, kFingerCount> currents{};
  currents[static_cast<std::size_t>(Finger::thumb)] = current_a;
  currents[static_cast<std::size_t>(Finger::index)] = current_a;
  currents[static_cast<std::size_t>(Finger::middle)] = current_a;
  const auto ticks = static_cast<std::int64_t>(seconds * 1000.0);
  for (std::int64_t k = 0; k < ticks; ++k) {
    const TimeNs t = k * kNsPerMillisecond;
    out = glove.track(t, truth);
    glove.set_device_currents(t + kNsPerMillisecond, currents);
  }
  return {out, glove.end_trial()};
}

}  // namespace

TEST(PegFtm, TrackerOptionParsesAndNamesTheKey) {
  auto c = PegInHoleConfig::parse("[study]\ntracker = \"ftm\"\n");
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->tracker, SimTracker::ftm);
  auto bad = PegInHoleConfig::parse("[study]\ntracker = \"vicon\"\n");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("tracker"), std::string::npos) << bad.error().message;
}

TEST(PegFtm, WithoutAaIsTheFtmsAbductionRemovedNotTheServos) {
  PegInHoleConfig c;
  c.tracker = SimTracker::ftm;
  EXPECT_FALSE(servo_loop_options(c, setting_from_number(2)).remove_finger_abduction);
  c.tracker = SimTracker::ideal;
  EXPECT_TRUE(servo_loop_options(c, setting_from_number(2)).remove_finger_abduction);

  auto glove = pegftm_glove(3);
  ASSERT_TRUE(glove);
  const HandCommand truth = pegftm_still_hand(0.22);
  const auto with = pegftm_run(*glove, truth, true, 2.0, 0.0);
  const auto without = pegftm_run(*glove, truth, false, 2.0, 0.0);
  const std::size_t aa = index_of(HandDof::index_mcp_abduction);
  // The FTM measures the spread (within its calibration's error) ...
  EXPECT_NEAR(with.first.angles[aa], 0.22, deg_to_rad(6.0));
  // ... and without AA reports none, while the flexion is still measured.
  EXPECT_EQ(without.first.angles[aa], 0.0);
  EXPECT_EQ(without.first.angles[index_of(HandDof::middle_mcp_abduction)], 0.0);
  EXPECT_NEAR(without.first.angles[index_of(HandDof::index_mcp_flexion)], 0.4, deg_to_rad(8.0));
}

TEST(PegFtm, DeviceCurrentsReachTheCompasses) {
  // Same glove seed, same hand: only the devices' current differs.
  const HandCommand truth = pegftm_still_hand(0.1);
  auto quiet = pegftm_glove(5);
  auto pushing = pegftm_glove(5);
  ASSERT_TRUE(quiet && pushing);
  const auto q = pegftm_run(*quiet, truth, true, 1.0, 0.0);
  const auto p = pegftm_run(*pushing, truth, true, 1.0, 1.5);
  EXPECT_GT(q.second.samples, 100U);
  EXPECT_DOUBLE_EQ(q.second.max_current_a[1], 0.0);
  EXPECT_DOUBLE_EQ(p.second.max_current_a[1], 1.5);
  for (std::size_t i = 0; i < kFtmCompassCount; ++i) {
    EXPECT_GT(q.second.max_disturbance_uT[i], 0.0) << i;  // the devices' magnets
    // The winding term (moment_per_current) adds to the magnets' at every IMU.
    EXPECT_GT(p.second.max_disturbance_uT[i], 1.2 * q.second.max_disturbance_uT[i]) << i;
  }
}

TEST(PegFtm, ShortSimulatedTrialRunsOnTheTrackedHand) {
  PegInHoleConfig c;
  c.tracker = SimTracker::ftm;
  auto shape = simulated_participant_hand(c.sim_user);
  ASSERT_TRUE(shape.ok());
  const HandModel hand(*shape);
  auto dev = load_device_model(c);
  ASSERT_TRUE(dev.ok()) << dev.error().message;
  auto glove = pegftm_glove(7);
  ASSERT_TRUE(glove);
  SimulatedUser user(c, hand, 7);
  SimulatedTrialOptions to;
  to.time_limit_s = 2.0;
  to.ftm_glove = glove.get();
  auto r = run_simulated_trial(c, trial_layout(c, 7, 0), setting_from_number(1), user, hand, *dev, to);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_TRUE(r->ftm.has_value());
  // The world ran on an estimate: not the true hand, but close to it (the
  // wave-1 bench: 2-3.5 deg on free motion; here reaches with a 6 ms + wrist
  // tracker lag and the participant's pronated thumb).
  EXPECT_GT(r->ftm->mean_angle_error_deg, 0.1);
  EXPECT_LT(r->ftm->mean_angle_error_deg, 20.0);
  EXPECT_GT(r->ftm->mean_wrist_error_mm, 0.05);
  EXPECT_LT(r->ftm->mean_wrist_error_mm, 40.0);
  EXPECT_GE(r->ftm->samples, 390U);
  const study::Response resp = trial_response(
      c, 0, setting_from_number(1), trial_layout(c, 7, 0),
      {r->completed, r->completion_time_s, r->breaks, r->drops, r->peak_force_n, r->mean_force_n, "", "simulated", r->ftm});
  EXPECT_EQ(resp.extra.at("tracker"), "ftm");
  EXPECT_FALSE(resp.extra.at("ftm_max_disturbance_uT_index_pp").empty());
}

TEST(PegFtm, LeadSegmentMatchesTheLongWireAndPairCancels) {
  // A 2 m conductor seen from 5 mm at its middle: mu0 I / (2 pi d).
  const double i_a = 0.5, d = 0.005;
  const Vec3 b = sim::segment_field_T(Vec3(0, 0, -1), Vec3(0, 0, 1), i_a, Vec3(d, 0, 0));
  EXPECT_NEAR(b.norm(), 2e-7 * i_a / d, 1e-3 * 2e-7 * i_a / d);
  // Right-hand rule: current along +Z, point at +X: field along +Y.
  EXPECT_GT(b.y(), 0.0);
  // The pair (return 1 mm further along +X) nearly cancels: two long wires
  // at 20 and 19 mm, opposite currents (about mu0 I s / (2 pi r^2)).
  const Vec3 p(0.02, 0, 0);
  const Vec3 pair = sim::segment_field_T(Vec3(0, 0, -1), Vec3(0, 0, 1), i_a, p) +
                    sim::segment_field_T(Vec3(0.001, 0, 1), Vec3(0.001, 0, -1), i_a, p);
  const double expect = 2e-7 * i_a * (1.0 / 0.019 - 1.0 / 0.020);
  EXPECT_NEAR(pair.norm(), expect, 0.02 * expect);
}

TEST(PegFtm, LeadsDisturbTheProximalCompassesFarMoreThanTheDipoles) {
  const HandCommand truth = pegftm_still_hand(0.1);
  auto dipoles = pegftm_glove(5, false);
  auto leads = pegftm_glove(5, true);
  ASSERT_TRUE(dipoles && leads);
  const auto a = pegftm_run(*dipoles, truth, true, 0.5, 0.5);
  const auto b = pegftm_run(*leads, truth, true, 0.5, 0.5);
  const std::size_t thumb_mc = 1, index_pp = 2;
  EXPECT_GT(b.second.max_disturbance_uT[index_pp], 10.0 * a.second.max_disturbance_uT[index_pp]);
  EXPECT_GT(b.second.max_disturbance_uT[thumb_mc], 10.0 * a.second.max_disturbance_uT[thumb_mc]);
}

TEST(PegFtm, DrivenWearerIsWhatItWasDrivenWith) {
  ftm_sim::FtmWearerOptions o;
  o.driven_task = true;
  o.task_s = 10.0;
  auto w = ftm_sim::FtmWearerSimulator::create(o);
  ASSERT_TRUE(w.ok()) << w.error().message;
  auto& sim = **w;
  const TimeNs t0 = sim.task_begin_ns() + seconds_to_ns(o.calibration.task_transition_s);
  HandCommand a = pegftm_still_hand(0.1), b = pegftm_still_hand(0.2);
  b.T_world_wrist.p += Vec3(0.01, 0.0, 0.0);
  sim.drive(t0, a.T_world_wrist, a.angles);
  sim.drive(t0 + 10 * kNsPerMillisecond, b.T_world_wrist, b.angles);
  const std::size_t aa = index_of(HandDof::index_mcp_abduction);
  EXPECT_NEAR(sim.truth_at(t0).angles[aa], 0.1, 1e-9);
  // Linear between samples, held after the last.
  EXPECT_NEAR(sim.truth_at(t0 + 5 * kNsPerMillisecond).angles[aa], 0.15, 1e-9);
  EXPECT_NEAR(sim.truth_at(t0 + 50 * kNsPerMillisecond).angles[aa], 0.2, 1e-9);
  // A later drive changes what a time past the old end answers (no stale memo).
  sim.drive(t0 + 100 * kNsPerMillisecond, a.T_world_wrist, a.angles);
  EXPECT_NEAR(sim.truth_at(t0 + 55 * kNsPerMillisecond).angles[aa], 0.15, 1e-9);
  // Not driven: the motion protocol, which ignores drive().
  ftm_sim::FtmWearerOptions p;
  p.task_s = 2.0;
  auto q = ftm_sim::FtmWearerSimulator::create(p);
  ASSERT_TRUE(q.ok());
  const double before = (*q)->truth_at((*q)->task_begin_ns() + seconds_to_ns(1.5)).angles[aa];
  (*q)->drive((*q)->task_begin_ns(), b.T_world_wrist, b.angles);
  EXPECT_EQ((*q)->truth_at((*q)->task_begin_ns() + seconds_to_ns(1.5)).angles[aa], before);
}

// The diagnostic ablation (FtmGloveAblation) replaces exactly its part of the
// tracked hand by the true one and leaves the rest the tracker's.
TEST(PegFtm, AblationReplacesOnlyItsPartOfTheTrackedHand) {
  for (int k = 0; k <= static_cast<int>(FtmGloveAblation::true_mountings); ++k) {
    const auto a = static_cast<FtmGloveAblation>(k);
    auto back = parse_ftm_glove_ablation(to_string(a));
    ASSERT_TRUE(back.ok()) << to_string(a);
    EXPECT_EQ(*back, a);
  }
  auto bad = parse_ftm_glove_ablation("truth_everything");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("truth_everything"), std::string::npos) << bad.error().message;

  auto shape = simulated_participant_hand(SimUserOptions{});
  ASSERT_TRUE(shape.ok());
  const HandCommand truth = pegftm_still_hand(0.22);
  const auto run = [&](FtmGloveAblation a) {
    SimulatedFtmGloveOptions o;
    o.seed = 5;
    o.ablate = a;
    auto g = SimulatedFtmGlove::create(*shape, o);
    EXPECT_TRUE(g.ok()) << (g.ok() ? "" : g.error().message);
    EXPECT_NE((*g)->describe().find(to_string(a)), std::string::npos) << (*g)->describe();
    return pegftm_run(**g, truth, true, 1.0, 0.0);
  };
  const auto max_angle_diff = [](const HandAngles& x, const HandAngles& y) {
    double m = 0.0;
    for (std::size_t i = 0; i < kHandDofCount; ++i) m = std::max(m, std::abs(x[i] - y[i]));
    return m;
  };
  // The hand is still, so the true (smoothed) hand is the command itself.
  const auto wrist = run(FtmGloveAblation::truth_wrist);
  EXPECT_LT((wrist.first.T_world_wrist.p - truth.T_world_wrist.p).norm(), 1e-9);
  EXPECT_LT(wrist.first.T_world_wrist.q.angularDistance(truth.T_world_wrist.q), 1e-9);
  EXPECT_GT(max_angle_diff(wrist.first.angles, truth.angles), 1e-4);  // the tracker's angles
  // The figures still describe the tracker, not what the world got.
  EXPECT_GT(wrist.second.mean_wrist_angle_error_deg, 0.0);

  const auto angles = run(FtmGloveAblation::truth_angles);
  EXPECT_LT(max_angle_diff(angles.first.angles, truth.angles), 1e-12);
  EXPECT_GT(angles.first.T_world_wrist.q.angularDistance(truth.T_world_wrist.q), 1e-4);  // the tracker's wrist
}
