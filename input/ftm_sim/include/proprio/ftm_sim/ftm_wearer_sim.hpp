#pragma once
// A simulated wearer of the FTM glove (Lee 2021, ch. 3; issue 27 §1): the
// samples the glove's read-out board and the external wrist tracker deliver,
// with ground truth kept apart (truth_at), for the FTM tracker, its
// calibration and its benchmarks.
//
// A session runs through phases, as a real one would:
//   1. figure_eight: the wrist swings through many orientations (the compass's
//      hard/soft-iron calibration needs them), fingers relaxed;
//   2. pose_flat, pose_thumb_parallel, pose_bend_90: the three known poses of
//      §3.2.3, each reached by a minimum-jerk transition and then held
//      IMPERFECTLY (every joint a few degrees off the instruction, wobbling);
//   3. task: a HandMotionGenerator protocol (free motion or pinch-grasp).
//
// Sensors (ftm_glove.hpp): four MPU-9250 + AK8963 through sim::ImuSimulator
// (200 Hz, compass 100 Hz, raw with hard/soft iron) mid-segment on the dorsal
// side; three capacitive bend sensors (1 kHz) C = C0·(1 + g·θ + n·θ²) + artefact,
// low-passed, noisy; the wrist from an external tracker with jitter, latency
// and dropouts. Magnetic field: the Earth's, the three fingertip haptic
// devices (dipoles whose current follows a contact model unless a haptics
// emulator sets it) and scripted objects approaching the hand (Fig. 4.14).
//
// Every random effect draws from its own stream (mix_seed(seed, stream)), so
// switching one effect off leaves the others' draws unchanged; the same
// options give the same bytes. Numbers marked ASSUMED are our choices.
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/ftm/ftm_glove.hpp"
#include "proprio/sim/hand_motion.hpp"
#include "proprio/sim/imu_sim.hpp"
#include "proprio/sim/magnetic_field.hpp"
#include "proprio/sim/soft_tissue.hpp"

namespace proprio::ftm_sim {

enum class FtmPhase : std::uint8_t { figure_eight, pose_flat, pose_thumb_parallel, pose_bend_90, task };
std::string_view to_string(FtmPhase p) noexcept;

// Phases tile [0, end_ns) without gaps. A pose phase begins with its
// transition; hold_begin_ns is when the wearer has arrived and holds still
// (what a calibration should average; equals begin_ns for other phases).
struct FtmPhaseSpan {
  FtmPhase phase = FtmPhase::task;
  TimeNs begin_ns = 0;
  TimeNs end_ns = 0;
  TimeNs hold_begin_ns = 0;
};

// The simulated person's hand: a subject of subjects.hpp (subject_index >= 0)
// or explicit measurements.
struct FtmSubjectOptions {
  int subject_index = -1;  // 0..sim::kSimSubjectCount-1; -1: use the measurements below
  double hand_length_m = 0.19;
  double hand_width_m = 0.10;
  // When set, this exact hand (e.g. the peg-in-hole participant's, thumb
  // pronation included) instead of the two above or a subject.
  std::optional<HandShape> shape;
};

// The figure-eight and the three calibration poses.
struct FtmCalibrationPhaseOptions {
  bool enabled = true;  // false: the task starts at t = 0 (no figure-eight, no poses)
  double figure_eight_s = 16.0;       // issue: ~15-20 s
  double pose_transition_s = 1.0;     // minimum-jerk move into each pose
  double pose_hold_s = 3.0;           // issue: ~3 s each
  double task_transition_s = 1.0;     // from the last pose into the task's first posture
  // Figure-eight amplitudes (yaw about world up, pitch, roll) and its path.
  // ASSUMED: what a person swinging the hand for a compass calibration covers.
  double figure_eight_yaw_rad = deg_to_rad(80.0);
  double figure_eight_pitch_rad = deg_to_rad(60.0);
  double figure_eight_roll_rad = deg_to_rad(80.0);
  double figure_eight_path_m = 0.12;
  // Imperfect poses: each joint of each pose off the instruction by a
  // Gaussian (truncated at 3σ; clamped to the joint limits, so a straight PIP
  // can only err toward flexion). ASSUMED 4°: "several degrees".
  double pose_error_sigma_rad = deg_to_rad(4.0);
  // Wobble while holding: two sinusoids per joint (0.3-1.1 Hz) of this
  // amplitude, and the wrist's sway. ASSUMED.
  double wobble_amplitude_rad = deg_to_rad(0.8);
  double wrist_wobble_m = 0.002;
  double wrist_wobble_rad = deg_to_rad(0.7);
  bool enable_pose_error = true;
  bool enable_wobble = true;
};

// Distal joints that follow the synergy (DIP = 2/3 PIP, thumb IP = 1/2 MCP)
// only approximately: a residual per task keyframe, moved with the keyframe's
// minimum-jerk transition. Sized so that free motion gives R² ≈ 0.75 (DIP)
// and ≈ 0.65 (thumb IP) of the synergy's prediction (Hrabia et al. 2013:
// index DIP 0.77, thumb 0.59); the tests measure it.
struct FtmSynergyOptions {
  bool enable_residuals = true;
  double dip_residual_sigma_rad = deg_to_rad(10.0);
  double thumb_ip_residual_sigma_rad = deg_to_rad(6.0);
  // Pinch-grasp: the generator's scripted postures already leave the thumb
  // IP far off 1/2 MCP (power grasp: MCP 40°, IP 45°) while the thumb MCP
  // barely varies, so its thumb IP R² is ~0.15 whatever this residual; the
  // DIPs stay in range (measured in ftm_sim_tests).
};

// Soft capacitive bend sensors (StretchSense-class). All values ASSUMED
// (the thesis gives its sensors' fit, θ = β0 + β1·ρ, not their raw numbers).
struct FtmBendOptions {
  double rate_hz = ftm::kFtmBendRateHz;
  double c0_pF = 50.0;                  // at 0 rad
  double gain_per_rad = 0.25;           // +25 % per radian of flexion (12.5 pF/rad at C0)
  double nonlinearity_per_rad2 = -0.012;  // mild: −3 % of the linear term at 90°
  double gain_sigma = 0.10;             // per donning: relative spread of g (how tightly it sits)
  double offset_sigma_pF = 1.5;         // per donning: C0 shift (pre-stretch)
  double noise_sigma_pF = 0.05;         // white, per sample (≈ 0.23° at 12.5 pF/rad)
  double lowpass_tau_s = 0.02;          // silicone + read-out filter
  // Pressing the fingertip on an object loads the tendons and bunches the
  // glove's fabric over the joint: +0.6 pF (≈ 2.7°) at full contact.
  double contact_artefact_pF = 0.6;
  bool enable_donning_spread = true;
  bool enable_noise = true;
  bool enable_lowpass = true;
  bool enable_nonlinearity = true;
  bool enable_contact_artefact = true;
};

// The external wrist tracker (a VIVE tracker in the thesis). ASSUMED numbers
// of the order published for Lighthouse tracking.
struct FtmWristTrackerOptions {
  double rate_hz = 90.0;
  double jitter_sigma_m = 0.0007;               // per axis
  double jitter_sigma_rad = deg_to_rad(0.15);   // per axis
  // A sample stamped t describes the wrist at t − latency: the host stamps
  // arrival, the tracker's fusion and radio delay are unknown to it.
  double latency_s = 0.015;
  double dropout_mean_interval_s = 6.0;  // mean time between losses (occlusion)
  double dropout_mean_duration_s = 0.25;
  bool enable_jitter = true;
  bool enable_latency = true;
  bool enable_dropouts = true;
};

// A magnetic object brought near the hand and taken away (Fig. 4.14).
struct FtmMagneticObject {
  enum class Kind : std::uint8_t { drill, fan, earphone_case };
  Kind kind = Kind::drill;
  TimeNs t_start_ns = 0;  // the approach begins (simulation time)
  DurationNs approach_ns = 2 * kNsPerSecond;
  DurationNs hold_ns = 3 * kNsPerSecond;
  DurationNs retreat_ns = 2 * kNsPerSecond;
  // Where it stops: this far above the back of the hand (the dorsum IMU,
  // along the hand's dorsal axis); it comes from 1 m further out.
  double near_distance_m = 0.08;
  // true: the script runs in the hand's frame, so the object stays near the
  // moving hand (someone holds it there). false: it stops at a fixed world
  // point, where the dorsum is at the middle of the hold; the hand may move away.
  bool follow_hand = true;
  double current_A = 1.0;  // running motor (drill, fan); ignored for the case
};
std::string_view to_string(FtmMagneticObject::Kind k) noexcept;

struct FtmMagneticOptions {
  sim::EarthFieldOptions earth;
  bool enable_fingertip_devices = true;
  sim::HapticDeviceDipoleOptions device;  // sized by the thesis's 10 mm rule
  // Built-in contact model (pinch_grasp only): the device's motors push while
  // its fingertip holds an object, at device.full_current_A.
  bool enable_contact_current = true;
  // The devices' supply leads along the fingers (sim::CurrentLeadPair, the
  // device's current; ASSUMED geometry there). Off by default: the 10 mm-rule
  // dipole alone, as wave 1 measured; the peg-in-hole glove turns it on.
  bool enable_device_leads = false;
  Vec3 lead_offset_m = Vec3(0.006, 0.006, 0.0);  // off each joint's origin (+X lateral, +Y dorsal)
  double lead_separation_m = 0.001;
  bool enable_objects = true;
  std::vector<FtmMagneticObject> objects;  // none by default; see figure_4_14_objects()
  // A compass sample counts as disturbed when the dipoles turn the field at
  // the IMU by more than disturbed_angle_rad or change its magnitude by more
  // than disturbed_magnitude_fraction of the Earth field. Why these: 2° is
  // the size of heading error the 3° target cares about; 3 % is three
  // times the ~1 % a hard/soft-iron calibration leaves, so a detector can tell it.
  double disturbed_angle_rad = deg_to_rad(2.0);
  double disturbed_magnitude_fraction = 0.03;

  // Drill, fan and earphone case, one after the other, 12 s apart, from first_ns.
  static std::vector<FtmMagneticObject> figure_4_14_objects(TimeNs first_ns);
};

struct FtmWearerOptions {
  Handedness hand = Handedness::right;
  std::uint64_t seed = 1;
  FtmSubjectOptions subject;
  sim::MotionProtocol protocol = sim::MotionProtocol::free_motion;  // free_motion or pinch_grasp
  double task_s = 30.0;
  // Driven task: the task phase is whatever drive() feeds (a closed-loop
  // simulated participant, e.g. the peg-in-hole study's), not the motion
  // protocol, and no synergy residuals are added (the driver's distal angles
  // are the truth). The calibration phases run as usual first; task_s may
  // then be up to a day (a whole simulated study session).
  bool driven_task = false;
  sim::ImuNoiseOptions imu = default_imu();
  FtmBendOptions bend;
  FtmWristTrackerOptions wrist;
  FtmMagneticOptions magnetic;
  FtmCalibrationPhaseOptions calibration;
  FtmSynergyOptions synergy;
  // The IMUs sit on skin (sim/soft_tissue.hpp): sliding with the joints,
  // wobble, slip. A driven task has no motion ahead of now to drive the wobble
  // with, so there it has sliding and slip only. rigid() for mounts fixed to the bones.
  sim::SoftTissueOptions soft_tissue;

  // MPU-9250 defaults of ImuNoiseOptions at the board's 200 Hz, compass on, raw output.
  static sim::ImuNoiseOptions default_imu();
  // Errc::invalid_argument naming the field ("bend.rate_hz", ...).
  Status validate() const;
  std::string describe() const;
};

class FtmWearerSimulator final : public ftm::FtmSampleFeed {
 public:
  static Result<std::unique_ptr<FtmWearerSimulator>> create(FtmWearerOptions options);

  // Every sample with time_ns <= min(t_ns, end_ns()) not delivered before, in
  // time order (ties: IMUs by index, then bend sensors, then the wrist).
  void advance(TimeNs t_ns, std::vector<ftm::FtmEvent>& out) override;

  std::span<const FtmPhaseSpan> phases() const noexcept { return phases_; }
  TimeNs end_ns() const noexcept { return end_ns_; }
  TimeNs task_begin_ns() const noexcept { return task_begin_ns_; }
  FtmPhase phase_at(TimeNs t) const;

  struct Truth {
    TimeNs time_ns = 0;
    HandAngles angles{};
    HandPose pose;
    FtmPhase phase = FtmPhase::task;
    std::array<double, ftm::kFtmImuCount> mag_disturbance_uT{};  // |dipoles' field| at each IMU
    std::array<bool, ftm::kFtmImuCount> mag_disturbed{};  // FtmMagneticOptions' definition
    // How far the dipoles turn the field's horizontal part at each IMU (rad,
    // about world up, +Y): the heading error a compass would take from them.
    std::array<double, ftm::kFtmImuCount> mag_heading_deviation_rad{};
    // |‖field‖ - ‖earth‖| / ‖earth‖ and |dip - earth's dip| (rad) at each
    // IMU: what a VQF-style detector looks at, without noise or tilt error.
    std::array<double, ftm::kFtmImuCount> mag_norm_deviation{};
    std::array<double, ftm::kFtmImuCount> mag_dip_deviation_rad{};
    std::array<double, 3> fingertip_current_A{};  // thumb, index, middle devices
    std::array<double, 3> contact{};              // contact model level in [0, 1]
  };
  // Ground truth at any t (deterministic in t; the tracker never sees it).
  Truth truth_at(TimeNs t) const;
  HandAngles angles_at(TimeNs t) const;
  HandPose pose_at(TimeNs t) const;

  // The angles each calibration pose instructs (pose phases only).
  HandAngles instructed_angles(FtmPhase pose) const;
  // What the wearer actually held, before wobble (pose phases only).
  HandAngles held_angles(FtmPhase pose) const;

  // A haptics emulator's measured motor current for the device on f (thumb,
  // index or middle) from from_ns on; overrides the built-in contact model
  // from then on. Ignored (no device) with enable_fingertip_devices off. The
  // bend sensors' contact artefact keeps following the contact model (it is
  // the finger pressing, not the motor). Call it before advance() reaches
  // from_ns: compass samples already delivered are not redone.
  void set_fingertip_current(Finger f, TimeNs from_ns, double amperes);

  // Driven task (options().driven_task): the true hand at t_ns (>= the
  // previous call's t_ns; >= task_begin_ns()). Between calls the hand moves
  // linearly (angles) and by interpolate() (wrist); after the last call it
  // holds. advance(T) generates the IMU tick whose nominal time is up to half
  // a period (2.5 ms) past T, its samples lie up to 0.45 period (2.25 ms)
  // off nominal, and the IMU simulator differentiates the pose over ±1 ms:
  // 5.75 ms in all. So a caller must drive at least kDrivenLeadNs ahead of
  // the time it advance()s to, and a closed-loop driver sees the glove's
  // samples that much later than it moves (a real glove's transport delay
  // is of the same order).
  static constexpr DurationNs kDrivenLeadNs = 6 * kNsPerMillisecond;
  void drive(TimeNs t_ns, const Pose& T_world_wrist, const HandAngles& angles);
  TimeNs driven_until_ns() const noexcept { return driven_.empty() ? -1 : driven_.back().t; }

  const sim::ImuSimulator& imus() const { return *imu_sim_; }
  const sim::MagneticEnvironment& magnetic_environment() const { return *env_; }
  const HandModel& model() const noexcept { return model_; }
  const FtmWearerOptions& options() const noexcept { return options_; }
  // Per-donning bend sensor constants actually drawn: C0 (pF) and gain (1/rad).
  std::array<double, ftm::kFtmBendCount> bend_c0_pF() const noexcept { return bend_c0_; }
  std::array<double, ftm::kFtmBendCount> bend_gain_per_rad() const noexcept { return bend_gain_; }
  // The noise-free, unfiltered capacitance the bend sensor model gives at t.
  double bend_capacitance_truth_pF(ftm::FtmBend b, TimeNs t) const;
  std::string describe() const;

  FtmWearerSimulator(const FtmWearerSimulator&) = delete;
  FtmWearerSimulator& operator=(const FtmWearerSimulator&) = delete;

 private:
  explicit FtmWearerSimulator(FtmWearerOptions options, HandModel model);
  Status init();
  double contact_level(std::size_t device, TimeNs t) const;  // device 0 thumb, 1 index, 2 middle
  Pose wrist_at(TimeNs t, HandAngles& angles) const;  // memoised compute_wrist_at
  Pose compute_wrist_at(TimeNs t, HandAngles& angles) const;
  double bend_capacitance_of(ftm::FtmBend b, double theta_rad, TimeNs t) const;
  std::array<double, 5> residual_of_keyframe(std::size_t k) const;
  void generate_until(TimeNs t_ns);

  FtmWearerOptions options_;
  HandModel model_;
  mutable sim::HandMotionGenerator motion_;
  Pose T_world_wrist_rest_;
  HandAngles relaxed_{};
  std::array<HandAngles, 3> instructed_{};
  std::array<HandAngles, 3> held_{};
  std::array<double, 40> wobble_phase_{};
  std::array<double, 4> figure_eight_phase_{};
  std::vector<FtmPhaseSpan> phases_;
  TimeNs task_begin_ns_ = 0;
  TimeNs end_ns_ = 0;

  std::shared_ptr<sim::MagneticEnvironment> env_;
  std::array<std::optional<std::size_t>, 3> device_dipole_{};
  std::optional<sim::ImuSimulator> imu_sim_;
  std::optional<sim::SoftTissue> soft_tissue_;

  std::array<double, ftm::kFtmBendCount> bend_c0_{};
  std::array<double, ftm::kFtmBendCount> bend_gain_{};
  std::array<double, ftm::kFtmBendCount> bend_state_pF_{};
  std::array<Rng, ftm::kFtmBendCount> bend_noise_rng_{Rng(0), Rng(0), Rng(0)};
  std::int64_t bend_tick_ = 0;
  bool bend_started_ = false;

  Rng wrist_jitter_rng_{0};
  Rng wrist_dropout_rng_{0};
  std::int64_t wrist_tick_ = 0;
  bool wrist_dropped_ = false;
  Pose wrist_last_;

  std::vector<ftm::FtmEvent> pending_;

  struct DrivenSample {
    TimeNs t = 0;
    Pose wrist;
    HandAngles angles{};
  };
  // Recent driven samples only (older than 2 s before the newest are
  // dropped: the wrist tracker's latency is the furthest anyone looks back).
  std::vector<DrivenSample> driven_;
  std::size_t driven_begin_ = 0;
  Pose driven_at(TimeNs t, HandAngles& a) const;

  struct MemoEntry {
    TimeNs t = 0;
    bool valid = false;
    HandAngles angles{};
    Pose wrist;
  };
  mutable std::array<MemoEntry, 32> memo_{};
  mutable std::size_t memo_next_ = 0;
};

}  // namespace proprio::ftm_sim
