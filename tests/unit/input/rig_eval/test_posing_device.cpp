#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "proprio/rig_eval/posing_device.hpp"

namespace proprio::rig_eval {
namespace {

TEST(PosingDevice, HumanoidIsAValidSmallTree) {
  const PosingDevice d = make_humanoid_device();
  EXPECT_TRUE(d.skeleton.validate().ok());
  EXPECT_EQ(d.joint_count(), 6u);
  ASSERT_EQ(d.max_bend_rad.size(), d.joint_count());
  ASSERT_EQ(d.twist_sd_rad.size(), d.joint_count());
  // Proximal before distal, so a user working down the list fixes parents first.
  for (std::size_t j = 1; j < d.joint_count(); ++j) {
    const int node = d.joint_node[j];
    bool has_joint_ancestor_later = false;
    for (int p = d.skeleton.parent[static_cast<std::size_t>(node)]; p >= 0; p = d.skeleton.parent[static_cast<std::size_t>(p)]) {
      for (std::size_t k = j + 1; k < d.joint_count(); ++k) has_joint_ancestor_later |= d.joint_node[k] == p;
    }
    EXPECT_FALSE(has_joint_ancestor_later) << d.joint_names[j];
  }
}

TEST(PosingDevice, ShouldersPointSideways) {
  const PosingDevice d = make_humanoid_device();
  std::vector<Pose> T;
  device_forward_kinematics(d, straight_pose(d), T);
  const auto elbow_l = static_cast<std::size_t>(d.skeleton.find("elbow_l"));
  const auto shoulder_l = static_cast<std::size_t>(d.skeleton.find("shoulder_l"));
  const Vec3 arm = (T[elbow_l].p - T[shoulder_l].p).normalized();
  EXPECT_NEAR(arm.x(), 1.0, 1e-9);
}

TEST(PosingDevice, PoseErrorIsAnL2NormOverNodes) {
  const PosingDevice d = make_chain_device(2, 0.1);
  std::vector<Pose> a, b;
  device_forward_kinematics(d, straight_pose(d), a);
  EXPECT_DOUBLE_EQ(pose_error_m(a, a), 0.0);
  b = a;
  b[1].p += Vec3(0.03, 0, 0);
  b[2].p += Vec3(0, 0.04, 0);
  EXPECT_NEAR(pose_error_m(a, b), 0.05, 1e-12);
  EXPECT_NEAR(pose_error_m(b, a), 0.05, 1e-12);
}

TEST(PosingDevice, TargetPosesStayInTheirRangesAndFollowTheSeed) {
  const PosingDevice d = make_humanoid_device();
  Rng r1(7), r2(7), r3(8);
  for (int i = 0; i < 20; ++i) {
    const JointRotations a = sample_target_pose(d, r1);
    const JointRotations b = sample_target_pose(d, r2);
    const JointRotations c = sample_target_pose(d, r3);
    ASSERT_EQ(a.size(), d.joint_count());
    bool differs = false;
    for (std::size_t j = 0; j < a.size(); ++j) {
      EXPECT_TRUE(a[j].isApprox(b[j]));
      differs |= !a[j].isApprox(c[j]);
      const Vec3 dir = a[j] * Vec3::UnitZ();
      const double bend = std::acos(std::clamp(dir.z(), -1.0, 1.0));
      EXPECT_GE(bend, 0.25 * d.max_bend_rad[j] - 1e-9);
      EXPECT_LE(bend, d.max_bend_rad[j] + 1e-9);
    }
    EXPECT_TRUE(differs);
  }
}

TEST(PosingDevice, MeanJointAngleError) {
  const JointRotations a(3, Quat::Identity());
  JointRotations b = a;
  b[1] = Quat(Eigen::AngleAxisd(0.3, Vec3::UnitX()));
  EXPECT_NEAR(mean_joint_angle_error_rad(a, b), 0.1, 1e-12);
}

}  // namespace
}  // namespace proprio::rig_eval
