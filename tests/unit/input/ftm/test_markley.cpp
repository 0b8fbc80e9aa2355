// Markley's SVD solution of Wahba's problem: exact on noise-free vectors,
// a proper rotation, weights that matter when the vectors disagree, and clear
// errors where two vectors cannot fix an attitude.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "proprio/core/random.hpp"
#include "proprio/ftm/markley.hpp"

namespace proprio::ftm {
namespace markley_test {

Quat random_rotation(Rng& rng) {
  // Uniform on SO(3): a normalised 4D Gaussian.
  Quat q(rng.normal(), rng.normal(), rng.normal(), rng.normal());
  return q.normalized();
}

Vec3 random_direction(Rng& rng) { return Vec3(rng.normal(), rng.normal(), rng.normal()).normalized(); }

TEST(MarkleyAttitude, RecoversKnownRotationsExactlyFromNoiseFreeVectors) {
  Rng rng(27001);
  double worst_rad = 0.0;
  for (int i = 0; i < 500; ++i) {
    const Quat q_world_body = random_rotation(rng);
    // References of any geometry (not only gravity + a 60° dip field) and
    // magnitudes that differ from the body readings: only directions count.
    Vec3 g_ref = random_direction(rng) * 9.81, m_ref = random_direction(rng) * 48.0;
    if (g_ref.normalized().cross(m_ref.normalized()).norm() < 0.05) continue;
    const Vec3 accel = (q_world_body.conjugate() * g_ref) * rng.uniform(0.5, 2.0);
    const Vec3 mag = (q_world_body.conjugate() * m_ref) * rng.uniform(0.5, 2.0);
    const WahbaWeights w{rng.uniform(0.01, 10.0), rng.uniform(0.01, 10.0)};
    const Result<Quat> q = markley_attitude(accel, mag, g_ref, m_ref, w);
    ASSERT_TRUE(q.ok()) << q.error().message;
    EXPECT_NEAR(q->norm(), 1.0, 1e-12);
    worst_rad = std::max(worst_rad, angle_between(*q, q_world_body));
  }
  EXPECT_LT(worst_rad, 1e-9) << "worst recovery error " << worst_rad << " rad";
}

TEST(MarkleyAttitude, ProperRotationForAllQuadrantsOfTheSvd) {
  // With two vectors the attitude profile matrix has rank 2: the third
  // singular vector's sign is arbitrary, and without Markley's det(U)det(V)
  // factor half of these would come out as reflections (a wrong rotation).
  const Vec3 g_ref(0, 0, 9.81), m_ref(24.0, 0.0, -41.57);
  for (double yaw_deg = -180.0; yaw_deg < 180.0; yaw_deg += 15.0) {
    for (double pitch_deg : {-89.0, -45.0, 0.0, 30.0, 89.0}) {
      const Quat q_true = Quat(Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Vec3::UnitZ())) *
                          Quat(Eigen::AngleAxisd(pitch_deg * M_PI / 180.0, Vec3::UnitY())) *
                          Quat(Eigen::AngleAxisd(0.3, Vec3::UnitX()));
      const Result<Quat> q = markley_attitude(q_true.conjugate() * g_ref, q_true.conjugate() * m_ref, g_ref, m_ref);
      ASSERT_TRUE(q.ok()) << q.error().message;
      EXPECT_NEAR(q->toRotationMatrix().determinant(), 1.0, 1e-12);
      EXPECT_LT(angle_between(*q, q_true), 1e-9) << "yaw " << yaw_deg << " pitch " << pitch_deg;
    }
  }
}

TEST(MarkleyAttitude, WeightsDecideWhichVectorIsMatchedWhenTheyDisagree) {
  const Vec3 g_ref(0, 0, 9.81), m_ref(24.0, 0.0, -41.57);
  // The compass reads a field whose dip is 20° off the reference: no rotation
  // matches both, so the solution leans toward the heavier weight.
  const Vec3 accel = g_ref;
  const Vec3 mag = Quat(Eigen::AngleAxisd(20.0 * M_PI / 180.0, Vec3::UnitY())) * m_ref;
  auto residual_deg = [](const Quat& q, const Vec3& body, const Vec3& ref) {
    return std::acos(std::clamp(body.normalized().dot((q.conjugate() * ref).normalized()), -1.0, 1.0)) * 180.0 / M_PI;
  };
  const Result<Quat> trust_accel = markley_attitude(accel, mag, g_ref, m_ref, {1e6, 1.0});
  const Result<Quat> trust_mag = markley_attitude(accel, mag, g_ref, m_ref, {1.0, 1e6});
  const Result<Quat> equal = markley_attitude(accel, mag, g_ref, m_ref, {1.0, 1.0});
  ASSERT_TRUE(trust_accel.ok() && trust_mag.ok() && equal.ok());
  EXPECT_LT(residual_deg(*trust_accel, accel, g_ref), 1e-3);
  EXPECT_LT(residual_deg(*trust_mag, mag, m_ref), 1e-3);
  // Equal weights split the 20° between the two.
  EXPECT_NEAR(residual_deg(*equal, accel, g_ref), 10.0, 0.5);
  EXPECT_NEAR(residual_deg(*equal, mag, m_ref), 10.0, 0.5);
}

TEST(MarkleyAttitude, RefusesDegenerateInputsWithAClearError) {
  const Vec3 g(0, 0, 9.81), m(24.0, 0.0, -41.57);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  struct Case {
    const char* what;
    Vec3 accel, mag, g_ref, m_ref;
    WahbaWeights w;
    const char* mentions;
  };
  const Case cases[] = {
      {"zero accel", Vec3::Zero(), m, g, m, {}, "accel_body"},
      {"zero mag", g, Vec3::Zero(), g, m, {}, "mag_body"},
      {"zero gravity ref", g, m, Vec3::Zero(), m, {}, "gravity_ref"},
      {"zero field ref", g, m, g, Vec3::Zero(), {}, "mag_ref"},
      {"NaN accel", Vec3(nan, 0, 9.8), m, g, m, {}, "not finite"},
      {"inf mag", g, Vec3(inf, 0, 0), g, m, {}, "not finite"},
      {"parallel readings", g, Vec3(0, 0, 30.0), g, m, {}, "parallel"},
      {"antiparallel readings", g, Vec3(0, 0, -30.0), g, m, {}, "parallel"},
      {"nearly parallel readings", g, Vec3(1e-4, 0, 1.0), g, m, {}, "parallel"},
      {"field ref at 90 deg dip", g, m, g, Vec3(0, 0, -48.0), {}, "parallel"},
      {"zero weight", g, m, g, m, {0.0, 1.0}, "weights"},
      {"negative weight", g, m, g, m, {1.0, -1.0}, "weights"},
      {"NaN weight", g, m, g, m, {nan, 1.0}, "weights"},
  };
  for (const Case& c : cases) {
    const Result<Quat> q = markley_attitude(c.accel, c.mag, c.g_ref, c.m_ref, c.w);
    ASSERT_FALSE(q.ok()) << c.what;
    EXPECT_EQ(q.error().code, Errc::invalid_argument) << c.what;
    EXPECT_NE(q.error().message.find("markley_attitude"), std::string::npos) << q.error().message;
    EXPECT_NE(q.error().message.find(c.mentions), std::string::npos) << c.what << ": " << q.error().message;
  }
  // Just outside the parallel threshold (~0.3°) is still solvable.
  EXPECT_TRUE(markley_attitude(g, Vec3(0.005, 0, 1.0), g, m).ok());
}

}  // namespace markley_test
}  // namespace proprio::ftm
