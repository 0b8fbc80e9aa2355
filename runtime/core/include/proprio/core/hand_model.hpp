#pragma once
// A kinematic hand: 20 joint DOFs on top of a 6-DOF wrist, bone lengths scaled
// from hand length and width, joint limits, optional synergies, forward
// kinematics to the 26 OpenXR joints and inverse kinematics back to angles.
//
// Frames. The wrist frame W is the WRIST joint's frame: +Z back toward the
// forearm, +Y out of the back of the hand, +X = Y x Z. Fingers extend along -Z.
// For a right hand the thumb lies on -X; for a left hand on +X. Joint frames
// follow XR_EXT_hand_tracking (+Z back along the bone toward the wrist, +Y out
// of the back of the hand), unmirrored: the left hand is the mirror image of
// the right through W's YZ plane with axes kept right-handed.
#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "proprio/core/hand_pose.hpp"
#include "proprio/core/result.hpp"

namespace proprio {

// Angles in radians. Flexion is positive when the finger curls toward the
// palm. Finger ab/adduction is positive toward the thumb side (radial). Thumb
// CMC abduction rotates the metacarpal about its own dorsal (+Y) axis.
enum class HandDof : std::uint8_t {
  thumb_cmc_flexion = 0,
  thumb_cmc_abduction,
  thumb_mcp_flexion,
  thumb_ip_flexion,
  index_mcp_flexion,
  index_mcp_abduction,
  index_pip_flexion,
  index_dip_flexion,
  middle_mcp_flexion,
  middle_mcp_abduction,
  middle_pip_flexion,
  middle_dip_flexion,
  ring_mcp_flexion,
  ring_mcp_abduction,
  ring_pip_flexion,
  ring_dip_flexion,
  little_mcp_flexion,
  little_mcp_abduction,
  little_pip_flexion,
  little_dip_flexion,
};
inline constexpr std::size_t kHandDofCount = 20;
using HandAngles = std::array<double, kHandDofCount>;

constexpr std::size_t index_of(HandDof d) noexcept { return static_cast<std::size_t>(d); }
std::string_view to_string(HandDof d) noexcept;
// The four DOFs of a finger in the order above (thumb: CMC flex, CMC abd, MCP, IP).
constexpr std::size_t first_dof_of(Finger f) noexcept { return 4 * static_cast<std::size_t>(f); }
constexpr bool is_abduction(HandDof d) noexcept { return index_of(d) % 4 == 1; }

struct JointLimits {
  HandAngles min_rad{};
  HandAngles max_rad{};

  static JointLimits defaults();
  HandAngles clamp(const HandAngles& a) const;
  bool contains(const HandAngles& a, double tolerance_rad = 1e-9) const;
};

// Couplings a low-DOF tracker can lean on. Off by default.
struct Synergies {
  bool enabled = false;
  // DIP ≈ 2/3 PIP: Rijpkema & Girard, "Computer animation of knowledge-based
  // human grasping", SIGGRAPH 1991.
  double dip_from_pip = 2.0 / 3.0;
  // Thumb IP from MCP: a common heuristic, not taken from a cited measurement.
  double thumb_ip_from_mcp = 0.5;

  HandAngles apply(HandAngles a) const;
};

// Per-user geometry of a right hand in the wrist frame (the left hand mirrors it).
struct HandShape {
  struct Finger {
    Vec3 p_base_in_wrist = Vec3::Zero();  // CMC joint centre (the METACARPAL joint)
    Quat q_wrist_metacarpal_rest = Quat::Identity();
    // Thumb: metacarpal, proximal, distal (3 bones). Fingers: + intermediate (4 bones).
    std::array<double, 4> bone_length_m{};
    std::size_t bone_count = 4;
    // Skin radius at each XR joint of this finger, base to tip.
    std::array<double, 5> joint_radius_m{};
  };

  double hand_length_m = 0.19;  // wrist crease to middle fingertip, flat hand
  double hand_width_m = 0.10;   // thumb MCP to the ulnar edge of the hand (Lee 2021, Fig. 4.7)
  std::array<Finger, kFingerCount> fingers{};
  double palm_radius_m = 0.015;
  double wrist_radius_m = 0.02;

  // Scales a generic hand to these measurements. Errors (Errc::out_of_range)
  // when the numbers are not plausible adult hand sizes in metres.
  static Result<HandShape> from_measurements(double hand_length_m, double hand_width_m);
  // The measurements of a tracked hand, in any posture: its length from the
  // middle finger's joint-to-joint chain, its width from the spread of the
  // index and little MCPs (both rigid in this model), then
  // from_measurements(). Errors for an inactive or partly valid pose, or one
  // whose sizes are not an adult hand's.
  static Result<HandShape> from_tracked_pose(const HandPose& pose);
  std::string describe() const;
};

struct InverseKinematicsResult {
  HandAngles angles{};
  Pose T_world_wrist;
  // Largest distance between the input joints and FK of the recovered angles:
  // near zero for poses this model produced, larger for tracked poses that do
  // not fit the model exactly.
  double max_position_residual_m = 0.0;
};

class HandModel {
 public:
  explicit HandModel(HandShape shape, JointLimits limits = JointLimits::defaults());

  // Joint poses in the wrist frame of the given hand (WRIST is the identity).
  std::array<Pose, kHandJointCount> joint_poses_in_wrist(Handedness hand, const HandAngles& angles) const;

  // A fully tracked HandPose (all flags set, radii filled, no velocities).
  HandPose forward(Handedness hand, const HandAngles& angles, const Pose& T_world_wrist, TimeNs time_ns) const;

  // Angles from the relative joint orientations of a pose (as FK made it, or
  // as a tracker reports it). Angles are not clamped to the limits.
  InverseKinematicsResult inverse(const HandPose& pose) const;

  const HandShape& shape() const noexcept { return shape_; }
  const JointLimits& limits() const noexcept { return limits_; }

 private:
  HandShape shape_;
  JointLimits limits_;
};

constexpr double deg_to_rad(double deg) noexcept { return deg * 0.017453292519943295; }
constexpr double rad_to_deg(double rad) noexcept { return rad * 57.29577951308232; }

}  // namespace proprio
