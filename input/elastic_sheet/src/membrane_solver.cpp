// L-BFGS with a Laplacian initial Hessian (see membrane_solver.hpp).
#include "membrane_solver.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>

namespace proprio::elastic_sheet::detail {

Status MembraneSolver::init(const Membrane& membrane, const std::vector<std::uint8_t>& pinned,
                            const std::vector<double>& spring_k) {
  const std::size_t n = membrane.vertex_count();
  if (pinned.size() != n || spring_k.size() != n) {
    return make_error(Errc::invalid_argument, "solver: pinned and spring lists must have one entry per vertex");
  }
  pinned_ = pinned;
  spring_k_ = spring_k;
  const double two_mu_h = 2.0 * membrane.material().shear_modulus_pa() * membrane.material().thickness_m;
  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(membrane.triangle_count() * 9 + n);
  bool any_anchor = false;
  for (std::size_t t = 0; t < membrane.triangle_count(); ++t) {
    const auto& tri = membrane.triangles()[t];
    const auto& g = membrane.shape_gradients()[t];
    const double w = two_mu_h * membrane.rest_triangle_area_m2()[t];
    for (int a = 0; a < 3; ++a) {
      if (pinned[tri[a]]) continue;
      for (int b = 0; b < 3; ++b) {
        if (pinned[tri[b]]) continue;
        trip.emplace_back(tri[a], tri[b], w * g.row(a).dot(g.row(b)));
      }
    }
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (pinned[i]) {
      trip.emplace_back(i, i, 1.0);
      any_anchor = true;
    } else {
      trip.emplace_back(i, i, spring_k[i]);
      if (spring_k[i] > 0.0) any_anchor = true;
    }
  }
  if (!any_anchor) {
    return make_error(Errc::invalid_argument,
                      "solver: the sheet is neither pinned nor held by friction; it would drift (pin a vertex or set a friction stiffness)");
  }
  Eigen::SparseMatrix<double> k(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n));
  k.setFromTriplets(trip.begin(), trip.end());
  ldlt_.compute(k);
  if (ldlt_.info() != Eigen::Success) {
    return make_error(Errc::invalid_argument, "solver: the sheet's stiffness could not be factored (a vertex without triangles?)");
  }
  rhs_.resize(static_cast<Eigen::Index>(n), 2);
  sol_.resize(static_cast<Eigen::Index>(n), 2);
  return Status::success();
}

void MembraneSolver::precondition(const Eigen::VectorXd& g, Eigen::VectorXd& out) const {
  const Eigen::Index n = static_cast<Eigen::Index>(pinned_.size());
  auto& rhs = rhs_;
  auto& sol = sol_;
  for (Eigen::Index i = 0; i < n; ++i) {
    rhs(i, 0) = g[2 * i];
    rhs(i, 1) = g[2 * i + 1];
  }
  sol = ldlt_.solve(rhs);
  out.resize(2 * n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const bool p = pinned_[static_cast<std::size_t>(i)] != 0;
    out[2 * i] = p ? 0.0 : sol(i, 0);
    out[2 * i + 1] = p ? 0.0 : sol(i, 1);
  }
}

double MembraneSolver::evaluate(const Membrane& membrane, const LinearisedSurface& s, const std::vector<Vec3>& target,
                                const Eigen::VectorXd& q, Eigen::VectorXd* g, std::vector<Vec3>* membrane_gradient) {
  const std::size_t n = membrane.vertex_count();
  x_.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec2 dq(q[2 * i] - s.q0[i].x(), q[2 * i + 1] - s.q0[i].y());
    x_[i] = s.x0[i] + s.jacobian[i] * dq;
  }
  double e = membrane.energy(x_, g ? &gx_ : nullptr);
  if (!std::isfinite(e)) return e;
  if (g) g->resize(2 * static_cast<Eigen::Index>(n));
  for (std::size_t i = 0; i < n; ++i) {
    Vec3 gi = g ? gx_[i] : Vec3::Zero();
    if (spring_k_[i] > 0.0) {
      const Vec3 d = x_[i] - target[i];
      e += 0.5 * spring_k_[i] * d.squaredNorm();
      if (g) gi += spring_k_[i] * d;
    }
    if (g) {
      const Vec2 gq = pinned_[i] ? Vec2::Zero() : Vec2(s.jacobian[i].transpose() * gi);
      (*g)[2 * i] = gq.x();
      (*g)[2 * i + 1] = gq.y();
    }
  }
  if (membrane_gradient && g) *membrane_gradient = gx_;
  return e;
}

SolveOutcome MembraneSolver::solve(const Membrane& membrane, const LinearisedSurface& s, const std::vector<Vec3>& target,
                                   std::vector<Vec2>& q_io, int max_iterations, double tolerance_m, double max_step_m,
                                   std::vector<Vec3>* membrane_gradient) {
  const std::size_t n = membrane.vertex_count();
  Eigen::VectorXd q(2 * static_cast<Eigen::Index>(n));
  for (std::size_t i = 0; i < n; ++i) {
    q[2 * i] = q_io[i].x();
    q[2 * i + 1] = q_io[i].y();
  }
  SolveOutcome out;
  Eigen::VectorXd g, g_new, q_new, d, r;
  double f = evaluate(membrane, s, target, q, &g, nullptr);
  if (!std::isfinite(f)) {
    out.line_search_failed = true;
    out.energy_j = f;
    return out;
  }
  struct Pair { Eigen::VectorXd s, y; double rho; };
  std::deque<Pair> memory;
  constexpr std::size_t kMemory = 8;
  std::vector<double> alpha_k;
  for (int it = 0; it < max_iterations; ++it) {
    // Two-loop recursion with H0 = gamma K^-1.
    d = g;
    alpha_k.assign(memory.size(), 0.0);
    for (std::size_t k = memory.size(); k-- > 0;) {
      alpha_k[k] = memory[k].rho * memory[k].s.dot(d);
      d -= alpha_k[k] * memory[k].y;
    }
    // H0 = K^-1 unscaled: K is the rest stiffness itself, so it already has
    // the right units and scale (and skipping the usual gamma saves a solve).
    precondition(d, r);
    for (std::size_t k = 0; k < memory.size(); ++k) {
      const double beta = memory[k].rho * memory[k].y.dot(r);
      r += (alpha_k[k] - beta) * memory[k].s;
    }
    d = -r;
    double slope = g.dot(d);
    if (!(slope < 0.0)) {  // memory gone bad: restart from the Laplacian step
      memory.clear();
      precondition(g, r);
      d = -r;
      slope = g.dot(d);
      if (!(slope < 0.0)) {
        out.converged = true;
        break;
      }
    }
    double step_inf = d.cwiseAbs().maxCoeff();
    out.remaining_step_m = step_inf;
    if (step_inf < tolerance_m) {
      out.converged = true;
      break;
    }
    if (step_inf > max_step_m) {
      d *= max_step_m / step_inf;
      slope *= max_step_m / step_inf;
    }
    double a = 1.0, f_new = 0.0;
    bool accepted = false;
    for (int ls = 0; ls < 30; ++ls) {
      q_new = q + a * d;
      // With the gradient: the full step is accepted almost always, and the
      // gradient then costs less than a second pass over the triangles.
      f_new = evaluate(membrane, s, target, q_new, &g_new, nullptr);
      if (std::isfinite(f_new) && f_new <= f + 1e-4 * a * slope) {
        accepted = true;
        break;
      }
      a *= 0.5;
    }
    ++out.iterations;
    if (!accepted) {
      out.line_search_failed = true;
      break;
    }
    Pair p{q_new - q, g_new - g, 0.0};
    const double sy = p.s.dot(p.y);
    if (sy > 1e-300) {
      p.rho = 1.0 / sy;
      memory.push_back(std::move(p));
      if (memory.size() > kMemory) memory.pop_front();
    }
    q.swap(q_new);
    g.swap(g_new);
    f = f_new;
  }
  out.energy_j = f;
  if (membrane_gradient) evaluate(membrane, s, target, q, &g, membrane_gradient);
  for (std::size_t i = 0; i < n; ++i) q_io[i] = Vec2(q[2 * i], q[2 * i + 1]);
  return out;
}

}  // namespace proprio::elastic_sheet::detail
