// The reconstruction mesh S^0: Delaunay over the layout, each cell a fan.
#include "proprio/stretch_array_recon/recon_mesh.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <set>

namespace proprio::stretch_array_recon {
namespace test_recon_mesh {

using stretch_array::StripArrayLayout;

double tri_area(const ReconMesh& m, const Triangle& t) {
  const Point2 a = m.sheet_xy_m[t[1]] - m.sheet_xy_m[t[0]], b = m.sheet_xy_m[t[2]] - m.sheet_xy_m[t[0]];
  return 0.5 * (a.x() * b.y() - a.y() * b.x());
}

// The sheet rectangle: strip extents plus the margin.
double sheet_area(const StripArrayLayout& L, double margin) {
  double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
  for (const auto& s : L.top_strips)
    x0 = std::min(x0, s.centre_m - s.width_m / 2), x1 = std::max(x1, s.centre_m + s.width_m / 2);
  for (const auto& s : L.bottom_strips)
    y0 = std::min(y0, s.centre_m - s.width_m / 2), y1 = std::max(y1, s.centre_m + s.width_m / 2);
  return (x1 - x0 + 2 * margin) * (y1 - y0 + 2 * margin);
}

void expect_valid_mesh(const StripArrayLayout& L, const ReconMesh& m, double margin) {
  // Covers the sheet: positive triangles whose areas add up to the rectangle.
  for (const Triangle& t : m.triangles) EXPECT_GT(tri_area(m, t), 0.0);
  EXPECT_NEAR(m.area_m2(), sheet_area(L, margin), 1e-9);
  // Manifold: every edge is in one or two triangles, each direction at most once.
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
  for (const Triangle& t : m.triangles) {
    for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
  }
  for (const auto& [e, count] : directed) EXPECT_EQ(count, 1);
  // Each cell: its fan, centroid to every outline segment, tiling the cell.
  ASSERT_EQ(m.centroid_vertex.size(), L.cell_count());
  for (std::size_t c = 0; c < L.cell_count(); ++c) {
    std::set<std::pair<std::uint32_t, std::uint32_t>> fan;
    double area = 0.0;
    for (std::size_t t = 0; t < m.triangles.size(); ++t) {
      if (m.cell_of_triangle[t] != static_cast<std::int32_t>(c)) continue;
      const Triangle& tri = m.triangles[t];
      EXPECT_EQ(tri[0], m.centroid_vertex[c]);
      fan.emplace(tri[1], tri[2]);
      area += tri_area(m, tri);
    }
    const auto& ov = m.outline_vertices[c];
    EXPECT_EQ(fan.size(), ov.size()) << L.cells[c].name;
    for (std::size_t i = 0; i < ov.size(); ++i)
      EXPECT_TRUE(fan.count({ov[i], ov[(i + 1) % ov.size()]})) << L.cells[c].name;
    EXPECT_NEAR(area, L.rest_area_m2(c), 1e-12) << L.cells[c].name;
    EXPECT_LT((m.sheet_xy_m[m.centroid_vertex[c]] - L.centroid(c)).norm(), 1e-12);
  }
}

TEST(ReconMesh, Prototype92IsDelaunayWithAFanPerCell) {
  const auto L = StripArrayLayout::prototype_92();
  ReconMeshOptions o;
  auto m = build_recon_mesh(L, o);
  ASSERT_TRUE(m) << m.error().message;
  expect_valid_mesh(L, *m, o.margin_m);
  EXPECT_LE(m->outline_edge_m, o.max_edge_m);
}

TEST(ReconMesh, SubdividedOutlinesKeepTheirFans) {
  const auto L = StripArrayLayout::grid("g", 4, 3, 0.012, 0.008);
  ReconMeshOptions o;
  o.max_edge_m = 0.003;  // 8 mm sides in three pieces
  auto m = build_recon_mesh(L, o);
  ASSERT_TRUE(m) << m.error().message;
  expect_valid_mesh(L, *m, o.margin_m);
  for (const auto& ov : m->outline_vertices) EXPECT_EQ(ov.size(), 12u);
}

TEST(ReconMesh, CellsCloserThanTheirOutlineSegmentsAreRefined) {
  // 1 mm gaps between 10 mm cells: 10 mm segments' diametral circles hold the
  // neighbours' corners, so the builder must subdivide until they are edges.
  const auto L = StripArrayLayout::grid("tight", 3, 3, 0.011, 0.010);
  ReconMeshOptions o;
  o.max_edge_m = 0.010;
  o.fill_spacing_m = 0.0;
  auto m = build_recon_mesh(L, o);
  ASSERT_TRUE(m) << m.error().message;
  expect_valid_mesh(L, *m, o.margin_m);
  EXPECT_LT(m->outline_edge_m, o.max_edge_m);
}

TEST(ReconMesh, RefusesBadOptions) {
  ReconMeshOptions o;
  o.max_edge_m = -1;
  auto m = build_recon_mesh(StripArrayLayout::prototype_92(), o);
  ASSERT_FALSE(m);
  EXPECT_NE(m.error().message.find("max_edge_m"), std::string::npos);
}

TEST(MarkerSelection, RegularCoverageOfThePrototype) {
  const auto L = StripArrayLayout::prototype_92();
  auto m = build_recon_mesh(L);
  ASSERT_TRUE(m);
  MarkerSelectionOptions so;
  auto markers = select_marker_vertices(*m, so);
  ASSERT_TRUE(markers) << markers.error().message;
  ASSERT_GE(markers->size(), 4u);
  std::set<std::uint32_t> unique(markers->begin(), markers->end());
  EXPECT_EQ(unique.size(), markers->size());
  for (std::uint32_t v : *markers) EXPECT_EQ(m->kind[v], VertexKind::cell_centroid);
  // Every cell centroid has a marker within the spacing (no holes in coverage).
  for (std::uint32_t c : m->centroid_vertex) {
    double best = 1e9;
    for (std::uint32_t v : *markers) best = std::min(best, (m->sheet_xy_m[c] - m->sheet_xy_m[v]).norm());
    EXPECT_LE(best, so.max_spacing_m) << "cell vertex " << c;
  }
  // And each marker has a neighbour no more than 5 cm away (the thesis's
  // spacing; the grid nodes are closer, snapping to cells moves them).
  for (std::uint32_t a : *markers) {
    double best = 1e9;
    for (std::uint32_t b : *markers) {
      if (a != b) best = std::min(best, (m->sheet_xy_m[a] - m->sheet_xy_m[b]).norm());
    }
    EXPECT_LE(best, 0.05);
  }
}

TEST(RestShape, CylinderKeepsArcLengthAndRadius) {
  const auto L = StripArrayLayout::grid("g", 3, 3, 0.012, 0.008);
  auto m = build_recon_mesh(L);
  ASSERT_TRUE(m);
  const double R = 0.05;
  const Eigen::MatrixX3d V = rest_shape(*m, R);
  const Eigen::MatrixX3d F = rest_shape(*m, 0.0);
  const double xc = 0.5 * (F.col(0).minCoeff() + F.col(0).maxCoeff());
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    EXPECT_DOUBLE_EQ(F(i, 2), 0.0);
    EXPECT_NEAR(std::hypot(V(i, 0) - xc, V(i, 2) + R), R, 1e-12);  // on the cylinder, axis (xc, y, -R)
    EXPECT_DOUBLE_EQ(V(i, 1), F(i, 1));
    EXPECT_NEAR(R * std::atan2(V(i, 0) - xc, V(i, 2) + R), F(i, 0) - xc, 1e-12);  // arc length = sheet x
  }
}

}  // namespace test_recon_mesh
}  // namespace proprio::stretch_array_recon
