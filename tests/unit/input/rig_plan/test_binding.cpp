#include "proprio/rig_plan/binding.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "unit/input/rig_plan/runtime_fixtures.hpp"

namespace proprio::rig_plan::binding_tests {
namespace {

namespace fx = test_fixtures;

// The device as the bus would report it when built exactly to the plan, ids
// 100 + module number, listed in a scrambled order.
std::vector<ObservedModule> as_built(const Plan& plan) {
  std::vector<ObservedModule> out;
  for (std::size_t i = 0; i < plan.modules.size(); ++i) {
    const DeviceModule& m = plan.modules[i];
    ObservedModule o;
    o.id = 101 + static_cast<std::uint32_t>(i);
    o.is_splitter = m.type == DeviceModule::Type::splitter;
    o.kind = o.is_splitter ? m.kind : "joint";
    o.parent_id = m.parent_module < 0 ? 0 : 101 + static_cast<std::uint32_t>(m.parent_module);
    o.parent_outlet = m.parent_outlet;
    out.push_back(o);
  }
  std::reverse(out.begin(), out.end());
  return out;
}

ObservedModule* find(std::vector<ObservedModule>& v, std::uint32_t id) {
  for (auto& o : v)
    if (o.id == id) return &o;
  return nullptr;
}

int count(const Binding& b, BindingProblem::Kind kind) {
  return static_cast<int>(std::count_if(b.problems.begin(), b.problems.end(),
                                        [&](const BindingProblem& p) { return p.kind == kind; }));
}

TEST(Binding, AnExactDeviceBindsEveryModule) {
  const Plan plan = fx::small_plan(fx::small_input(2));
  auto b = bind_device(plan, as_built(plan));
  ASSERT_TRUE(b.ok()) << b.error().message;
  EXPECT_TRUE(b->complete()) << b->describe();
  for (std::size_t i = 0; i < plan.modules.size(); ++i) EXPECT_EQ(b->observed_id[i], 101 + i);
  // Readings follow the components to their modules (the list is reversed).
  const auto device = as_built(plan);
  std::vector<std::optional<Quat>> by_component(device.size());
  for (std::size_t k = 0; k < device.size(); ++k) by_component[k] = so3_exp(Vec3(0.01 * device[k].id, 0, 0));
  std::vector<std::optional<Quat>> per_module(plan.modules.size());
  b->plan_readings(by_component, per_module);
  for (std::size_t i = 0; i < plan.modules.size(); ++i) {
    ASSERT_TRUE(per_module[i].has_value());
    EXPECT_NEAR(so3_log(*per_module[i]).x(), 0.01 * static_cast<double>(101 + i), 1e-12);
  }
}

TEST(Binding, ExchangedJointsStillBind) {
  const Plan plan = fx::small_plan(fx::small_input(2));
  auto device = as_built(plan);
  // Joints 3 and 4 (ids 103, 104) trade places: all joints are alike.
  ObservedModule* a = find(device, 103);
  ObservedModule* c = find(device, 104);
  std::swap(a->parent_outlet, c->parent_outlet);
  find(device, 106)->parent_id = 103;  // l_fore's joint followed its parent
  auto b = bind_device(plan, device);
  ASSERT_TRUE(b.ok());
  EXPECT_TRUE(b->complete()) << b->describe();
  EXPECT_EQ(b->observed_id[2], 104u);
  EXPECT_EQ(b->observed_id[3], 103u);
}

TEST(Binding, AMissingModuleSaysWhereToPlugIt) {
  const Plan plan = fx::small_plan(fx::small_input(2));
  auto device = as_built(plan);
  device.erase(std::remove_if(device.begin(), device.end(), [](const ObservedModule& o) { return o.id == 105; }),
               device.end());
  auto b = bind_device(plan, device);
  ASSERT_TRUE(b.ok());
  EXPECT_FALSE(b->complete());
  EXPECT_EQ(b->bound_count(), 5);
  std::vector<std::optional<Quat>> per_module(plan.modules.size(), Quat::Identity());
  b->plan_readings(std::vector<std::optional<Quat>>(device.size(), Quat::Identity()), per_module);
  EXPECT_FALSE(per_module[4].has_value());
  EXPECT_TRUE(per_module[3].has_value());
  ASSERT_EQ(b->problems.size(), 1u) << b->describe();
  EXPECT_EQ(b->problems[0].kind, BindingProblem::Kind::missing);
  EXPECT_EQ(b->problems[0].plan_module, 4);
  EXPECT_NE(b->problems[0].message.find("module 5 (joint)"), std::string::npos);
  EXPECT_NE(b->problems[0].message.find("plug a joint into outlet 2 of module 2 (splitter T3)"), std::string::npos)
      << b->problems[0].message;

  // Without joint 4, joint 6 below it cannot bind either: one message for both.
  auto device2 = as_built(plan);
  device2.erase(std::remove_if(device2.begin(), device2.end(),
                               [](const ObservedModule& o) { return o.id == 104 || o.id == 106; }),
                device2.end());
  auto b2 = bind_device(plan, device2);
  ASSERT_TRUE(b2.ok());
  EXPECT_EQ(b2->bound_count(), 4);
  ASSERT_EQ(b2->problems.size(), 1u) << b2->describe();
  EXPECT_NE(b2->problems[0].message.find("and the 1 module(s) below it"), std::string::npos);
}

TEST(Binding, AnExtraModuleIsReportedAndTheRestBinds) {
  const Plan plan = fx::small_plan(fx::small_input(2));
  auto device = as_built(plan);
  device.push_back({900, false, "joint", 106, 0});  // after l_fore's joint
  device.push_back({901, false, "joint", 900, 0});  // and one more below it: not reported twice
  auto b = bind_device(plan, device);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->bound_count(), 6);
  ASSERT_EQ(b->problems.size(), 1u) << b->describe();
  EXPECT_EQ(b->problems[0].kind, BindingProblem::Kind::extra);
  EXPECT_EQ(b->problems[0].observed_id, 900u);
  EXPECT_NE(b->problems[0].message.find("the outlet of module 6 (joint)"), std::string::npos)
      << b->problems[0].message;
  EXPECT_NE(b->problems[0].message.find("unplug it"), std::string::npos);
}

TEST(Binding, AWrongSplitterIsNamedAndItsBranchesWait) {
  const Plan plan = fx::small_plan(fx::small_input(2));
  auto device = as_built(plan);
  find(device, 102)->kind = "Y3";
  auto b = bind_device(plan, device);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->bound_count(), 1);  // only the spine joint
  ASSERT_EQ(count(*b, BindingProblem::Kind::wrong_kind), 1) << b->describe();
  EXPECT_NE(b->describe().find("a Y3 splitter (id 0x00000066) is plugged into the outlet of module 1 (joint)"),
            std::string::npos)
      << b->describe();
  EXPECT_NE(b->describe().find("replace it with a T3 splitter"), std::string::npos);
  EXPECT_EQ(count(*b, BindingProblem::Kind::extra), 0) << b->describe();
}

TEST(Binding, SwappedBranchesAreDetected) {
  const Plan plan = fx::small_plan(fx::small_input(2));
  auto device = as_built(plan);
  // The l_arm branch (joints 104, 106) goes into outlet 2, the r_arm joint into outlet 1.
  find(device, 104)->parent_outlet = 2;
  find(device, 105)->parent_outlet = 1;
  auto b = bind_device(plan, device);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(count(*b, BindingProblem::Kind::swapped_branches), 1) << b->describe();
  EXPECT_NE(b->describe().find("outlets 1 and 2 of module 2 (splitter T3)"), std::string::npos) << b->describe();
  // What matches by position still binds: the two arm joints; l_fore's joint is extra.
  EXPECT_EQ(count(*b, BindingProblem::Kind::missing), 1);
  EXPECT_EQ(count(*b, BindingProblem::Kind::extra), 1);
}

TEST(Binding, DisconnectedOrLoopingComponentsAreReported) {
  const Plan plan = fx::small_plan(fx::small_input(2));
  auto device = as_built(plan);
  device.push_back({700, false, "joint", 777, 0});  // parent never heard from
  device.push_back({701, false, "joint", 702, 0});  // a loop
  device.push_back({702, false, "joint", 701, 0});
  auto b = bind_device(plan, device);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->bound_count(), 6);
  EXPECT_EQ(count(*b, BindingProblem::Kind::disconnected), 2) << b->describe();
  EXPECT_NE(b->describe().find("0x00000309"), std::string::npos);  // 777
  EXPECT_NE(b->describe().find("loop"), std::string::npos);
}

TEST(Binding, RefusesAMalformedObservation) {
  const Plan plan = fx::small_plan(fx::small_input(2));
  auto device = as_built(plan);
  device.push_back(device.front());
  auto twice = bind_device(plan, device);
  ASSERT_FALSE(twice.ok());
  EXPECT_NE(twice.error().message.find("two components"), std::string::npos);
  std::vector<ObservedModule> zero = {{0, false, "joint", 0, 0}};
  EXPECT_FALSE(bind_device(plan, zero).ok());
  // An empty device binds nothing and asks for the root module.
  auto empty = bind_device(plan, {});
  ASSERT_TRUE(empty.ok());
  ASSERT_EQ(empty->problems.size(), 1u);
  EXPECT_NE(empty->problems[0].message.find("plug a joint into the base"), std::string::npos);
}

}  // namespace
}  // namespace proprio::rig_plan::binding_tests
