#include "proprio/haptics/touch_script.hpp"

#include <algorithm>
#include <cmath>

namespace proprio::haptics {

namespace {
double smooth(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}
}  // namespace

TouchScript::TouchScript(const HandModel& model, Handedness hand, TouchScriptOptions options)
    : model_(model), hand_(hand), options_(options) {
  // Index nearly straight, the others curled out of the way, thumb tucked.
  for (Finger f : {Finger::middle, Finger::ring, Finger::little}) {
    const std::size_t d = first_dof_of(f);
    pointing_[d] = 1.2;
    pointing_[d + 2] = 1.4;
    pointing_[d + 3] = 0.9;
  }
  pointing_[first_dof_of(Finger::thumb) + 2] = 0.5;
  pointing_[first_dof_of(Finger::thumb) + 3] = 0.5;
  pointing_[first_dof_of(Finger::index)] = 0.3;
  // Palm down, pitched 35 degrees toward the surface: the fingertip meets it
  // first, partly with the pad and partly with the tip's end (so the force
  // has a large component along the finger, shear_z).
  q_world_wrist_ = Quat(Eigen::AngleAxisd(-0.6, Vec3::UnitX()));
  const auto T = model_.joint_poses_in_wrist(hand_, pointing_);
  p_tip_in_wrist_ = T[index_of(HandJoint::index_tip)].p;
}

void TouchScript::at(double t_s, Pose& T_world_wrist, HandAngles& angles) const {
  const double u = std::fmod(std::max(0.0, t_s), options_.period_s) / options_.period_s * 4.0;  // 0..4
  // Height of the index tip's skin above the surface, and slide along +x.
  const double tip_radius = model_.shape().fingers[1].joint_radius_m[4];
  double height = options_.approach_height_m, slide = 0.0;
  if (u < 1.0) {
    height = options_.approach_height_m * (1.0 - smooth(u));
  } else if (u < 1.5) {
    height = -options_.press_depth_m * smooth((u - 1.0) / 0.5);
  } else if (u < 3.0) {
    height = -options_.press_depth_m;
    slide = options_.slide_m * smooth((u - 1.5) / 1.5);
  } else {
    height = -options_.press_depth_m + (options_.approach_height_m + options_.press_depth_m) * smooth(u - 3.0);
    slide = options_.slide_m * (1.0 - smooth(u - 3.0));
  }
  const Vec3 p_tip = options_.p_surface_in_world + Vec3(slide, height + tip_radius, 0.0);
  T_world_wrist = Pose{q_world_wrist_, p_tip - q_world_wrist_ * p_tip_in_wrist_};
  angles = pointing_;
}

HandPose TouchScript::pose_at(double t_s, TimeNs time_ns) const {
  Pose T;
  HandAngles a;
  at(t_s, T, a);
  return model_.forward(hand_, a, T, time_ns);
}

}  // namespace proprio::haptics
