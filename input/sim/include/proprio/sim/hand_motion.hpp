#pragma once
// Seeded, deterministic procedural hand motion with ground truth. Motion is a
// chain of keyframes (joint angles + wrist pose) joined by minimum-jerk
// transitions, evaluated analytically, so any sample rate sees the same motion
// and the same seed gives the same bytes.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/random.hpp"

namespace proprio::sim {

enum class MotionProtocol {
  // Lee 2021, §4.6: a new random target pose every 3 s, which the subject follows.
  free_motion,
  // Thumb-index pinch, tripod pinch and a power grasp, with open hands between.
  pinch_grasp,
  // Relaxed fingers while the wrist translates and rotates through the view of
  // a head-mounted camera.
  wrist_sweep,
};
std::string_view to_string(MotionProtocol p) noexcept;
std::optional<MotionProtocol> parse_motion_protocol(std::string_view s) noexcept;

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
  double dip_deviation_rad = 0.14;        // ~8°: DIP around 2/3 PIP
  double thumb_ip_deviation_rad = 0.2;    // ~11°: thumb IP around 1/2 MCP
  double enslaved_deviation_rad = 0.26;   // ~15°: ring around middle, little around ring (flexions)
  // Head (viewpoint) at rest: 1.6 m up, looking along -Z. The head sways a
  // little around it; wrist targets are placed relative to it.
  Pose T_world_head_rest{Quat::Identity(), Vec3(0.0, 1.6, 0.0)};
  bool head_sway = true;
  // Wrist workspace in the resting head frame (metres); mirrored in x for a left hand.
  Vec3 wrist_min_in_head{-0.05, -0.35, -0.50};
  Vec3 wrist_max_in_head{0.20, -0.10, -0.28};
  double wrist_max_tilt_rad = 0.6;  // about 35 deg from palm-down, fingers-forward

  std::string describe() const;
};

struct HandMotionFrame {
  TimeNs time_ns = 0;
  HandAngles angles{};       // ground-truth joint angles
  Pose T_world_wrist;
  Pose T_world_head;         // the head-mounted viewpoint
  HandPose pose;             // 26 joints with velocities (central difference of the analytic motion)
  std::size_t keyframe = 0;  // index of the keyframe being moved to or held
};

class HandMotionGenerator {
 public:
  HandMotionGenerator(HandModel model, HandMotionOptions options);

  // Motion at time t >= 0 (seconds from the start of the protocol, as ns).
  // Extends the keyframe chain lazily; the result depends only on t, the
  // model and the options.
  HandMotionFrame sample(TimeNs t_ns);

  const HandModel& model() const noexcept { return model_; }
  const HandMotionOptions& options() const noexcept { return options_; }
  // The pinch posture solved for this hand (thumb and index pads touching);
  // solved only for the pinch-grasp protocol.
  const HandAngles& pinch_angles() const noexcept { return pinch_; }

 private:
  struct Keyframe {
    HandAngles angles;
    Pose T_head_wrist;  // relative to the resting head
  };
  const Keyframe& keyframe(std::size_t k);
  Keyframe make_keyframe(std::size_t k);
  void state_at(double t_s, HandAngles& angles, Pose& T_world_wrist, std::size_t& k);
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
};

// Minimum-jerk profile s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 (Flash & Hogan
// 1985), tau clamped to [0, 1].
double minimum_jerk(double tau) noexcept;

// Solves thumb and index angles so their tip pads touch (tip distance = sum of
// tip radii), staying near a natural pinch. Returns the angles.
HandAngles solve_pinch(const HandModel& model, Finger finger, const HandAngles& start);

}  // namespace proprio::sim
