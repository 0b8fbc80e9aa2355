#pragma once
// The sheet's mechanics and the per-step measures read downstream (issue 30).
//
// Model: an incompressible neo-Hookean membrane in plane stress. With F the
// 3x2 deformation gradient of a triangle (rest sheet -> deformed), C = F^T F,
// the thickness follows from incompressibility (h' = h / sqrt(det C)) and the
// strain energy per triangle is
//     W = (mu h A0 / 2) (tr C + 1 / det C - 3),   mu = E / 3.
// Uniaxial tension gives lateral stretch 1/sqrt(lambda) and area ratio
// sqrt(lambda) (tests/unit/input/elastic_sheet/test_membrane.cpp checks it).
// W grows without bound as a triangle collapses (det C -> 0), which keeps the
// solver away from inverted triangles without a separate guard.
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "proprio/core/result.hpp"
#include "proprio/elastic_sheet/body_proxy.hpp"
#include "proprio/stretch_array/sheet_mesh.hpp"

namespace proprio::elastic_sheet {

using stretch_array::SheetMesh;

struct MembraneMaterial {
  double youngs_modulus_pa = 0.85e6;  // layout.sheet.youngs_modulus_pa
  double thickness_m = 2.0e-3;        // layout.sheet.total_thickness_m
  double shear_modulus_pa() const noexcept { return youngs_modulus_pa / 3.0; }
  Status validate() const;
  std::string describe() const;
};

// Rest-state quantities of the mesh the energy needs, computed once.
class Membrane {
 public:
  static Result<Membrane> create(const SheetMesh& mesh, const MembraneMaterial& material);

  // Total strain energy (J) of the deformed vertices; +inf when a triangle
  // has collapsed. With `gradient`, also dE/dx per vertex (resized).
  double energy(const std::vector<Vec3>& vertices_m, std::vector<Vec3>* gradient = nullptr) const;

  std::size_t vertex_count() const noexcept { return vertex_count_; }
  std::size_t triangle_count() const noexcept { return triangles_.size(); }
  const std::vector<std::array<std::uint32_t, 3>>& triangles() const noexcept { return triangles_; }
  // Rest area per triangle and lumped per vertex (a third of each neighbour).
  const std::vector<double>& rest_triangle_area_m2() const noexcept { return rest_area_; }
  const std::vector<double>& rest_vertex_area_m2() const noexcept { return vertex_area_; }
  // Rest shape-function gradients per triangle: rows 0..2 for the corners.
  const std::vector<Eigen::Matrix<double, 3, 2>>& shape_gradients() const noexcept { return grad_n_; }
  const MembraneMaterial& material() const noexcept { return material_; }

 private:
  std::size_t vertex_count_ = 0;
  std::vector<std::array<std::uint32_t, 3>> triangles_;
  std::vector<Eigen::Matrix2d> rest_inverse_;  // Dm^-1
  std::vector<Eigen::Matrix<double, 3, 2>> grad_n_;
  std::vector<double> rest_area_, vertex_area_;
  MembraneMaterial material_;
};

// Per-triangle measures of a deformed sheet (same order as mesh.triangles).
std::vector<double> triangle_areas_m2(const SheetMesh& mesh, const std::vector<Vec3>& vertices_m);
// Deformed over rest area (= sqrt(det C)).
std::vector<double> triangle_area_ratios(const SheetMesh& mesh, const std::vector<Vec3>& vertices_m);
// The largest principal stretch sqrt(lambda_max(C)), for over-stretch effects.
std::vector<double> triangle_max_principal_stretch(const SheetMesh& mesh, const std::vector<Vec3>& vertices_m);

// A material point of the rest sheet (a marker sits on one): its triangle
// and barycentric weights, found once on the rest mesh.
struct MaterialPoint {
  std::uint32_t triangle = 0;
  Vec3 barycentric = Vec3::Zero();
};
// Refuses points outside the sheet (with the distance to it).
Result<MaterialPoint> locate_material_point(const SheetMesh& mesh, const Eigen::Vector2d& rest_xy_m);
Vec3 material_point_position_m(const SheetMesh& mesh, const std::vector<Vec3>& vertices_m, const MaterialPoint& point);

}  // namespace proprio::elastic_sheet
