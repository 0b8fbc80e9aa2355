// ARAP deformation with positional constraints, and the Procrustes fit.
#include "proprio/stretch_array_recon/arap.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "proprio/stretch_array_recon/recon_mesh.hpp"

namespace proprio::stretch_array_recon {
namespace test_arap {

using stretch_array::StripArrayLayout;

Eigen::Isometry3d some_rigid_motion() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = (Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()) *
                Eigen::AngleAxisd(-0.4, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.3, -0.2, 1.1);
  return T;
}

Eigen::MatrixX3d apply(const Eigen::Isometry3d& T, const Eigen::MatrixX3d& P) {
  return (P * T.linear().transpose()).rowwise() + T.translation().transpose();
}

Eigen::MatrixX3d rows(const Eigen::MatrixX3d& V, const std::vector<std::uint32_t>& idx) {
  Eigen::MatrixX3d out(static_cast<Eigen::Index>(idx.size()), 3);
  for (std::size_t k = 0; k < idx.size(); ++k) out.row(static_cast<Eigen::Index>(k)) = V.row(idx[k]);
  return out;
}

struct Prototype {
  ReconMesh mesh;
  std::vector<std::uint32_t> markers;
};

Prototype prototype() {
  auto m = build_recon_mesh(StripArrayLayout::prototype_92());
  EXPECT_TRUE(m);
  auto mk = select_marker_vertices(*m);
  EXPECT_TRUE(mk);
  return {*m, *mk};
}

TEST(Procrustes, RecoversAKnownTransform) {
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 0.05);
  Eigen::MatrixX3d A(7, 3);
  for (Eigen::Index i = 0; i < A.rows(); ++i) A.row(i) << n(rng), n(rng), n(rng);
  const Eigen::Isometry3d T = some_rigid_motion();
  auto fit = fit_rigid(A, apply(T, A));
  ASSERT_TRUE(fit) << fit.error().message;
  EXPECT_LT((fit->matrix() - T.matrix()).norm(), 1e-12);
  EXPECT_NEAR(fit->linear().determinant(), 1.0, 1e-12);
}

TEST(Procrustes, ThreePointsAndAReflectionFreeFit) {
  Eigen::MatrixX3d A(3, 3);
  A << 0, 0, 0, 0.1, 0, 0, 0, 0.05, 0;  // planar: a reflection fits as well as the rotation
  const Eigen::Isometry3d T = some_rigid_motion();
  auto fit = fit_rigid(A, apply(T, A));
  ASSERT_TRUE(fit);
  EXPECT_LT((fit->matrix() - T.matrix()).norm(), 1e-12);
}

TEST(Procrustes, RefusesCollinearAndTooFewPoints) {
  Eigen::MatrixX3d A(3, 3);
  A << 0, 0, 0, 1, 0, 0, 2, 0, 0;
  auto fit = fit_rigid(A, A);
  ASSERT_FALSE(fit);
  EXPECT_NE(fit.error().message.find("line"), std::string::npos);
  EXPECT_FALSE(fit_rigid(A.topRows(2), A.topRows(2)));
}

TEST(Arap, RigidMotionIsReproducedExactlyAndConstraintsKept) {
  const Prototype p = prototype();
  for (double radius : {0.0, 0.06}) {
    const Eigen::MatrixX3d rest = rest_shape(p.mesh, radius);
    auto arap = ArapDeformer::create(rest, p.mesh.triangles);
    ASSERT_TRUE(arap) << arap.error().message;
    const Eigen::MatrixX3d moved = apply(some_rigid_motion(), rest);
    Eigen::MatrixX3d V;  // no guess: starts from the Procrustes fit
    ArapStats st;
    ASSERT_TRUE(arap->solve(p.markers, rows(moved, p.markers), V, &st));
    EXPECT_LT((V - moved).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_LT(arap->energy(V), 1e-16);

    // From a poor guess (the rest shape itself) it still converges there.
    ArapOptions o;
    o.max_iterations = 500;
    o.tolerance_m = 1e-12;
    auto arap2 = ArapDeformer::create(rest, p.mesh.triangles, o);
    ASSERT_TRUE(arap2);
    // A small motion: ARAP from a far-off guess may sit in another minimum.
    Eigen::Isometry3d small = Eigen::Isometry3d::Identity();
    small.linear() = Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    small.translation() = Eigen::Vector3d(0.01, 0.0, 0.02);
    const Eigen::MatrixX3d moved2 = apply(small, rest);
    Eigen::MatrixX3d V2 = rest;
    ASSERT_TRUE(arap2->solve(p.markers, rows(moved2, p.markers), V2));
    // ARAP's local-global iterations converge slowly from a far guess.
    EXPECT_LT((V2 - moved2).cwiseAbs().maxCoeff(), 2e-4);
    for (std::uint32_t v : p.markers) EXPECT_EQ(V2.row(v), moved2.row(v));
  }
}

TEST(Arap, BendingAFlatSheetOntoACylinderFromItsMarkers) {
  // The known deformation: the flat sheet rolled onto a cylinder of 6 cm (an
  // isometry, which ARAP can represent up to the triangle discretisation).
  const Prototype p = prototype();
  const Eigen::MatrixX3d flat = rest_shape(p.mesh, 0.0);
  const Eigen::MatrixX3d bent = rest_shape(p.mesh, 0.08);
  ArapOptions o;
  o.max_iterations = 200;
  o.tolerance_m = 1e-9;
  auto arap = ArapDeformer::create(flat, p.mesh.triangles, o);
  ASSERT_TRUE(arap);
  Eigen::MatrixX3d V;
  ASSERT_TRUE(arap->solve(p.markers, rows(bent, p.markers), V));
  // Beyond the outermost markers (the bare corners of the banded layout,
  // 4 cm from any marker) nothing says the sheet keeps bending: ARAP
  // continues it flat there, as any deformation from sparse constraints
  // would. The test judges the sheet among the markers.
  std::vector<Eigen::Index> among;
  for (Eigen::Index i = 0; i < flat.rows(); ++i) {
    double nearest = 1e9;
    for (std::uint32_t v : p.markers) nearest = std::min(nearest, (flat.row(i) - flat.row(v)).norm());
    if (nearest <= 0.02) among.push_back(i);
  }
  ASSERT_GT(among.size(), flat.rows() / 2);
  Eigen::VectorXd err(static_cast<Eigen::Index>(among.size()));
  double sag = 0.0;
  for (std::size_t k = 0; k < among.size(); ++k) {
    err(static_cast<Eigen::Index>(k)) = (V.row(among[k]) - bent.row(among[k])).norm();
    sag = std::max(sag, (flat.row(among[k]) - bent.row(among[k])).norm());
  }
  // Without a solver the error would be the bend's sag itself.
  EXPECT_GT(sag, 0.02);
  EXPECT_LT(err.mean(), 1e-3) << "sag " << sag << " max " << err.maxCoeff();
  // The worst vertices sit at the edge of that region (measured: 6 mm of 33 mm sag).
  EXPECT_LT(err.maxCoeff(), 0.25 * sag);
  for (std::uint32_t v : p.markers) EXPECT_LT((V.row(v) - bent.row(v)).norm(), 1e-15);
}

TEST(Arap, CachesOneFactorisationPerConstraintSet) {
  const Prototype p = prototype();
  const Eigen::MatrixX3d rest = rest_shape(p.mesh, 0.0);
  ArapOptions o;
  o.factor_cache_size = 2;
  auto arap = ArapDeformer::create(rest, p.mesh.triangles, o);
  ASSERT_TRUE(arap);
  Eigen::MatrixX3d V;
  ArapStats st;
  const std::vector<std::uint32_t> a(p.markers.begin(), p.markers.end());
  const std::vector<std::uint32_t> b(p.markers.begin(), p.markers.end() - 1);
  const std::vector<std::uint32_t> c(p.markers.begin() + 1, p.markers.end());
  ASSERT_TRUE(arap->solve(a, rows(rest, a), V, &st));
  EXPECT_TRUE(st.refactored);
  ASSERT_TRUE(arap->solve(a, rows(rest, a), V, &st));
  EXPECT_FALSE(st.refactored);
  ASSERT_TRUE(arap->solve(b, rows(rest, b), V, &st));
  EXPECT_TRUE(st.refactored);
  ASSERT_TRUE(arap->solve(c, rows(rest, c), V, &st));
  EXPECT_TRUE(st.refactored);
  EXPECT_EQ(arap->cached_factorisations(), 2u);
  ASSERT_TRUE(arap->solve(a, rows(rest, a), V, &st));  // evicted
  EXPECT_TRUE(st.refactored);
}

TEST(Arap, RefusesBadConstraints) {
  const Prototype p = prototype();
  const Eigen::MatrixX3d rest = rest_shape(p.mesh, 0.0);
  auto arap = ArapDeformer::create(rest, p.mesh.triangles);
  ASSERT_TRUE(arap);
  Eigen::MatrixX3d V;
  EXPECT_FALSE(arap->solve({}, Eigen::MatrixX3d(0, 3), V));
  EXPECT_FALSE(arap->solve({0, 0}, Eigen::MatrixX3d::Zero(2, 3), V));
  EXPECT_FALSE(arap->solve({0, 1}, Eigen::MatrixX3d::Zero(3, 3), V));
  EXPECT_FALSE(arap->solve({static_cast<std::uint32_t>(rest.rows())}, Eigen::MatrixX3d::Zero(1, 3), V));
  Eigen::MatrixX3d nan = Eigen::MatrixX3d::Zero(1, 3);
  nan(0, 0) = std::nan("");
  EXPECT_FALSE(arap->solve({0}, nan, V));
}

TEST(Arap, APartWithoutConstraintsIsRefused) {
  // Two separate triangles, constraints on the first only.
  Eigen::MatrixX3d rest(6, 3);
  rest << 0, 0, 0, 1, 0, 0, 0, 1, 0, 5, 0, 0, 6, 0, 0, 5, 1, 0;
  auto arap = ArapDeformer::create(rest, {{0, 1, 2}, {3, 4, 5}});
  ASSERT_TRUE(arap) << arap.error().message;
  Eigen::MatrixX3d V;
  const Status s = arap->solve({0, 1, 2}, rest.topRows(3), V);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("connected part"), std::string::npos) << s.error().message;
}

}  // namespace test_arap
}  // namespace proprio::stretch_array_recon
