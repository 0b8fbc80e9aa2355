#include "proprio/stretch_array_recon/recon_mesh.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <utility>

#include <opencv2/imgproc.hpp>

namespace proprio::stretch_array_recon {
namespace recon_mesh_impl {

using stretch_array::StripArrayLayout;

double cross2(const Point2& a, const Point2& b) { return a.x() * b.y() - a.y() * b.x(); }

double signed_area(const Point2& a, const Point2& b, const Point2& c) { return 0.5 * cross2(b - a, c - a); }

double polygon_area(const std::vector<Point2>& poly) {
  double s = 0.0;
  for (std::size_t i = 0; i < poly.size(); ++i) s += cross2(poly[i], poly[(i + 1) % poly.size()]);
  return 0.5 * s;
}

bool point_in_polygon(const Point2& p, const std::vector<Point2>& poly) {
  bool inside = false;
  for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    const Point2& a = poly[i];
    const Point2& b = poly[j];
    if ((a.y() > p.y()) != (b.y() > p.y()) && p.x() < (b.x() - a.x()) * (p.y() - a.y()) / (b.y() - a.y()) + a.x()) {
      inside = !inside;
    }
  }
  return inside;
}

double segment_distance(const Point2& p, const Point2& a, const Point2& b) {
  const Point2 ab = b - a;
  const double t = std::clamp((p - a).dot(ab) / std::max(ab.squaredNorm(), 1e-30), 0.0, 1.0);
  return (a + t * ab - p).norm();
}

double polygon_distance(const Point2& p, const std::vector<Point2>& poly) {
  if (point_in_polygon(p, poly)) return 0.0;
  double d = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < poly.size(); ++i)
    d = std::min(d, segment_distance(p, poly[i], poly[(i + 1) % poly.size()]));
  return d;
}

// The polygon's corners with each side split into equal pieces of at most max_edge.
std::vector<Point2> subdivide(const std::vector<Point2>& poly, double max_edge, bool closed = true) {
  std::vector<Point2> out;
  const std::size_t sides = closed ? poly.size() : poly.size() - 1;
  for (std::size_t i = 0; i < sides; ++i) {
    const Point2& a = poly[i];
    const Point2& b = poly[(i + 1) % poly.size()];
    const int pieces = std::max(1, static_cast<int>(std::ceil((b - a).norm() / max_edge - 1e-9)));
    for (int k = 0; k < pieces; ++k) out.push_back(a + (b - a) * (static_cast<double>(k) / pieces));
  }
  return out;
}

struct Attempt {
  ReconMesh mesh;
  bool fans_ok = false;
  std::string why;
};

Result<Attempt> triangulate(const StripArrayLayout& layout, const std::vector<std::vector<Point2>>& outlines,
                            const ReconMeshOptions& o, double outline_edge) {
  Attempt at;
  ReconMesh& m = at.mesh;
  const std::size_t cells = layout.cell_count();

  // The sheet: strip extents (as SheetMesh) and every outline, plus the margin.
  double x0 = std::numeric_limits<double>::infinity(), y0 = x0, x1 = -x0, y1 = -x0;
  for (const auto& s : layout.top_strips)
    x0 = std::min(x0, s.centre_m - s.width_m / 2), x1 = std::max(x1, s.centre_m + s.width_m / 2);
  for (const auto& s : layout.bottom_strips)
    y0 = std::min(y0, s.centre_m - s.width_m / 2), y1 = std::max(y1, s.centre_m + s.width_m / 2);
  for (const auto& poly : outlines) {
    for (const Point2& p : poly) {
      x0 = std::min(x0, p.x()), x1 = std::max(x1, p.x()), y0 = std::min(y0, p.y()), y1 = std::max(y1, p.y());
    }
  }
  x0 -= o.margin_m, y0 -= o.margin_m, x1 += o.margin_m, y1 += o.margin_m;

  std::map<std::pair<double, double>, std::uint32_t> index_of;  // dedupes shared corners
  auto add = [&](const Point2& p, VertexKind kind, std::int32_t cell) -> std::uint32_t {
    const auto key = std::make_pair(p.x(), p.y());
    if (auto it = index_of.find(key); it != index_of.end()) return it->second;
    const auto i = static_cast<std::uint32_t>(m.sheet_xy_m.size());
    index_of.emplace(key, i);
    m.sheet_xy_m.push_back(p);
    m.kind.push_back(kind);
    m.cell_of_vertex.push_back(cell);
    return i;
  };

  m.outline_edge_m = outline_edge;
  m.centroid_vertex.resize(cells);
  m.outline_vertices.resize(cells);
  for (std::size_t c = 0; c < cells; ++c) {
    m.centroid_vertex[c] = add(layout.centroid(c), VertexKind::cell_centroid, static_cast<std::int32_t>(c));
    for (const Point2& p : subdivide(outlines[c], outline_edge)) {
      m.outline_vertices[c].push_back(add(p, VertexKind::cell_outline, static_cast<std::int32_t>(c)));
    }
  }
  const std::vector<Point2> box = {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
  for (const Point2& p : subdivide(box, o.boundary_edge_m)) add(p, VertexKind::boundary, -1);
  if (o.fill_spacing_m > 0) {
    const int nx = static_cast<int>(std::floor((x1 - x0) / o.fill_spacing_m));
    const int ny = static_cast<int>(std::floor((y1 - y0) / o.fill_spacing_m));
    const double ox = x0 + 0.5 * ((x1 - x0) - nx * o.fill_spacing_m);
    const double oy = y0 + 0.5 * ((y1 - y0) - ny * o.fill_spacing_m);
    for (int i = 0; i <= nx; ++i) {
      for (int j = 0; j <= ny; ++j) {
        const Point2 p(ox + i * o.fill_spacing_m, oy + j * o.fill_spacing_m);
        if (p.x() - x0 < 0.5 * o.fill_clearance_m || x1 - p.x() < 0.5 * o.fill_clearance_m ||
            p.y() - y0 < 0.5 * o.fill_clearance_m || y1 - p.y() < 0.5 * o.fill_clearance_m) {
          continue;
        }
        bool clear = true;
        for (const auto& poly : outlines) {
          if (polygon_distance(p, poly) < o.fill_clearance_m) {
            clear = false;
            break;
          }
        }
        if (clear) add(p, VertexKind::fill, -1);
      }
    }
  }

  // Subdiv2D works in float on an integer rectangle: 10 um units from the
  // sheet's corner keep a 1 m sheet at 1e5, well inside float precision.
  constexpr double kScale = 1e5;
  const int w = static_cast<int>(std::ceil((x1 - x0) * kScale)) + 20;
  const int h = static_cast<int>(std::ceil((y1 - y0) * kScale)) + 20;
  if (w > 2'000'000 || h > 2'000'000) {
    return make_error(Errc::invalid_argument,
                      "layout '" + layout.name + "' spans more than 20 m; check its units (metres)");
  }
  cv::Subdiv2D subdiv(cv::Rect(-10, -10, w, h));
  std::map<std::pair<float, float>, std::uint32_t> vertex_at;
  try {
    for (std::uint32_t i = 0; i < m.sheet_xy_m.size(); ++i) {
      const cv::Point2f q(static_cast<float>((m.sheet_xy_m[i].x() - x0) * kScale),
                          static_cast<float>((m.sheet_xy_m[i].y() - y0) * kScale));
      if (!vertex_at.emplace(std::make_pair(q.x, q.y), i).second) {
        return make_error(Errc::invalid_argument,
                          "layout '" + layout.name + "': two mesh points closer than 10 um; cells overlap or touch");
      }
      subdiv.insert(q);
    }
  } catch (const cv::Exception& e) {
    return make_error(Errc::invalid_argument,
                      "layout '" + layout.name + "': Delaunay triangulation failed (OpenCV: " + e.err + ")");
  }
  std::vector<cv::Vec6f> tri_list;
  subdiv.getTriangleList(tri_list);
  std::vector<Triangle> delaunay;
  for (const cv::Vec6f& t : tri_list) {
    Triangle tri{};
    bool inside = true;
    for (int k = 0; k < 3; ++k) {
      auto it = vertex_at.find(std::make_pair(t[2 * k], t[2 * k + 1]));
      if (it == vertex_at.end()) {
        inside = false;  // a corner of Subdiv2D's virtual outer triangle
        break;
      }
      tri[static_cast<std::size_t>(k)] = it->second;
    }
    if (!inside) continue;
    const auto& P = m.sheet_xy_m;
    const double a = signed_area(P[tri[0]], P[tri[1]], P[tri[2]]);
    if (std::abs(a) < 1e-14) continue;  // collinear boundary points
    if (a < 0) std::swap(tri[1], tri[2]);
    delaunay.push_back(tri);
  }

  std::set<std::pair<std::uint32_t, std::uint32_t>> edges;
  for (const Triangle& t : delaunay) {
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = t[static_cast<std::size_t>(k)], b = t[static_cast<std::size_t>((k + 1) % 3)];
      edges.emplace(std::min(a, b), std::max(a, b));
    }
  }
  for (std::size_t c = 0; c < cells; ++c) {
    const auto& ov = m.outline_vertices[c];
    for (std::size_t i = 0; i < ov.size(); ++i) {
      const std::uint32_t a = ov[i], b = ov[(i + 1) % ov.size()];
      if (!edges.count({std::min(a, b), std::max(a, b)})) {
        at.why = "an outline segment of cell '" + layout.cells[c].name + "' is not a Delaunay edge";
        return at;
      }
    }
  }

  // Replace each cell's Delaunay triangles by its fan.
  std::vector<std::int32_t> owner(delaunay.size(), -1);
  std::vector<double> removed_area(cells, 0.0);
  std::vector<std::set<std::uint32_t>> cell_points(cells);
  for (std::size_t c = 0; c < cells; ++c) {
    cell_points[c].insert(m.outline_vertices[c].begin(), m.outline_vertices[c].end());
    cell_points[c].insert(m.centroid_vertex[c]);
  }
  std::vector<std::int32_t> cell_of_point(m.sheet_xy_m.size(), -1);
  for (std::size_t c = 0; c < cells; ++c) {
    for (std::uint32_t v : cell_points[c]) cell_of_point[v] = static_cast<std::int32_t>(c);
  }
  for (std::size_t t = 0; t < delaunay.size(); ++t) {
    const Triangle& tri = delaunay[t];
    // A shared corner may belong to two cells; test every cell of any corner.
    for (std::uint32_t v : tri) {
      const std::int32_t c = cell_of_point[v];
      if (c < 0 || owner[t] >= 0) continue;
      const auto& pts = cell_points[static_cast<std::size_t>(c)];
      if (!pts.count(tri[0]) || !pts.count(tri[1]) || !pts.count(tri[2])) continue;
      const Point2 g = (m.sheet_xy_m[tri[0]] + m.sheet_xy_m[tri[1]] + m.sheet_xy_m[tri[2]]) / 3.0;
      if (point_in_polygon(g, outlines[static_cast<std::size_t>(c)])) owner[t] = c;
    }
    if (owner[t] >= 0) {
      const auto& P = m.sheet_xy_m;
      removed_area[static_cast<std::size_t>(owner[t])] += signed_area(P[tri[0]], P[tri[1]], P[tri[2]]);
    }
  }
  for (std::size_t t = 0; t < delaunay.size(); ++t) {
    if (owner[t] < 0) {
      m.triangles.push_back(delaunay[t]);
      m.cell_of_triangle.push_back(-1);
    }
  }
  for (std::size_t c = 0; c < cells; ++c) {
    const double area = polygon_area(outlines[c]);
    if (std::abs(removed_area[c] - area) > 1e-9 * std::max(1.0, area) + 1e-12) {
      at.why = "the Delaunay triangles of cell '" + layout.cells[c].name + "' do not tile it";
      return at;
    }
    const auto& ov = m.outline_vertices[c];
    for (std::size_t i = 0; i < ov.size(); ++i) {
      const Triangle tri{m.centroid_vertex[c], ov[i], ov[(i + 1) % ov.size()]};
      m.triangles.push_back(tri);
      m.cell_of_triangle.push_back(static_cast<std::int32_t>(c));
    }
  }
  at.fans_ok = true;
  return at;
}

}  // namespace recon_mesh_impl
using namespace recon_mesh_impl;

Status ReconMeshOptions::validate() const {
  auto positive = [](double v, const char* name) -> Status {
    if (!(v > 0) || !std::isfinite(v)) {
      return make_error(Errc::invalid_argument,
                        std::string(name) + " = " + std::to_string(v) + ": expected a positive length in metres");
    }
    return {};
  };
  if (Status s = positive(max_edge_m, "max_edge_m"); !s) return s;
  if (Status s = positive(margin_m, "margin_m"); !s) return s;
  if (Status s = positive(boundary_edge_m, "boundary_edge_m"); !s) return s;
  if (!(fill_spacing_m >= 0) || !(fill_clearance_m >= 0)) {
    return make_error(Errc::invalid_argument, "fill_spacing_m and fill_clearance_m must be >= 0 (0: no fill)");
  }
  if (max_refinements < 0 || max_refinements > 10) {
    return make_error(Errc::invalid_argument,
                      "max_refinements = " + std::to_string(max_refinements) + ": expected 0..10");
  }
  return {};
}

std::string ReconMeshOptions::describe() const {
  std::ostringstream s;
  s << "max_edge_m=" << max_edge_m << " margin_m=" << margin_m << " boundary_edge_m=" << boundary_edge_m
    << " fill_spacing_m=" << fill_spacing_m << " fill_clearance_m=" << fill_clearance_m
    << " max_refinements=" << max_refinements;
  return s.str();
}

double ReconMesh::area_m2() const {
  double a = 0.0;
  for (const Triangle& t : triangles) a += signed_area(sheet_xy_m[t[0]], sheet_xy_m[t[1]], sheet_xy_m[t[2]]);
  return a;
}

Result<ReconMesh> build_recon_mesh(const StripArrayLayout& layout, const ReconMeshOptions& options) {
  if (Status s = options.validate(); !s) return s.error();
  if (Status s = layout.validate(); !s) return s.error().with_context("reconstruction mesh");
  if (layout.cell_count() == 0) return make_error(Errc::invalid_argument, "layout '" + layout.name + "' has no cells");

  std::vector<std::vector<Point2>> outlines(layout.cell_count());
  for (std::size_t c = 0; c < layout.cell_count(); ++c) {
    outlines[c] = layout.outline(c);
    const Point2 g = layout.centroid(c);
    for (std::size_t i = 0; i < outlines[c].size(); ++i) {
      if (signed_area(g, outlines[c][i], outlines[c][(i + 1) % outlines[c].size()]) <= 0) {
        return make_error(Errc::unsupported, "cell '" + layout.cells[c].name +
                                                 "' is not star-shaped from its centroid, so it cannot be a fan of "
                                                 "triangles; split it or make its outline convex");
      }
    }
  }
  double edge = options.max_edge_m;
  std::string why;
  for (int attempt = 0; attempt <= options.max_refinements; ++attempt, edge *= 0.5) {
    auto at = triangulate(layout, outlines, options, edge);
    if (!at) return at.error();
    if (at->fans_ok) return std::move(at->mesh);
    why = at->why;
  }
  return make_error(Errc::unsupported, "layout '" + layout.name + "': " + why + " even with outline segments of " +
                                           std::to_string(edge * 2 * 1e3) +
                                           " mm; cells are too close to each other or to the sheet's edge for "
                                           "margin_m/fill_clearance_m");
}

Status MarkerSelectionOptions::validate() const {
  if (!(max_spacing_m > 0) || !std::isfinite(max_spacing_m)) {
    return make_error(Errc::invalid_argument,
                      "max_spacing_m = " + std::to_string(max_spacing_m) + ": expected a positive length in metres");
  }
  return {};
}

std::string MarkerSelectionOptions::describe() const { return "max_spacing_m=" + std::to_string(max_spacing_m); }

Result<std::vector<std::uint32_t>> select_marker_vertices(const ReconMesh& mesh,
                                                          const MarkerSelectionOptions& options) {
  if (Status s = options.validate(); !s) return s.error();
  if (mesh.centroid_vertex.empty())
    return make_error(Errc::invalid_argument, "the mesh has no cells to put markers on");
  double x0 = std::numeric_limits<double>::infinity(), y0 = x0, x1 = -x0, y1 = -x0;
  for (std::uint32_t v : mesh.centroid_vertex) {
    const Point2& p = mesh.sheet_xy_m[v];
    x0 = std::min(x0, p.x()), x1 = std::max(x1, p.x()), y0 = std::min(y0, p.y()), y1 = std::max(y1, p.y());
  }
  const int nx = static_cast<int>(std::ceil((x1 - x0) / options.max_spacing_m - 1e-9)) + 1;
  const int ny = static_cast<int>(std::ceil((y1 - y0) / options.max_spacing_m - 1e-9)) + 1;
  const double sx = nx > 1 ? (x1 - x0) / (nx - 1) : 0.0;
  const double sy = ny > 1 ? (y1 - y0) / (ny - 1) : 0.0;
  // A node with no cell within half a grid diagonal is over bare sheet (the
  // empty corners of a banded layout): no marker there.
  const double reach = 0.5 * std::hypot(std::max(sx, 1e-9), std::max(sy, 1e-9)) + 1e-9;
  std::vector<std::uint32_t> chosen;
  std::set<std::uint32_t> taken;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const Point2 node(x0 + i * sx, y0 + j * sy);
      double best = std::numeric_limits<double>::infinity();
      std::uint32_t best_v = 0;
      for (std::uint32_t v : mesh.centroid_vertex) {
        const double d = (mesh.sheet_xy_m[v] - node).norm();
        if (d < best && !taken.count(v)) best = d, best_v = v;
      }
      if (best <= reach) {
        taken.insert(best_v);
        chosen.push_back(best_v);
      }
    }
  }
  return chosen;
}

Eigen::MatrixX3d rest_shape(const ReconMesh& mesh, double cylinder_radius_m) {
  Eigen::MatrixX3d V(static_cast<Eigen::Index>(mesh.vertex_count()), 3);
  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0;
  for (const Point2& p : mesh.sheet_xy_m) x0 = std::min(x0, p.x()), x1 = std::max(x1, p.x());
  const double xc = mesh.vertex_count() ? 0.5 * (x0 + x1) : 0.0;
  for (std::size_t i = 0; i < mesh.vertex_count(); ++i) {
    const Point2& p = mesh.sheet_xy_m[i];
    const auto r = static_cast<Eigen::Index>(i);
    if (cylinder_radius_m > 0) {
      const double R = cylinder_radius_m, a = (p.x() - xc) / R;
      V.row(r) << xc + R * std::sin(a), p.y(), R * std::cos(a) - R;
    } else {
      V.row(r) << p.x(), p.y(), 0.0;
    }
  }
  return V;
}

}  // namespace proprio::stretch_array_recon
