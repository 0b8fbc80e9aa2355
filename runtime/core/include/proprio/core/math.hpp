#pragma once
// SO(3)/SE(3) helpers on Eigen. Quaternions are Hamilton (Eigen, GLM and OpenXR
// agree). Transforms are named by their frames: T_world_hand maps hand
// coordinates into world coordinates; p_tip_in_cam is a point.
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace proprio {

using Vec3 = Eigen::Vector3d;
using Quat = Eigen::Quaterniond;
using Mat3 = Eigen::Matrix3d;
using Vec6 = Eigen::Matrix<double, 6, 1>;  // twist: [rho (translation); phi (rotation)]

// A rigid transform, laid out like XrPosef. T_a_b.p is the origin of b in a.
struct Pose {
  Quat q = Quat::Identity();
  Vec3 p = Vec3::Zero();

  static Pose identity() { return {}; }
  Pose inverse() const {
    const Quat qi = q.conjugate();
    return {qi, -(qi * p)};
  }
  Vec3 operator*(const Vec3& p_in_b) const { return q * p_in_b + p; }
  Pose operator*(const Pose& T_b_c) const { return {(q * T_b_c.q).normalized(), q * T_b_c.p + p}; }
  Eigen::Matrix4d matrix() const;
};

Mat3 skew(const Vec3& v);

// Rotation vector (axis * angle, rad) -> unit quaternion. Exact near zero.
Quat so3_exp(const Vec3& rotation_vector);
// Unit quaternion -> rotation vector with angle in [0, pi] (shortest path).
Vec3 so3_log(const Quat& q);

// Left Jacobian of SO(3), the "V" matrix of SE(3) exp.
Mat3 so3_left_jacobian(const Vec3& phi);
Mat3 so3_left_jacobian_inverse(const Vec3& phi);

Pose se3_exp(const Vec6& twist);
Vec6 se3_log(const Pose& T);

// Error-state composition used by the EKFs: the perturbation is expressed in
// the local (body) frame, q ⊞ δθ = q ⊗ exp(δθ).
Quat boxplus(const Quat& q, const Vec3& delta_theta);
// Inverse of boxplus: q1 ⊟ q0 = log(q0⁻¹ ⊗ q1), so q0 ⊞ (q1 ⊟ q0) == q1.
Vec3 boxminus(const Quat& q1, const Quat& q0);

// Shortest-arc spherical interpolation, t in [0, 1] (extrapolates outside).
Quat slerp(const Quat& q0, const Quat& q1, double t);
// Rotation slerped, translation lerped: the motion a pose history assumes.
Pose interpolate(const Pose& T0, const Pose& T1, double t);

// Angle of the rotation between two orientations, rad in [0, pi].
double angle_between(const Quat& a, const Quat& b);

// Rotation whose columns are the given orthonormal axes (expressed in the parent frame).
Quat quat_from_axes(const Vec3& x_axis, const Vec3& y_axis, const Vec3& z_axis);

}  // namespace proprio
