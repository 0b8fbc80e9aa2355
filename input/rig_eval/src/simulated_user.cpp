#include "proprio/rig_eval/simulated_user.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <functional>

namespace proprio::rig_eval {
namespace {

constexpr double kDegToRad = M_PI / 180.0;
const Vec3 kViewAxis_world = Vec3::UnitY();  // the screen camera looks along +y

Quat user_about(const Vec3& axis, double angle_rad) { return Quat(Eigen::AngleAxisd(angle_rad, axis)); }

// Rotation that takes unit a to unit b along the great circle, scaled to `fraction` of the way.
Quat swing_between(const Vec3& a, const Vec3& b, double fraction = 1.0) {
  const Vec3 n = a.cross(b);
  const double s = n.norm();
  const double angle = std::atan2(s, a.dot(b));
  if (s < 1e-12) {
    if (angle < 1e-9) return Quat::Identity();
    // Opposite: any axis perpendicular to a.
    Vec3 axis = a.unitOrthogonal();
    return user_about(axis, fraction * angle);
  }
  return user_about(n / s, fraction * angle);
}

// Signed angle of q about the local z (q assumed close to a pure z rotation).
double twist_about_z(const Quat& q) {
  return rig_device::wrap_angle_rad(2.0 * std::atan2(q.z(), q.w()));
}

// The threshold for a bone-tip displacement along `dir` (unit): the image-plane
// and depth cues combined as independent cues (inverse variances add).
double cue_threshold(const Vec3& dir, double image_threshold, double depth_threshold) {
  const double c = std::min(1.0, std::abs(dir.dot(kViewAxis_world)));
  const double info = (1.0 - c * c) / (image_threshold * image_threshold) + c * c / (depth_threshold * depth_threshold);
  return 1.0 / std::sqrt(info);
}

double min_jerk(double tau) {
  tau = std::clamp(tau, 0.0, 1.0);
  return tau * tau * tau * (10.0 - 15.0 * tau + 6.0 * tau * tau);
}

struct PerceivedJoint {
  bool off = false;
  Quat q_world_outlet_wanted = Quat::Identity();  // where the person believes the outlet should be
};

// The device's state: each design's dials, and the q_in_out they give.
struct DialState {
  rig_device::JointAngles cardan;
  rig_device::TwistBendTwistAngles tbt;  // bend signed: a hinge bends both ways
};

class TrialSimulator {
 public:
  TrialSimulator(const PosingDevice& device, JointDesign design, const JointRotations& target,
                 const SimulatedUser& user, const TrialOptions& options, Rng& rng, const JointRotations& start)
      : device_(device), design_(design), target_(target), user_(user), options_(options), rng_(rng) {
    pose_ = start.empty() ? straight_pose(device) : start;
    dials_.resize(device.joint_count());
    for (std::size_t j = 0; j < pose_.size(); ++j) {
      dials_[j].cardan = rig_device::joint_angles_for(pose_[j]);
      dials_[j].tbt = rig_device::twist_bend_twist_angles_for(pose_[j]);
      pose_[j] = rotation_of(dials_[j]);
    }
    device_forward_kinematics(device_, target_, T_target_);
    device_forward_kinematics(device_, pose_, T_now_);
    descendants_.resize(device.joint_count());
    const auto& parent = device.skeleton.parent;
    for (std::size_t j = 0; j < device.joint_count(); ++j) {
      const int root = device.joint_node[j];
      for (std::size_t n = 0; n < device.skeleton.size(); ++n) {
        for (int p = parent[n]; p >= 0; p = parent[static_cast<std::size_t>(p)]) {
          if (p == root) {
            descendants_[j].push_back(static_cast<int>(n));
            break;
          }
        }
      }
    }
    result_.design = design;
    result_.initial_error_m = pose_error_m(T_now_, T_target_);
    result_.error.push_back({0.0, result_.initial_error_m});
  }

  TrialResult run() {
    bool satisfied = false;
    while (!out_of_time()) {
      bool moved = false;
      for (std::size_t j = 0; j < device_.joint_count() && !out_of_time(); ++j) {
        moved |= visit(static_cast<int>(j));
      }
      if (!moved && !out_of_time()) {
        satisfied = true;
        break;
      }
    }
    result_.timed_out = !satisfied;
    result_.stop_time_s = std::min(t_, options_.time_limit_s);
    clip_to_limit();
    result_.final_pose = pose_;
    return std::move(result_);
  }

 private:
  Quat rotation_of(const DialState& d) const {
    return design_ == JointDesign::cardan_twist ? rig_device::joint_rotation(d.cardan)
                                                : rig_device::twist_bend_twist_rotation(d.tbt);
  }
  bool out_of_time() const { return t_ >= options_.time_limit_s; }
  std::size_t node_of(int j) const { return static_cast<std::size_t>(device_.joint_node[static_cast<std::size_t>(j)]); }

  // The joint's inlet shaft frame in the world, now.
  Quat inlet_world(int j) const {
    const std::size_t node = node_of(j);
    const int parent = device_.skeleton.parent[node];
    const Quat q_parent = parent < 0 ? Quat::Identity() : T_now_[static_cast<std::size_t>(parent)].q;
    return (q_parent * device_.skeleton.q_parent_node_rest[node]).normalized();
  }

  // Time passes with the pose unchanged.
  void hold(double dt_s) {
    t_ += dt_s;
    result_.error.push_back({t_, result_.error.back().error_m});
  }

  // The joint's q_in_out follows `at(s)` for s in [0, 1] (already shaped by the
  // velocity profile) over `duration_s`; ends on `final_dials`.
  void move(int j, double duration_s, const std::function<Quat(double)>& at, const DialState& final_dials) {
    const auto ju = static_cast<std::size_t>(j);
    const double t0 = t_;
    const int steps = std::max(1, static_cast<int>(std::ceil(duration_s / options_.sample_dt_s)));
    if (options_.record_paths) result_.path.push_back({t0, j, (pose_[ju] * Vec3::UnitZ()).normalized()});
    for (int k = 1; k <= steps; ++k) {
      const double tau = static_cast<double>(k) / steps;
      pose_[ju] = k == steps ? rotation_of(final_dials) : at(min_jerk(tau)).normalized();
      device_forward_kinematics(device_, pose_, T_now_);
      t_ = t0 + tau * duration_s;
      result_.error.push_back({t_, pose_error_m(T_now_, T_target_)});
      if (options_.record_paths) result_.path.push_back({t_, j, (pose_[ju] * Vec3::UnitZ()).normalized()});
    }
    dials_[ju] = final_dials;
    ++result_.movements;
  }

  double movement_time(double angle_rad) const {
    // Minimum jerk: peak speed = 1.875 x mean speed.
    return std::max(user_.min_movement_s, 1.875 * std::abs(angle_rad) / user_.peak_speed_rad_s);
  }
  double motor_sd(double angle_rad) const {
    return user_.motor_noise_floor_rad + user_.motor_noise_fraction * std::abs(angle_rad);
  }
  // A perceived error component: unseen below its threshold, else noisy.
  double perceive_component(double value, double threshold) {
    const double sd = user_.perception_weber_fraction * std::abs(value) + user_.perception_floor_thresholds * threshold;
    const double seen = value + rng_.normal(0.0, sd);
    return std::abs(seen) < threshold ? 0.0 : seen;
  }

  void grasp(int j) {
    if (hand_joint_ == j) return;
    hold(user_.regrasp_s);
    ++result_.regrasps;
    hand_joint_ = j;
    hand_dial_ = -1;
  }

  // One look at joint j: what the person sees of its error, and where they
  // then want its outlet (in the world).
  PerceivedJoint look(int j) {
    hold(user_.fixation_s);
    ++result_.looks;
    const std::size_t node = node_of(j);
    const Quat W = T_now_[node].q;
    const Quat W_target = T_target_[node].q;
    const Vec3 d = (W * Vec3::UnitZ()).normalized();
    const Vec3 d_target = (W_target * Vec3::UnitZ()).normalized();

    // Swing: the tangent displacement of the bone's direction.
    const Vec3 n = d.cross(d_target);
    const double swing = std::atan2(n.norm(), d.dot(d_target));
    const Vec3 a = n.norm() > 1e-12 ? Vec3(swing * (n.normalized().cross(d))) : Vec3::Zero();
    Vec3 u1 = kViewAxis_world.cross(d);
    u1 = u1.norm() > 1e-9 ? u1.normalized() : d.unitOrthogonal();
    const Vec3 u2 = d.cross(u1).normalized();
    const double th1 = cue_threshold(u1, user_.image_threshold_rad, user_.depth_threshold_rad);
    const double th2 = cue_threshold(u2, user_.image_threshold_rad, user_.depth_threshold_rad);
    const Vec3 p = perceive_component(a.dot(u1), th1) * u1 + perceive_component(a.dot(u2), th2) * u2;

    // Twist about the bone, seen by how far the descendants sit off its axis.
    const Quat transported = swing_between(d, d_target) * W;
    const double twist = twist_about_z(transported.conjugate() * W_target);
    const Vec3 p_joint = T_now_[node].p;
    double lever = 0.0;
    double reach = 0.0;
    Vec3 twist_dir = u1;
    for (const int dn : descendants_[static_cast<std::size_t>(j)]) {
      const Vec3 r = T_now_[static_cast<std::size_t>(dn)].p - p_joint;
      const Vec3 off_axis = r - r.dot(d) * d;
      reach = std::max(reach, r.norm());
      if (off_axis.norm() > lever) {
        lever = off_axis.norm();
        twist_dir = d.cross(off_axis).normalized();
      }
    }
    const double visibility = reach > 0.0 ? std::max(lever / reach, 0.05) : 0.05;
    const double th_twist =
        cue_threshold(twist_dir, user_.image_threshold_rad, user_.depth_threshold_rad) / visibility;
    const double twist_seen = perceive_component(twist, th_twist);

    PerceivedJoint out;
    out.off = p.norm() > 0.0 || twist_seen != 0.0;
    const Quat swing_seen = p.norm() > 0.0 ? user_about(d.cross(p).normalized(), p.norm()) : Quat::Identity();
    out.q_world_outlet_wanted = (swing_seen * W * user_about(Vec3::UnitZ(), twist_seen)).normalized();
    return out;
  }

  // The wanted q_in_out, from the wanted world outlet frame and the joint's inlet now.
  Quat wanted_in_out(int j, const PerceivedJoint& seen) const {
    return (inlet_world(j).conjugate() * seen.q_world_outlet_wanted).normalized();
  }

  // A visit: up to max_attempts look-and-correct rounds. True when anything moved.
  bool visit(int j) {
    bool moved = false;
    for (int attempt = 0; attempt < user_.max_attempts_per_visit && !out_of_time(); ++attempt) {
      const bool acted = design_ == JointDesign::cardan_twist ? attempt_cardan(j) : attempt_twist_bend_twist(j);
      if (!acted) break;
      moved = true;
    }
    return moved;
  }

  // Ours: one movement of the outlet: geodesic swing plus the wrist's twist.
  bool attempt_cardan(int j) {
    const PerceivedJoint seen = look(j);
    if (!seen.off) return false;
    grasp(j);
    const auto ju = static_cast<std::size_t>(j);
    const Quat q0 = pose_[ju];
    const Quat q_want = wanted_in_out(j, seen);
    const Vec3 d0 = (q0 * Vec3::UnitZ()).normalized();
    const Vec3 d_want = (q_want * Vec3::UnitZ()).normalized();
    const double swing_want = std::atan2(d0.cross(d_want).norm(), d0.dot(d_want));
    const double twist_want = twist_about_z((swing_between(d0, d_want) * q0).conjugate() * q_want);
    // Signal-dependent endpoint noise, per axis of the tangent plane and on the twist.
    Vec3 e1 = d_want.unitOrthogonal();
    const Vec3 e2 = d_want.cross(e1);
    const Vec3 slip = rng_.normal(0.0, motor_sd(swing_want)) * e1 + rng_.normal(0.0, motor_sd(swing_want)) * e2;
    const Vec3 d_end = slip.norm() > 0.0 ? (user_about(d_want.cross(slip).normalized(), slip.norm()) * d_want).normalized()
                                         : d_want;
    const double twist_end = twist_want + rng_.normal(0.0, motor_sd(twist_want));
    const double swing_end = std::atan2(d0.cross(d_end).norm(), d0.dot(d_end));
    // The wrist turns at most one grip's worth with the swing; the rest follows in re-grips.
    const double grip = user_.max_turn_per_grip_rad;
    double twist_now = std::clamp(twist_end, -grip, grip);
    const Quat swing_q = swing_between(d0, d_end);
    hold(user_.reaction_time_s);
    {
      const double tw = twist_now;
      const Quat q_end = (swing_q * q0 * user_about(Vec3::UnitZ(), tw)).normalized();
      DialState end = dials_[ju];
      end.cardan = rig_device::joint_angles_for(q_end, end.cardan.twist_in_rad);
      move(j, movement_time(std::max(swing_end, std::abs(tw))),
           [&](double s) { return swing_between(d0, d_end, s) * q0 * user_about(Vec3::UnitZ(), s * tw); }, end);
    }
    double twist_left = twist_end - twist_now;
    while (std::abs(twist_left) > 1e-9 && !out_of_time()) {
      const double tw = std::clamp(twist_left, -grip, grip);
      hold(user_.dial_switch_s);  // re-grip the outlet
      const Quat qs = pose_[ju];
      const Quat q_end = (qs * user_about(Vec3::UnitZ(), tw)).normalized();
      DialState end = dials_[ju];
      end.cardan = rig_device::joint_angles_for(q_end, end.cardan.twist_in_rad);
      move(j, movement_time(tw), [&](double s) { return qs * user_about(Vec3::UnitZ(), s * tw); }, end);
      twist_left -= tw;
    }
    return true;
  }

  // Theirs: turn one dial (0 twist_a, 1 bend, 2 twist_b) by `delta`, with
  // endpoint noise, in grips of at most max_turn_per_grip for the twists.
  void turn_dial(int j, int dial, double delta) {
    const auto ju = static_cast<std::size_t>(j);
    delta += rng_.normal(0.0, motor_sd(delta));
    if (hand_dial_ != dial) {
      if (hand_dial_ >= 0) hold(user_.dial_switch_s);
      hand_dial_ = dial;
    }
    hold(user_.reaction_time_s);
    const double grip = dial == 1 ? M_PI : user_.max_turn_per_grip_rad;
    bool first = true;
    while (std::abs(delta) > 1e-12 && !out_of_time()) {
      if (!first) hold(user_.dial_switch_s);
      first = false;
      const double step = std::clamp(delta, -grip, grip);
      const rig_device::TwistBendTwistAngles from = dials_[ju].tbt;
      DialState end = dials_[ju];
      double* angle = dial == 0 ? &end.tbt.twist_a_rad : dial == 1 ? &end.tbt.bend_rad : &end.tbt.twist_b_rad;
      *angle += step;
      if (dial == 1) end.tbt.bend_rad = std::clamp(end.tbt.bend_rad, -kMaxHingeRad, kMaxHingeRad);
      const rig_device::TwistBendTwistAngles to = end.tbt;
      move(j, movement_time(step),
           [&](double s) {
             rig_device::TwistBendTwistAngles a = from;
             a.twist_a_rad += s * (to.twist_a_rad - from.twist_a_rad);
             a.bend_rad += s * (to.bend_rad - from.bend_rad);
             a.twist_b_rad += s * (to.twist_b_rad - from.twist_b_rad);
             return rig_device::twist_bend_twist_rotation(a);
           },
           end);
      delta -= step;
    }
  }

  // Theirs: one round of plane, bend, twist, each judged by eye afresh. True
  // when a dial was turned (a round whose later looks find nothing to do ends the visit).
  bool attempt_twist_bend_twist(int j) {
    const auto ju = static_cast<std::size_t>(j);
    const int movements_before = result_.movements;
    PerceivedJoint seen = look(j);
    if (!seen.off) return false;
    grasp(j);
    // 1. The bend plane: visible only once the bone is visibly bent.
    {
      const rig_device::TwistBendTwistAngles& now = dials_[ju].tbt;
      const Vec3 d_want = (wanted_in_out(j, seen) * Vec3::UnitZ()).normalized();
      const double polar_want = std::acos(std::clamp(d_want.z(), -1.0, 1.0));
      const double bent = std::abs(now.bend_rad);
      if (bent > user_.image_threshold_rad && polar_want > 1e-6) {
        // The bone's azimuth about the inlet shaft, as seen: a short or
        // steep bone shows its direction poorly.
        const double azimuth_bone = now.twist_a_rad + (now.bend_rad > 0 ? -M_PI / 2 : M_PI / 2);
        const double azimuth_seen =
            azimuth_bone + rng_.normal(0.0, user_.perception_floor_thresholds * user_.image_threshold_rad / std::sin(std::min(bent, M_PI / 2)));
        double delta = rig_device::wrap_angle_rad(std::atan2(d_want.y(), d_want.x()) - azimuth_seen);
        // The hinge bends both ways: align the plane, not the side.
        if (delta > M_PI / 2) delta -= M_PI;
        if (delta < -M_PI / 2) delta += M_PI;
        if (std::abs(delta) * std::sin(std::min(polar_want, M_PI / 2)) > user_.image_threshold_rad) turn_dial(j, 0, delta);
      }
    }
    // 2. The bend, judged afresh.
    if (!out_of_time()) {
      seen = look(j);
      const rig_device::TwistBendTwistAngles& now = dials_[ju].tbt;
      const Vec3 d_want = (wanted_in_out(j, seen) * Vec3::UnitZ()).normalized();
      const double polar_want = std::acos(std::clamp(d_want.z(), -1.0, 1.0));
      double side;
      if (std::abs(now.bend_rad) > user_.image_threshold_rad) {
        // The side of the hinge plane the wanted bone is on.
        const Vec3 positive(std::sin(now.twist_a_rad), -std::cos(now.twist_a_rad), 0.0);
        side = positive.dot(d_want) >= 0.0 ? 1.0 : -1.0;
      } else {
        side = rng_.uniform01() < 0.5 ? 1.0 : -1.0;  // a straight hinge shows no side
      }
      const double delta = side * polar_want - now.bend_rad;
      if (seen.off && std::abs(delta) > user_.image_threshold_rad) turn_dial(j, 1, delta);
    }
    // 3. The outlet's twist, judged afresh.
    if (!out_of_time()) {
      seen = look(j);
      if (seen.off) {
        const Quat q0 = pose_[ju];
        const Quat q_want = wanted_in_out(j, seen);
        const Vec3 d0 = (q0 * Vec3::UnitZ()).normalized();
        const Vec3 d_want = (q_want * Vec3::UnitZ()).normalized();
        const double delta = twist_about_z((swing_between(d0, d_want) * q0).conjugate() * q_want);
        if (delta != 0.0) turn_dial(j, 2, delta);
      }
    }
    return result_.movements > movements_before;
  }

  void clip_to_limit() {
    auto& e = result_.error;
    const double limit = options_.time_limit_s;
    for (std::size_t i = 1; i < e.size(); ++i) {
      if (e[i].t_s > limit) {
        const double f = (limit - e[i - 1].t_s) / std::max(e[i].t_s - e[i - 1].t_s, 1e-12);
        e[i].error_m = e[i - 1].error_m + f * (e[i].error_m - e[i - 1].error_m);
        e[i].t_s = limit;
        e.resize(i + 1);
        break;
      }
    }
  }

  static constexpr double kMaxHingeRad = 135.0 * kDegToRad;

  const PosingDevice& device_;
  JointDesign design_;
  const JointRotations& target_;
  const SimulatedUser& user_;
  const TrialOptions& options_;
  Rng& rng_;
  JointRotations pose_;
  std::vector<DialState> dials_;
  std::vector<Pose> T_target_;
  std::vector<Pose> T_now_;
  std::vector<std::vector<int>> descendants_;
  double t_ = 0.0;
  int hand_joint_ = -1;
  int hand_dial_ = -1;
  TrialResult result_;
};

double lognormal_factor(Rng& rng, double sd) { return sd > 0.0 ? std::exp(rng.normal(0.0, sd)) : 1.0; }

}  // namespace

const char* to_string(JointDesign design) {
  switch (design) {
    case JointDesign::cardan_twist: return "cardan_twist";
    case JointDesign::twist_bend_twist: return "twist_bend_twist";
  }
  return "?";
}

Status UserModelOptions::validate() const {
  const auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  const auto non_negative = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (!positive(image_threshold_deg) || !positive(depth_threshold_deg) || image_threshold_deg > 45.0 ||
      depth_threshold_deg > 90.0) {
    return make_error(Errc::invalid_argument,
                      "simulated user: the image and depth thresholds must be > 0 deg (at most 45 and 90)");
  }
  if (!non_negative(perception_weber_fraction) || perception_weber_fraction > 1.0 ||
      !non_negative(perception_floor_thresholds) || perception_floor_thresholds > 2.0) {
    return make_error(Errc::invalid_argument,
                      "simulated user: perception_weber_fraction must be in [0, 1], perception_floor_thresholds in [0, 2]");
  }
  if (!non_negative(fixation_s) || !non_negative(reaction_time_s) || !non_negative(regrasp_s) ||
      !non_negative(dial_switch_s) || !positive(min_movement_s) || fixation_s + reaction_time_s + regrasp_s > 60.0) {
    return make_error(Errc::invalid_argument,
                      "simulated user: times must be >= 0 s (min_movement_s > 0) and a look, reaction and re-grasp under 60 s");
  }
  if (!positive(peak_speed_deg_s) || peak_speed_deg_s > 5000.0 || !positive(max_turn_per_grip_deg) ||
      max_turn_per_grip_deg > 360.0) {
    return make_error(Errc::invalid_argument,
                      "simulated user: peak_speed_deg_s must be in (0, 5000], max_turn_per_grip_deg in (0, 360]");
  }
  if (!non_negative(motor_noise_floor_deg) || motor_noise_floor_deg > 30.0 || !non_negative(motor_noise_fraction) ||
      motor_noise_fraction > 1.0) {
    return make_error(Errc::invalid_argument,
                      "simulated user: motor_noise_floor_deg must be in [0, 30], motor_noise_fraction in [0, 1]");
  }
  if (max_attempts_per_visit < 1 || max_attempts_per_visit > 100) {
    return make_error(Errc::invalid_argument, "simulated user: max_attempts_per_visit must be 1-100");
  }
  if (!non_negative(participant_spread) || participant_spread > 1.0) {
    return make_error(Errc::invalid_argument, "simulated user: participant_spread must be in [0, 1]");
  }
  return {};
}

std::string UserModelOptions::describe() const {
  return fmt::format(
      "simulated user: sees bone errors above {:g} deg in the image plane, {:g} deg in depth (noise {:g} x error + "
      "{:g} threshold); looks {:g} s, reacts {:g} s, re-grasps {:g} s, switches dial {:g} s; minimum-jerk moves of "
      ">= {:g} s at <= {:g} deg/s peak, <= {:g} deg per grip, endpoint SD {:g} deg + {:g} x rotation; <= {} "
      "attempts per joint visit; participants spread by log-normal SD {:g}",
      image_threshold_deg, depth_threshold_deg, perception_weber_fraction, perception_floor_thresholds, fixation_s,
      reaction_time_s, regrasp_s, dial_switch_s, min_movement_s, peak_speed_deg_s, max_turn_per_grip_deg,
      motor_noise_floor_deg, motor_noise_fraction, max_attempts_per_visit, participant_spread);
}

SimulatedUser typical_user(const UserModelOptions& o) {
  SimulatedUser u;
  u.image_threshold_rad = o.image_threshold_deg * kDegToRad;
  u.depth_threshold_rad = o.depth_threshold_deg * kDegToRad;
  u.perception_weber_fraction = o.perception_weber_fraction;
  u.perception_floor_thresholds = o.perception_floor_thresholds;
  u.fixation_s = o.fixation_s;
  u.reaction_time_s = o.reaction_time_s;
  u.regrasp_s = o.regrasp_s;
  u.dial_switch_s = o.dial_switch_s;
  u.min_movement_s = o.min_movement_s;
  u.peak_speed_rad_s = o.peak_speed_deg_s * kDegToRad;
  u.max_turn_per_grip_rad = o.max_turn_per_grip_deg * kDegToRad;
  u.motor_noise_floor_rad = o.motor_noise_floor_deg * kDegToRad;
  u.motor_noise_fraction = o.motor_noise_fraction;
  u.max_attempts_per_visit = o.max_attempts_per_visit;
  return u;
}

SimulatedUser draw_participant(const UserModelOptions& o, Rng& rng) {
  SimulatedUser u = typical_user(o);
  const double sd = o.participant_spread;
  // One factor per trait: how keenly they see, how steadily they move, how fast they move, how quickly they act.
  const double seeing = lognormal_factor(rng, sd);
  const double steadiness = lognormal_factor(rng, sd);
  const double speed = lognormal_factor(rng, sd);
  const double pace = lognormal_factor(rng, sd);
  u.image_threshold_rad *= seeing;
  u.depth_threshold_rad *= seeing;
  u.motor_noise_floor_rad *= steadiness;
  u.motor_noise_fraction *= steadiness;
  u.peak_speed_rad_s *= speed;
  u.fixation_s *= pace;
  u.reaction_time_s *= pace;
  u.regrasp_s *= pace;
  u.dial_switch_s *= pace;
  u.min_movement_s *= pace;
  return u;
}

Status TrialOptions::validate() const {
  if (!std::isfinite(time_limit_s) || time_limit_s <= 0.0 || time_limit_s > 24 * 3600.0) {
    return make_error(Errc::invalid_argument, "posing trial: time_limit_s must be in (0, 86400]");
  }
  if (!std::isfinite(sample_dt_s) || sample_dt_s < 1e-3 || sample_dt_s > 1.0) {
    return make_error(Errc::invalid_argument, "posing trial: sample_dt_s must be in [0.001, 1]");
  }
  return {};
}

TrialResult simulate_trial(const PosingDevice& device, JointDesign design, const JointRotations& target,
                           const SimulatedUser& user, const TrialOptions& options, Rng& rng,
                           const JointRotations& start) {
  assert(target.size() == device.joint_count());
  assert(start.empty() || start.size() == device.joint_count());
  TrialSimulator sim(device, design, target, user, options, rng, start);
  return sim.run();
}

double outlet_path_length_rad(const std::vector<OutletPathSample>& path, int joint) {
  double length = 0.0;
  const OutletPathSample* last = nullptr;
  for (const auto& s : path) {
    if (s.joint != joint) continue;
    if (last != nullptr) length += std::atan2(last->d_in_inlet.cross(s.d_in_inlet).norm(), last->d_in_inlet.dot(s.d_in_inlet));
    last = &s;
  }
  return length;
}

}  // namespace proprio::rig_eval
