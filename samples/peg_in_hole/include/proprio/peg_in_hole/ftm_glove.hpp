#pragma once
// The simulated participant wearing the FTM glove (issue 27; Lee 2021's
// glove, the one the thesis's peg-in-hole study used): `--tracker ftm`.
//
// One glove per participant, donned once: a simulated FTM wearer
// (ftm_sim::FtmWearerSimulator, driven task) with the participant's own hand,
// calibrated through the real calibration (figure-eight and three imperfect
// poses, ftm_sim::calibrate_from_wearer), then driven tick by tick by the
// participant's HandCommand (the TRUE hand). The FTM tracker's estimate is
// what the study's world gets. Each fingertip device's motor current (the
// emulated drives' current sense) goes to the wearer's device dipoles, so the
// compasses are disturbed exactly when the devices push.
//
// Timing: the wearer's time runs on across trials; each trial is mapped onto
// it after a one-second minimum-jerk move from where the last trial left the
// hand to where the next begins (the participant putting the hand back at
// rest), which the tracker also sees. The tracker consumes samples up to
// ftm_sim::FtmWearerSimulator::kDrivenLeadNs (6 ms) behind the participant's
// command, so the tracked hand lags the true one by that much plus the wrist
// tracker's 15 ms latency and the filters' own lag.
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/peg_in_hole/simulated_user.hpp"

namespace proprio::peg_in_hole {

inline constexpr std::size_t kFtmCompassCount = 4;  // dorsum, thumb metacarpal, index and middle proximal

// What a trial did to the FTM (CSV columns, docs/peg-in-hole.md).
struct FtmTrialFigures {
  // Largest |field of the devices (and leads)| at each IMU over the trial, µT (simulator truth).
  std::array<double, kFtmCompassCount> max_disturbance_uT{};
  // Fraction of the trial's compass samples the tracker's detector flagged, per IMU.
  std::array<double, kFtmCompassCount> flagged_fraction{};
  // Fraction of the trial's samples the simulator counts as disturbed (field
  // turned > 2° or magnitude off > 3 %; ftm_sim::FtmMagneticOptions).
  std::array<double, kFtmCompassCount> disturbed_fraction{};
  std::array<double, 3> max_current_a{};  // thumb, index, middle device (sum of motors)
  // Tracked against true hand over the trial: mean |Δangle| over the tracked
  // DOFs (deg) and mean wrist position error (mm).
  double mean_angle_error_deg = 0.0;
  double mean_wrist_error_mm = 0.0;
  // Mean wrist orientation error (deg), tracked against true; not a CSV column.
  double mean_wrist_angle_error_deg = 0.0;
  // Mean of the wrist orientation error as a rotation vector in the true
  // wrist frame (x, y, z; deg): a steady offset shows here, noise averages out.
  std::array<double, 3> mean_wrist_rotation_error_in_wrist_deg{};
  std::uint64_t samples = 0;  // truth samples (one per 5 ms)
};

// DIAGNOSTIC ONLY (why trials fail with the FTM; docs/peg-in-hole.md): replace
// one part of the tracked hand the world gets by the participant's true
// (smoothed) hand, or the whole of it by the true hand delayed. The tracker
// still runs and the error figures still describe its own estimate; a study
// run with anything but `none` does not simulate the FTM.
enum class FtmGloveAblation : std::uint8_t {
  none,                  // the tracker's estimate (the FTM as simulated)
  truth,                 // the true hand (everything replaced: the wiring's control)
  truth_angles,          // all 20 angles true, the tracker's wrist
  truth_wrist,           // the true wrist pose, the tracker's angles
  truth_wrist_position,  // the true wrist position, the tracker's wrist orientation
  truth_wrist_rotation,  // the true wrist orientation, the tracker's wrist position
  truth_thumb,           // the thumb's four angles true
  truth_index_middle,    // index and middle's eight angles true
  truth_ring_little,     // ring and little's eight angles true
  truth_distal,          // the thumb IP and the four DIPs true
  truth_delayed_30ms,    // the true hand 30 ms late (the tracker's lag alone)
  true_mountings,        // the tracker's estimate, its calibration's IMU mountings replaced by the true ones
};
const char* to_string(FtmGloveAblation a) noexcept;
Result<FtmGloveAblation> parse_ftm_glove_ablation(std::string_view name);

struct SimulatedFtmGloveOptions {
  std::uint64_t seed = 1;
  double between_trials_s = 1.0;  // the hand's move back to rest between trials
  // The devices' supply leads along the fingers as well as their dipoles
  // (ftm_sim::FtmMagneticOptions::enable_device_leads): the dipoles alone
  // give ~0.01 µT at the compasses, the leads ~1 µT (docs/peg-in-hole.md).
  bool device_leads = true;
  FtmGloveAblation ablate = FtmGloveAblation::none;  // DIAGNOSTIC ONLY (see the enum)
  Status validate() const;
  std::string describe() const;
};

class SimulatedFtmGlove {
 public:
  // Dons and calibrates the glove on `participant_hand` (costs the
  // calibration phases' ~29 simulated seconds).
  static Result<std::unique_ptr<SimulatedFtmGlove>> create(const HandShape& participant_hand,
                                                           const SimulatedFtmGloveOptions& options);
  ~SimulatedFtmGlove();

  // A new trial whose world time starts at 0 with the hand at `first`.
  // track_abduction false: the thesis's "without AA".
  Status begin_trial(const HandCommand& first, bool track_abduction);
  // One world tick at world_t_ns: the true hand in, the tracked hand out.
  HandCommand track(TimeNs world_t_ns, const HandCommand& truth);
  // The devices' currents at world_t_ns (after the world's tick), A per finger.
  void set_device_currents(TimeNs world_t_ns, const std::array<double, kFingerCount>& current_a);
  FtmTrialFigures end_trial();

  std::string describe() const;

 private:
  struct Impl;
  explicit SimulatedFtmGlove(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace proprio::peg_in_hole
