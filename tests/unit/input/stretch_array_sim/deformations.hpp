#pragma once
// Analytic deformations of a flat array sheet, for the simulator's tests
// (the elastic-sheet simulator is another module's).
#include <cmath>
#include <vector>

#include <Eigen/Core>

#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_array/sheet_mesh.hpp"
#include "proprio/stretch_array_sim/array_sheet.hpp"

namespace proprio::stretch_array_sim::testing {

inline stretch_array::SheetMesh mesh_of(const stretch_array::StripArrayLayout& L, double max_edge_m = 0.003) {
  stretch_array::SheetMeshOptions o;
  o.max_edge_m = max_edge_m;
  return *stretch_array::build_sheet_mesh(L, o);
}

inline ArraySheet sheet_of(const stretch_array::StripArrayLayout& L, double max_edge_m = 0.003) {
  return *ArraySheet::create(L, mesh_of(L, max_edge_m));
}

template <typename F>
std::vector<Eigen::Vector3d> deform(const ArraySheet& s, F f) {
  std::vector<Eigen::Vector3d> out;
  for (const auto& p : s.mesh().vertices_m) out.push_back(f(p));
  return out;
}

// Equal stretch in x and y (area lambda^2).
inline std::vector<Eigen::Vector3d> uniform_stretch(const ArraySheet& s, double lambda) {
  return deform(s, [&](const Eigen::Vector2d& p) { return Eigen::Vector3d(lambda * p.x(), lambda * p.y(), 0.0); });
}
// Stretched along x, free to contract: width and thickness shrink alike.
inline std::vector<Eigen::Vector3d> uniaxial_stretch(const ArraySheet& s, double lambda) {
  return deform(s, [&](const Eigen::Vector2d& p) { return Eigen::Vector3d(lambda * p.x(), p.y() / std::sqrt(lambda), 0.0); });
}
// Rolled around an axis along y, radius r: no stretch at all.
inline std::vector<Eigen::Vector3d> cylinder(const ArraySheet& s, double radius_m) {
  return deform(s, [&](const Eigen::Vector2d& p) {
    return Eigen::Vector3d(radius_m * std::sin(p.x() / radius_m), p.y(), radius_m * (1.0 - std::cos(p.x() / radius_m)));
  });
}
// A Gaussian bump of height h and width sigma at c.
inline std::vector<Eigen::Vector3d> bump(const ArraySheet& s, Eigen::Vector2d c, double h_m, double sigma_m) {
  return deform(s, [&](const Eigen::Vector2d& p) {
    return Eigen::Vector3d(p.x(), p.y(), h_m * std::exp(-(p - c).squaredNorm() / (2 * sigma_m * sigma_m)));
  });
}
// A sheet pulled harder on one side than the other (strings on clips): the
// stretch along x grows from 1 at the low edge to 1 + 2a at the high edge,
// along y from 1 to 1 + 2b, and the y stretch depends on x too.
inline std::vector<Eigen::Vector3d> graded_stretch(const ArraySheet& s, double a, double b) {
  Eigen::Vector2d lo = s.mesh().vertices_m.front(), hi = lo;
  for (const auto& p : s.mesh().vertices_m) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Eigen::Vector2d size = hi - lo;
  return deform(s, [&](const Eigen::Vector2d& p) {
    const Eigen::Vector2d u = (p - lo).cwiseQuotient(size);
    const double bx = b * (0.5 + u.x());
    return Eigen::Vector3d(lo.x() + (p.x() - lo.x()) * (1 + a * u.x()), lo.y() + (p.y() - lo.y()) * (1 + bx * u.y()), 0.0);
  });
}

}  // namespace proprio::stretch_array_sim::testing
