#include "proprio/ftm/imu_bias.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <Eigen/Eigenvalues>

namespace proprio::ftm {
namespace {

constexpr double kRadPerDeg = M_PI / 180.0;

bool positive_finite(double x) { return std::isfinite(x) && x > 0.0; }

// Samples the estimators use: no status bit but the compass's overflow (the
// compass is not used here), finite accelerometer and gyro.
bool usable_sample(const FtmImuSample& s) {
  return (s.status & ~sample_status::mag_overflow) == 0 && s.accel_mps2.allFinite() && s.gyro_radps.allFinite();
}

Vec3 axis_std(const Vec3& sum, const Vec3& sum2, double n) {
  const Vec3 mean = sum / n;
  return (sum2 / n - mean.cwiseProduct(mean)).cwiseMax(0.0).cwiseSqrt();
}

}  // namespace

// ---------------------------------------------------------------- still gyro

Status StillBiasOptions::validate() const {
  auto fail = [this](const char* field, const char* why) {
    return make_error(Errc::invalid_argument,
                      std::string("StillBiasOptions.") + field + " " + why + " (" + describe() + ")");
  };
  if (!positive_finite(window_s) || window_s > 60.0) return fail("window_s", "must be in (0, 60] s");
  if (!positive_finite(max_gyro_std_radps)) return fail("max_gyro_std_radps", "must be > 0");
  if (!positive_finite(max_accel_std_mps2)) return fail("max_accel_std_mps2", "must be > 0");
  if (!positive_finite(max_gyro_bias_radps)) return fail("max_gyro_bias_radps", "must be > 0");
  if (!positive_finite(max_tilt_drift_rad) || max_tilt_drift_rad > M_PI) {
    return fail("max_tilt_drift_rad", "must be in (0, pi]");
  }
  if (!positive_finite(gravity_mps2)) return fail("gravity_mps2", "must be > 0");
  if (!positive_finite(max_gravity_error_mps2)) return fail("max_gravity_error_mps2", "must be > 0");
  return {};
}

std::string StillBiasOptions::describe() const {
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "still window %.3g s: gyro std <= %.3g deg/s, accel std <= %.3g m/s^2, |mean gyro| <= %.3g deg/s, "
                "tilt drift <= %.3g deg, | |a| - %.5g | <= %.3g m/s^2",
                window_s, max_gyro_std_radps / kRadPerDeg, max_accel_std_mps2, max_gyro_bias_radps / kRadPerDeg,
                max_tilt_drift_rad / kRadPerDeg, gravity_mps2, max_gravity_error_mps2);
  return buf;
}

void StillBiasAccumulator::reset() noexcept { *this = StillBiasAccumulator(options_); }

bool StillBiasAccumulator::add(const FtmImuSample& s) noexcept {
  if (complete_) return false;
  if (!usable_sample(s)) return true;
  if (n_ > 0 && s.time_ns <= last_ns_) return true;
  if (n_ == 0) first_ns_ = s.time_ns;
  const double u = ns_to_seconds(s.time_ns - first_ns_);
  if (u >= options_.window_s) {
    complete_ = true;
    return false;
  }
  last_ns_ = s.time_ns;
  ++n_;
  sum_gyro_ += s.gyro_radps;
  sum2_gyro_ += s.gyro_radps.cwiseProduct(s.gyro_radps);
  sum_accel_ += s.accel_mps2;
  sum2_accel_ += s.accel_mps2.cwiseProduct(s.accel_mps2);
  const std::size_t half = u < 0.5 * options_.window_s ? 0 : 1;
  ++n_half_[half];
  sum_accel_half_[half] += s.accel_mps2;
  return true;
}

std::optional<Vec3> StillBiasAccumulator::accepted_gyro_bias() const noexcept {
  if (!complete_ || n_half_[0] < 2 || n_half_[1] < 2) return std::nullopt;
  const double n = static_cast<double>(n_);
  const Vec3 bias = sum_gyro_ / n;
  const Vec3 mean_accel = sum_accel_ / n;
  const Vec3 a0 = sum_accel_half_[0] / static_cast<double>(n_half_[0]);
  const Vec3 a1 = sum_accel_half_[1] / static_cast<double>(n_half_[1]);
  const bool still = axis_std(sum_gyro_, sum2_gyro_, n).maxCoeff() <= options_.max_gyro_std_radps &&
                     axis_std(sum_accel_, sum2_accel_, n).maxCoeff() <= options_.max_accel_std_mps2 &&
                     bias.norm() <= options_.max_gyro_bias_radps &&
                     std::atan2(a0.cross(a1).norm(), a0.dot(a1)) <= options_.max_tilt_drift_rad &&
                     std::abs(mean_accel.norm() - options_.gravity_mps2) <= options_.max_gravity_error_mps2;
  if (!still) return std::nullopt;
  return bias;
}

Result<StillBiasEstimate> StillBiasAccumulator::estimate() const {
  if (!complete_ || n_half_[0] < 2 || n_half_[1] < 2) {
    return make_error(Errc::unavailable, "turn-on bias: the still window (" + std::to_string(options_.window_s) +
                                             " s) is not covered yet");
  }
  const double n = static_cast<double>(n_);
  StillBiasEstimate e;
  e.samples = n_;
  e.duration_s = ns_to_seconds(last_ns_ - first_ns_);
  e.gyro_bias_radps = sum_gyro_ / n;
  e.mean_accel_mps2 = sum_accel_ / n;
  e.gyro_std_radps = axis_std(sum_gyro_, sum2_gyro_, n).maxCoeff();
  e.accel_std_mps2 = axis_std(sum_accel_, sum2_accel_, n).maxCoeff();
  const Vec3 a0 = sum_accel_half_[0] / static_cast<double>(n_half_[0]);
  const Vec3 a1 = sum_accel_half_[1] / static_cast<double>(n_half_[1]);
  e.tilt_drift_rad = std::atan2(a0.cross(a1).norm(), a0.dot(a1));
  char buf[200];
  auto refuse = [&buf](const char* what, double value, double limit) {
    std::snprintf(buf, sizeof buf, "turn-on bias refused, the IMU was not still: %s %.3g > %.3g", what, value, limit);
    return make_error(Errc::out_of_range, buf);
  };
  if (e.gyro_std_radps > options_.max_gyro_std_radps) {
    return refuse("gyro std (deg/s)", e.gyro_std_radps / kRadPerDeg, options_.max_gyro_std_radps / kRadPerDeg);
  }
  if (e.accel_std_mps2 > options_.max_accel_std_mps2) {
    return refuse("accel std (m/s^2)", e.accel_std_mps2, options_.max_accel_std_mps2);
  }
  if (e.gyro_bias_radps.norm() > options_.max_gyro_bias_radps) {
    return refuse("mean rate (deg/s)", e.gyro_bias_radps.norm() / kRadPerDeg, options_.max_gyro_bias_radps / kRadPerDeg);
  }
  if (e.tilt_drift_rad > options_.max_tilt_drift_rad) {
    return refuse("tilt drift (deg)", e.tilt_drift_rad / kRadPerDeg, options_.max_tilt_drift_rad / kRadPerDeg);
  }
  const double g_err = std::abs(e.mean_accel_mps2.norm() - options_.gravity_mps2);
  if (g_err > options_.max_gravity_error_mps2) {
    return refuse("| |a| - g | (m/s^2)", g_err, options_.max_gravity_error_mps2);
  }
  return e;
}

Result<StillBiasEstimate> estimate_still_bias(std::span<const FtmImuSample> samples, const StillBiasOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  StillBiasAccumulator acc(options);
  for (const auto& s : samples) {
    if (!acc.add(s) && acc.complete()) break;
  }
  return acc.estimate();
}

// ---------------------------------------------------------------- accel fit

Status AccelBiasFitOptions::validate() const {
  auto fail = [this](const char* field, const char* why) {
    return make_error(Errc::invalid_argument,
                      std::string("AccelBiasFitOptions.") + field + " " + why + " (" + describe() + ")");
  };
  if (!positive_finite(gravity_mps2)) return fail("gravity_mps2", "must be > 0");
  if (!positive_finite(max_rate_radps)) return fail("max_rate_radps", "must be > 0");
  if (!positive_finite(max_gravity_error_mps2)) return fail("max_gravity_error_mps2", "must be > 0");
  if (!positive_finite(min_direction_spread) || min_direction_spread > 1.0 / 3.0) {
    return fail("min_direction_spread", "must be in (0, 1/3]");
  }
  if (min_samples < 4) return fail("min_samples", "must be >= 4");
  if (!positive_finite(max_bias_mps2)) return fail("max_bias_mps2", "must be > 0");
  if (!positive_finite(max_residual_rms_mps2)) return fail("max_residual_rms_mps2", "must be > 0");
  return {};
}

std::string AccelBiasFitOptions::describe() const {
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "sphere fit |a - b| = %.5g m/s^2 on samples with rate <= %.3g rad/s and | |a| - g | <= %.3g m/s^2; "
                "needs >= %zu samples, direction spread >= %.3g; refuses |b| > %.3g m/s^2 or residual RMS > %.3g m/s^2",
                gravity_mps2, max_rate_radps, max_gravity_error_mps2, min_samples, min_direction_spread,
                max_bias_mps2, max_residual_rms_mps2);
  return buf;
}

Result<AccelBiasEstimate> fit_accel_bias(std::span<const FtmImuSample> samples, const AccelBiasFitOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  const double g = options.gravity_mps2;
  std::vector<Vec3> a;
  a.reserve(samples.size());
  for (const auto& s : samples) {
    if (!usable_sample(s)) continue;
    if (s.gyro_radps.norm() > options.max_rate_radps) continue;
    if (std::abs(s.accel_mps2.norm() - g) > options.max_gravity_error_mps2) continue;
    a.push_back(s.accel_mps2);
  }
  AccelBiasEstimate e;
  e.samples = a.size();
  if (a.size() < options.min_samples) {
    return make_error(Errc::unavailable, "accelerometer offset: only " + std::to_string(a.size()) +
                                             " quasi-static samples (need " + std::to_string(options.min_samples) +
                                             "); turn the IMU more slowly through more orientations");
  }
  Mat3 uu = Mat3::Zero();
  for (const Vec3& v : a) uu += v.normalized() * v.normalized().transpose();
  uu /= static_cast<double>(a.size());
  e.direction_spread = Eigen::SelfAdjointEigenSolver<Mat3>(uu).eigenvalues().minCoeff();
  if (e.direction_spread < options.min_direction_spread) {
    char buf[200];
    std::snprintf(buf, sizeof buf,
                  "accelerometer offset: the orientations span too little (spread %.3g < %.3g); tilt the IMU "
                  "through more orientations",
                  e.direction_spread, options.min_direction_spread);
    return make_error(Errc::unavailable, buf);
  }
  // Gauss-Newton on r_i = ‖a_i - b‖ - g, Huber weights at 3x the
  // accelerometer's per-sample noise (~0.03 m/s²).
  constexpr double kHuber = 0.1;
  Vec3 b = Vec3::Zero();
  for (int it = 0; it < 20; ++it) {
    Mat3 H = Mat3::Zero();
    Vec3 rhs = Vec3::Zero();
    for (const Vec3& v : a) {
      const Vec3 d = v - b;
      const double dn = d.norm();
      if (!(dn > 0.0)) continue;
      const double r = dn - g;
      const double w = std::abs(r) <= kHuber ? 1.0 : kHuber / std::abs(r);
      const Vec3 J = -d / dn;  // ∂r/∂b
      H += w * J * J.transpose();
      rhs -= w * J * r;
    }
    const Vec3 step = H.ldlt().solve(rhs);
    if (!step.allFinite()) break;
    b += step;
    if (step.norm() < 1e-7) break;
  }
  double ss = 0.0;
  for (const Vec3& v : a) ss += std::pow((v - b).norm() - g, 2);
  e.bias_mps2 = b;
  e.residual_rms_mps2 = std::sqrt(ss / static_cast<double>(a.size()));
  char buf[200];
  if (!b.allFinite() || b.norm() > options.max_bias_mps2) {
    std::snprintf(buf, sizeof buf, "accelerometer offset refused: |b| = %.3g m/s^2 > %.3g", b.norm(),
                  options.max_bias_mps2);
    return make_error(Errc::out_of_range, buf);
  }
  if (e.residual_rms_mps2 > options.max_residual_rms_mps2) {
    std::snprintf(buf, sizeof buf,
                  "accelerometer offset refused: residual RMS %.3g m/s^2 > %.3g (the IMU was not at rest)",
                  e.residual_rms_mps2, options.max_residual_rms_mps2);
    return make_error(Errc::out_of_range, buf);
  }
  return e;
}

std::vector<FtmImuSample> imu_samples_of(std::span<const FtmEvent> events, std::size_t imu) {
  std::vector<FtmImuSample> out;
  for (const auto& e : events) {
    if (e.kind == FtmEvent::Kind::imu && e.index == imu) out.push_back(e.imu);
  }
  return out;
}

}  // namespace proprio::ftm
