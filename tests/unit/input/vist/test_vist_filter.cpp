// The VIST error-state EKF: measurement Jacobians against finite differences,
// the JPL -> Hamilton boundary, the transition matrix against the nominal
// integrator, and the filter's behaviour on clean and broken data.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "proprio/core/random.hpp"
#include "proprio/vist/segment_filter.hpp"

namespace proprio::vist {
namespace {

using Vec21 = Eigen::Matrix<double, kSegmentErrorDim, 1>;

SegmentState random_state(Rng& rng) {
  SegmentState s;
  s.p_imu_in_world = Vec3(rng.uniform(-1, 1), rng.uniform(0, 2), rng.uniform(-1, 1));
  s.v_imu_in_world = Vec3(rng.normal(), rng.normal(), rng.normal()) * 0.3;
  s.q_world_imu = so3_exp(Vec3(rng.normal(), rng.normal(), rng.normal()));
  s.gyro_bias_radps = Vec3(rng.normal(), rng.normal(), rng.normal()) * 0.02;
  s.accel_bias_mps2 = Vec3(rng.normal(), rng.normal(), rng.normal()) * 0.1;
  s.scale = Vec3(rng.uniform(0.9, 1.1), rng.uniform(0.9, 1.1), rng.uniform(0.9, 1.1));
  s.q_imu_segment = so3_exp(Vec3(rng.normal(), rng.normal(), rng.normal()) * 0.5);
  return s;
}

Vec21 unit(int i, double h) {
  Vec21 dx = Vec21::Zero();
  dx(i) = h;
  return dx;
}

TEST(VistFilterJacobians, MarkerModelMatchesCentralDifferences) {
  Rng rng(11);
  for (int trial = 0; trial < 20; ++trial) {
    const SegmentState s = random_state(rng);
    const Vec3 lever(rng.uniform(-0.03, 0.03), rng.uniform(-0.02, 0.02), rng.uniform(-0.04, 0.04));
    VistFilter::H3 H;
    VistFilter::marker_model(s, lever, &H);
    const double h = 1e-6;
    for (int i = 0; i < kSegmentErrorDim; ++i) {
      SegmentState a = s, b = s;
      VistFilter::inject(a, unit(i, h));
      VistFilter::inject(b, unit(i, -h));
      const Vec3 numeric = (VistFilter::marker_model(a, lever, nullptr) - VistFilter::marker_model(b, lever, nullptr)) / (2 * h);
      EXPECT_LT((numeric - H.col(i)).norm(), 1e-7) << "column " << i << " trial " << trial;
    }
  }
}

TEST(VistFilterJacobians, ConstraintModelsMatchCentralDifferences) {
  Rng rng(12);
  for (int trial = 0; trial < 20; ++trial) {
    const SegmentState p = random_state(rng), c = random_state(rng);
    PositionConstraint pc;
    pc.lever_in_parent = Vec3(0.01, 0.005, -0.03);
    pc.lever_in_child = Vec3(0.0, -0.008, 0.02);
    RotationConstraint rc;
    rc.a_in_parent = Vec3(0.2, 0.9, 0.1).normalized();
    rc.b_in_child = Vec3::UnitX();
    VistFilter::H3 Hp, Hc;
    VistFilter::position_constraint_model(p, c, pc, &Hp, &Hc);
    VistFilter::H1 Rp, Rc;
    VistFilter::rotation_constraint_model(p, c, rc, &Rp, &Rc);
    const double h = 1e-6;
    for (int i = 0; i < kSegmentErrorDim; ++i) {
      for (int side = 0; side < 2; ++side) {
        SegmentState pa = p, pb = p, ca = c, cb = c;
        VistFilter::inject(side == 0 ? pa : ca, unit(i, h));
        VistFilter::inject(side == 0 ? pb : cb, unit(i, -h));
        const Vec3 dpos = (VistFilter::position_constraint_model(pa, ca, pc, nullptr, nullptr) -
                           VistFilter::position_constraint_model(pb, cb, pc, nullptr, nullptr)) /
                          (2 * h);
        const double drot = (VistFilter::rotation_constraint_model(pa, ca, rc, nullptr, nullptr) -
                             VistFilter::rotation_constraint_model(pb, cb, rc, nullptr, nullptr)) /
                            (2 * h);
        EXPECT_LT((dpos - (side == 0 ? Hp : Hc).col(i)).norm(), 1e-7) << "position, side " << side << " col " << i;
        EXPECT_NEAR(drot, (side == 0 ? Rp : Rc)(0, i), 1e-7) << "rotation, side " << side << " col " << i;
      }
    }
  }
}

// The thesis writes its filter in JPL quaternions (Trawny & Roumeliotis 2005):
// q̄ = [v; w] represents C(q̄), the rotation from global to local, and the
// error is δq̄ ⊗ q̄̂ with the JPL product. We use Hamilton q_world_imu with the
// local perturbation q̂ ⊗ Exp(δθ). Check that these are the same thing.
TEST(VistFilterConventions, JplErrorQuaternionIsHamiltonLocalPerturbation) {
  auto jpl_C = [](const Eigen::Vector4d& q) {  // T&R eq. 78: C = (2w² - 1) I - 2 w [v×] + 2 v vᵀ
    const Vec3 v = q.head<3>();
    const double w = q(3);
    return Mat3((2 * w * w - 1) * Mat3::Identity() - 2 * w * skew(v) + 2 * v * v.transpose());
  };
  auto jpl_mul = [](const Eigen::Vector4d& q, const Eigen::Vector4d& p) {  // T&R eq. 8: L(q) p
    Eigen::Matrix4d L;
    L.topLeftCorner<3, 3>() = q(3) * Mat3::Identity() - skew(q.head<3>());
    L.topRightCorner<3, 1>() = q.head<3>();
    L.bottomLeftCorner<1, 3>() = -q.head<3>().transpose();
    L(3, 3) = q(3);
    return Eigen::Vector4d(L * p);
  };
  Rng rng(13);
  for (int trial = 0; trial < 20; ++trial) {
    const Quat q_world_imu = so3_exp(Vec3(rng.normal(), rng.normal(), rng.normal()));
    const Eigen::Vector4d q_jpl(q_world_imu.x(), q_world_imu.y(), q_world_imu.z(), q_world_imu.w());
    // Same four numbers: JPL's C(q̄) (global -> local) is the transpose of Hamilton's R (local -> global).
    EXPECT_LT((jpl_C(q_jpl) - q_world_imu.toRotationMatrix().transpose()).norm(), 1e-12);
    const Vec3 dtheta = Vec3(rng.normal(), rng.normal(), rng.normal()) * 0.05;
    const Quat dq = so3_exp(dtheta);
    const Eigen::Vector4d dq_jpl(dq.x(), dq.y(), dq.z(), dq.w());
    const Eigen::Vector4d true_jpl = jpl_mul(dq_jpl, q_jpl);
    const Quat true_hamilton = boxplus(q_world_imu, dtheta);
    EXPECT_LT((true_jpl - Eigen::Vector4d(true_hamilton.x(), true_hamilton.y(), true_hamilton.z(), true_hamilton.w()))
                  .norm(),
              1e-12);
  }
}

// Φ (eq. 4.24, discretised) is the Jacobian of one nominal IMU step with
// respect to the error state: checked numerically through the same
// boxplus/boxminus the filter uses.
TEST(VistFilterConventions, TransitionIsTheJacobianOfTheNominalStep) {
  Rng rng(14);
  const Vec3 g(0, -9.80665, 0);
  const double dt = 0.01;
  for (int trial = 0; trial < 10; ++trial) {
    const SegmentState s = random_state(rng);
    const Vec3 w = Vec3(rng.normal(), rng.normal(), rng.normal());
    const Vec3 a = Vec3(rng.normal(), rng.normal(), rng.normal()) * 3.0 + Vec3(0, 9.8, 0);
    const auto phi = VistFilter::transition(s, dt, w, a);
    auto error_after = [&](const Vec21& dx0) {
      SegmentState x = s, xr = s;
      VistFilter::inject(x, dx0);
      VistFilter::integrate_nominal(x, dt, w, a, g);
      VistFilter::integrate_nominal(xr, dt, w, a, g);
      Eigen::Matrix<double, 15, 1> e;
      e.segment<3>(0) = x.p_imu_in_world - xr.p_imu_in_world;
      e.segment<3>(3) = x.v_imu_in_world - xr.v_imu_in_world;
      e.segment<3>(6) = boxminus(x.q_world_imu, xr.q_world_imu);
      e.segment<3>(9) = x.gyro_bias_radps - xr.gyro_bias_radps;
      e.segment<3>(12) = x.accel_bias_mps2 - xr.accel_bias_mps2;
      return e;
    };
    const double h = 1e-6;
    for (int i = 0; i < 15; ++i) {
      const Eigen::Matrix<double, 15, 1> col = (error_after(unit(i, h)) - error_after(unit(i, -h))) / (2 * h);
      // First-order discretisation: entries agree to O(dt²·|w|·|a|).
      EXPECT_LT((col - phi.col(i)).norm(), 2e-3) << "column " << i;
    }
  }
}

VistModel thesis_model() {
  auto shape = HandShape::from_measurements(0.19, 0.10);
  auto m = VistModel::build(ImuGloveDescription::vist_default(), *shape, Handedness::right);
  EXPECT_TRUE(m) << m.error().message;
  return *m;
}

TEST(VistModel, ThesisGloveHasTheThesisConstraints) {
  const VistModel m = thesis_model();
  EXPECT_EQ(m.segments.size(), 7u);
  EXPECT_EQ(m.markers.size(), 37u);
  EXPECT_EQ(m.position_constraints.size(), 6u);  // thumb CMC, MCP; index and middle MCP, PIP
  EXPECT_EQ(m.rotation_constraints.size(), 7u);  // no twist at 3 MCPs; no twist/abduction at 2 PIPs
  EXPECT_EQ(m.scale_couplings.size(), 3u);
}

TEST(VistModel, RejectsAMarkerOnASegmentWithoutAnImu) {
  ImuGloveDescription g = ImuGloveDescription::vist_default();
  MarkerSpec extra;
  extra.segment = HandJoint::ring_proximal;
  g.markers.push_back(extra);
  auto shape = HandShape::from_measurements(0.19, 0.10);
  auto m = VistModel::build(g, *shape, Handedness::right);
  ASSERT_FALSE(m);
  EXPECT_NE(m.error().message.find("ring_proximal"), std::string::npos) << m.error().message;
}

// The true hand: the nominal model's segments at rest poses, IMUs level.
std::vector<SegmentState> rest_states(const VistModel& m) {
  std::vector<SegmentState> out(m.segments.size());
  for (std::size_t k = 0; k < out.size(); ++k) {
    out[k].p_imu_in_world = Vec3(0.05 * static_cast<double>(k), 1.2, -0.4);
    out[k].q_imu_segment = m.segments[k].q_segment_imu.conjugate();
  }
  return out;
}

TEST(VistFilter, AtRestWithIdealSamplesItStaysPutAndGrowsUncertain) {
  const VistModel m = thesis_model();
  auto f = VistFilter::create(m);
  ASSERT_TRUE(f);
  const auto truth = rest_states(m);
  ASSERT_TRUE(f->initialize(0, truth));
  const double p0 = f->segment_covariance(0)(0, 0);
  for (int i = 1; i <= 100; ++i) {
    for (std::size_t k = 0; k < m.segments.size(); ++k) {
      ASSERT_TRUE(f->propagate(k, i * 10'000'000, Vec3::Zero(), Vec3(0, 9.80665, 0)));
    }
  }
  for (std::size_t k = 0; k < m.segments.size(); ++k) {
    EXPECT_LT((f->state(k).p_imu_in_world - truth[k].p_imu_in_world).norm(), 1e-9);
    EXPECT_LT(angle_between(f->state(k).q_world_imu, truth[k].q_world_imu), 1e-9);
  }
  const Eigen::MatrixXd& P = f->covariance();
  EXPECT_GT(P(0, 0), p0);
  EXPECT_LT((P - P.transpose()).norm(), 1e-12);
  EXPECT_EQ(Eigen::LLT<Eigen::MatrixXd>(P).info(), Eigen::Success);
}

TEST(VistFilter, MarkersPullAPerturbedHandOntoTheTruth) {
  const VistModel m = thesis_model();
  auto f = VistFilter::create(m);
  ASSERT_TRUE(f);
  const auto truth = rest_states(m);
  auto start = truth;
  Rng rng(15);
  for (auto& s : start) {
    s.p_imu_in_world += Vec3(rng.normal(), rng.normal(), rng.normal()) * 0.01;
    s.q_world_imu = boxplus(s.q_world_imu, Vec3(rng.normal(), rng.normal(), rng.normal()) * 0.05);
  }
  ASSERT_TRUE(f->initialize(0, start));
  std::vector<MarkerMeasurement> z;
  for (std::size_t j = 0; j < m.markers.size(); ++j) {
    z.push_back({j, truth[m.markers[j].segment].point_in_world(m.markers[j].lever_in_segment), Mat3::Identity() * 1e-6});
  }
  auto marker_error = [&] {
    double e = 0.0;
    for (std::size_t j = 0; j < m.markers.size(); ++j) e = std::max(e, (f->marker_in_world(j) - z[j].p_in_world).norm());
    return e;
  };
  const double before = marker_error();
  for (int i = 0; i < 5; ++i) f->correct(z, false);
  EXPECT_GT(before, 0.01);
  EXPECT_LT(marker_error(), 5e-4);
}

TEST(VistFilter, RejectsNonFiniteInputsAndStaysFinite) {
  const VistModel m = thesis_model();
  auto f = VistFilter::create(m);
  ASSERT_TRUE(f);
  ASSERT_TRUE(f->initialize(0, rest_states(m)));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(f->propagate(0, 10'000'000, Vec3(nan, 0, 0), Vec3(0, 9.8, 0)));
  EXPECT_FALSE(f->propagate(0, 10'000'000, Vec3::Zero(), Vec3(0, std::numeric_limits<double>::infinity(), 0)));
  std::vector<MarkerMeasurement> z = {{0, Vec3(nan, 0, 0), Mat3::Identity() * 1e-6}};
  const auto st = f->correct(z, false);
  EXPECT_EQ(st.markers_used, 0u);
  EXPECT_EQ(st.markers_gated, 1u);
  EXPECT_TRUE(f->covariance().allFinite());
  for (const auto& s : f->states()) EXPECT_TRUE(s.p_imu_in_world.allFinite());
}

TEST(VistFilter, GatesAnOutlierMarker) {
  const VistModel m = thesis_model();
  auto f = VistFilter::create(m);
  ASSERT_TRUE(f);
  const auto truth = rest_states(m);
  ASSERT_TRUE(f->initialize(0, truth));
  // Half a metre off: far beyond the 3 cm initial position sigma.
  std::vector<MarkerMeasurement> z = {{0, f->marker_in_world(0) + Vec3(0.5, 0, 0), Mat3::Identity() * 1e-6}};
  const auto st = f->correct(z, false);
  EXPECT_EQ(st.markers_gated, 1u);
  EXPECT_LT((f->state(0).p_imu_in_world - truth[0].p_imu_in_world).norm(), 1e-12);
}

TEST(VistFilterOptions, ValidateNamesTheBadField) {
  FilterOptions o;
  o.joint_position_sigma_m = 0.0;
  const auto st = o.validate();
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().message.find("joint_position_sigma_m"), std::string::npos);
  EXPECT_NE(FilterOptions{}.describe().find("chi²"), std::string::npos);
}

}  // namespace
}  // namespace proprio::vist
