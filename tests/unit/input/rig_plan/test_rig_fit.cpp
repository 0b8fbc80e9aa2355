#include <gtest/gtest.h>

#include <numeric>

#include "proprio/rig_plan/rig_fit.hpp"
#include "unit/input/rig_plan/synthetic_rigs.hpp"

namespace proprio::rig_plan {
namespace {

std::vector<int> all_drivable(const RigModel& m) {
  std::vector<int> d;
  for (std::size_t v = 0; v < m.node_count(); ++v)
    if (m.can_drive(static_cast<int>(v))) d.push_back(static_cast<int>(v));
  return d;
}

std::vector<Mat3> rest_of(const RigModel& m, const std::vector<int>& driven) {
  std::vector<Mat3> R;
  for (int v : driven) R.push_back(m.R_parent_node_rest(v));
  return R;
}

TEST(NodeWeights, NormalisedNonNegativeAndUniformWithoutSkin) {
  RigInput in = synthetic::humanoid(2, 1);
  const std::vector<double> w = node_weights(in);
  ASSERT_EQ(w.size(), in.skeleton.size());
  EXPECT_NEAR(std::accumulate(w.begin(), w.end(), 0.0), 1.0, 1e-12);
  for (double x : w) EXPECT_GE(x, 0.0);
  std::fill(in.area_m2.begin(), in.area_m2.end(), 0.0);
  const std::vector<double> u = node_weights(in);
  for (double x : u) EXPECT_NEAR(x, 1.0 / static_cast<double>(in.skeleton.size()), 1e-15);
}

TEST(NodeWeights, ProportionalToEachNodesOwnArea) {
  // root -> a -> {b, c}: each node's own area, normalised; subtrees add nothing.
  RigInput in;
  const int root = in.skeleton.add("root", -1, Vec3::Zero());
  const int a = in.skeleton.add("a", root, Vec3(0, 1, 0));
  const int b = in.skeleton.add("b", a, Vec3(1, 0, 0));
  const int c = in.skeleton.add("c", a, Vec3(-1, 0, 0));
  in.area_m2 = {0.0, 0.4, 0.1, 0.3};
  const std::vector<double> w = node_weights(in);
  EXPECT_DOUBLE_EQ(w[static_cast<std::size_t>(root)], 0.0);
  EXPECT_NEAR(w[static_cast<std::size_t>(a)], 0.5, 1e-15);
  EXPECT_NEAR(w[static_cast<std::size_t>(b)], 0.125, 1e-15);
  EXPECT_NEAR(w[static_cast<std::size_t>(c)], 0.375, 1e-15);
}

TEST(RigModel, TargetsAreTheSamplesForwardKinematics) {
  const RigInput in = synthetic::humanoid(3, 2);
  auto m = RigModel::create(in);
  ASSERT_TRUE(m.ok()) << m.error().message;
  std::vector<Pose> T;
  for (int s = 0; s < 3; ++s) {
    forward_kinematics(in.skeleton, in.samples[static_cast<std::size_t>(s)], T);
    for (std::size_t v = 0; v < in.skeleton.size(); ++v)
      EXPECT_LT((m->target(s, static_cast<int>(v)) - T[v].p).norm(), 1e-12);
  }
}

TEST(RigModel, RejectsInvalidInput) {
  RigInput in = synthetic::chain(3, 2, 1);
  in.area_m2.push_back(1.0);
  EXPECT_FALSE(RigModel::create(in).ok());
}

TEST(ReachabilityFitter, EnergyMatchesAnIndependentForwardKinematics) {
  const RigInput in = synthetic::humanoid(2, 7);
  auto m = RigModel::create(in);
  ASSERT_TRUE(m.ok());
  ReachabilityFitter f(*m);
  const int upper_arm = in.skeleton.find("l_upper_arm");
  const int shin = in.skeleton.find("r_shin");
  ASSERT_TRUE(f.set_setup({{upper_arm, shin}, {}, {}}).ok());
  std::vector<Mat3> R = {so3_exp(Vec3(0.3, -0.2, 0.1)).toRotationMatrix(), so3_exp(Vec3(0.0, 0.5, 0.0)).toRotationMatrix()};
  // The same pose built by hand: rest rotations, the sample's root, the two driven nodes.
  SkeletonPose pose = rest_pose(in.skeleton);
  pose.q_parent_node[0] = in.samples[1].q_parent_node[0];
  pose.t_world_root_m = in.samples[1].t_world_root_m;
  pose.q_parent_node[static_cast<std::size_t>(upper_arm)] = Quat(R[0]);
  pose.q_parent_node[static_cast<std::size_t>(shin)] = Quat(R[1]);
  std::vector<Pose> T;
  forward_kinematics(in.skeleton, pose, T);
  const std::vector<double> w = node_weights(in);
  double expected = 0.0;
  for (std::size_t v = 0; v < T.size(); ++v) expected += w[v] * (m->target(1, static_cast<int>(v)) - T[v].p).squaredNorm();
  EXPECT_NEAR(f.energy(1, R), expected, 1e-12);
  // Unassigned nodes keep their rest rotation and move rigidly with their parent.
  for (std::size_t v = 0; v < T.size(); ++v) EXPECT_LT((f.positions()[v] - T[v].p).norm(), 1e-12);
}

TEST(ReachabilityFitter, ConvergesToZeroWhenEveryMovingBoneHasAJoint) {
  for (const RigInput& in : {synthetic::chain(6, 4, 11), synthetic::humanoid(6, 12), synthetic::star(4, 3, 4, 13)}) {
    auto m = RigModel::create(in);
    ASSERT_TRUE(m.ok());
    ReachabilityFitter f(*m);
    const std::vector<int> driven = all_drivable(*m);
    ASSERT_TRUE(f.set_setup({driven, {}, {}}).ok());
    for (int s = 0; s < static_cast<int>(in.samples.size()); ++s) {
      std::vector<Mat3> R = rest_of(*m, driven);
      const double E0 = f.energy(s, R);
      ASSERT_GT(E0, 1e-6) << in.name;
      const double E = f.fit_sample(s, R);
      EXPECT_LT(E, 1e-12 * E0 + 1e-16) << in.name << " sample " << s << " from rest: " << E0 << " -> " << E;
    }
  }
}

TEST(ReachabilityFitter, NeverEndsAboveItsStart) {
  const RigInput in = synthetic::humanoid(8, 21);
  auto m = RigModel::create(in);
  ASSERT_TRUE(m.ok());
  ReachabilityFitter f(*m);
  const std::vector<int> driven = {in.skeleton.find("spine1"), in.skeleton.find("l_forearm"),
                                   in.skeleton.find("r_thigh")};
  ASSERT_TRUE(f.set_setup({driven, {}, {}}).ok());
  Rng rng(5);
  for (int s = 0; s < 8; ++s) {
    std::vector<Mat3> R;
    for (std::size_t k = 0; k < driven.size(); ++k)
      R.push_back(so3_exp(Vec3(rng.normal(), rng.normal(), rng.normal())).toRotationMatrix());
    const double E0 = f.energy(s, R);
    const double E = f.fit_sample(s, R);
    EXPECT_LE(E, E0);
    // The returned rotations are the optimum's and still rotations.
    EXPECT_NEAR(f.energy(s, R), E, 1e-15);
    for (const Mat3& r : R) EXPECT_LT((r.transpose() * r - Mat3::Identity()).norm(), 1e-9);
  }
}

TEST(ReachabilityFitter, AFittedJointBeatsARigidOne) {
  const RigInput in = synthetic::chain(5, 6, 3);
  auto m = RigModel::create(in);
  ASSERT_TRUE(m.ok());
  ReachabilityFitter rigid(*m), one(*m);
  ASSERT_TRUE(rigid.set_setup({}).ok());
  ASSERT_TRUE(one.set_setup({{1}, {}, {}}).ok());
  for (int s = 0; s < 6; ++s) {
    std::vector<Mat3> R = {m->R_parent_node_sample(s, 1)};
    EXPECT_LT(one.fit_sample(s, R), rigid.energy(s, {}));
  }
}

TEST(ReachabilityFitter, RejectsRootsDuplicatesAndBadWeights) {
  const RigInput in = synthetic::chain(3, 1, 1);
  auto m = RigModel::create(in);
  ASSERT_TRUE(m.ok());
  ReachabilityFitter f(*m);
  EXPECT_FALSE(f.set_setup({{0}, {}, {}}).ok());
  EXPECT_FALSE(f.set_setup({{1, 1}, {}, {}}).ok());
  EXPECT_FALSE(f.set_setup({{99}, {}, {}}).ok());
  EXPECT_FALSE(f.set_setup({{1}, {}, {1.0}}).ok());
  EXPECT_TRUE(f.set_setup({{1, 2}, {}, {}}).ok());
}

TEST(FitOptions, ValidateAndDescribe) {
  FitOptions o;
  EXPECT_TRUE(o.validate().ok());
  EXPECT_FALSE(o.describe().empty());
  o.max_iterations = 0;
  EXPECT_FALSE(o.validate().ok());
  o = FitOptions{};
  o.relative_tolerance = -1.0;
  EXPECT_FALSE(o.validate().ok());
}

}  // namespace
}  // namespace proprio::rig_plan
