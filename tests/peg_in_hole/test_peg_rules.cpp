// Peg-in-hole: the task's rules, config, randomisation and the study
// conditions as the servo loop applies them.
#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <string>

#include <fmt/format.h>

#include "proprio/peg_in_hole/config.hpp"
#include "proprio/peg_in_hole/monitor.hpp"
#include "proprio/peg_in_hole/protocol.hpp"
#include "proprio/peg_in_hole/simulated_user.hpp"
#include "proprio/peg_in_hole/study_runner.hpp"
#include "proprio/peg_in_hole/world.hpp"
#include "proprio/study/design.hpp"

using namespace proprio;
using namespace proprio::peg_in_hole;

namespace {

// Feeds a constant force at 1 kHz; the tick (1-based) the peg broke, or -1.
int ticks_to_break(double force_n, int max_ticks, double tau_s = 0.02) {
  BreakMonitor m(5.0, tau_s);
  for (int i = 0; i <= max_ticks; ++i) {
    if (m.update(static_cast<TimeNs>(i) * kNsPerMillisecond, force_n)) return i;
  }
  return -1;
}

}  // namespace

TEST(PegBreak, ExactlyFiveNewtonsBreaksAndJustBelowNeverDoes) {
  EXPECT_GT(ticks_to_break(5.0, 5000), 0) << "a steady 5 N must reach the inclusive threshold";
  EXPECT_EQ(ticks_to_break(4.999, 20000), -1);
  EXPECT_EQ(ticks_to_break(4.0, 20000), -1);
}

TEST(PegBreak, TheFilterDelaysABreakByItsTimeConstant) {
  // A step to 6 N crosses 5 N when 6 (1 - exp(-t / tau)) = 5: t = tau ln 6 = 35.8 ms.
  const int t = ticks_to_break(6.0, 1000);
  EXPECT_GE(t, 35);
  EXPECT_LE(t, 37);
  // A 3 ms spike of 20 N (a finger landing) does not break it: 20 (1 - e^-0.15) = 2.8 N.
  BreakMonitor m(5.0, 0.02);
  bool broke = false;
  for (int i = 0; i < 200; ++i) broke |= m.update(i * kNsPerMillisecond, i >= 10 && i < 13 ? 20.0 : 0.5);
  EXPECT_FALSE(broke);
  EXPECT_LT(m.filtered_n(), 5.0);
}

TEST(PegBreak, BreaksOnceUntilResetAndIgnoresNaN) {
  BreakMonitor m(5.0, 0.0);  // unfiltered
  EXPECT_FALSE(m.update(0, std::nan("")));
  EXPECT_FALSE(m.update(1, std::numeric_limits<double>::infinity()));
  EXPECT_EQ(m.rejected_samples(), 2u);
  EXPECT_FALSE(m.update(2, 4.9));
  EXPECT_TRUE(m.update(3, 5.0));
  EXPECT_FALSE(m.update(4, 9.0)) << "already broken";
  EXPECT_TRUE(m.broken());
  m.reset();
  EXPECT_FALSE(m.broken());
  EXPECT_EQ(m.filtered_n(), 0.0);
}

TEST(PegBreak, GraspForceIsTheLargestContactNormalForce) {
  std::array<double, kFingerCount> n{};
  n[0] = 2.0;
  n[1] = 3.5;
  n[2] = std::nan("");
  EXPECT_DOUBLE_EQ(grasp_force_n(n), 3.5);
}

TEST(PegColour, WhiteToBlueOverTheScaleAndRedWhenBroken) {
  const auto white = peg_colour(0.0, 10.0, false);
  const auto half = peg_colour(5.0, 10.0, false);
  const auto blue = peg_colour(12.0, 10.0, false);
  const auto red = peg_colour(1.0, 10.0, true);
  EXPECT_FLOAT_EQ(white[0], 1.0f);
  EXPECT_FLOAT_EQ(white[2], 1.0f);
  EXPECT_FLOAT_EQ(half[0], 0.5f);
  EXPECT_FLOAT_EQ(blue[0], 0.0f);
  EXPECT_FLOAT_EQ(blue[2], 1.0f);
  EXPECT_GT(red[0], red[2]);
  EXPECT_NEAR(force_from_colour(half, 10.0), 5.0, 1e-6);
  EXPECT_FLOAT_EQ(peg_colour(std::nan(""), 10.0, false)[0], 1.0f);
}

TEST(PegHole, InsertionNeedsDepthInsideTheBore) {
  PegInHoleConfig c;
  const HoleGeometry h = hole_geometry(c, Vec3(0.25, 1.0, -0.45));
  const Quat along_x(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitY()));  // object z -> world +x
  const double half = 0.5 * c.peg.length_m;
  const Pose in{along_x, Vec3(0.25 + 0.035 - half, 1.0, -0.45)};
  EXPECT_TRUE(insertion_state(in, half, h).inserted);
  const Pose shallow{along_x, Vec3(0.25 + 0.02 - half, 1.0, -0.45)};
  EXPECT_FALSE(insertion_state(shallow, half, h).inserted);
  const Pose beside{along_x, Vec3(0.25 + 0.035 - half, 1.04, -0.45)};
  EXPECT_FALSE(insertion_state(beside, half, h).inserted);
  EXPECT_NEAR(insertion_state(in, half, h).axis_angle_rad, 0.0, 1e-9);
}

TEST(PegConfig, DefaultsAreThePublishedValues) {
  PegInHoleConfig c;
  EXPECT_DOUBLE_EQ(c.peg.length_m, 0.1862);
  EXPECT_DOUBLE_EQ(c.peg.radius_m, 0.02584);
  EXPECT_DOUBLE_EQ(c.peg.mass_kg, 0.5);
  EXPECT_DOUBLE_EQ(c.peg.break_force_n, 5.0);
  EXPECT_DOUBLE_EQ(c.peg.colour_scale_max_n, 10.0);
  EXPECT_DOUBLE_EQ(c.familiarisation.spring_phase_s, 180.0);
  EXPECT_DOUBLE_EQ(c.familiarisation.ground_phase_s, 180.0);
  EXPECT_EQ(c.main_task.repetitions, 5);
  EXPECT_EQ(c.main_task.familiarisation_trials, 4);
  ASSERT_EQ(c.devices.fingers.size(), 3u);
  EXPECT_EQ(c.devices.fingers[0], Finger::thumb);
  EXPECT_TRUE(c.validate());
}

TEST(PegConfig, TomlOverridesAndClearErrors) {
  auto c = PegInHoleConfig::parse("[hole]\nclearance_m = 0.001\n[main_task]\nrepetitions = 2\n[devices]\nfingers = "
                                  "[\"thumb\", \"index\"]\n",
                                  "t.toml");
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_DOUBLE_EQ(c->hole.clearance_m, 0.001);
  EXPECT_EQ(c->main_task.repetitions, 2);
  EXPECT_EQ(c->devices.fingers.size(), 2u);
  EXPECT_DOUBLE_EQ(c->devices.finger_joint_stiffness_nm_per_rad, 2.5);
  auto stiff = PegInHoleConfig::parse("[devices]\nfinger_joint_stiffness_nm_per_rad = 1.5\n[sim_user]\nfelt_ceiling_n = 0.9\n");
  ASSERT_TRUE(stiff) << stiff.error().message;
  EXPECT_DOUBLE_EQ(stiff->devices.finger_joint_stiffness_nm_per_rad, 1.5);
  EXPECT_DOUBLE_EQ(stiff->sim_user.felt_ceiling_n, 0.9);
  EXPECT_FALSE(PegInHoleConfig::parse("[devices]\nfinger_joint_stiffness_nm_per_rad = 0\n"));
  auto scaled = PegInHoleConfig::parse("[devices]\nforce_scale = 0.5\n[sim_user]\nthumb_pronation_deg = 0\n");
  ASSERT_TRUE(scaled) << scaled.error().message;
  EXPECT_DOUBLE_EQ(scaled->devices.force_scale, 0.5);
  EXPECT_DOUBLE_EQ(scaled->sim_user.thumb_pronation_deg, 0.0);
  EXPECT_FALSE(PegInHoleConfig::parse("[devices]\nforce_scale = 0\n"));
  EXPECT_DOUBLE_EQ(c->devices.solver_tolerance, 1e-5);
  auto tight = PegInHoleConfig::parse("[devices]\nsolver_tolerance = 1e-8\n");
  ASSERT_TRUE(tight) << tight.error().message;
  EXPECT_DOUBLE_EQ(contact_sim_options(*tight).solver_tolerance, 1e-8);
  EXPECT_FALSE(PegInHoleConfig::parse("[devices]\nsolver_tolerance = 0.01\n"));
  EXPECT_FALSE(contact_sim_options(*c).torsional_friction);
  auto torsion = PegInHoleConfig::parse("[devices]\ntorsional_friction = true\n");
  ASSERT_TRUE(torsion) << torsion.error().message;
  EXPECT_TRUE(contact_sim_options(*torsion).torsional_friction);
  EXPECT_NE(torsion->describe().find("torsional friction on"), std::string::npos) << torsion->describe();
  EXPECT_FALSE(PegInHoleConfig::parse("[devices]\ntorsional_friction = 1.5\n"));
  EXPECT_EQ(c->devices.emulator_substeps, 4);
  auto fine = PegInHoleConfig::parse("[devices]\nemulator_substeps = 20\n");
  ASSERT_TRUE(fine) << fine.error().message;
  EXPECT_EQ(fine->devices.emulator_substeps, 20);
  EXPECT_NE(fine->describe().find("20 emulated device substeps"), std::string::npos) << fine->describe();
  EXPECT_FALSE(PegInHoleConfig::parse("[devices]\nemulator_substeps = 0\n"));
  auto unknown = PegInHoleConfig::parse("[peg]\nradius = 0.02\n", "t.toml");
  ASSERT_FALSE(unknown);
  EXPECT_NE(unknown.error().message.find("radius_m"), std::string::npos) << unknown.error().message;
  EXPECT_NE(unknown.error().message.find("t.toml"), std::string::npos);
  EXPECT_FALSE(PegInHoleConfig::parse("[peg]\nbreak_force_n = nan\n", "t.toml"));
  EXPECT_FALSE(PegInHoleConfig::parse("[peg]\nbreak_force_n = -1\n", "t.toml"));
  EXPECT_FALSE(PegInHoleConfig::parse("[hole]\nclearance_m = 0.04\n", "t.toml")) << "wider than the peg";
  EXPECT_FALSE(PegInHoleConfig::parse("[layout]\nhole_m = [0.25, 1.0]\n", "t.toml"));
  EXPECT_FALSE(PegInHoleConfig::parse("[devices]\nfingers = [\"pinky\"]\n", "t.toml"));
  EXPECT_FALSE(PegInHoleConfig::parse("[peg\n", "t.toml"));
}

TEST(PegProtocol, TwentyTrialsFourSettingsPerRoundReproducibleFromTheSeed) {
  PegInHoleConfig c;
  auto design = study_design(c);
  ASSERT_TRUE(design) << design.error().message;
  EXPECT_EQ(design->kind, "completion-time");
  const auto plan = study::plan_trials(*design, 0, 1234);
  const auto again = study::plan_trials(*design, 0, 1234);
  const auto other = study::plan_trials(*design, 1, 99);
  const auto cells = study::condition_cells(*design);
  ASSERT_EQ(plan.size(), 20u);
  bool differs = false;
  for (std::size_t i = 0; i < plan.size(); ++i) {
    EXPECT_EQ(plan[i].cell, again[i].cell);
    differs |= plan[i].cell != other[i].cell;
  }
  EXPECT_TRUE(differs) << "another participant's seed gives another order";
  for (int round = 0; round < 5; ++round) {
    std::set<int> settings;
    for (int k = 0; k < 4; ++k) {
      const auto& levels = cells[static_cast<std::size_t>(plan[static_cast<std::size_t>(4 * round + k)].cell)].levels;
      EXPECT_EQ(levels[0], std::to_string(round + 1));
      settings.insert(setting_of(levels).number());
    }
    EXPECT_EQ(settings.size(), 4u) << "round " << round + 1 << " holds every setting once";
  }
}

TEST(PegProtocol, LayoutsAreSeededAndWithinTheirRanges) {
  PegInHoleConfig c;
  std::set<double> xs;
  for (int t = 0; t < 20; ++t) {
    const TrialLayout a = trial_layout(c, 77, t), b = trial_layout(c, 77, t);
    EXPECT_EQ(a.p_peg_start_in_world, b.p_peg_start_in_world);
    EXPECT_EQ(a.p_hole_in_world, b.p_hole_in_world);
    for (int k = 0; k < 3; ++k) {
      EXPECT_LE(std::abs(a.p_peg_start_in_world[k] - c.layout.peg_start_m[k]), c.layout.peg_start_range_m[k] + 1e-12);
      EXPECT_LE(std::abs(a.p_hole_in_world[k] - c.layout.hole_m[k]), c.layout.hole_range_m[k] + 1e-12);
    }
    xs.insert(a.p_peg_start_in_world.x());
  }
  EXPECT_EQ(xs.size(), 20u);
  EXPECT_NE(trial_layout(c, 78, 0).p_hole_in_world, trial_layout(c, 77, 0).p_hole_in_world);
}

namespace {

// The simulated participants' hand, as the study runner builds it.
HandModel user_hand() { return HandModel(*simulated_participant_hand(PegInHoleConfig{}.sim_user)); }

std::unique_ptr<PegWorld> make_world(Setting s) {
  PegInHoleConfig c;
  auto dev = load_device_model(c);
  EXPECT_TRUE(dev);
  auto w = PegWorld::create(c, trial_layout(c, 5, 0), s, user_hand(), *dev);
  EXPECT_TRUE(w) << (w ? "" : w.error().message);
  return std::move(*w);
}

}  // namespace

TEST(PegConditions, WithoutAaTheProxyLosesFingerAbduction) {
  for (bool aa : {true, false}) {
    auto w = make_world(Setting{true, aa});
    HandAngles a{};
    a[index_of(HandDof::index_mcp_abduction)] = 0.2;
    a[index_of(HandDof::middle_mcp_abduction)] = -0.12;
    a[index_of(HandDof::thumb_cmc_abduction)] = 0.5;
    const Pose T{Quat::Identity(), Vec3(0.0, 1.3, -0.1)};  // in free air
    for (int i = 0; i < 400; ++i) {
      w->submit_hand(T, a);
      w->step();
    }
    const HandAngles q = w->servo().simulation().proxy_angles();
    if (aa) {
      EXPECT_NEAR(q[index_of(HandDof::index_mcp_abduction)], 0.2, 0.03);
      EXPECT_NEAR(q[index_of(HandDof::middle_mcp_abduction)], -0.12, 0.03);
    } else {
      EXPECT_NEAR(q[index_of(HandDof::index_mcp_abduction)], 0.0, 0.01);
      EXPECT_NEAR(q[index_of(HandDof::middle_mcp_abduction)], 0.0, 0.01);
    }
    // The thumb keeps its CMC abduction (opposition) either way.
    EXPECT_NEAR(q[index_of(HandDof::thumb_cmc_abduction)], 0.5, 0.05);
  }
}

TEST(PegConditions, WithoutHapticsTheDevicesGetZeroWhileContactsStay) {
  for (bool haptics : {true, false}) {
    auto w = make_world(Setting{haptics, true});
    PegInHoleConfig c;
    SimulatedUser user(c, user_hand(), 3);
    const TrialLayout layout = w->layout();
    user.begin(0, Pose{Quat(Eigen::AngleAxisd(-0.3, Vec3::UnitX())),
                       layout.p_peg_start_in_world + Vec3(0.0, c.peg.length_m + 0.12, 0.25)});
    double max_contact = 0.0, max_commanded = 0.0, max_measured = 0.0;
    // Until a second after the hand first pressed on the peg (up to 10 s).
    int touched_at = -1;
    for (int i = 0; i < 10000 && (touched_at < 0 || i < touched_at + 1000); ++i) {
      const HandCommand cmd = user.act(perceive(*w));
      w->submit_hand(cmd.T_world_wrist, cmd.angles);
      w->step();
      max_contact = std::max(max_contact, grasp_force_n(w->snapshot().hands[0].object_normal_n));
      if (touched_at < 0 && max_contact > 0.2) touched_at = i;
      for (std::size_t ch = 0; ch < w->snapshot().channel_count; ++ch) {
        max_commanded = std::max(max_commanded, w->snapshot().channels[ch].commanded.in_tip_frame().norm());
        max_measured = std::max(max_measured, w->snapshot().channels[ch].measured.in_tip_frame().norm());
      }
    }
    EXPECT_GT(max_contact, 0.2) << "the hand touched the peg";
    if (haptics) {
      EXPECT_GT(max_commanded, 0.1);
    } else {
      EXPECT_EQ(max_commanded, 0.0);
      // Nothing a fingertip could feel (detection thresholds are tens of mN):
      // the idle motors' PD holds rest to within an encoder count, which
      // leaves the platform pressing up to ~0.6 mN.
      EXPECT_LT(max_measured, 0.005) << "the emulated devices render nothing";
    }
  }
}

TEST(PegWorldSpring, TheFamiliarisationPegHangsBelowItsAnchor) {
  PegInHoleConfig c;
  auto dev = load_device_model(c);
  ASSERT_TRUE(dev);
  auto w = PegWorld::create(c, trial_layout(c, 5, 0), Setting{}, user_hand(), *dev, WorldPhase::spring);
  ASSERT_TRUE(w) << w.error().message;
  for (int i = 0; i < 3000; ++i) (*w)->step();
  // Static sag m g / k = 0.5 * 9.81 / 200 = 2.45 cm below the anchor's rest point.
  const Vec3 rest = c.familiarisation.spring_anchor_m - Vec3(0, 0.5 * c.peg.length_m, 0);
  EXPECT_NEAR((*w)->peg_pose().p.y(), rest.y() - 0.5 * 9.81 / 200.0, 0.003);
  EXPECT_NEAR((*w)->peg_pose().p.x(), rest.x(), 0.002);
}

namespace {
// The angle (deg) between the thumb pad's normal and the direction to the
// finger pads, at the closure where the pinch would span the peg.
double thumb_pad_angle_deg(const PegInHoleConfig& c) {
  auto shape = simulated_participant_hand(c.sim_user);
  EXPECT_TRUE(shape);
  const HandModel hand(*shape);
  const SimulatedUser user(c, hand, 1);
  const double span = 2.0 * c.peg.radius_m + shape->fingers[0].joint_radius_m[3] + shape->fingers[1].joint_radius_m[4];
  double best_gap = 1e9, angle = 180.0;
  for (double s = 0.0; s <= 2.0; s += 0.01) {
    const auto j = hand.joint_poses_in_wrist(Handedness::right, user.posture(s));
    const Pose& t = j[index_of(HandJoint::thumb_tip)];
    const Vec3 f = 0.5 * (j[index_of(HandJoint::index_tip)].p + j[index_of(HandJoint::middle_tip)].p);
    const double gap = std::abs((f - t.p).norm() - span);
    if (gap < best_gap) {
      best_gap = gap;
      const Vec3 pad = t.q * Vec3(0, -1, 0);  // the pad faces the joint frame's -y
      angle = rad_to_deg(std::acos(std::clamp(pad.dot((f - t.p).normalized()), -1.0, 1.0)));
    }
  }
  return angle;
}
}  // namespace

// Without pronation the thumb meets the peg with the side of its tip, and the
// lift wedges it into the peg (docs/peg-in-hole.md, state item 8).
TEST(SimulatedUser, ThePronatedThumbsPadFacesTheFingerPads) {
  PegInHoleConfig c;
  EXPECT_LT(thumb_pad_angle_deg(c), 35.0);
  c.sim_user.thumb_pronation_deg = 0.0;
  EXPECT_GT(thumb_pad_angle_deg(c), 45.0);
}

// The user aims each finger at its own contact (the spread fingers reach the
// peg at different closures), so with AA both fingers carry the peg when the
// lift begins; before, the ulnar middle finger often hung in the air and the
// thumb and index alone pinched the peg, off its centre.
TEST(SimulatedUser, WithAaBothFingersCarryThePegWhenTheLiftBegins) {
  PegInHoleConfig c;
  auto dev = load_device_model(c);
  ASSERT_TRUE(dev);
  int both_carry = 0;
  std::string forces;
  for (int k = 0; k < 6; ++k) {
    SCOPED_TRACE(k);
    auto w = PegWorld::create(c, trial_layout(c, 21, k), Setting{false, true}, user_hand(), *dev);
    ASSERT_TRUE(w);
    SimulatedUser user(c, user_hand(), 40 + static_cast<std::uint64_t>(k));
    const TrialLayout& layout = (*w)->layout();
    user.begin(0, Pose{Quat(Eigen::AngleAxisd(-0.3, Vec3::UnitX())),
                       layout.p_peg_start_in_world + Vec3(0.0, c.peg.length_m + 0.12, 0.25)});
    // Each finger's normal force, averaged over the first half second of the lift.
    double index_n = 0.0, middle_n = 0.0;
    int lift_ticks = 0;
    for (int i = 0; i < 15000 && lift_ticks < 500; ++i) {
      const HandCommand cmd = user.act(perceive(**w));
      (*w)->submit_hand(cmd.T_world_wrist, cmd.angles);
      (*w)->step();
      if (user.phase_name() == "lift") {
        index_n += (*w)->snapshot().hands[0].contact[1].normal_n / 500.0;
        middle_n += (*w)->snapshot().hands[0].contact[2].normal_n / 500.0;
        ++lift_ticks;
      }
    }
    ASSERT_EQ(lift_ticks, 500) << "the user lifted the peg";
    forces += fmt::format(" ({:.2f}, {:.2f})", index_n, middle_n);
    if (std::min(index_n, middle_n) > 0.4) ++both_carry;
  }
  // Measured: 5 of 6 with the aimed fingers, 2 of 6 with a common closure.
  EXPECT_GE(both_carry, 5) << "index and middle normal force (N) per layout:" << forces;
}
