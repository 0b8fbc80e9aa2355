#include "proprio/ftm/markley.hpp"

#include <cmath>
#include <string>

#include <Eigen/SVD>

namespace proprio::ftm {
namespace {

// sin of ~0.1°: below it two observations no longer fix the rotation about
// them to better than the sensors' own resolution.
constexpr double kMinSinBetween = 2e-3;

Status check_vector(const Vec3& v, const char* name) {
  if (!v.allFinite()) {
    return make_error(Errc::invalid_argument, std::string("markley_attitude: ") + name + " is not finite");
  }
  if (!(v.norm() > 0.0)) {
    return make_error(Errc::invalid_argument, std::string("markley_attitude: ") + name + " has zero length");
  }
  return {};
}

}  // namespace

Result<Quat> markley_attitude(const Vec3& accel_body, const Vec3& mag_body, const Vec3& gravity_ref,
                              const Vec3& mag_ref, const WahbaWeights& weights) {
  if (Status s = check_vector(accel_body, "accel_body"); !s) return s.error();
  if (Status s = check_vector(mag_body, "mag_body"); !s) return s.error();
  if (Status s = check_vector(gravity_ref, "gravity_ref"); !s) return s.error();
  if (Status s = check_vector(mag_ref, "mag_ref"); !s) return s.error();
  if (!(weights.accel > 0.0) || !(weights.mag > 0.0) || !std::isfinite(weights.accel) ||
      !std::isfinite(weights.mag)) {
    return make_error(Errc::invalid_argument, "markley_attitude: weights must be finite and > 0 (got accel=" +
                                                  std::to_string(weights.accel) +
                                                  ", mag=" + std::to_string(weights.mag) + ")");
  }
  const Vec3 b1 = accel_body.normalized(), b2 = mag_body.normalized();
  const Vec3 r1 = gravity_ref.normalized(), r2 = mag_ref.normalized();
  if (b1.cross(b2).norm() < kMinSinBetween) {
    return make_error(Errc::invalid_argument,
                      "markley_attitude: accelerometer and magnetometer readings are (anti)parallel, "
                      "so heading about them is undefined");
  }
  if (r1.cross(r2).norm() < kMinSinBetween) {
    return make_error(Errc::invalid_argument,
                      "markley_attitude: the reference gravity and magnetic field are (anti)parallel "
                      "(a field at ±90° dip has no heading information)");
  }
  // Attitude profile matrix; A = R_body_world maps reference to body.
  const Mat3 B = weights.accel * b1 * r1.transpose() + weights.mag * b2 * r2.transpose();
  const Eigen::JacobiSVD<Mat3> svd(B, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Mat3& U = svd.matrixU();
  const Mat3& V = svd.matrixV();
  const double d = U.determinant() * V.determinant();
  const Mat3 A = U * Eigen::Vector3d(1.0, 1.0, d).asDiagonal() * V.transpose();
  Quat q_world_body(A.transpose());
  q_world_body.normalize();
  if (!q_world_body.coeffs().allFinite()) {
    return make_error(Errc::invalid_argument, "markley_attitude: the SVD did not give a finite rotation");
  }
  return q_world_body;
}

}  // namespace proprio::ftm
