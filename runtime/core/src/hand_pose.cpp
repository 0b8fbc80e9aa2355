#include "proprio/core/hand_pose.hpp"

namespace proprio {

bool HandPose::fully_valid() const noexcept {
  if (!active) return false;
  for (auto f : flags) {
    if ((f & (kOrientationValid | kPositionValid)) != (kOrientationValid | kPositionValid)) return false;
  }
  return true;
}

std::array<double, kHandJointCount> joint_position_errors(const HandPose& a, const HandPose& b) {
  std::array<double, kHandJointCount> e{};
  for (std::size_t i = 0; i < kHandJointCount; ++i) e[i] = (a.T_world_joint[i].p - b.T_world_joint[i].p).norm();
  return e;
}

}  // namespace proprio
