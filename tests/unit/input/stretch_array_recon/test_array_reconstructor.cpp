// Cell ratios -> regressor -> markers -> ARAP, with a linear model whose
// outputs are known (make_models.py's lr_grid9: the flat 3 x 3 grid's corner
// cells moved rigidly, cell 0 lifting marker 3).
#include "proprio/stretch_array_recon/array_reconstructor.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

namespace proprio::stretch_array_recon {
namespace test_array_reconstructor {

using stretch_array::StripArrayLayout;

std::filesystem::path model_path() {
  return std::filesystem::path(PROPRIO_TESTS_DIR) / "data" / "stretch_array_recon" / "lr_grid9.onnx";
}

// The transform make_models.py applies to the flat corner markers.
Eigen::Isometry3d script_transform() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(30.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.1, 0.2, 0.3);
  return T;
}

struct Fixture {
  ReconMesh mesh;
  std::vector<std::uint32_t> markers;
};

Fixture grid9() {
  // grid() numbers cells top-strip-major: cell 3 t + b sits at (12 t, 12 b) mm.
  auto mesh = build_recon_mesh(StripArrayLayout::grid("g9", 3, 3, 0.012, 0.008));
  EXPECT_TRUE(mesh);
  Fixture f{*mesh, {}};
  for (std::size_t cell : {0u, 6u, 2u, 8u}) f.markers.push_back(f.mesh.centroid_vertex[cell]);
  return f;
}

Result<ArrayReconstructor> make(const Fixture& f) {
  auto reg = MarkerRegressor::load(model_path(), 9, 4);
  if (!reg) return reg.error();
  ArrayReconstructorOptions o;
  o.arap.max_iterations = 50;
  o.arap.tolerance_m = 1e-9;
  return ArrayReconstructor::create(f.mesh, f.markers, std::move(*reg), o);
}

TEST(ArrayReconstructor, RestReadingsGiveTheRigidlyMovedSheet) {
  const Fixture f = grid9();
  auto r = make(f);
  ASSERT_TRUE(r) << r.error().message;
  ASSERT_TRUE(r->align_session_from_cells(Eigen::VectorXd::Ones(9)));
  EXPECT_LT((r->T_session_rest().matrix() - script_transform().matrix()).norm(), 1e-5);
  ReconstructedFrame out;
  ASSERT_TRUE(r->reconstruct(Eigen::VectorXd::Ones(9), out));
  const Eigen::MatrixX3d want = (rest_shape(f.mesh) * script_transform().linear().transpose()).rowwise() +
                                script_transform().translation().transpose();
  EXPECT_LT((out.vertices_m - want).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_GE(out.regressor_s, 0.0);
  EXPECT_GE(out.arap_s, 0.0);
}

TEST(ArrayReconstructor, MarkersFromTheRegressorConstrainTheSheet) {
  const Fixture f = grid9();
  auto r = make(f);
  ASSERT_TRUE(r);
  // No align_session: the first frame aligns the sheet.
  Eigen::VectorXd cells = Eigen::VectorXd::Ones(9);
  cells(0) = 1.2;  // lifts marker 3 by 0.05 * 0.2 = 10 mm
  ReconstructedFrame out;
  ASSERT_TRUE(r->reconstruct(cells, out));
  EXPECT_TRUE(r->aligned());
  EXPECT_NEAR(out.markers_m(3, 2) - out.markers_m(0, 2), 0.01, 1e-6);
  for (std::size_t k = 0; k < f.markers.size(); ++k) {
    EXPECT_LT((out.vertices_m.row(f.markers[k]) - out.markers_m.row(static_cast<Eigen::Index>(k))).norm(), 1e-12);
  }
  // The lift spreads smoothly: the middle cell rises part of the way.
  const double mid = out.vertices_m(f.mesh.centroid_vertex[4], 2) - 0.3;
  EXPECT_GT(mid, 0.0005);
  EXPECT_LT(mid, 0.01);
  // Back at rest the warm-started frame returns to the rigid sheet (to
  // within ARAP's slow final convergence).
  ASSERT_TRUE(r->reconstruct(Eigen::VectorXd::Ones(9), out));
  EXPECT_LT(std::abs(out.vertices_m(f.mesh.centroid_vertex[4], 2) - 0.3), 2e-4);
}

TEST(ArrayReconstructor, RefusesMismatchesAndNanReadings) {
  const Fixture f = grid9();
  auto reg = MarkerRegressor::load(model_path(), 9, 4);
  ASSERT_TRUE(reg);
  std::vector<std::uint32_t> three(f.markers.begin(), f.markers.end() - 1);
  auto bad = ArrayReconstructor::create(f.mesh, three, std::move(*reg));
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("4 markers"), std::string::npos);

  auto r = make(f);
  ASSERT_TRUE(r);
  Eigen::VectorXd cells = Eigen::VectorXd::Ones(9);
  cells(2) = std::nan("");
  ReconstructedFrame out;
  EXPECT_FALSE(r->reconstruct(cells, out));
  EXPECT_FALSE(r->aligned());
}

}  // namespace test_array_reconstructor
}  // namespace proprio::stretch_array_recon
