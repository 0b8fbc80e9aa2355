#include "proprio/rig_device/joint_kinematics.hpp"

#include <algorithm>
#include <cmath>

namespace proprio::rig_device {
namespace {

Quat about(const Vec3& axis, double angle_rad) { return Quat(Eigen::AngleAxisd(angle_rad, axis)); }

}  // namespace

double wrap_angle_rad(double angle_rad) {
  double a = std::remainder(angle_rad, 2.0 * M_PI);
  if (a <= -M_PI) a += 2.0 * M_PI;
  return a;
}

Quat joint_rotation(const JointAngles& a) {
  return (about(Vec3::UnitZ(), a.twist_in_rad) * about(Vec3::UnitX(), a.bend_x_rad) *
          about(Vec3::UnitY(), a.bend_y_rad) * about(Vec3::UnitZ(), a.twist_out_rad))
      .normalized();
}

JointAngles joint_angles_for(const Quat& q_in_out, double twist_in_rad) {
  // R = Rx(a) Ry(b) Rz(c) once the inlet twist is taken off:
  //   R02 = sin b, R12 = -sin a cos b, R22 = cos a cos b, R01 = -cos b sin c, R00 = cos b cos c.
  const Mat3 R = (about(Vec3::UnitZ(), -twist_in_rad) * q_in_out.normalized()).toRotationMatrix();
  JointAngles out;
  out.twist_in_rad = wrap_angle_rad(twist_in_rad);
  out.bend_y_rad = std::asin(std::clamp(R(0, 2), -1.0, 1.0));
  if (std::abs(R(0, 2)) < 1.0 - 1e-12) {
    out.bend_x_rad = std::atan2(-R(1, 2), R(2, 2));
    out.twist_out_rad = std::atan2(-R(0, 1), R(0, 0));
  } else {
    // Gimbal: only bend_x + twist_out (or their difference) is determined.
    out.bend_x_rad = std::atan2(R(2, 1), R(1, 1));
    out.twist_out_rad = 0.0;
  }
  return out;
}

Quat twist_bend_twist_rotation(const TwistBendTwistAngles& a) {
  return (about(Vec3::UnitZ(), a.twist_a_rad) * about(Vec3::UnitX(), a.bend_rad) *
          about(Vec3::UnitZ(), a.twist_b_rad))
      .normalized();
}

TwistBendTwistAngles twist_bend_twist_angles_for(const Quat& q_in_out) {
  // R = Rz(a) Rx(b) Rz(c): R22 = cos b, R02 = sin a sin b, R12 = -cos a sin b,
  // R20 = sin b sin c, R21 = sin b cos c.
  const Mat3 R = q_in_out.normalized().toRotationMatrix();
  TwistBendTwistAngles out;
  out.bend_rad = std::acos(std::clamp(R(2, 2), -1.0, 1.0));
  if (std::sin(out.bend_rad) > 1e-9) {
    out.twist_a_rad = std::atan2(R(0, 2), -R(1, 2));
    out.twist_b_rad = std::atan2(R(2, 0), R(2, 1));
  } else {
    // Straight: one combined twist about z. (Folded back, bend = pi, is past
    // any physical hinge and not handled.)
    out.twist_a_rad = std::atan2(R(1, 0), R(0, 0));
    out.twist_b_rad = 0.0;
  }
  return out;
}

}  // namespace proprio::rig_device
