// The FTM tracker on exact synthetic readings: kinematic round trip (angles ->
// ideal IMU orientations and capacitances -> angles and joint poses), both
// hands, calibrated mountings, and what bad sensors do to the flags.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "ftm_hand_synth.hpp"
#include "proprio/ftm/ftm_tracker.hpp"

namespace proprio::ftm {
namespace {

namespace hs = hand_synth;
constexpr TimeNs kTrkTick = 5'000'000;

FtmCalibration trk_truth(Handedness hand, Rng& rng, double mount_deg) {
  FtmCalibration c = nominal_ftm_calibration(hand, 0.185, 0.09);
  for (auto& q : c.q_imu_segment) q = hs::random_rotation(rng, deg_to_rad(mount_deg));
  for (std::size_t b = 0; b < kFtmBendCount; ++b) {
    c.beta0_rad[b] = rng.uniform(-0.3, 0.3);
    c.beta1_rad_per_pF[b] = rng.uniform(0.04, 0.07);
  }
  return c;
}

HandModel trk_model(const FtmCalibration& c) {
  return HandModel(HandShape::from_measurements(c.hand_length_m, c.hand_width_m).value());
}

FtmTracker trk_make(const FtmCalibration& c, FtmTrackerOptions o = {}) {
  o.hand = c.hand;
  auto t = FtmTracker::create(o, c);
  EXPECT_TRUE(t.ok()) << (t.ok() ? "" : t.error().message);
  return std::move(t).value();
}

void trk_feed(FtmTracker& t, const HandModel& m, const FtmCalibration& c, const hs::HandTruth& h, TimeNs t0,
              int ticks) {
  std::vector<FtmEvent> ev;
  for (int k = 0; k < ticks; ++k) hs::tick(ev, m, c, h, t0 + k * kTrkTick, static_cast<std::uint64_t>(k));
  for (const auto& e : ev) t.push(e);
}

bool trk_finite(const HandPose& p) {
  for (const auto& T : p.T_world_joint)
    if (!T.p.allFinite() || !T.q.coeffs().allFinite()) return false;
  return true;
}

bool otr(const HandPose& p, HandJoint j) { return p.flags[index_of(j)] & kOrientationTracked; }
bool ptr(const HandPose& p, HandJoint j) { return p.flags[index_of(j)] & kPositionTracked; }

TEST(FtmTracker, KinematicRoundTripRecoversTrackedAnglesAndJointPoses) {
  Rng rng(2701);
  const FtmTrackerOptions defaults;
  double worst_deg = 0.0, worst_mm = 0.0;
  for (Handedness hand : {Handedness::right, Handedness::left}) {
    for (int trial = 0; trial < 20; ++trial) {
      const FtmCalibration c = trk_truth(hand, rng, 25.0);
      const HandModel m = trk_model(c);
      hs::HandTruth h;
      h.angles = hs::random_tracked_angles(rng, defaults.synergies);
      h.T_world_wrist = {hs::random_rotation(rng, M_PI), Vec3(rng.uniform(-1, 1), 1.0, rng.uniform(-1, 1))};
      FtmTracker t = trk_make(c);
      trk_feed(t, m, c, h, 1'000'000'000, 10);
      for (HandDof d : kFtmTrackedDofs) {
        const double e = rad_to_deg(std::abs(t.angles()[index_of(d)] - h.angles[index_of(d)]));
        worst_deg = std::max(worst_deg, e);
        EXPECT_LT(e, 0.5) << to_string(d) << " trial " << trial << " " << to_string(hand);
      }
      const auto tracked = t.dof_tracked();
      for (HandDof d : kFtmTrackedDofs) EXPECT_TRUE(tracked[index_of(d)]) << to_string(d);
      EXPECT_FALSE(tracked[index_of(HandDof::index_dip_flexion)]);
      EXPECT_FALSE(tracked[index_of(HandDof::ring_mcp_flexion)]);
      HandPose est;
      t.estimate(est);
      ASSERT_TRUE(est.active);
      const HandPose ref = m.forward(hand, h.angles, h.T_world_wrist, 0);
      const auto err = joint_position_errors(est, ref);
      for (std::size_t j = 0; j < kHandJointCount; ++j) {
        worst_mm = std::max(worst_mm, err[j] * 1e3);
        EXPECT_LT(err[j], 1e-3) << to_string(joint_at(j));
      }
      EXPECT_LT(rad_to_deg(angle_between(est.joint(HandJoint::wrist).q, h.T_world_wrist.q)), 0.5);
      EXPECT_TRUE(otr(est, HandJoint::index_intermediate));
      EXPECT_TRUE(ptr(est, HandJoint::index_distal));  // placed by MCP + PIP only
      EXPECT_FALSE(otr(est, HandJoint::index_distal));  // turned by the DIP synergy
      EXPECT_FALSE(otr(est, HandJoint::ring_proximal));
      EXPECT_FALSE(otr(est, HandJoint::ring_metacarpal));
      EXPECT_FALSE(ptr(est, HandJoint::little_tip));
      EXPECT_TRUE(est.flags[index_of(HandJoint::ring_tip)] & kPositionValid);
    }
  }
  std::printf("round trip: worst tracked-angle error %.2e deg, worst joint position error %.2e mm\n", worst_deg,
              worst_mm);
}

TEST(FtmTracker, ThumbPronationIsKeptInThePoseAndLeftOutOfTheAngles) {
  Rng rng(2702);
  const FtmCalibration c = trk_truth(Handedness::right, rng, 10.0);
  const HandModel m = trk_model(c);
  hs::HandTruth h;
  h.angles[index_of(HandDof::thumb_cmc_flexion)] = deg_to_rad(20.0);
  h.angles[index_of(HandDof::thumb_cmc_abduction)] = deg_to_rad(15.0);
  h.T_world_wrist.p = Vec3(0, 1, 0);
  const double ps = deg_to_rad(25.0);
  // The metacarpal pronated by ps about its long axis (not in HandModel).
  FtmTracker t = trk_make(c);
  const auto T = m.joint_poses_in_wrist(Handedness::right, h.angles);
  auto q = hs::imu_orientations(m, c, h);
  const Quat q_seg_pron = T[index_of(HandJoint::thumb_metacarpal)].q * Quat(Eigen::AngleAxisd(ps, Vec3::UnitZ()));
  q[1] = (h.T_world_wrist.q * q_seg_pron * c.q_imu_segment[1].conjugate()).normalized();
  for (int k = 0; k < 5; ++k) {
    const TimeNs tk = 1'000'000'000 + k * kTrkTick;
    for (std::size_t i = 0; i < kFtmImuCount; ++i) t.push_imu(static_cast<FtmImu>(i), hs::imu_sample(tk, q[i], c, i, k % 2 ? 1e-9 : -1e-9));
    t.push_wrist({tk, h.T_world_wrist, true});
  }
  EXPECT_NEAR(rad_to_deg(t.angles()[index_of(HandDof::thumb_cmc_flexion)]), 20.0, 0.5);
  EXPECT_NEAR(rad_to_deg(t.angles()[index_of(HandDof::thumb_cmc_abduction)]), 15.0, 0.5);
  EXPECT_NEAR(rad_to_deg(t.thumb_pronation_rad()), 25.0, 0.5);
  HandPose est;
  t.estimate(est);
  EXPECT_LT(rad_to_deg(angle_between(est.joint(HandJoint::thumb_metacarpal).q, h.T_world_wrist.q * q_seg_pron)), 0.5);
}

TEST(FtmTracker, TheThumbCmcAxisOffsetMovesTheMcpAsEquation32Says) {
  Rng rng(2705);
  const FtmCalibration c = trk_truth(Handedness::right, rng, 10.0);
  const HandModel m = trk_model(c);
  hs::HandTruth h;
  const double fe = deg_to_rad(30.0), aa = deg_to_rad(20.0), d = 0.01;
  h.angles[index_of(HandDof::thumb_cmc_flexion)] = fe;
  h.angles[index_of(HandDof::thumb_cmc_abduction)] = aa;
  h.T_world_wrist.p = Vec3(0, 1, 0);
  FtmTrackerOptions o;
  o.thumb_cmc_axis_offset_m = d;
  FtmTracker t = trk_make(c, o);
  trk_feed(t, m, c, h, 1'000'000'000, 5);
  HandPose est;
  t.estimate(est);
  // p_mcp = p_cmc + R_rest Ry(aa) (d along the bone) + R_mc (the remaining L - d).
  const HandShape::Finger& g = m.shape().fingers[0];
  const Quat q_aa = g.q_wrist_metacarpal_rest * Quat(Eigen::AngleAxisd(aa, Vec3::UnitY()));
  const Quat q_mc = q_aa * Quat(Eigen::AngleAxisd(-fe, Vec3::UnitX()));
  const Vec3 expected = h.T_world_wrist * (g.p_base_in_wrist + q_aa * Vec3(0, 0, -d) +
                                           q_mc * Vec3(0, 0, -(g.bone_length_m[0] - d)));
  EXPECT_LT((est.joint(HandJoint::thumb_proximal).p - expected).norm(), 1e-6);
  const HandPose ref = m.forward(Handedness::right, h.angles, h.T_world_wrist, 0);
  EXPECT_GT((est.joint(HandJoint::thumb_proximal).p - ref.joint(HandJoint::thumb_proximal).p).norm(), 1e-3);
  EXPECT_NEAR(t.angles()[index_of(HandDof::thumb_cmc_flexion)], fe, deg_to_rad(0.5));
}

TEST(FtmTracker, WithoutAbductionTheMcpAbductionIsHeldAtZeroAndNotTracked) {
  Rng rng(2703);
  const FtmCalibration c = trk_truth(Handedness::right, rng, 10.0);
  const HandModel m = trk_model(c);
  hs::HandTruth h;
  h.angles[index_of(HandDof::index_mcp_abduction)] = deg_to_rad(12.0);
  h.angles[index_of(HandDof::index_mcp_flexion)] = deg_to_rad(30.0);
  FtmTrackerOptions o;
  o.track_abduction = false;
  FtmTracker t = trk_make(c, o);
  trk_feed(t, m, c, h, 1'000'000'000, 5);
  EXPECT_EQ(t.angles()[index_of(HandDof::index_mcp_abduction)], 0.0);
  EXPECT_NEAR(rad_to_deg(t.angles()[index_of(HandDof::index_mcp_flexion)]), 30.0, 0.5);
  EXPECT_FALSE(t.dof_tracked()[index_of(HandDof::index_mcp_abduction)]);
  EXPECT_TRUE(t.dof_tracked()[index_of(HandDof::index_mcp_flexion)]);
}

// Runs 0.1 s of good data, then 0.3 s where `spoil` edits each event.
template <typename Spoil>
FtmTracker trk_run_spoiled(const FtmCalibration& c, const HandModel& m, const hs::HandTruth& h, Spoil spoil) {
  FtmTracker t = trk_make(c);
  std::vector<FtmEvent> ev;
  for (int k = 0; k < 80; ++k) {
    ev.clear();
    hs::tick(ev, m, c, h, 1'000'000'000 + k * kTrkTick, static_cast<std::uint64_t>(k));
    for (auto& e : ev) {
      if (k >= 20 && !spoil(e, k)) continue;
      t.push(e);
    }
  }
  return t;
}

struct TrkFixture {
  Rng rng{2704};
  FtmCalibration c = trk_truth(Handedness::right, rng, 15.0);
  HandModel m = trk_model(c);
  hs::HandTruth h;
  TrkFixture() {
    h.angles = hs::random_tracked_angles(rng, FtmTrackerOptions{}.synergies);
    h.T_world_wrist = {hs::random_rotation(rng, 1.0), Vec3(0.2, 1.1, -0.3)};
  }
};

TEST(FtmTracker, NanSamplesCostOnlyTheJointsOfThatImu) {
  TrkFixture f;
  FtmTracker t = trk_run_spoiled(f.c, f.m, f.h, [](FtmEvent& e, int) {
    if (e.kind == FtmEvent::Kind::imu && e.index == index_of(FtmImu::index_proximal))
      e.imu.accel_mps2.x() = std::nan("");
    return true;
  });
  const auto tr = t.dof_tracked();
  EXPECT_FALSE(t.imu_ok(FtmImu::index_proximal));
  EXPECT_FALSE(tr[index_of(HandDof::index_mcp_flexion)]);
  EXPECT_FALSE(tr[index_of(HandDof::index_mcp_abduction)]);
  EXPECT_TRUE(tr[index_of(HandDof::index_pip_flexion)]);
  EXPECT_TRUE(tr[index_of(HandDof::middle_mcp_flexion)]);
  EXPECT_TRUE(tr[index_of(HandDof::thumb_cmc_flexion)]);
  HandPose est;
  t.estimate(est);
  EXPECT_TRUE(trk_finite(est));
  EXPECT_TRUE(ptr(est, HandJoint::index_proximal));   // the MCP's position is rigid with the wrist
  EXPECT_FALSE(otr(est, HandJoint::index_proximal));
  EXPECT_FALSE(ptr(est, HandJoint::index_intermediate));
  EXPECT_TRUE(est.flags[index_of(HandJoint::index_intermediate)] & kOrientationValid);
  EXPECT_TRUE(otr(est, HandJoint::middle_intermediate));
  EXPECT_TRUE(otr(est, HandJoint::thumb_proximal));
  // The held angles are the last good ones, not garbage.
  EXPECT_NEAR(t.angles()[index_of(HandDof::index_mcp_flexion)], f.h.angles[index_of(HandDof::index_mcp_flexion)],
              deg_to_rad(0.5));
}

TEST(FtmTracker, StaleAndSaturatedSamplesAreDropped) {
  TrkFixture f;
  FtmTracker t = trk_run_spoiled(f.c, f.m, f.h, [](FtmEvent& e, int) {
    if (e.kind == FtmEvent::Kind::imu && e.index == index_of(FtmImu::thumb_metacarpal))
      e.imu.status = sample_status::stale;
    if (e.kind == FtmEvent::Kind::imu && e.index == index_of(FtmImu::middle_proximal))
      e.imu.status = sample_status::gyro_saturated;
    return true;
  });
  const auto tr = t.dof_tracked();
  EXPECT_FALSE(tr[index_of(HandDof::thumb_cmc_flexion)]);
  EXPECT_FALSE(tr[index_of(HandDof::middle_mcp_flexion)]);
  EXPECT_TRUE(tr[index_of(HandDof::thumb_mcp_flexion)]);  // a bend sensor
  EXPECT_TRUE(tr[index_of(HandDof::index_mcp_flexion)]);
  HandPose est;
  t.estimate(est);
  EXPECT_FALSE(otr(est, HandJoint::thumb_metacarpal));
  EXPECT_FALSE(ptr(est, HandJoint::thumb_proximal));
  EXPECT_TRUE(otr(est, HandJoint::index_intermediate));
}

TEST(FtmTracker, AStuckImuIsDetectedFromRepeatedValues) {
  TrkFixture f;
  Vec3 frozen_a = Vec3::Zero(), frozen_g = Vec3::Zero();
  FtmTracker t = trk_run_spoiled(f.c, f.m, f.h, [&](FtmEvent& e, int k) {
    if (e.kind == FtmEvent::Kind::imu && e.index == index_of(FtmImu::middle_proximal)) {
      if (k == 20) {
        frozen_a = e.imu.accel_mps2;
        frozen_g = e.imu.gyro_radps;
      }
      e.imu.accel_mps2 = frozen_a;
      e.imu.gyro_radps = frozen_g;
    }
    return true;
  });
  EXPECT_FALSE(t.imu_ok(FtmImu::middle_proximal));
  EXPECT_FALSE(t.dof_tracked()[index_of(HandDof::middle_mcp_flexion)]);
  EXPECT_TRUE(t.dof_tracked()[index_of(HandDof::index_mcp_flexion)]);
}

TEST(FtmTracker, ABendSensorThatStopsLosesOnlyItsJoint) {
  TrkFixture f;
  FtmTracker t = trk_run_spoiled(f.c, f.m, f.h, [](FtmEvent& e, int) {
    return !(e.kind == FtmEvent::Kind::bend && e.index == index_of(FtmBend::index_pip));
  });
  const auto tr = t.dof_tracked();
  EXPECT_FALSE(tr[index_of(HandDof::index_pip_flexion)]);
  EXPECT_TRUE(tr[index_of(HandDof::index_mcp_flexion)]);
  EXPECT_TRUE(tr[index_of(HandDof::middle_pip_flexion)]);
  HandPose est;
  t.estimate(est);
  EXPECT_TRUE(otr(est, HandJoint::index_proximal));
  EXPECT_FALSE(otr(est, HandJoint::index_intermediate));
  EXPECT_TRUE(ptr(est, HandJoint::index_intermediate));
  EXPECT_FALSE(ptr(est, HandJoint::index_distal));
}

TEST(FtmTracker, TheWristTrackerStandsInForAFailedDorsumImu) {
  TrkFixture f;
  FtmTracker t = trk_run_spoiled(f.c, f.m, f.h, [](FtmEvent& e, int) {
    return !(e.kind == FtmEvent::Kind::imu && e.index == index_of(FtmImu::dorsum));
  });
  EXPECT_FALSE(t.imu_ok(FtmImu::dorsum));
  EXPECT_TRUE(t.dof_tracked()[index_of(HandDof::index_mcp_flexion)]);
  HandPose est;
  t.estimate(est);
  EXPECT_TRUE(otr(est, HandJoint::wrist));
  EXPECT_LT(rad_to_deg(angle_between(est.joint(HandJoint::wrist).q, f.h.T_world_wrist.q)), 0.5);

  // Without either, everything is held: valid, not tracked.
  FtmTracker t2 = trk_run_spoiled(f.c, f.m, f.h, [](FtmEvent& e, int) {
    if (e.kind == FtmEvent::Kind::wrist) e.wrist.valid = false;  // a dropout
    return !(e.kind == FtmEvent::Kind::imu && e.index == 0);
  });
  t2.estimate(est);
  EXPECT_TRUE(est.active);
  EXPECT_TRUE(trk_finite(est));
  for (std::size_t j = 0; j < kHandJointCount; ++j) {
    EXPECT_EQ(est.flags[j] & (kOrientationTracked | kPositionTracked), 0) << to_string(joint_at(j));
    EXPECT_TRUE(est.flags[j] & kOrientationValid);
  }
  EXPECT_FALSE(t2.dof_tracked()[index_of(HandDof::thumb_cmc_flexion)]);
}

TEST(FtmTracker, WristDropoutClearsOnlyPositionTracking) {
  TrkFixture f;
  FtmTracker t = trk_run_spoiled(f.c, f.m, f.h, [](FtmEvent& e, int) {
    if (e.kind == FtmEvent::Kind::wrist) e.wrist.valid = false;
    return true;
  });
  HandPose est;
  t.estimate(est);
  EXPECT_TRUE(otr(est, HandJoint::index_intermediate));
  EXPECT_FALSE(ptr(est, HandJoint::wrist));
  EXPECT_TRUE(est.flags[index_of(HandJoint::wrist)] & kPositionValid);
  EXPECT_LT((est.joint(HandJoint::wrist).p - f.h.T_world_wrist.p).norm(), 1e-9);  // the last position held
}

TEST(FtmTracker, NothingYetMeansInactiveAndNoWristMeansNoPosition) {
  TrkFixture f;
  FtmTracker t = trk_make(f.c);
  HandPose est;
  t.estimate(est);
  EXPECT_FALSE(est.active);
  const auto q = hs::imu_orientations(f.m, f.c, f.h);
  for (std::size_t i = 0; i < kFtmImuCount; ++i) t.push_imu(static_cast<FtmImu>(i), hs::imu_sample(1000, q[i], f.c, i, 0.0));
  t.estimate(est);
  EXPECT_TRUE(est.active);
  EXPECT_TRUE(trk_finite(est));
  EXPECT_EQ(est.flags[index_of(HandJoint::wrist)] & (kPositionValid | kPositionTracked), 0);
  EXPECT_TRUE(otr(est, HandJoint::wrist));
  t.reset();
  t.estimate(est);
  EXPECT_FALSE(est.active);
}

TEST(FtmTracker, OptionsAndCreateRejectWhatCannotWork) {
  FtmTrackerOptions o;
  EXPECT_TRUE(o.validate().ok());
  EXPECT_NE(o.describe().find("synergies on"), std::string::npos);
  o.imu_timeout_ns = 0;
  EXPECT_NE(o.validate().error().message.find("imu_timeout_ns"), std::string::npos);
  o = {};
  o.thumb_cmc_axis_offset_m = -0.01;
  EXPECT_NE(o.validate().error().message.find("thumb_cmc_axis_offset_m"), std::string::npos);
  o = {};
  o.hand = Handedness::left;
  auto t = FtmTracker::create(o, nominal_ftm_calibration(Handedness::right, 0.19, 0.1));
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.error().message.find("left"), std::string::npos);
  EXPECT_FALSE(FtmTracker::create({}, nominal_ftm_calibration(Handedness::right, 0.5, 0.1)).ok());
}

}  // namespace
}  // namespace proprio::ftm
