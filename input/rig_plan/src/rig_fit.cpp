#include "proprio/rig_plan/rig_fit.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace proprio::rig_plan {

std::vector<double> node_weights(const RigInput& input) {
  const std::size_t n = input.skeleton.size();
  std::vector<double> w(n, 0.0);
  double total = 0.0;
  for (std::size_t i = 0; i < n && i < input.area_m2.size(); ++i) {
    w[i] = std::isfinite(input.area_m2[i]) && input.area_m2[i] > 0.0 ? input.area_m2[i] : 0.0;
    total += w[i];
  }
  if (total <= 0.0) {
    std::fill(w.begin(), w.end(), n > 0 ? 1.0 / static_cast<double>(n) : 0.0);
    return w;
  }
  for (double& x : w) x /= total;
  return w;
}

Status FitOptions::validate() const {
  if (max_iterations < 1 || max_iterations > 10000)
    return make_error(Errc::invalid_argument, "fit max_iterations must be in [1, 10000]");
  if (!std::isfinite(relative_tolerance) || relative_tolerance < 0.0 || relative_tolerance >= 1.0)
    return make_error(Errc::invalid_argument, "fit relative_tolerance must be in [0, 1)");
  if (!std::isfinite(absolute_tolerance_m2) || absolute_tolerance_m2 < 0.0)
    return make_error(Errc::invalid_argument, "fit absolute_tolerance_m2 must be finite and >= 0");
  if (!std::isfinite(relative_damping) || relative_damping < 0.0 || relative_damping > 1.0)
    return make_error(Errc::invalid_argument, "fit relative_damping must be in [0, 1]");
  return {};
}

std::string FitOptions::describe() const {
  std::ostringstream s;
  s << "Gauss-Newton: at most " << max_iterations << " iterations, stop when |dE| <= |E| * " << relative_tolerance
    << " + " << absolute_tolerance_m2 << " m^2, damping " << relative_damping << " of max diag(D^T D)";
  return s.str();
}

Result<RigModel> RigModel::create(const RigInput& input) {
  if (Status s = input.validate(); !s) return s.error();
  RigModel m;
  const Skeleton& sk = input.skeleton;
  const std::size_t n = sk.size();
  m.parent_ = sk.parent;
  m.children_ = sk.children();
  m.weights_ = node_weights(input);
  m.subtree_weight_below_.assign(n, 0.0);
  for (std::size_t i = n; i-- > 0;) {
    const int p = sk.parent[i];
    if (p >= 0) m.subtree_weight_below_[static_cast<std::size_t>(p)] += m.subtree_weight_below_[i] + m.weights_[i];
  }
  m.t_parent_node_m_ = sk.t_parent_node_m;
  m.R_rest_.resize(n);
  for (std::size_t i = 0; i < n; ++i) m.R_rest_[i] = sk.q_parent_node_rest[i].normalized().toRotationMatrix();
  const std::size_t S = input.samples.size();
  m.R_sample_.assign(S, std::vector<Mat3>(n));
  m.t_root_.resize(S);
  m.targets_.assign(S, std::vector<Vec3>(n));
  std::vector<Pose> T;
  for (std::size_t s = 0; s < S; ++s) {
    const SkeletonPose& pose = input.samples[s];
    for (std::size_t i = 0; i < n; ++i) m.R_sample_[s][i] = pose.q_parent_node[i].normalized().toRotationMatrix();
    m.t_root_[s] = pose.t_world_root_m;
    forward_kinematics(sk, pose, T);
    for (std::size_t i = 0; i < n; ++i) m.targets_[s][i] = T[i].p;
  }
  return m;
}

ReachabilityFitter::ReachabilityFitter(const RigModel& model, FitOptions options)
    : model_(&model), options_(options) {
  const std::size_t n = model.node_count();
  G_world_.resize(n);
  p_world_.resize(n);
  mode_.assign(n, NodeMode::rest);
  driven_slot_.assign(n, -1);
  weights_ = model.weights();
}

Status ReachabilityFitter::set_setup(const FitSetup& setup) {
  const RigModel& m = *model_;
  const std::size_t n = m.node_count();
  std::vector<NodeMode> mode(n, NodeMode::rest);
  std::vector<int> slot(n, -1);
  for (std::size_t k = 0; k < setup.driven.size(); ++k) {
    const int v = setup.driven[k];
    if (v < 0 || static_cast<std::size_t>(v) >= n)
      return make_error(Errc::invalid_argument, "a driven node index is out of range");
    if (m.parent()[static_cast<std::size_t>(v)] < 0)
      return make_error(Errc::invalid_argument, "a root node cannot be driven: the device senses local rotations only");
    if (slot[static_cast<std::size_t>(v)] >= 0)
      return make_error(Errc::invalid_argument, "a node is driven twice");
    slot[static_cast<std::size_t>(v)] = static_cast<int>(k);
    mode[static_cast<std::size_t>(v)] = NodeMode::driven;
  }
  for (int v : setup.follow_sample) {
    if (v < 0 || static_cast<std::size_t>(v) >= n)
      return make_error(Errc::invalid_argument, "a follow-sample node index is out of range");
    if (mode[static_cast<std::size_t>(v)] == NodeMode::rest) mode[static_cast<std::size_t>(v)] = NodeMode::sample;
  }
  for (std::size_t i = 0; i < n; ++i)
    if (m.parent()[i] < 0) mode[i] = NodeMode::sample;
  if (!setup.weights.empty()) {
    if (setup.weights.size() != n) return make_error(Errc::invalid_argument, "fit weights must have one per node");
    for (double w : setup.weights)
      if (!std::isfinite(w) || w < 0.0) return make_error(Errc::invalid_argument, "fit weights must be finite and >= 0");
    weights_ = setup.weights;
  } else {
    weights_ = m.weights();
  }
  driven_ = setup.driven;
  mode_ = std::move(mode);
  driven_slot_ = std::move(slot);
  // Driven strict ancestors of each node: the driven ancestors of its parent,
  // plus the parent itself when driven (parents come first).
  anc_begin_.assign(n + 1, 0);
  anc_slots_.clear();
  std::vector<int> begin(n), count(n);
  for (std::size_t i = 0; i < n; ++i) {
    begin[i] = static_cast<int>(anc_slots_.size());
    const int p = m.parent()[i];
    if (p >= 0) {
      const auto pu = static_cast<std::size_t>(p);
      for (int a = 0; a < count[pu]; ++a) anc_slots_.push_back(anc_slots_[static_cast<std::size_t>(begin[pu] + a)]);
      if (driven_slot_[pu] >= 0) anc_slots_.push_back(driven_slot_[pu]);
    }
    count[i] = static_cast<int>(anc_slots_.size()) - begin[i];
  }
  for (std::size_t i = 0; i < n; ++i) anc_begin_[i] = begin[i];
  anc_begin_[n] = static_cast<int>(anc_slots_.size());
  weighted_nodes_.clear();
  for (std::size_t i = 0; i < n; ++i)
    if (weights_[i] > 0.0 && anc_begin_[i + 1] > anc_begin_[i]) weighted_nodes_.push_back(static_cast<int>(i));
  const auto dim = static_cast<Eigen::Index>(3 * driven_.size());
  JtJ_.resize(dim, dim);
  Jtr_.resize(dim);
  omega_.resize(dim);
  B_.resize(driven_.size());
  R_trial_.resize(driven_.size());
  return {};
}

double ReachabilityFitter::evaluate(int sample, std::span<const Mat3> R_local) {
  const RigModel& m = *model_;
  const std::size_t n = m.node_count();
  const auto& parent = m.parent();
  bool first_root = true;
  double E = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const int iv = static_cast<int>(i);
    const Mat3* R;
    switch (mode_[i]) {
      case NodeMode::driven: R = &R_local[static_cast<std::size_t>(driven_slot_[i])]; break;
      case NodeMode::sample: R = &m.R_parent_node_sample(sample, iv); break;
      default: R = &m.R_parent_node_rest(iv); break;
    }
    const int p = parent[i];
    if (p < 0) {
      p_world_[i] = m.t_parent_node_m(iv);
      if (first_root) p_world_[i] += m.t_world_root_m(sample);
      first_root = false;
      G_world_[i] = *R;
    } else {
      const auto pu = static_cast<std::size_t>(p);
      p_world_[i].noalias() = p_world_[pu] + G_world_[pu] * m.t_parent_node_m(iv);
      G_world_[i].noalias() = G_world_[pu] * *R;
    }
    if (weights_[i] > 0.0) E += weights_[i] * (m.target(sample, iv) - p_world_[i]).squaredNorm();
  }
  current_sample_ = sample;
  return E;
}

double ReachabilityFitter::energy(int sample, std::span<const Mat3> R_local) { return evaluate(sample, R_local); }

void ReachabilityFitter::accumulate_normal_equations() {
  const RigModel& m = *model_;
  JtJ_.setZero();
  Jtr_.setZero();
  for (int d : weighted_nodes_) {
    const auto du = static_cast<std::size_t>(d);
    const double w = weights_[du];
    const Vec3 e = m.target(current_sample_, d) - p_world_[du];  // n - n~
    const int b0 = anc_begin_[du], b1 = anc_begin_[du + 1];
    // D's block for (d, j), up to sqrt(w): [p_d - p_j]x G_j.
    for (int a = b0; a < b1; ++a) {
      const int k = anc_slots_[static_cast<std::size_t>(a)];
      const auto j = static_cast<std::size_t>(driven_[static_cast<std::size_t>(k)]);
      B_[static_cast<std::size_t>(a - b0)].noalias() = skew(p_world_[du] - p_world_[j]) * G_world_[j];
    }
    for (int a = b0; a < b1; ++a) {
      const Mat3& Ba = B_[static_cast<std::size_t>(a - b0)];
      const int ka = anc_slots_[static_cast<std::size_t>(a)];
      Jtr_.segment<3>(3 * ka).noalias() += w * (Ba.transpose() * e);
      for (int c = a; c < b1; ++c) {
        const int kc = anc_slots_[static_cast<std::size_t>(c)];
        const Mat3 blk = w * (Ba.transpose() * B_[static_cast<std::size_t>(c - b0)]);
        JtJ_.block<3, 3>(3 * ka, 3 * kc) += blk;
        if (kc != ka) JtJ_.block<3, 3>(3 * kc, 3 * ka) += blk.transpose();
      }
    }
  }
}

double ReachabilityFitter::fit_sample(int sample, std::span<Mat3> R_local) {
  last_iterations_ = 0;
  double E = evaluate(sample, R_local);
  if (driven_.empty()) return E;
  const std::size_t l = driven_.size();
  for (int it = 0; it < options_.max_iterations; ++it) {
    last_iterations_ = it + 1;
    accumulate_normal_equations();  // at R_local (evaluate left p_world_, G_world_ there)
    const double max_diag = JtJ_.diagonal().maxCoeff();
    if (!(max_diag > 0.0)) break;
    JtJ_.diagonal().array() += options_.relative_damping * max_diag + 1e-300;
    ldlt_.compute(JtJ_);
    // D = sqrt(w) B and r = sqrt(w) (n - n~), so D^T r = sum w B^T (n - n~) = Jtr_.
    omega_ = -ldlt_.solve(Jtr_);
    if (!omega_.allFinite()) break;
    double scale = 1.0;
    double E_new = E;
    bool accepted = false;
    for (int halving = 0; halving < 12; ++halving) {
      for (std::size_t k = 0; k < l; ++k) {
        const Vec3 w = scale * omega_.segment<3>(static_cast<Eigen::Index>(3 * k));
        const double angle = w.norm();
        R_trial_[k] = angle > 0.0 ? Mat3(R_local[k] * Eigen::AngleAxisd(angle, w / angle).toRotationMatrix())
                                  : R_local[k];
      }
      E_new = evaluate(sample, R_trial_);
      if (E_new <= E) {
        accepted = true;
        break;
      }
      scale *= 0.5;
    }
    if (!accepted) {
      evaluate(sample, R_local);  // leave the workspace at the returned pose
      break;
    }
    for (std::size_t k = 0; k < l; ++k) R_local[k] = R_trial_[k];
    const bool done = std::abs(E_new - E) <= std::abs(E_new) * options_.relative_tolerance + options_.absolute_tolerance_m2;
    E = E_new;
    if (done) break;
  }
  return E;
}

std::vector<Mat3> to_matrices(std::span<const Quat> q) {
  std::vector<Mat3> R(q.size());
  for (std::size_t i = 0; i < q.size(); ++i) R[i] = q[i].normalized().toRotationMatrix();
  return R;
}

std::vector<Quat> to_quats(std::span<const Mat3> R) {
  std::vector<Quat> q(R.size());
  for (std::size_t i = 0; i < R.size(); ++i) q[i] = Quat(R[i]).normalized();
  return q;
}

}  // namespace proprio::rig_plan
