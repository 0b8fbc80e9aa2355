#pragma once
// Seeded, deterministic procedural hand motion with ground truth. Motion is a
// chain of keyframes (joint angles + wrist pose) joined by minimum-jerk
// transitions, or (the natural protocol) a stream of overlapping minimum-jerk
// submovements with tremor and flicks, or (tapping, pinch-grasp-contact) moves
// that stop abruptly at contact. Everything is evaluated analytically, so any
// sample rate sees the same motion and the same seed gives the same bytes.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"

namespace proprio::sim {

namespace hand_motion_detail {

// A minimum-jerk move of duration D aimed past contact, which it reaches at
// progress s_contact (fraction of the aimed displacement): it follows the
// profile until stop_begin_s, then decelerates uniformly from rate_begin
// (progress per second) to rest at s_contact at rest_s = stop_begin_s + stop.
struct ContactMove {
  double duration_s = 1.0;
  double s_contact = 1.0;
  double stop_begin_s = 1.0;
  double s_begin = 1.0;
  double rate_begin = 0.0;
  double rest_s = 1.0;
};

// One submovement of the natural protocol: from start_s for duration_s, the
// state (angles, wrist position and rotation vector) moves from the previous
// submovement's end state (the first: from the start) to its end state along
// a minimum-jerk profile, its displacement added to those of the others.
struct Submovement {
  double start_s = 0.0;
  double duration_s = 1.0;
  double next_start_s = 0.0;  // when the next submovement starts
  HandAngles end_angles{};
  Vec3 end_position = Vec3::Zero();
  Vec3 end_rotation = Vec3::Zero();
};

// One out-and-back flick: wrist (rotation about axis_in_wrist) or a finger
// (flexion, sign and size in amplitude_rad).
struct Flick {
  double start_s = 0.0;
  double duration_s = 0.1;
  double amplitude_rad = 0.0;  // signed for a finger (+ flexes)
  bool wrist = true;
  Vec3 axis_in_wrist = Vec3::UnitZ();
  Finger finger = Finger::index;
};

// Tremor: kComponents sinusoids shared by kChannels signals (3 wrist
// translation, 3 wrist rotation, 5 finger flexions), each channel with its
// own amplitude and phase per component, each component with a slow
// amplitude modulation.
struct Tremor {
  static constexpr std::size_t kComponents = 3;
  static constexpr std::size_t kChannels = 11;
  std::array<double, kComponents> frequency_hz{};
  std::array<double, kComponents> modulation_hz{};
  std::array<double, kComponents> modulation_phase{};
  // amplitude * cos(phase), amplitude * sin(phase) per channel and component.
  std::array<std::array<double, kComponents>, kChannels> a_cos{};
  std::array<std::array<double, kComponents>, kChannels> a_sin{};
};

// One tap: lift from the previous rest (contact, or the start) to phi_up
// while the wrist moves to wrist_xz; move down toward phi_aim; stop at
// contact; rest until the next tap's lift. phi is the tapping finger's
// flexion parameter (0 = contact posture).
struct Tap {
  double lift_s = 0.0;       // lift starts
  double up_s = 0.2;         // lift duration
  double down_s = 0.15;      // aimed downward move's duration
  double contact_s = 0.0;    // contact stop ends (the finger is at rest on the table)
  double next_lift_s = 0.0;  // the rest ends
  double phi_up = -0.3;
  double phi_aim = 0.0;
  ContactMove down;
  Eigen::Vector2d wrist_xz = Eigen::Vector2d::Zero();
};

}  // namespace hand_motion_detail

enum class MotionProtocol {
  // Lee 2021, §4.6: a new random target pose every 3 s, which the subject follows.
  free_motion,
  // Thumb-index pinch, tripod pinch and a power grasp, with open hands between.
  pinch_grasp,
  // Relaxed fingers while the wrist translates and rotates through the view of
  // a head-mounted camera.
  wrist_sweep,
  // Continuous natural movement: a stream of minimum-jerk submovements of
  // drawn durations, each starting before the previous one ends, their
  // displacements superposed (Flash & Hogan 1985; Flash & Henis 1991), with
  // only occasional short holds; physiological tremor and occasional fast
  // flicks on top (options below).
  natural,
  // Fingertip taps on a virtual table: the tapping finger lifts, moves down,
  // stops abruptly where its tip touches the table, rests, lifts again.
  tapping,
  // pinch_grasp, but every closing move (pinch, tripod, power grasp) aims a
  // little past the grasp posture and stops abruptly when the pads touch, as
  // a real hand does, instead of settling smoothly.
  pinch_grasp_contact,
};
inline constexpr std::array<MotionProtocol, 6> kMotionProtocols = {
    MotionProtocol::free_motion, MotionProtocol::pinch_grasp, MotionProtocol::wrist_sweep,
    MotionProtocol::natural,     MotionProtocol::tapping,     MotionProtocol::pinch_grasp_contact};
// "free-motion", "pinch-grasp", "wrist-sweep", "natural", "tapping", "pinch-grasp-contact".
std::string_view to_string(MotionProtocol p) noexcept;
std::optional<MotionProtocol> parse_motion_protocol(std::string_view s) noexcept;
// Every protocol's name, in kMotionProtocols' order (for option checks and messages).
std::vector<std::string> motion_protocol_names();

struct HandMotionOptions {
  MotionProtocol protocol = MotionProtocol::free_motion;
  Handedness hand = Handedness::right;
  std::uint64_t seed = 1;
  double target_interval_s = 3.0;  // a new keyframe this often
  double transition_s = 1.0;       // minimum-jerk move time; the rest of the interval holds
  double limit_fraction = 0.85;    // random angles stay within this central fraction of each range
  // Free motion draws targets a hand can make: a finger's DIP cannot flex
  // much on its own, and the ring and little fingers are "enslaved" to their
  // neighbours. Rijpkema & Girard 1991 give DIP = 2/3 PIP; Häger-Ross &
  // Schieber 2000 measured that ring and little fingers move with their
  // neighbours. The deviation sigmas below are assumptions. false: every DOF
  // is drawn independently over its range (no real hand can do all of these).
  bool natural_coupling = true;
  double dip_deviation_rad = 0.14;       // ~8°: DIP around 2/3 PIP
  double thumb_ip_deviation_rad = 0.2;   // ~11°: thumb IP around 1/2 MCP
  double enslaved_deviation_rad = 0.26;  // ~15°: ring around middle, little around ring (flexions)
  // Head (viewpoint) at rest: 1.6 m up, looking along -Z. The head sways a
  // little around it; wrist targets are placed relative to it.
  Pose T_world_head_rest{Quat::Identity(), Vec3(0.0, 1.6, 0.0)};
  bool head_sway = true;
  // Wrist workspace in the resting head frame (metres); mirrored in x for a left hand.
  Vec3 wrist_min_in_head{-0.05, -0.35, -0.50};
  Vec3 wrist_max_in_head{0.20, -0.10, -0.28};
  double wrist_max_tilt_rad = 0.6;  // about 35 deg from palm-down, fingers-forward

  // --- natural: overlapping submovements ---------------------------------
  // Each submovement moves the joint angles and the wrist pose (position and
  // rotation vector in the resting head frame) part of the way toward a new
  // random target drawn like free_motion's (limit_fraction, natural coupling,
  // wrist workspace); the part is duration / submovement_max_s, so a longer
  // submovement goes further and peak speeds stay in one range. The next
  // submovement starts after a drawn fraction of the current one's duration
  // (before it ends: the two overlap and their displacements add) and never
  // ends before it, so the motion is a convex mixture of targets and stays
  // inside the joint limits and the workspace. Durations 0.3-1.2 s: the range
  // of discrete reaching and grasping movements; the onset fractions and hold
  // numbers are assumptions.
  double submovement_min_s = 0.3;
  double submovement_max_s = 1.2;
  double submovement_onset_min = 0.4;  // next onset after this fraction of the current duration ...
  double submovement_onset_max = 0.8;  // ... up to this one (1: no overlap)
  double hold_probability = 0.05;      // chance that a submovement ends in a hold before the next
  double hold_min_s = 0.2;
  double hold_max_s = 0.6;

  // --- natural: physiological tremor ---------------------------------------
  // A sum of a few sinusoids with seeded frequencies in 8-12 Hz, the band of
  // physiological tremor (Elble & Koller, "Tremor", 1990; McAuley & Marsden,
  // Brain 123, 2000), with slowly varying amplitude, on the wrist (small
  // rotation and translation in the wrist frame) and the finger flexions.
  // tremor_rms_m is the RMS displacement of the index fingertip with the hand
  // relaxed (flexed postures see a little less); 0.1 mm is an assumption at
  // the low end of "sub-millimetre" for a hand held unsupported in the air.
  bool tremor = true;
  double tremor_rms_m = 1.0e-4;
  double tremor_min_hz = 8.0;
  double tremor_max_hz = 12.0;
  double tremor_modulation = 0.3;  // depth of the slow (0.1-0.4 Hz) amplitude variation, 0..1

  // --- natural: quick flicks -------------------------------------------------
  // Occasional fast out-and-back flicks of the wrist (about an axis between
  // flexion/extension and pronation/supination) or of the index or middle
  // finger (MCP, PIP and DIP together), each half a minimum-jerk move. The
  // peak angular velocity (of the wrist, or of the finger's distal segment
  // relative to the hand) is drawn between the two numbers: close to the
  // 2000 deg/s full scale of a common MEMS gyro (MPU-9250), and below it once
  // the rest of the motion (at most ~350 deg/s) is added. Assumptions: an
  // interval of 5-10 s, 80-150 ms per flick.
  bool flicks = true;
  double flick_interval_min_s = 5.0;
  double flick_interval_max_s = 10.0;
  double flick_min_s = 0.08;  // whole flick, out and back
  double flick_max_s = 0.15;
  double flick_peak_min_deg_s = 1000.0;
  double flick_peak_max_deg_s = 1600.0;
  double flick_wrist_fraction = 0.5;  // the share of flicks made by the wrist; the rest by a finger

  // --- tapping and pinch-grasp-contact: contact stops ----------------------
  // A move toward contact aims contact_aim_beyond of its length past the
  // contact posture; where it reaches contact it decelerates uniformly to
  // rest within contact_stop_s (the fingertip pulp compressing), an
  // acceleration spike an IMU sees. The joints' spheres stand for the loaded
  // pads: they reach contact at the end of the stop and never pass it.
  // Positions and velocities stay continuous; accelerations jump. false: the
  // move settles smoothly on the contact posture (minimum jerk) in the same
  // time. The 15 ms stop is an assumption (uniform deceleration from
  // 0.1-0.4 m/s over it travels 1-3 mm, a plausible pulp compression).
  bool contact_stops = true;
  double contact_stop_s = 0.015;
  double contact_aim_beyond = 0.25;

  // --- tapping -----------------------------------------------------------------
  // The palm faces down, the wrist a little above a table whose top is
  // horizontal in the resting head frame; the tapping finger taps with its
  // pad (the tip joint's sphere); the other fingers hover tap_hover_m above.
  // The wrist moves up to tap_shift_m sideways and forward while the finger
  // lifts, so taps land on different spots. Rates near 2 taps/s.
  Finger tap_finger = Finger::index;
  double table_height_in_head_m = -0.38;
  double tap_hover_m = 0.015;
  double tap_shift_m = 0.03;
  double tap_lift_min_rad = 0.15;  // lift: the finger extends this much (MCP; PIP and DIP follow) ...
  double tap_lift_max_rad = 0.35;  // ... up to this much from the contact posture
  double tap_up_min_s = 0.15;      // lift duration
  double tap_up_max_s = 0.25;
  double tap_down_min_s = 0.15;  // duration of the (aimed) downward move
  double tap_down_max_s = 0.25;
  double tap_dwell_min_s = 0.05;  // rest on the table
  double tap_dwell_max_s = 0.15;

  // Errc::invalid_argument naming the field: NaN, infinite, negative or
  // out-of-range numbers, or a min above its max.
  Status validate() const;
  std::string describe() const;
};

struct HandMotionFrame {
  TimeNs time_ns = 0;
  HandAngles angles{};  // ground-truth joint angles
  Pose T_world_wrist;
  Pose T_world_head;         // the head-mounted viewpoint
  HandPose pose;             // 26 joints with velocities (central difference of the analytic motion)
  std::size_t keyframe = 0;  // index of the keyframe (natural: submovement; tapping: tap) being moved to or held
  // tapping, pinch-grasp-contact: the finger is stopped against the table or
  // the other pad (from the end of the contact stop until it lifts or opens).
  bool in_contact = false;
};

class HandMotionGenerator {
 public:
  // Options must validate(); create() checks them.
  HandMotionGenerator(HandModel model, HandMotionOptions options);
  static Result<HandMotionGenerator> create(HandModel model, HandMotionOptions options);

  // Motion at time t >= 0 (seconds from the start of the protocol, as ns).
  // Extends the keyframe chain lazily; the result depends only on t, the
  // model and the options.
  HandMotionFrame sample(TimeNs t_ns);

  const HandModel& model() const noexcept { return model_; }
  const HandMotionOptions& options() const noexcept { return options_; }
  // The pinch posture solved for this hand (thumb and index pads touching);
  // solved only for the pinch-grasp protocols.
  const HandAngles& pinch_angles() const noexcept { return pinch_; }
  // tapping: the tapping finger's posture at contact (its tip sphere on the
  // table) and the height of the table top in the world.
  const HandAngles& tap_contact_angles() const noexcept { return tap_contact_; }
  double table_height_in_world_m() const noexcept;

 private:
  struct Keyframe {
    HandAngles angles;
    Pose T_head_wrist;  // relative to the resting head
  };
  const Keyframe& keyframe(std::size_t k);
  Keyframe make_keyframe(std::size_t k);
  HandAngles random_angles(Rng& rng) const;
  // Position in the resting head frame and rotation vector (right hand).
  void random_wrist(Rng& rng, double position_fraction, double tilt_fraction, Vec3& p, Vec3& rotation) const;
  void state_at(double t_s, HandAngles& angles, Pose& T_world_wrist, std::size_t& k, bool& contact);
  void natural_state_at(double t_s, HandAngles& angles, Pose& T_head_wrist, std::size_t& k);
  void natural_base_at(double t_s, HandAngles& angles, Vec3& p, Vec3& rotation, std::size_t& k);
  void tapping_state_at(double t_s, HandAngles& angles, Pose& T_head_wrist, std::size_t& k, bool& contact);
  const hand_motion_detail::Submovement& submovement(std::size_t j);
  const hand_motion_detail::Flick& flick(std::size_t i);
  const hand_motion_detail::Tap& tap(std::size_t i);
  void setup_tremor();
  void setup_tapping();
  Pose head_at(double t_s) const;

  HandModel model_;
  HandMotionOptions options_;
  Rng rng_;
  std::vector<Keyframe> keyframes_;
  HandAngles relaxed_{};
  HandAngles pinch_{};
  HandAngles tripod_{};
  HandAngles power_{};
  std::array<double, 6> head_phase_{};
  // natural
  Rng submovement_rng_;
  Rng flick_rng_;
  std::vector<hand_motion_detail::Submovement> submovements_;
  std::vector<hand_motion_detail::Flick> flicks_;
  hand_motion_detail::Tremor tremor_;
  // pinch_grasp_contact: the closing moves
  hand_motion_detail::ContactMove grasp_move_;
  // tapping
  Rng tap_rng_;
  std::vector<hand_motion_detail::Tap> taps_;
  HandAngles tap_contact_{};  // tapping finger at contact, the others hovering
  HandAngles tap_flex_{};     // direction of the tapping finger's flexion (per radian of MCP)
  double tap_wrist_height_in_head_m_ = 0.0;
};

// Minimum-jerk profile s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 (Flash & Hogan
// 1985), tau clamped to [0, 1].
double minimum_jerk(double tau) noexcept;

// Solves thumb and index angles so their tip pads touch (tip distance = sum of
// tip radii), staying near a natural pinch. Returns the angles.
HandAngles solve_pinch(const HandModel& model, Finger finger, const HandAngles& start);

}  // namespace proprio::sim
