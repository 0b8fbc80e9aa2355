#include <gtest/gtest.h>

#include <functional>

#include "proprio/core/random.hpp"
#include "proprio/rig_plan/splitter_ilp.hpp"

namespace proprio::rig_plan {
namespace {

Quat outlet(double azimuth_deg, double tilt_deg) {
  return (Quat(Eigen::AngleAxisd(azimuth_deg * M_PI / 180.0, Vec3::UnitZ())) *
          Quat(Eigen::AngleAxisd(tilt_deg * M_PI / 180.0, Vec3::UnitY())))
      .normalized();
}

rig_device::SplitterKind kind(const std::string& name, std::vector<Quat> outlets) {
  rig_device::SplitterKind k;
  k.name = name;
  k.q_inlet_outlet = std::move(outlets);
  return k;
}

rig_device::Kit kit_with(std::vector<rig_device::SplitterKind> kinds, std::vector<int> counts) {
  rig_device::Kit kit;
  kit.splitter_kinds = std::move(kinds);
  kit.splitter_counts = std::move(counts);
  return kit;
}

Vec3 dir(double azimuth_deg, double tilt_deg) { return outlet(azimuth_deg, tilt_deg) * Vec3::UnitZ(); }

BranchingNode node(int rig_node, std::vector<Vec3> dirs, std::vector<double> gains, int parent = -1, int parent_branch = -1) {
  BranchingNode n;
  n.node = rig_node;
  n.inlet_dir = Vec3::UnitZ();
  for (std::size_t i = 0; i < dirs.size(); ++i) n.branch_child.push_back(rig_node * 10 + static_cast<int>(i) + 1);
  n.branch_dir = std::move(dirs);
  n.branch_gain = std::move(gains);
  n.parent = parent;
  n.parent_branch = parent_branch;
  return n;
}

TEST(Kabsch, RecoversAKnownRotation) {
  const Quat R = so3_exp(Vec3(0.4, -1.1, 0.7));
  std::vector<Vec3> a = {Vec3::UnitX(), Vec3(0.3, 1.0, -0.2).normalized(), Vec3(-0.5, 0.1, 0.9).normalized()};
  std::vector<Vec3> b;
  for (const Vec3& v : a) b.push_back(R * v);
  const Quat got = kabsch(a, b, std::vector<double>(3, 1.0));
  EXPECT_LT(angle_between(got, R), 1e-9);
}

TEST(SplitterCandidates, RejectsMatchesBeyondSixtyDegrees) {
  // A T-shaped node (branches opposite, across the inlet) and a splitter whose
  // two outlets are 10 degrees apart: no orientation lets it follow both.
  const std::vector<BranchingNode> nodes = {node(1, {dir(0, 90), dir(180, 90)}, {1.0, 1.0})};
  const rig_device::Kit kit = kit_with({kind("V", {outlet(0, 5), outlet(180, 5)})}, {1});
  const SplitterIlpOptions options;
  const auto candidates = enumerate_splitter_candidates(nodes, kit, options);
  int singles = 0;
  for (const SplitterCandidate& c : candidates) {
    EXPECT_LE(c.max_error_rad, options.max_gate_error_rad);
    if (c.kind == 0) {
      int matched = 0;
      for (int b : c.outlet_branch) matched += b >= 0 ? 1 : 0;
      EXPECT_EQ(matched, 1) << "a pair match this far off must be rejected";
      ++singles;
    }
  }
  EXPECT_GT(singles, 0);
  // A T splitter matches both, with almost no error.
  const rig_device::Kit tkit = kit_with({kind("T", {outlet(0, 90), outlet(180, 90)})}, {1});
  bool both = false;
  for (const SplitterCandidate& c : enumerate_splitter_candidates(nodes, tkit, options))
    if (c.kind == 0 && c.outlet_branch[0] >= 0 && c.outlet_branch[1] >= 0) {
      both = true;
      EXPECT_LT(c.mean_error_rad, 1e-6);
    }
  EXPECT_TRUE(both);
}

TEST(SplitterCandidates, PhantomsCoverOneBranchEach) {
  const std::vector<BranchingNode> nodes = {node(1, {dir(0, 90), dir(120, 90), dir(240, 90)}, {1.0, 2.0, 3.0})};
  const auto candidates = enumerate_splitter_candidates(nodes, kit_with({}, {}), {});
  ASSERT_EQ(candidates.size(), 3u);
  for (const SplitterCandidate& c : candidates) {
    EXPECT_EQ(c.kind, kPhantomKind);
    ASSERT_EQ(c.outlet_branch.size(), 1u);
    EXPECT_DOUBLE_EQ(c.gain, nodes[0].branch_gain[static_cast<std::size_t>(c.outlet_branch[0])]);
  }
}

// Brute force over every choice (nothing, or one candidate) per node.
double brute_force_best(const std::vector<BranchingNode>& nodes, const std::vector<SplitterCandidate>& cands,
                        const rig_device::Kit& kit, const SplitterIlpOptions& options) {
  std::vector<std::vector<int>> at(nodes.size());
  for (std::size_t i = 0; i < cands.size(); ++i) at[static_cast<std::size_t>(cands[i].branching)].push_back(static_cast<int>(i));
  std::vector<int> chosen;
  double best = 0.0;
  std::function<void(std::size_t)> rec = [&](std::size_t n) {
    if (n == nodes.size()) {
      if (!check_splitter_solution(nodes, cands, kit, options, chosen).ok()) return;
      double g = 0.0;
      for (int i : chosen) g += cands[static_cast<std::size_t>(i)].gain;
      best = std::max(best, g);
      return;
    }
    rec(n + 1);
    for (int i : at[n]) {
      chosen.push_back(i);
      rec(n + 1);
      chosen.pop_back();
    }
  };
  rec(0);
  return best;
}

TEST(SplitterIlp, RespectsTheConstraintsAndMatchesBruteForce) {
  const rig_device::Kit kit = kit_with({kind("T2", {outlet(0, 90), outlet(180, 90)}),
                                        kind("Y3", {outlet(0, 45), outlet(120, 45), outlet(240, 45)})},
                                       {1, 1});
  Rng rng(17);
  for (int trial = 0; trial < 12; ++trial) {
    // A random hierarchy of 4-5 branching nodes with 2-3 branches each.
    std::vector<BranchingNode> nodes;
    const int count = 4 + static_cast<int>(rng.below(2));
    for (int n = 0; n < count; ++n) {
      const int branches = 2 + static_cast<int>(rng.below(2));
      std::vector<Vec3> dirs;
      std::vector<double> gains;
      for (int b = 0; b < branches; ++b) {
        dirs.push_back(dir(rng.uniform(0, 360), rng.uniform(20, 110)));
        gains.push_back(rng.uniform(0.0, 1.0));
      }
      int parent = -1, parent_branch = -1;
      if (n > 0) {
        parent = static_cast<int>(rng.below(static_cast<std::uint64_t>(n)));
        parent_branch = static_cast<int>(rng.below(nodes[static_cast<std::size_t>(parent)].branch_child.size()));
      }
      nodes.push_back(node(n + 1, dirs, gains, parent, parent_branch));
    }
    SplitterIlpOptions options;
    options.max_phantoms = static_cast<int>(rng.below(3));
    const auto cands = enumerate_splitter_candidates(nodes, kit, options);
    auto sol = solve_splitter_ilp(nodes, cands, kit, options);
    ASSERT_TRUE(sol.ok()) << sol.error().message;
    EXPECT_TRUE(check_splitter_solution(nodes, cands, kit, options, sol->chosen).ok()) << sol->note;
    EXPECT_TRUE(sol->proven_optimal) << sol->note;
    EXPECT_NEAR(sol->gain, brute_force_best(nodes, cands, kit, options), 1e-4) << "trial " << trial;
  }
}

TEST(SplitterIlp, HierarchyKeepsChildrenBelowCoveredBranchesOnly) {
  // The child node hangs off branch 1 of the root node, which is worth little;
  // without phantoms and with one splitter, covering the child needs the root
  // to cover branch 1 first.
  const rig_device::Kit kit = kit_with({kind("T2", {outlet(0, 90), outlet(180, 90)})}, {1});
  const std::vector<BranchingNode> nodes = {node(1, {dir(0, 90), dir(180, 90)}, {0.1, 0.1}),
                                            node(2, {dir(0, 90), dir(180, 90)}, {5.0, 5.0}, 0, 1)};
  SplitterIlpOptions options;
  options.max_phantoms = 0;
  const auto cands = enumerate_splitter_candidates(nodes, kit, options);
  auto sol = solve_splitter_ilp(nodes, cands, kit, options);
  ASSERT_TRUE(sol.ok());
  ASSERT_EQ(sol->chosen.size(), 1u);
  EXPECT_EQ(cands[static_cast<std::size_t>(sol->chosen[0])].branching, 0);
  // With one phantom, the phantom opens branch 1 and the splitter goes below.
  options.max_phantoms = 1;
  const auto cands2 = enumerate_splitter_candidates(nodes, kit, options);
  auto sol2 = solve_splitter_ilp(nodes, cands2, kit, options);
  ASSERT_TRUE(sol2.ok());
  ASSERT_EQ(sol2->chosen.size(), 2u);
  EXPECT_TRUE(check_splitter_solution(nodes, cands2, kit, options, sol2->chosen).ok());
  EXPECT_NEAR(sol2->gain, 10.1, 1e-9);
}

TEST(SplitterIlp, AmongEqualGainsPrefersTheLowerRotationalError) {
  // Two kinds cover the same two branches; one fits the geometry better.
  const std::vector<BranchingNode> nodes = {node(1, {dir(0, 90), dir(180, 90)}, {1.0, 1.0})};
  const rig_device::Kit kit = kit_with({kind("rough", {outlet(0, 60), outlet(180, 60)}),
                                        kind("exact", {outlet(0, 90), outlet(180, 90)})},
                                       {1, 1});
  SplitterIlpOptions options;
  const auto cands = enumerate_splitter_candidates(nodes, kit, options);
  auto sol = solve_splitter_ilp(nodes, cands, kit, options);
  ASSERT_TRUE(sol.ok());
  ASSERT_EQ(sol->chosen.size(), 1u);
  EXPECT_EQ(cands[static_cast<std::size_t>(sol->chosen[0])].kind, 1);
  EXPECT_NEAR(sol->gain, 2.0, 1e-12);
}

TEST(SplitterIlp, WideBranchingStaysBounded) {
  // 40 branches (far more than any splitter has outlets): only the
  // max_branches best are matched, and the answer still holds (3.3)-(3.5).
  std::vector<Vec3> dirs;
  std::vector<double> gains;
  for (int b = 0; b < 40; ++b) {
    dirs.push_back(dir(9.0 * b, 30.0 + b));
    gains.push_back(0.01 * (b + 1));
  }
  const std::vector<BranchingNode> nodes = {node(1, dirs, gains)};
  const rig_device::Kit kit = kit_with({kind("Y3", {outlet(0, 45), outlet(120, 45), outlet(240, 45)})}, {1});
  SplitterIlpOptions options;
  options.max_branches = 6;
  const auto cands = enumerate_splitter_candidates(nodes, kit, options);
  for (const SplitterCandidate& c : cands)
    for (int b : c.outlet_branch)
      if (b >= 0 && c.kind == 0) {
        EXPECT_GE(b, 40 - 6) << "only the best branches are matched";
      }
  auto sol = solve_splitter_ilp(nodes, cands, kit, options);
  ASSERT_TRUE(sol.ok());
  EXPECT_TRUE(check_splitter_solution(nodes, cands, kit, options, sol->chosen).ok());
  EXPECT_GT(sol->gain, 0.4);
}

TEST(SplitterIlp, RejectsInconsistentInput) {
  std::vector<BranchingNode> nodes = {node(1, {dir(0, 90), dir(180, 90)}, {1.0, 1.0})};
  nodes[0].branch_gain.pop_back();
  EXPECT_FALSE(solve_splitter_ilp(nodes, {}, kit_with({}, {}), {}).ok());
  SplitterIlpOptions bad;
  bad.time_limit_s = 0.0;
  EXPECT_FALSE(bad.validate().ok());
}

}  // namespace
}  // namespace proprio::rig_plan
