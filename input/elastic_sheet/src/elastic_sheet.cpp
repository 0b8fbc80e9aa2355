// The sheet on a moving body (see elastic_sheet.hpp).
#include "proprio/elastic_sheet/elastic_sheet.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/Geometry>

#include "membrane_solver.hpp"

namespace proprio::elastic_sheet {

namespace {

constexpr int kSettleRounds = 200;

double sheet_uniform(std::uint64_t& state, double lo, double hi) {
  std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return lo + (hi - lo) * (static_cast<double>(z >> 11) * 0x1.0p-53);
}

}  // namespace

Status SheetPlacement::validate() const {
  for (double v : {axial_offset_m, around_angle_rad, inplane_rotation_rad, prestretch_around, prestretch_along}) {
    if (!std::isfinite(v)) return make_error(Errc::invalid_argument, "sheet placement has a non-finite value");
  }
  if (prestretch_around < 0.8 || prestretch_around > 1.5 || prestretch_along < 0.8 || prestretch_along > 1.5) {
    return make_error(Errc::invalid_argument,
                      "sheet placement pre-stretch must be within 0.8-1.5 (a tight sleeve is ~1.05 around the limb)");
  }
  return Status::success();
}

std::string SheetPlacement::describe() const {
  std::ostringstream s;
  s << "placement: " << axial_offset_m * 1e3 << " mm along, " << around_angle_rad * 180.0 / M_PI << " deg around, "
    << inplane_rotation_rad * 180.0 / M_PI << " deg turned, pre-stretch " << prestretch_around << " x "
    << prestretch_along;
  return s.str();
}

SheetPlacement SheetPlacement::redonned(std::uint64_t seed, double max_offset_m, double max_angle_rad,
                                        double max_rotation_rad) const {
  std::uint64_t state = seed * 0xD1B54A32D192ED03ull + 99;
  SheetPlacement p = *this;
  p.axial_offset_m += sheet_uniform(state, -max_offset_m, max_offset_m);
  p.around_angle_rad += sheet_uniform(state, -max_angle_rad, max_angle_rad);
  p.inplane_rotation_rad += sheet_uniform(state, -max_rotation_rad, max_rotation_rad);
  return p;
}

Status FrictionOptions::validate() const {
  if (!(stiffness_pa_per_m > 0.0) || !std::isfinite(stiffness_pa_per_m)) {
    return make_error(Errc::invalid_argument, "friction stiffness_pa_per_m must be positive (default 5e7 N/m^3)");
  }
  if (!(friction_coefficient >= 0.0) || !(adhesion_pa >= 0.0)) {
    return make_error(Errc::invalid_argument, "friction_coefficient and adhesion_pa must be >= 0");
  }
  return Status::success();
}

Status SheetSolverOptions::validate() const {
  if (max_iterations < 1 || max_iterations > 100000) {
    return make_error(Errc::invalid_argument, "solver max_iterations must be 1-100000");
  }
  if (!(tolerance_m > 0.0) || !(max_step_m > 0.0) || slip_passes < 0 || slip_passes > 10) {
    return make_error(Errc::invalid_argument, "solver: tolerance_m and max_step_m must be positive, slip_passes 0-10");
  }
  return Status::success();
}

Status ElasticSheetOptions::validate() const {
  if (auto s = material.validate(); !s) return s;
  if (auto s = placement.validate(); !s) return s;
  if (auto s = friction.validate(); !s) return s;
  return solver.validate();
}

std::string ElasticSheetOptions::describe() const {
  std::ostringstream s;
  s << material.describe() << "; " << placement.describe() << "; friction k=" << friction.stiffness_pa_per_m
    << " N/m^3, mu_f=" << friction.friction_coefficient << ", adhesion " << friction.adhesion_pa << " Pa, slip "
    << (friction.slip ? "on" : "off") << "; solver <= " << solver.max_iterations << " iterations, tol "
    << solver.tolerance_m * 1e6 << " um";
  return s.str();
}

ElasticSheetOptions ElasticSheetOptions::from_layout(const stretch_array::StripArrayLayout& layout) {
  ElasticSheetOptions o;
  o.material.youngs_modulus_pa = layout.sheet.youngs_modulus_pa;
  o.material.thickness_m = layout.sheet.total_thickness_m;
  return o;
}

ElasticSheet::ElasticSheet(ElasticSheet&&) noexcept = default;
ElasticSheet& ElasticSheet::operator=(ElasticSheet&&) noexcept = default;
ElasticSheet::~ElasticSheet() = default;

Result<ElasticSheet> ElasticSheet::create(SheetMesh mesh, std::shared_ptr<const BodyProxy> body,
                                          const ElasticSheetOptions& options) {
  if (!body) return make_error(Errc::invalid_argument, "elastic sheet: no body proxy given (make_body())");
  if (auto v = options.validate(); !v) return v.error().with_context("elastic sheet options");
  auto membrane = Membrane::create(mesh, options.material);
  if (!membrane) return membrane.error();

  ElasticSheet s;
  s.mesh_ = std::move(mesh);
  s.body_ = std::move(body);
  s.options_ = options;
  s.membrane_ = std::make_unique<Membrane>(std::move(*membrane));
  const std::size_t n = s.mesh_.vertices_m.size();

  Eigen::Vector2d lo = s.mesh_.vertices_m[0], hi = lo;
  for (const auto& p : s.mesh_.vertices_m) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Eigen::Vector2d centre = 0.5 * (lo + hi);
  const auto& pl = options.placement;
  const Eigen::Rotation2Dd turn(pl.inplane_rotation_rad);
  const Vec2 site = s.body_->default_site_uv_m() +
                    Vec2(s.body_->rest_radius_m() * pl.around_angle_rad, pl.axial_offset_m);
  s.q_.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d d = turn * (s.mesh_.vertices_m[i] - centre);
    s.q_[i] = site + Vec2(d.x() * pl.prestretch_around, d.y() * pl.prestretch_along);
  }
  s.anchor_ = s.q_;
  s.donned_ = s.q_;
  s.spring_k_.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    s.spring_k_[i] = options.friction.stiffness_pa_per_m * s.membrane_->rest_vertex_area_m2()[i];
  }
  s.solver_ = std::make_unique<detail::MembraneSolver>();
  if (auto st = s.solver_->init(*s.membrane_, std::vector<std::uint8_t>(n, 0), s.spring_k_); !st) return st.error();
  s.x_.resize(n);
  for (std::size_t i = 0; i < n; ++i) s.x_[i] = s.body_->skin_point_m(s.q_[i], 0.0);
  // The donned state: stuck where it was put, in equilibrium with the skin.
  auto first = s.solve_at(0.0, options.solver.max_iterations * 5);
  if (!first) return first.error().with_context("while donning the sheet");
  // Settle: where the pre-stretch pulls harder than friction holds (near the
  // free edges) the sheet creeps until it holds -- as a sleeve settles when
  // it is smoothed on. Motion then starts from a state that sticks.
  for (int k = 0; k < kSettleRounds && options.friction.slip && s.stats_.max_slip_m > options.solver.tolerance_m; ++k) {
    auto more = s.solve_at(0.0, options.solver.max_iterations * 2);
    if (!more) return more.error().with_context("while settling the donned sheet");
  }
  return s;
}

Result<SheetStepStats> ElasticSheet::step(double t_s) {
  if (!std::isfinite(t_s)) return make_error(Errc::invalid_argument, "elastic sheet step: time is not finite");
  return solve_at(t_s, options_.solver.max_iterations);
}

Result<SheetStepStats> ElasticSheet::solve_at(double t, int max_iterations) {
  const std::size_t n = q_.size();
  const BodyProxy& body = *body_;
  detail::LinearisedSurface lin;
  lin.x0.resize(n);
  lin.jacobian.resize(n);
  std::vector<Vec3> target(n), membrane_gradient;
  SheetStepStats stats;
  stats.converged = true;
  constexpr double h = 1e-7;  // forward differences (see BodyProxy::skin_jacobian)
  constexpr double kCountedSlide = 1e-7;  // slides below 0.1 um are not reported as slip
  {
    std::vector<Vec2> shifted(n);
    std::vector<Vec3> xu, xv;
    body.skin_points_m(q_, t, lin.x0);
    for (std::size_t i = 0; i < n; ++i) shifted[i] = q_[i] + Vec2(h, 0.0);
    body.skin_points_m(shifted, t, xu);
    for (std::size_t i = 0; i < n; ++i) shifted[i] = q_[i] + Vec2(0.0, h);
    body.skin_points_m(shifted, t, xv);
    for (std::size_t i = 0; i < n; ++i) {
      lin.jacobian[i].col(0) = (xu[i] - lin.x0[i]) / h;
      lin.jacobian[i].col(1) = (xv[i] - lin.x0[i]) / h;
    }
  }
  lin.q0 = q_;
  const auto& fr = options_.friction;
  const auto& sv = options_.solver;
  for (int pass = 0; pass <= sv.slip_passes; ++pass) {
    body.skin_points_m(anchor_, t, target);
    const auto out = solver_->solve(*membrane_, lin, target, q_, max_iterations, sv.tolerance_m, sv.max_step_m,
                                    &membrane_gradient);
    stats.iterations += out.iterations;
    stats.energy_j = out.energy_j;
    stats.converged = stats.converged && out.converged;
    if (!std::isfinite(out.energy_j)) {
      return make_error(Errc::out_of_range, "elastic sheet: a triangle collapsed at t=" + std::to_string(t) +
                                                " s; take smaller time steps or a finer mesh");
    }
    body.skin_points_m(q_, t, x_);
    if (!fr.slip) break;
    // Return mapping of the friction springs: anchors slide until each spring
    // sits at its Coulomb limit.
    std::size_t slipping = 0;
    double pass_max_slip = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const Vec3 normal = lin.jacobian[i].col(0).cross(lin.jacobian[i].col(1)).normalized();
      Vec3 d = x_[i] - target[i];
      d -= d.dot(normal) * normal;
      const double force = spring_k_[i] * d.norm();
      const double pressing = std::max(0.0, membrane_gradient[i].dot(normal));
      const double limit = fr.friction_coefficient * pressing + fr.adhesion_pa * membrane_->rest_vertex_area_m2()[i];
      if (force > limit) {
        const Vec2 old = anchor_[i];
        anchor_[i] = q_[i] + (anchor_[i] - q_[i]) * (limit / force);
        const double slide = (anchor_[i] - old).norm();
        pass_max_slip = std::max(pass_max_slip, slide);
        if (slide > kCountedSlide) ++slipping;
      }
    }
    stats.slipping_vertices = std::max(stats.slipping_vertices, slipping);
    stats.max_slip_m = std::max(stats.max_slip_m, pass_max_slip);
    // Re-solve only where the slide matters at the solver's own precision.
    if (pass_max_slip < sv.tolerance_m || pass == sv.slip_passes) break;
    // Re-linearise at the new state, keeping the Jacobians: q moved by
    // microns to millimetres, and the exact map is applied after the solve.
    lin.x0 = x_;
    lin.q0 = q_;
  }
  t_s_ = t;
  stats_ = stats;
  return stats;
}

}  // namespace proprio::elastic_sheet
