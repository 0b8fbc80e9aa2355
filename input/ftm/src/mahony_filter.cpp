#include "proprio/ftm/mahony_filter.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>

namespace proprio::ftm {
namespace {

constexpr double kDeg = M_PI / 180.0;
// A component at 99.9 % of full scale is taken as clipped: the sensor's
// register pins there, and a reading that large says nothing about direction.
constexpr double kClipFraction = 0.999;

// A zero rate is a reading; a zero specific force or field is a dead sensor.
bool usable(const Vec3& v, double range, bool zero_ok) noexcept {
  return v.allFinite() && v.cwiseAbs().maxCoeff() < kClipFraction * range && (zero_ok || v.squaredNorm() > 0.0);
}

bool finite_positive(double x) { return std::isfinite(x) && x > 0.0; }

// Slowest decay rate (rad/s) of the PI loop s² + k s + k_I: how fast the bias
// estimate settles along an axis corrected with gain k.
double slowest_rate(double k, double k_i) {
  const std::complex<double> disc = std::sqrt(std::complex<double>(k * k - 4.0 * k_i, 0.0));
  return std::min(std::abs((-k + disc).real()), std::abs((-k - disc).real())) / 2.0;
}

}  // namespace

Vec3 euler_zyx_rad(const Quat& q) noexcept {
  const Mat3 R = q.normalized().toRotationMatrix();
  return {std::atan2(R(1, 0), R(0, 0)), std::asin(std::clamp(-R(2, 0), -1.0, 1.0)), std::atan2(R(2, 1), R(2, 2))};
}

Status MahonyOptions::validate() const {
  auto fail = [this](const std::string& what) {
    return make_error(Errc::invalid_argument, "Mahony filter: " + what + " (options: " + describe() + ")");
  };
  if (!gravity_ref_in_world_mps2.allFinite() || !(gravity_ref_in_world_mps2.norm() > 0.0)) {
    return fail("gravity_ref_in_world_mps2 must be finite and non-zero");
  }
  if (!mag_ref_in_world_uT.allFinite() || !(mag_ref_in_world_uT.norm() > 0.0)) {
    return fail("mag_ref_in_world_uT must be finite and non-zero (set it from the compass calibration)");
  }
  if (gravity_ref_in_world_mps2.normalized().cross(mag_ref_in_world_uT.normalized()).norm() < 0.05) {
    return fail("mag_ref_in_world_uT is within 3° of vertical: it carries no heading");
  }
  if (!finite_positive(k_accel_radps) || !(k_mag_radps >= 0.0) || !std::isfinite(k_mag_radps) ||
      !(k_bias_radps2 >= 0.0) || !std::isfinite(k_bias_radps2)) {
    return fail("need k_accel_radps > 0, k_mag_radps >= 0 and k_bias_radps2 >= 0, all finite");
  }
  if (!(max_bias_radps >= 0.0) || !std::isfinite(max_bias_radps)) return fail("max_bias_radps must be >= 0");
  if (!finite_positive(bias_learning_max_error_rad) || bias_learning_max_error_rad > M_PI) {
    return fail("bias_learning_max_error_rad must be in (0, pi]");
  }
  if (initial_bias_radps && !initial_bias_radps->allFinite()) return fail("initial_bias_radps must be finite");
  if (!finite_positive(accel_gate_mps2) || !finite_positive(gyro_range_radps) || !finite_positive(accel_range_mps2) ||
      !finite_positive(mag_range_uT)) {
    return fail("accel_gate_mps2 and the sensor ranges must be > 0");
  }
  if (!finite_positive(max_dt_s) || !(gyro_hold_s >= 0.0) || !std::isfinite(gyro_hold_s)) {
    return fail("need max_dt_s > 0 and gyro_hold_s >= 0");
  }
  if (!finite_positive(init_weights.accel) || !finite_positive(init_weights.mag)) {
    return fail("init_weights must be > 0");
  }
  if (Status s = disturbance.validate(); !s) return s.error().with_context("Mahony filter");
  return {};
}

std::string MahonyOptions::describe() const {
  char buf[768];
  std::snprintf(
      buf, sizeof buf,
      "k_accel=%.3g rad/s (tilt crossover %.3g Hz), k_mag=%.3g rad/s (heading crossover %.3g Hz), "
      "k_bias=%.3g rad/s^2 (bias settles at %.3g rad/s on tilt axes, %.3g rad/s on heading; learnt while the "
      "error < %.3g deg), |bias|<=%.3g deg/s, "
      "compass %s, %s; accel gate |norm-g|>%.3g m/s^2; ranges %.0f deg/s, %.3g g, %.0f uT; max dt %.3g s, "
      "gyro hold %.3g s; disturbance: %s",
      k_accel_radps, k_accel_radps / (2.0 * M_PI), k_mag_radps, k_mag_radps / (2.0 * M_PI), k_bias_radps2,
      slowest_rate(k_accel_radps, k_bias_radps2), slowest_rate(k_mag_radps, k_bias_radps2), bias_learning_max_error_rad / kDeg,
      max_bias_radps / kDeg,
      heading_only_mag ? "heading only" : "full vector", gate_mag ? "gated by the detector" : "not gated (plain)",
      accel_gate_mps2, gyro_range_radps / kDeg, accel_range_mps2 / 9.80665, mag_range_uT, max_dt_s, gyro_hold_s,
      disturbance.describe().c_str());
  return buf;
}

MahonyFilter::MahonyFilter(const MahonyOptions& options)
    : options_(options),
      detector_(options.disturbance, options.mag_ref_in_world_uT, options.gravity_ref_in_world_mps2),
      up_in_world_(options.gravity_ref_in_world_mps2.normalized()),
      mag_ref_dir_(options.mag_ref_in_world_uT.normalized()),
      gravity_norm_(options.gravity_ref_in_world_mps2.norm()) {
  const Vec3 h = mag_ref_dir_ - mag_ref_dir_.dot(up_in_world_) * up_in_world_;
  mag_ref_horizontal_dir_ = h.normalized();
  reset();
}

Result<MahonyFilter> MahonyFilter::create(const MahonyOptions& options) {
  if (Status s = options.validate(); !s) return s.error();
  return MahonyFilter(options);
}

void MahonyFilter::reset() noexcept {
  q_world_body_ = Quat::Identity();
  bias_radps_ = options_.initial_bias_radps.value_or(Vec3::Zero());
  last_gyro_radps_ = Vec3::Zero();
  initialised_ = has_time_ = has_good_gyro_ = has_mag_time_ = false;
  last_ns_ = last_good_gyro_ns_ = last_mag_ns_ = 0;
  detector_.reset();
}

void MahonyFilter::set_gyro_bias(const Vec3& bias_radps) noexcept {
  if (!bias_radps.allFinite()) return;
  bias_radps_ = bias_radps;
  const double b = bias_radps_.norm();
  if (b > options_.max_bias_radps) bias_radps_ *= options_.max_bias_radps / b;
}

bool MahonyFilter::try_initialise(const Vec3& accel, const Vec3& mag) noexcept {
  const Result<Quat> q = markley_attitude(accel, mag, options_.gravity_ref_in_world_mps2,
                                          options_.mag_ref_in_world_uT, options_.init_weights);
  if (!q) return false;
  q_world_body_ = *q;
  initialised_ = true;
  return true;
}

std::uint32_t MahonyFilter::update(TimeNs t_ns, const Vec3& gyro_radps, const Vec3& accel_mps2,
                                   const std::optional<Vec3>& mag_uT) noexcept {
  std::uint32_t flags = 0;
  if (has_time_ && t_ns <= last_ns_) {
    return kTimeNotAdvancing | (initialised_ ? 0u : static_cast<std::uint32_t>(kNotInitialised));
  }
  const bool gyro_ok = usable(gyro_radps, options_.gyro_range_radps, true);
  const bool accel_ok = usable(accel_mps2, options_.accel_range_mps2, false);
  const bool mag_ok = mag_uT && usable(*mag_uT, options_.mag_range_uT, false);
  if (!gyro_ok) flags |= kGyroInvalid;
  if (!accel_ok) flags |= kAccelInvalid;
  if (!mag_uT) {
    flags |= kMagAbsent;
  } else if (!mag_ok) {
    flags |= kMagInvalid;
  }

  const double dt = has_time_ ? ns_to_seconds(t_ns - last_ns_) : 0.0;
  const bool gap = has_time_ && dt > options_.max_dt_s;
  if (gap) flags |= kTimeGap;

  // The rate over (last, t]: the mean of the two ends (trapezoid), or a held
  // rate across a short gyro failure, or no rotation at all after that.
  Vec3 rate = bias_radps_;
  if (gyro_ok) {
    rate = has_good_gyro_ && last_good_gyro_ns_ == last_ns_ ? 0.5 * (gyro_radps + last_gyro_radps_) : gyro_radps;
    last_gyro_radps_ = gyro_radps;
    last_good_gyro_ns_ = t_ns;
    has_good_gyro_ = true;
  } else if (has_good_gyro_ && ns_to_seconds(t_ns - last_good_gyro_ns_) <= options_.gyro_hold_s) {
    rate = last_gyro_radps_;
  }
  last_ns_ = t_ns;
  has_time_ = true;

  if (!initialised_ || gap) {
    // Prime the detector with the accelerometer's "up": with no attitude yet
    // it is the best tilt there is.
    bool disturbed = false;
    if (mag_ok && accel_ok) {
      disturbed = detector_.update(t_ns, *mag_uT, accel_mps2.normalized()) && !detector_.rejection_expired();
      if (disturbed) flags |= kMagDisturbed;
    }
    // A gap is re-initialised only from a compass the detector trusts (when
    // gating): otherwise keep the attitude we had, which is the better guess.
    const bool may_init = mag_ok && accel_ok && (!initialised_ || !(options_.gate_mag && disturbed));
    if (may_init && try_initialise(accel_mps2, *mag_uT)) {
      flags |= kInitialised;
      last_mag_ns_ = t_ns;
      has_mag_time_ = true;
    }
    if (!initialised_) flags |= kNotInitialised;
    return flags;
  }

  // Predict with the gyro, then correct with the vectors measured at t, so
  // that the correction compares like with like (no one-sample lag).
  q_world_body_ = q_world_body_ * so3_exp((rate - bias_radps_) * dt);
  const Quat q_body_world = q_world_body_.conjugate();
  const Vec3 up_in_body = q_body_world * up_in_world_;

  Vec3 e_accel = Vec3::Zero(), e_mag = Vec3::Zero();
  // cos of the angle between measured and predicted direction, per vector.
  double cos_accel = 1.0, cos_mag = 1.0;
  if (accel_ok) {
    const double a = accel_mps2.norm();
    if (std::abs(a - gravity_norm_) > options_.accel_gate_mps2) {
      flags |= kAccelRejected;
    } else {
      const Vec3 v = accel_mps2 / a;
      e_accel = v.cross(up_in_body);
      cos_accel = v.dot(up_in_body);
    }
  }
  double dt_mag = 0.0;
  if (mag_ok) {
    const Vec3& m = *mag_uT;
    // The compass may run slower than the IMU: its correction spans the time
    // since its last valid sample, so its gain does not depend on its rate.
    const double dt_since_mag = has_mag_time_ ? std::min(ns_to_seconds(t_ns - last_mag_ns_), options_.max_dt_s) : dt;
    last_mag_ns_ = t_ns;
    has_mag_time_ = true;
    const bool disturbed = detector_.update(t_ns, m, up_in_body);
    const bool expired = detector_.rejection_expired();
    if (disturbed) flags |= kMagDisturbed;
    if (expired) flags |= kMagRejectionExpired;
    if (options_.gate_mag && disturbed && !expired) {
      flags |= kMagGated;
    } else {
      dt_mag = dt_since_mag;
      if (options_.heading_only_mag) {
        const Vec3 m_h = m - m.dot(up_in_body) * up_in_body;
        const double n = m_h.norm();
        // A field within ~6° of vertical in the body has no usable horizontal part.
        if (n > 0.1 * m.norm()) {
          const Vec3 predicted = q_body_world * mag_ref_horizontal_dir_;
          e_mag = (m_h / n).cross(predicted);
          cos_mag = (m_h / n).dot(predicted);
        }
      } else {
        const Vec3 predicted = q_body_world * mag_ref_dir_;
        e_mag = m.normalized().cross(predicted);
        cos_mag = m.normalized().dot(predicted);
      }
    }
  }

  const Vec3 correction = options_.k_accel_radps * dt * e_accel + options_.k_mag_radps * dt_mag * e_mag;
  q_world_body_ = (q_world_body_ * so3_exp(correction)).normalized();
  // Anti-windup: an error this large comes from a wrong attitude (start-up,
  // a fast reach the accelerometer gate let through), not from a gyro bias;
  // integrating it would leave a bias error that takes k_accel/k_bias to undo.
  // (By cosine: |e| = sin of the error, small again near 180°.)
  const double cos_limit = std::cos(options_.bias_learning_max_error_rad);
  const double w_accel = cos_accel >= cos_limit ? dt : 0.0;
  const double w_mag = cos_mag >= cos_limit ? dt_mag : 0.0;
  const Vec3 e_bias = w_accel * e_accel + w_mag * e_mag;
  bias_radps_ -= options_.k_bias_radps2 * e_bias;
  const double b = bias_radps_.norm();
  if (b > options_.max_bias_radps) bias_radps_ *= options_.max_bias_radps / b;
  return flags;
}

}  // namespace proprio::ftm
