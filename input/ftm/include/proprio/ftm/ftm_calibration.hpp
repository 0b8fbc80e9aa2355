#pragma once
// Per-user calibration of the FTM glove (Lee 2021, §3.2.3; issue 27):
//  * the IMU mountings R_b_f (each hand segment's frame in its IMU's frame),
//    from three known poses: R_s_f is known from the pose, R_s_b measured, so
//    R_b_f = R_s_bᵀ R_s_f; over three poses the chordal least-squares mean;
//  * the bend sensors' θ = β0 + β1·ρ, a line fitted through the three poses;
//  * each compass's hard/soft iron and the Earth field in the world frame,
//    from a figure-eight motion (solve_mag_and_field).
// Saved per user as TOML.
#include <array>
#include <cstddef>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/ftm/ftm_glove.hpp"
#include "proprio/ftm/imu_bias.hpp"
#include "proprio/ftm/mag_calibration.hpp"
#include "proprio/ftm/mahony_filter.hpp"

namespace proprio::ftm {

struct FtmCalibration {
  Handedness hand = Handedness::right;
  double hand_length_m = 0.19;
  double hand_width_m = 0.10;
  std::string subject;
  // R_b_f of the thesis: the segment's frame (HandModel's joint frame of
  // segment_of(imu), for the hand's own handedness) in the IMU's frame.
  std::array<Quat, kFtmImuCount> q_imu_segment{Quat::Identity(), Quat::Identity(), Quat::Identity(),
                                               Quat::Identity()};
  std::array<double, kFtmBendCount> beta0_rad{};
  std::array<double, kFtmBendCount> beta1_rad_per_pF{};
  std::array<MagCalibration, kFtmImuCount> mag{};
  // The local field in the world frame: the reference of the Mahony filters
  // and the disturbance detector.
  Vec3 earth_field_world_uT = MahonyOptions{}.mag_ref_in_world_uT;
  // Turn-on offsets (imu_bias.hpp) of this power-up, subtracted from every
  // reading before the filters: the accelerometer's from the figure-eight,
  // the gyro's seeds the filters' bias (from the still calibration poses).
  // Session values: not saved in the TOML file (they change at each
  // power-up); a loaded calibration has zeros until calibrate_ftm runs again.
  std::array<Vec3, kFtmImuCount> accel_bias_mps2{Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};
  std::array<Vec3, kFtmImuCount> gyro_bias_radps{Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};

  Status validate() const;
  std::string describe() const;
};

// Identity mountings, a typical bend gain (a StretchSense-type sensor: about
// 90° over 30 pF, zero at 0 pF), identity compass corrections and
// MahonyOptions' default field. Hand size is not checked here (validate()).
FtmCalibration nominal_ftm_calibration(Handedness hand, double hand_length_m, double hand_width_m);

// TOML, written by save/format and read by load. A broken file gives an error
// naming the file and the key (Config's file:line:col).
Result<FtmCalibration> load_ftm_calibration(const std::filesystem::path& path);
// Same, from text; source_name stands in for the file in messages.
Result<FtmCalibration> parse_ftm_calibration(std::string_view toml_text, const std::string& source_name);
Status save_ftm_calibration(const std::filesystem::path& path, const FtmCalibration& calibration);
std::string format_ftm_calibration(const FtmCalibration& calibration);

// The three known poses, held in this order.
enum class FtmCalibrationPose { flat = 0, thumb_parallel, bend_90 };
inline constexpr std::size_t kFtmCalibrationPoseCount = 3;
std::string_view to_string(FtmCalibrationPose pose) noexcept;
// What to tell the wearer.
std::string_view instruction(FtmCalibrationPose pose) noexcept;
// The joint angles the pose asks for (HandModel's convention; the same
// numbers for a left hand). flat: all 0. thumb_parallel: fingers flat, the
// thumb's CMC angles (1° grid) that put its metacarpal parallel to the index
// proximal phalanx (they depend on the hand's proportions, hence the shape).
// bend_90: thumb_parallel with the PIPs at 90°, DIPs 60°, thumb MCP 60° (its
// limit), thumb IP 30°. The same definition, to the bit, as the simulated
// wearer's instructed poses (input/ftm_sim).
HandAngles known_angles(FtmCalibrationPose pose, const HandShape& shape);
// For the default 0.19 m x 0.10 m hand.
HandAngles known_angles(FtmCalibrationPose pose);

// One held pose, as the collector saw it.
struct FtmPoseCapture {
  FtmCalibrationPose pose = FtmCalibrationPose::flat;
  std::array<Quat, kFtmImuCount> q_world_imu{Quat::Identity(), Quat::Identity(), Quat::Identity(),
                                             Quat::Identity()};
  std::array<double, kFtmBendCount> capacitance_pF{};  // mean over the still window
  Pose T_world_wrist;        // the wrist tracker's last valid pose
  bool wrist_valid = false;  // false: no valid wrist sample was seen
  double gyro_rms_radps = 0.0;  // over the last still window, worst IMU
  // Mean rate per IMU over the same window: the gyro's offset while still.
  std::array<Vec3, kFtmImuCount> gyro_mean_radps{Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};
  std::size_t samples = 0;      // IMU samples that went into the filters
};

// Collects one held pose from FtmEvents. Runs its own Mahony filters (with
// the calibration's compass corrections and field), so the orientations it
// reports are the same estimates the tracker will compute.
class FtmPoseCollector {
 public:
  // Stillness: the gyro norm of every IMU stays under this over the window.
  static constexpr double kStillGyroRadps = 0.15;  // ~8.6 °/s: a held hand trembles at ~1-3 °/s
  // Filters need this long after their first sample before their attitude is
  // used (1/k_accel is 1 s; heading converges more slowly from Markley's
  // start, which is already close).
  static constexpr DurationNs kSettleNs = 1'000'000'000;

  FtmPoseCollector(FtmCalibrationPose pose, const FtmCalibration& mag_and_field, MahonyOptions options);

  void push(const FtmEvent& event) noexcept;
  // True when every IMU and bend sensor has delivered samples over the last
  // `window` and the gyros stayed under kStillGyroRadps through it, and the
  // filters have settled.
  bool still(DurationNs window) const;
  // The capture; errors when an IMU never initialised or a bend sensor never
  // delivered a usable sample.
  Result<FtmPoseCapture> finish() const;

  FtmCalibrationPose pose() const noexcept { return pose_; }

 private:
  static constexpr std::size_t kRing = 1024;  // per IMU / bend: > 5 s at 200 Hz, 1 s at 1 kHz
  struct TimedValue {
    TimeNs t = 0;
    double v = 0.0;
  };
  FtmCalibrationPose pose_;
  FtmCalibration cal_;
  std::vector<MahonyFilter> filters_;  // one per IMU (no default constructor)
  std::array<std::array<TimedValue, kRing>, kFtmImuCount> gyro_;  // gyro norm
  std::array<std::array<Vec3, kRing>, kFtmImuCount> gyro_vec_;     // the same samples' rates
  std::array<std::size_t, kFtmImuCount> gyro_n_{};
  std::array<std::array<TimedValue, kRing>, kFtmBendCount> bend_;
  std::array<std::size_t, kFtmBendCount> bend_n_{};
  std::array<TimeNs, kFtmImuCount> first_ns_{};
  std::size_t samples_ = 0;
  TimeNs newest_ns_ = 0;
  Pose wrist_;
  bool wrist_valid_ = false;
};

// Per-IMU ellipsoid fit (fit_mag_ellipsoid) on the fresh compass samples of a
// figure-eight recording, then the Earth field in the world frame.
// Assumption: the dorsum IMU is rigid with the wrist tracker, related by
// base.q_imu_segment[dorsum] (identity until the three-pose calibration has
// run; run that and this again to refine). With valid wrist samples, each
// dorsum compass sample is rotated into the world by the wrist tracker's
// orientation nearest in time (within 50 ms) and averaged. Without them the
// documented fallback: the field's dip comes from the dorsum accelerometer
// (samples within 0.2 g of rest) and its horizontal part is put along world
// -Z (MahonyOptions' convention): heading is then relative to magnetic north,
// which is enough for the fingers (relative orientations) but not for a wrist
// pose in a tracker's frame.
Result<FtmCalibration> solve_mag_and_field(std::span<const FtmEvent> figure_eight, FtmCalibration base,
                                           const MagFitOptions& options = {});

// β0/β1 and q_imu_segment from three captures (one per pose, any order), each
// a least-squares fit over the poses (chordal mean of the rotations; a line
// through the (ρ, θ) pairs). The dorsum's segment is the wrist: its mounting
// comes from the wrist tracker's orientation (kept from base when a capture
// has no valid wrist sample). The finger segments' orientations in each pose
// are the dorsum IMU's (with that mounting) composed with HandModel FK of
// known_angles(pose), so the tracker's relative rotations reproduce the
// known poses. Assumption: the IMUs' world and the wrist tracker's share
// their heading (solve_mag_and_field with wrist samples makes them).
// Errors: not 3 captures, a pose twice, a bend sensor whose capacitance
// barely changes between the poses.
Result<FtmCalibration> solve_three_pose(std::span<const FtmPoseCapture> captures, FtmCalibration base);

// A whole calibration session as recorded: the figure-eight, then each of
// the three poses (from when the wearer was asked to take it until the
// capture). Events in time order within each part; the parts follow each
// other in time.
struct FtmCalibrationRecording {
  std::vector<FtmEvent> figure_eight;
  std::array<std::vector<FtmEvent>, kFtmCalibrationPoseCount> poses;
};

struct FtmCalibrationOutcome {
  FtmCalibration calibration;
  std::array<FtmPoseCapture, kFtmCalibrationPoseCount> captures{};
  // Per IMU: whether the accelerometer offset was fitted, and why not.
  std::array<bool, kFtmImuCount> accel_bias_fitted{};
  std::array<std::string, kFtmImuCount> accel_bias_note{};
  // Per IMU: whether the gyro offset was taken from the poses, and why not.
  std::array<bool, kFtmImuCount> gyro_bias_estimated{};
  std::array<std::string, kFtmImuCount> gyro_bias_note{};
};

// The turn-on offsets calibrate_ftm estimates (imu_bias.hpp), both from the
// readings alone: the accelerometer's by a sphere fit over the figure-eight,
// the gyro's as the mean rate while the three poses are held still.
struct FtmTurnOnBiasOptions {
  bool fit_accel = true;
  AccelBiasFitOptions accel_fit;
  bool gyro_from_poses = true;
  // The three poses' mean rates must agree within this for their mean to be
  // taken as the offset: 0.3 °/s is ~20 σ of a 0.5 s mean's noise, while a
  // held hand that drifts (the simulated wearer's poses differ by 2-4 °/s)
  // is refused and the filters learn the offset online instead.
  double max_pose_gyro_disagreement_radps = 0.3 * M_PI / 180.0;
  Status validate() const;
  std::string describe() const;
};

// The whole procedure on a recording: solve_mag_and_field on the
// figure-eight, then one FtmPoseCollector per pose (fed from the start of the
// session, so its filters have converged as a live run's would), then
// solve_three_pose. `base` gives hand, size and subject. Errors say which
// step failed.
Result<FtmCalibrationOutcome> calibrate_ftm(const FtmCalibrationRecording& recording, const FtmCalibration& base,
                                            const MahonyOptions& attitude = {}, const MagFitOptions& mag = {},
                                            const FtmTurnOnBiasOptions& bias = {});

}  // namespace proprio::ftm
