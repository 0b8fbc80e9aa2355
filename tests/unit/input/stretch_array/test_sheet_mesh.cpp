// The rest sheet's triangle mesh (issue 30): every cell covered exactly by its
// own triangles, the whole sheet covered, all triangles counter-clockwise and
// within the requested size; eq. 4.8 over a cell's triangles.
#include <gtest/gtest.h>

#include <cmath>

#include "proprio/stretch_array/capacitance.hpp"
#include "proprio/stretch_array/sheet_mesh.hpp"

namespace proprio::stretch_array {
namespace {

TEST(SheetMesh, CellsAreCoveredExactlyByTheirOwnTriangles) {
  const StripArrayLayout L = StripArrayLayout::prototype_92();
  SheetMeshOptions o;
  o.max_edge_m = 0.002;
  auto mesh = build_sheet_mesh(L, o);
  ASSERT_TRUE(mesh) << mesh.error().message;
  double total = 0.0;
  double longest = 0.0;
  for (std::size_t t = 0; t < mesh->triangles.size(); ++t) {
    const double a = mesh->triangle_area_m2(t);
    ASSERT_GT(a, 0.0) << "triangle " << t << " is not counter-clockwise";
    total += a;
    for (int k = 0; k < 3; ++k) {
      const Point2 p = mesh->vertices_m[mesh->triangles[t][k]], q = mesh->vertices_m[mesh->triangles[t][(k + 1) % 3]];
      longest = std::max(longest, (p - q).norm());
    }
  }
  // The sheet: strips from -4 mm to 136 mm, plus 4 mm margins: 148 mm square.
  EXPECT_NEAR(total, 0.148 * 0.148, 1e-9);
  EXPECT_LE(longest, 0.002 * std::sqrt(2.0) + 1e-12);
  const auto per_cell = mesh->triangles_of_cells(L.cell_count());
  for (std::size_t c = 0; c < L.cell_count(); ++c) {
    double area = 0.0;
    for (std::uint32_t t : per_cell[c]) area += mesh->triangle_area_m2(t);
    EXPECT_NEAR(area, L.rest_area_m2(c), 1e-12) << L.cells[c].name;
    EXPECT_GE(per_cell[c].size(), 2u);
  }
}

TEST(SheetMesh, EquationFourEightOverACellsTriangles) {
  const StripArrayLayout L = StripArrayLayout::grid("one", 1, 1, 0.01, 0.015);
  auto mesh = build_sheet_mesh(L);
  ASSERT_TRUE(mesh) << mesh.error().message;
  const auto tris = mesh->triangles_of_cells(1)[0];
  std::vector<double> rest, stretched;
  for (std::uint32_t t : tris) {
    rest.push_back(mesh->triangle_area_m2(t));
    stretched.push_back(1.2 * mesh->triangle_area_m2(t));
  }
  EXPECT_NEAR(cell_capacitance_ratio(rest, stretched), 1.44, 1e-12) << "uniform stretch: (A/A0)^2";
}

TEST(SheetMesh, RefusesWhatItCannotMesh) {
  StripArrayLayout L = StripArrayLayout::grid("g", 2, 2, 0.01, 0.005);
  L.cells[0].outline_m = {{0, 0}, {0.004, 0}, {0.004, 0.004}};
  auto explicit_outline = build_sheet_mesh(L);
  ASSERT_FALSE(explicit_outline);
  EXPECT_NE(explicit_outline.error().message.find("explicit outline"), std::string::npos);
  SheetMeshOptions tiny;
  tiny.max_edge_m = 1e-5;
  EXPECT_FALSE(build_sheet_mesh(StripArrayLayout::grid("g", 2, 2, 0.01, 0.005), tiny));
  SheetMeshOptions fine_but_huge;
  fine_but_huge.max_edge_m = 1e-4;
  EXPECT_FALSE(build_sheet_mesh(StripArrayLayout::biceps_144(), fine_but_huge)) << "too many vertices";
}

}  // namespace
}  // namespace proprio::stretch_array
