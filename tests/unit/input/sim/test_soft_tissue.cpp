// Soft tissue: each effect moves a mount by what its model says, checked
// against closed forms (the sliding formula at a known flexion, the spring's
// static sag and resonance, the slip walk's stationary spread), and the IMU
// simulator feels a moving mount.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/sim/imu_sim.hpp"
#include "proprio/sim/soft_tissue.hpp"
#include "proprio/sim/subjects.hpp"

using namespace proprio;
using namespace proprio::sim;

namespace soft_tissue_test {

HandShape shape() { return *sim_subject(3)->shape(); }

HandPose pose_with(const HandAngles& angles, const Pose& T_world_wrist = Pose{}) {
  return HandModel(shape()).forward(Handedness::right, angles, T_world_wrist, 0);
}

SoftTissueOptions only(bool sliding, bool wobble, bool slip) {
  SoftTissueOptions o;
  o.sliding = sliding;
  o.wobble = wobble;
  o.slip = slip;
  return o;
}

TEST(SoftTissue, SlidingIsZeroOnAStraightHandForEveryMarkerOfTheGlove) {
  // The flexion measure reads zero at zero angles on every joint it uses, so
  // no mount of the shipped glove moves on a flat hand.
  const auto glove = ImuGloveDescription::vist_default();
  std::vector<SkinMount> mounts;
  for (const PlacedMarker& m : glove.place_markers(shape(), Handedness::right)) {
    mounts.push_back({m.segment, m.p_in_segment, false});
  }
  auto tissue = SoftTissue::create(nullptr, mounts, only(true, false, false), 1);
  ASSERT_TRUE(tissue) << tissue.error().message;
  const HandPose flat = pose_with(HandAngles{});
  for (std::size_t i = 0; i < mounts.size(); ++i) EXPECT_LT(tissue->sliding(i, flat).norm(), 1e-9) << i;
}

TEST(SoftTissue, ADorsalMountNextToAFlexedPipSlidesTowardItByTheModelsAmount) {
  // A mount on the middle phalanx, 4 mm past the PIP and 9 mm above the bone:
  // with the PIP flexed 70 deg and the DIP straight it moves toward the PIP
  // (+Z of its segment) by gain * h * theta * exp(-d / decay).
  const Vec3 p(0.0, 0.009, -0.004);
  auto tissue = SoftTissue::create(nullptr, {{HandJoint::index_intermediate, p, false}}, only(true, false, false), 1);
  ASSERT_TRUE(tissue);
  HandAngles a{};
  const double theta = deg_to_rad(70.0);
  a[index_of(HandDof::index_pip_flexion)] = theta;
  const Vec3 d = tissue->sliding(0, pose_with(a));
  const SoftTissueOptions o;
  const double expected = o.sliding_gain * p.y() * theta * std::exp(-p.norm() / o.sliding_decay_m);
  EXPECT_NEAR(d.z(), expected, 1e-6);
  EXPECT_GT(expected, 0.001);  // "several millimetres near a knuckle": this one moves over 1 mm
  EXPECT_NEAR(d.x(), 0.0, 1e-9);
  EXPECT_NEAR(d.y(), 0.0, 1e-9);
  // The palmar side folds instead: pushed away from the joint.
  auto palmar = SoftTissue::create(nullptr, {{HandJoint::index_intermediate, Vec3(0.0, -0.009, -0.004), false}},
                                   only(true, false, false), 1);
  EXPECT_NEAR(palmar->sliding(0, pose_with(a)).z(), -expected, 1e-6);
}

TEST(SoftTissue, BackOfHandAndThumbMountsFollowTheirOwnKnuckles) {
  // A dorsal mount on the back of the hand 8 mm before the index knuckle is
  // pulled toward it (distally, -Z of the wrist) as the index MCP flexes; it
  // does not move when only the little finger flexes far away. A thumb mount
  // past the IP moves toward the IP when it flexes.
  const HandPose flat = pose_with(HandAngles{});
  const Pose& T_wrist = flat.joint(HandJoint::wrist);
  const Vec3 knuckle = T_wrist.inverse() * flat.joint(HandJoint::index_proximal).p;
  const Vec3 p = knuckle + Vec3(0.0, 0.012, 0.008);
  const Vec3 thumb_p(0.0, 0.008, -0.005);
  auto tissue = SoftTissue::create(
      nullptr, {{HandJoint::wrist, p, false}, {HandJoint::thumb_distal, thumb_p, false}}, only(true, false, false), 1);
  ASSERT_TRUE(tissue);
  HandAngles index_flexed{}, little_flexed{}, thumb_flexed{};
  index_flexed[index_of(HandDof::index_mcp_flexion)] = deg_to_rad(60.0);
  little_flexed[index_of(HandDof::little_mcp_flexion)] = deg_to_rad(60.0);
  thumb_flexed[index_of(HandDof::thumb_ip_flexion)] = deg_to_rad(50.0);
  EXPECT_LT(tissue->sliding(0, pose_with(index_flexed)).z(), -0.0005);
  EXPECT_LT(tissue->sliding(0, pose_with(little_flexed)).norm(), 0.2 * tissue->sliding(0, pose_with(index_flexed)).norm());
  EXPECT_GT(tissue->sliding(1, pose_with(thumb_flexed)).z(), 0.0005);
  EXPECT_LT(tissue->sliding(1, flat).norm(), 1e-9);
}

TEST(SoftTissue, WobbleSagsByGravityOverOmegaSquaredOnAStillHand) {
  const Pose T_world_wrist(Quat(Eigen::AngleAxisd(0.7, Vec3(1.0, 0.3, 0.0).normalized())), Vec3(0.1, 1.2, -0.3));
  const HandPose still = pose_with(HandAngles{}, T_world_wrist);
  auto tissue = SoftTissue::create([&](TimeNs) { return still; }, {{HandJoint::index_proximal, Vec3(0, 0.01, -0.02), false}},
                                   only(false, true, false), 5);
  ASSERT_TRUE(tissue);
  const double w = 2.0 * M_PI * tissue->wobble_frequency_hz(HandJoint::index_proximal);
  const Vec3 down_in_segment = still.joint(HandJoint::index_proximal).q.conjugate() * Vec3(0.0, -1.0, 0.0);
  for (TimeNs t : {TimeNs{0}, TimeNs{1234567}, TimeNs{250'000'000}}) {
    const Vec3 x = tissue->wobble(HandJoint::index_proximal, t);
    EXPECT_NEAR((x - 9.80665 / (w * w) * down_in_segment).norm(), 0.0, 1e-9) << t;
  }
}

TEST(SoftTissue, WobbleRingsAtResonanceByOneOverTwoZeta) {
  // The wrist shaken along world x at the patch's own frequency: the steady
  // relative motion is A / (2 zeta) (the sag is along y and constant).
  SoftTissueOptions o = only(false, true, false);
  o.wobble_frequency_spread = 0.0;
  o.wobble_step_s = 2e-4;  // fine grid: the sampled drive's phase lag stays below 1 %
  const double amplitude_m = 1e-4;
  const double w = 2.0 * M_PI * o.wobble_frequency_hz;
  auto poses = [&](TimeNs t) {
    return pose_with(HandAngles{}, Pose(Quat::Identity(), Vec3(amplitude_m * std::sin(w * ns_to_seconds(t)), 1.0, 0.0)));
  };
  auto tissue = SoftTissue::create(poses, {{HandJoint::wrist, Vec3(0.0, 0.02, -0.05), false}}, o, 1);
  ASSERT_TRUE(tissue);
  // The wrist frame is world-aligned here, so world x is segment x. After
  // 1 s the transient (time constant 1 / (zeta w) = 27 ms) is gone.
  double peak = 0.0;
  for (TimeNs t = 1'000'000'000; t < 1'200'000'000; t += 100'000) {
    peak = std::max(peak, std::abs(tissue->wobble(HandJoint::wrist, t).x()));
  }
  EXPECT_NEAR(peak, amplitude_m / (2.0 * o.wobble_damping_ratio), 0.02 * amplitude_m / (2.0 * o.wobble_damping_ratio));
}

TEST(SoftTissue, AnswersDependOnTimeNotOnTheOrderOfQuestions) {
  const double w = 2.0 * M_PI * 3.0;
  auto poses = [&](TimeNs t) {
    const double s = ns_to_seconds(t);
    HandAngles a{};
    a[index_of(HandDof::index_pip_flexion)] = 0.6 + 0.5 * std::sin(w * s);
    return pose_with(a, Pose(Quat(Eigen::AngleAxisd(0.4 * std::sin(2.0 * s), Vec3::UnitY())), Vec3(0.0, 1.0, 0.0)));
  };
  SoftTissueOptions o;
  o.wobble_history_s = 0.5;  // short, so the shuffled order also exercises the restart
  const std::vector<SkinMount> mounts{{HandJoint::index_intermediate, Vec3(0.0, 0.008, -0.01), false},
                                      {HandJoint::wrist, Vec3(0.01, 0.02, -0.06), true}};
  std::vector<TimeNs> times;
  for (int i = 0; i < 40; ++i) times.push_back(static_cast<TimeNs>(i) * 37'123'457);
  auto a = SoftTissue::create(poses, mounts, o, 9);
  auto b = SoftTissue::create(poses, mounts, o, 9);
  std::vector<Vec3> forward;
  for (TimeNs t : times) forward.push_back(a->offset(1, poses(t), t) + a->offset(0, poses(t), t));
  std::vector<std::size_t> order(times.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = (i * 17) % order.size();
  for (std::size_t i : order) {
    const TimeNs t = times[i];
    EXPECT_NEAR((b->offset(0, poses(t), t) + b->offset(1, poses(t), t) - forward[i]).norm(), 0.0, 1e-12) << i;
  }
}

TEST(SoftTissue, SlipStartsAtZeroAndWandersWithTheStationarySigma) {
  SoftTissueOptions o = only(false, false, true);
  o.slip_time_constant_s = 10.0;
  std::vector<SkinMount> mounts;
  for (HandJoint j : {HandJoint::wrist, HandJoint::index_proximal, HandJoint::index_intermediate,
                      HandJoint::middle_proximal, HandJoint::ring_proximal, HandJoint::thumb_proximal}) {
    mounts.push_back({j, Vec3(0.0, 0.01, -0.01), false});
  }
  double sum_sq = 0.0;
  int n = 0;
  for (std::uint64_t seed = 0; seed < 120; ++seed) {
    auto tissue = SoftTissue::create(nullptr, mounts, o, seed);
    ASSERT_TRUE(tissue);
    for (const SkinMount& m : mounts) {
      EXPECT_EQ(tissue->slip(m.segment, 0).norm(), 0.0);
      const Vec3 s = tissue->slip(m.segment, 40'000'000'000);  // 4 time constants: stationary
      EXPECT_EQ(s.y(), 0.0);  // on the surface: along and sideways only
      sum_sq += s.x() * s.x() + s.z() * s.z();
      n += 2;
    }
  }
  EXPECT_NEAR(std::sqrt(sum_sq / n), o.slip_sigma_m, 0.08 * o.slip_sigma_m);
}

TEST(SoftTissue, TheImuSimulatorFeelsAMountMovingOnItsBone) {
  // A still hand; the IMU's mount oscillates along its segment's x by c sin(w t).
  // The accelerometer's reading differs from the rigid one by -c w^2 sin(w t)
  // along that axis (in the IMU frame).
  const HandPose still = pose_with(HandAngles{}, Pose(Quat::Identity(), Vec3(0.0, 1.0, 0.0)));
  const auto imus = ImuGloveDescription::vist_default().place_imus(shape(), Handedness::right);
  const double c = 2e-4, w = 2.0 * M_PI * 7.0;
  auto rigid = ImuSimulator::create([&](TimeNs) { return still; }, imus, ImuNoiseOptions::ideal(), 1);
  auto soft = ImuSimulator::create([&](TimeNs) { return still; }, imus, ImuNoiseOptions::ideal(), 1);
  ASSERT_TRUE(rigid && soft);
  soft->set_mount_offsets([&](std::size_t, const HandPose&, TimeNs t) {
    return Vec3(c * std::sin(w * ns_to_seconds(t)), 0.0, 0.0);
  });
  for (int tick = 0; tick < 20; ++tick) {
    const auto r0 = rigid->next();
    const auto r1 = soft->next();
    for (std::size_t i = 0; i < r0.size(); ++i) {
      const double t = ns_to_seconds(r1[i].time_ns);
      const Vec3 expected_in_segment(-c * w * w * std::sin(w * t), 0.0, 0.0);
      const Vec3 expected = soft->mountings()[i].T_segment_imu.q.conjugate() * expected_in_segment;
      EXPECT_NEAR((r1[i].sample.accel_mps2 - r0[i].sample.accel_mps2 - expected).norm(), 0.0, 1e-3) << tick;
      EXPECT_NEAR((r1[i].sample.gyro_radps - r0[i].sample.gyro_radps).norm(), 0.0, 1e-9);
    }
  }
}

TEST(SoftTissue, RejectsBadOptionsAndMountsWithAClearMessage) {
  SoftTissueOptions o;
  o.wobble_frequency_hz = std::nan("");
  auto bad = SoftTissue::create(nullptr, {}, o, 1);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("wobble_frequency_hz"), std::string::npos);
  auto tip = SoftTissue::create(nullptr, {{HandJoint::index_tip, Vec3::Zero(), false}}, only(true, false, false), 1);
  ASSERT_FALSE(tip);
  EXPECT_NE(tip.error().message.find("index_tip"), std::string::npos);
  auto no_motion = SoftTissue::create(nullptr, {}, SoftTissueOptions{}, 1);
  ASSERT_FALSE(no_motion);
  EXPECT_NE(no_motion.error().message.find("pose function"), std::string::npos);
  EXPECT_NE(SoftTissueOptions::rigid().describe().find("sliding=off"), std::string::npos);
}

}  // namespace soft_tissue_test
