#include "proprio/stretch_array/sheet_mesh.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace proprio::stretch_array {

Status SheetMeshOptions::validate() const {
  if (!(std::isfinite(margin_m) && margin_m >= 0.0 && margin_m < 1.0)) {
    return make_error(Errc::invalid_argument, "sheet mesh: margin_m must be in [0, 1) m");
  }
  if (!(std::isfinite(max_edge_m) && max_edge_m >= 1e-4 && max_edge_m < 1.0)) {
    return make_error(Errc::invalid_argument, "sheet mesh: max_edge_m must be in [0.1 mm, 1 m)");
  }
  return {};
}

double SheetMesh::triangle_area_m2(std::size_t t) const {
  const auto& tri = triangles.at(t);
  const Point2 a = vertices_m[tri[0]], b = vertices_m[tri[1]], c = vertices_m[tri[2]];
  return 0.5 * ((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
}

std::vector<std::vector<std::uint32_t>> SheetMesh::triangles_of_cells(std::size_t cell_count) const {
  std::vector<std::vector<std::uint32_t>> out(cell_count);
  for (std::size_t t = 0; t < triangles.size(); ++t) {
    const std::int32_t c = cell_of_triangle[t];
    if (c >= 0 && static_cast<std::size_t>(c) < cell_count) out[static_cast<std::size_t>(c)].push_back(static_cast<std::uint32_t>(t));
  }
  return out;
}

namespace {

// The sorted grid lines along one axis: every strip edge, the margins, and
// enough lines between them that no interval is longer than max_edge.
std::vector<double> grid_lines(const std::vector<Strip>& strips, double margin, double max_edge) {
  std::vector<double> edges;
  for (const Strip& s : strips) {
    edges.push_back(s.centre_m - 0.5 * s.width_m);
    edges.push_back(s.centre_m + 0.5 * s.width_m);
  }
  std::sort(edges.begin(), edges.end());
  edges.insert(edges.begin(), edges.front() - margin);
  edges.push_back(edges.back() + margin);
  std::vector<double> lines;
  for (std::size_t i = 0; i + 1 < edges.size(); ++i) {
    const double a = edges[i], b = edges[i + 1];
    if (b - a < 1e-9) continue;  // coincident edges (touching strips)
    const int parts = std::max(1, static_cast<int>(std::ceil((b - a) / max_edge - 1e-9)));
    for (int k = 0; k < parts; ++k) lines.push_back(a + (b - a) * k / parts);
  }
  lines.push_back(edges.back());
  return lines;
}

}  // namespace

Result<SheetMesh> build_sheet_mesh(const StripArrayLayout& layout, const SheetMeshOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  if (auto st = layout.validate(); !st) return st.error();
  for (const ArrayCell& c : layout.cells) {
    if (!c.outline_m.empty()) {
      return make_error(Errc::unsupported, "sheet mesh: cell '" + c.name +
                                               "' has an explicit outline; the mesher handles straight strips only "
                                               "(docs/stretch-arrays.md)");
    }
  }
  const std::vector<double> xs = grid_lines(layout.top_strips, options.margin_m, options.max_edge_m);
  const std::vector<double> ys = grid_lines(layout.bottom_strips, options.margin_m, options.max_edge_m);
  const std::size_t nx = xs.size(), ny = ys.size();
  if (nx * ny > 2'000'000) {
    return make_error(Errc::invalid_argument, "sheet mesh: " + std::to_string(nx * ny) +
                                                  " vertices is too many; raise max_edge_m");
  }
  SheetMesh mesh;
  mesh.vertices_m.reserve(nx * ny);
  for (std::size_t j = 0; j < ny; ++j) {
    for (std::size_t i = 0; i < nx; ++i) mesh.vertices_m.emplace_back(xs[i], ys[j]);
  }
  const auto vertex = [nx](std::size_t i, std::size_t j) { return static_cast<std::uint32_t>(j * nx + i); };
  // The cell (if any) a point belongs to: inside both strips of a listed crossing.
  std::vector<std::int32_t> cell_at(layout.top_strips.size() * layout.bottom_strips.size(), -1);
  for (std::size_t c = 0; c < layout.cells.size(); ++c) {
    cell_at[layout.cells[c].top * layout.bottom_strips.size() + layout.cells[c].bottom] = static_cast<std::int32_t>(c);
  }
  const auto inside = [](const Strip& s, double v) {
    return v > s.centre_m - 0.5 * s.width_m && v < s.centre_m + 0.5 * s.width_m;
  };
  const auto cell_of = [&](const Point2& p) -> std::int32_t {
    for (std::size_t t = 0; t < layout.top_strips.size(); ++t) {
      if (!inside(layout.top_strips[t], p.x())) continue;
      for (std::size_t b = 0; b < layout.bottom_strips.size(); ++b) {
        if (inside(layout.bottom_strips[b], p.y())) return cell_at[t * layout.bottom_strips.size() + b];
      }
    }
    return -1;
  };
  for (std::size_t j = 0; j + 1 < ny; ++j) {
    for (std::size_t i = 0; i + 1 < nx; ++i) {
      const std::uint32_t a = vertex(i, j), b = vertex(i + 1, j), c = vertex(i + 1, j + 1), d = vertex(i, j + 1);
      // Grid lines include every strip edge, so the whole rectangle is in one cell or in none.
      const std::int32_t cell = cell_of(0.5 * (mesh.vertices_m[a] + mesh.vertices_m[c]));
      if ((i + j) % 2 == 0) {
        mesh.triangles.push_back({a, b, c});
        mesh.triangles.push_back({a, c, d});
      } else {
        mesh.triangles.push_back({a, b, d});
        mesh.triangles.push_back({b, c, d});
      }
      mesh.cell_of_triangle.push_back(cell);
      mesh.cell_of_triangle.push_back(cell);
    }
  }
  return mesh;
}

}  // namespace proprio::stretch_array
