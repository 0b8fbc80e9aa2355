#include "proprio/rig_plan/splitter_ilp.hpp"

#include <algorithm>
#include <cstdint>
#include <exception>
#include <limits>
#include <map>
#include <numeric>
#include <sstream>

#include <Eigen/SVD>

// COIN-OR's headers trip the project's warnings; they are not ours to fix.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpedantic"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wconversion"
#pragma GCC diagnostic ignored "-Wsign-conversion"
#pragma GCC diagnostic ignored "-Wold-style-cast"
#pragma GCC diagnostic ignored "-Wunused-parameter"
#pragma GCC diagnostic ignored "-Woverloaded-virtual"
#pragma GCC diagnostic ignored "-Wnon-virtual-dtor"
#pragma GCC diagnostic ignored "-Wuseless-cast"
#pragma GCC diagnostic ignored "-Wdeprecated-copy"
#include "CbcModel.hpp"
#include "CoinError.hpp"
#include "CoinPackedMatrix.hpp"
#include "CoinPackedVector.hpp"
#include "OsiClpSolverInterface.hpp"
#pragma GCC diagnostic pop

namespace proprio::rig_plan {

namespace ilp_detail {

double angle_between_dirs(const Vec3& a, const Vec3& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

bool defined(const Vec3& v) { return v.squaredNorm() > 0.25; }

// The objective's tie-break: per radian of mean error, a fraction of the
// largest gain far below any gain difference that matters.
constexpr double kTiePenaltyPerRad = 1e-6 / M_PI;

}  // namespace ilp_detail

bool SplitterCandidate::covers(int branch) const {
  return std::find(outlet_branch.begin(), outlet_branch.end(), branch) != outlet_branch.end();
}

Status SplitterIlpOptions::validate() const {
  if (!std::isfinite(max_gate_error_rad) || max_gate_error_rad <= 0.0 || max_gate_error_rad > M_PI)
    return make_error(Errc::invalid_argument, "splitter max_gate_error_rad must be in (0, pi]");
  if (!std::isfinite(time_limit_s) || time_limit_s <= 0.0 || time_limit_s > 3600.0)
    return make_error(Errc::invalid_argument, "ILP time_limit_s must be in (0, 3600]");
  if (max_phantoms < -1) return make_error(Errc::invalid_argument, "max_phantoms must be -1 (no limit) or >= 0");
  if (max_branches < 1 || max_branches > 16)
    return make_error(Errc::invalid_argument, "splitter max_branches must be in [1, 16]");
  if (max_maps_per_pair < 1 || max_maps_total < 1)
    return make_error(Errc::invalid_argument, "max_maps_per_pair and max_maps_total must be >= 1");
  return {};
}

std::string SplitterIlpOptions::describe() const {
  std::ostringstream s;
  s << "splitters: reject gates more than " << max_gate_error_rad * 180.0 / M_PI << " deg off, ILP (CBC) limit "
    << time_limit_s << " s, phantoms " << (max_phantoms < 0 ? std::string("unlimited") : std::to_string(max_phantoms))
    << ", at most " << max_branches << " branches matched per node";
  return s.str();
}

Quat kabsch(std::span<const Vec3> a, std::span<const Vec3> b, std::span<const double> w) {
  using namespace ilp_detail;
  Mat3 H = Mat3::Zero();
  const std::size_t n = std::min({a.size(), b.size(), w.size()});
  for (std::size_t i = 0; i < n; ++i)
    if (defined(a[i]) && defined(b[i]) && w[i] > 0.0) H += w[i] * a[i] * b[i].transpose();
  if (H.squaredNorm() == 0.0) return Quat::Identity();
  Eigen::JacobiSVD<Mat3> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Mat3 U = svd.matrixU(), V = svd.matrixV();
  Mat3 D = Mat3::Identity();
  D(2, 2) = (V * U.transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  return Quat(Mat3(V * D * U.transpose())).normalized();
}

std::vector<SplitterCandidate> enumerate_splitter_candidates(const std::vector<BranchingNode>& nodes,
                                                             const rig_device::Kit& kit,
                                                             const SplitterIlpOptions& options) {
  using namespace ilp_detail;
  std::vector<SplitterCandidate> out;
  std::size_t visited_total = 0;
  for (std::size_t bi = 0; bi < nodes.size(); ++bi) {
    const BranchingNode& bn = nodes[bi];
    const int B = static_cast<int>(bn.branch_child.size());
    // Phantoms: one per branch, no geometry.
    for (int b = 0; b < B; ++b) {
      SplitterCandidate c;
      c.branching = static_cast<int>(bi);
      c.kind = kPhantomKind;
      c.outlet_branch = {b};
      c.gain = bn.branch_gain[static_cast<std::size_t>(b)];
      out.push_back(std::move(c));
    }
    // The branches worth matching, by gain.
    std::vector<int> order(static_cast<std::size_t>(B));
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](int x, int y) {
      return bn.branch_gain[static_cast<std::size_t>(x)] > bn.branch_gain[static_cast<std::size_t>(y)];
    });
    if (static_cast<int>(order.size()) > options.max_branches) order.resize(static_cast<std::size_t>(options.max_branches));
    std::vector<int> pos_of(static_cast<std::size_t>(B), 0);  // branch -> bit in the covered mask
    for (std::size_t o = 0; o < order.size(); ++o) pos_of[static_cast<std::size_t>(order[o])] = static_cast<int>(o);
    for (std::size_t k = 0; k < kit.splitter_kinds.size(); ++k) {
      if (k >= kit.splitter_counts.size() || kit.splitter_counts[k] <= 0) continue;
      const rig_device::SplitterKind& kind = kit.splitter_kinds[k];
      const int V = static_cast<int>(kind.valence());
      std::vector<Vec3> outlet_dir(static_cast<std::size_t>(V));
      for (int m = 0; m < V; ++m) outlet_dir[static_cast<std::size_t>(m)] = kind.q_inlet_outlet[static_cast<std::size_t>(m)] * Vec3::UnitZ();
      std::map<std::uint32_t, SplitterCandidate> best;  // by covered-branch mask
      std::vector<int> map(static_cast<std::size_t>(V), -1);
      std::vector<char> used(order.size(), 0);
      std::size_t visited = 0;
      std::vector<Vec3> a, b;
      std::vector<double> w;
      auto score = [&]() {
        a.clear();
        b.clear();
        w.clear();
        std::uint32_t mask = 0;
        if (defined(bn.inlet_dir)) {
          a.push_back(Vec3::UnitZ());
          b.push_back(bn.inlet_dir);
          w.push_back(1.0);
        }
        for (int m = 0; m < V; ++m) {
          const int br = map[static_cast<std::size_t>(m)];
          if (br < 0) continue;
          mask |= 1u << pos_of[static_cast<std::size_t>(br)];
          a.push_back(outlet_dir[static_cast<std::size_t>(m)]);
          b.push_back(bn.branch_dir[static_cast<std::size_t>(br)]);
          w.push_back(1.0);
        }
        if (mask == 0) return;
        const Quat R = kabsch(a, b, w);
        double max_err = 0.0, sum_err = 0.0;
        int matched = 0;
        if (defined(bn.inlet_dir)) max_err = angle_between_dirs(R * Vec3::UnitZ(), bn.inlet_dir);
        double gain = 0.0;
        for (int m = 0; m < V; ++m) {
          const int br = map[static_cast<std::size_t>(m)];
          if (br < 0) continue;
          gain += bn.branch_gain[static_cast<std::size_t>(br)];
          const Vec3& d = bn.branch_dir[static_cast<std::size_t>(br)];
          const double e = defined(d) ? angle_between_dirs(R * outlet_dir[static_cast<std::size_t>(m)], d) : 0.0;
          max_err = std::max(max_err, e);
          sum_err += e;
          ++matched;
        }
        if (max_err > options.max_gate_error_rad) return;
        const double mean = sum_err / matched;
        auto it = best.find(mask);
        if (it != best.end() && it->second.mean_error_rad <= mean) return;
        SplitterCandidate c;
        c.branching = static_cast<int>(bi);
        c.kind = static_cast<int>(k);
        c.outlet_branch = map;
        c.q_node_splitter = R;
        c.gain = gain;
        c.mean_error_rad = mean;
        c.max_error_rad = max_err;
        best[mask] = std::move(c);
      };
      // Every injective partial map outlets -> branches, depth first.
      auto recurse = [&](auto&& self, int m) -> void {
        if (visited >= options.max_maps_per_pair || visited_total >= options.max_maps_total) return;
        if (m == V) {
          ++visited;
          ++visited_total;
          score();
          return;
        }
        map[static_cast<std::size_t>(m)] = -1;
        self(self, m + 1);
        for (std::size_t o = 0; o < order.size(); ++o) {
          if (used[o]) continue;
          used[o] = 1;
          map[static_cast<std::size_t>(m)] = order[o];
          self(self, m + 1);
          used[o] = 0;
          map[static_cast<std::size_t>(m)] = -1;
        }
      };
      recurse(recurse, 0);
      for (auto& [mask, c] : best) out.push_back(std::move(c));
    }
  }
  return out;
}

Status check_splitter_solution(const std::vector<BranchingNode>& nodes,
                               const std::vector<SplitterCandidate>& candidates, const rig_device::Kit& kit,
                               const SplitterIlpOptions& options, std::span<const int> chosen) {
  std::vector<int> per_kind(kit.splitter_kinds.size(), 0);
  int phantoms = 0;
  std::vector<int> at_node(nodes.size(), -1);
  for (int i : chosen) {
    if (i < 0 || static_cast<std::size_t>(i) >= candidates.size())
      return make_error(Errc::invalid_argument, "a chosen splitter candidate index is out of range");
    const SplitterCandidate& c = candidates[static_cast<std::size_t>(i)];
    if (c.kind == kPhantomKind) {
      ++phantoms;
    } else {
      if (c.kind < 0 || static_cast<std::size_t>(c.kind) >= per_kind.size())
        return make_error(Errc::invalid_argument, "a chosen splitter has an unknown kind");
      ++per_kind[static_cast<std::size_t>(c.kind)];
    }
    if (c.max_error_rad > options.max_gate_error_rad + 1e-9)
      return make_error(Errc::invalid_argument, "a chosen splitter leaves a gate beyond the angular limit");
    if (at_node[static_cast<std::size_t>(c.branching)] >= 0)
      return make_error(Errc::invalid_argument, "(3.4) broken: two splitters on branching node " +
                                                    std::to_string(nodes[static_cast<std::size_t>(c.branching)].node));
    at_node[static_cast<std::size_t>(c.branching)] = i;
  }
  for (std::size_t k = 0; k < per_kind.size(); ++k)
    if (per_kind[k] > (k < kit.splitter_counts.size() ? kit.splitter_counts[k] : 0))
      return make_error(Errc::invalid_argument, "(3.3) broken: more '" + kit.splitter_kinds[k].name +
                                                    "' splitters placed than the kit has");
  if (options.max_phantoms >= 0 && phantoms > options.max_phantoms)
    return make_error(Errc::invalid_argument, "(3.3) broken: more phantom splitters than allowed");
  for (std::size_t n = 0; n < nodes.size(); ++n) {
    if (at_node[n] < 0 || nodes[n].parent < 0) continue;
    const int p = at_node[static_cast<std::size_t>(nodes[n].parent)];
    if (p < 0 || !candidates[static_cast<std::size_t>(p)].covers(nodes[n].parent_branch))
      return make_error(Errc::invalid_argument, "(3.5) broken: branching node " + std::to_string(nodes[n].node) +
                                                    " has a splitter but its branch of the parent is not covered");
  }
  return {};
}

namespace ilp_detail {

double objective_of(const SplitterCandidate& c, double gain_scale) {
  return c.gain / gain_scale - kTiePenaltyPerRad * c.mean_error_rad;
}

// Feasible by construction: best objective first, a node's splitter only once
// its parent's covers the branch; repeated until nothing more fits.
std::vector<int> greedy_solution(const std::vector<BranchingNode>& nodes,
                                 const std::vector<SplitterCandidate>& candidates, const rig_device::Kit& kit,
                                 const SplitterIlpOptions& options, double gain_scale) {
  std::vector<int> order(candidates.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int x, int y) {
    return objective_of(candidates[static_cast<std::size_t>(x)], gain_scale) >
           objective_of(candidates[static_cast<std::size_t>(y)], gain_scale);
  });
  std::vector<int> left(kit.splitter_kinds.size(), 0);
  for (std::size_t k = 0; k < left.size() && k < kit.splitter_counts.size(); ++k) left[k] = kit.splitter_counts[k];
  int phantoms_left = options.max_phantoms < 0 ? std::numeric_limits<int>::max() : options.max_phantoms;
  std::vector<int> at_node(nodes.size(), -1);
  std::vector<int> chosen;
  for (bool changed = true; changed;) {
    changed = false;
    for (int i : order) {
      const SplitterCandidate& c = candidates[static_cast<std::size_t>(i)];
      if (objective_of(c, gain_scale) <= 0.0) continue;
      if (at_node[static_cast<std::size_t>(c.branching)] >= 0) continue;
      const BranchingNode& bn = nodes[static_cast<std::size_t>(c.branching)];
      if (bn.parent >= 0) {
        const int p = at_node[static_cast<std::size_t>(bn.parent)];
        if (p < 0 || !candidates[static_cast<std::size_t>(p)].covers(bn.parent_branch)) continue;
      }
      if (c.kind == kPhantomKind) {
        if (phantoms_left <= 0) continue;
        --phantoms_left;
      } else {
        if (left[static_cast<std::size_t>(c.kind)] <= 0) continue;
        --left[static_cast<std::size_t>(c.kind)];
      }
      at_node[static_cast<std::size_t>(c.branching)] = i;
      chosen.push_back(i);
      changed = true;
    }
  }
  return chosen;
}

double gain_of(const std::vector<SplitterCandidate>& candidates, const std::vector<int>& chosen) {
  double g = 0.0;
  for (int i : chosen) g += candidates[static_cast<std::size_t>(i)].gain;
  return g;
}

}  // namespace ilp_detail

Result<SplitterSolution> solve_splitter_ilp(const std::vector<BranchingNode>& nodes,
                                            const std::vector<SplitterCandidate>& candidates,
                                            const rig_device::Kit& kit, const SplitterIlpOptions& options) {
  using namespace ilp_detail;
  if (Status s = options.validate(); !s) return s.error();
  for (std::size_t n = 0; n < nodes.size(); ++n) {
    const BranchingNode& bn = nodes[n];
    if (bn.branch_dir.size() != bn.branch_child.size() || bn.branch_gain.size() != bn.branch_child.size())
      return make_error(Errc::invalid_argument, "a branching node's branch lists differ in length");
    if (bn.parent >= static_cast<int>(n))
      return make_error(Errc::invalid_argument, "branching nodes must come after their branching parent");
    if (bn.parent >= 0 && (bn.parent_branch < 0 ||
                           static_cast<std::size_t>(bn.parent_branch) >=
                               nodes[static_cast<std::size_t>(bn.parent)].branch_child.size()))
      return make_error(Errc::invalid_argument, "a branching node names a parent branch that does not exist");
  }
  for (const SplitterCandidate& c : candidates)
    if (c.branching < 0 || static_cast<std::size_t>(c.branching) >= nodes.size() ||
        (c.kind != kPhantomKind && (c.kind < 0 || static_cast<std::size_t>(c.kind) >= kit.splitter_kinds.size())) ||
        !std::isfinite(c.gain) || c.gain < 0.0)
      return make_error(Errc::invalid_argument, "a splitter candidate names an unknown node or kind, or has a bad gain");

  SplitterSolution sol;
  if (candidates.empty()) {
    sol.proven_optimal = true;
    sol.note = "no candidates";
    return sol;
  }
  double gain_scale = 0.0;
  for (const SplitterCandidate& c : candidates) gain_scale = std::max(gain_scale, c.gain);
  if (!(gain_scale > 0.0)) gain_scale = 1.0;
  const std::vector<int> greedy = greedy_solution(nodes, candidates, kit, options, gain_scale);

  const int ncols = static_cast<int>(candidates.size());
  std::vector<double> obj(candidates.size()), collb(candidates.size(), 0.0), colub(candidates.size(), 1.0);
  for (std::size_t i = 0; i < candidates.size(); ++i) obj[i] = objective_of(candidates[i], gain_scale);
  CoinPackedMatrix rows(false, 0, 0);
  rows.setDimensions(0, ncols);
  std::vector<double> rowlb, rowub;
  auto add_row = [&](const CoinPackedVector& v, double ub) {
    rows.appendRow(v);
    rowlb.push_back(-COIN_DBL_MAX);
    rowub.push_back(ub);
  };
  // (3.3), per kind and for the phantoms.
  for (std::size_t k = 0; k < kit.splitter_kinds.size(); ++k) {
    CoinPackedVector v;
    for (int i = 0; i < ncols; ++i)
      if (candidates[static_cast<std::size_t>(i)].kind == static_cast<int>(k)) v.insert(i, 1.0);
    if (v.getNumElements() > 0) add_row(v, k < kit.splitter_counts.size() ? kit.splitter_counts[k] : 0.0);
  }
  if (options.max_phantoms >= 0) {
    CoinPackedVector v;
    for (int i = 0; i < ncols; ++i)
      if (candidates[static_cast<std::size_t>(i)].kind == kPhantomKind) v.insert(i, 1.0);
    if (v.getNumElements() > 0) add_row(v, options.max_phantoms);
  }
  // (3.4) and (3.5).
  std::vector<std::vector<int>> at(nodes.size());
  for (int i = 0; i < ncols; ++i) at[static_cast<std::size_t>(candidates[static_cast<std::size_t>(i)].branching)].push_back(i);
  for (std::size_t n = 0; n < nodes.size(); ++n) {
    if (at[n].empty()) continue;
    CoinPackedVector v;
    for (int i : at[n]) v.insert(i, 1.0);
    add_row(v, 1.0);
    if (nodes[n].parent >= 0) {
      CoinPackedVector h;
      for (int i : at[n]) h.insert(i, 1.0);
      for (int i : at[static_cast<std::size_t>(nodes[n].parent)])
        if (candidates[static_cast<std::size_t>(i)].covers(nodes[n].parent_branch)) h.insert(i, -1.0);
      add_row(h, 0.0);
    }
  }

  try {
    OsiClpSolverInterface lp;
    lp.messageHandler()->setLogLevel(0);
    lp.loadProblem(rows, collb.data(), colub.data(), obj.data(), rowlb.data(), rowub.data());
    for (int i = 0; i < ncols; ++i) lp.setInteger(i);
    lp.setObjSense(-1.0);  // maximise
    CbcModel model(lp);
    model.setLogLevel(0);
    model.messageHandler()->setLogLevel(0);
    model.solver()->messageHandler()->setLogLevel(0);
    model.setUseElapsedTime(true);  // a wall-clock bound: the CLI waits in wall time
    model.setMaximumSeconds(options.time_limit_s);
    model.setAllowableGap(1e-12);
    model.setAllowableFractionGap(0.0);
    model.setDblParam(CbcModel::CbcCutoffIncrement, 1e-12);
    {
      // The greedy assignment is feasible: start from it.
      std::vector<double> start(candidates.size(), 0.0);
      for (int i : greedy) start[static_cast<std::size_t>(i)] = 1.0;
      double start_obj = 0.0;
      for (int i : greedy) start_obj += obj[static_cast<std::size_t>(i)];
      model.setBestSolution(start.data(), ncols, -start_obj, true);
    }
    model.branchAndBound();
    const double* x = model.bestSolution();
    if (x != nullptr) {
      std::vector<int> chosen;
      for (int i = 0; i < ncols; ++i)
        if (x[i] > 0.5) chosen.push_back(i);
      if (check_splitter_solution(nodes, candidates, kit, options, chosen).ok()) {
        sol.chosen = std::move(chosen);
        sol.proven_optimal = model.isProvenOptimal();
        sol.gain = gain_of(candidates, sol.chosen);
        sol.note = sol.proven_optimal ? "CBC, optimal" : "CBC, stopped at the time limit";
        return sol;
      }
      sol.note = "CBC's answer broke a constraint; greedy assignment used";
    } else {
      sol.note = "CBC found no solution; greedy assignment used";
    }
  } catch (const CoinError& e) {
    sol.note = "CBC failed (" + e.message() + "); greedy assignment used";
  } catch (const std::exception& e) {
    sol.note = std::string("CBC failed (") + e.what() + "); greedy assignment used";
  }
  sol.chosen = greedy;
  sol.gain = gain_of(candidates, greedy);
  sol.proven_optimal = false;
  return sol;
}

}  // namespace proprio::rig_plan
