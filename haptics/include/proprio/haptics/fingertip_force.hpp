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

// One contact's force on the fingertip as the pad would feel it: what a
// cutaneous device, which presses only on the pad, renders for a contact
// anywhere on the distal phalanx (pad, end, side, nail).
//
// The fingertip is a rounded body of pulp; wherever a surface touches it, the
// skin there is pressed along the contact normal and stretched by friction
// across it. The map rolls the touched patch of skin onto the pad: it rotates
// the force by the smallest rotation that takes the contact normal onto the
// pad normal (+Y). The force along the contact normal (always a push) becomes
// pad pressure, normal_n >= 0, and friction becomes shear in the pad's plane.
// Magnitudes are kept: a tip end pressed along the finger's axis with 16 N is
// 16 N of pad pressure, where the fingertip frame's projection (the force's
// own normal_n) reads zero or less and a device would render nothing.
// A contact square on the pad is unchanged; a pad pressed obliquely reads its
// contact's normal force as pressure and only friction as shear, where the
// projection reads the pad's tilt as shear.
//
// f_in_tip: the force on the finger, fingertip frame. n_in_tip: the unit
// contact normal pointing into the finger (the way the surface pushes it).
// A normal straight onto the nail (no unique smallest rotation) turns half a
// turn about Z, the way side contacts roll. Non-finite input gives non-finite
// output (the safety gate refuses it).
inline FingertipForce felt_on_pad(const Vec3& f_in_tip, const Vec3& n_in_tip) noexcept {
  const double c = n_in_tip.y();  // cos of the angle between the contact normal and +Y
  if (c > -1.0 + 1e-9) {
    // Rodrigues with w = n x Y = sin(angle) * axis: R f = c f + w x f + (w . f) w / (1 + c).
    const Vec3 w = n_in_tip.cross(Vec3::UnitY());
    return FingertipForce::from_tip_frame(c * f_in_tip + w.cross(f_in_tip) + (w.dot(f_in_tip) / (1.0 + c)) * w);
  }
  return FingertipForce::from_tip_frame(Vec3(-f_in_tip.x(), -f_in_tip.y(), f_in_tip.z()));
}

}  // namespace proprio::haptics
