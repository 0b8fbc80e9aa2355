#pragma once
// A scripted tracked hand for simulated haptics runs (demo, benchmarks,
// `proprio haptics sim`): the index finger pointing, the other fingers
// curled, the wrist approaching a surface point from above, pressing a set
// depth below it (the tracked hand penetrates; the proxy does not), sliding
// along the surface and lifting off, repeated.
#include "proprio/core/hand_model.hpp"

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

}  // namespace proprio::haptics
