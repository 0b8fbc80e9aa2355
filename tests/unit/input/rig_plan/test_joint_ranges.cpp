#include <cmath>

#include <gtest/gtest.h>

#include "proprio/rig_plan/joint_ranges.hpp"
#include "proprio/rig_plan/retarget.hpp"
#include "runtime_fixtures.hpp"

namespace proprio::rig_plan {
namespace {

using test_fixtures::small_input;
using test_fixtures::small_plan;

double angle_between(const Quat& a, const Quat& b) { return so3_log(a.conjugate() * b).norm(); }

// A plan whose joints all sit far off straight at rest (as a device copying a
// rig's right angles at rest would): each rest setting and its samples turned
// by the same bend, which leaves the mapping M unchanged.
Plan bent_plan(const RigInput& in, double bend_rad) {
  Plan plan = small_plan(in);
  for (auto& m : plan.modules) {
    if (m.type != DeviceModule::Type::joint) continue;
    const Quat turn = so3_exp(Vec3(bend_rad, 0.0, 0.0));
    for (std::size_t s = 0; s < plan.device_poses.size(); ++s) {
      const std::size_t k = static_cast<std::size_t>(&m - plan.modules.data());
      const Quat delta = plan.device_poses[s][k] * m.q_in_out_rest.conjugate();
      plan.device_poses[s][k] = (delta * m.q_in_out_rest * turn).normalized();
    }
    m.q_in_out_rest = (m.q_in_out_rest * turn).normalized();
  }
  return plan;
}

TEST(JointRanges, ShaftAngleIsTheAngleBetweenTheShafts) {
  EXPECT_NEAR(shaft_angle_rad(Quat::Identity()), 0.0, 1e-12);
  EXPECT_NEAR(shaft_angle_rad(so3_exp(Vec3(0.4, 0, 0))), 0.4, 1e-12);
  EXPECT_NEAR(shaft_angle_rad(so3_exp(Vec3(0, 0, 2.0))), 0.0, 1e-12);  // twist is free
}

TEST(JointRanges, CentringKeepsEverySampleOnTheSameRigPoseAndBringsJointsInRange) {
  const RigInput in = small_input(10, 5);
  Plan plan = bent_plan(in, 1.3);  // 75 degrees off straight at rest
  const auto before = joint_range_report(plan);
  ASSERT_GT(before.joints_past_stop, 0);

  auto r0 = Retargeter::create(in, plan);
  ASSERT_TRUE(r0.ok()) << r0.error().message;
  std::vector<SkeletonPose> poses_before;
  for (int s = 0; s < static_cast<int>(in.samples.size()); ++s) {
    auto p = r0->device_pose_to_rig(s);
    ASSERT_TRUE(p.ok());
    poses_before.push_back(*p);
  }
  const int moved = center_joint_ranges(plan);
  EXPECT_GT(moved, 0);
  const auto after = joint_range_report(plan);
  EXPECT_LT(after.joints_past_stop, before.joints_past_stop);
  for (std::size_t j = 0; j < after.joints.size(); ++j)
    EXPECT_LE(after.joints[j].max_shaft_rad, before.joints[j].max_shaft_rad + 1e-9) << "joint " << j;

  auto r1 = Retargeter::create(in, plan);
  ASSERT_TRUE(r1.ok()) << r1.error().message;
  for (int s = 0; s < static_cast<int>(in.samples.size()); ++s) {
    auto p = r1->device_pose_to_rig(s);
    ASSERT_TRUE(p.ok());
    for (std::size_t n = 0; n < p->q_parent_node.size(); ++n)
      EXPECT_LT(angle_between(p->q_parent_node[n], poses_before[static_cast<std::size_t>(s)].q_parent_node[n]), 1e-6)
          << "sample " << s << " node " << in.skeleton.names[n];
  }
  // Readings at the rest settings still give the rig's rest for driven nodes.
  std::vector<std::optional<Quat>> q(plan.modules.size());
  for (std::size_t m = 0; m < plan.modules.size(); ++m)
    if (plan.modules[m].type == DeviceModule::Type::joint) q[m] = plan.modules[m].q_in_out_rest;
  RetargetOptions no_space;
  no_space.pose_space = false;
  auto r2 = Retargeter::create(in, plan, no_space);
  ASSERT_TRUE(r2.ok());
  SkeletonPose rest;
  ASSERT_TRUE(r2->retarget(q, rest).ok());
  for (std::size_t n = 0; n < rest.q_parent_node.size(); ++n)
    EXPECT_LT(angle_between(rest.q_parent_node[n], in.skeleton.q_parent_node_rest[n]), 1e-9);
}

TEST(JointRanges, JointsWellInsideTheirStopsAreLeftAlone) {
  const RigInput in = small_input(6, 9);
  Plan plan = small_plan(in);
  const Plan original = plan;
  plan.kit.joint.bend_limit_rad = M_PI / 2;  // room for everything the fixture asks
  const auto report = joint_range_report(plan);
  bool all_inside = true;
  for (const auto& j : report.joints) all_inside = all_inside && j.max_shaft_rad < M_PI / 2 - 0.1;
  if (!all_inside) GTEST_SKIP() << "the fixture's samples bend a joint near 90 degrees";
  EXPECT_EQ(center_joint_ranges(plan), 0);
  for (std::size_t m = 0; m < plan.modules.size(); ++m)
    EXPECT_LT(angle_between(plan.modules[m].q_in_out_rest, original.modules[m].q_in_out_rest), 1e-12);
}

}  // namespace
}  // namespace proprio::rig_plan
