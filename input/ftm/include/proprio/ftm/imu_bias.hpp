#pragma once
// Turn-on bias estimation for the FTM's MPU-9250s, what a user does before
// trusting an IMU: the datasheet allows a zero-rate offset of ±5 °/s and a
// zero-g offset of ±60 mg (X, Y) / ±80 mg (Z) at each power-up, which the
// Mahony filter's bias integrator would take tens of seconds to learn (and
// the accelerometer's offset it cannot learn at all: it tilts the estimate by
// up to ~4°, differently in each orientation).
//
//  * Gyro: the IMU lies still for a second at turn-on; its mean rate is the
//    bias (Earth's rotation, 0.004 °/s, is far below the noise of the mean).
//    The estimate refuses a window that was not still: a gyro or
//    accelerometer spread above the noise, a mean rate beyond any offset the
//    part can have, or an accelerometer direction that drifted between the
//    two halves of the window (a slow steady turn about a tilted axis).
//    Blind spot: a slow steady turn about the vertical leaves the
//    accelerometer unchanged and is taken for bias; keep the IMU on a table.
//  * Accelerometer: at rest the specific force has the length of g whatever
//    the orientation, so the offset b is the centre of the sphere ‖a - b‖ = g
//    through samples in many orientations (the figure-eight the compass
//    calibration needs anyway). Only quasi-static samples are used (low rate,
//    ‖a‖ near g): centripetal and tangential acceleration would bend the
//    sphere. The fit is refused when the orientations span too little
//    (an offset along a direction never turned away from cannot be told
//    from gravity), when the residual is too large or the offset beyond the
//    part's tolerance. Scale-factor errors are not fitted (the MPU-9250's
//    ±3 % sensitivity tolerance would need a full ellipsoid and more poses).
//
// Both are turn-on values: they change at each power-up (repeatability), so
// they belong to a session, not to the per-user calibration file.
#include <array>
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/ftm/ftm_glove.hpp"

namespace proprio::ftm {

struct StillBiasOptions {
  // Length of the still window. At 200 Hz, 1 s averages the gyro's
  // 0.1 °/s-per-sample noise down to ~0.007 °/s.
  double window_s = 1.0;
  // Per-axis standard deviation over the window above which the IMU was not
  // still. The MPU-9250's white noise at 200 Hz is ~0.1 °/s and ~3 mg per
  // sample: 0.5 °/s and 0.1 m/s² (~10 mg) are 3-5 σ, while a hand held in
  // the air (tremor 1-3 °/s) is refused.
  double max_gyro_std_radps = 0.5 * M_PI / 180.0;
  double max_accel_std_mps2 = 0.1;
  // A mean rate above this cannot be an offset (datasheet ±5 °/s; margin as
  // MahonyOptions::max_bias_radps): the IMU was turning.
  double max_gyro_bias_radps = 10.0 * M_PI / 180.0;
  // The accelerometer direction may move this much between the first and
  // second half of the window (noise of the half-means: ~0.02°). 0.3° refuses
  // a steady turn of ≥ 0.6 °/s about a non-vertical axis.
  double max_tilt_drift_rad = 0.3 * M_PI / 180.0;
  // ‖mean accel‖ must be within this of gravity (the accelerometer offset
  // itself is up to 80 mg).
  double gravity_mps2 = 9.80665;
  double max_gravity_error_mps2 = 0.2 * 9.80665;

  Status validate() const;  // Errc::invalid_argument naming the field
  std::string describe() const;
};

struct StillBiasEstimate {
  Vec3 gyro_bias_radps = Vec3::Zero();
  Vec3 mean_accel_mps2 = Vec3::Zero();
  double gyro_std_radps = 0.0;   // worst axis
  double accel_std_mps2 = 0.0;   // worst axis
  double tilt_drift_rad = 0.0;
  std::size_t samples = 0;
  double duration_s = 0.0;
};

// Streaming form (no allocation): feed samples from turn-on; once complete()
// (window_s covered), estimate() tells the bias or why the window was not
// still. Samples with a status bit set or non-finite values are skipped.
class StillBiasAccumulator {
 public:
  StillBiasAccumulator() = default;
  explicit StillBiasAccumulator(const StillBiasOptions& options) : options_(options) {}
  // Returns true while the sample still went into the window.
  bool add(const FtmImuSample& sample) noexcept;
  bool complete() const noexcept { return complete_; }
  // Errc::unavailable when the window is not yet covered; Errc::out_of_range
  // naming the failed check when the IMU was not still.
  Result<StillBiasEstimate> estimate() const;
  // The same checks without a message (no allocation): the gyro offset when
  // the window is complete and was still, else nullopt.
  std::optional<Vec3> accepted_gyro_bias() const noexcept;
  void reset() noexcept;
  const StillBiasOptions& options() const noexcept { return options_; }

 private:
  StillBiasOptions options_;
  TimeNs first_ns_ = 0, last_ns_ = 0;
  std::size_t n_ = 0;
  std::array<std::size_t, 2> n_half_{};
  Vec3 sum_gyro_ = Vec3::Zero(), sum2_gyro_ = Vec3::Zero();
  Vec3 sum_accel_ = Vec3::Zero(), sum2_accel_ = Vec3::Zero();
  std::array<Vec3, 2> sum_accel_half_{Vec3::Zero(), Vec3::Zero()};
  bool complete_ = false;
};

// Batch form: the first window_s of `samples` (time order).
Result<StillBiasEstimate> estimate_still_bias(std::span<const FtmImuSample> samples,
                                              const StillBiasOptions& options = {});

struct AccelBiasFitOptions {
  double gravity_mps2 = 9.80665;
  // Quasi-static samples only: rate under this and ‖a‖ within
  // max_gravity_error of g (the offset itself is up to 80 mg, so not tighter
  // than ~0.1 g). 2 rad/s: at 1 rad/s a brisk figure-eight left too few
  // orientations on the simulated bench (spread 0.018); at 2 rad/s a 5 cm
  // lever arm adds up to 0.2 m/s² of centripetal acceleration at the peaks,
  // which the Huber weights and the residual check below keep in bounds.
  double max_rate_radps = 2.0;
  double max_gravity_error_mps2 = 0.15 * 9.80665;
  // The smallest eigenvalue of the mean of u uᵀ over the samples' directions
  // u: 1/3 for directions all round the sphere, 0 for one orientation. Below
  // 0.03 (tilts within about ±10° of one pose) an offset across that pose is
  // hardly observable and the fit is refused.
  double min_direction_spread = 0.03;
  std::size_t min_samples = 200;
  // Refuse an offset beyond the part's tolerance with margin (80 mg ≈ 0.8 m/s²).
  double max_bias_mps2 = 1.5;
  // Refuse when the RMS of ‖a - b‖ - g exceeds this: the samples were not at
  // rest (noise alone is ~0.03 m/s²).
  double max_residual_rms_mps2 = 0.25;

  Status validate() const;  // Errc::invalid_argument naming the field
  std::string describe() const;
};

struct AccelBiasEstimate {
  Vec3 bias_mps2 = Vec3::Zero();
  double residual_rms_mps2 = 0.0;
  double direction_spread = 0.0;
  std::size_t samples = 0;  // quasi-static samples used
};

// Sphere fit with known radius g (Gauss-Newton from b = 0, Huber-weighted so
// a few accelerated samples do not drag it). Errc::unavailable when too few
// quasi-static samples or too little spread; Errc::out_of_range when the
// offset or residual is implausible.
Result<AccelBiasEstimate> fit_accel_bias(std::span<const FtmImuSample> samples, const AccelBiasFitOptions& options = {});

// The samples of one IMU from a recording, in order.
std::vector<FtmImuSample> imu_samples_of(std::span<const FtmEvent> events, std::size_t imu);

}  // namespace proprio::ftm
