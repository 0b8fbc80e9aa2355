#include <gtest/gtest.h>

#include <set>

#include "proprio/rig_device/kit.hpp"
#include "proprio/rig_plan/rig_reduction.hpp"
#include "unit/input/rig_plan/synthetic_rigs.hpp"

namespace proprio::rig_plan {
namespace {

using synthetic::Builder;

rig_device::Kit kit_of(int joints, bool splitters) {
  rig_device::Kit kit = rig_device::default_kit();
  kit.joint_count = joints;
  if (!splitters)
    for (int& c : kit.splitter_counts) c = 0;
  return kit;
}

bool is_descendant_or_self(const Skeleton& sk, int ancestor, int v) {
  for (int u = v; u >= 0; u = sk.parent[static_cast<std::size_t>(u)])
    if (u == ancestor) return true;
  return false;
}

// The plan's tree: parents first, outlets in range, splitter counts within
// the kit, joints on distinct drivable nodes below their parent module's node,
// every splitter feeding at least two modules, device poses for every sample.
void expect_consistent(const Plan& plan, const RigInput& in, const rig_device::Kit& kit) {
  const Skeleton& sk = in.skeleton;
  std::set<int> joint_nodes;
  std::vector<int> per_kind(kit.splitter_kinds.size(), 0);
  std::vector<int> children(plan.modules.size(), 0);
  ASSERT_LE(plan.joint_count(), kit.joint_count);
  for (std::size_t i = 0; i < plan.modules.size(); ++i) {
    const DeviceModule& m = plan.modules[i];
    ASSERT_LT(m.parent_module, static_cast<int>(i)) << "parents come first";
    ASSERT_GE(m.rig_node, 0);
    ASSERT_LT(m.rig_node, static_cast<int>(sk.size()));
    EXPECT_NEAR(m.q_parent_inlet.norm(), 1.0, 1e-9);
    EXPECT_NEAR(m.q_in_out_rest.norm(), 1.0, 1e-9);
    if (m.parent_module >= 0) {
      const DeviceModule& p = plan.modules[static_cast<std::size_t>(m.parent_module)];
      ++children[static_cast<std::size_t>(m.parent_module)];
      EXPECT_TRUE(is_descendant_or_self(sk, p.rig_node, m.rig_node));
      if (p.type == DeviceModule::Type::joint) {
        EXPECT_EQ(m.parent_outlet, 0);
      } else {
        ASSERT_GE(m.parent_outlet, 0);
        ASSERT_LT(m.parent_outlet, static_cast<int>(p.outlet_rig_child.size()));
        const int branch = p.outlet_rig_child[static_cast<std::size_t>(m.parent_outlet)];
        ASSERT_GE(branch, 0) << "a module hangs off an outlet the plan marks unused";
        EXPECT_TRUE(is_descendant_or_self(sk, branch, m.rig_node));
      }
    }
    if (m.type == DeviceModule::Type::joint) {
      EXPECT_TRUE(joint_nodes.insert(m.rig_node).second) << "two joints drive one node";
      EXPECT_GE(sk.parent[static_cast<std::size_t>(m.rig_node)], 0) << "a joint drives a root";
    } else {
      std::size_t k = 0;
      while (k < kit.splitter_kinds.size() && kit.splitter_kinds[k].name != m.kind) ++k;
      ASSERT_LT(k, kit.splitter_kinds.size()) << m.kind;
      ++per_kind[k];
      EXPECT_EQ(m.outlet_rig_child.size(), kit.splitter_kinds[k].valence());
      int used = 0;
      for (int c : m.outlet_rig_child) {
        if (c < 0) continue;
        ++used;
        EXPECT_EQ(sk.parent[static_cast<std::size_t>(c)], m.rig_node);
      }
      EXPECT_GE(used, 2);
      EXPECT_LE(m.angular_error_rad, 60.0 * M_PI / 180.0 + 1e-9);
    }
  }
  for (std::size_t i = 0; i < plan.modules.size(); ++i)
    if (plan.modules[i].type == DeviceModule::Type::joint) {
      EXPECT_LE(children[i], 1) << "a joint has one outlet";
    } else {
      EXPECT_GE(children[i], 2);
    }
  for (std::size_t k = 0; k < per_kind.size(); ++k) EXPECT_LE(per_kind[k], kit.splitter_counts[k]);
  ASSERT_EQ(plan.device_poses.size(), in.samples.size());
  for (const auto& pose : plan.device_poses) EXPECT_EQ(pose.size(), plan.modules.size());
}

// At rest the physical device lines up: each joint's inlet frame (its rig
// parent's rest frame times q_parent_inlet) is the outlet frame of the module
// it plugs into (a joint's inlet times its rest rotation; a splitter's inlet
// frame, its parent's outlet times its rest orientation, times the outlet's
// fixed rotation). Returns how many links were checked.
int expect_rest_frames_chain(const Plan& plan, const RigInput& in, const rig_device::Kit& kit) {
  std::vector<Pose> T;
  forward_kinematics(in.skeleton, rest_pose(in.skeleton), T);
  std::vector<std::vector<Quat>> outlet(plan.modules.size());
  std::vector<char> known(plan.modules.size(), 0);
  int checked = 0;
  for (std::size_t i = 0; i < plan.modules.size(); ++i) {
    const DeviceModule& m = plan.modules[i];
    const bool parent_known = m.parent_module >= 0 && known[static_cast<std::size_t>(m.parent_module)];
    const Quat up = parent_known ? outlet[static_cast<std::size_t>(m.parent_module)][static_cast<std::size_t>(m.parent_outlet)]
                                 : Quat::Identity();
    if (m.type == DeviceModule::Type::joint) {
      const int p = in.skeleton.parent[static_cast<std::size_t>(m.rig_node)];
      const Quat inlet = T[static_cast<std::size_t>(p)].q * m.q_parent_inlet;
      if (parent_known) {
        EXPECT_LT(angle_between(inlet, up), 1e-9) << "joint on " << in.skeleton.names[static_cast<std::size_t>(m.rig_node)];
        ++checked;
      }
      outlet[i] = {inlet * m.q_in_out_rest};
      known[i] = 1;
    } else if (parent_known) {
      if (plan.modules[static_cast<std::size_t>(m.parent_module)].type == DeviceModule::Type::joint) {
        EXPECT_LT(angle_between(m.q_in_out_rest, Quat::Identity()), 1e-9) << "a joint points into its splitter";
      }
      std::size_t k = 0;
      while (kit.splitter_kinds[k].name != m.kind) ++k;
      const Quat inlet = up * m.q_in_out_rest;
      for (const Quat& q : kit.splitter_kinds[k].q_inlet_outlet) outlet[i].push_back(inlet * q);
      known[i] = 1;
    }
  }
  return checked;
}

// E of the rig poses the plan's mapping M gives for its own device poses:
// driven nodes q = (q_parent_inlet Delta q_parent_inlet^-1) q_rest, the rest
// rigid, roots from the sample (plan.hpp's convention).
double error_through_mapping(const Plan& plan, const RigInput& in) {
  const std::vector<double> w = node_weights(in);
  double E = 0.0;
  std::vector<Pose> T, target;
  for (std::size_t s = 0; s < in.samples.size(); ++s) {
    SkeletonPose pose = rest_pose(in.skeleton);
    for (std::size_t v = 0; v < in.skeleton.size(); ++v)
      if (in.skeleton.parent[v] < 0) pose.q_parent_node[v] = in.samples[s].q_parent_node[v];
    pose.t_world_root_m = in.samples[s].t_world_root_m;
    for (std::size_t i = 0; i < plan.modules.size(); ++i) {
      const DeviceModule& m = plan.modules[i];
      if (m.type != DeviceModule::Type::joint) continue;
      const Quat delta = plan.device_poses[s][i] * m.q_in_out_rest.conjugate();
      pose.q_parent_node[static_cast<std::size_t>(m.rig_node)] =
          (m.q_parent_inlet * delta * m.q_parent_inlet.conjugate() *
           in.skeleton.q_parent_node_rest[static_cast<std::size_t>(m.rig_node)])
              .normalized();
    }
    forward_kinematics(in.skeleton, pose, T);
    forward_kinematics(in.skeleton, in.samples[s], target);
    for (std::size_t v = 0; v < T.size(); ++v) E += w[v] * (T[v].p - target[v].p).squaredNorm();
  }
  return E;
}

TEST(RigReduction, GreedyErrorCurveFallsMonotonically) {
  for (const RigInput& in : {synthetic::humanoid(6, 31), synthetic::star(3, 4, 5, 32)}) {
    auto plan = reduce_rig(in, kit_of(10, true));
    ASSERT_TRUE(plan.ok()) << plan.error().message;
    ASSERT_FALSE(plan->error_after_joint.empty());
    EXPECT_LT(plan->error_after_joint.front(), plan->error_rigid);
    for (std::size_t k = 1; k < plan->error_after_joint.size(); ++k)
      EXPECT_LE(plan->error_after_joint[k], plan->error_after_joint[k - 1]) << in.name << " joint " << k;
    EXPECT_LE(plan->error_final, plan->error_rigid);
  }
}

TEST(RigReduction, PlanTreeIsConsistentAndItsPosesReproduceTheFit) {
  for (const RigInput& in : {synthetic::humanoid(6, 41), synthetic::star(4, 3, 5, 42), synthetic::chain(6, 4, 43)}) {
    const rig_device::Kit kit = kit_of(8, true);
    auto plan = reduce_rig(in, kit);
    ASSERT_TRUE(plan.ok()) << plan.error().message;
    SCOPED_TRACE(in.name);
    expect_consistent(*plan, in, kit);
    EXPECT_GT(plan->joint_count(), 0);
    EXPECT_NEAR(error_through_mapping(*plan, in), plan->error_final, 1e-9 * (1.0 + plan->error_rigid));
    EXPECT_GT(expect_rest_frames_chain(*plan, in, kit), 0);
  }
}

TEST(RigReduction, EnoughJointsOnAChainReachEverySample) {
  const RigInput in = synthetic::chain(5, 4, 51);
  auto plan = reduce_rig(in, kit_of(18, true));
  ASSERT_TRUE(plan.ok()) << plan.error().message;
  // Every bone but the tip moves weight: four joints, no error left.
  EXPECT_EQ(plan->joint_count(), 4);
  EXPECT_LT(plan->error_final, 1e-10 * plan->error_rigid);
}

TEST(RigReduction, WithoutSplittersPhantomsMakeOneChain) {
  const RigInput in = synthetic::star(3, 4, 5, 61);
  const rig_device::Kit kit = kit_of(6, false);
  auto plan = reduce_rig(in, kit);
  ASSERT_TRUE(plan.ok()) << plan.error().message;
  expect_consistent(*plan, in, kit);
  EXPECT_EQ(plan->splitter_count(), 0);
  // One chain: one root module, each module at most one child, and all joints in one arm.
  int roots = 0;
  std::set<int> arms;
  for (const DeviceModule& m : plan->modules) {
    roots += m.parent_module < 0 ? 1 : 0;
    int u = m.rig_node;
    while (in.skeleton.parent[static_cast<std::size_t>(u)] != 0) u = in.skeleton.parent[static_cast<std::size_t>(u)];
    arms.insert(u);
  }
  EXPECT_EQ(roots, 1);
  EXPECT_EQ(arms.size(), 1u);
  // The unconstrained curve may use every arm; the device cannot.
  EXPECT_GE(plan->error_final, plan->error_after_joint.back() - 1e-15);
}

TEST(RigReduction, ASplitterLetsTheDeviceBranch) {
  // A star with three arms 120 degrees apart in a plane and a kit with a T3
  // and Y3 splitter: the device splits at the root.
  const RigInput in = synthetic::star(3, 3, 6, 71);
  const rig_device::Kit kit = kit_of(9, true);
  auto plan = reduce_rig(in, kit);
  ASSERT_TRUE(plan.ok()) << plan.error().message;
  expect_consistent(*plan, in, kit);
  EXPECT_GE(plan->splitter_count(), 1);
  std::set<int> arms;
  for (const DeviceModule& m : plan->modules) {
    if (m.type != DeviceModule::Type::joint) continue;
    int u = m.rig_node;
    while (in.skeleton.parent[static_cast<std::size_t>(u)] != 0) u = in.skeleton.parent[static_cast<std::size_t>(u)];
    arms.insert(u);
  }
  EXPECT_GE(arms.size(), 2u);
}

TEST(RigReduction, ReportsProgressAndHonoursMaxJoints) {
  const RigInput in = synthetic::humanoid(4, 81);
  ReductionOptions options;
  options.max_joints = 3;
  int calls = 0;
  auto plan = reduce_rig(in, kit_of(18, true), options, [&](const ReductionProgress& p) {
    ++calls;
    EXPECT_LE(p.joints_placed, 3);
    EXPECT_EQ(p.joints_available, 3);
  });
  ASSERT_TRUE(plan.ok()) << plan.error().message;
  EXPECT_GT(calls, 0);
  EXPECT_LE(plan->joint_count(), 3);
  EXPECT_LE(plan->error_after_joint.size(), 3u);
}

TEST(RigReduction, RejectsBadInputKitAndOptions) {
  RigInput in = synthetic::chain(3, 2, 1);
  ReductionOptions options;
  options.max_iterations = 0;
  EXPECT_FALSE(reduce_rig(in, kit_of(4, true), options).ok());
  rig_device::Kit kit = kit_of(4, true);
  kit.splitter_counts[0] = -1;
  EXPECT_FALSE(reduce_rig(in, kit).ok());
  in.area_m2[0] = -1.0;
  EXPECT_FALSE(reduce_rig(in, kit_of(4, true)).ok());
  EXPECT_FALSE(ReductionOptions{}.describe().empty());
}

TEST(RigReduction, DegenerateRigsGiveEmptyOrSmallPlans) {
  {
    // One node: nothing to drive.
    RigInput in;
    in.name = "dot";
    in.skeleton.add("root", -1, Vec3::Zero());
    in.area_m2 = {1.0};
    SkeletonPose p = rest_pose(in.skeleton);
    in.samples = {p};
    in.sample_names = {"rest"};
    auto plan = reduce_rig(in, kit_of(18, true));
    ASSERT_TRUE(plan.ok()) << plan.error().message;
    EXPECT_TRUE(plan->modules.empty());
    EXPECT_DOUBLE_EQ(plan->error_final, plan->error_rigid);
    ASSERT_EQ(plan->device_poses.size(), 1u);
  }
  {
    // Co-located nodes (zero offsets), no skin, a kit without joints.
    Builder b;
    const int root = b.add("root", -1, Vec3::Zero(), 0.0, 0.2);
    const int hub = b.add("hub", root, Vec3::Zero(), 0.0, 0.5);
    b.add("hub2", hub, Vec3::Zero(), 0.0, 0.5);
    b.chain("a", hub, 3, Vec3(0.1, 0, 0), 0.0, 0.5);
    b.chain("b", hub, 3, Vec3(-0.1, 0, 0), 0.0, 0.5);
    const RigInput in = b.with_samples(4, 9);
    for (int joints : {0, 5}) {
      const rig_device::Kit kit = kit_of(joints, true);
      auto plan = reduce_rig(in, kit);
      ASSERT_TRUE(plan.ok()) << plan.error().message;
      expect_consistent(*plan, in, kit);
      EXPECT_LE(plan->error_final, plan->error_rigid);
      if (joints == 0) {
        EXPECT_TRUE(plan->modules.empty());
      }
    }
  }
}

TEST(GreedyJoints, StayWithinTheAllowedNodesAndLowerTheError) {
  const RigInput in = synthetic::humanoid(5, 91);
  auto m = RigModel::create(in);
  ASSERT_TRUE(m.ok());
  std::vector<char> allowed(in.skeleton.size(), 0);
  for (const char* name : {"l_upper_arm", "l_forearm", "spine", "r_thigh"})
    allowed[static_cast<std::size_t>(in.skeleton.find(name))] = 1;
  std::vector<int> driven;
  std::vector<std::vector<Mat3>> solution;
  auto g = place_joints_greedily(*m, {}, driven, solution, allowed, 3, 0.0);
  ASSERT_TRUE(g.ok()) << g.error().message;
  ASSERT_EQ(driven.size(), 3u);
  ASSERT_EQ(g->error_after_joint.size(), 3u);
  double previous = g->error_start;
  for (std::size_t k = 0; k < driven.size(); ++k) {
    EXPECT_TRUE(allowed[static_cast<std::size_t>(driven[k])]);
    EXPECT_LT(g->error_after_joint[k], previous);
    previous = g->error_after_joint[k];
  }
  ASSERT_EQ(solution.size(), in.samples.size());
  for (const auto& s : solution) EXPECT_EQ(s.size(), driven.size());
  EXPECT_FALSE(place_joints_greedily(*m, {}, driven, solution, std::vector<char>(3, 1), 4, 0.0).ok());
}

TEST(BranchingNodes, HumanoidHasHipsAndChest) {
  const RigInput in = synthetic::humanoid(2, 3);
  auto m = RigModel::create(in);
  ASSERT_TRUE(m.ok());
  const auto nodes = find_branching_nodes(*m);
  ASSERT_EQ(nodes.size(), 2u);
  EXPECT_EQ(nodes[0].node, in.skeleton.find("hips"));
  EXPECT_EQ(nodes[0].branch_child.size(), 3u);
  EXPECT_EQ(nodes[1].node, in.skeleton.find("chest"));
  EXPECT_EQ(nodes[1].parent, 0);
  EXPECT_EQ(nodes[0].branch_child[static_cast<std::size_t>(nodes[1].parent_branch)], in.skeleton.find("spine"));
  for (const auto& n : nodes)
    for (const Vec3& d : n.branch_dir) EXPECT_NEAR(d.norm(), 1.0, 1e-12);
  // The spine's chain runs down to the chest, inclusive.
  const std::vector<int> chain = branch_chain(*m, in.skeleton.find("spine"));
  ASSERT_FALSE(chain.empty());
  EXPECT_EQ(chain.back(), in.skeleton.find("chest"));
}

}  // namespace
}  // namespace proprio::rig_plan
