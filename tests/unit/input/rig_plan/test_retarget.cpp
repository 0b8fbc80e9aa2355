#include "proprio/rig_plan/retarget.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <new>
#include <optional>
#include <vector>

#include "unit/input/rig_plan/runtime_fixtures.hpp"

// Counts heap allocations so a test can show a retarget call makes none. Not
// under AddressSanitizer, which owns operator new there.
#if defined(__SANITIZE_ADDRESS__)
#define PROPRIO_RIG_PLAN_COUNT_ALLOCATIONS 0
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define PROPRIO_RIG_PLAN_COUNT_ALLOCATIONS 0
#endif
#endif
#ifndef PROPRIO_RIG_PLAN_COUNT_ALLOCATIONS
#define PROPRIO_RIG_PLAN_COUNT_ALLOCATIONS 1
#endif

#if PROPRIO_RIG_PLAN_COUNT_ALLOCATIONS
// GCC cannot see that this new and these deletes pair up through malloc/free.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
namespace {
std::atomic<long> g_rig_plan_allocations{0};
}
void* operator new(std::size_t size) {
  g_rig_plan_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop
#endif

namespace proprio::rig_plan::retarget_tests {
namespace {

namespace fx = test_fixtures;

std::vector<std::optional<Quat>> readings_of(const Plan& plan, int sample) {
  std::vector<std::optional<Quat>> r(plan.modules.size());
  for (std::size_t m = 0; m < plan.modules.size(); ++m)
    r[m] = plan.device_poses[static_cast<std::size_t>(sample)][m];
  return r;
}

TEST(Retargeter, AllJointsReproduceTheDrivenNodesExactly) {
  const RigInput input = fx::small_input(8);
  const Plan plan = fx::small_plan(input);
  for (bool pose_space : {false, true}) {
    RetargetOptions options;
    options.pose_space = pose_space;
    auto r = Retargeter::create(input, plan, options);
    ASSERT_TRUE(r.ok()) << r.error().message;
    Rng rng(3);
    for (int trial = 0; trial < 20; ++trial) {
      std::vector<std::optional<Quat>> readings(plan.modules.size());
      for (auto& q : readings) q = fx::random_rotation(rng, 1.5);
      SkeletonPose pose;
      ASSERT_TRUE(r->retarget(readings, pose).ok());
      ASSERT_EQ(pose.q_parent_node.size(), input.skeleton.size());
      for (std::size_t m = 0; m < plan.modules.size(); ++m) {
        const DeviceModule& j = plan.modules[m];
        if (j.type != DeviceModule::Type::joint) continue;
        const auto b = static_cast<std::size_t>(j.rig_node);
        // M of plan.hpp, written out.
        const Quat delta = *readings[m] * j.q_in_out_rest.inverse();
        const Quat expected = j.q_parent_inlet * delta * j.q_parent_inlet.inverse() * input.skeleton.q_parent_node_rest[b];
        EXPECT_LT(angle_between(pose.q_parent_node[b], expected), 1e-12);
      }
      if (!pose_space) {
        for (int b : {0, 2, 4, 8}) EXPECT_LT(angle_between(pose.q_parent_node[static_cast<std::size_t>(b)],
                                                          input.skeleton.q_parent_node_rest[static_cast<std::size_t>(b)]),
                                            1e-15);
      }
    }
  }
}

TEST(Retargeter, RestSettingGivesTheRestRotation) {
  const RigInput input = fx::small_input(8);
  const Plan plan = fx::small_plan(input);
  RetargetOptions options;
  options.pose_space = false;
  auto r = Retargeter::create(input, plan, options);
  ASSERT_TRUE(r.ok());
  std::vector<std::optional<Quat>> readings(plan.modules.size());
  for (std::size_t m = 0; m < plan.modules.size(); ++m) readings[m] = plan.modules[m].q_in_out_rest;
  SkeletonPose pose;
  ASSERT_TRUE(r->retarget(readings, pose).ok());
  for (std::size_t b = 0; b < input.skeleton.size(); ++b)
    EXPECT_LT(angle_between(pose.q_parent_node[b], input.skeleton.q_parent_node_rest[b]), 1e-12);
}

TEST(Retargeter, EachFittedDevicePoseGivesItsSample) {
  const RigInput input = fx::small_input(8);
  const Plan plan = fx::small_plan(input);
  auto r = Retargeter::create(input, plan);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_NE(r->pose_space(), nullptr);
  for (int i = 0; i < 8; ++i) {
    auto pose = r->device_pose_to_rig(i);
    ASSERT_TRUE(pose.ok());
    for (std::size_t b = 0; b < input.skeleton.size(); ++b)
      EXPECT_LT(angle_between(pose->q_parent_node[b], input.samples[static_cast<std::size_t>(i)].q_parent_node[b]), 1e-8)
          << "sample " << i << " node " << b;
  }
  EXPECT_FALSE(r->device_pose_to_rig(8).ok());
}

TEST(Retargeter, MissingJointsAreInterpolated) {
  const RigInput input = fx::small_input(8);
  const Plan plan = fx::small_plan(input);
  auto with = Retargeter::create(input, plan);
  ASSERT_TRUE(with.ok());
  auto readings = readings_of(plan, 3);
  readings[5].reset();                                           // joint on l_fore detached
  readings[2] = Quat(std::nan(""), 0.0, 0.0, 0.0);               // a broken sensor: missing too
  SkeletonPose pose;
  ASSERT_TRUE(with->retarget(readings, pose).ok());
  std::vector<Quat> blended(input.skeleton.size(), Quat::Identity());
  with->pose_space()->blend(with->last_weights(), blended);
  for (int b : {6, 3}) {  // l_fore, neck
    const auto ub = static_cast<std::size_t>(b);
    EXPECT_LT(angle_between(pose.q_parent_node[ub], blended[ub]), 1e-12);
    EXPECT_NEAR(pose.q_parent_node[ub].norm(), 1.0, 1e-12);
  }
  // The joints that are there still drive their nodes.
  EXPECT_LT(angle_between(pose.q_parent_node[5], input.samples[3].q_parent_node[5]), 1e-9);

  RetargetOptions off;
  off.pose_space = false;
  auto without = Retargeter::create(input, plan, off);
  ASSERT_TRUE(without.ok());
  ASSERT_TRUE(without->retarget(readings, pose).ok());
  EXPECT_LT(angle_between(pose.q_parent_node[6], input.skeleton.q_parent_node_rest[6]), 1e-15);
}

TEST(Retargeter, RefusesMismatchedInput) {
  const RigInput input = fx::small_input(8);
  Plan plan = fx::small_plan(input);
  auto r = Retargeter::create(input, plan);
  ASSERT_TRUE(r.ok());
  SkeletonPose pose;
  std::vector<std::optional<Quat>> too_few(3);
  EXPECT_FALSE(r->retarget(too_few, pose).ok());

  Plan fewer_poses = plan;
  fewer_poses.device_poses.pop_back();
  auto e = Retargeter::create(input, fewer_poses);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message.find("recompute"), std::string::npos);

  Plan off_rig = plan;
  off_rig.modules[3].rig_node = 40;
  EXPECT_FALSE(Retargeter::create(input, off_rig).ok());

  RetargetOptions bad;
  bad.pose_space_options.identical_tolerance = -1.0;
  EXPECT_FALSE(Retargeter::create(input, plan, bad).ok());
  EXPECT_FALSE(RetargetOptions{}.describe().empty());
}

TEST(Retargeter, DoesNotAllocateAfterTheFirstCall) {
#if PROPRIO_RIG_PLAN_COUNT_ALLOCATIONS
  const RigInput input = fx::small_input(12);
  const Plan plan = fx::small_plan(input);
  auto r = Retargeter::create(input, plan);
  ASSERT_TRUE(r.ok());
  auto readings = readings_of(plan, 2);
  SkeletonPose pose;
  ASSERT_TRUE(r->retarget(readings, pose).ok());
  readings[4].reset();
  const long before = g_rig_plan_allocations.load();
  ASSERT_GT(before, 0);  // the hook sees allocations at all
  for (int k = 0; k < 50; ++k) {
    readings[0] = plan.device_poses[static_cast<std::size_t>(k % 12)][0];
    ASSERT_TRUE(r->retarget(readings, pose).ok());
  }
  EXPECT_EQ(g_rig_plan_allocations.load(), before);
#else
  GTEST_SKIP() << "allocation counting is off under AddressSanitizer";
#endif
}

}  // namespace
}  // namespace proprio::rig_plan::retarget_tests
