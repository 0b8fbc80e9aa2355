#include <gtest/gtest.h>

#include <cmath>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/random.hpp"

#include <openxr/openxr.h>

using namespace proprio;

namespace {

HandModel model(double L = 0.19, double B = 0.10) { return HandModel(*HandShape::from_measurements(L, B)); }

HandAngles random_angles(Rng& rng, const JointLimits& lim) {
  HandAngles a;
  for (std::size_t i = 0; i < kHandDofCount; ++i) a[i] = rng.uniform(lim.min_rad[i], lim.max_rad[i]);
  return a;
}

Vec3 axis(const Pose& T, int i) { return T.q.toRotationMatrix().col(i); }
double angle_deg(const Vec3& a, const Vec3& b) {
  return rad_to_deg(std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)));
}

const Pose kSomeWrist{so3_exp(Vec3(0.3, -1.1, 0.4)), Vec3(0.1, 1.2, -0.4)};

}  // namespace

class HandConventions : public ::testing::TestWithParam<Handedness> {};

TEST_P(HandConventions, ZPointsBackAlongEveryBoneTowardTheWrist) {
  const HandModel m = model();
  Rng rng(1);
  for (int trial = 0; trial < 50; ++trial) {
    const HandPose p = m.forward(GetParam(), random_angles(rng, m.limits()), kSomeWrist, 0);
    for (std::size_t fi = 0; fi < kFingerCount; ++fi) {
      const FingerJoints fj = finger_joints(static_cast<Finger>(fi));
      for (std::size_t k = 0; k + 1 < fj.count; ++k) {
        const Pose& joint = p.joint(fj.joints[k]);
        const Pose& child = p.joint(fj.joints[k + 1]);
        EXPECT_LT(angle_deg(axis(joint, 2), joint.p - child.p), 1e-4) << to_string(fj.joints[k]);
      }
      const Pose& tip = p.joint(fj.joints[fj.count - 1]);
      const Pose& distal = p.joint(fj.joints[fj.count - 2]);
      EXPECT_LT(angle_deg(axis(tip, 2), distal.p - tip.p), 1e-4) << "tip of finger " << fi;
    }
  }
}

TEST_P(HandConventions, YPointsOutOfTheBackOfAFlatHand) {
  const HandModel m = model();
  const HandPose p = m.forward(GetParam(), HandAngles{}, kSomeWrist, 0);
  // The back-of-hand normal from geometry alone: across the knuckles (little
  // to index for a left hand, index to little for a right... see below) crossed
  // with the wrist-to-knuckle direction.
  const Vec3 across = p.joint(HandJoint::little_proximal).p - p.joint(HandJoint::index_proximal).p;
  const Vec3 distal = p.joint(HandJoint::middle_proximal).p - p.joint(HandJoint::wrist).p;
  // For a right hand seen from the back with fingers up, the little finger is
  // on the right: (little - index) x distal points out of the back. A left
  // hand is the mirror image, so the sign flips.
  const Vec3 dorsal = (GetParam() == Handedness::right ? 1.0 : -1.0) * across.cross(distal).normalized();
  for (auto j : {HandJoint::wrist, HandJoint::palm, HandJoint::index_proximal, HandJoint::middle_intermediate,
                 HandJoint::ring_distal, HandJoint::little_tip, HandJoint::middle_metacarpal}) {
    EXPECT_LT(angle_deg(axis(p.joint(j), 1), dorsal), 12.0) << to_string(j);
  }
  // The thumb nail faces partly sideways, but still away from the palm.
  EXPECT_GT(axis(p.joint(HandJoint::thumb_distal), 1).dot(dorsal), 0.3);
}

TEST_P(HandConventions, ThumbIsOnTheCorrectSideForTheHand) {
  const HandModel m = model();
  const HandPose p = m.forward(GetParam(), HandAngles{}, Pose::identity(), 0);
  // In the wrist frame the right thumb lies on -X, the left on +X.
  const double thumb_x = p.joint(HandJoint::thumb_tip).p.x();
  const double little_x = p.joint(HandJoint::little_tip).p.x();
  if (GetParam() == Handedness::right) {
    EXPECT_LT(thumb_x, 0.0);
    EXPECT_GT(little_x, 0.0);
  } else {
    EXPECT_GT(thumb_x, 0.0);
    EXPECT_LT(little_x, 0.0);
  }
}

TEST_P(HandConventions, PalmAtMiddleMetacarpalMidpointAndWristZAlongTheHand) {
  const HandModel m = model();
  Rng rng(2);
  for (int trial = 0; trial < 20; ++trial) {
    const HandPose p = m.forward(GetParam(), random_angles(rng, m.limits()), kSomeWrist, 0);
    const Vec3 mc = p.joint(HandJoint::middle_metacarpal).p;
    const Vec3 prox = p.joint(HandJoint::middle_proximal).p;
    EXPECT_LT((p.joint(HandJoint::palm).p - 0.5 * (mc + prox)).norm(), 0.01 * (prox - mc).norm());
    const Pose& wrist = p.joint(HandJoint::wrist);
    EXPECT_LT(angle_deg(axis(wrist, 2), wrist.p - mc), 14.0);
    EXPECT_LT(angle_between(p.joint(HandJoint::palm).q, p.joint(HandJoint::middle_metacarpal).q), 1e-9);
  }
}

TEST_P(HandConventions, RadiiArePositiveAndAllJointsFullyTracked) {
  const HandPose p = model().forward(GetParam(), HandAngles{}, kSomeWrist, 42);
  EXPECT_TRUE(p.fully_valid());
  EXPECT_EQ(p.time_ns, 42);
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    EXPECT_GT(p.radius_m[i], 0.003) << to_string(joint_at(i));
    EXPECT_LT(p.radius_m[i], 0.03) << to_string(joint_at(i));
  }
}

TEST_P(HandConventions, ForwardThenInverseRecoversTheAnglesAndWrist) {
  const HandModel m = model(0.18, 0.095);
  Rng rng(GetParam() == Handedness::left ? 3 : 4);
  for (int trial = 0; trial < 500; ++trial) {
    const HandAngles a = random_angles(rng, m.limits());
    const Pose T_world_wrist{so3_exp(Vec3(rng.normal(), rng.normal(), rng.normal())),
                             Vec3(rng.normal(), rng.normal(), rng.normal())};
    const auto ik = m.inverse(m.forward(GetParam(), a, T_world_wrist, 0));
    for (std::size_t i = 0; i < kHandDofCount; ++i) {
      ASSERT_NEAR(ik.angles[i], a[i], 1e-9) << to_string(static_cast<HandDof>(i)) << " trial " << trial;
    }
    EXPECT_LT(ik.max_position_residual_m, 1e-9);
    EXPECT_LT((ik.T_world_wrist.p - T_world_wrist.p).norm(), 1e-12);
  }
}

INSTANTIATE_TEST_SUITE_P(BothHands, HandConventions, ::testing::Values(Handedness::left, Handedness::right),
                         [](const auto& param_info) { return std::string(to_string(param_info.param)); });

TEST(HandModel, LeftHandIsTheMirrorImageOfTheRight) {
  const HandModel m = model();
  Rng rng(5);
  const HandAngles a = random_angles(rng, m.limits());
  const auto right = m.joint_poses_in_wrist(Handedness::right, a);
  const auto left = m.joint_poses_in_wrist(Handedness::left, a);
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    EXPECT_NEAR(left[i].p.x(), -right[i].p.x(), 1e-12);
    EXPECT_NEAR(left[i].p.y(), right[i].p.y(), 1e-12);
    EXPECT_NEAR(left[i].p.z(), right[i].p.z(), 1e-12);
    // Y and Z axes mirror; X follows from right-handedness.
    const Mat3 Rr = right[i].q.toRotationMatrix(), Rl = left[i].q.toRotationMatrix();
    const Eigen::Vector3d S(-1, 1, 1);
    EXPECT_LT((Rl.col(1) - S.cwiseProduct(Rr.col(1))).norm(), 1e-9);
    EXPECT_LT((Rl.col(2) - S.cwiseProduct(Rr.col(2))).norm(), 1e-9);
    EXPECT_NEAR(Rl.determinant(), 1.0, 1e-9);
  }
}

TEST(HandModel, FlatHandLengthMatchesTheMeasurement) {
  for (double L : {0.17, 0.19, 0.205}) {
    const auto T = model(L, 0.1).joint_poses_in_wrist(Handedness::right, HandAngles{});
    EXPECT_NEAR(T[index_of(HandJoint::middle_tip)].p.norm(), L, 0.005 * L);
  }
}

TEST(HandModel, BoneLengthsFollowBuchholzRatios) {
  const HandModel m = model(0.20, 0.10);
  const auto T = m.joint_poses_in_wrist(Handedness::right, HandAngles{});
  EXPECT_NEAR((T[index_of(HandJoint::index_intermediate)].p - T[index_of(HandJoint::index_proximal)].p).norm(),
              0.265 * 0.20, 1e-12);
  EXPECT_NEAR((T[index_of(HandJoint::thumb_distal)].p - T[index_of(HandJoint::thumb_proximal)].p).norm(),
              0.196 * 0.20, 1e-12);
}

TEST(HandModel, FlexionCurlsTowardThePalm) {
  const HandModel m = model();
  HandAngles a{};
  a[index_of(HandDof::index_mcp_flexion)] = deg_to_rad(60);
  const auto T = m.joint_poses_in_wrist(Handedness::right, a);
  EXPECT_LT(T[index_of(HandJoint::index_tip)].p.y(), -0.03) << "palm faces -Y in the wrist frame";
  a = HandAngles{};
  a[index_of(HandDof::index_mcp_abduction)] = deg_to_rad(20);
  const auto S = m.joint_poses_in_wrist(Handedness::right, a);
  const auto F = m.joint_poses_in_wrist(Handedness::right, HandAngles{});
  EXPECT_LT(S[index_of(HandJoint::index_tip)].p.x(), F[index_of(HandJoint::index_tip)].p.x() - 0.01)
      << "positive abduction moves toward the thumb (-X on a right hand)";
}

TEST(HandModel, InverseReportsResidualForPosesTheModelCannotMake) {
  const HandModel m = model();
  HandPose p = m.forward(Handedness::right, HandAngles{}, Pose::identity(), 0);
  p.joint(HandJoint::index_tip).p += Vec3(0, 0, -0.01);  // a longer fingertip than this model has
  EXPECT_NEAR(m.inverse(p).max_position_residual_m, 0.01, 1e-9);
}

TEST(HandShape, RejectsImplausibleSizesWithUnits) {
  auto s = HandShape::from_measurements(19.0, 0.1);  // centimetres by mistake
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::out_of_range);
  EXPECT_NE(s.error().message.find("metres"), std::string::npos);
  EXPECT_FALSE(HandShape::from_measurements(0.19, std::nan("")).ok());
}

TEST(JointLimits, ClampAndContains) {
  const JointLimits lim = JointLimits::defaults();
  HandAngles a{};
  EXPECT_TRUE(lim.contains(a));
  a[index_of(HandDof::index_pip_flexion)] = deg_to_rad(150);
  EXPECT_FALSE(lim.contains(a));
  const HandAngles c = lim.clamp(a);
  EXPECT_TRUE(lim.contains(c));
  EXPECT_NEAR(rad_to_deg(c[index_of(HandDof::index_pip_flexion)]), 110.0, 1e-9);
}

TEST(Synergies, DipFollowsPipAndThumbIpFollowsMcp) {
  Synergies s;
  HandAngles a{};
  a[index_of(HandDof::ring_pip_flexion)] = 0.9;
  a[index_of(HandDof::thumb_mcp_flexion)] = 0.4;
  EXPECT_EQ(s.apply(a), a) << "off by default";
  s.enabled = true;
  const HandAngles b = s.apply(a);
  EXPECT_NEAR(b[index_of(HandDof::ring_dip_flexion)], 0.6, 1e-12);
  EXPECT_NEAR(b[index_of(HandDof::thumb_ip_flexion)], 0.2, 1e-12);
}

TEST(HandJoint, OrderAndNamesMatchOpenXr) {
  EXPECT_EQ(index_of(HandJoint::palm), static_cast<std::size_t>(XR_HAND_JOINT_PALM_EXT));
  EXPECT_EQ(index_of(HandJoint::wrist), static_cast<std::size_t>(XR_HAND_JOINT_WRIST_EXT));
  EXPECT_EQ(index_of(HandJoint::thumb_tip), static_cast<std::size_t>(XR_HAND_JOINT_THUMB_TIP_EXT));
  EXPECT_EQ(index_of(HandJoint::index_metacarpal), static_cast<std::size_t>(XR_HAND_JOINT_INDEX_METACARPAL_EXT));
  EXPECT_EQ(index_of(HandJoint::ring_distal), static_cast<std::size_t>(XR_HAND_JOINT_RING_DISTAL_EXT));
  EXPECT_EQ(index_of(HandJoint::little_tip), static_cast<std::size_t>(XR_HAND_JOINT_LITTLE_TIP_EXT));
  EXPECT_EQ(kHandJointCount, static_cast<std::size_t>(XR_HAND_JOINT_COUNT_EXT));
  EXPECT_EQ(to_string(HandJoint::ring_intermediate), "ring_intermediate");
  EXPECT_EQ(*parent_of(HandJoint::index_proximal), HandJoint::index_metacarpal);
  EXPECT_EQ(*parent_of(HandJoint::thumb_metacarpal), HandJoint::wrist);
  EXPECT_FALSE(parent_of(HandJoint::palm).has_value());
  EXPECT_EQ(tip_of(Finger::middle), HandJoint::middle_tip);
}

// The contact simulation's proxy takes the tracked hand's size (issue 29):
// whatever the posture, the measurements come back from the joints alone.
TEST(HandShape, MeasuredFromATrackedPoseInAnyPosture) {
  for (const auto& [L, B] : {std::pair{0.165, 0.085}, std::pair{0.19, 0.10}, std::pair{0.215, 0.112}}) {
    const HandModel m = model(L, B);
    HandAngles a{};
    for (std::size_t i = 0; i < kHandDofCount; ++i) a[i] = 0.3 * std::sin(1.7 * static_cast<double>(i) + 10.0 * L);
    for (Handedness side : {Handedness::left, Handedness::right}) {
      const HandPose pose = m.forward(side, a, Pose{Quat(Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized())),
                                                    Vec3(0.1, 1.2, -0.3)}, 0);
      auto shape = HandShape::from_tracked_pose(pose);
      ASSERT_TRUE(shape.ok()) << shape.error().message;
      EXPECT_NEAR(shape->hand_length_m, L, 1e-6);
      EXPECT_NEAR(shape->hand_width_m, B, 1e-5);
    }
  }
  HandPose inactive;
  EXPECT_FALSE(HandShape::from_tracked_pose(inactive).ok());
  HandPose giant = model().forward(Handedness::right, HandAngles{}, Pose{}, 0);
  for (auto& T : giant.T_world_joint) T.p *= 3.0;
  const auto refused = HandShape::from_tracked_pose(giant);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("0.10-0.30 m"), std::string::npos) << refused.error().message;
}
