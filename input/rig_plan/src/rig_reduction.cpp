#include "proprio/rig_plan/rig_reduction.hpp"
#include "proprio/rig_plan/joint_ranges.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace proprio::rig_plan {

namespace reduction_detail {

// Nodes closer than this to a node are "on" it: no direction can be read.
constexpr double kOnNodeM = 1e-3;

Quat z_to(const Vec3& d) {
  if (d.squaredNorm() < 0.25) return Quat::Identity();
  return Quat::FromTwoVectors(Vec3::UnitZ(), d.normalized()).normalized();
}

struct RestFrames {
  std::vector<Mat3> R_world;
  std::vector<Vec3> p_world;
};

RestFrames rest_frames(const RigModel& m) {
  RestFrames f;
  const std::size_t n = m.node_count();
  f.R_world.resize(n);
  f.p_world.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const int iv = static_cast<int>(i);
    const int p = m.parent()[i];
    if (p < 0) {
      f.R_world[i] = m.R_parent_node_rest(iv);
      f.p_world[i] = m.t_parent_node_m(iv);
    } else {
      const auto pu = static_cast<std::size_t>(p);
      f.p_world[i] = f.p_world[pu] + f.R_world[pu] * m.t_parent_node_m(iv);
      f.R_world[i] = f.R_world[pu] * m.R_parent_node_rest(iv);
    }
  }
  return f;
}

// The child whose subtree carries the most weight (ties: the first).
int heaviest_child(const RigModel& m, int v) {
  int best = -1;
  double best_w = -1.0;
  for (int c : m.children()[static_cast<std::size_t>(v)]) {
    const double w = m.subtree_weight_below(c) + m.weights()[static_cast<std::size_t>(c)];
    if (w > best_w) {
      best_w = w;
      best = c;
    }
  }
  return best;
}

// Direction, in v's rest frame, from v to the first node at least kOnNodeM
// away down the chain that starts at `start` (following the heaviest child).
Vec3 direction_down(const RigModel& m, const RestFrames& f, int v, int start) {
  const auto vu = static_cast<std::size_t>(v);
  for (int u = start; u >= 0; u = heaviest_child(m, u)) {
    const Vec3 d = f.p_world[static_cast<std::size_t>(u)] - f.p_world[vu];
    if (d.norm() >= kOnNodeM) return (f.R_world[vu].transpose() * d).normalized();
  }
  return Vec3::Zero();
}

// Direction of travel into v, in v's rest frame.
Vec3 direction_in(const RigModel& m, const RestFrames& f, int v) {
  const auto vu = static_cast<std::size_t>(v);
  for (int a = m.parent()[vu]; a >= 0; a = m.parent()[static_cast<std::size_t>(a)]) {
    const Vec3 d = f.p_world[vu] - f.p_world[static_cast<std::size_t>(a)];
    if (d.norm() >= kOnNodeM) return (f.R_world[vu].transpose() * d).normalized();
  }
  return Vec3::Zero();
}

// Fits every sample for `driven`, each from the best of: the warm start
// (solution for driven[0..warm_k), rest for the others), the warm start with
// the new nodes at the sample's rotations, and all sample rotations (A.2).
// Starting no higher than the warm start keeps the greedy curve monotone.
// Stops early once the running sum exceeds `abort_above`; returns +inf then.
double fit_all(ReachabilityFitter& fitter, const RigModel& m, const std::vector<int>& driven,
               const std::vector<std::vector<Mat3>>& warm, std::vector<std::vector<Mat3>>& out,
               double abort_above = std::numeric_limits<double>::infinity()) {
  const std::size_t S = m.sample_count();
  const std::size_t l = driven.size();
  out.resize(S);
  std::vector<Mat3> a(l), b(l), c(l);
  double total = 0.0;
  for (std::size_t s = 0; s < S; ++s) {
    const int si = static_cast<int>(s);
    const std::size_t warm_k = s < warm.size() ? std::min(warm[s].size(), l) : 0;
    for (std::size_t k = 0; k < l; ++k) {
      const Mat3& sample_R = m.R_parent_node_sample(si, driven[k]);
      a[k] = k < warm_k ? warm[s][k] : m.R_parent_node_rest(driven[k]);
      b[k] = k < warm_k ? warm[s][k] : sample_R;
      c[k] = sample_R;
    }
    double Ea = fitter.energy(si, a);
    const double Eb = warm_k < l ? fitter.energy(si, b) : Ea;
    const double Ec = warm_k > 0 ? fitter.energy(si, c) : Eb;
    std::vector<Mat3>* start = &a;
    if (Eb < Ea) {
      start = &b;
      Ea = Eb;
    }
    if (Ec < Ea) start = &c;
    total += fitter.fit_sample(si, *start);
    out[s] = *start;
    if (total > abort_above) return std::numeric_limits<double>::infinity();
  }
  return total;
}

double rigid_error(const RigModel& m, const FitOptions& fit) {
  ReachabilityFitter f(m, fit);
  (void)f.set_setup({});
  double E = 0.0;
  for (std::size_t s = 0; s < m.sample_count(); ++s) E += f.energy(static_cast<int>(s), {});
  return E;
}

}  // namespace reduction_detail

Status ReductionOptions::validate() const {
  if (max_joints < -1 || max_joints > 256) return make_error(Errc::invalid_argument, "max_joints must be -1 or in [0, 256]");
  if (max_iterations < 1 || max_iterations > 100)
    return make_error(Errc::invalid_argument, "max_iterations must be in [1, 100]");
  if (!std::isfinite(min_relative_gain) || min_relative_gain < 0.0 || min_relative_gain >= 1.0)
    return make_error(Errc::invalid_argument, "min_relative_gain must be in [0, 1)");
  if (Status s = fit.validate(); !s) return s;
  return splitters.validate();
}

std::string ReductionOptions::describe() const {
  std::ostringstream s;
  s << "joints: " << (max_joints < 0 ? std::string("all of the kit's") : "at most " + std::to_string(max_joints))
    << "; " << max_iterations << " remove/refill alternations at most; splitters "
    << (use_splitters ? "on" : "off (phantoms only)") << "; joints' rest settings "
    << (center_joint_ranges ? "centred in their range where the stops need it" : "copying the rig at rest") << "\n"
    << fit.describe() << "\n"
    << splitters.describe();
  return s.str();
}

std::vector<int> branch_chain(const RigModel& m, int child) {
  using namespace reduction_detail;
  std::vector<int> chain;
  for (int u = child; u >= 0;) {
    chain.push_back(u);
    int next = -1, moving = 0;
    // A child continues the chain when its subtree moves weight (only then
    // can a joint in it do anything).
    for (int c : m.children()[static_cast<std::size_t>(u)])
      if (m.moves_weight(c)) {
        ++moving;
        next = c;
      }
    if (moving != 1) break;  // leaf, or the next branching node (kept, inclusive)
    u = next;
  }
  return chain;
}

std::vector<BranchingNode> find_branching_nodes(const RigModel& m) {
  using namespace reduction_detail;
  const RestFrames f = rest_frames(m);
  std::vector<BranchingNode> out;
  std::vector<int> index_of(m.node_count(), -1);
  for (std::size_t v = 0; v < m.node_count(); ++v) {
    BranchingNode bn;
    bn.node = static_cast<int>(v);
    for (int c : m.children()[v])
      if (m.moves_weight(c)) bn.branch_child.push_back(c);
    if (bn.branch_child.size() < 2) continue;
    bn.inlet_dir = direction_in(m, f, bn.node);
    for (int c : bn.branch_child) bn.branch_dir.push_back(direction_down(m, f, bn.node, c));
    bn.branch_gain.assign(bn.branch_child.size(), 0.0);
    // Nearest branching ancestor, and which of its branches leads here.
    int below = bn.node;
    for (int a = m.parent()[v]; a >= 0; below = a, a = m.parent()[static_cast<std::size_t>(a)]) {
      const int ai = index_of[static_cast<std::size_t>(a)];
      if (ai < 0) continue;
      const auto& br = out[static_cast<std::size_t>(ai)].branch_child;
      const auto it = std::find(br.begin(), br.end(), below);
      bn.parent = ai;
      bn.parent_branch = it == br.end() ? -1 : static_cast<int>(it - br.begin());
      break;
    }
    index_of[v] = static_cast<int>(out.size());
    out.push_back(std::move(bn));
  }
  return out;
}

Result<GreedyResult> place_joints_greedily(const RigModel& m, const FitOptions& fit, std::vector<int>& driven,
                                           std::vector<std::vector<Mat3>>& solution, const std::vector<char>& allowed,
                                           int joint_budget, double min_relative_gain,
                                           const std::function<void(int, double)>& on_joint) {
  using namespace reduction_detail;
  if (!allowed.empty() && allowed.size() != m.node_count())
    return make_error(Errc::invalid_argument, "the allowed-node mask must have one entry per node");
  ReachabilityFitter fitter(m, fit);
  GreedyResult result;
  if (Status s = fitter.set_setup({driven, {}, {}}); !s) return s.error();
  std::vector<std::vector<Mat3>> current;
  double E = fit_all(fitter, m, driven, solution, current);
  solution = current;
  result.error_start = E;
  const double E_rigid = rigid_error(m, fit);
  const double min_gain = min_relative_gain * E_rigid;
  std::vector<char> is_driven(m.node_count(), 0);
  for (int v : driven) is_driven[static_cast<std::size_t>(v)] = 1;
  std::vector<std::vector<Mat3>> trial, best_solution;
  std::vector<int> candidate_driven;
  while (static_cast<int>(driven.size()) < joint_budget) {
    int best = -1;
    double best_E = E - min_gain;
    for (std::size_t v = 0; v < m.node_count(); ++v) {
      if (is_driven[v] || !m.can_drive(static_cast<int>(v))) continue;
      if (!allowed.empty() && !allowed[v]) continue;
      candidate_driven = driven;
      candidate_driven.push_back(static_cast<int>(v));
      if (Status s = fitter.set_setup({candidate_driven, {}, {}}); !s) return s.error();
      // E sums non-negative per-sample terms: a candidate is dropped as soon
      // as its running sum passes the best so far.
      const double Ev = fit_all(fitter, m, candidate_driven, solution, trial, best_E);
      if (Ev < best_E) {
        best_E = Ev;
        best = static_cast<int>(v);
        best_solution.swap(trial);
      }
    }
    if (best < 0) break;
    driven.push_back(best);
    is_driven[static_cast<std::size_t>(best)] = 1;
    solution = best_solution;
    E = best_E;
    result.error_after_joint.push_back(E);
    if (on_joint) on_joint(best, E);
  }
  return result;
}

namespace reduction_detail {

// Splitter gains: see the header.
void compute_branch_gains(const RigModel& m, const FitOptions& fit, std::vector<BranchingNode>& nodes) {
  ReachabilityFitter fitter(m, fit);
  const std::size_t n = m.node_count();
  // Subtrees as intervals of a depth-first order, so membership is O(1).
  std::vector<int> enter(n, 0), leave(n, 0);
  {
    int clock = 0;
    std::vector<std::pair<int, std::size_t>> stack;
    for (std::size_t r = 0; r < n; ++r) {
      if (m.parent()[r] >= 0) continue;
      stack.push_back({static_cast<int>(r), 0});
      enter[r] = clock++;
      while (!stack.empty()) {
        auto& [v, next] = stack.back();
        const auto& kids = m.children()[static_cast<std::size_t>(v)];
        if (next < kids.size()) {
          const int c = kids[next++];
          enter[static_cast<std::size_t>(c)] = clock++;
          stack.push_back({c, 0});
        } else {
          leave[static_cast<std::size_t>(v)] = clock;
          stack.pop_back();
        }
      }
    }
  }
  std::vector<double> w(n);
  std::vector<std::vector<Mat3>> sol;
  for (BranchingNode& bn : nodes) {
    for (std::size_t b = 0; b < bn.branch_child.size(); ++b) {
      const int c = bn.branch_child[b];
      for (std::size_t v = 0; v < n; ++v)
        w[v] = enter[v] >= enter[static_cast<std::size_t>(c)] && enter[v] < leave[static_cast<std::size_t>(c)]
                   ? m.weights()[v]
                   : 0.0;
      std::vector<int> held;
      for (int a = bn.node; a >= 0; a = m.parent()[static_cast<std::size_t>(a)]) held.push_back(a);
      std::vector<int> free;
      for (int u : branch_chain(m, c))
        if (m.can_drive(u)) free.push_back(u);
      if (!fitter.set_setup({{}, held, w}).ok()) continue;
      double E_rigid = 0.0;
      for (std::size_t s = 0; s < m.sample_count(); ++s) E_rigid += fitter.energy(static_cast<int>(s), {});
      if (!fitter.set_setup({free, held, w}).ok()) continue;
      const double E_free = fit_all(fitter, m, free, {}, sol);
      bn.branch_gain[b] = std::max(0.0, E_rigid - E_free);
    }
  }
}

// Which nodes a device with these splitters reaches (3.5's "not virtual").
std::vector<char> reachable_nodes(const RigModel& m, const std::vector<BranchingNode>& nodes,
                                  const std::vector<SplitterCandidate>& candidates, const std::vector<int>& chosen_at) {
  const std::size_t n = m.node_count();
  std::vector<int> index_of(n, -1);
  for (std::size_t i = 0; i < nodes.size(); ++i) index_of[static_cast<std::size_t>(nodes[i].node)] = static_cast<int>(i);
  std::vector<char> reach(n, 0);
  for (std::size_t v = 0; v < n; ++v) {
    const int p = m.parent()[v];
    if (p < 0) {
      reach[v] = 1;
      continue;
    }
    const auto pu = static_cast<std::size_t>(p);
    reach[v] = reach[pu];
    const int bi = index_of[pu];
    if (bi < 0 || !reach[v]) continue;
    const auto& br = nodes[static_cast<std::size_t>(bi)].branch_child;
    const auto it = std::find(br.begin(), br.end(), static_cast<int>(v));
    if (it == br.end()) continue;  // moves no weight: nothing there to reach
    const int ci = chosen_at[static_cast<std::size_t>(bi)];
    reach[v] = ci >= 0 && candidates[static_cast<std::size_t>(ci)].covers(static_cast<int>(it - br.begin()));
  }
  return reach;
}

struct AttachPoint {
  int module = -1;  // -1: the base
  int outlet = 0;
  bool base = true;
  bool reachable = true;
};

}  // namespace reduction_detail

Result<Plan> reduce_rig(const RigInput& input, const rig_device::Kit& kit, const ReductionOptions& options,
                        const ProgressCallback& progress) {
  using namespace reduction_detail;
  if (Status s = options.validate(); !s) return s.error();
  if (Status s = kit.validate(); !s) return s.error().with_context("kit");
  Result<RigModel> model_r = RigModel::create(input);
  if (!model_r) return model_r.error();
  const RigModel& m = *model_r;
  const std::size_t n = m.node_count();
  const std::size_t S = m.sample_count();
  const int budget = options.max_joints < 0 ? kit.joint_count : std::min(options.max_joints, kit.joint_count);
  auto report = [&](const char* phase, int it, int placed, double E, int node = -1) {
    if (progress) progress({phase, it, placed, budget, E, node});
  };

  Plan plan;
  plan.character = input.name;
  plan.kit = kit;
  plan.error_rigid = rigid_error(m, options.fit);
  report("joints", 1, 0, plan.error_rigid);

  // Phase 1, first pass: ignoring branching (Fig. 3.7's curve).
  std::vector<int> driven;
  std::vector<std::vector<Mat3>> solution;
  {
    Result<GreedyResult> g = place_joints_greedily(
        m, options.fit, driven, solution, {}, budget, options.min_relative_gain,
        [&](int v, double E) { report("joints", 1, static_cast<int>(driven.size()), E, v); });
    if (!g) return g.error();
    plan.error_after_joint = g->error_after_joint;
  }

  // Phase 2: splitters. The gains and candidates do not depend on the joints.
  std::vector<BranchingNode> nodes = find_branching_nodes(m);
  compute_branch_gains(m, options.fit, nodes);
  rig_device::Kit ilp_kit = kit;
  if (!options.use_splitters)
    for (int& c : ilp_kit.splitter_counts) c = 0;
  SplitterIlpOptions ilp_options = options.splitters;
  const std::vector<SplitterCandidate> candidates = enumerate_splitter_candidates(nodes, ilp_kit, ilp_options);
  // The branch gains, and so the ILP's answer, do not depend on the joints:
  // one solve serves every alternation.
  report("splitters", 1, static_cast<int>(driven.size()),
         plan.error_after_joint.empty() ? plan.error_rigid : plan.error_after_joint.back());
  Result<SplitterSolution> sol = solve_splitter_ilp(nodes, candidates, ilp_kit, ilp_options);
  if (!sol) return sol.error();
  std::vector<int> chosen_at(nodes.size(), -1);
  for (int ci : sol->chosen) chosen_at[static_cast<std::size_t>(candidates[static_cast<std::size_t>(ci)].branching)] = ci;
  const std::vector<char> reach = reachable_nodes(m, nodes, candidates, chosen_at);
  // Alternate: remove the joints the splitters do not reach, give the freed
  // joints to bones they do reach, until nothing changes.
  int last_pass = 1;
  for (int it = 1; it <= options.max_iterations; ++it) {
    std::vector<int> kept;
    std::vector<std::vector<Mat3>> kept_solution(S);
    for (std::size_t k = 0; k < driven.size(); ++k) {
      if (!reach[static_cast<std::size_t>(driven[k])]) continue;
      kept.push_back(driven[k]);
      for (std::size_t s = 0; s < S; ++s) kept_solution[s].push_back(solution[s][k]);
    }
    const bool pruned = kept.size() != driven.size();
    driven = std::move(kept);
    solution = std::move(kept_solution);
    if (!pruned && it > 1) break;
    last_pass = it + 1;
    const std::size_t before = driven.size();
    Result<GreedyResult> g = place_joints_greedily(
        m, options.fit, driven, solution, reach, budget, options.min_relative_gain,
        [&](int v, double E) { report("joints", it + 1, static_cast<int>(driven.size()), E, v); });
    if (!g) return g.error();
    if (!pruned && driven.size() == before) break;
  }

  // Final fit of the device's joints, in rig order (parents first).
  std::vector<std::size_t> order(driven.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return driven[a] < driven[b]; });
  {
    std::vector<int> sorted;
    std::vector<std::vector<Mat3>> sorted_solution(S);
    for (std::size_t k : order) {
      sorted.push_back(driven[k]);
      for (std::size_t s = 0; s < S; ++s) sorted_solution[s].push_back(solution[s][k]);
    }
    driven = std::move(sorted);
    solution = std::move(sorted_solution);
  }
  ReachabilityFitter fitter(m, options.fit);
  if (Status s = fitter.set_setup({driven, {}, {}}); !s) return s.error();
  std::vector<std::vector<Mat3>> final_solution;
  plan.error_final = fit_all(fitter, m, driven, solution, final_solution);
  report("final fit", last_pass, static_cast<int>(driven.size()), plan.error_final);

  // The device tree.
  const RestFrames f = rest_frames(m);
  std::vector<int> slot(n, -1);
  for (std::size_t k = 0; k < driven.size(); ++k) slot[static_cast<std::size_t>(driven[k])] = static_cast<int>(k);
  // Joints below each node (inclusive), to drop splitters feeding < 2 joints.
  std::vector<int> joints_below(n, 0);
  for (std::size_t v = n; v-- > 0;) {
    joints_below[v] += slot[v] >= 0 ? 1 : 0;
    const int p = m.parent()[v];
    if (p >= 0) joints_below[static_cast<std::size_t>(p)] += joints_below[v];
  }
  std::vector<int> index_of(n, -1);
  for (std::size_t i = 0; i < nodes.size(); ++i) index_of[static_cast<std::size_t>(nodes[i].node)] = static_cast<int>(i);

  std::vector<AttachPoint> in(n);
  std::vector<int> joint_module(n, -1);
  std::vector<Mat3> splitter_frame;  // per module: a splitter's inlet frame at rest (world)
  for (std::size_t v = 0; v < n; ++v) {
    const int vi = static_cast<int>(v);
    const int p = m.parent()[v];
    AttachPoint point = in[v];
    if (p < 0) point = AttachPoint{};
    if (slot[v] >= 0 && point.reachable) {
      DeviceModule j;
      j.type = DeviceModule::Type::joint;
      j.kind = kit.joint.name;
      j.rig_node = vi;
      j.parent_module = point.module;
      j.parent_outlet = point.outlet;
      joint_module[v] = static_cast<int>(plan.modules.size());
      plan.modules.push_back(std::move(j));
      point.module = joint_module[v];
      point.outlet = 0;
      point.base = false;
    }
    // What each child sees.
    const int bi = index_of[v];
    const auto& kids = m.children()[v];
    if (bi < 0 || !point.reachable) {
      for (int c : kids) in[static_cast<std::size_t>(c)] = point;
      continue;
    }
    const BranchingNode& bn = nodes[static_cast<std::size_t>(bi)];
    const int ci = chosen_at[static_cast<std::size_t>(bi)];
    AttachPoint unreachable = point;
    unreachable.reachable = false;
    for (int c : kids) in[static_cast<std::size_t>(c)] = unreachable;
    for (int c : kids)
      if (std::find(bn.branch_child.begin(), bn.branch_child.end(), c) == bn.branch_child.end())
        in[static_cast<std::size_t>(c)] = point;  // moves no weight; never holds a joint
    if (ci < 0) continue;
    const SplitterCandidate& cand = candidates[static_cast<std::size_t>(ci)];
    int fed = 0;  // covered branches that hold joints
    for (int b : cand.outlet_branch)
      if (b >= 0 && joints_below[static_cast<std::size_t>(bn.branch_child[static_cast<std::size_t>(b)])] > 0) ++fed;
    if (cand.kind == kPhantomKind || fed < 2) {
      // A joint carries on into the branch that has joints (a phantom).
      for (int b : cand.outlet_branch) {
        const int c = b >= 0 ? bn.branch_child[static_cast<std::size_t>(b)] : -1;
        if (c >= 0 && joints_below[static_cast<std::size_t>(c)] > 0) in[static_cast<std::size_t>(c)] = point;
      }
      continue;
    }
    const rig_device::SplitterKind& kind = kit.splitter_kinds[static_cast<std::size_t>(cand.kind)];
    DeviceModule sp;
    sp.type = DeviceModule::Type::splitter;
    sp.kind = kind.name;
    sp.rig_node = vi;
    sp.parent_module = point.module;
    sp.parent_outlet = point.outlet;
    const Mat3 R_world_splitter = f.R_world[v] * cand.q_node_splitter.toRotationMatrix();
    sp.outlet_rig_child.assign(kind.valence(), -1);
    double sum_err = 0.0;
    int used = 0;
    const int sp_index = static_cast<int>(plan.modules.size());
    for (std::size_t o = 0; o < cand.outlet_branch.size(); ++o) {
      const int b = cand.outlet_branch[o];
      if (b < 0) continue;
      const int c = bn.branch_child[static_cast<std::size_t>(b)];
      if (joints_below[static_cast<std::size_t>(c)] == 0) continue;
      sp.outlet_rig_child[o] = c;
      const Vec3 d = bn.branch_dir[static_cast<std::size_t>(b)];
      const Vec3 got = cand.q_node_splitter * (kind.q_inlet_outlet[o] * Vec3::UnitZ());
      sum_err += d.squaredNorm() > 0.25 ? std::atan2(got.cross(d).norm(), got.dot(d)) : 0.0;
      ++used;
      AttachPoint out;
      out.module = sp_index;
      out.outlet = static_cast<int>(o);
      out.base = false;
      in[static_cast<std::size_t>(c)] = out;
    }
    sp.angular_error_rad = used > 0 ? sum_err / used : 0.0;
    plan.modules.push_back(std::move(sp));
    splitter_frame.resize(plan.modules.size(), Mat3::Identity());
    splitter_frame.back() = R_world_splitter;
  }

  // Rest frames, parents first. A joint's inlet is the outlet it plugs into
  // (at the base: along the bone into its node); its outlet points at the
  // module it feeds, along the collapsed rig edge, or straight into the
  // splitter's inlet, so a splitter after a joint needs no rest rotation.
  // Without a module after it, the outlet points down the rig. A splitter
  // sits as its Kabsch match says; its outlets feed the joints below.
  {
    const std::size_t M = plan.modules.size();
    splitter_frame.resize(M, Mat3::Identity());
    std::vector<int> fed_by_joint(M, -1);
    for (std::size_t i = 0; i < M; ++i) {
      const int pm = plan.modules[i].parent_module;
      if (pm >= 0 && plan.modules[static_cast<std::size_t>(pm)].type == DeviceModule::Type::joint)
        fed_by_joint[static_cast<std::size_t>(pm)] = static_cast<int>(i);
    }
    std::vector<Mat3> R_world_out(M, Mat3::Identity());  // joints: outlet; splitters: inlet
    for (std::size_t i = 0; i < M; ++i) {
      DeviceModule& mod = plan.modules[i];
      const int pm = mod.parent_module;
      Mat3 up = Mat3::Identity();
      if (pm >= 0) {
        const DeviceModule& parent = plan.modules[static_cast<std::size_t>(pm)];
        up = R_world_out[static_cast<std::size_t>(pm)];
        if (parent.type == DeviceModule::Type::splitter) {
          std::size_t k = 0;
          while (kit.splitter_kinds[k].name != parent.kind) ++k;
          up = up * kit.splitter_kinds[k].q_inlet_outlet[static_cast<std::size_t>(mod.parent_outlet)].toRotationMatrix();
        }
      }
      if (mod.type == DeviceModule::Type::splitter) {
        R_world_out[i] = splitter_frame[i];
        mod.q_in_out_rest = Quat(Mat3((pm >= 0 ? up : splitter_frame[i]).transpose() * splitter_frame[i])).normalized();
        continue;
      }
      const int b = mod.rig_node;
      const auto bu = static_cast<std::size_t>(b);
      const Mat3& R_world_parent = f.R_world[static_cast<std::size_t>(m.parent()[bu])];
      const Mat3 inlet = pm >= 0 ? up : Mat3(R_world_parent * z_to(m.t_parent_node_m(b)).toRotationMatrix());
      Mat3 outlet = f.R_world[bu] * z_to(direction_down(m, f, b, heaviest_child(m, b))).toRotationMatrix();
      const int next = fed_by_joint[i];
      if (next >= 0) {
        const DeviceModule& nm = plan.modules[static_cast<std::size_t>(next)];
        if (nm.type == DeviceModule::Type::splitter) {
          outlet = splitter_frame[static_cast<std::size_t>(next)];
        } else {
          const Vec3 d = f.p_world[static_cast<std::size_t>(nm.rig_node)] - f.p_world[bu];
          if (d.norm() >= kOnNodeM) outlet = f.R_world[bu] * z_to(f.R_world[bu].transpose() * d).toRotationMatrix();
        }
      }
      mod.q_parent_inlet = Quat(Mat3(R_world_parent.transpose() * inlet)).normalized();
      mod.q_in_out_rest = Quat(Mat3(inlet.transpose() * outlet)).normalized();
      R_world_out[i] = outlet;
    }
  }

  // Device poses: per sample, q_in_out = Delta * q_in_out_rest with Delta the
  // fitted local rotation seen in the inlet frame (plan.hpp's M, inverted).
  plan.device_poses.assign(S, std::vector<Quat>(plan.modules.size(), Quat::Identity()));
  for (std::size_t s = 0; s < S; ++s)
    for (std::size_t k = 0; k < driven.size(); ++k) {
      const int v = driven[k];
      const int mi = joint_module[static_cast<std::size_t>(v)];
      if (mi < 0) continue;
      const DeviceModule& j = plan.modules[static_cast<std::size_t>(mi)];
      const Quat R_b = Quat(final_solution[s][k]).normalized();
      const Quat q_rest_b = Quat(m.R_parent_node_rest(v)).normalized();
      const Quat delta = j.q_parent_inlet.conjugate() * R_b * q_rest_b.conjugate() * j.q_parent_inlet;
      plan.device_poses[s][static_cast<std::size_t>(mi)] = (delta * j.q_in_out_rest).normalized();
    }
  // A device shaped exactly like the rig at rest can need joints bent past
  // their stops (joint_ranges.hpp); give those joints room both ways.
  if (options.center_joint_ranges) center_joint_ranges(plan);
  return plan;
}

}  // namespace proprio::rig_plan
