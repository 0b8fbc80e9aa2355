#pragma once
// Rig reduction (thesis §3.2.2): which modules of a kit go where on a
// character's rig. Two phases:
//  1. joints: greedily, each remaining joint goes to the bone whose fit
//     (rig_fit.hpp, App. A.2) lowers the pose error E (eq. 3.1) most. The
//     first pass ignores branching (any bone that moves weight may take a
//     joint); its error curve is Plan::error_after_joint (Fig. 3.7).
//  2. splitters: the ILP of splitter_ilp.hpp puts splitters (and phantom
//     splitters, a joint carrying on into one branch) on branching nodes.
// Then, as the thesis repeats the phases "until there are no more joints or
// splitters left": joints in branches no splitter reaches are removed and
// the freed joints go, greedily again, to bones the splitters reach, until
// nothing changes. The splitter gains below do not depend on the joints, so
// the ILP is solved once. Splitters that end up feeding fewer than two
// joints are left out of the device (a joint carries on alone, as a phantom).
// The result is a device tree (parents first) with the rest settings that
// make the device look like the rig at rest, and the fitted device poses.
//
// Branch gains for the ILP (c of eq. 3.2): per branching node n and branch
// starting at child c, the drop of E over c's subtree when the chain from c
// down to the next branching node (inclusive) turns from rigid into joints,
// with n's frame held at the sample's. Branches add up because, with n's
// frame fixed, they do not interact.
#include <functional>
#include <string>

#include "proprio/core/result.hpp"
#include "proprio/rig_device/kit.hpp"
#include "proprio/rig_plan/plan.hpp"
#include "proprio/rig_plan/rig_fit.hpp"
#include "proprio/rig_plan/splitter_ilp.hpp"

namespace proprio::rig_plan {

struct ReductionOptions {
  int max_joints = -1;        // -1: every joint of the kit; otherwise min(this, kit's)
  int max_iterations = 4;     // remove/refill alternations after the splitters
  bool use_splitters = true;  // false: joints only, on one chain of phantoms
  // A joint is only placed while it lowers E by more than this fraction of
  // the rigid error.
  double min_relative_gain = 1e-9;
  // Re-centre the rest settings of joints that would work near or past their
  // stops (joint_ranges.hpp); off: the device copies the rig at rest exactly.
  bool center_joint_ranges = true;
  FitOptions fit;
  SplitterIlpOptions splitters;
  Status validate() const;
  std::string describe() const;
};

struct ReductionProgress {
  std::string phase;          // "joints", "splitters", "final fit"
  int iteration = 0;          // alternation, from 1
  int joints_placed = 0;
  int joints_available = 0;
  double error = 0.0;         // E of the current assignment (m^2, eq. 3.1 over the samples)
  int node = -1;              // "joints": the rig node the last joint went to
};
using ProgressCallback = std::function<void(const ReductionProgress&)>;

// Validates the input, the kit and the options; errors name what to fix.
// Joints never drive a root (the device senses local rotations only). Cost
// grows with bones x samples x depth per candidate fit: about 1 s for 100
// bones and 12 samples on one core, 15 s for a 400-node deep tree.
Result<Plan> reduce_rig(const RigInput& input, const rig_device::Kit& kit, const ReductionOptions& options = {},
                        const ProgressCallback& progress = {});

// Exposed for tests and tools.

// The branching nodes of the rig (two or more children whose subtrees move
// weight, see RigModel::moves_weight), parents first, with directions and
// hierarchy filled in; gains left at zero.
std::vector<BranchingNode> find_branching_nodes(const RigModel& model);

// The chain of a branch: c, its only weight-moving child, ... down to and
// including the next branching node or the last node that moves weight.
std::vector<int> branch_chain(const RigModel& model, int child);

// Greedy joint placement (phase 1) from `driven` (kept), over `allowed`
// nodes (empty: every drivable node), until `joint_budget` joints are driven
// or no joint lowers E. Returns the energies after each added joint; updates
// `driven` and `solution` ([sample][k], local rotations of driven[k]).
struct GreedyResult {
  double error_start = 0.0;
  std::vector<double> error_after_joint;
};
Result<GreedyResult> place_joints_greedily(const RigModel& model, const FitOptions& fit, std::vector<int>& driven,
                                           std::vector<std::vector<Mat3>>& solution, const std::vector<char>& allowed,
                                           int joint_budget, double min_relative_gain,
                                           const std::function<void(int, double)>& on_joint = {});

}  // namespace proprio::rig_plan
