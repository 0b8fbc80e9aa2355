#pragma once
#include <array>
#include <cstdint>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/time.hpp"

namespace proprio {

// Bit values equal XrSpaceLocationFlags so they pass straight through the layer.
enum JointFlag : std::uint8_t {
  kOrientationValid = 0x1,
  kPositionValid = 0x2,
  kOrientationTracked = 0x4,
  kPositionTracked = 0x8,
};
inline constexpr std::uint8_t kJointFullyTracked =
    kOrientationValid | kPositionValid | kOrientationTracked | kPositionTracked;

// One hand at one instant: the 26 OpenXR joints in the source's tracking frame
// ("world": right-handed, +Y up, metres). Joint orientations follow
// XR_EXT_hand_tracking: +Z back along the bone toward the wrist, +Y out of the
// back of the hand, the same on both hands.
struct HandPose {
  TimeNs time_ns = 0;  // when the hand was in this pose (measurement time)
  // Latency bookkeeping (CLOCK_MONOTONIC; 0 = unknown). data_time_ns: the
  // newest sensor sample behind this pose; ready_time_ns: when the pose could
  // first be served (PoseHistory::push stamps it). A lookup between or past
  // samples reports the newer sample's two times.
  TimeNs data_time_ns = 0;
  TimeNs ready_time_ns = 0;
  Handedness hand = Handedness::right;
  bool active = false;  // false: nothing below is meaningful
  std::array<Pose, kHandJointCount> T_world_joint{};
  std::array<double, kHandJointCount> radius_m{};
  std::array<std::uint8_t, kHandJointCount> flags{};
  bool has_velocity = false;
  std::array<Vec3, kHandJointCount> linear_velocity_in_world{};   // m/s
  std::array<Vec3, kHandJointCount> angular_velocity_in_world{};  // rad/s

  const Pose& joint(HandJoint j) const { return T_world_joint[index_of(j)]; }
  Pose& joint(HandJoint j) { return T_world_joint[index_of(j)]; }
  void set_all_flags(std::uint8_t f) { flags.fill(f); }
  // True when every joint has both VALID bits, i.e. the pose is usable as-is.
  bool fully_valid() const noexcept;
};

// Pointwise distance between two poses' joints (metres), e.g. tracker vs ground truth.
std::array<double, kHandJointCount> joint_position_errors(const HandPose& a, const HandPose& b);

}  // namespace proprio
