// The ideal cell capacitances of a deformed sheet (eq. 4.8's physics) and the
// strips' stretch-dependent resistance paths, on analytic deformations.
#include <gtest/gtest.h>

#include <cmath>

#include "deformations.hpp"
#include "proprio/stretch_array/capacitance.hpp"
#include "proprio/stretch_array_sim/array_sheet.hpp"

namespace proprio::stretch_array_sim {
namespace {

using stretch_array::StripArrayLayout;
using namespace testing;

TEST(ArraySheet, RestCapacitanceIsThePlateCapacitor) {
  const StripArrayLayout L = StripArrayLayout::prototype_92();
  const ArraySheet s = sheet_of(L);
  ASSERT_EQ(s.rest_state().cell_f.size(), L.cell_count());
  for (std::size_t c = 0; c < L.cell_count(); ++c) {
    const double c0 = stretch_array::plate_capacitance_f(L.sheet.relative_permittivity, L.rest_area_m2(c), L.sheet.dielectric_thickness_m);
    EXPECT_NEAR(s.rest_state().cell_f[c], c0, 1e-9 * c0);
    EXPECT_NEAR(s.rest_state().cell_max_stretch[c], 1.0, 1e-12);
  }
}

TEST(ArraySheet, IdealModelIsEq48OnEveryDeformation) {
  const StripArrayLayout L = StripArrayLayout::prototype_92();
  const ArraySheet s = sheet_of(L);
  const auto& c0 = s.rest_state().cell_f;
  for (const auto& v : {uniform_stretch(s, 1.3), uniaxial_stretch(s, 1.6), cylinder(s, 0.04), bump(s, {0.06, 0.06}, 0.02, 0.015),
                        graded_stretch(s, 0.25, 0.1)}) {
    auto ideal = s.ideal_capacitance_f(v);
    auto ratio = s.eq48_ratio(v);
    ASSERT_TRUE(ideal && ratio);
    for (std::size_t c = 0; c < L.cell_count(); ++c) {
      EXPECT_NEAR((*ideal)[c] / c0[c], (*ratio)[c], 1e-12 * (*ratio)[c]);
    }
  }
}

TEST(ArraySheet, UniaxialAndUniformStretchFollowEq42And43) {
  const ArraySheet s = sheet_of(StripArrayLayout::prototype_92());
  const auto& c0 = s.rest_state().cell_f;
  auto uni = s.ideal_capacitance_f(uniaxial_stretch(s, 1.4));
  auto area = s.ideal_capacitance_f(uniform_stretch(s, 1.2));
  ASSERT_TRUE(uni && area);
  for (std::size_t c = 0; c < c0.size(); ++c) {
    EXPECT_NEAR((*uni)[c] / c0[c], stretch_array::uniaxial_capacitance_ratio(1.4), 1e-9);
    EXPECT_NEAR((*area)[c] / c0[c], stretch_array::area_capacitance_ratio(1.2 * 1.2), 1e-9);
  }
}

TEST(ArraySheet, BendingWithoutStretchLeavesCapacitanceAndResistance) {
  const ArraySheet s = sheet_of(StripArrayLayout::prototype_92());
  auto st = s.evaluate(cylinder(s, 0.035));
  ASSERT_TRUE(st);
  const auto& r = s.rest_state();
  for (std::size_t c = 0; c < r.cell_f.size(); ++c) {
    // Chords of a 3 mm grid on a 35 mm radius shorten by under 0.1 %.
    EXPECT_NEAR(st->cell_f[c] / r.cell_f[c], 1.0, 2e-3);
    EXPECT_NEAR(st->top_squares[c], r.top_squares[c], 2e-3 * r.top_squares[c] + 1e-9);
    EXPECT_NEAR(st->bottom_squares[c], r.bottom_squares[c], 2e-3 * r.bottom_squares[c] + 1e-9);
  }
}

TEST(ArraySheet, ABumpRaisesOnlyTheCellsUnderIt) {
  const StripArrayLayout L = StripArrayLayout::prototype_92();
  const ArraySheet s = sheet_of(L);
  const Eigen::Vector2d centre(0.066, 0.066);
  auto st = s.evaluate(bump(s, centre, 0.015, 0.012));
  ASSERT_TRUE(st);
  for (std::size_t c = 0; c < L.cell_count(); ++c) {
    const double ratio = st->cell_f[c] / s.rest_state().cell_f[c];
    const double d = (L.centroid(c) - centre).norm();
    EXPECT_GE(ratio, 1.0 - 1e-12);
    if (d < 0.02) {
      EXPECT_GT(ratio, 1.05) << L.cells[c].name;
    }
    if (d > 0.07) {
      EXPECT_LT(ratio, 1.01) << L.cells[c].name;
    }
  }
}

TEST(ArraySheet, StripResistanceGrowsWithTheSquareOfTheStretchAlongIt) {
  const StripArrayLayout L = StripArrayLayout::prototype_92();
  const ArraySheet s = sheet_of(L);
  const auto& r = s.rest_state();
  // Rest: the path to a cell is its distance from the sheet's low edge over the strip width.
  for (std::size_t c = 0; c < L.cell_count(); ++c) {
    const Eigen::Vector2d p = L.centroid(c);
    const double lo_y = L.bottom_strips.front().centre_m - 0.004 - 0.004, lo_x = L.top_strips.front().centre_m - 0.004 - 0.004;
    EXPECT_NEAR(r.top_squares[c], (p.y() - lo_y) / L.top_strips[L.cells[c].top].width_m, 1e-4);
    EXPECT_NEAR(r.bottom_squares[c], (p.x() - lo_x) / L.bottom_strips[L.cells[c].bottom].width_m, 1e-4);
  }
  // Stretched 1.5x along x with free contraction: bottom strips (along x)
  // go up 1.5^2, top strips (along y) down to 1/1.5 (their length shrinks
  // by 1/sqrt(1.5), squared).
  auto st = s.evaluate(uniaxial_stretch(s, 1.5));
  ASSERT_TRUE(st);
  for (std::size_t c = 0; c < L.cell_count(); ++c) {
    EXPECT_NEAR(st->bottom_squares[c], 2.25 * r.bottom_squares[c], 1e-9 * r.bottom_squares[c]);
    EXPECT_NEAR(st->top_squares[c], r.top_squares[c] / 1.5, 1e-9 * r.top_squares[c]);
    EXPECT_NEAR(st->cell_max_stretch[c], 1.5, 1e-9);
  }
}

TEST(ArraySheet, RefusesMismatchedInput) {
  const StripArrayLayout L = StripArrayLayout::prototype_92();
  const ArraySheet s = sheet_of(L);
  std::vector<Eigen::Vector3d> few(3, Eigen::Vector3d::Zero());
  auto r = s.evaluate(few);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("vertices"), std::string::npos);
  auto v = s.rest_vertices_m();
  v[5].x() = std::nan("");
  EXPECT_FALSE(s.evaluate(v));
  // A mesh of another layout.
  auto other = ArraySheet::create(L, mesh_of(StripArrayLayout::grid("small", 2, 2, 0.012, 0.008)));
  EXPECT_FALSE(other);
}

}  // namespace
}  // namespace proprio::stretch_array_sim

namespace proprio::stretch_array_sim {
namespace {

TEST(ArraySheet, StatesInterpolateFieldByField) {
  const ArraySheet s = testing::sheet_of(stretch_array::StripArrayLayout::prototype_92());
  const SheetState a = s.rest_state(), b = *s.evaluate(testing::uniform_stretch(s, 1.2));
  auto m = interpolate(a, b, 0.25);
  ASSERT_TRUE(m);
  for (std::size_t c = 0; c < a.cell_f.size(); ++c) {
    EXPECT_NEAR(m->cell_f[c], 0.75 * a.cell_f[c] + 0.25 * b.cell_f[c], 1e-24);
    EXPECT_NEAR(m->bottom_squares[c], 0.75 * a.bottom_squares[c] + 0.25 * b.bottom_squares[c], 1e-12);
    EXPECT_NEAR(m->cell_max_stretch[c], 1.05, 1e-9);
  }
  SheetState short_state = a;
  short_state.cell_f.pop_back();
  EXPECT_FALSE(interpolate(a, short_state, 0.5));
}

}  // namespace
}  // namespace proprio::stretch_array_sim
