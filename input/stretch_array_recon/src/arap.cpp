#include "proprio/stretch_array_recon/arap.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>
#include <utility>

#include <Eigen/SVD>
#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>

namespace proprio::stretch_array_recon {

Result<Eigen::Isometry3d> fit_rigid(const Eigen::MatrixX3d& from, const Eigen::MatrixX3d& to) {
  if (from.rows() != to.rows() || from.rows() < 3) {
    return make_error(Errc::invalid_argument, "Procrustes needs >= 3 point pairs (got " + std::to_string(from.rows()) +
                                                  " and " + std::to_string(to.rows()) + ")");
  }
  if (!from.allFinite() || !to.allFinite())
    return make_error(Errc::invalid_argument, "Procrustes: a point is NaN or infinite");
  const Eigen::RowVector3d ca = from.colwise().mean(), cb = to.colwise().mean();
  const Eigen::MatrixX3d A = from.rowwise() - ca, B = to.rowwise() - cb;
  const Eigen::Matrix3d H = A.transpose() * B;
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d sv = svd.singularValues();
  // Collinear points leave the rotation about their line undetermined.
  if (sv(1) <= 1e-12 * std::max(sv(0), 1e-300)) {
    return make_error(Errc::invalid_argument,
                      "Procrustes: the points lie on one line (or coincide); pick three markers that span a triangle");
  }
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  if ((svd.matrixV() * svd.matrixU().transpose()).determinant() < 0) D(2, 2) = -1;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = svd.matrixV() * D * svd.matrixU().transpose();
  T.translation() = cb.transpose() - T.linear() * ca.transpose();
  return T;
}

Status ArapOptions::validate() const {
  if (max_iterations < 1 || max_iterations > 10000) {
    return make_error(Errc::invalid_argument,
                      "max_iterations = " + std::to_string(max_iterations) + ": expected 1..10000");
  }
  if (!(tolerance_m >= 0)) return make_error(Errc::invalid_argument, "tolerance_m must be >= 0 metres");
  if (factor_cache_size < 1) return make_error(Errc::invalid_argument, "factor_cache_size must be >= 1");
  return {};
}

std::string ArapOptions::describe() const {
  std::ostringstream s;
  s << "max_iterations=" << max_iterations << " tolerance_m=" << tolerance_m
    << " factor_cache_size=" << factor_cache_size;
  return s.str();
}

namespace arap_impl {

using SpMat = Eigen::SparseMatrix<double>;

struct Factor {
  std::vector<std::int32_t> free_index;  // vertex -> row in L_ff, or -1
  std::vector<std::uint32_t> free_vertices;
  SpMat L_fc;  // free x constrained (columns in constraint order)
  Eigen::SimplicialLDLT<SpMat> ldlt;
};

}  // namespace arap_impl
using namespace arap_impl;

struct ArapDeformer::Impl {
  ArapOptions options;
  Eigen::MatrixX3d rest;
  // Neighbours as CSR: for vertex i, nbr[off[i]..off[i+1]) with weights.
  std::vector<std::int32_t> off;
  std::vector<std::uint32_t> nbr;
  std::vector<double> w;
  SpMat L;  // the cotangent Laplacian: L_ii = sum_j w_ij, L_ij = -w_ij
  std::list<std::pair<std::vector<std::uint32_t>, std::shared_ptr<Factor>>> cache;  // most recent first
  std::vector<Eigen::Matrix3d> R;
  Eigen::MatrixX3d b, rhs_f;
  std::vector<std::uint32_t> component;  // per vertex, its connected part
  std::uint32_t component_count = 0;

  Result<std::shared_ptr<Factor>> factor_for(const std::vector<std::uint32_t>& constrained, bool& refactored) {
    for (auto it = cache.begin(); it != cache.end(); ++it) {
      if (it->first == constrained) {
        cache.splice(cache.begin(), cache, it);
        refactored = false;
        return it->second;
      }
    }
    refactored = true;
    const auto n = static_cast<std::size_t>(rest.rows());
    // A part of the mesh without a constrained vertex leaves L_ff singular,
    // and SimplicialLDLT does not always say so: check the parts instead.
    std::vector<bool> held(component_count, false);
    for (std::uint32_t v : constrained) held[component[v]] = true;
    if (std::find(held.begin(), held.end(), false) != held.end()) {
      return make_error(Errc::invalid_argument,
                        "ARAP: a connected part of the mesh has no constrained vertex, so it "
                        "would float freely; constrain at least one vertex of every part");
    }
    auto f = std::make_shared<Factor>();
    f->free_index.assign(n, -1);
    std::vector<std::int32_t> con_index(n, -1);
    for (std::size_t k = 0; k < constrained.size(); ++k) con_index[constrained[k]] = static_cast<std::int32_t>(k);
    for (std::uint32_t v = 0; v < n; ++v) {
      if (con_index[v] < 0) {
        f->free_index[v] = static_cast<std::int32_t>(f->free_vertices.size());
        f->free_vertices.push_back(v);
      }
    }
    std::vector<Eigen::Triplet<double>> ff, fc;
    for (int col = 0; col < L.outerSize(); ++col) {
      for (SpMat::InnerIterator it(L, col); it; ++it) {
        const std::int32_t r = f->free_index[static_cast<std::size_t>(it.row())];
        if (r < 0) continue;
        const std::int32_t cf = f->free_index[static_cast<std::size_t>(col)];
        if (cf >= 0) {
          ff.emplace_back(r, cf, it.value());
        } else {
          fc.emplace_back(r, con_index[static_cast<std::size_t>(col)], it.value());
        }
      }
    }
    const auto nf = static_cast<Eigen::Index>(f->free_vertices.size());
    SpMat Lff(nf, nf);
    Lff.setFromTriplets(ff.begin(), ff.end());
    f->L_fc.resize(nf, static_cast<Eigen::Index>(constrained.size()));
    f->L_fc.setFromTriplets(fc.begin(), fc.end());
    if (nf > 0) {
      f->ldlt.compute(Lff);
      if (f->ldlt.info() != Eigen::Success) {
        return make_error(Errc::invalid_argument,
                          "ARAP: the constrained Laplacian is singular; every connected part of "
                          "the mesh needs at least one constrained vertex");
      }
    }
    cache.emplace_front(constrained, f);
    while (cache.size() > options.factor_cache_size) cache.pop_back();
    return f;
  }

  void local_step(const Eigen::MatrixX3d& V) {
    const auto n = static_cast<std::size_t>(rest.rows());
    for (std::size_t i = 0; i < n; ++i) {
      Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
      for (auto k = off[i]; k < off[i + 1]; ++k) {
        const std::uint32_t j = nbr[static_cast<std::size_t>(k)];
        const Eigen::Vector3d e0 = (rest.row(static_cast<Eigen::Index>(i)) - rest.row(j)).transpose();
        const Eigen::Vector3d e = (V.row(static_cast<Eigen::Index>(i)) - V.row(j)).transpose();
        S.noalias() += w[static_cast<std::size_t>(k)] * e0 * e.transpose();
      }
      Eigen::JacobiSVD<Eigen::Matrix3d> svd(S, Eigen::ComputeFullU | Eigen::ComputeFullV);
      Eigen::Matrix3d Ri = svd.matrixV() * svd.matrixU().transpose();
      if (Ri.determinant() < 0) {
        Eigen::Matrix3d U = svd.matrixU();
        U.col(2) *= -1;  // the smallest singular value's direction
        Ri = svd.matrixV() * U.transpose();
      }
      R[i] = Ri;
    }
  }
};

ArapDeformer::ArapDeformer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ArapDeformer::ArapDeformer(ArapDeformer&&) noexcept = default;
ArapDeformer& ArapDeformer::operator=(ArapDeformer&&) noexcept = default;
ArapDeformer::~ArapDeformer() = default;

Result<ArapDeformer> ArapDeformer::create(const Eigen::MatrixX3d& rest_m,
                                          const std::vector<std::array<std::uint32_t, 3>>& triangles,
                                          const ArapOptions& options) {
  if (Status s = options.validate(); !s) return s.error();
  const auto n = static_cast<std::size_t>(rest_m.rows());
  if (n == 0 || triangles.empty())
    return make_error(Errc::invalid_argument, "ARAP: the mesh has no vertices or no triangles");
  if (!rest_m.allFinite()) return make_error(Errc::invalid_argument, "ARAP: a rest vertex is NaN or infinite");
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  impl->rest = rest_m;
  std::map<std::pair<std::uint32_t, std::uint32_t>, double> edge_w;
  double mean_abs = 0.0;
  for (const auto& t : triangles) {
    for (std::uint32_t v : t) {
      if (v >= n)
        return make_error(Errc::invalid_argument,
                          "ARAP: a triangle names vertex " + std::to_string(v) + " of " + std::to_string(n));
    }
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = t[static_cast<std::size_t>(k)], b = t[static_cast<std::size_t>((k + 1) % 3)],
                          c = t[static_cast<std::size_t>((k + 2) % 3)];
      const Eigen::Vector3d u = (rest_m.row(a) - rest_m.row(c)).transpose(),
                            v = (rest_m.row(b) - rest_m.row(c)).transpose();
      const double cr = u.cross(v).norm();
      if (cr <= 1e-300)
        return make_error(Errc::invalid_argument, "ARAP: a triangle has zero area (vertices " + std::to_string(a) +
                                                      ", " + std::to_string(b) + ", " + std::to_string(c) + ")");
      const double half_cot = 0.5 * u.dot(v) / cr;  // the angle at c faces edge ab
      edge_w[{std::min(a, b), std::max(a, b)}] += half_cot;
      mean_abs += std::abs(half_cot);
    }
  }
  mean_abs /= static_cast<double>(3 * triangles.size());
  std::vector<std::vector<std::pair<std::uint32_t, double>>> adj(n);
  std::vector<Eigen::Triplet<double>> trip;
  for (auto& [e, wij] : edge_w) {
    const double wc = std::max(wij, 1e-3 * mean_abs);
    adj[e.first].emplace_back(e.second, wc);
    adj[e.second].emplace_back(e.first, wc);
    trip.emplace_back(e.first, e.second, -wc);
    trip.emplace_back(e.second, e.first, -wc);
    trip.emplace_back(e.first, e.first, wc);
    trip.emplace_back(e.second, e.second, wc);
  }
  impl->off.assign(n + 1, 0);
  for (std::size_t i = 0; i < n; ++i) {
    impl->off[i + 1] = impl->off[i] + static_cast<std::int32_t>(adj[i].size());
    for (auto& [j, wij] : adj[i]) impl->nbr.push_back(j), impl->w.push_back(wij);
  }
  impl->L.resize(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n));
  impl->L.setFromTriplets(trip.begin(), trip.end());
  impl->component.assign(n, std::numeric_limits<std::uint32_t>::max());
  for (std::uint32_t seed = 0; seed < n; ++seed) {
    if (impl->component[seed] != std::numeric_limits<std::uint32_t>::max()) continue;
    std::vector<std::uint32_t> stack{seed};
    impl->component[seed] = impl->component_count;
    while (!stack.empty()) {
      const std::uint32_t v = stack.back();
      stack.pop_back();
      for (auto k = impl->off[v]; k < impl->off[v + 1]; ++k) {
        const std::uint32_t u = impl->nbr[static_cast<std::size_t>(k)];
        if (impl->component[u] == std::numeric_limits<std::uint32_t>::max()) {
          impl->component[u] = impl->component_count;
          stack.push_back(u);
        }
      }
    }
    ++impl->component_count;
  }
  impl->R.assign(n, Eigen::Matrix3d::Identity());
  impl->b.resize(static_cast<Eigen::Index>(n), 3);
  return ArapDeformer(std::move(impl));
}

Status ArapDeformer::solve(const std::vector<std::uint32_t>& constrained, const Eigen::MatrixX3d& targets_m,
                           Eigen::MatrixX3d& V, ArapStats* stats) {
  Impl& m = *impl_;
  const auto n = static_cast<std::size_t>(m.rest.rows());
  if (constrained.empty())
    return make_error(Errc::invalid_argument, "ARAP: no constrained vertices; the shape would float freely");
  if (targets_m.rows() != static_cast<Eigen::Index>(constrained.size())) {
    return make_error(Errc::invalid_argument, "ARAP: " + std::to_string(constrained.size()) +
                                                  " constrained vertices but " + std::to_string(targets_m.rows()) +
                                                  " targets");
  }
  if (!targets_m.allFinite()) return make_error(Errc::invalid_argument, "ARAP: a target position is NaN or infinite");
  {
    std::vector<std::uint32_t> sorted = constrained;
    std::sort(sorted.begin(), sorted.end());
    if (sorted.back() >= n)
      return make_error(Errc::invalid_argument,
                        "ARAP: constrained vertex " + std::to_string(sorted.back()) + " of " + std::to_string(n));
    if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) {
      return make_error(Errc::invalid_argument, "ARAP: a vertex is constrained twice");
    }
  }
  bool refactored = false;
  auto fr = m.factor_for(constrained, refactored);
  if (!fr) return fr.error();
  const Factor& f = **fr;

  if (V.rows() != static_cast<Eigen::Index>(n) || !V.allFinite()) {
    Eigen::MatrixX3d from(static_cast<Eigen::Index>(constrained.size()), 3);
    for (std::size_t k = 0; k < constrained.size(); ++k)
      from.row(static_cast<Eigen::Index>(k)) = m.rest.row(constrained[k]);
    auto T = fit_rigid(from, targets_m);
    if (T) {
      V = (m.rest * T->linear().transpose()).rowwise() + T->translation().transpose();
    } else {
      V = m.rest.rowwise() + (targets_m.colwise().mean() - from.colwise().mean());
    }
  }
  for (std::size_t k = 0; k < constrained.size(); ++k)
    V.row(constrained[k]) = targets_m.row(static_cast<Eigen::Index>(k));

  const Eigen::MatrixX3d lc = f.L_fc * targets_m;
  int it = 0;
  double step = 0.0;
  for (; it < m.options.max_iterations && !f.free_vertices.empty(); ++it) {
    m.local_step(V);
    for (std::size_t i = 0; i < n; ++i) {
      Eigen::Vector3d bi = Eigen::Vector3d::Zero();
      for (auto k = m.off[i]; k < m.off[i + 1]; ++k) {
        const std::uint32_t j = m.nbr[static_cast<std::size_t>(k)];
        bi += (0.5 * m.w[static_cast<std::size_t>(k)]) *
              ((m.R[i] + m.R[j]) * (m.rest.row(static_cast<Eigen::Index>(i)) - m.rest.row(j)).transpose());
      }
      m.b.row(static_cast<Eigen::Index>(i)) = bi.transpose();
    }
    m.rhs_f.resize(static_cast<Eigen::Index>(f.free_vertices.size()), 3);
    for (std::size_t r = 0; r < f.free_vertices.size(); ++r)
      m.rhs_f.row(static_cast<Eigen::Index>(r)) = m.b.row(f.free_vertices[r]);
    m.rhs_f -= lc;
    const Eigen::MatrixX3d x = f.ldlt.solve(m.rhs_f);
    step = 0.0;
    for (std::size_t r = 0; r < f.free_vertices.size(); ++r) {
      const auto v = static_cast<Eigen::Index>(f.free_vertices[r]);
      step = std::max(step, (x.row(static_cast<Eigen::Index>(r)) - V.row(v)).norm());
      V.row(v) = x.row(static_cast<Eigen::Index>(r));
    }
    if (step <= m.options.tolerance_m) {
      ++it;
      break;
    }
  }
  if (!V.allFinite())
    return make_error(Errc::invalid_argument, "ARAP: the solution is not finite (a degenerate mesh?)");
  if (stats) *stats = ArapStats{it, step, refactored};
  return {};
}

double ArapDeformer::energy(const Eigen::MatrixX3d& V) const {
  Impl& m = *impl_;
  m.local_step(V);
  double e = 0.0;
  for (std::size_t i = 0; i < static_cast<std::size_t>(m.rest.rows()); ++i) {
    for (auto k = m.off[i]; k < m.off[i + 1]; ++k) {
      const std::uint32_t j = m.nbr[static_cast<std::size_t>(k)];
      const Eigen::Vector3d d = (V.row(static_cast<Eigen::Index>(i)) - V.row(j)).transpose() -
                                m.R[i] * (m.rest.row(static_cast<Eigen::Index>(i)) - m.rest.row(j)).transpose();
      e += m.w[static_cast<std::size_t>(k)] * d.squaredNorm();
    }
  }
  return e;
}

const Eigen::MatrixX3d& ArapDeformer::rest() const noexcept { return impl_->rest; }
std::size_t ArapDeformer::vertex_count() const noexcept { return static_cast<std::size_t>(impl_->rest.rows()); }
std::size_t ArapDeformer::cached_factorisations() const noexcept { return impl_->cache.size(); }

}  // namespace proprio::stretch_array_recon
