#pragma once
// One trial's world in simulated time: the haptic scene of the trial, the
// servo loop (virtual coupling, safety gates, one emulated 3-DOF fingertip
// device per configured finger) ticked once per simulated millisecond, and
// the task's rules (break, respawn, drop, insertion). Nothing sleeps: a
// simulated participant runs as fast as MuJoCo steps.
//
// The study conditions go through the servo loop exactly as with real
// devices: ServoLoopOptions::remove_finger_abduction ("without AA") and
// haptics_enabled ("without haptics": zero device output, same simulation).
#include <memory>
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/haptics/servo_loop.hpp"
#include "proprio/peg_in_hole/config.hpp"
#include "proprio/peg_in_hole/monitor.hpp"
#include "proprio/peg_in_hole/protocol.hpp"

namespace proprio::peg_in_hole {

enum class WorldPhase {
  trial,          // the main task: peg on the table, hole in the plate
  spring,         // familiarisation 1: the peg hangs from a spring
  ground,         // familiarisation 2: lift and rotate from the ground (no hole to finish)
};

struct PegEvent {
  enum class Kind { none, broke, respawned, dropped, inserted } kind = Kind::none;
  TimeNs time_ns = 0;
};

class PegWorld {
 public:
  // device_model: the fingertip device every configured finger wears
  // (emulated in process, through the real wire encoding).
  static Result<std::unique_ptr<PegWorld>> create(const PegInHoleConfig& config, const TrialLayout& layout,
                                                  Setting setting, const HandModel& hand_model,
                                                  std::shared_ptr<const haptics::FingertipDeviceModel> device_model,
                                                  WorldPhase phase = WorldPhase::trial);

  // The tracked hand (what a glove would report now). Applied from the next tick.
  void submit_hand(const Pose& T_world_wrist, const HandAngles& angles);
  // One servo tick (1 ms of simulated time) and the task rules.
  PegEvent step();

  TimeNs now_ns() const noexcept { return now_ns_; }
  double elapsed_s() const noexcept;
  const haptics::ServoSnapshot& snapshot() const noexcept { return snapshot_; }
  Pose peg_pose() const noexcept { return peg_pose_; }
  const TrialLayout& layout() const noexcept { return layout_; }
  const HoleGeometry& hole() const noexcept { return hole_; }
  Setting setting() const noexcept { return setting_; }
  const PegInHoleConfig& config() const noexcept { return config_; }
  WorldPhase phase() const noexcept { return phase_; }

  bool broken() const noexcept { return monitor_.broken(); }
  double filtered_grasp_force_n() const noexcept { return monitor_.filtered_n(); }
  std::array<float, 4> peg_rgba() const noexcept;
  bool inserted() const noexcept { return inserted_; }
  InsertionState insertion() const noexcept { return insertion_; }
  int breaks() const noexcept { return breaks_; }
  int drops() const noexcept { return drops_; }
  int respawns() const noexcept { return respawns_; }
  // Largest fingertip normal force of any tick, and its mean over the ticks a
  // fingertip touched something (N; the simulation's filtered contact force).
  double peak_force_n() const noexcept { return peak_force_n_; }
  double mean_force_n() const noexcept { return contact_ticks_ ? force_sum_ / static_cast<double>(contact_ticks_) : 0.0; }
  haptics::ServoTiming timing() const { return servo_->timing(); }
  haptics::ServoLoop& servo() noexcept { return *servo_; }
  // Each finger's emulated device: the sum of its motors' |current| (A) as
  // the drives' current sense reads it after the latest tick; 0 for fingers
  // without a device. What the FTM's compasses feel (docs/peg-in-hole.md).
  std::array<double, kFingerCount> device_current_a() const noexcept;
  const HandModel& hand_model() const noexcept { return servo_->simulation().hand_model(); }

 private:
  PegWorld(const PegInHoleConfig& config, const TrialLayout& layout, Setting setting, WorldPhase phase);
  void respawn();

  PegInHoleConfig config_;
  TrialLayout layout_;
  Setting setting_;
  WorldPhase phase_;
  HoleGeometry hole_;
  std::unique_ptr<haptics::ServoLoop> servo_;
  std::vector<std::pair<Finger, std::shared_ptr<haptics::EmulatedFingertip>>> devices_;
  haptics::ServoSnapshot snapshot_;
  BreakMonitor monitor_;
  TimeNs now_ns_ = 0, start_ns_ = 0, broken_at_ns_ = 0, idle_since_ns_ = -1;
  Pose peg_pose_;
  // The table top's extent in x and z: its contact plane has no edges, so a
  // peg pushed beyond them is taken as fallen off.
  Vec3 p_table_in_world_ = Vec3::Zero(), table_half_extents_m_ = Vec3::Constant(1e9);
  InsertionState insertion_;
  bool inserted_ = false;
  int breaks_ = 0, drops_ = 0, respawns_ = 0;
  double peak_force_n_ = 0.0, force_sum_ = 0.0;
  std::uint64_t contact_ticks_ = 0;
};

// The device model the sample uses by default: config/haptics/platform_3dof.toml
// (3-DOF, Lee 2021's CHD), or devices.model from the config.
Result<std::shared_ptr<const haptics::FingertipDeviceModel>> load_device_model(const PegInHoleConfig& config);
// The contact simulation the study runs on, simulated or live: the proxy
// fingers' coupling and the solver tolerance from [devices].
haptics::ContactSimOptions contact_sim_options(const PegInHoleConfig& config);
// The servo loop for one setting, simulated or live: AA removed or not,
// haptics on or off, and [devices] force_scale.
haptics::ServoLoopOptions servo_loop_options(const PegInHoleConfig& config, Setting setting);

}  // namespace proprio::peg_in_hole
