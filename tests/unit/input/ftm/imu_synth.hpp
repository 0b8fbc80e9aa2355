#pragma once
// Synthetic MPU-9250 + AK8963 readings along a known trajectory, for the FTM
// attitude tests and benchmark. World is Z-up here (the thesis's bench and
// ZYX Euler angles); the filter takes its references as options, so any
// world frame works the same way.
//
// Noise model (per sample, white, σ = density · √rate, as Kalibr and the
// project's IMU simulator use): gyro 0.01 °/s/√Hz and accelerometer
// 300 µg/√Hz (MPU-9250 product specification), compass 0.5 µT white plus the
// AK8963's 0.15 µT/LSB quantisation and ±4800 µT clipping.
#include <algorithm>
#include <cmath>
#include <functional>
#include <optional>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/time.hpp"

namespace proprio::ftm::imu_synth {

inline constexpr double kG = 9.80665;
inline constexpr double kDeg = M_PI / 180.0;

inline Vec3 gravity_ref_z_up() { return {0.0, 0.0, kG}; }
// 48 µT, 60° dip, north along +X.
inline Vec3 earth_field_uT() { return {48.0 * std::cos(60.0 * kDeg), 0.0, -48.0 * std::sin(60.0 * kDeg)}; }

// The truth at one instant.
struct Motion {
  Quat q_world_body = Quat::Identity();
  Vec3 omega_body_radps = Vec3::Zero();
  Vec3 accel_world_mps2 = Vec3::Zero();  // linear acceleration of the IMU, gravity excluded
  Vec3 p_world_m = Vec3::Zero();         // where the IMU is (for dipole fields)
};

struct Sample {
  TimeNs t_ns = 0;
  Vec3 gyro_radps, accel_mps2;
  std::optional<Vec3> mag_uT;
  Motion truth;
  Vec3 disturbance_world_uT = Vec3::Zero();
};

struct NoiseModel {
  double imu_rate_hz = 200.0;
  int mag_every = 2;  // compass at 100 Hz
  double gyro_density_radps_rthz = 0.01 * kDeg;
  double accel_density_mps2_rthz = 300e-6 * kG;
  double mag_noise_uT = 0.5;
  double mag_lsb_uT = 0.15;
  double mag_range_uT = 4800.0;
  Vec3 gyro_bias_radps = Vec3::Zero();
};

// Samples k = 0 .. n-1 at t = k / rate. disturbance(t, p) adds a field (µT,
// world) at the IMU's position.
inline std::vector<Sample> synthesise(double duration_s, const std::function<Motion(double)>& motion,
                                      const NoiseModel& noise, std::uint64_t seed,
                                      const std::function<Vec3(double, const Vec3&)>& disturbance = {}) {
  Rng rng(seed);
  const int n = static_cast<int>(duration_s * noise.imu_rate_hz);
  const double sg = noise.gyro_density_radps_rthz * std::sqrt(noise.imu_rate_hz);
  const double sa = noise.accel_density_mps2_rthz * std::sqrt(noise.imu_rate_hz);
  std::vector<Sample> out;
  out.reserve(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) {
    const double t = k / noise.imu_rate_hz;
    Sample s;
    s.t_ns = seconds_to_ns(t);
    s.truth = motion(t);
    const Quat q_body_world = s.truth.q_world_body.conjugate();
    s.gyro_radps = s.truth.omega_body_radps + noise.gyro_bias_radps + sg * Vec3(rng.normal(), rng.normal(), rng.normal());
    s.accel_mps2 = q_body_world * (s.truth.accel_world_mps2 + gravity_ref_z_up()) +
                   sa * Vec3(rng.normal(), rng.normal(), rng.normal());
    if (disturbance) s.disturbance_world_uT = disturbance(t, s.truth.p_world_m);
    if (k % noise.mag_every == 0) {
      Vec3 m = q_body_world * (earth_field_uT() + s.disturbance_world_uT) +
               noise.mag_noise_uT * Vec3(rng.normal(), rng.normal(), rng.normal());
      for (int i = 0; i < 3; ++i) {
        m[i] = std::clamp(noise.mag_lsb_uT * std::round(m[i] / noise.mag_lsb_uT), -noise.mag_range_uT,
                          noise.mag_range_uT);
      }
      s.mag_uT = m;
    }
    out.push_back(s);
  }
  return out;
}

// Rotation about one fixed axis through `pivot`, body frame starting at the
// identity, the IMU at lever_in_body from the pivot: angle θ(t) with rate and
// acceleration given; returns the exact rate and linear acceleration.
inline Motion about_axis(const Vec3& axis, double theta, double theta_dot, double theta_ddot,
                         const Vec3& lever_in_body, const Vec3& pivot = Vec3::Zero()) {
  Motion m;
  m.q_world_body = Quat(Eigen::AngleAxisd(theta, axis.normalized()));
  const Vec3 w = theta_dot * axis.normalized();
  const Vec3 alpha = theta_ddot * axis.normalized();
  m.omega_body_radps = w;  // body axis = world axis for a rotation from the identity about a fixed axis
  const Vec3 r = m.q_world_body * lever_in_body;
  m.p_world_m = pivot + r;
  m.accel_world_mps2 = alpha.cross(r) + w.cross(w.cross(r));
  return m;
}

// Smooth 0 -> amplitude move over `duration` (raised cosine): angle, rate, acceleration.
inline Vec3 raised_cosine(double s_time, double duration, double amplitude) {
  const double s = std::clamp(s_time / duration, 0.0, 1.0);
  if (s_time <= 0.0 || s_time >= duration) return {s >= 1.0 ? amplitude : 0.0, 0.0, 0.0};
  const double w = M_PI / duration;
  return {0.5 * amplitude * (1.0 - std::cos(M_PI * s)), 0.5 * amplitude * w * std::sin(M_PI * s),
          0.5 * amplitude * w * w * std::cos(M_PI * s)};
}

// The thesis's IMU bench (§3.3.1, Fig. 3.4): at rest, then ~90° about X and
// back, about Y and back, about Z and back, each move 2 s with 2 s holds. Y
// peaks at 80° rather than 90° because ZYX Euler angles are singular at 90°
// pitch, where yaw and roll errors stop meaning anything.
struct BenchPlan {
  double rest_s = 5.0;
  double move_s = 2.0;
  double hold_s = 2.0;
  Vec3 lever_in_body_m = Vec3(0.03, 0.02, 0.01);  // IMU off the turntable's axis: centripetal and tangential acceleration
  double duration_s() const { return rest_s + 3.0 * (2.0 * move_s + 2.0 * hold_s); }
  Motion operator()(double t) const {
    const Vec3 axes[3] = {Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ()};
    const double peaks[3] = {90.0 * kDeg, 80.0 * kDeg, 90.0 * kDeg};
    double u = t - rest_s;
    const double leg = 2.0 * move_s + 2.0 * hold_s;
    if (u < 0.0) return about_axis(Vec3::UnitX(), 0.0, 0.0, 0.0, lever_in_body_m);
    const int i = std::min(2, static_cast<int>(u / leg));
    u -= i * leg;
    Vec3 a;
    if (u < move_s) {
      a = raised_cosine(u, move_s, peaks[i]);
    } else if (u < move_s + hold_s) {
      a = {peaks[i], 0.0, 0.0};
    } else if (u < 2.0 * move_s + hold_s) {
      const Vec3 r = raised_cosine(u - move_s - hold_s, move_s, peaks[i]);
      a = {peaks[i] - r[0], -r[1], -r[2]};
    } else {
      a = Vec3::Zero();
    }
    return about_axis(axes[i], a[0], a[1], a[2], lever_in_body_m);
  }
};

// Field of a point dipole (moment in A·m², positions in m) in µT.
inline Vec3 dipole_field_uT(const Vec3& moment_Am2, const Vec3& p_dipole_m, const Vec3& p_m) {
  const Vec3 r = p_m - p_dipole_m;
  const double d = r.norm();
  const Vec3 u = r / d;
  return 1e-7 * (3.0 * moment_Am2.dot(u) * u - moment_Am2) / (d * d * d) * 1e6;
}

inline double wrap_pi(double a) { return std::remainder(a, 2.0 * M_PI); }

}  // namespace proprio::ftm::imu_synth
