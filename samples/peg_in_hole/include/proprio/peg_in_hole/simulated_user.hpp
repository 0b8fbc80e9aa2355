#pragma once
// A simulated participant for headless runs: a scripted fingertip
// manipulation policy (reach, pinch-grasp, lift, orient, insert) with
// human-like motor noise.
//
// It acts ONLY through the tracked hand (wrist pose + joint angles, what a
// glove reports) and perceives ONLY what a participant could: by eye the
// rendered (proxy) hand, the peg's pose and colour (white -> blue with grasp
// force, red when broken) and the hole; by touch the force its fingertip
// devices render (zero when haptics are off). It is never told the setting:
// it notices "no touch" when it sees contact but feels nothing, and it
// suffers from "no AA" only through the physics (its planned finger spread
// is removed before coupling, so its fingers land elsewhere and the peg
// tilts in the grasp, which it must then correct by eye).
#include <array>
#include <cstdint>
#include <string_view>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/time.hpp"
#include "proprio/peg_in_hole/config.hpp"
#include "proprio/peg_in_hole/monitor.hpp"

namespace proprio::peg_in_hole {

// The simulated participant's hand: HandShape::from_measurements with the
// thumb pronated by o.thumb_pronation_deg. The study runs its proxy hand on
// the same shape.
Result<HandShape> simulated_participant_hand(const SimUserOptions& o);

struct Percept {
  TimeNs time_ns = 0;
  // Vision (exact here; the user adds its own perceptual noise).
  Pose T_world_peg;
  std::array<float, 4> peg_rgba{1, 1, 1, 1};
  Pose T_world_proxy_wrist;
  std::array<Vec3, kFingerCount> p_proxy_tip_in_world{};
  HoleGeometry hole;
  // Touch: the force each finger's device renders (normal, shear magnitude).
  std::array<double, kFingerCount> felt_normal_n{};
  std::array<double, kFingerCount> felt_shear_n{};
};

struct HandCommand {
  Pose T_world_wrist;
  HandAngles angles{};
};

class SimulatedUser {
 public:
  SimulatedUser(const PegInHoleConfig& config, HandModel own_hand, std::uint64_t seed);

  // A new trial (or familiarisation phase): the hand starts at rest here.
  void begin(TimeNs now_ns, const Pose& T_world_wrist_rest);
  // One tick: what the glove reports now.
  HandCommand act(const Percept& percept);
  // Familiarisation 1 (spring): touch and grasp, no lifting or inserting.
  void set_grasp_only(bool on) noexcept { grasp_only_ = on; }

  std::string_view phase_name() const noexcept;
  double closure() const noexcept { return s_; }
  int regrasps() const noexcept { return regrasps_; }
  // Why the hand last let go (broken, slipped, missed, tipped, closed on nothing).
  std::string_view release_reason() const noexcept { return release_reason_; }
  // What the user has learnt (kept across trials): its grip target with
  // touch and its feed-forward closure without.
  double grip_target_n() const noexcept { return grip_target_n_; }
  double feedforward_closure() const noexcept { return feedforward_; }
  // Grip newtons per felt device newton, as learnt so far.
  double felt_gain() const noexcept { return felt_gain_; }

  // The planned grasp posture at closure s (0 open .. ~2 closed), with the
  // planned ab/adduction.
  HandAngles posture(double s) const;

 private:
  enum class Phase { reach, approach, touch, close, lift, rotate, align, insert, done, release, wait_respawn };
  void plan_grasp(const Pose& T_world_peg_seen);
  void start_move(const Pose& to, double duration_s);
  bool move_done(double extra_s = 0.0) const noexcept { return move_elapsed_s_ >= move_duration_s_ + extra_s; }
  void pace_held_move(const Percept& p, double dt);
  Pose seen_peg(const Percept& p);
  double felt_peak(const Percept& p) const;  // the largest felt normal force
  double seen_force(const Percept& p);
  bool contact_felt(const Percept& p) const;
  double wanted_grip_n(const Percept& p) const;
  // A closure change, from one look at the colour.
  double closure_correction(double seen_n, double wanted_n) const;
  // One tick of grip control; true while the grip is where the user wants it.
  // look_interval_scale < 1: the colour is watched more closely than every
  // visual reaction time (while taking the weight).
  bool regulate_grip(const Percept& p, double dt, double look_interval_scale = 1.0);
  void go(Phase next);
  void release_because(const char* reason);
  double caution() const noexcept;

  PegInHoleConfig config_;
  SimUserOptions o_;
  HandModel hand_;
  Rng rng_;
  Phase phase_ = Phase::reach;
  TimeNs now_ = 0, phase_start_ = 0, last_ = 0;
  bool grasp_only_ = false;
  bool loading_ = false;
  const char* release_reason_ = "";

  // Plan.
  double s_contact_ = 1.0, s_open_ = 0.2, s_ = 0.2;
  // Closure added to s_ for index and middle: each finger aimed at its own
  // contact (plan_grasp).
  std::array<double, 2> finger_closure_offset_{};
  Pose T_grasp_, T_standoff_, T_pre_, T_rest_;
  Vec3 p_grasp_in_world_ = Vec3::Zero();
  // The guarded move: along the pinch axis until the thumb touches; the hand
  // stops a reaction time after the contact is felt or seen.
  Vec3 pinch_axis_in_world_ = Vec3::UnitX();
  TimeNs guard_stop_at_ = -1;
  double guard_travel_m_ = 0.0;
  // What the user judges alignment by: the peg's pose as seen, averaged over
  // a fraction of a second (a peg swinging in the grasp is judged by where it
  // hangs, not chased swing by swing).
  Vec3 steady_peg_axis_ = Vec3::UnitY(), steady_peg_p_ = Vec3::Zero();
  // Current commanded trajectory (min-jerk between two wrist poses).
  Pose move_from_, move_to_, cmd_;
  double move_duration_s_ = 0.0;
  // How far along the movement is, in its own time: a held peg's movement is
  // paced by how hard the grip presses (pace_held_move), so this runs slower
  // than the clock, or stops, while the grip is near the break.
  double move_elapsed_s_ = 0.0;
  double move_rate_ = 1.0;
  // Motor noise state (Ornstein-Uhlenbeck): wrist position, wrist rotation, fingers.
  Vec3 noise_p_ = Vec3::Zero(), noise_r_ = Vec3::Zero();
  std::array<double, kHandDofCount> noise_q_{};
  Vec3 percept_p_err_ = Vec3::Zero(), percept_r_err_ = Vec3::Zero();
  // Grip.
  double grip_target_n_, feedforward_;
  bool touch_noticed_ = false, touch_missing_ = false, last_visual_ok_ = false;
  TimeNs next_visual_check_ = 0, stable_since_ = -1;
  double last_seen_n_ = 0.0;  // the force last read off the peg's colour
  // Newtons of grip (as the colour shows them) per felt device newton: the
  // user learns it by matching colour and touch (the thesis's familiarisation
  // exists for this). Starts naive at 1.
  double felt_gain_ = 1.0;
  double felt_err_ = 0.0;  // the felt force's error of the moment (device newtons)
  double ff_closure_this_grasp_ = 0.0;
  double contact_s_ = -1.0;
  int regrasps_ = 0, align_iterations_ = 0;
  double insert_progress_m_ = 0.0;
  double insert_depth0_ = 2.0;  // the peg's depth when pushing began (> 1: not yet seen)
  Vec3 insert_origin_ = Vec3::Zero();
};

}  // namespace proprio::peg_in_hole
