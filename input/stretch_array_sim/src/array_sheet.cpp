#include "proprio/stretch_array_sim/array_sheet.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Eigenvalues>

#include "proprio/stretch_array/capacitance.hpp"

namespace proprio::stretch_array_sim {

namespace sa = proprio::stretch_array;

namespace {

constexpr double kPieceM = 0.5e-3;  // strip centre lines are integrated in pieces of at most this

// Point location on the rest mesh: a uniform grid of buckets over the
// triangles' bounding boxes (the meshes are regular grids, so buckets hold a
// handful of triangles each).
class TriangleLocator {
 public:
  explicit TriangleLocator(const sa::SheetMesh& mesh) : mesh_(mesh) {
    lo_ = hi_ = mesh.vertices_m.front();
    for (const auto& v : mesh.vertices_m) {
      lo_ = lo_.cwiseMin(v);
      hi_ = hi_.cwiseMax(v);
    }
    n_ = std::max<int>(1, static_cast<int>(std::sqrt(static_cast<double>(mesh.triangles.size()) / 2.0)));
    size_ = (hi_ - lo_) / n_;
    size_ = size_.cwiseMax(Eigen::Vector2d(1e-9, 1e-9));
    buckets_.resize(static_cast<std::size_t>(n_ * n_));
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
      Eigen::Vector2d a = mesh.vertices_m[mesh.triangles[t][0]], b = a;
      for (int k = 1; k < 3; ++k) {
        a = a.cwiseMin(mesh.vertices_m[mesh.triangles[t][k]]);
        b = b.cwiseMax(mesh.vertices_m[mesh.triangles[t][k]]);
      }
      const auto [i0, j0] = bucket(a);
      const auto [i1, j1] = bucket(b);
      for (int i = i0; i <= i1; ++i) {
        for (int j = j0; j <= j1; ++j) buckets_[static_cast<std::size_t>(i * n_ + j)].push_back(static_cast<std::uint32_t>(t));
      }
    }
  }
  // A triangle containing p, or -1.
  long find(const Eigen::Vector2d& p) const {
    const auto [i, j] = bucket(p);
    for (std::uint32_t t : buckets_[static_cast<std::size_t>(i * n_ + j)]) {
      const auto& tri = mesh_.triangles[t];
      const Eigen::Vector2d a = mesh_.vertices_m[tri[0]], b = mesh_.vertices_m[tri[1]], c = mesh_.vertices_m[tri[2]];
      Eigen::Matrix2d E;
      E << b - a, c - a;
      const Eigen::Vector2d w = E.inverse() * (p - a);
      constexpr double tol = -1e-9;
      if (w.x() >= tol && w.y() >= tol && w.x() + w.y() <= 1.0 - tol) return static_cast<long>(t);
    }
    return -1;
  }
  const Eigen::Vector2d& lo() const { return lo_; }
  const Eigen::Vector2d& hi() const { return hi_; }

 private:
  std::pair<int, int> bucket(const Eigen::Vector2d& p) const {
    const Eigen::Vector2d q = (p - lo_).cwiseQuotient(size_);
    return {std::clamp(static_cast<int>(std::floor(q.x())), 0, n_ - 1), std::clamp(static_cast<int>(std::floor(q.y())), 0, n_ - 1)};
  }
  const sa::SheetMesh& mesh_;
  Eigen::Vector2d lo_, hi_, size_;
  int n_ = 1;
  std::vector<std::vector<std::uint32_t>> buckets_;
};

Error sheet_error(const std::string& what) { return make_error(Errc::invalid_argument, "array sheet: " + what); }

}  // namespace

Result<ArraySheet> ArraySheet::create(const sa::StripArrayLayout& layout, const sa::SheetMesh& mesh) {
  if (auto v = layout.validate(); !v) return v.error().with_context("array sheet");
  if (mesh.vertices_m.empty() || mesh.triangles.empty() || mesh.cell_of_triangle.size() != mesh.triangles.size()) {
    return sheet_error("the mesh is empty or its cell_of_triangle does not match its triangles; build it with build_sheet_mesh()");
  }
  ArraySheet s;
  s.layout_ = std::make_shared<const sa::StripArrayLayout>(layout);
  s.mesh_ = std::make_shared<const sa::SheetMesh>(mesh);
  s.eps_over_d0_ = layout.sheet.relative_permittivity * sa::kVacuumPermittivity / layout.sheet.dielectric_thickness_m;
  for (const auto& tri : mesh.triangles) {
    for (auto v : tri) {
      if (v >= mesh.vertices_m.size()) return sheet_error("a triangle names a vertex that does not exist");
    }
  }
  s.cell_triangles_ = mesh.triangles_of_cells(layout.cells.size());
  for (std::size_t c = 0; c < layout.cells.size(); ++c) {
    if (s.cell_triangles_[c].empty()) return sheet_error("cell '" + layout.cells[c].name + "' has no triangles in the mesh; was it built for this layout?");
  }
  s.triangle_rest_m2_.resize(mesh.triangles.size());
  s.rest_edges_inverse_.resize(mesh.triangles.size());
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    Eigen::Matrix2d E;
    E << mesh.vertices_m[tri[1]] - mesh.vertices_m[tri[0]], mesh.vertices_m[tri[2]] - mesh.vertices_m[tri[0]];
    s.triangle_rest_m2_[t] = 0.5 * std::abs(E.determinant());
    if (!(s.triangle_rest_m2_[t] > 1e-14)) return sheet_error("triangle " + std::to_string(t) + " is degenerate");
    s.rest_edges_inverse_[t] = E.inverse();
  }

  // Strip centre lines, from the connector end (the sheet's low edge) to the
  // far edge of each strip's last cell, cut at every cell centre.
  const TriangleLocator locator(mesh);
  auto build_path = [&](bool top, std::size_t strip, StripPath& path) -> Status {
    const sa::Strip& st = top ? layout.top_strips[strip] : layout.bottom_strips[strip];
    path.direction = top ? Eigen::Vector2d(0, 1) : Eigen::Vector2d(1, 0);
    const int axis = top ? 1 : 0;
    std::vector<std::pair<double, std::size_t>> along;  // (coordinate of the cell centre, cell)
    double end = -std::numeric_limits<double>::infinity();
    for (std::size_t c = 0; c < layout.cells.size(); ++c) {
      const auto& cell = layout.cells[c];
      if ((top ? cell.top : cell.bottom) != strip) continue;
      const double centre = layout.centroid(c)[axis];
      along.push_back({centre, c});
      const auto outline = layout.outline(c);
      for (const auto& p : outline) end = std::max(end, p[axis]);
    }
    std::sort(along.begin(), along.end());
    const double start = locator.lo()[axis] + 1e-7;
    std::vector<double> breaks = {start};
    for (const auto& a : along) breaks.push_back(a.first);
    if (along.empty()) end = start;
    breaks.push_back(std::max(end, start));
    double squares = 0.0;
    for (std::size_t i = 0; i + 1 < breaks.size(); ++i) {
      const double a = breaks[i], b = breaks[i + 1];
      if (i > 0 && i <= along.size()) {
        path.cells.push_back(along[i - 1].second);
        path.samples_before_cell.push_back(path.samples.size());
      }
      const int pieces = std::max(1, static_cast<int>(std::ceil((b - a) / kPieceM)));
      if (b - a <= 0.0) continue;
      for (int k = 0; k < pieces; ++k) {
        Eigen::Vector2d p;
        p[axis] = a + (b - a) * (k + 0.5) / pieces;
        p[1 - axis] = st.centre_m;
        const long t = locator.find(p);
        if (t < 0) {
          return sheet_error("strip '" + st.name + "' leaves the mesh at (" + std::to_string(p.x()) + ", " + std::to_string(p.y()) +
                     ") m; was the mesh built for this layout?");
        }
        path.samples.push_back({static_cast<std::uint32_t>(t), (b - a) / pieces / st.width_m});
        squares += (b - a) / pieces / st.width_m;
      }
    }
    // A cell centre at the very end of the strip (no piece after it).
    for (std::size_t i = path.cells.size(); i < along.size(); ++i) {
      path.cells.push_back(along[i].second);
      path.samples_before_cell.push_back(path.samples.size());
    }
    s.strip_rest_squares_.push_back(squares);
    return {};
  };
  s.top_paths_.resize(layout.top_strips.size());
  s.bottom_paths_.resize(layout.bottom_strips.size());
  for (std::size_t t = 0; t < layout.top_strips.size(); ++t) {
    if (auto st = build_path(true, t, s.top_paths_[t]); !st) return st.error();
  }
  for (std::size_t b = 0; b < layout.bottom_strips.size(); ++b) {
    if (auto st = build_path(false, b, s.bottom_paths_[b]); !st) return st.error();
  }
  auto rest = s.evaluate_impl(s.rest_vertices_m());
  if (!rest) return rest.error();
  s.rest_ = std::move(*rest);
  return s;
}

std::vector<Eigen::Vector3d> ArraySheet::rest_vertices_m() const {
  std::vector<Eigen::Vector3d> v;
  v.reserve(mesh_->vertices_m.size());
  for (const auto& p : mesh_->vertices_m) v.emplace_back(p.x(), p.y(), 0.0);
  return v;
}

Result<SheetState> ArraySheet::evaluate(std::span<const Eigen::Vector3d> vertices_m) const { return evaluate_impl(vertices_m); }

Result<SheetState> ArraySheet::evaluate_impl(std::span<const Eigen::Vector3d> vertices_m) const {
  if (vertices_m.size() != mesh_->vertices_m.size()) {
    return sheet_error("got " + std::to_string(vertices_m.size()) + " vertices for a mesh of " + std::to_string(mesh_->vertices_m.size()));
  }
  for (const auto& v : vertices_m) {
    if (!v.allFinite()) return sheet_error("a vertex position is not finite");
  }
  const std::size_t T = mesh_->triangles.size();
  // Per triangle: deformation gradient F (3 x 2) from the rest sheet.
  std::vector<Eigen::Matrix<double, 3, 2>> F(T);
  for (std::size_t t = 0; t < T; ++t) {
    const auto& tri = mesh_->triangles[t];
    Eigen::Matrix<double, 3, 2> D;
    D << vertices_m[tri[1]] - vertices_m[tri[0]], vertices_m[tri[2]] - vertices_m[tri[0]];
    F[t] = D * rest_edges_inverse_[t];
  }
  SheetState out;
  const std::size_t C = layout_->cells.size();
  out.cell_f.assign(C, 0.0);
  out.cell_max_stretch.assign(C, 0.0);
  out.top_squares.assign(C, 0.0);
  out.bottom_squares.assign(C, 0.0);
  for (std::size_t c = 0; c < C; ++c) {
    double sum = 0.0, max_stretch = 0.0;
    for (std::uint32_t t : cell_triangles_[c]) {
      const auto& tri = mesh_->triangles[t];
      const double a = 0.5 * (vertices_m[tri[1]] - vertices_m[tri[0]]).cross(vertices_m[tri[2]] - vertices_m[tri[0]]).norm();
      sum += a * a / triangle_rest_m2_[t];
      const Eigen::Matrix2d G = F[t].transpose() * F[t];
      const double largest = Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(G, Eigen::EigenvaluesOnly).eigenvalues()[1];
      max_stretch = std::max(max_stretch, std::sqrt(std::max(0.0, largest)));
    }
    out.cell_f[c] = eps_over_d0_ * sum;
    out.cell_max_stretch[c] = max_stretch;
  }
  auto integrate = [&](const StripPath& path, std::vector<double>& squares) {
    double acc = 0.0;
    std::size_t next = 0;
    for (std::size_t j = 0; j < path.cells.size(); ++j) {
      for (; next < path.samples_before_cell[j]; ++next) {
        const Sample& s = path.samples[next];
        const double l1 = (F[s.triangle] * path.direction).norm();
        acc += l1 * l1 * s.ds_over_w;
      }
      squares[path.cells[j]] = acc;
    }
  };
  for (const auto& p : top_paths_) integrate(p, out.top_squares);
  for (const auto& p : bottom_paths_) integrate(p, out.bottom_squares);
  return out;
}

Result<SheetState> interpolate(const SheetState& a, const SheetState& b, double w) {
  if (a.cell_f.size() != b.cell_f.size() || a.cell_max_stretch.size() != b.cell_max_stretch.size() ||
      a.top_squares.size() != b.top_squares.size() || a.bottom_squares.size() != b.bottom_squares.size()) {
    return sheet_error("cannot interpolate sheet states of different layouts");
  }
  if (!std::isfinite(w)) return sheet_error("interpolation weight is not finite");
  auto lerp = [w](const std::vector<double>& x, const std::vector<double>& y) {
    std::vector<double> out(x.size());
    for (std::size_t i = 0; i < x.size(); ++i) out[i] = (1.0 - w) * x[i] + w * y[i];
    return out;
  };
  return SheetState{lerp(a.cell_f, b.cell_f), lerp(a.cell_max_stretch, b.cell_max_stretch), lerp(a.top_squares, b.top_squares),
                    lerp(a.bottom_squares, b.bottom_squares)};
}

Result<std::vector<double>> ArraySheet::ideal_capacitance_f(std::span<const Eigen::Vector3d> vertices_m) const {
  auto s = evaluate_impl(vertices_m);
  if (!s) return s.error();
  return std::move(s->cell_f);
}

Result<std::vector<double>> ArraySheet::eq48_ratio(std::span<const Eigen::Vector3d> vertices_m) const {
  if (vertices_m.size() != mesh_->vertices_m.size()) return sheet_error("vertex count does not match the mesh");
  std::vector<double> out(layout_->cells.size());
  std::vector<double> rest, deformed;
  for (std::size_t c = 0; c < out.size(); ++c) {
    rest.clear();
    deformed.clear();
    for (std::uint32_t t : cell_triangles_[c]) {
      const auto& tri = mesh_->triangles[t];
      rest.push_back(triangle_rest_m2_[t]);
      deformed.push_back(0.5 * (vertices_m[tri[1]] - vertices_m[tri[0]]).cross(vertices_m[tri[2]] - vertices_m[tri[0]]).norm());
    }
    out[c] = sa::cell_capacitance_ratio(rest, deformed);
  }
  return out;
}

}  // namespace proprio::stretch_array_sim
