#include "proprio/haptics/touch_script.hpp"

#include <algorithm>
#include <cmath>
#include <string>

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

namespace {
// The pinch family: the thumb opposed and fixed, the index curling with s
// (0 open .. 2 closed), the other fingers in a loose fist.
HandAngles pinch_posture(const HandModel& model, double s) {
  HandAngles a{};
  const auto set = [&](HandDof d, double deg) { a[index_of(d)] = deg_to_rad(deg); };
  set(HandDof::thumb_cmc_flexion, 30);
  set(HandDof::thumb_cmc_abduction, 30);
  set(HandDof::thumb_mcp_flexion, 20);
  set(HandDof::thumb_ip_flexion, 20);
  const double curl = std::min(s, 1.0);
  set(HandDof::index_mcp_flexion, 10 + 40 * s);
  set(HandDof::index_pip_flexion, 15 + 25 * curl);
  set(HandDof::index_dip_flexion, 5 + 10 * curl);
  for (HandDof d : {HandDof::middle_mcp_flexion, HandDof::ring_mcp_flexion, HandDof::little_mcp_flexion}) set(d, 80);
  for (HandDof d : {HandDof::middle_pip_flexion, HandDof::ring_pip_flexion, HandDof::little_pip_flexion}) set(d, 95);
  for (HandDof d : {HandDof::middle_dip_flexion, HandDof::ring_dip_flexion, HandDof::little_dip_flexion}) set(d, 50);
  return model.limits().clamp(a);
}
}  // namespace

Result<CylinderPinch> pinch_upright_cylinder(const HandModel& model, Handedness hand, const CylinderPinchOptions& o) {
  Vec3 away(o.approach_from.x(), 0.0, o.approach_from.z());
  if (!(o.radius_m > 0.0) || !(o.squeeze_m >= 0.0) || !o.p_axis_in_world.allFinite() || !(away.norm() > 1e-6)) {
    return make_error(Errc::invalid_argument,
                      "pinch_upright_cylinder: needs a radius > 0, a squeeze >= 0, a finite axis point and a "
                      "horizontal approach direction");
  }
  away.normalize();
  const auto tips = [&](double s) {
    const auto j = model.joint_poses_in_wrist(hand, pinch_posture(model, s));
    return std::pair<Vec3, Vec3>(j[index_of(HandJoint::thumb_tip)].p, j[index_of(HandJoint::index_tip)].p);
  };
  const double r_thumb = model.shape().fingers[0].joint_radius_m[3];
  const double r_index = model.shape().fingers[1].joint_radius_m[4];
  const double touching = 2.0 * o.radius_m + r_thumb + r_index;  // tip distance when both tips touch
  const double open_gap = touching + 0.015, closed_gap = touching - 2.0 * o.squeeze_m;
  double s_open = -1.0, s_closed = -1.0;
  for (double s = 0.0; s <= 2.0 && s_closed < 0.0; s += 0.005) {
    const auto [t, i] = tips(s);
    const double d = (i - t).norm();
    if (s_open < 0.0 && d <= open_gap) s_open = s;
    if (d <= closed_gap) s_closed = s;
  }
  if (s_open <= 0.0 || s_closed < 0.0) {  // s_open 0: already narrower than open at s = 0
    return make_error(Errc::invalid_argument,
                      "pinch_upright_cylinder: this hand's thumb-index pinch does not span " +
                          std::to_string(std::lround(open_gap * 1e3)) + " mm and close to " +
                          std::to_string(std::lround(closed_gap * 1e3)) + " mm");
  }
  CylinderPinch out;
  out.open = pinch_posture(model, s_open);
  out.closed = pinch_posture(model, s_closed);
  // Wrist-frame basis of the closed pinch: a along the pinch (thumb to index),
  // u from the wrist toward the pinch's midpoint, c = u x a.
  const auto [t, i] = tips(s_closed);
  const Vec3 a = (i - t).normalized();
  const Vec3 mid = 0.5 * (t + i);
  const Vec3 u = (mid - mid.dot(a) * a).normalized();
  const Vec3 c = u.cross(a);
  // World: u toward the axis, the pinch horizontal across it, and the sign
  // that keeps the back of the hand (wrist +Y) up rather than down.
  const Vec3 U = -away;
  Vec3 A = U.cross(Vec3::UnitY()).normalized();
  if (U.cross(A).y() * c.y() < 0.0) A = -A;
  Mat3 W, H;
  W << U, A, U.cross(A);
  H << u, a, c;
  const Quat q = Quat(Mat3(W * H.transpose())).normalized();
  out.T_world_wrist = Pose{q, o.p_axis_in_world - q * mid};
  // Start open with the thumb 3 mm off the surface: the index then has about
  // 12 mm, and closing (moving the wrist in and curling) meets both.
  out.T_world_wrist_start = Pose{q, out.T_world_wrist.p - (o.squeeze_m + 0.003) * (q * a)};
  return out;
}

Result<std::array<CylinderPinch, 2>> pinch_peg_with_both_hands(const HandModel& model, const HapticScene& scene) {
  const SceneObject* peg = scene.find("peg");
  if (peg == nullptr) return make_error(Errc::not_found, "the peg-in-hole scene has no peg");
  std::array<CylinderPinch, 2> out;
  for (std::size_t h = 0; h < 2; ++h) {
    CylinderPinchOptions o;
    o.radius_m = peg->radius_m;
    o.p_axis_in_world = peg->T_world_object.p + Vec3(0.0, h == 0 ? -0.035 : 0.03, 0.0);
    o.approach_from = Vec3(h == 0 ? -1.0 : 1.0, 0.0, 0.0);
    auto p = pinch_upright_cylinder(model, h == 0 ? Handedness::left : Handedness::right, o);
    if (!p) return p.error();
    out[h] = *p;
  }
  return out;
}

}  // namespace proprio::haptics
