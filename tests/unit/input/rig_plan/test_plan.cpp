#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "proprio/rig_plan/plan.hpp"
#include "unit/input/rig_plan/synthetic_rigs.hpp"

namespace proprio::rig_plan {
namespace {

TEST(RigInputValidate, AcceptsTheSyntheticCharacters) {
  EXPECT_TRUE(synthetic::chain(4, 3, 1).validate().ok());
  EXPECT_TRUE(synthetic::star(3, 3, 3, 2).validate().ok());
  EXPECT_TRUE(synthetic::humanoid(5, 3).validate().ok());
  EXPECT_TRUE(synthetic::creature(2, 4).validate().ok());
}

TEST(RigInputValidate, RejectsBadAreasNamesAndPoses) {
  const RigInput good = synthetic::humanoid(3, 5);
  {
    RigInput in = good;
    in.area_m2[2] = -0.1;
    const Status s = in.validate();
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find(good.skeleton.names[2]), std::string::npos) << s.error().message;
  }
  {
    RigInput in = good;
    in.area_m2[1] = std::numeric_limits<double>::quiet_NaN();
    EXPECT_FALSE(in.validate().ok());
  }
  {
    RigInput in = good;
    in.area_m2.pop_back();
    EXPECT_FALSE(in.validate().ok());
  }
  {
    RigInput in = good;
    in.sample_names.pop_back();
    EXPECT_FALSE(in.validate().ok());
  }
  {
    RigInput in = good;
    in.sample_names[1] = in.sample_names[0];
    EXPECT_FALSE(in.validate().ok());
  }
  {
    RigInput in = good;
    in.sample_names[0].clear();
    EXPECT_FALSE(in.validate().ok());
  }
  {
    RigInput in = good;
    in.samples[1].q_parent_node[3] = Quat(2.0, 0.0, 0.0, 0.0);  // not unit
    EXPECT_FALSE(in.validate().ok());
  }
  {
    RigInput in = good;
    in.samples[0].q_parent_node.pop_back();
    EXPECT_FALSE(in.validate().ok());
  }
  {
    RigInput in = good;
    in.samples.clear();
    in.sample_names.clear();
    EXPECT_FALSE(in.validate().ok());
  }
  {
    RigInput in = good;
    in.skeleton.parent[3] = 7;  // parent after child
    EXPECT_FALSE(in.validate().ok());
  }
}

TEST(PlanCounts, CountJointsAndSplittersSeparately) {
  Plan plan;
  EXPECT_EQ(plan.joint_count(), 0);
  EXPECT_EQ(plan.splitter_count(), 0);
  DeviceModule joint;
  DeviceModule splitter;
  splitter.type = DeviceModule::Type::splitter;
  plan.modules = {joint, splitter, joint, joint};
  EXPECT_EQ(plan.joint_count(), 3);
  EXPECT_EQ(plan.splitter_count(), 1);
}

}  // namespace
}  // namespace proprio::rig_plan
