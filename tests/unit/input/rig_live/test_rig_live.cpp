#include <chrono>
#include <cmath>
#include <thread>

#include <gtest/gtest.h>

#include "proprio/rig_device/joint_kinematics.hpp"
#include "proprio/rig_live/live_bench.hpp"
#include "proprio/rig_live/plan_device.hpp"
#include "proprio/rig_live/rig_live.hpp"
#include "proprio/rig_plan/rig_reduction.hpp"

namespace proprio::rig_live {
namespace {

// A four-bone arm with a branching hand, five sample poses; planned with the
// thesis's kit, so the tests run on what `rig plan` makes.
rig_plan::RigInput small_rig() {
  rig_plan::RigInput in;
  in.name = "arm";
  Skeleton& s = in.skeleton;
  s.add("root", -1, Vec3(0, 1, 0));
  s.add("upper", 0, Vec3(0.0, 0.0, 0.3));
  s.add("lower", 1, Vec3(0.0, 0.0, 0.3));
  s.add("hand", 2, Vec3(0.0, 0.0, 0.25));
  s.add("finger_a", 3, Vec3(0.05, 0.0, 0.1));
  s.add("finger_b", 3, Vec3(-0.05, 0.0, 0.1));
  in.area_m2.assign(s.size(), 0.02);
  const double angles[5][3] = {{0.3, -0.2, 0.1}, {-0.4, 0.5, 0.0}, {0.6, 0.2, -0.3}, {0.0, -0.6, 0.4}, {-0.2, 0.1, 0.7}};
  for (int k = 0; k < 5; ++k) {
    SkeletonPose p = rest_pose(s);
    p.q_parent_node[1] = so3_exp(Vec3(angles[k][0], angles[k][1], 0.1 * k));
    p.q_parent_node[2] = so3_exp(Vec3(angles[k][1], 0.0, angles[k][2]));
    p.q_parent_node[3] = so3_exp(Vec3(angles[k][2], angles[k][0], 0.0));
    p.q_parent_node[4] = so3_exp(Vec3(0.2 * k, 0.0, 0.0));
    in.samples.push_back(p);
    in.sample_names.push_back("pose" + std::to_string(k));
  }
  return in;
}

rig_plan::Plan small_plan(const rig_plan::RigInput& in) {
  auto plan = rig_plan::reduce_rig(in, rig_device::default_kit());
  EXPECT_TRUE(plan.ok()) << (plan.ok() ? "" : plan.error().message);
  return plan.ok() ? *plan : rig_plan::Plan{};
}

double angle_between(const Quat& a, const Quat& b) { return so3_log(a.conjugate() * b).norm(); }

TEST(PlanBusTree, OneComponentPerModuleUnderOneBase) {
  const auto in = small_rig();
  const auto plan = small_plan(in);
  ASSERT_FALSE(plan.modules.empty());
  auto tree = bus_tree_for_plan(plan, 7);
  ASSERT_TRUE(tree.ok()) << tree.error().message;
  ASSERT_EQ(tree->tree.components.size(), plan.modules.size() + 1);
  EXPECT_EQ(tree->tree.components[0].kind, rig_bus::ComponentKind::base);
  for (std::size_t m = 0; m < plan.modules.size(); ++m) {
    const auto& c = tree->tree.components[m + 1];
    EXPECT_EQ(c.id, tree->module_id[m]);
    EXPECT_EQ(tree->module_of.at(c.id), static_cast<int>(m));
    EXPECT_EQ(c.parent, plan.modules[m].parent_module + 1);
    EXPECT_EQ(c.kind == rig_bus::ComponentKind::splitter, plan.modules[m].type == rig_plan::DeviceModule::Type::splitter);
  }
  // Another seed, other IDs (the parts' programming times differ).
  auto other = bus_tree_for_plan(plan, 8);
  ASSERT_TRUE(other.ok());
  EXPECT_NE(other->module_id, tree->module_id);

  rig_plan::Plan broken = plan;
  broken.modules.clear();
  EXPECT_FALSE(bus_tree_for_plan(broken).ok());
}

TEST(PlanAnimator, StartsAtRestAndHoldsEachSamplePose) {
  const auto in = small_rig();
  const auto plan = small_plan(in);
  ASSERT_FALSE(plan.device_poses.empty());
  AnimatorOptions o;
  o.seconds_per_pose = 2.0;
  o.hold_fraction = 0.5;
  auto a = PlanAnimator::create(plan, o);
  ASSERT_TRUE(a.ok()) << a.error().message;
  std::vector<Quat> q;
  a->q_in_out(0.0, q);
  for (std::size_t m = 0; m < plan.modules.size(); ++m) {
    if (plan.modules[m].type == rig_plan::DeviceModule::Type::joint) {
      EXPECT_LT(angle_between(q[m], plan.modules[m].q_in_out_rest), 1e-9);
    }
  }
  // During the hold of segment k the device is at sample k exactly.
  for (std::size_t k = 0; k < plan.device_poses.size(); ++k) {
    const double t = 2.0 * static_cast<double>(k) + 1.5;
    EXPECT_EQ(a->target_sample(t), k);
    a->q_in_out(t, q);
    for (std::size_t m = 0; m < plan.modules.size(); ++m) EXPECT_LT(angle_between(q[m], plan.device_poses[k][m]), 1e-9);
  }
  // Continuous: no jump between neighbouring instants.
  std::vector<Quat> prev;
  a->q_in_out(0.0, prev);
  for (double t = 0.01; t < 12.0; t += 0.01) {
    a->q_in_out(t, q);
    for (std::size_t m = 0; m < q.size(); ++m) ASSERT_LT(angle_between(q[m], prev[m]), 0.05) << "t " << t;
    prev = q;
  }
  AnimatorOptions bad;
  bad.seconds_per_pose = std::nan("");
  EXPECT_FALSE(PlanAnimator::create(plan, bad).ok());
}

TEST(EmulatedPlanDevice, ReportsTheAnimatorsAnglesThroughTheSensors) {
  const auto in = small_rig();
  const auto plan = small_plan(in);
  auto tree = bus_tree_for_plan(plan);
  ASSERT_TRUE(tree.ok());
  EmulatedDeviceOptions exact;
  exact.hall_sensors = false;
  auto ideal = EmulatedPlanDevice::create(plan, *tree, exact);
  ASSERT_TRUE(ideal.ok()) << ideal.error().message;
  EmulatedDeviceOptions real;
  auto sensed = EmulatedPlanDevice::create(plan, *tree, real);
  ASSERT_TRUE(sensed.ok()) << sensed.error().message;
  double worst_rad = 0.0;
  int compared = 0;
  for (std::size_t m = 0; m < plan.modules.size(); ++m) {
    if (plan.modules[m].type != rig_plan::DeviceModule::Type::joint) continue;
    for (TimeNs t = 0; t < 8 * kNsPerSecond; t += 20 * kNsPerMillisecond) {
      const auto a = (*ideal)->angles(t, tree->module_id[m]);
      const Quat want = (*ideal)->animator().q_in_out(static_cast<double>(t) * 1e-9, m);
      ASSERT_LT(angle_between(rig_device::joint_rotation(a), want), 1e-9);
      const auto b = (*sensed)->angles(t, tree->module_id[m]);
      const auto within = [&](const rig_device::JointAngles& x) {
        const double lim = plan.kit.joint.bend_limit_rad - 0.05;
        return std::abs(x.bend_x_rad) < lim && std::abs(x.bend_y_rad) < lim;
      };
      if (!within(a)) continue;  // beyond the joint's reach the sensors read its stop, not the command
      worst_rad = std::max(worst_rad, angle_between(rig_device::joint_rotation(b), want));
      ++compared;
    }
  }
  ASSERT_GT(compared, 100);
  // Backlash, noise and calibration leave a few tenths of a degree per angle.
  EXPECT_LT(worst_rad * 180.0 / M_PI, 3.0);
  // Components that are not joints report nothing.
  const auto none = (*ideal)->angles(0, 12345);
  EXPECT_EQ(none.bend_x_rad, 0.0);
}

// The whole live chain in real time: emulator thread, fake cable, driver
// thread, binding, retargeting. No faults and exact angles: the pose must
// follow the animator closely once the bus is up (the difference is the
// bus's latency, a few tens of milliseconds of slow motion).
TEST(RigLiveSource, EmulatedDeviceBindsAndFollowsTheAnimator) {
  const auto in = small_rig();
  const auto plan = small_plan(in);
  RigLiveOptions o;
  o.emulated.hall_sensors = false;
  o.emulated.animator.seconds_per_pose = 4.0;
  auto source = RigLiveSource::create(in, plan, o);
  ASSERT_TRUE(source.ok()) << source.error().message;
  ASSERT_TRUE((*source)->start().ok());
  RigLiveFrame f;
  bool bound = false;
  for (int i = 0; i < 300 && !bound; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    ASSERT_TRUE((*source)->update(f).ok());
    bound = f.joints_live == f.joints_planned && f.binding_problems.empty();
  }
  ASSERT_TRUE(bound) << f.binding_problems << " live " << f.joints_live << "/" << f.joints_planned;
  ASSERT_TRUE(f.truth.has_value());
  std::vector<Pose> T_live, T_true;
  double worst_m = 0.0;
  for (int i = 0; i < 30; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    ASSERT_TRUE((*source)->update(f).ok());
    forward_kinematics(in.skeleton, f.pose, T_live);
    forward_kinematics(in.skeleton, *f.truth, T_true);
    for (std::size_t n = 0; n < T_live.size(); ++n) worst_m = std::max(worst_m, (T_live[n].p - T_true[n].p).norm());
  }
  (*source)->stop();
  EXPECT_LT(worst_m, 0.05);
  EXPECT_GT((*source)->device_stats().host.messages, 0u);
}

// The same chain in simulated time: with exact angles and a clean bus the
// only error left is the bus's latency on a slow animator; with the sensors
// and the faults the device stays bound and close.
TEST(LiveBench, CleanBusLeavesOnlyLatencyAndFaultsStayBounded) {
  const auto in = small_rig();
  const auto plan = small_plan(in);
  LiveBenchOptions clean;
  clean.seconds = 12.0;
  clean.hall_sensors = false;
  clean.faults = {};
  auto a = run_live_bench(in, plan, clean);
  ASSERT_TRUE(a.ok()) << a.error().message;
  EXPECT_GT(a->frames, 500u);
  EXPECT_GT(a->frames_all_live_fraction, 0.99);
  EXPECT_EQ(a->host_detaches, 0u);
  EXPECT_LT(a->joint_error_deg.mean, 1.0);
  EXPECT_LT(a->node_error_percent.mean, 1.0);

  LiveBenchOptions faulty;
  faulty.seconds = 12.0;
  faulty.faults.power_loss_interval_ns = 3 * kNsPerSecond;
  auto b = run_live_bench(in, plan, faulty);
  ASSERT_TRUE(b.ok()) << b.error().message;
  EXPECT_GT(b->power_losses, 0u);
  EXPECT_GT(b->joints_live_fraction, 0.7);
  EXPECT_GE(b->node_error_m.mean, a->node_error_m.mean * 0.5);  // not better than the clean run by luck alone
  EXPECT_TRUE(std::isfinite(b->node_error_m.max));

  LiveBenchOptions bad;
  bad.warmup_s = 100.0;
  EXPECT_FALSE(run_live_bench(in, plan, bad).ok());
}

TEST(RigLiveOptions, RefusesNonsense) {
  RigLiveOptions o;
  o.device = "bluetooth";
  EXPECT_FALSE(o.validate().ok());
  o = {};
  o.stale_after_s = -1;
  EXPECT_FALSE(o.validate().ok());
  o = {};
  o.faults.loss_probability = 2.0;
  EXPECT_FALSE(o.validate().ok());
  EXPECT_TRUE(RigLiveOptions{}.validate().ok());
}

}  // namespace
}  // namespace proprio::rig_live
