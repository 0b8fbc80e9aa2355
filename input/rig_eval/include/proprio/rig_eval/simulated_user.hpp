#pragma once
// A scripted person posing a PosingDevice to match an on-screen target pose,
// with either joint design of thesis §3.2.1 (joint_kinematics.hpp). The same
// perception, planning and motor model drives both designs; only what one
// grasp of a joint can do differs:
//
//  * cardan_twist (ours): the hand holds the outlet module and moves it as a
//    whole. The outlet direction travels along the geodesic (great circle) to
//    where the person wants it, and the wrist turns the outlet about its shaft
//    (the free twist rings follow) at the same time: one movement per attempt.
//  * twist_bend_twist (Jacobson et al. 2014): the hinge only bends in the plane
//    that twist_a sets, so the person turns one dial at a time. Not knowing the
//    Euler decomposition, they work by what they see: turn twist_a until the
//    bone's bend plane looks aligned with the target bone (only possible once
//    the bone is visibly bent: a straight bone shows no plane, so they bend
//    first, to whichever side the hinge happens to face), bend until the angle
//    looks right, turn twist_b until the child bones / marker look right,
//    repeat. Each dial is its own grip (a finger re-grip between dials), and
//    twist_a swings the bent outlet along a circle about the inlet shaft (and
//    spins the outlet, so twist_b must follow): the zig-zag of Fig. 3.4.
//
// Perception (the rendered character seen from one fixed camera). For each
// joint the person compares its bone with the target overlay's bone: the
// error is split into a component that moves the bone tip within the image
// plane and one that tilts it in depth. Each is seen with its own threshold
// (image: 2 deg, a line orientation against a superimposed reference is
// discriminated to about 1-2 deg, we take the upper end for a small rendered
// figure; depth: 8 deg, a monocular view shows depth tilts only through
// foreshortening and shading, with a length Weber fraction of ~4 % that is
// 4 deg for a bone 30 deg out of the image plane and ~16 deg for one lying
// in it). A component below its threshold is not seen at all; one above it is
// seen with Weber-like noise (10 % of the error plus a quarter threshold).
// Twist about a bone shows only by how far its descendants (or the marker)
// sit off its axis, so its threshold is the swing threshold divided by that
// lever (sin of the angle off the axis). The person's target for the joint is
// where they perceive the target bone, in the world (on screen), so errors of
// the parent carry into the child as they would for a person.
//
// Motor model. Every movement starts after a reaction time (0.25 s), follows
// a minimum-jerk profile whose peak angular speed is at most the person's
// (150 deg/s turning a joint by hand: careful positioning, well below the
// 300-500 deg/s of fast wrist turns), lasts at least 0.3 s, and ends with
// signal-dependent noise (Harris & Wolpert 1998): SD 0.5 deg + 7 % of the
// rotation, per axis. A twist is turned at most 90 deg per grip (the wrist's
// comfortable range); beyond that the person re-grips and continues.
// Looking at a joint (a fixation) takes 0.3 s; releasing one joint and
// grasping another takes 1 s (reach and grasp); switching between the dials
// of one joint takes 0.5 s. One hand manipulates, the other holds the parent
// module steady; the holding hand moves with every re-grasp, which is the
// re-grasp time.
//
// Plan. Joints are worked on proximal to distal (parents first, as their
// error moves everything below them). A visit to a joint makes at most
// `max_attempts_per_visit` look-and-correct attempts, then moves on. A pass
// over all joints in which nothing looked wrong ends the trial ("good
// enough"), as does the time limit.
#include <cstdint>
#include <string>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/rig_device/joint_kinematics.hpp"
#include "proprio/rig_eval/posing_device.hpp"

namespace proprio::rig_eval {

enum class JointDesign {
  cardan_twist,      // ours: Cardan joint + two twist rings
  twist_bend_twist,  // Jacobson et al. 2014
};
const char* to_string(JointDesign design);

// The population's typical person; participants scatter around it.
struct UserModelOptions {
  double image_threshold_deg = 2.0;
  double depth_threshold_deg = 8.0;
  double perception_weber_fraction = 0.10;
  double perception_floor_thresholds = 0.25;  // noise SD at zero error, in thresholds
  double fixation_s = 0.30;
  double reaction_time_s = 0.25;
  double regrasp_s = 1.0;
  double dial_switch_s = 0.5;
  double min_movement_s = 0.3;
  double peak_speed_deg_s = 150.0;
  double max_turn_per_grip_deg = 90.0;
  double motor_noise_floor_deg = 0.5;
  double motor_noise_fraction = 0.07;
  int max_attempts_per_visit = 3;
  // Each participant multiplies the thresholds, the motor noise, the speed and
  // the times by their own log-normal factors with this SD (0: all alike).
  double participant_spread = 0.2;

  Status validate() const;
  std::string describe() const;
};

// One person, in SI units (rad, s).
struct SimulatedUser {
  double image_threshold_rad = 0.0;
  double depth_threshold_rad = 0.0;
  double perception_weber_fraction = 0.0;
  double perception_floor_thresholds = 0.0;
  double fixation_s = 0.0;
  double reaction_time_s = 0.0;
  double regrasp_s = 0.0;
  double dial_switch_s = 0.0;
  double min_movement_s = 0.0;
  double peak_speed_rad_s = 0.0;
  double max_turn_per_grip_rad = 0.0;
  double motor_noise_floor_rad = 0.0;
  double motor_noise_fraction = 0.0;
  int max_attempts_per_visit = 1;
};

SimulatedUser typical_user(const UserModelOptions& options);
SimulatedUser draw_participant(const UserModelOptions& options, Rng& rng);

struct TrialOptions {
  double time_limit_s = 600.0;
  double sample_dt_s = 0.05;  // how finely the error is recorded during movements
  bool record_paths = false;  // keep every joint's outlet direction over time
  Status validate() const;
};

struct ErrorSample {
  double t_s = 0.0;
  double error_m = 0.0;
};

// A joint's outlet direction in its inlet frame (unit), while it is moved.
struct OutletPathSample {
  double t_s = 0.0;
  int joint = 0;
  Vec3 d_in_inlet = Vec3::UnitZ();
};

struct TrialResult {
  JointDesign design = JointDesign::cardan_twist;
  double initial_error_m = 0.0;
  // Piecewise linear in time, from t = 0 to stop_time_s, times non-decreasing.
  std::vector<ErrorSample> error;
  JointRotations final_pose;
  double stop_time_s = 0.0;
  bool timed_out = false;  // stopped by the time limit, not satisfied
  int looks = 0;
  int movements = 0;
  int regrasps = 0;
  std::vector<OutletPathSample> path;  // record_paths only; one sample at each movement's start too
};

// Poses `device` from `start` (straight when empty) towards `target`. The
// user never sees `target` except through its perception model.
TrialResult simulate_trial(const PosingDevice& device, JointDesign design, const JointRotations& target,
                           const SimulatedUser& user, const TrialOptions& options, Rng& rng,
                           const JointRotations& start = {});

// Angle travelled by one joint's outlet direction along a recorded path, rad.
double outlet_path_length_rad(const std::vector<OutletPathSample>& path, int joint);

}  // namespace proprio::rig_eval
