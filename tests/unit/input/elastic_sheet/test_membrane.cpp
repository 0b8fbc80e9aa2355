// The membrane energy and the flat rigs (input/elastic_sheet, issue 30).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include "proprio/elastic_sheet/flat_scenarios.hpp"
#include "proprio/elastic_sheet/membrane.hpp"
#include "proprio/stretch_array/sheet_mesh.hpp"

namespace es = proprio::elastic_sheet;

namespace {

std::vector<es::Vec3> flat_positions(const es::SheetMesh& mesh) {
  std::vector<es::Vec3> x;
  for (const auto& p : mesh.vertices_m) x.emplace_back(p.x(), p.y(), 0.0);
  return x;
}

}  // namespace

TEST(Membrane, EnergyGradientMatchesFiniteDifferences) {
  auto mesh = es::rectangle_mesh(0.010, 0.012, 0.002);
  ASSERT_TRUE(mesh.ok());
  auto membrane = es::Membrane::create(*mesh, {});
  ASSERT_TRUE(membrane.ok());
  // A generic 3-D deformation: stretched, sheared, bent out of plane, jittered.
  auto x = flat_positions(*mesh);
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double u = x[i].x(), v = x[i].y();
    x[i] = es::Vec3(1.3 * u + 0.2 * v + 1e-4 * std::sin(7.0 * i), 0.9 * v + 1e-4 * std::cos(3.0 * i),
                    20.0 * u * v + 5.0 * u * u);
  }
  std::vector<es::Vec3> g;
  const double e = membrane->energy(x, &g);
  ASSERT_TRUE(std::isfinite(e));
  ASSERT_GT(e, 0.0);
  const double h = 1e-8;
  double worst = 0.0, scale = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      auto xp = x, xm = x;
      xp[i][c] += h;
      xm[i][c] -= h;
      const double fd = (membrane->energy(xp) - membrane->energy(xm)) / (2.0 * h);
      worst = std::max(worst, std::abs(fd - g[i][c]));
      scale = std::max(scale, std::abs(g[i][c]));
    }
  }
  // Central differences of an O(1e-3) J energy at h = 1e-8 m: truncation
  // ~h^2 and round-off ~1e-16 * E / h; both far below 1e-5 of the largest entry.
  EXPECT_LT(worst, 1e-5 * scale) << "largest gradient entry " << scale;
}

TEST(Membrane, RestStateIsStressFreeAndCollapseIsRefused) {
  auto mesh = es::rectangle_mesh(0.006, 0.006, 0.002);
  ASSERT_TRUE(mesh.ok());
  auto membrane = es::Membrane::create(*mesh, {});
  ASSERT_TRUE(membrane.ok());
  auto x = flat_positions(*mesh);
  std::vector<es::Vec3> g;
  EXPECT_NEAR(membrane->energy(x, &g), 0.0, 1e-15);
  for (const auto& gi : g) EXPECT_LT(gi.norm(), 1e-12);
  // A rigid motion costs nothing either.
  for (auto& p : x) p = es::Vec3(p.y(), 0.3, -p.x());
  EXPECT_NEAR(membrane->energy(x), 0.0, 1e-12);
  // Flatten everything onto a line: every triangle collapses.
  for (auto& p : x) p.y() = p.z() = 0.0;
  EXPECT_TRUE(std::isinf(membrane->energy(x)));
}

TEST(Membrane, RefusesBadInput) {
  es::MembraneMaterial bad;
  bad.youngs_modulus_pa = -1.0;
  EXPECT_FALSE(bad.validate().ok());
  es::SheetMesh empty;
  EXPECT_FALSE(es::Membrane::create(empty, {}).ok());
}

// Incompressible plane stress: stretching by lambda with free sides gives a
// width of 1/sqrt(lambda) and an area of sqrt(lambda). The clamps hold the
// ends at full width; that disturbance decays within about one width
// (Saint-Venant), and the middle of a 50 mm cell is 1.7 widths from either
// clamp, so 1 % is left for the clamps and the 1 mm mesh together.
TEST(UniaxialStretchRig, IncompressibleWidthAndAreaRatios) {
  auto rig = es::UniaxialStretchRig::create({});
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  const double width = 0.015, length = 0.050;
  for (double lambda : {1.2, 1.5, 2.0}) {
    auto r = rig->set_stretch(lambda);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_TRUE(r->converged);
    EXPECT_NEAR(rig->mid_width_m() / width, 1.0 / std::sqrt(lambda), 0.01 / std::sqrt(lambda)) << "lambda " << lambda;
    // The triangles of the middle fifth of the rest cell.
    const auto ratios = es::triangle_area_ratios(rig->mesh(), rig->vertices_m());
    const auto stretch = es::triangle_max_principal_stretch(rig->mesh(), rig->vertices_m());
    double sum = 0.0, sum_stretch = 0.0;
    int count = 0;
    for (std::size_t t = 0; t < rig->mesh().triangles.size(); ++t) {
      double y = 0.0;
      for (auto i : rig->mesh().triangles[t]) y += rig->mesh().vertices_m[i].y() / 3.0;
      if (std::abs(y - 0.5 * length) > 0.1 * length) continue;
      sum += ratios[t];
      sum_stretch += stretch[t];
      ++count;
    }
    ASSERT_GT(count, 0);
    EXPECT_NEAR(sum / count, std::sqrt(lambda), 0.01 * std::sqrt(lambda)) << "lambda " << lambda;
    EXPECT_NEAR(sum_stretch / count, lambda, 0.01 * lambda) << "lambda " << lambda;
    // The clamped ends keep their width exactly.
    double lo = 1e9, hi = -1e9;
    for (std::size_t i = 0; i < rig->mesh().vertices_m.size(); ++i) {
      if (rig->mesh().vertices_m[i].y() > 1e-12) continue;
      lo = std::min(lo, rig->vertices_m()[i].x());
      hi = std::max(hi, rig->vertices_m()[i].x());
    }
    EXPECT_NEAR(hi - lo, width, 1e-12);
  }
  EXPECT_FALSE(rig->set_stretch(-1.0).ok());
}

TEST(StringPullRig, FrameHoldsAndStringsStretchTheSheetUnevenly) {
  auto layout = proprio::stretch_array::StripArrayLayout::prototype_92();
  auto mesh = proprio::stretch_array::build_sheet_mesh(layout);
  ASSERT_TRUE(mesh.ok());
  es::StringPullOptions options;
  options.seed = 5;
  auto rig = es::StringPullRig::create(*mesh, options);
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  ASSERT_EQ(rig->strings().size(), 3u);
  double largest_spread = 0.0;
  for (int k = 0; k <= 40; ++k) {
    const double t = 0.25 * k;
    auto r = rig->step(t);
    ASSERT_TRUE(r.ok()) << r.error().message;
    const auto& x = rig->vertices_m();
    // The clips follow their strings.
    for (std::size_t s = 0; s < rig->strings().size(); ++s) {
      const auto& str = rig->strings()[s];
      for (auto i : str.clip_vertices) {
        const Eigen::Vector2d expected = mesh->vertices_m[i] + rig->pull_m(s, t) * str.direction;
        EXPECT_NEAR((x[i].head<2>() - expected).norm(), 0.0, 1e-12);
      }
      EXPECT_GE(rig->pull_m(s, t), 0.0);
      EXPECT_LE(rig->pull_m(s, t), options.max_pull_m);
    }
    const auto ratios = es::triangle_area_ratios(rig->mesh(), x);
    for (double a : ratios) ASSERT_TRUE(std::isfinite(a) && a > 0.2 && a < 3.0);
    largest_spread = std::max(largest_spread, *std::max_element(ratios.begin(), ratios.end()) -
                                                  *std::min_element(ratios.begin(), ratios.end()));
  }
  // The corners of the frame never move; the stretch varies across the sheet.
  EXPECT_GT(largest_spread, 0.1);
  for (std::size_t i = 0; i < mesh->vertices_m.size(); ++i) {
    EXPECT_DOUBLE_EQ(rig->vertices_m()[i].z(), 0.0);
  }
}

TEST(MaterialPoints, FollowAffineMotionExactlyAndRefuseOutsidePoints) {
  auto mesh = es::rectangle_mesh(0.020, 0.030, 0.003);
  ASSERT_TRUE(mesh.ok());
  Eigen::Matrix<double, 3, 2> a;
  a << 1.2, 0.1, -0.05, 0.9, 0.3, 0.2;
  const es::Vec3 b(0.01, -0.02, 0.05);
  std::vector<es::Vec3> x;
  for (const auto& p : mesh->vertices_m) x.push_back(a * p + b);
  for (const Eigen::Vector2d& p : {Eigen::Vector2d(0.0071, 0.0133), Eigen::Vector2d(0.0, 0.0), Eigen::Vector2d(0.02, 0.03)}) {
    auto mp = es::locate_material_point(*mesh, p);
    ASSERT_TRUE(mp.ok()) << mp.error().message;
    EXPECT_NEAR((es::material_point_position_m(*mesh, x, *mp) - (a * p + b)).norm(), 0.0, 1e-12);
  }
  EXPECT_FALSE(es::locate_material_point(*mesh, Eigen::Vector2d(0.03, 0.01)).ok());
  // Areas scale with det of the in-plane map.
  std::vector<es::Vec3> doubled;
  for (const auto& p : mesh->vertices_m) doubled.emplace_back(2.0 * p.x(), 2.0 * p.y(), 0.0);
  const auto areas = es::triangle_areas_m2(*mesh, doubled);
  for (std::size_t t = 0; t < areas.size(); ++t) EXPECT_NEAR(areas[t], 4.0 * mesh->triangle_area_m2(t), 1e-15);
}
