// The incompressible neo-Hookean membrane (see membrane.hpp) and the
// per-triangle measures.
#include "proprio/elastic_sheet/membrane.hpp"

#include <cmath>
#include <limits>
#include <sstream>

#include <Eigen/Eigenvalues>

namespace proprio::elastic_sheet {

Status MembraneMaterial::validate() const {
  if (!(youngs_modulus_pa > 0.0) || !std::isfinite(youngs_modulus_pa)) {
    return make_error(Errc::invalid_argument, "membrane youngs_modulus_pa must be positive (silicone: 0.73e6-0.98e6)");
  }
  if (!(thickness_m > 0.0) || thickness_m > 0.05) {
    return make_error(Errc::invalid_argument, "membrane thickness_m must be in (0, 0.05] m (the sheet: ~2e-3)");
  }
  return Status::success();
}

std::string MembraneMaterial::describe() const {
  std::ostringstream s;
  s << "neo-Hookean membrane E=" << youngs_modulus_pa * 1e-6 << " MPa (mu=" << shear_modulus_pa() * 1e-6
    << " MPa), h=" << thickness_m * 1e3 << " mm";
  return s.str();
}

Result<Membrane> Membrane::create(const SheetMesh& mesh, const MembraneMaterial& material) {
  if (auto v = material.validate(); !v) return v.error();
  if (mesh.vertices_m.empty() || mesh.triangles.empty()) {
    return make_error(Errc::invalid_argument, "the sheet mesh is empty; build it with build_sheet_mesh(layout)");
  }
  Membrane m;
  m.material_ = material;
  m.vertex_count_ = mesh.vertices_m.size();
  m.triangles_ = mesh.triangles;
  m.rest_inverse_.resize(mesh.triangles.size());
  m.grad_n_.resize(mesh.triangles.size());
  m.rest_area_.resize(mesh.triangles.size());
  m.vertex_area_.assign(m.vertex_count_, 0.0);
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    for (auto i : tri) {
      if (i >= m.vertex_count_) {
        return make_error(Errc::invalid_argument, "sheet mesh triangle " + std::to_string(t) + " names a vertex out of range");
      }
    }
    Eigen::Matrix2d dm;
    dm.col(0) = mesh.vertices_m[tri[1]] - mesh.vertices_m[tri[0]];
    dm.col(1) = mesh.vertices_m[tri[2]] - mesh.vertices_m[tri[0]];
    const double det = dm.determinant();
    if (!(det > 1e-14)) {
      return make_error(Errc::invalid_argument, "sheet mesh triangle " + std::to_string(t) +
                                                    " is degenerate or clockwise on the rest sheet");
    }
    m.rest_inverse_[t] = dm.inverse();
    m.rest_area_[t] = 0.5 * det;
    // Shape-function gradients: rows of [-1 -1; 1 0; 0 1] * Dm^-1.
    Eigen::Matrix<double, 3, 2> sel;
    sel << -1, -1, 1, 0, 0, 1;
    m.grad_n_[t] = sel * m.rest_inverse_[t];
    for (auto i : tri) m.vertex_area_[i] += m.rest_area_[t] / 3.0;
  }
  return m;
}

double Membrane::energy(const std::vector<Vec3>& x, std::vector<Vec3>* gradient) const {
  const double mu_h = material_.shear_modulus_pa() * material_.thickness_m;
  if (gradient) gradient->assign(vertex_count_, Vec3::Zero());
  double total = 0.0;
  for (std::size_t t = 0; t < triangles_.size(); ++t) {
    const auto& tri = triangles_[t];
    Eigen::Matrix<double, 3, 2> ds;
    ds.col(0) = x[tri[1]] - x[tri[0]];
    ds.col(1) = x[tri[2]] - x[tri[0]];
    const Eigen::Matrix<double, 3, 2> f = ds * rest_inverse_[t];
    const double c00 = f.col(0).squaredNorm(), c11 = f.col(1).squaredNorm(), c01 = f.col(0).dot(f.col(1));
    const double det_c = c00 * c11 - c01 * c01;
    if (!(det_c > 1e-10)) return std::numeric_limits<double>::infinity();
    const double k = 0.5 * mu_h * rest_area_[t];
    total += k * (c00 + c11 + 1.0 / det_c - 3.0);
    if (gradient) {
      // dW/dF = mu h A0 (F - F C^-1 / det C), C^-1 = adj(C) / det C.
      Eigen::Matrix2d adj;
      adj << c11, -c01, -c01, c00;
      const Eigen::Matrix<double, 3, 2> p = (2.0 * k) * (f - f * adj / (det_c * det_c));
      const Eigen::Matrix<double, 3, 2> h = p * rest_inverse_[t].transpose();
      (*gradient)[tri[1]] += h.col(0);
      (*gradient)[tri[2]] += h.col(1);
      (*gradient)[tri[0]] -= h.col(0) + h.col(1);
    }
  }
  return total;
}

namespace {

// C = F^T F of triangle t of the mesh, deformed.
Eigen::Matrix2d membrane_cauchy_green(const SheetMesh& mesh, const std::vector<Vec3>& x, std::size_t t) {
  const auto& tri = mesh.triangles[t];
  Eigen::Matrix2d dm;
  dm.col(0) = mesh.vertices_m[tri[1]] - mesh.vertices_m[tri[0]];
  dm.col(1) = mesh.vertices_m[tri[2]] - mesh.vertices_m[tri[0]];
  Eigen::Matrix<double, 3, 2> ds;
  ds.col(0) = x[tri[1]] - x[tri[0]];
  ds.col(1) = x[tri[2]] - x[tri[0]];
  const Eigen::Matrix<double, 3, 2> f = ds * dm.inverse();
  return f.transpose() * f;
}

}  // namespace

std::vector<double> triangle_areas_m2(const SheetMesh& mesh, const std::vector<Vec3>& x) {
  std::vector<double> out(mesh.triangles.size(), 0.0);
  if (x.size() != mesh.vertices_m.size()) return out;
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    out[t] = 0.5 * (x[tri[1]] - x[tri[0]]).cross(x[tri[2]] - x[tri[0]]).norm();
  }
  return out;
}

std::vector<double> triangle_area_ratios(const SheetMesh& mesh, const std::vector<Vec3>& x) {
  std::vector<double> out(mesh.triangles.size(), 0.0);
  if (x.size() != mesh.vertices_m.size()) return out;
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    out[t] = std::sqrt(std::max(0.0, membrane_cauchy_green(mesh, x, t).determinant()));
  }
  return out;
}

std::vector<double> triangle_max_principal_stretch(const SheetMesh& mesh, const std::vector<Vec3>& x) {
  std::vector<double> out(mesh.triangles.size(), 0.0);
  if (x.size() != mesh.vertices_m.size()) return out;
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Eigen::Matrix2d c = membrane_cauchy_green(mesh, x, t);
    // Largest eigenvalue of a symmetric 2x2 in closed form.
    const double mean = 0.5 * (c(0, 0) + c(1, 1));
    const double diff = 0.5 * (c(0, 0) - c(1, 1));
    out[t] = std::sqrt(mean + std::sqrt(diff * diff + c(0, 1) * c(0, 1)));
  }
  return out;
}

Result<MaterialPoint> locate_material_point(const SheetMesh& mesh, const Eigen::Vector2d& p) {
  double best_outside = std::numeric_limits<double>::infinity();
  MaterialPoint best;
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    const Eigen::Vector2d a = mesh.vertices_m[tri[0]], b = mesh.vertices_m[tri[1]], c = mesh.vertices_m[tri[2]];
    Eigen::Matrix2d m;
    m.col(0) = b - a;
    m.col(1) = c - a;
    const Eigen::Vector2d w = m.inverse() * (p - a);
    const Vec3 bary(1.0 - w.x() - w.y(), w.x(), w.y());
    const double outside = std::max(0.0, -bary.minCoeff());
    if (outside < best_outside) {
      best_outside = outside;
      best.triangle = static_cast<std::uint32_t>(t);
      best.barycentric = bary;
      if (outside == 0.0) break;
    }
  }
  if (best_outside > 1e-9) {
    return make_error(Errc::out_of_range, "material point (" + std::to_string(p.x()) + ", " + std::to_string(p.y()) +
                                              ") m is not on the rest sheet; markers must sit inside the mesh");
  }
  best.barycentric = best.barycentric.cwiseMax(0.0);
  best.barycentric /= best.barycentric.sum();
  return best;
}

Vec3 material_point_position_m(const SheetMesh& mesh, const std::vector<Vec3>& x, const MaterialPoint& point) {
  const auto& tri = mesh.triangles[point.triangle];
  return point.barycentric[0] * x[tri[0]] + point.barycentric[1] * x[tri[1]] + point.barycentric[2] * x[tri[2]];
}

}  // namespace proprio::elastic_sheet
