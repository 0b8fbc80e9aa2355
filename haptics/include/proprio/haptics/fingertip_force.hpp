#pragma once
// The force a virtual object exerts on one fingertip, in the fingertip frame.
// It is what the contact simulation (or an analytic force law) produces and
// what a fingertip device model turns into motor commands.
//
// Fingertip frame F: the finger's TIP joint frame (XR_EXT_hand_tracking
// convention, the same on both hands): +Z back along the distal bone toward
// the wrist, +Y out of the nail, +X = Y x Z. The pad faces -Y, so an object
// pressing on the pad pushes the finger toward +Y:
//   normal_n  = F . +Y   (>= 0 when pressing on the pad; a device renders only >= 0)
//   shear_x_n = F . +X   (across the pad)
//   shear_z_n = F . +Z   (along the pad, toward the wrist: positive when the
//                         object drags the skin proximally)
// Newtons. A device frame that differs (e.g. a band that shears only along Z)
// says so in its model.
#include <cmath>

#include "proprio/core/math.hpp"

namespace proprio::haptics {

struct FingertipForce {
  double normal_n = 0.0;
  double shear_x_n = 0.0;
  double shear_z_n = 0.0;

  double shear_magnitude_n() const noexcept { return std::hypot(shear_x_n, shear_z_n); }
  bool is_finite() const noexcept {
    return std::isfinite(normal_n) && std::isfinite(shear_x_n) && std::isfinite(shear_z_n);
  }
  // The force as a vector in the fingertip frame (x, y = normal, z).
  Vec3 in_tip_frame() const noexcept { return {shear_x_n, normal_n, shear_z_n}; }
  static FingertipForce from_tip_frame(const Vec3& f_in_tip) noexcept {
    return {f_in_tip.y(), f_in_tip.x(), f_in_tip.z()};
  }
};

}  // namespace proprio::haptics
