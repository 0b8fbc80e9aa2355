#pragma once
// Simulated glove IMUs (MPU-9250 class, as on the glove of Lee 2021, ch. 4):
// accelerometer (specific force, gravity included) and gyroscope sampled at
// 100 Hz from the analytic hand motion, with the error model of the thesis's
// EKF (eq. 4.18, after Trawny & Roumeliotis 2005):
//
//   w_m = w + b_g + n_g
//   a_m = R_world_imuᵀ (a_world - g_world) + b_a + n_a
//   db_g/dt = n_bg,  db_a/dt = n_ba
//
// plus a turn-on bias, a per-IMU mounting misalignment, sample-instant jitter
// and full-scale saturation. What the simulator *knows* (true mounting, true
// biases, noise-free signals) is kept in ImuGroundTruth, never in a reading.
//
// Noise convention (Kalibr "IMU Noise Model", also OpenVINS): the options hold
// continuous-time densities; a sample at rate f = 1/dt gets
//   white noise   sigma_d  = density * sqrt(f)         (= density / sqrt(dt))
//   bias step     sigma_bd = random_walk * sqrt(dt)    per sample
//
// Frames: world is OpenXR (+Y up), so g_world = (0, -9.80665, 0) m/s² and a
// level IMU at rest reads +9.80665 along world +Y, expressed in its own axes.
//
// Optionally (MagnetometerOptions::enabled, off by default) each IMU also has
// the MPU-9250's AK8963 compass, reading the field of a MagneticEnvironment
// (magnetic_field.hpp):
//
//   m_raw = Q( S · R_world_imuᵀ B_world(p_imu, t) + b + n_m )
//
// S the soft-iron matrix, b the hard-iron offset (both drawn per IMU), n_m
// white noise, Q the 16-bit quantiser (0.15 µT/LSB) with overflow flag. With
// output = calibrated the reading is Ĉ⁻¹(m_raw − b̂), where Ĉ = (I + D)·S and
// b̂ = b + δb are what an imperfect hard/soft-iron calibration found (D, δb
// the residual error). Readings are in the IMU's frame (the accelerometer's
// axes: the AK8963's own axes are swapped/flipped on the die, which a driver
// undoes), sample-and-hold between compass samples.
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/hand_pose.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/sim/magnetic_field.hpp"

namespace proprio::sim {

class HandMotionGenerator;

inline constexpr double kStandardGravity = 9.80665;  // m/s², CGPM 1901 (also the datasheet's "g")

enum class MagnetometerOutput : std::uint8_t {
  raw,         // what the chip gives: hard and soft iron included (a tracker calibrates it itself)
  calibrated,  // after the simulated imperfect calibration: only its residual error is left
};

// The AK8963 in the MPU-9250 (AK8963 datasheet; MPU-9250 product
// specification PS-MPU-9250A-01 rev 1.0, table 3).
struct MagnetometerOptions {
  // Off by default: the glove of Lee 2021 ch. 4 (VIST) has no compass, and
  // every existing user of ImuSimulator expects mag_T to stay empty.
  bool enabled = false;

  // Continuous measurement mode 2 is 100 Hz, the chip's fastest; mode 1 is
  // 8 Hz. The compass samples on the IMU ticks, decimated to this rate, and
  // every reading carries the newest sample (ImuReading::mag_fresh marks new ones).
  double sample_rate_hz = 100.0;
  // 16-bit output (CNTL1 BIT = 1): 0.15 µT/LSB, data registers ±32760.
  double resolution_T_per_lsb = 0.15e-6;
  std::int32_t max_count = 32760;
  // Full scale ±4800 µT (MPU-9250 PS). HOFL is set when an axis exceeds it or
  // when |x|+|y|+|z| >= 4912 µT (the AK8963 datasheet's ST2 note, as we read
  // it: the sensor can overflow before a register saturates).
  double range_T = 4800e-6;
  double overflow_sum_T = 4912e-6;

  // White noise per axis and sample. The datasheets give no noise figure;
  // 0.3 µT (2 LSB) is an ASSUMPTION of the order hobbyist logs of the part show.
  double noise_sigma_T = 0.3e-6;
  // Hard iron per axis (PCB traces, the battery, the glove's own parts),
  // Gaussian truncated at 3σ. ASSUMED: 15 µT, a third of the Earth field.
  double hard_iron_sigma_T = 15e-6;
  // Soft iron S = I + E: diagonal (scale, incl. the chip's unadjusted
  // sensitivity, ASA) and symmetric off-diagonal (cross-coupling), truncated
  // at 3σ. ASSUMED: 3 % and 1 %.
  double soft_iron_scale_sigma = 0.03;
  double soft_iron_cross_sigma = 0.01;
  // What a figure-eight ellipsoid fit leaves (output = calibrated only):
  // offset per axis and a general matrix error D, truncated at 3σ. ASSUMED:
  // 0.5 µT and 0.5 % (~1 % of the field, the ripple a calibrated norm shows).
  double residual_offset_sigma_T = 0.5e-6;
  double residual_matrix_sigma = 0.005;
  MagnetometerOutput output = MagnetometerOutput::raw;

  bool enable_noise = true;
  bool enable_hard_iron = true;
  bool enable_soft_iron = true;
  bool enable_residual_calibration_error = true;
  bool enable_quantisation = true;
  bool enable_overflow = true;  // clamp to ±max_count and set HOFL

  DurationNs period_ns() const;
  Status validate() const;  // Errc::invalid_argument naming the field ("magnetometer.<field>")
  std::string describe() const;
};

struct ImuNoiseOptions {
  double sample_rate_hz = 100.0;  // the thesis's glove samples every IMU at 100 Hz (Lee 2021, §4.2)

  // White noise, continuous-time densities. MPU-9250 product specification
  // PS-MPU-9250A-01 rev 1.0, tables 1-2: gyro rate noise spectral density
  // 0.01 °/s/√Hz; accelerometer noise power spectral density 300 µg/√Hz.
  // At 100 Hz that is 0.1 °/s and 2.9 mg per sample, matching the datasheet's
  // "total RMS noise 0.1 °/s-rms" at a 92 Hz low-pass (its accelerometer
  // "8 mg-rms" at 94 Hz is higher than its own density implies; we follow the density).
  double gyro_noise_density = deg_to_rad(0.01);             // rad/s/√Hz
  double accel_noise_density = 300e-6 * kStandardGravity;   // m/s²/√Hz

  // Bias random walk (rate random walk): the datasheet gives none. ASSUMED
  // values of the order seen in Kalibr/OpenVINS configs of MEMS IMUs (EuRoC's
  // ADIS16448: 1.94e-5 rad/s²/√Hz and 3.0e-3 m/s³/√Hz), a little worse on the
  // gyro for a consumer part. Over 60 s: about 0.02 °/s and 1.6 mg of drift (1σ).
  double gyro_bias_random_walk = 5e-5;   // rad/s²/√Hz
  double accel_bias_random_walk = 2e-3;  // m/s³/√Hz

  // Turn-on bias, drawn once per IMU per simulator, Gaussian with these
  // standard deviations and truncated at 3σ. The datasheet's tolerances
  // ("initial ZRO tolerance ±5 °/s"; "zero-G initial calibration tolerance
  // ±60 mg X,Y, ±80 mg Z") are read as those ±3σ bounds, so no drawn bias is
  // outside the specification.
  double turn_on_bias_gyro = deg_to_rad(5.0) / 3.0;                                       // rad/s, each axis
  Vec3 turn_on_bias_accel = Vec3(60e-3, 60e-3, 80e-3) * (kStandardGravity / 3.0);         // m/s², per axis

  // Mounting misalignment of each IMU against its nominal T_segment_imu: a
  // rotation about a uniformly random axis by an angle uniform in
  // [0, max_misalignment_rad]. 10° is the "up to ±10°" (the thesis
  // estimates this offset online, Fig. 4.5-D, without stating its size).
  double max_misalignment_rad = deg_to_rad(10.0);

  // Sample-instant jitter: each IMU is sampled at nominal + j, j Gaussian
  // with this standard deviation, truncated at ±5σ and at ±0.45 period so
  // samples stay in order. The reading's time is that true instant (the
  // architecture's "time it was measured"). 200 µs: an ATmega328 polling seven
  // sensors over SPI in turn (Lee 2021, §4.2); an assumption, not a measurement.
  double timestamp_jitter_ns = 200e3;

  // Full scale of the widest MPU-9250 ranges (AFS_SEL=3, FS_SEL=3). Readings
  // are clipped per axis to ±range and flagged.
  double accel_range_mps2 = 16.0 * kStandardGravity;
  double gyro_range_radps = deg_to_rad(2000.0);

  double gravity_mps2 = kStandardGravity;

  MagnetometerOptions magnetometer;  // off unless magnetometer.enabled

  // Half-step of the central differences that turn the analytic motion into
  // acceleration and angular rate. 1 ms keeps the truncation error
  // (h²/12·|p''''|, ~1e-5 m/s² for a minimum-jerk reach) and the round-off
  // (~4ε|p|/h², ~2e-9 m/s² at 2 m from the origin) both far below the
  // accelerometer's 0.03 m/s² noise. Must be below half the sample period.
  double difference_step_s = 1e-3;

  // Switches for tests: each effect can be turned off on its own.
  bool enable_white_noise = true;
  bool enable_bias_random_walk = true;
  bool enable_turn_on_bias = true;
  bool enable_misalignment = true;
  bool enable_timestamp_jitter = true;
  bool enable_saturation = true;

  // Everything off: readings equal the ground-truth signals, exactly on the grid.
  // The magnetometer keeps its `enabled` (off), with all its errors off.
  static ImuNoiseOptions ideal();

  // Standard deviations per sample that these densities give (0 when the effect is off).
  double gyro_noise_sigma() const;   // rad/s
  double accel_noise_sigma() const;  // m/s²
  double gyro_bias_step_sigma() const;   // rad/s per sample
  double accel_bias_step_sigma() const;  // m/s² per sample
  DurationNs period_ns() const;

  // Errc::invalid_argument naming the field when a value is not usable.
  Status validate() const;
  std::string describe() const;
};

// What a device delivers for one IMU at one tick.
struct ImuReading {
  TimeNs time_ns = 0;  // the instant the sample describes (nominal tick + jitter)
  ImuSample sample;    // sensor frame; sensor_id = index into the simulator's IMUs
  bool accel_saturated = false;  // some axis was clipped to ±accel_range_mps2
  bool gyro_saturated = false;   // some axis was clipped to ±gyro_range_radps
  // Compass (only with MagnetometerOptions::enabled; sample.mag_T holds it).
  bool mag_fresh = false;     // a new compass sample this tick (else the last one, held)
  bool mag_overflow = false;  // HOFL of the held sample: its value is not valid
};

// Drawn once per simulator from its seed, per IMU.
struct ImuMounting {
  std::uint16_t sensor_id = 0;
  std::size_t glove_imu_index = 0;  // PlacedImu::index (into ImuGloveDescription::imus)
  HandJoint segment = HandJoint::wrist;
  Pose T_segment_imu_nominal;  // as placed
  Pose T_segment_imu;          // true: nominal composed with the misalignment
  Quat q_nominal_imu = Quat::Identity();  // the misalignment (true IMU axes in the nominal IMU frame)
  double misalignment_rad = 0.0;          // its angle
  Vec3 turn_on_bias_gyro_radps = Vec3::Zero();
  Vec3 turn_on_bias_accel_mps2 = Vec3::Zero();
  // Compass errors (drawn whatever the switches; zero/identity when switched off).
  Vec3 mag_hard_iron_T = Vec3::Zero();              // b
  Mat3 mag_soft_iron = Mat3::Identity();            // S
  Vec3 mag_calibration_offset_T = Vec3::Zero();     // b̂ (used by output = calibrated)
  Mat3 mag_calibration_matrix = Mat3::Identity();   // Ĉ
};

// The truth behind one reading. Never part of what a tracker sees.
struct ImuGroundTruth {
  std::uint16_t sensor_id = 0;
  TimeNs nominal_time_ns = 0;  // the tick on the rate grid
  TimeNs time_ns = 0;          // the true sample instant (equals the reading's)
  Pose T_segment_imu;          // true mounting, misalignment included
  Pose T_world_imu;            // at time_ns
  Vec3 gyro_bias_radps = Vec3::Zero();   // bias in this reading (turn-on + walk so far)
  Vec3 accel_bias_mps2 = Vec3::Zero();
  Vec3 specific_force_mps2 = Vec3::Zero();  // noise-free, bias-free, unclipped, IMU frame
  Vec3 angular_rate_radps = Vec3::Zero();   // noise-free, bias-free, unclipped, IMU frame
  Vec3 accel_noise_mps2 = Vec3::Zero();     // the white noise drawn for this reading
  Vec3 gyro_noise_radps = Vec3::Zero();
  // Compass truth of the held sample (unchanged on ticks without a new one).
  TimeNs mag_time_ns = 0;                  // the instant it was measured
  Vec3 mag_field_world_T = Vec3::Zero();   // total field at the IMU, world frame
  Vec3 mag_field_T = Vec3::Zero();         // the same in the IMU frame: an ideal compass's reading
  Vec3 mag_earth_T = Vec3::Zero();         // the Earth's part alone, IMU frame
  Vec3 mag_noise_T = Vec3::Zero();         // the white noise drawn for it (chip side, before Q)
};

// The hand in the world at any time: the simulator evaluates it at each sample
// instant and ±difference_step_s around it. Must be deterministic in t.
using HandPoseFunction = std::function<HandPose(TimeNs)>;

// Streams readings tick by tick: the bias random walk makes each tick depend
// on the ones before, so there is no random access in time. One owner calls
// next(); not thread-safe. describe() states the seed, for the session log.
class ImuSimulator {
 public:
  // The IMUs sit on the segments of the hand the pose function returns
  // (typically ImuGloveDescription::place_imus(shape)); sensor_id i is imus[i].
  // The first tick is at first_tick_ns. Errors: invalid options, no IMUs, or
  // more than 65535 of them (Errc::invalid_argument).
  static Result<ImuSimulator> create(HandPoseFunction poses, std::vector<PlacedImu> imus, ImuNoiseOptions options,
                                     std::uint64_t seed, TimeNs first_tick_ns = 0);
  // Samples a motion generator, which must outlive the simulator. Its time
  // base (t = 0 at the protocol start) is the simulator's.
  static Result<ImuSimulator> create(HandMotionGenerator& motion, std::vector<PlacedImu> imus, ImuNoiseOptions options,
                                     std::uint64_t seed, TimeNs first_tick_ns = 0);

  // Readings of every IMU at the next tick, in sensor_id order. The span stays
  // valid until the next call. Ground truth for the same tick: ground_truth().
  std::span<const ImuReading> next();
  std::span<const ImuGroundTruth> ground_truth() const noexcept { return truth_; }

  std::span<const ImuMounting> mountings() const noexcept { return mountings_; }
  std::size_t imu_count() const noexcept { return mountings_.size(); }
  std::int64_t ticks_done() const noexcept { return tick_; }
  TimeNs next_nominal_time_ns() const noexcept;
  const ImuNoiseOptions& options() const noexcept { return options_; }
  std::uint64_t seed() const noexcept { return seed_; }
  std::string describe() const;

  // The field the compasses read (when enabled). Default: the Earth field of
  // EarthFieldOptions{} alone; nullptr restores that. The caller may keep a
  // non-const pointer to change currents between ticks; dipoles attached to
  // hand joints follow the hand this simulator samples.
  void set_magnetic_environment(std::shared_ptr<const MagneticEnvironment> environment);

  // Soft tissue (sim/soft_tissue.hpp): where IMU `imu`'s mount has moved from
  // its place at time t (the hand then in `pose`), in its segment frame. Like
  // the pose function it must be deterministic in t; the accelerometer then
  // feels the mount's own motion (sliding, wobble). Empty (the default):
  // rigidly on the bone.
  using MountOffsetFunction = std::function<Vec3(std::size_t imu, const HandPose& pose, TimeNs t)>;
  void set_mount_offsets(MountOffsetFunction offsets) { mount_offsets_ = std::move(offsets); }
  const MagneticEnvironment& magnetic_environment() const noexcept { return *magnetic_env_; }

 private:
  // Each effect draws from its own stream (mix_seed(seed, imu), then per
  // effect), so switching one effect off leaves the others' draws unchanged.
  struct ImuState {
    Rng jitter_rng{0};
    Rng noise_rng{0};
    Rng walk_rng{0};
    Vec3 gyro_bias = Vec3::Zero();
    Vec3 accel_bias = Vec3::Zero();
    Rng mag_noise_rng{0};
  };
  ImuSimulator(HandPoseFunction poses, std::vector<PlacedImu> imus, ImuNoiseOptions options, std::uint64_t seed,
               TimeNs first_tick_ns);

  HandPoseFunction poses_;
  ImuNoiseOptions options_;
  std::uint64_t seed_ = 0;
  TimeNs first_tick_ns_ = 0;
  std::int64_t tick_ = 0;
  std::vector<ImuMounting> mountings_;
  std::vector<ImuState> state_;  // biases and random streams per IMU
  std::vector<ImuReading> readings_;
  std::vector<ImuGroundTruth> truth_;
  std::shared_ptr<const MagneticEnvironment> magnetic_env_;
  MountOffsetFunction mount_offsets_;
  std::int64_t mag_last_slot_ = -1;  // decimation of the compass rate from the tick rate
};

// Declares one stream per IMU, "imu/<sensor_id>", with the mounting and the
// noise options in its JSON meta. Returns the stream ids in sensor_id order.
Result<std::vector<StreamId>> add_imu_streams(RecordingWriter& writer, const ImuSimulator& sim,
                                              std::string_view name_prefix = "imu/");
// Writes one tick's readings to the streams add_imu_streams declared.
Status write_imu_readings(RecordingWriter& writer, std::span<const StreamId> streams,
                          std::span<const ImuReading> readings);

}  // namespace proprio::sim
