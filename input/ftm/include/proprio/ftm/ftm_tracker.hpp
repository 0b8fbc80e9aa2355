#pragma once
// The FTM glove's tracker (Lee 2021, §3.2.2; issue 27): four Mahony filters
// (one per IMU), the thesis's kinematics for the relative rotations, the bend
// sensors for the 1-DOF joints, synergies for the distal ones and HandModel's
// forward kinematics to the 26 XR joints.
//
// Kinematics. Each segment's orientation in the world is R_s_f = R_s_b R_b_f
// (the filter's estimate times the calibrated mounting). Relative to the hand
// (the dorsum IMU's segment, rigid with WRIST): R_h_x = R_s_hᵀ R_s_x.
//  * Thumb CMC, 3 DOF (eq. 3.2): the metacarpal's rotation relative to its
//    rest frame in HandModel, q_cmc = q_restᵀ R_h_mp, is decomposed as
//    Ry(aa)·Rx(-fe)·Rz(ps): HandModel's flex_abd (abduction about the dorsal
//    +Y, flexion about +X) followed by pronation-supination about the bone's
//    long axis. The thesis orders FE, PS, AA about its own frames; ours puts
//    the two DOFs HandModel has first so that with ps = 0 the angles are
//    HandModel's exactly. The 20-DOF model has no pronation, so the thumb's
//    joint poses take the full measured rotation (ps included), and the
//    reported angles are fe and aa. The axis offset d (p_fe_aa = d e1, along
//    the PS axis): the metacarpal's first d metres turn with Ry(aa) only, the
//    rest with the full rotation; d = 0 reproduces HandModel's FK.
//  * Index/middle MCP, 2 DOF: q_mcp = q_metacarpal_restᵀ R_h_pp decomposed as
//    HandModel's flex_abd (abduction held at 0 when track_abduction is off:
//    the thesis's "without AA").
//  * Thumb MCP, index/middle PIP: θ = β0 + β1·ρ.
//  * Thumb IP, DIPs: synergies. Ring and little follow the middle finger
//    (MCP and PIP flexion copied, abduction held at 0: the enslaving of
//    HandMotionGenerator's natural coupling): valid, never tracked (their metacarpals included).
//
// Sensor health. An IMU counts while its filter is initialised, its last
// usable sample (no status bit but mag_overflow, finite) is within
// imu_timeout_ns of the newest sample seen, and its accelerometer and gyro
// have not repeated identical values for longer than imu_timeout_ns (a stuck
// bus). A bend sensor counts while its last usable sample is within
// bend_timeout_ns. A DOF whose sensor does not count holds its last value and
// loses the tracked flag. A joint's orientation is tracked when the wrist
// orientation and every DOF between the wrist and it are; its position when
// the wrist position and every DOF before it are. If the dorsum IMU fails,
// the wrist tracker's orientation (when valid) stands in for R_s_h.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/hand_pose.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/ftm/ftm_calibration.hpp"
#include "proprio/ftm/ftm_glove.hpp"
#include "proprio/ftm/imu_bias.hpp"
#include "proprio/ftm/mahony_filter.hpp"

namespace proprio::ftm {

struct FtmTrackerOptions {
  Handedness hand = Handedness::right;
  // Per-IMU filter; its mag_ref_in_world_uT is replaced by the calibration's field.
  MahonyOptions attitude;
  // The thesis's synergies: DIP = 2/3 PIP, thumb IP = 0.5 MCP.
  Synergies synergies{true, 2.0 / 3.0, 0.5};
  // Thesis eq. 3.2's d. 0 by default: HandModel (and the simulated wearer
  // built on it) has a single CMC centre.
  double thumb_cmc_axis_offset_m = 0.0;
  // false: index/middle MCP abduction held at 0 (the thesis's "without AA").
  bool track_abduction = true;
  DurationNs imu_timeout_ns = 100'000'000;
  DurationNs bend_timeout_ns = 100'000'000;
  DurationNs wrist_timeout_ns = 500'000'000;
  // Turn-on gyro offset from a still start (imu_bias.hpp): over each IMU's
  // first still.window_s of samples, if the glove lay still (on a table), the
  // mean rate seeds that filter's bias; a moving start is refused and the
  // filter learns the offset online (turn_on_gyro_bias() tells which). Not
  // used for an IMU whose calibration already carries a gyro offset
  // (calibrate_ftm's still poses): that is the same power-up's estimate.
  bool still_start_gyro_bias = true;
  StillBiasOptions still;

  Status validate() const;
  std::string describe() const;
};

class FtmTracker {
 public:
  static Result<FtmTracker> create(const FtmTrackerOptions& options, const FtmCalibration& calibration);

  void push(const FtmEvent& event) noexcept;
  void push_imu(FtmImu imu, const FtmImuSample& sample) noexcept;
  void push_bend(FtmBend bend, const FtmBendSample& sample) noexcept;
  void push_wrist(const FtmWristSample& sample) noexcept;

  // All 26 joints at the newest sample time; no allocation. out.active is
  // false until some wrist orientation (dorsum IMU or wrist tracker) exists.
  void estimate(HandPose& out) const noexcept;

  const HandAngles& angles() const noexcept { return angles_; }
  std::array<bool, kHandDofCount> dof_tracked() const noexcept;
  // The thumb CMC's measured pronation-supination (rad, about the metacarpal's
  // long axis): in the thumb's joint poses, not in the 20-DOF angles.
  double thumb_pronation_rad() const noexcept { return thumb_ps_rad_; }
  std::uint32_t imu_flags(FtmImu imu) const noexcept { return imu_flags_[index_of(imu)]; }
  bool mag_disturbed(FtmImu imu) const noexcept { return filters_[index_of(imu)].detector().disturbed(); }
  // The filter's current gyro-bias estimate (rad/s, IMU axes).
  const Vec3& gyro_bias_radps(FtmImu imu) const noexcept { return filters_[index_of(imu)].gyro_bias_radps(); }
  // What the still-start estimate did for this IMU (still_start_gyro_bias).
  enum class TurnOnBias : std::uint8_t { off, pending, estimated, refused, from_calibration };
  TurnOnBias turn_on_gyro_bias(FtmImu imu) const noexcept { return turn_on_state_[index_of(imu)]; }
  // Whether the IMU / bend sensor currently counts (see the header comment).
  bool imu_ok(FtmImu imu) const noexcept;
  bool bend_ok(FtmBend bend) const noexcept;
  TimeNs last_time_ns() const noexcept { return newest_ns_; }
  const FtmCalibration& calibration() const noexcept { return calibration_; }
  const FtmTrackerOptions& options() const noexcept { return options_; }
  void reset() noexcept;

 private:
  FtmTracker(const FtmTrackerOptions& options, const FtmCalibration& calibration, HandModel model,
             std::vector<MahonyFilter> filters);
  bool wrist_ok() const noexcept;
  bool hand_orientation(Quat& q_world_hand, bool& tracked) const noexcept;
  void update_imu_angles() noexcept;  // decodes the IMU DOFs, then refresh_angles()
  void refresh_angles() noexcept;     // followers and synergies from raw_

  FtmTrackerOptions options_;
  FtmCalibration calibration_;
  HandModel model_;
  std::vector<MahonyFilter> filters_;
  std::array<StillBiasAccumulator, kFtmImuCount> still_;
  std::array<TurnOnBias, kFtmImuCount> turn_on_state_{};
  std::array<Quat, kFtmImuCount> q_rest_conj_{};  // HandModel rest frames, conjugated (thumb, index, middle)
  HandAngles raw_{};     // measured DOFs (before synergies and followers)
  HandAngles angles_{};  // what estimate reports
  double thumb_ps_rad_ = 0.0;
  std::array<std::uint32_t, kFtmImuCount> imu_flags_{};
  std::array<TimeNs, kFtmImuCount> imu_good_ns_{};
  std::array<bool, kFtmImuCount> imu_seen_{};
  std::array<Vec3, kFtmImuCount> last_accel_{}, last_gyro_{};
  std::array<TimeNs, kFtmImuCount> unchanged_since_ns_{};
  std::array<TimeNs, kFtmBendCount> bend_good_ns_{};
  std::array<bool, kFtmBendCount> bend_seen_{};
  std::array<bool, kHandDofCount> dof_measured_{};  // ever had a value from its sensor
  Pose wrist_;
  TimeNs wrist_good_ns_ = 0;
  bool wrist_seen_ = false, wrist_valid_now_ = false;
  Quat q_cmc_ = Quat::Identity();  // the thumb metacarpal's full measured rotation (right-hand frames)
  std::array<double, kHandJointCount> radius_m_{};
  Quat last_q_world_hand_ = Quat::Identity();
  bool hand_seen_ = false;
  TimeNs newest_ns_ = 0;
};

}  // namespace proprio::ftm
