#pragma once
// The reachability fit of App. A.2: for a candidate assignment D (the rig
// nodes that get a device joint), the device pose that brings the rig's nodes
// closest to a sample pose, by Gauss-Newton on the joints' local rotations.
//
//   E_i = sum_b w_b |n_b - n~_b(R)|^2                           (A.2, eq. 3.1)
//   R_j <- R_j exp(J(omega_j))                                 (A.5, A.6)
//   r = sqrt(W) (n - n~(R)),  D = dr/domega,  omega = -(D^T D)^-1 D^T r   (A.7-A.9;
//       the thesis prints D where D^T belongs)
//   stop when |E^{k+1} - E^k| <= |E^{k+1}| rel + abs            (A.10)
//
// Frames: positions are the rig nodes' origins in the world (the forward
// kinematics of core/skeleton.hpp). Roots always take the sample's rotation
// and root translation: the device senses local rotations only, the
// character's global placement is controlled elsewhere (thesis §3.5). Nodes
// without a joint keep their rest local rotation and move rigidly with their
// parent (A.2: "all the unassigned rig nodes inherit the rotation of their
// parent").
//
// The Jacobian is analytic: perturbing driven node j's local rotation by
// exp(omega) moves every descendant d by -[p_d - p_j]x G_j omega, with G_j the
// world rotation of j's frame. A tiny Levenberg term keeps D^T D invertible
// when a joint's twist moves nothing (a bone whose children lie on its axis),
// and a step that raises the energy is halved, so a fit never ends above the
// energy it started from (the greedy error curve relies on this).
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Cholesky>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/rig_plan/plan.hpp"

namespace proprio::rig_plan {

// The diagonal of W in eq. 3.1, one per node, summing to 1: w_b =
// area_b / sum(area), as the thesis words it ("proportional to the surface
// area which it directly controls"). The input's area_m2 is already the area
// each node controls directly (the skin binds each surface patch to one node;
// subtree areas are not in it), so each part of the surface counts once.
// The area is scored at the node's origin, the point the fit compares.
// (Splitting a bone's area between its origin and its children, which sees
// the bone's own rotation too, changed the measured error curves by a few
// per cent either way; the thesis's reading was kept.) With no area at all
// (a rig without skin), every node weighs the same. Normalising makes E a
// weighted mean squared distance (m^2) per sample, comparable between
// characters.
std::vector<double> node_weights(const RigInput& input);

struct FitOptions {
  int max_iterations = 50;
  // A.10. The thesis's 1e-6 absolute term is in its own (unstated) units; with
  // normalised weights E is in m^2 and a character ~1 m tall starts near 1e-2,
  // so the absolute term here is far smaller.
  double relative_tolerance = 1e-6;
  double absolute_tolerance_m2 = 1e-14;
  // Levenberg term relative to the largest diagonal entry of D^T D.
  double relative_damping = 1e-9;
  Status validate() const;
  std::string describe() const;
};

// Everything a fit reads that does not change between candidate assignments:
// the skeleton as matrices, the samples' rotations and node positions (the
// targets n of A.8) and W. Shared read-only between fitters (and threads).
class RigModel {
 public:
  // Validates the input (RigInput::validate).
  static Result<RigModel> create(const RigInput& input);

  std::size_t node_count() const { return parent_.size(); }
  std::size_t sample_count() const { return targets_.size(); }
  const std::vector<int>& parent() const { return parent_; }
  const std::vector<std::vector<int>>& children() const { return children_; }
  const std::vector<double>& weights() const { return weights_; }
  const Vec3& t_parent_node_m(int node) const { return t_parent_node_m_[static_cast<std::size_t>(node)]; }
  const Mat3& R_parent_node_rest(int node) const { return R_rest_[static_cast<std::size_t>(node)]; }
  const Mat3& R_parent_node_sample(int sample, int node) const {
    return R_sample_[static_cast<std::size_t>(sample)][static_cast<std::size_t>(node)];
  }
  const Vec3& t_world_root_m(int sample) const { return t_root_[static_cast<std::size_t>(sample)]; }
  // n_b of A.8: node positions in sample pose i.
  const Vec3& target(int sample, int node) const {
    return targets_[static_cast<std::size_t>(sample)][static_cast<std::size_t>(node)];
  }
  // True when some node strictly below `node` has weight: only then can a
  // joint on `node` change the energy.
  bool moves_weight(int node) const { return subtree_weight_below_[static_cast<std::size_t>(node)] > 0.0; }
  double subtree_weight_below(int node) const { return subtree_weight_below_[static_cast<std::size_t>(node)]; }
  // Nodes a joint may drive: not a root, and moving some weight.
  bool can_drive(int node) const {
    return parent_[static_cast<std::size_t>(node)] >= 0 && moves_weight(node);
  }

 private:
  std::vector<int> parent_;
  std::vector<std::vector<int>> children_;
  std::vector<double> weights_;
  std::vector<double> subtree_weight_below_;
  std::vector<Vec3> t_parent_node_m_;
  std::vector<Mat3> R_rest_;
  std::vector<std::vector<Mat3>> R_sample_;
  std::vector<Vec3> t_root_;
  std::vector<std::vector<Vec3>> targets_;
};

// How a node's local rotation is set during a fit.
enum class NodeMode : std::uint8_t { rest, sample, driven };

// One candidate assignment: the driven nodes (distinct, not roots). By
// default every other node is rigid (rest); `follow_sample` lists nodes that
// take the sample's rotation instead (the splitter gains fix a branching
// node's frame to the sample's). `weights` (empty: the model's) lets a fit
// score part of the rig only.
struct FitSetup {
  std::vector<int> driven;
  std::vector<int> follow_sample;
  std::vector<double> weights;
};

// Gauss-Newton fitter with its own workspace: no allocation per iteration.
// One per thread.
class ReachabilityFitter {
 public:
  explicit ReachabilityFitter(const RigModel& model, FitOptions options = {});

  // Checks the setup against the model and precomputes which driven nodes
  // move each node.
  Status set_setup(const FitSetup& setup);
  const std::vector<int>& driven() const { return driven_; }

  // Fits sample pose `sample`. R_local holds one local rotation per driven
  // node: the start on entry (A.2 starts from the sample's rotations; the
  // caller chooses), the optimum on return. Returns E_i.
  double fit_sample(int sample, std::span<Mat3> R_local);
  // E_i for the given local rotations, no fitting.
  double energy(int sample, std::span<const Mat3> R_local);
  // Iterations the last fit_sample took.
  int last_iterations() const { return last_iterations_; }
  // World node positions of the last energy evaluation (for tests and plots).
  const std::vector<Vec3>& positions() const { return p_world_; }

 private:
  double evaluate(int sample, std::span<const Mat3> R_local);
  void accumulate_normal_equations();

  const RigModel* model_;
  FitOptions options_;
  std::vector<int> driven_;
  std::vector<NodeMode> mode_;
  std::vector<int> driven_slot_;      // node -> index into driven_, -1
  std::vector<double> weights_;
  // Per node, the driven strict ancestors (slots), flattened.
  std::vector<int> anc_begin_;
  std::vector<int> anc_slots_;
  std::vector<int> weighted_nodes_;
  int current_sample_ = 0;
  // Workspace.
  std::vector<Mat3> G_world_;
  std::vector<Vec3> p_world_;
  std::vector<Mat3> B_;
  std::vector<Mat3> R_trial_;
  Eigen::MatrixXd JtJ_;
  Eigen::VectorXd Jtr_;
  Eigen::VectorXd omega_;
  Eigen::LDLT<Eigen::MatrixXd> ldlt_;
  int last_iterations_ = 0;
};

// Convenience for callers holding quaternions.
std::vector<Mat3> to_matrices(std::span<const Quat> q);
std::vector<Quat> to_quats(std::span<const Mat3> R);

}  // namespace proprio::rig_plan
