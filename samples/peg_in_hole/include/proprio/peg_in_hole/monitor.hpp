#pragma once
// The task's rules, independent of where forces and poses come from (the
// servo loop in a simulated run, the servo snapshot per frame in a live one):
// when the peg breaks, what colour it shows, when it counts as inserted.
#include <array>
#include <cstdint>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/time.hpp"
#include "proprio/haptics/fingertip_force.hpp"
#include "proprio/peg_in_hole/config.hpp"

namespace proprio::peg_in_hole {

// The force that breaks the peg ("|lambda_N|"): the largest fingertip force
// on the peg along the contact normals (haptics::FingertipContact::
// object_normal_n: the peg is the scene's only movable object). Not the
// fingertip frame's normal: a pad meets the round peg at an angle (a thumb
// often touches with its tip's end), and what falls on the pad frame's shear
// axes would otherwise crush the bottle unnoticed. Not a fingertip pressed on
// the table or the hole's plate either: that does not squeeze the peg.
double grasp_force_n(const std::array<double, kFingerCount>& object_normal_n) noexcept;

// First-order low-pass of the grasp force and the break test on it. The
// threshold is inclusive: a filtered force of exactly break_force_n breaks.
class BreakMonitor {
 public:
  BreakMonitor(double break_force_n, double time_constant_s) noexcept
      : threshold_(break_force_n), tau_s_(time_constant_s) {}
  // One sample; true on the sample that breaks the peg (once, until reset()).
  // Non-finite samples are ignored (counted): NaN must neither break the peg
  // nor poison the filter.
  bool update(TimeNs time_ns, double force_n) noexcept;
  void reset() noexcept;  // a fresh peg (respawned)
  double filtered_n() const noexcept { return filtered_; }
  bool broken() const noexcept { return broken_; }
  std::uint64_t rejected_samples() const noexcept { return rejected_; }

 private:
  double threshold_, tau_s_;
  double filtered_ = 0.0;
  TimeNs last_ns_ = 0;
  bool started_ = false, broken_ = false;
  std::uint64_t rejected_ = 0;
};

// White at 0 N to blue at scale_max_n; a broken peg is dark red.
std::array<float, 4> peg_colour(double force_n, double scale_max_n, bool broken) noexcept;
// The inverse a participant does by eye: the force a colour means.
double force_from_colour(const std::array<float, 4>& rgba, double scale_max_n) noexcept;

// The hole: centre of its opening on the plate's front face and the axis
// pointing into the plate.
struct HoleGeometry {
  Vec3 p_entry_in_world = Vec3::Zero();
  Vec3 axis_in_world = Vec3::UnitX();
  double radius_m = 0.0;
  double insertion_depth_m = 0.03;
};
HoleGeometry hole_geometry(const PegInHoleConfig& config, const Vec3& p_hole_in_world);

// How far the peg's deeper end is past the entry along the axis (m; negative
// outside), and whether that end is within the hole's radius of the axis.
struct InsertionState {
  double depth_m = 0.0;
  double radial_offset_m = 0.0;
  double axis_angle_rad = 0.0;  // between the peg's axis and the hole's
  bool inserted = false;        // depth >= insertion_depth inside the bore
};
InsertionState insertion_state(const Pose& T_world_peg, double peg_half_length_m, const HoleGeometry& hole) noexcept;

// The peg's axis (its object z) in the world, and its two end points.
Vec3 peg_axis(const Pose& T_world_peg) noexcept;

}  // namespace proprio::peg_in_hole
