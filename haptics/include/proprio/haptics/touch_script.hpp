#pragma once
// A scripted tracked hand for simulated haptics runs (demo, benchmarks,
// `proprio haptics sim`): the index finger pointing, the other fingers
// curled, the wrist approaching a surface point from above, pressing a set
// depth below it (the tracked hand penetrates; the proxy does not), sliding
// along the surface and lifting off, repeated.
//
// Also a static thumb-index pinch of an upright cylinder (pinch_upright_cylinder):
// the two-hand servo benchmark's grasp of the peg.
#include <array>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/result.hpp"
#include "proprio/haptics/scene.hpp"

namespace proprio::haptics {

struct TouchScriptOptions {
  Vec3 p_surface_in_world = Vec3(0.0, 1.0, -0.55);  // where the index tip first lands
  double approach_height_m = 0.06;
  // How far below the surface the tracked fingertip goes; the proxy itself
  // stays within a millimetre of the surface. The pitched finger meets it
  // with the end of its tip first and, nearly straight, acts as a strut for
  // the wrist coupling: at 1 cm the contact force peaks near 16 N along the
  // finger (the coupling's leash caps it) before the slide brings the pad
  // round, at about 1 N.
  double press_depth_m = 0.01;
  double slide_m = 0.08;         // along +x while pressed
  double period_s = 4.0;         // approach 1 s, press 0.5 s, slide 1.5 s, lift 1 s
};

class TouchScript {
 public:
  TouchScript(const HandModel& model, Handedness hand, TouchScriptOptions options = {});
  // The tracked wrist and angles at time t (seconds since the start).
  void at(double t_s, Pose& T_world_wrist, HandAngles& angles) const;
  HandPose pose_at(double t_s, TimeNs time_ns) const;

 private:
  const HandModel& model_;
  Handedness hand_;
  TouchScriptOptions options_;
  HandAngles pointing_{};
  Quat q_world_wrist_;
  Vec3 p_tip_in_wrist_;  // index tip, in the wrist frame, for the pointing pose
};

// A tip pinch of an upright cylinder (axis along world +Y) between the thumb
// and the index pad, the hand coming from one side, back of the hand up-ish;
// middle, ring and little curled out of the way. The fingers' closure is
// found on the hand model (thumb-to-index distance against the cylinder's
// diameter plus both tips' radii), so it fits any hand size that can span it.
struct CylinderPinchOptions {
  Vec3 p_axis_in_world = Vec3(0.0, 0.95, -0.40);  // on the cylinder's axis, at the pinch's height
  double radius_m = 0.02584;
  // Horizontal, from the cylinder toward the wrist: where the hand comes from.
  Vec3 approach_from = Vec3::UnitX();
  // How far each tracked fingertip ends up inside the surface: the proxy
  // stops on it, the joint servos squeeze (about 0.3-0.7 N per tip at 6 mm
  // on the peg-in-hole peg).
  double squeeze_m = 0.006;
};
struct CylinderPinch {
  HandAngles open{};    // the tips 15 mm further apart than touching both sides
  HandAngles closed{};  // both tracked tips squeeze_m inside the surface
  Pose T_world_wrist_start;  // with `open`: the thumb 3 mm off the surface, touching nothing
  Pose T_world_wrist;        // with `closed`: the pinch centred on the axis
};
// Errc::invalid_argument when the hand cannot span the cylinder (or closes
// past it with no room to squeeze) in this posture.
Result<CylinderPinch> pinch_upright_cylinder(const HandModel& model, Handedness hand, const CylinderPinchOptions& o);

// Both hands pinching the standing peg of `scene` (the two-hand servo case of
// `bench haptics` and BM_ServoTickTwoHandsPinchingPeg), left then right: the
// left hand from -x 3.5 cm below the peg's middle, the right from +x 3 cm
// above it. Errc::not_found when the scene has no object named "peg".
Result<std::array<CylinderPinch, 2>> pinch_peg_with_both_hands(const HandModel& model, const HapticScene& scene);

}  // namespace proprio::haptics
