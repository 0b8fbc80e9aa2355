#include "proprio/core/math.hpp"

#include <cmath>

namespace proprio {

namespace {
// Below this angle the closed forms lose precision; Taylor series take over.
constexpr double kSmallAngle = 1e-6;
}  // namespace

Eigen::Matrix4d Pose::matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = q.toRotationMatrix();
  m.topRightCorner<3, 1>() = p;
  return m;
}

Mat3 skew(const Vec3& v) {
  Mat3 m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Quat so3_exp(const Vec3& w) {
  const double theta = w.norm();
  if (theta < kSmallAngle) {
    // q ≈ [1 - θ²/8, w/2 (1 - θ²/24)]
    const double t2 = theta * theta;
    Quat q(1.0 - t2 / 8.0, 0, 0, 0);
    q.vec() = 0.5 * (1.0 - t2 / 24.0) * w;
    return q.normalized();
  }
  const double half = 0.5 * theta;
  Quat q(std::cos(half), 0, 0, 0);
  q.vec() = (std::sin(half) / theta) * w;
  return q;
}

Vec3 so3_log(const Quat& q_in) {
  Quat q = q_in.normalized();
  if (q.w() < 0) q.coeffs() = -q.coeffs();  // pick the short way round
  const double s = q.vec().norm();
  if (s < kSmallAngle) {
    // θ ≈ 2 s, and θ/s ≈ 2/w (1 + s²/(3w²))
    return (2.0 / q.w()) * (1.0 + s * s / (3.0 * q.w() * q.w())) * q.vec();
  }
  const double theta = 2.0 * std::atan2(s, q.w());
  return (theta / s) * q.vec();
}

Mat3 so3_left_jacobian(const Vec3& phi) {
  const double theta = phi.norm();
  const Mat3 K = skew(phi);
  if (theta < kSmallAngle) return Mat3::Identity() + 0.5 * K + K * K / 6.0;
  const double t2 = theta * theta;
  return Mat3::Identity() + ((1.0 - std::cos(theta)) / t2) * K +
         ((theta - std::sin(theta)) / (t2 * theta)) * K * K;
}

Mat3 so3_left_jacobian_inverse(const Vec3& phi) {
  const double theta = phi.norm();
  const Mat3 K = skew(phi);
  if (theta < kSmallAngle) return Mat3::Identity() - 0.5 * K + K * K / 12.0;
  const double t2 = theta * theta;
  const double c = (1.0 / t2) * (1.0 - (theta * std::sin(theta)) / (2.0 * (1.0 - std::cos(theta))));
  return Mat3::Identity() - 0.5 * K + c * K * K;
}

Pose se3_exp(const Vec6& xi) {
  const Vec3 rho = xi.head<3>();
  const Vec3 phi = xi.tail<3>();
  return {so3_exp(phi), so3_left_jacobian(phi) * rho};
}

Vec6 se3_log(const Pose& T) {
  const Vec3 phi = so3_log(T.q);
  Vec6 xi;
  xi.head<3>() = so3_left_jacobian_inverse(phi) * T.p;
  xi.tail<3>() = phi;
  return xi;
}

Quat boxplus(const Quat& q, const Vec3& delta_theta) { return (q * so3_exp(delta_theta)).normalized(); }

Vec3 boxminus(const Quat& q1, const Quat& q0) { return so3_log(q0.conjugate() * q1); }

Quat slerp(const Quat& q0, const Quat& q1, double t) {
  // Via the tangent space, so it also extrapolates sensibly for t outside [0,1]
  // and always takes the shortest arc (so3_log picks it).
  return boxplus(q0, t * boxminus(q1, q0));
}

Pose interpolate(const Pose& T0, const Pose& T1, double t) {
  return {slerp(T0.q, T1.q, t), T0.p + t * (T1.p - T0.p)};
}

double angle_between(const Quat& a, const Quat& b) { return boxminus(b, a).norm(); }

Quat quat_from_axes(const Vec3& x_axis, const Vec3& y_axis, const Vec3& z_axis) {
  Mat3 R;
  R.col(0) = x_axis;
  R.col(1) = y_axis;
  R.col(2) = z_axis;
  return Quat(R).normalized();
}

}  // namespace proprio
