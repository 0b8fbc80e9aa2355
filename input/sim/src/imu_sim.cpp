#include "proprio/sim/imu_sim.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <utility>

#include "proprio/sim/hand_motion.hpp"

namespace proprio::sim {

namespace {

// Sub-streams of mix_seed(seed, imu): one per random effect, so that turning
// one effect off (or changing its size) does not shift another's draws.
enum Stream : std::uint64_t {
  kMountStream = 0,
  kTurnOnStream = 1,
  kJitterStream = 2,
  kNoiseStream = 3,
  kWalkStream = 4,
  kMagIronStream = 5,  // hard/soft iron and the calibration's residual
  kMagNoiseStream = 6,
};

Rng stream_rng(std::uint64_t seed, std::size_t imu, Stream s) {
  return Rng(mix_seed(mix_seed(seed, static_cast<std::uint64_t>(imu)), s));
}

// Standard normal truncated to |z| <= bound by rejection: deterministic, and
// the accepted values keep the normal's shape inside the bound.
double truncated_normal(Rng& rng, double bound) {
  for (;;) {
    const double z = rng.normal();
    if (std::abs(z) <= bound) return z;
  }
}

Vec3 normal3(Rng& rng) {
  // Evaluated in x, y, z order on purpose: Vec3(rng.normal(), ...) would leave
  // the order to the compiler and break bit-for-bit reproducibility.
  const double x = rng.normal();
  const double y = rng.normal();
  const double z = rng.normal();
  return {x, y, z};
}

bool clip(Vec3& v, double range) {
  bool clipped = false;
  for (int k = 0; k < 3; ++k) {
    if (v[k] > range) {
      v[k] = range;
      clipped = true;
    } else if (v[k] < -range) {
      v[k] = -range;
      clipped = true;
    }
  }
  return clipped;
}

bool finite_nonnegative(double v) { return std::isfinite(v) && v >= 0.0; }

Error bad_option(const char* field, double value, const char* what) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "IMU noise option %s = %g is not usable: %s", field, value, what);
  return make_error(Errc::invalid_argument, buf);
}

Error bad_mag_option(const char* field, double value, const char* what) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "IMU noise option magnetometer.%s = %g is not usable: %s", field, value, what);
  return make_error(Errc::invalid_argument, buf);
}

// Per-axis quantiser and overflow of the AK8963, on the chip side (before any
// calibration). Returns HOFL.
bool quantise_mag(Vec3& v, const MagnetometerOptions& o) {
  bool overflow = false;
  if (o.enable_overflow) {
    overflow = v.cwiseAbs().maxCoeff() > o.range_T || v.cwiseAbs().sum() >= o.overflow_sum_T;
  }
  const double full = static_cast<double>(o.max_count);
  for (int k = 0; k < 3; ++k) {
    double counts = v[k] / o.resolution_T_per_lsb;
    if (o.enable_quantisation) counts = std::nearbyint(counts);
    if (o.enable_overflow) counts = std::clamp(counts, -full, full);
    v[k] = counts * o.resolution_T_per_lsb;
  }
  return overflow;
}

}  // namespace

DurationNs MagnetometerOptions::period_ns() const { return seconds_to_ns(1.0 / sample_rate_hz); }

Status MagnetometerOptions::validate() const {
  if (!std::isfinite(sample_rate_hz) || sample_rate_hz <= 0.0 || sample_rate_hz > 100.0) {
    return bad_mag_option("sample_rate_hz", sample_rate_hz,
                          "the AK8963 measures at 100 Hz at most (continuous mode 2); use a rate in (0, 100]");
  }
  if (!std::isfinite(resolution_T_per_lsb) || resolution_T_per_lsb <= 0.0) {
    return bad_mag_option("resolution_T_per_lsb", resolution_T_per_lsb, "it must be > 0 (0.15e-6 for 16-bit output)");
  }
  if (max_count <= 0) return bad_mag_option("max_count", max_count, "it must be > 0 (32760 for 16-bit output)");
  if (!std::isfinite(range_T) || range_T <= 0.0) return bad_mag_option("range_T", range_T, "it must be > 0");
  if (!std::isfinite(overflow_sum_T) || overflow_sum_T <= 0.0) {
    return bad_mag_option("overflow_sum_T", overflow_sum_T, "it must be > 0");
  }
  const struct {
    const char* name;
    double value;
  } nonneg[] = {{"noise_sigma_T", noise_sigma_T},
                {"hard_iron_sigma_T", hard_iron_sigma_T},
                {"soft_iron_scale_sigma", soft_iron_scale_sigma},
                {"soft_iron_cross_sigma", soft_iron_cross_sigma},
                {"residual_offset_sigma_T", residual_offset_sigma_T},
                {"residual_matrix_sigma", residual_matrix_sigma}};
  for (const auto& f : nonneg) {
    if (!std::isfinite(f.value) || f.value < 0.0) return bad_mag_option(f.name, f.value, "it must be finite and >= 0");
  }
  // Draws are truncated at 3σ; these bounds keep S = I + E and I + D strictly
  // diagonally dominant, hence invertible, for every draw.
  if (3.0 * (soft_iron_scale_sigma + 2.0 * soft_iron_cross_sigma) >= 1.0) {
    return bad_mag_option("soft_iron_scale_sigma", soft_iron_scale_sigma,
                          "3*(scale_sigma + 2*cross_sigma) must be < 1 so that S stays invertible");
  }
  if (9.0 * residual_matrix_sigma >= 1.0) {
    return bad_mag_option("residual_matrix_sigma", residual_matrix_sigma, "it must be < 1/9 so that I + D stays invertible");
  }
  return Status::success();
}

std::string MagnetometerOptions::describe() const {
  char buf[600];
  std::snprintf(buf, sizeof buf,
                "mag: rate=%.1fHz res=%.3g uT/LSB range=+-%.0f uT (HOFL also at |x|+|y|+|z|>=%.0f uT)%s%s "
                "noise=%.3g uT%s hard_iron_sigma=%.3g uT%s soft_iron_sigma: scale=%.3g cross=%.3g%s output=%s "
                "residual: offset=%.3g uT matrix=%.3g%s",
                sample_rate_hz, resolution_T_per_lsb * 1e6, range_T * 1e6, overflow_sum_T * 1e6,
                enable_quantisation ? "" : " [no quantisation]", enable_overflow ? "" : " [no overflow]",
                noise_sigma_T * 1e6, enable_noise ? "" : " [off]", hard_iron_sigma_T * 1e6,
                enable_hard_iron ? "" : " [off]", soft_iron_scale_sigma, soft_iron_cross_sigma,
                enable_soft_iron ? "" : " [off]", output == MagnetometerOutput::raw ? "raw" : "calibrated",
                residual_offset_sigma_T * 1e6, residual_matrix_sigma,
                enable_residual_calibration_error ? "" : " [off]");
  return buf;
}

ImuNoiseOptions ImuNoiseOptions::ideal() {
  ImuNoiseOptions o;
  o.enable_white_noise = false;
  o.enable_bias_random_walk = false;
  o.enable_turn_on_bias = false;
  o.enable_misalignment = false;
  o.enable_timestamp_jitter = false;
  o.enable_saturation = false;
  o.magnetometer.enable_noise = false;
  o.magnetometer.enable_hard_iron = false;
  o.magnetometer.enable_soft_iron = false;
  o.magnetometer.enable_residual_calibration_error = false;
  o.magnetometer.enable_quantisation = false;
  o.magnetometer.enable_overflow = false;
  return o;
}

double ImuNoiseOptions::gyro_noise_sigma() const {
  return enable_white_noise ? gyro_noise_density * std::sqrt(sample_rate_hz) : 0.0;
}
double ImuNoiseOptions::accel_noise_sigma() const {
  return enable_white_noise ? accel_noise_density * std::sqrt(sample_rate_hz) : 0.0;
}
double ImuNoiseOptions::gyro_bias_step_sigma() const {
  return enable_bias_random_walk ? gyro_bias_random_walk / std::sqrt(sample_rate_hz) : 0.0;
}
double ImuNoiseOptions::accel_bias_step_sigma() const {
  return enable_bias_random_walk ? accel_bias_random_walk / std::sqrt(sample_rate_hz) : 0.0;
}
DurationNs ImuNoiseOptions::period_ns() const { return seconds_to_ns(1.0 / sample_rate_hz); }

Status ImuNoiseOptions::validate() const {
  if (!std::isfinite(sample_rate_hz) || sample_rate_hz <= 0.0 || sample_rate_hz > 1e6) {
    return bad_option("sample_rate_hz", sample_rate_hz, "use a rate in (0, 1e6] Hz, e.g. 100");
  }
  const struct {
    const char* name;
    double value;
  } nonneg[] = {{"gyro_noise_density", gyro_noise_density},
                {"accel_noise_density", accel_noise_density},
                {"gyro_bias_random_walk", gyro_bias_random_walk},
                {"accel_bias_random_walk", accel_bias_random_walk},
                {"turn_on_bias_gyro", turn_on_bias_gyro},
                {"turn_on_bias_accel.x", turn_on_bias_accel.x()},
                {"turn_on_bias_accel.y", turn_on_bias_accel.y()},
                {"turn_on_bias_accel.z", turn_on_bias_accel.z()},
                {"timestamp_jitter_ns", timestamp_jitter_ns},
                {"gravity_mps2", gravity_mps2}};
  for (const auto& f : nonneg) {
    if (!finite_nonnegative(f.value)) return bad_option(f.name, f.value, "it must be finite and >= 0");
  }
  if (!std::isfinite(max_misalignment_rad) || max_misalignment_rad < 0.0 || max_misalignment_rad > M_PI) {
    return bad_option("max_misalignment_rad", max_misalignment_rad, "use an angle in [0, pi] rad");
  }
  if (!std::isfinite(accel_range_mps2) || accel_range_mps2 <= 0.0) {
    return bad_option("accel_range_mps2", accel_range_mps2, "the full scale must be > 0");
  }
  if (!std::isfinite(gyro_range_radps) || gyro_range_radps <= 0.0) {
    return bad_option("gyro_range_radps", gyro_range_radps, "the full scale must be > 0");
  }
  const double period_s = 1.0 / sample_rate_hz;
  if (!std::isfinite(difference_step_s) || seconds_to_ns(difference_step_s) < 1 ||
      difference_step_s >= 0.5 * period_s) {
    return bad_option("difference_step_s", difference_step_s,
                      "use at least 1 ns and less than half the sample period (1e-3 s at 100 Hz)");
  }
  return magnetometer.validate();
}

std::string ImuNoiseOptions::describe() const {
  char buf[900];
  std::snprintf(
      buf, sizeof buf,
      "rate=%.1fHz gyro_noise=%.3g rad/s/rtHz (%.3g deg/s/rtHz)%s accel_noise=%.3g m/s2/rtHz (%.0f ug/rtHz)%s "
      "gyro_bias_walk=%.3g rad/s2/rtHz accel_bias_walk=%.3g m/s3/rtHz%s "
      "turn_on_bias_sigma: gyro=%.3g rad/s (%.2f deg/s) accel=[%.3g,%.3g,%.3g] m/s2 (truncated at 3 sigma)%s "
      "misalignment<=%.1fdeg%s jitter_sigma=%.0fus%s range: accel=%.1f m/s2 (%.0f g) gyro=%.2f rad/s (%.0f deg/s)%s "
      "g=%.5f m/s2 diff_step=%.2gs",
      sample_rate_hz, gyro_noise_density, rad_to_deg(gyro_noise_density), enable_white_noise ? "" : " [off]",
      accel_noise_density, accel_noise_density / kStandardGravity * 1e6, enable_white_noise ? "" : " [off]",
      gyro_bias_random_walk, accel_bias_random_walk, enable_bias_random_walk ? "" : " [off]", turn_on_bias_gyro,
      rad_to_deg(turn_on_bias_gyro), turn_on_bias_accel.x(), turn_on_bias_accel.y(), turn_on_bias_accel.z(),
      enable_turn_on_bias ? "" : " [off]", rad_to_deg(max_misalignment_rad), enable_misalignment ? "" : " [off]",
      timestamp_jitter_ns * 1e-3, enable_timestamp_jitter ? "" : " [off]", accel_range_mps2,
      accel_range_mps2 / kStandardGravity, gyro_range_radps, rad_to_deg(gyro_range_radps),
      enable_saturation ? "" : " [off]", gravity_mps2, difference_step_s);
  std::string out = buf;
  if (magnetometer.enabled) out += " " + magnetometer.describe();
  return out;
}

Result<ImuSimulator> ImuSimulator::create(HandPoseFunction poses, std::vector<PlacedImu> imus, ImuNoiseOptions options,
                                          std::uint64_t seed, TimeNs first_tick_ns) {
  if (Status s = options.validate(); !s.ok()) return s.error();
  if (!poses) return make_error(Errc::invalid_argument, "ImuSimulator: no hand pose function was given");
  if (imus.empty()) {
    return make_error(Errc::invalid_argument,
                      "ImuSimulator: the glove has no IMUs to simulate; describe them in the glove's [[imu]] entries");
  }
  if (imus.size() > std::numeric_limits<std::uint16_t>::max()) {
    return make_error(Errc::invalid_argument, "ImuSimulator: more than 65535 IMUs do not fit a u16 sensor id");
  }
  return ImuSimulator(std::move(poses), std::move(imus), options, seed, first_tick_ns);
}

Result<ImuSimulator> ImuSimulator::create(HandMotionGenerator& motion, std::vector<PlacedImu> imus,
                                          ImuNoiseOptions options, std::uint64_t seed, TimeNs first_tick_ns) {
  // The generator clamps t < 0 to its start, so the difference step around
  // t = 0 sees the hand holding still, as it does at the protocol's start.
  return create([&motion](TimeNs t) { return motion.sample(t).pose; }, std::move(imus), options, seed,
                first_tick_ns);
}

ImuSimulator::ImuSimulator(HandPoseFunction poses, std::vector<PlacedImu> imus, ImuNoiseOptions options,
                           std::uint64_t seed, TimeNs first_tick_ns)
    : poses_(std::move(poses)),
      options_(options),
      seed_(seed),
      first_tick_ns_(first_tick_ns),
      magnetic_env_(std::make_shared<const MagneticEnvironment>()) {
  const std::size_t n = imus.size();
  mountings_.resize(n);
  state_.resize(n);
  readings_.resize(n);
  truth_.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    ImuMounting& m = mountings_[i];
    m.sensor_id = static_cast<std::uint16_t>(i);
    m.glove_imu_index = imus[i].index;
    m.segment = imus[i].segment;
    m.T_segment_imu_nominal = imus[i].T_segment_imu;
    if (options_.enable_misalignment && options_.max_misalignment_rad > 0.0) {
      Rng rng = stream_rng(seed, i, kMountStream);
      // A normalised Gaussian vector is uniform on the sphere; a zero vector
      // (probability ~0) is redrawn so the stream stays deterministic.
      Vec3 axis;
      do { axis = normal3(rng); } while (axis.norm() < 1e-12);
      axis.normalize();
      m.misalignment_rad = options_.max_misalignment_rad * rng.uniform01();
      m.q_nominal_imu = so3_exp(m.misalignment_rad * axis);
    }
    // The IMU sits where it was placed; only its axes are off. The position
    // error of a real mounting (a millimetre or two) is not modelled.
    m.T_segment_imu = m.T_segment_imu_nominal * Pose{m.q_nominal_imu, Vec3::Zero()};
    if (options_.enable_turn_on_bias) {
      Rng rng = stream_rng(seed, i, kTurnOnStream);
      for (int k = 0; k < 3; ++k) m.turn_on_bias_gyro_radps[k] = options_.turn_on_bias_gyro * truncated_normal(rng, 3.0);
      for (int k = 0; k < 3; ++k) {
        m.turn_on_bias_accel_mps2[k] = options_.turn_on_bias_accel[k] * truncated_normal(rng, 3.0);
      }
    }
    {
      // Every draw is made whatever the switches, in a fixed order, so that
      // switching one error off leaves the others as they were.
      const MagnetometerOptions& mo = options_.magnetometer;
      Rng rng = stream_rng(seed, i, kMagIronStream);
      Vec3 hard, diag, cross, res_offset;
      Mat3 res_matrix;
      for (int k = 0; k < 3; ++k) hard[k] = mo.hard_iron_sigma_T * truncated_normal(rng, 3.0);
      for (int k = 0; k < 3; ++k) diag[k] = mo.soft_iron_scale_sigma * truncated_normal(rng, 3.0);
      for (int k = 0; k < 3; ++k) cross[k] = mo.soft_iron_cross_sigma * truncated_normal(rng, 3.0);
      for (int k = 0; k < 3; ++k) res_offset[k] = mo.residual_offset_sigma_T * truncated_normal(rng, 3.0);
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) res_matrix(r, c) = mo.residual_matrix_sigma * truncated_normal(rng, 3.0);
      }
      if (mo.enable_hard_iron) m.mag_hard_iron_T = hard;
      if (mo.enable_soft_iron) {
        Mat3 E = diag.asDiagonal();
        E(0, 1) = E(1, 0) = cross[0];
        E(0, 2) = E(2, 0) = cross[1];
        E(1, 2) = E(2, 1) = cross[2];
        m.mag_soft_iron = Mat3::Identity() + E;
      }
      m.mag_calibration_offset_T = m.mag_hard_iron_T;
      m.mag_calibration_matrix = m.mag_soft_iron;
      if (mo.enable_residual_calibration_error) {
        m.mag_calibration_offset_T += res_offset;
        m.mag_calibration_matrix = (Mat3::Identity() + res_matrix) * m.mag_soft_iron;
      }
    }
    ImuState& s = state_[i];
    s.mag_noise_rng = stream_rng(seed, i, kMagNoiseStream);
    s.jitter_rng = stream_rng(seed, i, kJitterStream);
    s.noise_rng = stream_rng(seed, i, kNoiseStream);
    s.walk_rng = stream_rng(seed, i, kWalkStream);
    s.gyro_bias = m.turn_on_bias_gyro_radps;
    s.accel_bias = m.turn_on_bias_accel_mps2;
  }
}

TimeNs ImuSimulator::next_nominal_time_ns() const noexcept {
  // Tick k at k / rate from the first tick, rounded per tick so that rates
  // whose period is not a whole number of ns do not accumulate rounding.
  return first_tick_ns_ + seconds_to_ns(static_cast<double>(tick_) / options_.sample_rate_hz);
}

std::span<const ImuReading> ImuSimulator::next() {
  const TimeNs nominal = next_nominal_time_ns();
  const DurationNs h_ns = seconds_to_ns(options_.difference_step_s);
  const double h = ns_to_seconds(h_ns);  // the step actually taken, after rounding to ns
  const double jitter_sigma = options_.enable_timestamp_jitter ? options_.timestamp_jitter_ns : 0.0;
  const double jitter_limit = 0.45 * static_cast<double>(options_.period_ns());
  const double gyro_sigma = options_.gyro_noise_sigma();
  const double accel_sigma = options_.accel_noise_sigma();
  const double gyro_step = options_.gyro_bias_step_sigma();
  const double accel_step = options_.accel_bias_step_sigma();
  const Vec3 g_world(0.0, -options_.gravity_mps2, 0.0);
  const MagnetometerOptions& mo = options_.magnetometer;
  // The compass samples on the ticks, decimated to its own (lower or equal)
  // rate: a new sample whenever tick * rate_mag / rate_imu reaches a new integer.
  bool mag_fresh = false;
  if (mo.enabled) {
    const std::int64_t slot = mo.sample_rate_hz >= options_.sample_rate_hz
                                  ? tick_
                                  : static_cast<std::int64_t>(std::floor(static_cast<double>(tick_) *
                                                                         mo.sample_rate_hz / options_.sample_rate_hz));
    mag_fresh = slot != mag_last_slot_;
    mag_last_slot_ = slot;
  }
  const double mag_noise_sigma = mo.enable_noise ? mo.noise_sigma_T : 0.0;

  // The hand at t - h, t, t + h. Without jitter every IMU shares t, so the
  // (costly) pose function runs three times per tick instead of per IMU.
  TimeNs cached_t = 0;
  bool have_cache = false;
  HandPose before, at, after;

  for (std::size_t i = 0; i < mountings_.size(); ++i) {
    const ImuMounting& m = mountings_[i];
    ImuState& s = state_[i];

    TimeNs t = nominal;
    if (jitter_sigma > 0.0) {
      const double j = std::clamp(jitter_sigma * truncated_normal(s.jitter_rng, 5.0), -jitter_limit, jitter_limit);
      t += static_cast<TimeNs>(std::llround(j));
    }
    if (!have_cache || t != cached_t) {
      before = poses_(t - h_ns);
      at = poses_(t);
      after = poses_(t + h_ns);
      cached_t = t;
      have_cache = true;
    }

    // On soft tissue the mount moves on its segment (translation only).
    auto mount = [&](const HandPose& pose, TimeNs when) {
      if (!mount_offsets_) return pose.joint(m.segment) * m.T_segment_imu;
      return pose.joint(m.segment) * Pose{Quat::Identity(), mount_offsets_(i, pose, when)} * m.T_segment_imu;
    };
    const Pose T_world_imu_before = mount(before, t - h_ns);
    const Pose T_world_imu = mount(at, t);
    const Pose T_world_imu_after = mount(after, t + h_ns);

    // Second central difference of the IMU's own position: the acceleration
    // its proof mass feels, lever arm (centripetal, tangential) included.
    const Vec3 a_world = (T_world_imu_after.p - 2.0 * T_world_imu.p + T_world_imu_before.p) / (h * h);
    // Specific force: what an accelerometer measures, f = Rᵀ(a - g).
    const Vec3 specific_force = T_world_imu.q.conjugate() * (a_world - g_world);
    // Body rate from the relative rotation across the step, R(t-h)ᵀR(t+h) =
    // exp(2h ω_body) + O(h³): exact for a constant rate about any axis.
    const Vec3 angular_rate = so3_log(T_world_imu_before.q.conjugate() * T_world_imu_after.q) / (2.0 * h);

    ImuGroundTruth& gt = truth_[i];
    gt.sensor_id = m.sensor_id;
    gt.nominal_time_ns = nominal;
    gt.time_ns = t;
    gt.T_segment_imu = m.T_segment_imu;
    gt.T_world_imu = T_world_imu;
    gt.gyro_bias_radps = s.gyro_bias;
    gt.accel_bias_mps2 = s.accel_bias;
    gt.specific_force_mps2 = specific_force;
    gt.angular_rate_radps = angular_rate;
    // Gyro noise first, then accel: a fixed draw order keeps the bytes reproducible.
    gt.gyro_noise_radps = gyro_sigma > 0.0 ? Vec3(gyro_sigma * normal3(s.noise_rng)) : Vec3(Vec3::Zero());
    gt.accel_noise_mps2 = accel_sigma > 0.0 ? Vec3(accel_sigma * normal3(s.noise_rng)) : Vec3(Vec3::Zero());

    ImuReading& r = readings_[i];
    r.time_ns = t;
    r.sample.sensor_id = m.sensor_id;
    r.sample.gyro_radps = angular_rate + s.gyro_bias + gt.gyro_noise_radps;
    r.sample.accel_mps2 = specific_force + s.accel_bias + gt.accel_noise_mps2;
    r.mag_fresh = mag_fresh;
    if (!mo.enabled) {
      r.sample.mag_T.reset();  // VIST's glove has no compass (it fails near haptic devices, Lee 2021 §4.7)
      r.mag_overflow = false;
    } else if (mag_fresh) {
      // Measured at this reading's own instant; the pose `at` is already there.
      gt.mag_time_ns = t;
      gt.mag_field_world_T = magnetic_env_->field_world_T(T_world_imu.p, t, &at);
      gt.mag_field_T = T_world_imu.q.conjugate() * gt.mag_field_world_T;
      gt.mag_earth_T = T_world_imu.q.conjugate() * magnetic_env_->earth_field_world_T();
      gt.mag_noise_T = mag_noise_sigma > 0.0 ? Vec3(mag_noise_sigma * normal3(s.mag_noise_rng)) : Vec3(Vec3::Zero());
      Vec3 chip = m.mag_soft_iron * gt.mag_field_T + m.mag_hard_iron_T + gt.mag_noise_T;
      r.mag_overflow = quantise_mag(chip, mo);
      if (mo.output == MagnetometerOutput::calibrated) {
        chip = m.mag_calibration_matrix.inverse() * (chip - m.mag_calibration_offset_T);
      }
      r.sample.mag_T = chip;
    }
    r.gyro_saturated = options_.enable_saturation && clip(r.sample.gyro_radps, options_.gyro_range_radps);
    r.accel_saturated = options_.enable_saturation && clip(r.sample.accel_mps2, options_.accel_range_mps2);

    // Bias for the next sample: one step of the discrete random walk.
    if (gyro_step > 0.0) s.gyro_bias += gyro_step * normal3(s.walk_rng);
    if (accel_step > 0.0) s.accel_bias += accel_step * normal3(s.walk_rng);
  }
  ++tick_;
  return readings_;
}

std::string ImuSimulator::describe() const {
  std::string out = "ImuSimulator: " + std::to_string(mountings_.size()) + " IMUs, seed " + std::to_string(seed_) +
                    ", " + options_.describe();
  for (const auto& m : mountings_) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "\n  imu %u on %s: misalignment %.2f deg", static_cast<unsigned>(m.sensor_id),
                  std::string(to_string(m.segment)).c_str(), rad_to_deg(m.misalignment_rad));
    out += buf;
    if (options_.magnetometer.enabled) {
      std::snprintf(buf, sizeof buf, ", mag hard iron (%.1f, %.1f, %.1f) uT", m.mag_hard_iron_T.x() * 1e6,
                    m.mag_hard_iron_T.y() * 1e6, m.mag_hard_iron_T.z() * 1e6);
      out += buf;
    }
  }
  if (options_.magnetometer.enabled) out += "\n" + magnetic_env_->describe();
  return out;
}

void ImuSimulator::set_magnetic_environment(std::shared_ptr<const MagneticEnvironment> environment) {
  magnetic_env_ = environment ? std::move(environment) : std::make_shared<const MagneticEnvironment>();
}

Result<std::vector<StreamId>> add_imu_streams(RecordingWriter& writer, const ImuSimulator& sim,
                                              std::string_view name_prefix) {
  std::vector<StreamId> ids;
  ids.reserve(sim.imu_count());
  const ImuNoiseOptions& o = sim.options();
  for (const auto& m : sim.mountings()) {
    // Only what a user of the real glove would know goes into the meta: the
    // nominal mounting and the sensor's nominal specification. The drawn
    // misalignment and biases are ground truth and stay out of it.
    const Pose& T = m.T_segment_imu_nominal;
    char meta[768];
    std::snprintf(meta, sizeof meta,
                  "{\"sensor_id\":%u,\"segment\":\"%s\",\"glove_imu_index\":%zu,\"rate_hz\":%.17g,"
                  "\"T_segment_imu_nominal\":{\"q_wxyz\":[%.17g,%.17g,%.17g,%.17g],\"p_m\":[%.17g,%.17g,%.17g]},"
                  "\"gyro_noise_density\":%.17g,\"accel_noise_density\":%.17g,"
                  "\"gyro_bias_random_walk\":%.17g,\"accel_bias_random_walk\":%.17g,"
                  "\"gyro_range_radps\":%.17g,\"accel_range_mps2\":%.17g,\"simulated\":true}",
                  static_cast<unsigned>(m.sensor_id), std::string(to_string(m.segment)).c_str(), m.glove_imu_index,
                  o.sample_rate_hz, T.q.w(), T.q.x(), T.q.y(), T.q.z(), T.p.x(), T.p.y(), T.p.z(),
                  o.gyro_noise_density, o.accel_noise_density, o.gyro_bias_random_walk, o.accel_bias_random_walk,
                  o.gyro_range_radps, o.accel_range_mps2);
    std::string meta_json = meta;
    if (o.magnetometer.enabled) {
      // Nominal compass specification only; the drawn irons are ground truth.
      char mag[256];
      std::snprintf(mag, sizeof mag, ",\"mag_rate_hz\":%.17g,\"mag_resolution_T\":%.17g,\"mag_range_T\":%.17g,"
                    "\"mag_output\":\"%s\"",
                    o.magnetometer.sample_rate_hz, o.magnetometer.resolution_T_per_lsb, o.magnetometer.range_T,
                    o.magnetometer.output == MagnetometerOutput::raw ? "raw" : "calibrated");
      meta_json.insert(meta_json.size() - 1, mag);
    }
    const std::string name = std::string(name_prefix) + std::to_string(m.sensor_id);
    auto id = writer.add_stream(StreamKind::imu, name, meta_json);
    if (!id.ok()) return id.error().with_context("declaring IMU stream '" + name + "'");
    ids.push_back(*id);
  }
  return ids;
}

Status write_imu_readings(RecordingWriter& writer, std::span<const StreamId> streams,
                          std::span<const ImuReading> readings) {
  for (const ImuReading& r : readings) {
    if (r.sample.sensor_id >= streams.size()) {
      return make_error(Errc::invalid_argument, "IMU reading of sensor " + std::to_string(r.sample.sensor_id) +
                                                    " has no stream; declare them with add_imu_streams first");
    }
    if (Status s = writer.write(streams[r.sample.sensor_id], r.sample, r.time_ns); !s.ok()) return s;
  }
  return Status::success();
}

}  // namespace proprio::sim
