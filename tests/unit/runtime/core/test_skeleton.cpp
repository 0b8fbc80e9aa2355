#include "proprio/core/skeleton.hpp"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

namespace proprio {
namespace {

Skeleton arm() {
  Skeleton s;
  s.add("shoulder", -1, Vec3(0, 0, 1));
  s.add("elbow", 0, Vec3(0.3, 0, 0));
  s.add("wrist", 1, Vec3(0.25, 0, 0));
  s.add("thumb", 2, Vec3(0.05, 0.02, 0), Quat(Eigen::AngleAxisd(0.3, Vec3::UnitZ())));
  return s;
}

TEST(Skeleton, RestPoseChainsOffsets) {
  const Skeleton s = arm();
  ASSERT_TRUE(s.validate().ok());
  std::vector<Pose> T;
  forward_kinematics(s, rest_pose(s), T);
  ASSERT_EQ(T.size(), 4u);
  EXPECT_TRUE(T[2].p.isApprox(Vec3(0.55, 0, 1), 1e-12));
  EXPECT_TRUE(T[3].p.isApprox(Vec3(0.60, 0.02, 1), 1e-12));
  EXPECT_NEAR(Eigen::AngleAxisd(T[3].q).angle(), 0.3, 1e-12);
}

TEST(Skeleton, RotatingANodeSwingsItsSubtreeAndNothingElse) {
  const Skeleton s = arm();
  SkeletonPose pose = rest_pose(s);
  pose.q_parent_node[1] = Quat(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ()));
  pose.t_world_root_m = Vec3(1, 2, 3);
  std::vector<Pose> T;
  forward_kinematics(s, pose, T);
  EXPECT_TRUE(T[1].p.isApprox(Vec3(1.3, 2, 4), 1e-12));         // the elbow only moves with the root
  EXPECT_TRUE(T[2].p.isApprox(Vec3(1.3, 2.25, 4), 1e-12));      // the wrist swings 90 degrees about it
}

TEST(Skeleton, ValidateNamesTheBadNode) {
  Skeleton s = arm();
  s.parent[2] = 3;
  Status st = s.validate();
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("wrist"), std::string::npos);

  s = arm();
  s.names[3] = "elbow";
  EXPECT_FALSE(s.validate().ok());
  s = arm();
  s.t_parent_node_m[1].x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(s.validate().ok());
  s = arm();
  s.q_parent_node_rest[0] = Quat(2, 0, 0, 0);
  EXPECT_FALSE(s.validate().ok());
  EXPECT_FALSE(Skeleton{}.validate().ok());
}

TEST(Skeleton, PoseValidationAndLookup) {
  const Skeleton s = arm();
  SkeletonPose pose = rest_pose(s);
  EXPECT_TRUE(validate_pose(s, pose).ok());
  pose.q_parent_node[2] = Quat(std::nan(""), 0, 0, 1);
  EXPECT_FALSE(validate_pose(s, pose).ok());
  pose.q_parent_node.pop_back();
  EXPECT_FALSE(validate_pose(s, pose).ok());
  EXPECT_EQ(s.find("wrist"), 2);
  EXPECT_EQ(s.find("tail"), -1);
  const auto kids = s.children();
  ASSERT_EQ(kids[0].size(), 1u);
  EXPECT_EQ(kids[0][0], 1);
  EXPECT_TRUE(kids[3].empty());
}

}  // namespace
}  // namespace proprio
