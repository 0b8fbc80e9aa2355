#pragma once
// Splitter placement (thesis §3.2.2, eqs. 3.2-3.5): which splitter kind sits
// on which branching node of the rig, and which of its outlets follows which
// branch, as an integer linear program solved with COIN-OR CBC.
//
//   max c^T x                                                   (3.2)
//   sum_{i in A(s)} x_i <= count(s)      per splitter kind       (3.3, grouped by kind)
//   sum_{i in A(n)} x_i <= 1             per branching node      (3.4)
//   sum_{i in A(n_c)} x_i <= sum_{k in A(n_p, m)} x_k            (3.5)
//       n_c's nearest branching ancestor is n_p, reached through n_p's branch m
//
// A candidate is a (branching node, kind, outlet -> branch map). Its gain is
// the sum of the gains of the branches it covers (each branch's gain comes
// from the reachability fit; see rig_reduction.cpp). Outlet maps whose best
// (Kabsch) orientation leaves any matched gate, inlet included, more than 60
// degrees off are rejected. Phantom splitters of valence 1 (kind -1) stand
// for a joint that carries on into one branch without a splitter; they have
// no geometry. Among equal gains the lowest mean rotational error wins: the
// objective carries a tiny penalty per radian of mean error.
#include <cmath>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/rig_device/kit.hpp"

namespace proprio::rig_plan {

// A rig node with two or more branches that move weight, as the ILP sees it.
// Directions are unit vectors in the node's own (rest) frame, or zero where
// undefined (a root has no inlet; a branch whose nodes all sit on the node).
struct BranchingNode {
  int node = -1;                      // rig node index
  Vec3 inlet_dir = Vec3::Zero();      // direction of travel into the node
  std::vector<int> branch_child;      // rig child starting each branch
  std::vector<Vec3> branch_dir;       // from the node towards each branch
  std::vector<double> branch_gain;    // >= 0 per branch
  int parent = -1;                    // nearest branching ancestor (index in the list), -1 none
  int parent_branch = -1;             // the parent's branch that leads here
};

inline constexpr int kPhantomKind = -1;

struct SplitterCandidate {
  int branching = -1;               // index into the BranchingNode list
  int kind = kPhantomKind;          // index into Kit::splitter_kinds, or kPhantomKind
  std::vector<int> outlet_branch;   // per outlet: branch index, or -1 when the outlet stays free
  Quat q_node_splitter = Quat::Identity();  // the splitter's inlet frame (shaft +z) in the node's frame
  double gain = 0.0;
  double mean_error_rad = 0.0;      // over the matched outlets
  double max_error_rad = 0.0;       // over the matched gates, inlet included
  bool covers(int branch) const;
};

struct SplitterIlpOptions {
  double max_gate_error_rad = 60.0 * M_PI / 180.0;  // the thesis's rejection
  double time_limit_s = 10.0;
  int max_phantoms = -1;            // -1: no limit besides one per branching node
  // Bounds the enumeration on rigs with very wide branching (a hand with many
  // fingers and an 8-outlet splitter): only the `max_branches` branches with
  // the largest gains are matched to outlets.
  int max_branches = 10;
  // Outlet maps scored per (node, kind) and over the whole rig (each is a
  // 3x3 SVD, about a microsecond): bounds hostile rigs with hundreds of
  // wide branchings. Real rigs stay far below both.
  std::size_t max_maps_per_pair = 200000;
  std::size_t max_maps_total = 4000000;
  Status validate() const;
  std::string describe() const;
};

// R minimising sum_i w_i |R a_i - b_i|^2 (Kabsch 1976), proper (det +1).
// Pairs with zero a or b are ignored; with fewer than two independent pairs
// the rotation is one of the optima.
Quat kabsch(std::span<const Vec3> a, std::span<const Vec3> b, std::span<const double> w);

// Every (branching node, kind, outlet map) that passes the angular filter,
// keeping per (node, kind, set of covered branches) only the map with the
// lowest mean error; plus one phantom per branch. Kinds with count 0 are
// skipped.
std::vector<SplitterCandidate> enumerate_splitter_candidates(const std::vector<BranchingNode>& nodes,
                                                             const rig_device::Kit& kit,
                                                             const SplitterIlpOptions& options);

struct SplitterSolution {
  std::vector<int> chosen;          // candidate indices, at most one per branching node
  double gain = 0.0;
  bool proven_optimal = false;
  std::string note;                 // how it was solved (CBC, or the greedy fallback and why)
};

// Solves (3.2)-(3.5) with CBC (logging off, time bounded). When CBC fails or
// finds nothing, a greedy feasible assignment is returned instead (say so in
// `note`); errors only for inconsistent input.
Result<SplitterSolution> solve_splitter_ilp(const std::vector<BranchingNode>& nodes,
                                            const std::vector<SplitterCandidate>& candidates,
                                            const rig_device::Kit& kit, const SplitterIlpOptions& options);

// (3.3)-(3.5) for a set of chosen candidates; the message names the broken constraint.
Status check_splitter_solution(const std::vector<BranchingNode>& nodes,
                               const std::vector<SplitterCandidate>& candidates, const rig_device::Kit& kit,
                               const SplitterIlpOptions& options, std::span<const int> chosen);

}  // namespace proprio::rig_plan
