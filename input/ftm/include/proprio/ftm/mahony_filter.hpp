#pragma once
// Mahony's explicit complementary filter on SO(3) with gyro-bias estimation
// (Mahony, Hamel & Pflimlin, "Nonlinear complementary filters on the special
// orthogonal group", IEEE TAC 53(5), 2008, eqs. 32 and 47), the attitude
// filter of the FTM thesis (Lee 2021, §3.2.2), one per IMU:
//
//   ω_mes = Σ k_i (v_i × v̂_i),   v̂_i = R̂ᵀ v0_i            (vector measurements)
//   Ṙ̂    = R̂ (Ω_y - b̂ + ω_mes)×                           (integrated by the exponential map)
//   ḃ̂    = -k_I Σ (v_i × v̂_i)
//
// with v_i the measured directions in the body, v0_i the same directions in
// the world and R̂ = R_world_body. For a small attitude error θ about an axis
// perpendicular to v_i, |v_i × v̂_i| ≈ θ, so each k_i (rad/s) is the crossover
// frequency of a first-order complementary filter: below k_i/2π the vector
// observation wins, above it the gyro. Per error axis the loop with the bias
// integrator is s² + k s + k_I.
//
// Two departures from the paper's generic vector form, both switchable:
//  * heading_only_mag: the compass corrects only heading (the rotation about
//    "up"), from the horizontal parts of measured and predicted field. A
//    disturbed or mis-calibrated compass then cannot tilt the estimate, and
//    the field's inclination does not weaken the heading correction.
//  * gate_mag: the compass is left out while a MagDisturbanceDetector flags
//    the field (heading from the gyro meanwhile). With gate_mag = false the
//    detector still runs and flags, but the filter uses every compass sample:
//    the plain filter, kept for comparison.
//
// Initialisation: the first sample with a usable accelerometer and compass
// sets R̂ by markley_attitude (bias starts at zero or at initial_bias_radps).
// Until then update() only reports what was missing.
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/ftm/mag_disturbance.hpp"
#include "proprio/ftm/markley.hpp"

namespace proprio::ftm {

// What happened to one sample; a bit set per event.
enum MahonyFlag : std::uint32_t {
  kInitialised = 1u << 0,        // this sample initialised (or re-initialised) R̂ from Markley
  kNotInitialised = 1u << 1,     // no attitude yet (waiting for a usable accelerometer + compass)
  kTimeNotAdvancing = 1u << 2,   // t <= previous t: sample ignored entirely
  kTimeGap = 1u << 3,            // dt > max_dt_s: not integrated across; re-initialised if possible
  kGyroInvalid = 1u << 4,        // gyro non-finite or saturated: the last good rate was held
  kAccelInvalid = 1u << 5,       // accelerometer non-finite, zero or saturated: no tilt correction
  kAccelRejected = 1u << 6,      // |‖a‖ - g| too large (linear acceleration): no tilt correction
  kMagInvalid = 1u << 7,         // compass non-finite, zero or saturated (AK8963 overflow): no heading correction
  kMagDisturbed = 1u << 8,       // the detector flags the field (also set when not gating)
  kMagGated = 1u << 9,           // compass left out because of kMagDisturbed (gate_mag)
  kMagRejectionExpired = 1u << 10,  // disturbance outlasted max_rejection_s: compass used again
  kMagAbsent = 1u << 11,         // no compass sample with this IMU sample (it runs slower)
};

struct MahonyOptions {
  // Specific force at rest, in the world: "up" times g. World is OpenXR (+Y up).
  Vec3 gravity_ref_in_world_mps2 = Vec3(0.0, 9.80665, 0.0);
  // The local Earth field in the world, from the compass calibration. The
  // default is a typical mid-latitude European field (48 µT, 60° dip,
  // horizontal part along -Z); FtmTracker replaces it with the field its
  // figure-eight calibration measured (FtmCalibration::earth_field_world_uT).
  Vec3 mag_ref_in_world_uT = Vec3(0.0, -41.569, -24.0);

  // Tilt correction gain, rad/s. 1.0 puts the accelerometer/gyro crossover at
  // 0.16 Hz. For the MPU-9250's white noise alone (gyro 0.01 °/s/√Hz, accel
  // 300 µg/√Hz) the optimum is σ_gyro/σ_accel ≈ 0.6 rad/s, where white noise
  // costs only ~0.01° either way; what costs more is the gyro's bias and
  // scale-factor error (±3 %) before the bias has converged, and a higher
  // gain removes it sooner. On the synthetic bench (tests/unit/input/ftm) the
  // mean ZYX error went 0.46° → 0.26° → 0.20° for k_accel 0.3 → 1 → 2 (k_mag
  // 0.3, k_bias 0.03); we stop at a 1 s time constant because on a glove
  // higher gains let the linear accelerations of a reach tilt the estimate.
  double k_accel_radps = 1.0;
  // Heading correction gain, rad/s: crossover 0.048 Hz. Per sample, 0.5 µT of
  // noise on the ~24 µT horizontal field is ~1.2° of heading, five times the
  // accelerometer's per-sample angle noise (0.24° at 200 Hz); white noise
  // alone would favour ≈ 0.08 rad/s. We take 0.3 so that heading recovers in
  // seconds after start-up or a gated disturbance, and no more, because this
  // gain also sets how fast an undetected disturbance drags heading.
  double k_mag_radps = 0.3;
  // Bias integrator gain, rad/s² per rad of error. With k = 1.0 the tilt loop
  // s² + s + 0.05 has a slow root at ≈ 0.053 rad/s (bias time constant
  // ≈ 19 s); the heading loop s² + 0.3 s + 0.05 is damped at ζ ≈ 0.67 (no
  // ringing). 0.1 converged faster on the synthetic bench (mean error 0.18°
  // against 0.26° at 0.03) but under-damps heading (ζ ≈ 0.47) and lets more
  // of an undetected compass disturbance into the bias.
  double k_bias_radps2 = 0.05;
  // Anti-windup: the bias estimate is clamped to this norm (MPU-9250 zero-rate
  // offset is specified as ±5 °/s at 25 °C; 10 °/s leaves margin).
  double max_bias_radps = 10.0 * M_PI / 180.0;
  // The bias integrator ignores a vector whose error exceeds this: so large
  // an error means a wrong attitude (start-up from a disturbed compass, a
  // fast reach), and integrating it would wind the bias up. 10° is far above
  // what a bias of a few °/s leaves against k_accel = 1 rad/s (< 0.1 rad).
  double bias_learning_max_error_rad = 10.0 * M_PI / 180.0;  // in (0, pi]
  std::optional<Vec3> initial_bias_radps;

  bool heading_only_mag = true;
  bool gate_mag = true;
  MagDisturbanceOptions disturbance;

  // No tilt correction while |‖a‖ - g| exceeds this (m/s²): linear
  // acceleration would be taken for tilt. 0.2 g.
  double accel_gate_mps2 = 0.2 * 9.80665;
  // Saturation of the sensors' full-scale ranges (MPU-9250 at ±2000 °/s,
  // ±16 g; AK8963 ±4800 µT). A component at or beyond 99.9 % of the range is
  // treated as clipped.
  double gyro_range_radps = 2000.0 * M_PI / 180.0;
  double accel_range_mps2 = 16.0 * 9.80665;
  double mag_range_uT = 4800.0;
  // A gap longer than this is not integrated across (a 200 Hz IMU that lost
  // 20 samples): R̂ is re-initialised from Markley when the sample allows it.
  double max_dt_s = 0.1;
  // A gyro that fails is bridged with its last good rate for at most this
  // long; after that the rate is taken as zero (attitude held).
  double gyro_hold_s = 0.05;
  // Markley weights for (re-)initialisation: inverse per-sample variances of
  // the two directions (accelerometer ≈ 0.24°, compass ≈ 1.2°: 1 : 1/25), so
  // tilt comes from the accelerometer and the compass mostly sets heading.
  WahbaWeights init_weights{1.0, 0.04};

  Status validate() const;
  std::string describe() const;
};

class MahonyFilter {
 public:
  // Call options.validate() first; create() does it for you.
  explicit MahonyFilter(const MahonyOptions& options);
  static Result<MahonyFilter> create(const MahonyOptions& options);

  // One IMU sample at t_ns: gyro (rad/s), accelerometer (m/s², specific
  // force), compass (µT, in the reference's unit; std::nullopt when this IMU
  // sample has none). Returns the MahonyFlag bits of what happened.
  std::uint32_t update(TimeNs t_ns, const Vec3& gyro_radps, const Vec3& accel_mps2,
                       const std::optional<Vec3>& mag_uT) noexcept;

  bool initialised() const noexcept { return initialised_; }
  const Quat& q_world_body() const noexcept { return q_world_body_; }
  const Vec3& gyro_bias_radps() const noexcept { return bias_radps_; }
  TimeNs last_time_ns() const noexcept { return last_ns_; }
  const MagDisturbanceDetector& detector() const noexcept { return detector_; }
  const MahonyOptions& options() const noexcept { return options_; }
  // Forgets attitude, bias and time; the next usable sample initialises again.
  // The bias restarts at initial_bias_radps (or zero).
  void reset() noexcept;
  // Seeds the bias integrator with an external estimate (a turn-on still
  // window, imu_bias.hpp), clamped to max_bias_radps like the integrator's
  // own; the integrator goes on learning from it. Non-finite input is ignored.
  void set_gyro_bias(const Vec3& bias_radps) noexcept;

 private:
  bool try_initialise(const Vec3& accel, const Vec3& mag) noexcept;

  MahonyOptions options_;
  MagDisturbanceDetector detector_;
  Vec3 up_in_world_, mag_ref_dir_, mag_ref_horizontal_dir_;
  double gravity_norm_ = 0.0;
  Quat q_world_body_ = Quat::Identity();
  Vec3 bias_radps_ = Vec3::Zero();
  Vec3 last_gyro_radps_ = Vec3::Zero();
  TimeNs last_ns_ = 0, last_good_gyro_ns_ = 0, last_mag_ns_ = 0;
  bool initialised_ = false, has_time_ = false, has_good_gyro_ = false, has_mag_time_ = false;
};

// ZYX Euler angles (yaw about Z, then pitch about Y, then roll about X) of a
// rotation, as (yaw, pitch, roll) in rad: how the thesis reports IMU error.
// Singular at pitch ±90°.
Vec3 euler_zyx_rad(const Quat& q) noexcept;

}  // namespace proprio::ftm
