#include "proprio/sim/hand_motion.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

namespace proprio::sim {

namespace {

// Half-width of the central difference that gives the ground-truth velocities.
constexpr double kVelocityStepS = 0.5e-3;

HandAngles degrees(std::initializer_list<double> deg) {
  HandAngles a{};
  std::size_t i = 0;
  for (double d : deg) a[i++] = deg_to_rad(d);
  return a;
}

Pose mirror_for(Handedness hand, const Pose& T_right) {
  if (hand == Handedness::right) return T_right;
  // Same mirror as the hand model: x -> -x, frames kept right-handed.
  return {Quat(T_right.q.w(), T_right.q.x(), -T_right.q.y(), -T_right.q.z()),
          Vec3(-T_right.p.x(), T_right.p.y(), T_right.p.z())};
}

}  // namespace

std::string_view to_string(MotionProtocol p) noexcept {
  switch (p) {
    case MotionProtocol::free_motion: return "free-motion";
    case MotionProtocol::pinch_grasp: return "pinch-grasp";
    case MotionProtocol::wrist_sweep: return "wrist-sweep";
  }
  return "?";
}

std::optional<MotionProtocol> parse_motion_protocol(std::string_view s) noexcept {
  for (auto p : {MotionProtocol::free_motion, MotionProtocol::pinch_grasp, MotionProtocol::wrist_sweep}) {
    if (s == to_string(p)) return p;
  }
  return std::nullopt;
}

std::string HandMotionOptions::describe() const {
  char buf[480];
  std::snprintf(buf, sizeof buf,
                "protocol=%s hand=%s seed=%llu interval=%.2fs transition=%.2fs limit_fraction=%.2f head_sway=%s "
                "wrist_box=[%.2f,%.2f,%.2f]..[%.2f,%.2f,%.2f]m max_tilt=%.1fdeg natural_coupling=%s "
                "(dip_dev=%.1fdeg thumb_ip_dev=%.1fdeg enslaved_dev=%.1fdeg)",
                std::string(to_string(protocol)).c_str(), std::string(proprio::to_string(hand)).c_str(),
                static_cast<unsigned long long>(seed), target_interval_s, transition_s, limit_fraction,
                head_sway ? "on" : "off", wrist_min_in_head.x(), wrist_min_in_head.y(), wrist_min_in_head.z(),
                wrist_max_in_head.x(), wrist_max_in_head.y(), wrist_max_in_head.z(), rad_to_deg(wrist_max_tilt_rad),
                natural_coupling ? "on" : "off", rad_to_deg(dip_deviation_rad), rad_to_deg(thumb_ip_deviation_rad),
                rad_to_deg(enslaved_deviation_rad));
  return buf;
}

double minimum_jerk(double tau) noexcept {
  tau = std::clamp(tau, 0.0, 1.0);
  const double t3 = tau * tau * tau;
  return t3 * (10.0 + tau * (-15.0 + 6.0 * tau));
}

HandAngles solve_pinch(const HandModel& model, Finger finger, const HandAngles& start) {
  // Unknowns: thumb CMC flex/abd, MCP, IP, and the finger's MCP flexion and PIP
  // (DIP follows PIP at 2/3). Residuals: the gap between the two tip spheres,
  // plus a weak pull toward the starting posture that picks the natural one of
  // the many solutions. Levenberg-Marquardt with a numeric Jacobian.
  const std::size_t f0 = first_dof_of(finger);
  const std::array<std::size_t, 6> vars = {0, 1, 2, 3, f0, f0 + 2};
  const HandJoint thumb_tip = tip_of(Finger::thumb);
  const HandJoint finger_tip = tip_of(finger);
  const auto& shape = model.shape();
  const double contact = shape.fingers[0].joint_radius_m[3] + shape.fingers[static_cast<std::size_t>(finger)].joint_radius_m[4];
  constexpr double kRegularisation = 0.01;  // metres of gap per radian of deviation

  auto residuals = [&](const HandAngles& a) {
    HandAngles full = a;
    full[f0 + 3] = (2.0 / 3.0) * full[f0 + 2];
    const auto T = model.joint_poses_in_wrist(Handedness::right, full);
    Eigen::Matrix<double, 7, 1> r;
    r(0) = (T[index_of(thumb_tip)].p - T[index_of(finger_tip)].p).norm() - contact;
    for (std::size_t i = 0; i < vars.size(); ++i) r(static_cast<Eigen::Index>(i + 1)) = kRegularisation * (a[vars[i]] - start[vars[i]]);
    return r;
  };

  HandAngles x = model.limits().clamp(start);
  double lambda = 1e-3;
  auto r = residuals(x);
  for (int iter = 0; iter < 200 && std::abs(r(0)) > 1e-5; ++iter) {
    Eigen::Matrix<double, 7, 6> J;
    for (std::size_t i = 0; i < vars.size(); ++i) {
      HandAngles xp = x;
      xp[vars[i]] += 1e-6;
      J.col(static_cast<Eigen::Index>(i)) = (residuals(xp) - r) / 1e-6;
    }
    const Eigen::Matrix<double, 6, 6> H = J.transpose() * J;
    const Eigen::Matrix<double, 6, 1> g = J.transpose() * r;
    const Eigen::Matrix<double, 6, 1> step =
        -(H + lambda * Eigen::Matrix<double, 6, 6>::Identity()).ldlt().solve(g);
    HandAngles candidate = x;
    for (std::size_t i = 0; i < vars.size(); ++i) candidate[vars[i]] += step(static_cast<Eigen::Index>(i));
    candidate = model.limits().clamp(candidate);
    const auto rc = residuals(candidate);
    if (rc.squaredNorm() < r.squaredNorm()) {
      x = candidate;
      r = rc;
      lambda = std::max(lambda * 0.3, 1e-9);
    } else {
      lambda *= 10.0;
    }
  }
  x[f0 + 3] = (2.0 / 3.0) * x[f0 + 2];
  return x;
}

HandMotionGenerator::HandMotionGenerator(HandModel model, HandMotionOptions options)
    : model_(std::move(model)), options_(options), rng_(mix_seed(options.seed, 0)) {
  // Postures in degrees, DOF order of HandDof.
  relaxed_ = degrees({10, 10, 10, 10, 15, 5, 20, 10, 15, 0, 20, 10, 15, -3, 20, 10, 15, -8, 20, 10});
  const HandAngles pinch_start =
      degrees({30, 25, 20, 15, 40, 0, 40, 27, 30, 0, 45, 30, 30, -3, 45, 30, 30, -8, 45, 30});
  pinch_ = pinch_start;
  tripod_ = pinch_start;
  if (options_.protocol == MotionProtocol::pinch_grasp) {  // the solve is the costly part of construction
    pinch_ = solve_pinch(model_, Finger::index, pinch_start);
    HandAngles tripod_start = pinch_start;
    tripod_start[first_dof_of(Finger::middle)] = deg_to_rad(45);
    tripod_ = solve_pinch(model_, Finger::index, tripod_start);
    tripod_[first_dof_of(Finger::middle)] = tripod_[first_dof_of(Finger::index)] + deg_to_rad(5);
    tripod_[first_dof_of(Finger::middle) + 2] = tripod_[first_dof_of(Finger::index) + 2];
    tripod_[first_dof_of(Finger::middle) + 3] = tripod_[first_dof_of(Finger::index) + 3];
  }
  power_ = degrees({35, 30, 40, 45, 70, 0, 85, 55, 72, 0, 88, 58, 75, -3, 88, 58, 78, -8, 85, 55});
  Rng head_rng(mix_seed(options.seed, 1));
  for (auto& ph : head_phase_) ph = head_rng.uniform(0.0, 2.0 * std::numbers::pi);
}

HandMotionGenerator::Keyframe HandMotionGenerator::make_keyframe(std::size_t k) {
  const JointLimits& lim = model_.limits();
  const double shrink = 0.5 * (1.0 - options_.limit_fraction);
  auto random_angles = [&] {
    HandAngles a;
    for (std::size_t i = 0; i < kHandDofCount; ++i) {
      const double span = lim.max_rad[i] - lim.min_rad[i];
      a[i] = rng_.uniform(lim.min_rad[i] + shrink * span, lim.max_rad[i] - shrink * span);
    }
    if (options_.natural_coupling) {
      auto dof = [&](Finger f, std::size_t i) -> double& { return a[first_dof_of(f) + i]; };
      for (Finger f : {Finger::ring, Finger::little}) {
        const Finger neighbour = f == Finger::ring ? Finger::middle : Finger::ring;
        for (std::size_t i : {std::size_t{0}, std::size_t{2}}) {  // MCP and PIP flexion
          dof(f, i) = dof(neighbour, i) + options_.enslaved_deviation_rad * rng_.normal();
        }
      }
      for (Finger f : {Finger::index, Finger::middle, Finger::ring, Finger::little}) {
        dof(f, 3) = (2.0 / 3.0) * dof(f, 2) + options_.dip_deviation_rad * rng_.normal();
      }
      dof(Finger::thumb, 3) = 0.5 * dof(Finger::thumb, 2) + options_.thumb_ip_deviation_rad * rng_.normal();
      a = lim.clamp(a);
    }
    return a;
  };
  auto random_wrist = [&](double position_fraction, double tilt_fraction) {
    Vec3 p;
    const Vec3 centre = 0.5 * (options_.wrist_min_in_head + options_.wrist_max_in_head);
    for (int i = 0; i < 3; ++i) {
      p[i] = centre[i] + position_fraction * rng_.uniform(options_.wrist_min_in_head[i] - centre[i],
                                                         options_.wrist_max_in_head[i] - centre[i]);
    }
    // A random rotation vector inside a ball: tilt away from palm-down,
    // fingers-forward (the wrist frame aligned with the head frame).
    Vec3 axis(rng_.normal(), rng_.normal(), rng_.normal());
    const double n = axis.norm();
    axis = n > 1e-12 ? Vec3(axis / n) : Vec3(Vec3::UnitY());
    const double angle = tilt_fraction * options_.wrist_max_tilt_rad * std::cbrt(rng_.uniform01());
    return Pose{so3_exp(angle * axis), p};
  };

  Keyframe kf;
  switch (options_.protocol) {
    case MotionProtocol::free_motion:
      kf.angles = (k == 0) ? relaxed_ : random_angles();
      kf.T_head_wrist = random_wrist(k == 0 ? 0.0 : 1.0, k == 0 ? 0.0 : 1.0);
      break;
    case MotionProtocol::pinch_grasp: {
      const HandAngles* cycle[] = {&relaxed_, &pinch_, &relaxed_, &tripod_, &relaxed_, &power_};
      kf.angles = *cycle[k % 6];
      kf.T_head_wrist = random_wrist(k == 0 ? 0.0 : 0.3, k == 0 ? 0.0 : 0.3);
      break;
    }
    case MotionProtocol::wrist_sweep:
      kf.angles = relaxed_;
      for (std::size_t i = 0; i < kHandDofCount; ++i) kf.angles[i] += deg_to_rad(rng_.uniform(-5.0, 5.0));
      kf.angles = lim.clamp(kf.angles);
      kf.T_head_wrist = random_wrist(k == 0 ? 0.0 : 1.0, k == 0 ? 0.0 : 1.6);
      break;
  }
  kf.T_head_wrist = mirror_for(options_.hand, kf.T_head_wrist);
  return kf;
}

const HandMotionGenerator::Keyframe& HandMotionGenerator::keyframe(std::size_t k) {
  // Generated strictly in order from one engine, so keyframe k is the same no
  // matter which times were sampled before.
  while (keyframes_.size() <= k) keyframes_.push_back(make_keyframe(keyframes_.size()));
  return keyframes_[k];
}

Pose HandMotionGenerator::head_at(double t) const {
  if (!options_.head_sway) return options_.T_world_head_rest;
  // Slow sway of a seated person: a few degrees and about a centimetre.
  const auto& ph = head_phase_;
  const Vec3 rotation(deg_to_rad(3.0) * std::sin(0.21 * 2 * std::numbers::pi * t + ph[0]),
                      deg_to_rad(5.0) * std::sin(0.13 * 2 * std::numbers::pi * t + ph[1]),
                      deg_to_rad(2.0) * std::sin(0.17 * 2 * std::numbers::pi * t + ph[2]));
  const Vec3 offset(0.010 * std::sin(0.11 * 2 * std::numbers::pi * t + ph[3]), 0.005 * std::sin(0.19 * 2 * std::numbers::pi * t + ph[4]),
                    0.010 * std::sin(0.07 * 2 * std::numbers::pi * t + ph[5]));
  return options_.T_world_head_rest * Pose{so3_exp(rotation), offset};
}

void HandMotionGenerator::state_at(double t, HandAngles& angles, Pose& T_world_wrist, std::size_t& k) {
  t = std::max(t, 0.0);
  const double interval = options_.target_interval_s;
  k = static_cast<std::size_t>(t / interval);
  const double into = t - static_cast<double>(k) * interval;
  const Keyframe& to = keyframe(k);
  Pose T_head_wrist = to.T_head_wrist;
  angles = to.angles;
  const double transition = std::min(options_.transition_s, interval);
  if (k > 0 && into < transition) {  // after the transition the target is held exactly
    const Keyframe& from = keyframes_[k - 1];
    const double s = minimum_jerk(into / transition);
    for (std::size_t i = 0; i < kHandDofCount; ++i) angles[i] = from.angles[i] + s * (to.angles[i] - from.angles[i]);
    T_head_wrist = interpolate(from.T_head_wrist, to.T_head_wrist, s);
  }
  T_world_wrist = options_.T_world_head_rest * T_head_wrist;
}

HandMotionFrame HandMotionGenerator::sample(TimeNs t_ns) {
  HandMotionFrame frame;
  frame.time_ns = t_ns;
  const double t = ns_to_seconds(t_ns);
  state_at(t, frame.angles, frame.T_world_wrist, frame.keyframe);
  frame.T_world_head = head_at(t);
  frame.pose = model_.forward(options_.hand, frame.angles, frame.T_world_wrist, t_ns);

  HandAngles a_minus, a_plus;
  Pose w_minus, w_plus;
  std::size_t unused;
  state_at(t - kVelocityStepS, a_minus, w_minus, unused);
  state_at(t + kVelocityStepS, a_plus, w_plus, unused);
  const auto T_minus = model_.forward(options_.hand, a_minus, w_minus, t_ns);
  const auto T_plus = model_.forward(options_.hand, a_plus, w_plus, t_ns);
  const double dt = 2.0 * kVelocityStepS;
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    frame.pose.linear_velocity_in_world[i] = (T_plus.T_world_joint[i].p - T_minus.T_world_joint[i].p) / dt;
    frame.pose.angular_velocity_in_world[i] =
        so3_log(T_plus.T_world_joint[i].q * T_minus.T_world_joint[i].q.conjugate()) / dt;
  }
  frame.pose.has_velocity = true;
  return frame;
}

}  // namespace proprio::sim
