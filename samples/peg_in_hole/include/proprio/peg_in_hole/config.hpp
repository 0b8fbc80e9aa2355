#pragma once
// The peg-in-hole study's configuration (Lee 2021 §3.3.3, Fig. 3.7/3.8).
// Defaults are the published values; everything is configurable from TOML
// (format: docs/peg-in-hole.md). SI units throughout, keys carry the unit.
#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"

namespace proprio::peg_in_hole {

struct PegOptions {
  // "a round bottle": 186.2 mm tall, radius 25.84 mm, 500 g.
  double radius_m = 0.02584;
  double length_m = 0.1862;
  double mass_kg = 0.5;
  // Fingertip on the bottle. The thesis gives none; 1.0 is MuJoCo's default
  // and within what skin on plastic measures (about 0.5-1.5). The thumb
  // carries the reaction of both fingers, so a lift needs mass*g/(2*mu) =
  // 2.45 N at the thumb against the 5 N break: a window of 2.5 N, 1.9 N at 0.8.
  double friction = 1.0;
  // Breaks when the filtered fingertip contact force reaches this (>=).
  double break_force_n = 5.0;
  // First-order low-pass on the largest fingertip normal force before the
  // break test: MuJoCo's contact forces spike for a step or two when a finger
  // lands, which a real bottle would not notice. The thesis gives no value.
  double break_filter_time_constant_s = 0.02;
  // Colour: white at 0 N to blue at colour_scale_max_n ("0 <= |lambda_N| <= 10 N").
  double colour_scale_max_n = 10.0;
  // A broken peg shows its broken colour this long, then respawns at the start.
  double respawn_delay_s = 0.5;
  // A peg that falls off the table or tips over is put back by the
  // experimenter (the clock keeps running). Not in the thesis; see the docs.
  bool respawn_dropped = true;
};

struct HoleOptions {
  double clearance_m = 0.002;        // radial
  double plate_thickness_m = 0.06;
  double insertion_depth_m = 0.03;   // the peg's leading end this far past the plate's front face = done
};

// Where things are at the start of a trial: nominal positions plus a uniform
// random offset in [-range, +range] per axis ("randomly (yet not too much)").
struct LayoutOptions {
  double table_height_m = 0.85;
  Vec3 peg_start_m = Vec3(0.0, 0.85, -0.40);  // the peg's base centre, standing upright
  Vec3 peg_start_range_m = Vec3(0.04, 0.0, 0.03);
  Vec3 hole_m = Vec3(0.25, 1.0, -0.45);       // the hole's centre on the plate's front face (axis along +x)
  Vec3 hole_range_m = Vec3(0.0, 0.04, 0.04);
};

struct FamiliarisationOptions {
  double spring_phase_s = 180.0;  // touch and grasp a peg hanging on a spring
  double ground_phase_s = 180.0;  // lift and rotate it from the ground
  Vec3 spring_anchor_m = Vec3(0.0, 1.15, -0.40);  // the peg top hangs here: ~9 cm above the table
  double spring_stiffness_n_per_m = 200.0;
  double spring_damping_ns_per_m = 5.0;
};

struct MainTaskOptions {
  int repetitions = 5;             // of the four settings, each round in random order
  int familiarisation_trials = 4;  // the first round counts as familiarisation
  double trial_timeout_s = 120.0;  // a trial not done by then is recorded as timed out
};

struct DeviceOptions {
  std::vector<Finger> fingers{Finger::thumb, Finger::index, Finger::middle};
  std::filesystem::path model;  // empty: config/haptics/platform_3dof.toml (3-DOF)
  // Virtual coupling of the proxy's finger joints (haptics::CouplingOptions).
  // The haptics default (0.5 N m/rad) gives about 1 N of pinch at full finger
  // closure, less than the ~2.5 N at the thumb that lifting 500 g at friction 1
  // takes; 2.5 N m/rad puts 3-5 N within the fingers' range of motion (peg
  // probe, docs/peg-in-hole.md). Damping stays critical.
  double finger_joint_stiffness_nm_per_rad = 2.5;
  // Rendered force per simulated newton (haptics::ServoLoopOptions::
  // force_scale). 0.3 maps the 5 N break onto the 3-DOF platform's 1.5 N: at
  // 1 every grip above 1.5 N feels the same, and touch cannot warn of a break.
  double force_scale = 0.3;
  // The contact solver's relative tolerance (haptics::ContactSimOptions::
  // solver_tolerance): 1e-5 instead of MuJoCo's 1e-8 makes a simulated study
  // about a fifth faster and changes no force a device could render.
  double solver_tolerance = 1e-5;
  // Fingertip contacts resist spin about their normal (haptics::
  // ContactSimOptions::torsional_friction). Off: point contacts with Coulomb
  // friction, the 3-DOF force the devices render. The pads' contact patches
  // still hold the peg against spin, and a wider finger spread (AA) should
  // hold it better, as in a real pinch; docs/peg-in-hole.md (item 12) has
  // what two runs measured.
  bool torsional_friction = false;
  // Physics substeps per 1 ms control period of each emulated device's motors
  // (devices::FingertipEmulatorOptions::physics_substeps, 20 by default). 4
  // (250 µs) still resolves the motors' ~2.5 ms electromechanical time
  // constant, and a simulated study spends 6% fewer instructions (callgrind).
  // Real devices ignore it.
  int emulator_substeps = 4;
};

struct RecordingOptions {
  bool enabled = true;
  // Hand and peg poses per second. A tracked + proxy HandPose pair is ~3.4 kB,
  // so 100 Hz costs ~34 kB per trial second; 30 Hz keeps a 200-trial study
  // in the hundreds of MB.
  double rate_hz = 30.0;
};

// The simulated participant (docs/peg-in-hole.md, "Simulated user").
struct SimUserOptions {
  double hand_length_m = 0.19, hand_width_m = 0.09;
  double reach_speed_mps = 0.35;       // mean wrist speed of a reach (min-jerk profile)
  double lift_height_m = 0.10;         // above the table, before rotating
  double rotate_duration_s = 0.9;
  double insert_speed_mps = 0.04;
  // Motor noise: wrist position noise grows with speed (signal-dependent),
  // plus a slow drift (physiological tremor is far smaller than this).
  double position_noise_m = 0.0015;
  double speed_noise_fraction = 0.04;
  double angle_noise_rad = 0.01;
  // Perception. Vision: the peg's and the rendered hand's poses, with noise;
  // the peg colour read as force with noise. Touch: the device's force.
  double visual_position_noise_m = 0.0008;
  double visual_angle_noise_rad = 0.008;
  double visual_force_noise_n = 0.5;   // reading 0-10 N off the white-blue colour (5% of the scale)
  double haptic_force_noise_n = 0.05;  // device newtons, drifting over ~0.1 s
  double visual_reaction_s = 0.25;     // a corrective submovement after a visual check
  // Touch is faster than sight: the delay from a fingertip touching to the
  // hand stopping (tactile reaction, ~60-100 ms) against visual_reaction_s
  // when the only sign of contact is seeing it.
  double haptic_reaction_s = 0.08;
  // The last centimetres to the peg are a slow, guarded move that stops on
  // contact (felt or seen), as people touch a light object they could tip.
  double guarded_speed_mps = 0.04;
  // Grip: with touch, regulate the felt force to the target and raise it with
  // the felt load (grip-load coupling); without, close by feel-less feed-forward
  // and look at the colour.
  double grip_target_n = 3.4;
  // Touch is trusted while the device presses less than this (device
  // newtons; the 3-DOF platform clamps at 1.5 N): above it a stronger grip
  // feels no different, and the colour decides.
  double felt_ceiling_n = 1.3;
  double grip_load_ratio = 1.3;        // grip >= ratio * felt shear / friction
  double closing_speed = 1.2;          // posture closure per second
  // Extra closure past contact without touch: about 3 N at the thumb, at the
  // ~40 N per unit closure of the peg's finger coupling.
  double feedforward_closure = 0.07;
  double feedforward_closure_sd = 0.025;
  // Ab/adduction in the planned grasp: index radial, middle ulnar (spreads the
  // fingers under the peg against its tilt).
  double index_abduction_rad = 0.22;
  double middle_abduction_rad = -0.2;
  // The thumb of the pinch (degrees): nearly straight and fully abducted, so
  // that with the pronation below its pad faces the finger pads.
  double thumb_cmc_flexion_deg = 5, thumb_cmc_abduction_deg = 45, thumb_mcp_flexion_deg = -10,
         thumb_ip_flexion_deg = -15;
  // Axial rotation added to the participant's thumb metacarpal (about its long
  // axis, toward the fingers). The hand model's CMC flexes and abducts but does
  // not pronate, while a real thumb column turns 90-120 deg into opposition
  // (Kapandji); without it the thumb meets the peg with the side of its tip
  // and the lift wedges it into the peg (docs/peg-in-hole.md).
  double thumb_pronation_deg = 90;
  double alignment_tolerance_m = 0.0015;
  double alignment_tolerance_rad = 0.03;
};

// What the simulated study's world takes as the tracked hand
// (docs/peg-in-hole.md, "With the FTM glove"): the participant's commanded
// hand itself (ideal), or the FTM tracker's estimate of a simulated FTM
// wearer driven by that hand (ftm; "without AA" is then the FTM's abduction
// removed, FtmTrackerOptions::track_abduction, not the servo's).
enum class SimTracker : std::uint8_t { ideal, ftm };
const char* to_string(SimTracker t) noexcept;
Result<SimTracker> parse_sim_tracker(std::string_view name);  // "ideal" or "ftm"

struct PegInHoleConfig {
  std::string name = "peg-in-hole";
  SimTracker tracker = SimTracker::ideal;  // [study] tracker, or `--tracker`
  // With the FTM: model the devices' supply leads too ([study] ftm_device_leads).
  bool ftm_device_leads = true;
  std::uint64_t seed = 1;
  PegOptions peg;
  HoleOptions hole;
  LayoutOptions layout;
  FamiliarisationOptions familiarisation;
  MainTaskOptions main_task;
  DeviceOptions devices;
  RecordingOptions recording;
  SimUserOptions sim_user;

  Status validate() const;
  std::string describe() const;

  static Result<PegInHoleConfig> load_file(const std::filesystem::path& path);
  static Result<PegInHoleConfig> parse(const std::string& toml_text, const std::string& source_name = "<config>");
};

// The four settings in the thesis's numbering.
struct Setting {
  bool haptics = true;
  bool abduction = true;
  int number() const noexcept { return haptics ? (abduction ? 1 : 2) : (abduction ? 3 : 4); }
  std::string label() const;  // "wHF+wAA"
};
Setting setting_from_number(int number);

}  // namespace proprio::peg_in_hole
