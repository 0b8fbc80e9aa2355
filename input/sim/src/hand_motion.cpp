#include "proprio/sim/hand_motion.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>

namespace proprio::sim {

namespace hand_motion_detail {

// d/dtau of minimum_jerk: 30 tau^2 (1 - tau)^2, zero outside [0, 1].
double minimum_jerk_rate(double tau) noexcept {
  if (tau <= 0.0 || tau >= 1.0) return 0.0;
  const double a = tau * (1.0 - tau);
  return 30.0 * a * a;
}

// The contact stop of a minimum-jerk move of duration D aimed past contact
// (reached at progress s_contact < 1): the stop begins at the tau where
// coasting to rest with uniform deceleration over stop_s ends exactly at
// s_contact, m(tau) + m'(tau) stop_s / (2 D) = s_contact. That function rises
// from 0 at tau = 0 to above s_contact where m(tau) = s_contact; bisection.
ContactMove make_contact_move(double duration_s, double s_contact, double stop_s) {
  ContactMove c;
  c.duration_s = duration_s;
  c.s_contact = s_contact;
  const double k = stop_s / (2.0 * duration_s);
  double lo = 0.0, hi = 1.0;
  for (int i = 0; i < 80; ++i) {  // tau where m(tau) = s_contact
    const double mid = 0.5 * (lo + hi);
    (minimum_jerk(mid) < s_contact ? lo : hi) = mid;
  }
  const double tau_contact = hi;
  lo = 0.0;
  for (int i = 0; i < 80; ++i) {
    const double mid = 0.5 * (lo + hi);
    (minimum_jerk(mid) + minimum_jerk_rate(mid) * k < s_contact ? lo : hi) = mid;
  }
  const double tau_b = std::min(lo, tau_contact);
  c.stop_begin_s = tau_b * duration_s;
  c.s_begin = minimum_jerk(tau_b);
  // The rate that coasts exactly to s_contact in stop_s (equal to m'(tau_b) / D
  // up to the bisection's tolerance), so the rest position is exact.
  c.rate_begin = std::max(0.0, 2.0 * (s_contact - c.s_begin) / stop_s);
  c.rest_s = c.stop_begin_s + stop_s;
  return c;
}

// Progress (fraction of the aimed displacement, 0..s_contact) t seconds into
// the move. Without stops: a minimum-jerk settle on s_contact over the same
// time to rest.
double contact_progress(const ContactMove& c, double t, bool stops) noexcept {
  if (t >= c.rest_s) return c.s_contact;
  if (t <= 0.0) return 0.0;
  if (!stops) return c.s_contact * minimum_jerk(t / c.rest_s);
  if (t < c.stop_begin_s) return minimum_jerk(t / c.duration_s);
  const double u = t - c.stop_begin_s;
  const double stop_s = c.rest_s - c.stop_begin_s;
  return std::min(c.s_contact, c.s_begin + c.rate_begin * u - 0.5 * (c.rate_begin / stop_s) * u * u);
}

// Out and back: minimum jerk to 1 over the first half, back to 0 over the second.
double out_and_back(double tau) noexcept {
  if (tau <= 0.0 || tau >= 1.0) return 0.0;
  return tau < 0.5 ? minimum_jerk(2.0 * tau) : minimum_jerk(2.0 - 2.0 * tau);
}

// Tremor channels: 0-2 wrist translation, 3-5 wrist rotation (both in the
// wrist frame), 6-10 finger flexion (thumb..little).
std::array<double, Tremor::kChannels> tremor_channels(const Tremor& tr, double modulation, double t) noexcept {
  std::array<double, Tremor::kChannels> c{};
  for (std::size_t k = 0; k < Tremor::kComponents; ++k) {
    const double w = 2.0 * std::numbers::pi * tr.frequency_hz[k] * t;
    const double sn = std::sin(w), cs = std::cos(w);
    const double m =
        1.0 + modulation * std::sin(2.0 * std::numbers::pi * tr.modulation_hz[k] * t + tr.modulation_phase[k]);
    for (std::size_t i = 0; i < Tremor::kChannels; ++i) c[i] += m * (tr.a_cos[i][k] * sn + tr.a_sin[i][k] * cs);
  }
  return c;
}

// The flexion DOFs of a finger (thumb: CMC flexion, MCP, IP) and how much of
// a finger-wide flexion each takes (DIP at 2/3 of PIP).
constexpr std::array<std::size_t, 3> kFlexionOffsets = {0, 2, 3};
constexpr std::array<double, 3> kTremorFlexionWeights = {1.0, 1.0, 2.0 / 3.0};
// A flick's share per joint; sums to 1, so the distal segment turns by the
// whole amplitude relative to the hand.
constexpr std::array<double, 3> kFlickFlexionWeights = {0.375, 0.375, 0.25};

// The tapping finger's start: hovering, extended this far from contact.
constexpr double kTapStartPhi = -0.35;

}  // namespace hand_motion_detail

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
    case MotionProtocol::natural: return "natural";
    case MotionProtocol::tapping: return "tapping";
    case MotionProtocol::pinch_grasp_contact: return "pinch-grasp-contact";
  }
  return "?";
}

std::optional<MotionProtocol> parse_motion_protocol(std::string_view s) noexcept {
  for (auto p : kMotionProtocols) {
    if (s == to_string(p)) return p;
  }
  return std::nullopt;
}

std::vector<std::string> motion_protocol_names() {
  std::vector<std::string> names;
  for (auto p : kMotionProtocols) names.emplace_back(to_string(p));
  return names;
}

Status HandMotionOptions::validate() const {
  auto bad = [](const char* what, double v, const char* range) {
    char buf[200];
    std::snprintf(buf, sizeof buf, "hand motion options: %s is %g; it must be %s", what, v, range);
    return Status(make_error(Errc::invalid_argument, buf));
  };
  auto in = [](double v, double lo, double hi) { return v >= lo && v <= hi; };  // false for NaN
  auto pair = [&](const char* lo_name, double lo, const char* hi_name, double hi) -> Status {
    if (!(lo <= hi)) {
      return make_error(Errc::invalid_argument, std::string("hand motion options: ") + lo_name + " (" +
                                                    std::to_string(lo) + ") is above " + hi_name + " (" +
                                                    std::to_string(hi) + ")");
    }
    return {};
  };
  struct Check {
    const char* name;
    double value, lo, hi;
    const char* range;
  };
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const Check checks[] = {
      {"target_interval_s", target_interval_s, 1e-3, 3600.0, "in 0.001..3600 s"},
      {"transition_s", transition_s, 1e-3, 3600.0, "in 0.001..3600 s"},
      {"limit_fraction", limit_fraction, 0.0, 1.0, "in 0..1"},
      {"dip_deviation_rad", dip_deviation_rad, 0.0, 1.0, "in 0..1 rad"},
      {"thumb_ip_deviation_rad", thumb_ip_deviation_rad, 0.0, 1.0, "in 0..1 rad"},
      {"enslaved_deviation_rad", enslaved_deviation_rad, 0.0, 1.0, "in 0..1 rad"},
      {"wrist_max_tilt_rad", wrist_max_tilt_rad, 0.0, std::numbers::pi, "in 0..pi rad"},
      {"submovement_min_s", submovement_min_s, 0.01, 60.0, "in 0.01..60 s"},
      {"submovement_max_s", submovement_max_s, 0.01, 60.0, "in 0.01..60 s"},
      {"submovement_onset_min", submovement_onset_min, 0.05, 1.0, "in 0.05..1 (a fraction of the duration)"},
      {"submovement_onset_max", submovement_onset_max, 0.05, 1.0, "in 0.05..1 (a fraction of the duration)"},
      {"hold_probability", hold_probability, 0.0, 1.0, "in 0..1"},
      {"hold_min_s", hold_min_s, 0.0, 60.0, "in 0..60 s"},
      {"hold_max_s", hold_max_s, 0.0, 60.0, "in 0..60 s"},
      {"tremor_rms_m", tremor_rms_m, 0.0, 0.01, "in 0..0.01 m"},
      {"tremor_min_hz", tremor_min_hz, 0.1, 100.0, "in 0.1..100 Hz"},
      {"tremor_max_hz", tremor_max_hz, 0.1, 100.0, "in 0.1..100 Hz"},
      {"tremor_modulation", tremor_modulation, 0.0, 1.0, "in 0..1"},
      {"flick_interval_min_s", flick_interval_min_s, 0.01, 3600.0, "in 0.01..3600 s"},
      {"flick_interval_max_s", flick_interval_max_s, 0.01, 3600.0, "in 0.01..3600 s"},
      {"flick_min_s", flick_min_s, 0.005, 2.0, "in 0.005..2 s"},
      {"flick_max_s", flick_max_s, 0.005, 2.0, "in 0.005..2 s"},
      {"flick_peak_min_deg_s", flick_peak_min_deg_s, 0.0, 10000.0, "in 0..10000 deg/s"},
      {"flick_peak_max_deg_s", flick_peak_max_deg_s, 0.0, 10000.0, "in 0..10000 deg/s"},
      {"flick_wrist_fraction", flick_wrist_fraction, 0.0, 1.0, "in 0..1"},
      {"contact_stop_s", contact_stop_s, 1e-3, 0.2, "in 0.001..0.2 s"},
      {"contact_aim_beyond", contact_aim_beyond, 0.0, 2.0, "in 0..2 (a fraction of the move)"},
      {"table_height_in_head_m", table_height_in_head_m, -kInf, kInf, "finite"},
      {"tap_hover_m", tap_hover_m, 0.0, 0.1, "in 0..0.1 m"},
      {"tap_shift_m", tap_shift_m, 0.0, 0.3, "in 0..0.3 m"},
      {"tap_lift_min_rad", tap_lift_min_rad, 0.01, 0.6, "in 0.01..0.6 rad"},
      {"tap_lift_max_rad", tap_lift_max_rad, 0.01, 0.6, "in 0.01..0.6 rad"},
      {"tap_up_min_s", tap_up_min_s, 0.01, 10.0, "in 0.01..10 s"},
      {"tap_up_max_s", tap_up_max_s, 0.01, 10.0, "in 0.01..10 s"},
      {"tap_down_min_s", tap_down_min_s, 0.01, 10.0, "in 0.01..10 s"},
      {"tap_down_max_s", tap_down_max_s, 0.01, 10.0, "in 0.01..10 s"},
      {"tap_dwell_min_s", tap_dwell_min_s, 0.0, 10.0, "in 0..10 s"},
      {"tap_dwell_max_s", tap_dwell_max_s, 0.0, 10.0, "in 0..10 s"},
  };
  for (const Check& c : checks) {
    if (!std::isfinite(c.value) || !in(c.value, c.lo, c.hi)) return bad(c.name, c.value, c.range);
  }
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(wrist_min_in_head[i]) || !std::isfinite(wrist_max_in_head[i]) ||
        !(wrist_min_in_head[i] <= wrist_max_in_head[i])) {
      return make_error(Errc::invalid_argument,
                        "hand motion options: the wrist workspace needs finite wrist_min_in_head <= wrist_max_in_head "
                        "on every axis");
    }
  }
  if (!T_world_head_rest.p.allFinite() || !T_world_head_rest.q.coeffs().allFinite() ||
      std::abs(T_world_head_rest.q.norm() - 1.0) > 1e-6) {
    return make_error(Errc::invalid_argument,
                      "hand motion options: T_world_head_rest needs a finite position and a unit quaternion");
  }
  for (const Status& st :
       {pair("submovement_min_s", submovement_min_s, "submovement_max_s", submovement_max_s),
        pair("submovement_onset_min", submovement_onset_min, "submovement_onset_max", submovement_onset_max),
        pair("hold_min_s", hold_min_s, "hold_max_s", hold_max_s),
        pair("tremor_min_hz", tremor_min_hz, "tremor_max_hz", tremor_max_hz),
        pair("flick_interval_min_s", flick_interval_min_s, "flick_interval_max_s", flick_interval_max_s),
        pair("flick_min_s", flick_min_s, "flick_max_s", flick_max_s),
        pair("flick_peak_min_deg_s", flick_peak_min_deg_s, "flick_peak_max_deg_s", flick_peak_max_deg_s),
        pair("flick_max_s", flick_max_s, "flick_interval_min_s", flick_interval_min_s),
        pair("tap_lift_min_rad", tap_lift_min_rad, "tap_lift_max_rad", tap_lift_max_rad),
        pair("tap_up_min_s", tap_up_min_s, "tap_up_max_s", tap_up_max_s),
        pair("tap_down_min_s", tap_down_min_s, "tap_down_max_s", tap_down_max_s),
        pair("tap_dwell_min_s", tap_dwell_min_s, "tap_dwell_max_s", tap_dwell_max_s)}) {
    if (!st) return st;
  }
  if (tap_finger == Finger::thumb || static_cast<std::size_t>(tap_finger) >= kFingerCount) {
    return make_error(Errc::invalid_argument, "hand motion options: tap_finger must be index, middle, ring or little");
  }
  return {};
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
  std::string out = buf;
  std::snprintf(buf, sizeof buf,
                " natural(submovement=%.2f-%.2fs onset=%.2f-%.2f hold_p=%.2f hold=%.2f-%.2fs)"
                " tremor=%s(rms=%.3fmm %.1f-%.1fHz modulation=%.2f)"
                " flicks=%s(every %.1f-%.1fs %.0f-%.0fms peak=%.0f-%.0fdeg/s wrist_share=%.2f)",
                submovement_min_s, submovement_max_s, submovement_onset_min, submovement_onset_max, hold_probability,
                hold_min_s, hold_max_s, tremor ? "on" : "off", tremor_rms_m * 1e3, tremor_min_hz, tremor_max_hz,
                tremor_modulation, flicks ? "on" : "off", flick_interval_min_s, flick_interval_max_s, flick_min_s * 1e3,
                flick_max_s * 1e3, flick_peak_min_deg_s, flick_peak_max_deg_s, flick_wrist_fraction);
  out += buf;
  std::snprintf(buf, sizeof buf,
                " contact_stops=%s(stop=%.1fms aim_beyond=%.2f)"
                " tapping(finger=%s table=%.3fm hover=%.1fmm shift=%.1fmm lift=%.1f-%.1fdeg up=%.2f-%.2fs "
                "down=%.2f-%.2fs dwell=%.2f-%.2fs)",
                contact_stops ? "on" : "off", contact_stop_s * 1e3, contact_aim_beyond,
                std::string(proprio::to_string(tap_finger)).c_str(), table_height_in_head_m, tap_hover_m * 1e3,
                tap_shift_m * 1e3, rad_to_deg(tap_lift_min_rad), rad_to_deg(tap_lift_max_rad), tap_up_min_s,
                tap_up_max_s, tap_down_min_s, tap_down_max_s, tap_dwell_min_s, tap_dwell_max_s);
  out += buf;
  return out;
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
  const double contact =
      shape.fingers[0].joint_radius_m[3] + shape.fingers[static_cast<std::size_t>(finger)].joint_radius_m[4];
  constexpr double kRegularisation = 0.01;  // metres of gap per radian of deviation

  auto residuals = [&](const HandAngles& a) {
    HandAngles full = a;
    full[f0 + 3] = (2.0 / 3.0) * full[f0 + 2];
    const auto T = model.joint_poses_in_wrist(Handedness::right, full);
    Eigen::Matrix<double, 7, 1> r;
    r(0) = (T[index_of(thumb_tip)].p - T[index_of(finger_tip)].p).norm() - contact;
    for (std::size_t i = 0; i < vars.size(); ++i)
      r(static_cast<Eigen::Index>(i + 1)) = kRegularisation * (a[vars[i]] - start[vars[i]]);
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
    const Eigen::Matrix<double, 6, 1> step = -(H + lambda * Eigen::Matrix<double, 6, 6>::Identity()).ldlt().solve(g);
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
    : model_(std::move(model)),
      options_(options),
      rng_(mix_seed(options.seed, 0)),
      submovement_rng_(mix_seed(options.seed, 2)),
      flick_rng_(mix_seed(options.seed, 4)),
      tap_rng_(mix_seed(options.seed, 5)) {
  // Postures in degrees, DOF order of HandDof.
  relaxed_ = degrees({10, 10, 10, 10, 15, 5, 20, 10, 15, 0, 20, 10, 15, -3, 20, 10, 15, -8, 20, 10});
  const HandAngles pinch_start =
      degrees({30, 25, 20, 15, 40, 0, 40, 27, 30, 0, 45, 30, 30, -3, 45, 30, 30, -8, 45, 30});
  pinch_ = pinch_start;
  tripod_ = pinch_start;
  const bool pinching =
      options_.protocol == MotionProtocol::pinch_grasp || options_.protocol == MotionProtocol::pinch_grasp_contact;
  if (pinching) {  // the solve is the costly part of construction
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
  if (options_.protocol == MotionProtocol::natural) setup_tremor();
  if (options_.protocol == MotionProtocol::tapping) setup_tapping();
  if (options_.protocol == MotionProtocol::pinch_grasp_contact) {
    grasp_move_ =
        hand_motion_detail::make_contact_move(std::min(options_.transition_s, options_.target_interval_s),
                                              1.0 / (1.0 + options_.contact_aim_beyond), options_.contact_stop_s);
  }
}

Result<HandMotionGenerator> HandMotionGenerator::create(HandModel model, HandMotionOptions options) {
  if (auto st = options.validate(); !st) return st.error();
  return HandMotionGenerator(std::move(model), options);
}

double HandMotionGenerator::table_height_in_world_m() const noexcept {
  return (options_.T_world_head_rest * Vec3(0.0, options_.table_height_in_head_m, 0.0)).y();
}

HandAngles HandMotionGenerator::random_angles(Rng& rng) const {
  const JointLimits& lim = model_.limits();
  const double shrink = 0.5 * (1.0 - options_.limit_fraction);
  HandAngles a;
  for (std::size_t i = 0; i < kHandDofCount; ++i) {
    const double span = lim.max_rad[i] - lim.min_rad[i];
    a[i] = rng.uniform(lim.min_rad[i] + shrink * span, lim.max_rad[i] - shrink * span);
  }
  if (options_.natural_coupling) {
    auto dof = [&](Finger f, std::size_t i) -> double& { return a[first_dof_of(f) + i]; };
    for (Finger f : {Finger::ring, Finger::little}) {
      const Finger neighbour = f == Finger::ring ? Finger::middle : Finger::ring;
      for (std::size_t i : {std::size_t{0}, std::size_t{2}}) {  // MCP and PIP flexion
        dof(f, i) = dof(neighbour, i) + options_.enslaved_deviation_rad * rng.normal();
      }
    }
    for (Finger f : {Finger::index, Finger::middle, Finger::ring, Finger::little}) {
      dof(f, 3) = (2.0 / 3.0) * dof(f, 2) + options_.dip_deviation_rad * rng.normal();
    }
    dof(Finger::thumb, 3) = 0.5 * dof(Finger::thumb, 2) + options_.thumb_ip_deviation_rad * rng.normal();
    a = lim.clamp(a);
  }
  return a;
}

void HandMotionGenerator::random_wrist(Rng& rng, double position_fraction, double tilt_fraction, Vec3& p,
                                       Vec3& rotation) const {
  const Vec3 centre = 0.5 * (options_.wrist_min_in_head + options_.wrist_max_in_head);
  for (int i = 0; i < 3; ++i) {
    p[i] = centre[i] + position_fraction * rng.uniform(options_.wrist_min_in_head[i] - centre[i],
                                                       options_.wrist_max_in_head[i] - centre[i]);
  }
  // A random rotation vector inside a ball: tilt away from palm-down,
  // fingers-forward (the wrist frame aligned with the head frame).
  Vec3 axis(rng.normal(), rng.normal(), rng.normal());
  const double n = axis.norm();
  axis = n > 1e-12 ? Vec3(axis / n) : Vec3(Vec3::UnitY());
  const double angle = tilt_fraction * options_.wrist_max_tilt_rad * std::cbrt(rng.uniform01());
  rotation = angle * axis;
}

HandMotionGenerator::Keyframe HandMotionGenerator::make_keyframe(std::size_t k) {
  const JointLimits& lim = model_.limits();
  auto random_pose = [&](double position_fraction, double tilt_fraction) {
    Vec3 p, rotation;
    random_wrist(rng_, position_fraction, tilt_fraction, p, rotation);
    return Pose{so3_exp(rotation), p};
  };

  Keyframe kf;
  switch (options_.protocol) {
    case MotionProtocol::free_motion:
      kf.angles = (k == 0) ? relaxed_ : random_angles(rng_);
      kf.T_head_wrist = random_pose(k == 0 ? 0.0 : 1.0, k == 0 ? 0.0 : 1.0);
      break;
    case MotionProtocol::pinch_grasp:
    case MotionProtocol::pinch_grasp_contact: {
      const HandAngles* cycle[] = {&relaxed_, &pinch_, &relaxed_, &tripod_, &relaxed_, &power_};
      kf.angles = *cycle[k % 6];
      kf.T_head_wrist = random_pose(k == 0 ? 0.0 : 0.3, k == 0 ? 0.0 : 0.3);
      break;
    }
    case MotionProtocol::wrist_sweep:
      kf.angles = relaxed_;
      for (std::size_t i = 0; i < kHandDofCount; ++i) kf.angles[i] += deg_to_rad(rng_.uniform(-5.0, 5.0));
      kf.angles = lim.clamp(kf.angles);
      kf.T_head_wrist = random_pose(k == 0 ? 0.0 : 1.0, k == 0 ? 0.0 : 1.6);
      break;
    case MotionProtocol::natural:
    case MotionProtocol::tapping:  // no keyframes: their own state functions
      kf.angles = relaxed_;
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
  const Vec3 offset(0.010 * std::sin(0.11 * 2 * std::numbers::pi * t + ph[3]),
                    0.005 * std::sin(0.19 * 2 * std::numbers::pi * t + ph[4]),
                    0.010 * std::sin(0.07 * 2 * std::numbers::pi * t + ph[5]));
  return options_.T_world_head_rest * Pose{so3_exp(rotation), offset};
}

// --- natural ------------------------------------------------------------------

const hand_motion_detail::Submovement& HandMotionGenerator::submovement(std::size_t j) {
  // Generated strictly in order from their own engine (stream 2), so
  // submovement j is the same whatever was sampled before and whichever of
  // tremor and flicks are on.
  const auto& o = options_;
  while (submovements_.size() <= j) {
    hand_motion_detail::Submovement m;
    HandAngles from_angles = relaxed_;
    Vec3 from_p = 0.5 * (o.wrist_min_in_head + o.wrist_max_in_head);
    Vec3 from_r = Vec3::Zero();
    double previous_end = 0.0;
    if (submovements_.empty()) {
      m.start_s = submovement_rng_.uniform(0.0, 0.3);
    } else {
      const hand_motion_detail::Submovement& b = submovements_.back();
      from_angles = b.end_angles;
      from_p = b.end_position;
      from_r = b.end_rotation;
      m.start_s = b.next_start_s;
      previous_end = b.start_s + b.duration_s;
    }
    // Never end before the previous one: then every earlier submovement is
    // further along than every later one, and the state is a convex mixture
    // of the targets reached so far.
    m.duration_s =
        std::max(submovement_rng_.uniform(o.submovement_min_s, o.submovement_max_s), previous_end - m.start_s);
    const double reach = std::min(1.0, m.duration_s / o.submovement_max_s);
    const HandAngles target = random_angles(submovement_rng_);
    Vec3 target_p, target_r;
    random_wrist(submovement_rng_, 1.0, 1.0, target_p, target_r);
    for (std::size_t i = 0; i < kHandDofCount; ++i) {
      m.end_angles[i] = from_angles[i] + reach * (target[i] - from_angles[i]);
    }
    m.end_position = from_p + reach * (target_p - from_p);
    m.end_rotation = from_r + reach * (target_r - from_r);
    const double hold_draw = submovement_rng_.uniform01();
    const double hold_s = submovement_rng_.uniform(o.hold_min_s, o.hold_max_s);
    const double onset = submovement_rng_.uniform(o.submovement_onset_min, o.submovement_onset_max);
    m.next_start_s =
        hold_draw < o.hold_probability ? m.start_s + m.duration_s + hold_s : m.start_s + onset * m.duration_s;
    submovements_.push_back(m);
  }
  return submovements_[j];
}

void HandMotionGenerator::natural_base_at(double t, HandAngles& angles, Vec3& p, Vec3& rotation, std::size_t& k) {
  (void)submovement(0);
  while (submovements_.back().next_start_s <= t) (void)submovement(submovements_.size());
  const auto it =
      std::upper_bound(submovements_.begin(), submovements_.end(), t,
                       [](double time, const hand_motion_detail::Submovement& m) { return time < m.start_s; });
  if (it == submovements_.begin()) {
    angles = relaxed_;
    p = 0.5 * (options_.wrist_min_in_head + options_.wrist_max_in_head);
    rotation = Vec3::Zero();
    k = 0;
    return;
  }
  const std::size_t n = static_cast<std::size_t>(it - submovements_.begin()) - 1;
  const hand_motion_detail::Submovement& last = submovements_[n];
  angles = last.end_angles;
  p = last.end_position;
  rotation = last.end_rotation;
  // Take off what the submovements still under way have yet to add; ends are
  // in order, so those are the latest ones.
  for (std::size_t j = n + 1; j-- > 0;) {
    const hand_motion_detail::Submovement& m = submovements_[j];
    const double tau = (t - m.start_s) / m.duration_s;
    if (tau >= 1.0) break;
    const double remaining = 1.0 - minimum_jerk(tau);
    const HandAngles& from_angles = j > 0 ? submovements_[j - 1].end_angles : relaxed_;
    const Vec3 from_p = j > 0 ? submovements_[j - 1].end_position
                              : Vec3(0.5 * (options_.wrist_min_in_head + options_.wrist_max_in_head));
    const Vec3 from_r = j > 0 ? submovements_[j - 1].end_rotation : Vec3::Zero();
    for (std::size_t i = 0; i < kHandDofCount; ++i) angles[i] -= remaining * (m.end_angles[i] - from_angles[i]);
    p -= remaining * (m.end_position - from_p);
    rotation -= remaining * (m.end_rotation - from_r);
  }
  k = n + 1;  // keyframe 0 is the start; submovement j heads for keyframe j + 1
}

const hand_motion_detail::Flick& HandMotionGenerator::flick(std::size_t i) {
  const auto& o = options_;
  while (flicks_.size() <= i) {
    hand_motion_detail::Flick f;
    // Every draw is made for every flick (stream 4), whatever its kind.
    const double previous = flicks_.empty() ? 0.0 : flicks_.back().start_s;
    f.start_s = previous + flick_rng_.uniform(o.flick_interval_min_s, o.flick_interval_max_s);
    f.duration_s = flick_rng_.uniform(o.flick_min_s, o.flick_max_s);
    const double peak_rad_s = deg_to_rad(flick_rng_.uniform(o.flick_peak_min_deg_s, o.flick_peak_max_deg_s));
    f.wrist = flick_rng_.uniform01() < o.flick_wrist_fraction;
    const double axis_angle = flick_rng_.uniform(0.0, 2.0 * std::numbers::pi);
    f.finger = flick_rng_.uniform01() < 0.5 ? Finger::index : Finger::middle;
    // Each half is a minimum-jerk move of duration/2, whose peak rate is
    // 15/8 of its mean.
    const double amplitude = peak_rad_s * 0.5 * f.duration_s / 1.875;
    // Between flexion/extension (wrist x) and pronation/supination (wrist z).
    f.axis_in_wrist = Vec3(std::cos(axis_angle), 0.0, std::sin(axis_angle));
    f.amplitude_rad = amplitude;
    if (!f.wrist) {
      // Flex or extend, whichever has room at the start and the end of the
      // flick; a smaller flick where neither has (rare: the base motion stays
      // within limit_fraction of every range).
      HandAngles a0, a1;
      Vec3 p, r;
      std::size_t unused;
      natural_base_at(f.start_s, a0, p, r, unused);
      natural_base_at(f.start_s + f.duration_s, a1, p, r, unused);
      const JointLimits& lim = model_.limits();
      const double margin = deg_to_rad(3.0);
      const std::size_t f0 = first_dof_of(f.finger);
      double best_ratio = -1.0, best_sign = 1.0;
      for (double sign : {1.0, -1.0}) {
        double ratio = std::numeric_limits<double>::infinity();
        for (std::size_t j = 0; j < 3; ++j) {
          const std::size_t d = f0 + hand_motion_detail::kFlexionOffsets[j];
          const double room = sign > 0 ? lim.max_rad[d] - std::max(a0[d], a1[d]) - margin
                                       : std::min(a0[d], a1[d]) - lim.min_rad[d] - margin;
          ratio = std::min(ratio, room / (hand_motion_detail::kFlickFlexionWeights[j] * amplitude));
        }
        if (ratio > best_ratio) {
          best_ratio = ratio;
          best_sign = sign;
        }
      }
      f.amplitude_rad = best_sign * amplitude * std::clamp(best_ratio, 0.0, 1.0);
    }
    flicks_.push_back(f);
  }
  return flicks_[i];
}

void HandMotionGenerator::setup_tremor() {
  const auto& o = options_;
  Rng rng(mix_seed(o.seed, 3));
  hand_motion_detail::Tremor& tr = tremor_;
  for (std::size_t k = 0; k < hand_motion_detail::Tremor::kComponents; ++k) {
    tr.frequency_hz[k] = rng.uniform(o.tremor_min_hz, o.tremor_max_hz);
    tr.modulation_hz[k] = rng.uniform(0.1, 0.4);
    tr.modulation_phase[k] = rng.uniform(0.0, 2.0 * std::numbers::pi);
  }
  // How each channel moves the index fingertip, relaxed hand, wrist frame.
  const HandJoint tip = tip_of(Finger::index);
  const Vec3 p_tip = model_.joint_poses_in_wrist(Handedness::right, relaxed_)[index_of(tip)].p;
  Eigen::Matrix<double, 3, hand_motion_detail::Tremor::kChannels> J =
      Eigen::Matrix<double, 3, hand_motion_detail::Tremor::kChannels>::Zero();
  for (int i = 0; i < 3; ++i) {
    J.col(i) = Vec3::Unit(i);
    J.col(3 + i) = Vec3::Unit(i).cross(p_tip);
  }
  constexpr double h = 1e-6;
  for (std::size_t f = 0; f < kFingerCount; ++f) {
    HandAngles a = relaxed_;
    for (std::size_t j = 0; j < 3; ++j)
      a[4 * f + hand_motion_detail::kFlexionOffsets[j]] += h * hand_motion_detail::kTremorFlexionWeights[j];
    J.col(static_cast<Eigen::Index>(6 + f)) =
        (model_.joint_poses_in_wrist(Handedness::right, a)[index_of(tip)].p - p_tip) / h;
  }
  // Relative sizes: a metre of wrist translation per axis, the rotation that
  // moves the tip as much, the finger flexion that moves the tip as much.
  std::array<double, hand_motion_detail::Tremor::kChannels> relative{};
  const double finger_lever = std::max(J.col(6 + 1).norm(), 1e-3);
  for (std::size_t i = 0; i < hand_motion_detail::Tremor::kChannels; ++i) {
    relative[i] = i < 3 ? 1.0 : i < 6 ? 1.0 / std::max(p_tip.norm(), 1e-3) : 1.0 / finger_lever;
  }
  for (std::size_t i = 0; i < hand_motion_detail::Tremor::kChannels; ++i) {
    std::array<double, hand_motion_detail::Tremor::kComponents> w{};
    double norm2 = 0.0;
    for (auto& x : w) {
      x = rng.uniform(0.5, 1.0);
      norm2 += x * x;
    }
    for (std::size_t k = 0; k < hand_motion_detail::Tremor::kComponents; ++k) {
      const double phase = rng.uniform(0.0, 2.0 * std::numbers::pi);
      const double a = relative[i] * w[k] / std::sqrt(norm2);
      tr.a_cos[i][k] = a * std::cos(phase);
      tr.a_sin[i][k] = a * std::sin(phase);
    }
  }
  // Long-run covariance of the channels: for one component, E[(1 + m sin)^2]
  // E[sin(w t + a) sin(w t + b)] = (1 + m^2 / 2) cos(a - b) / 2; distinct
  // components do not correlate. Scale so the tip's RMS is tremor_rms_m.
  Eigen::Matrix<double, hand_motion_detail::Tremor::kChannels, hand_motion_detail::Tremor::kChannels> cov =
      Eigen::Matrix<double, hand_motion_detail::Tremor::kChannels, hand_motion_detail::Tremor::kChannels>::Zero();
  const double m = o.tremor_modulation;
  for (std::size_t i = 0; i < hand_motion_detail::Tremor::kChannels; ++i) {
    for (std::size_t j = 0; j < hand_motion_detail::Tremor::kChannels; ++j) {
      double c = 0.0;
      for (std::size_t k = 0; k < hand_motion_detail::Tremor::kComponents; ++k) {
        c += tr.a_cos[i][k] * tr.a_cos[j][k] + tr.a_sin[i][k] * tr.a_sin[j][k];
      }
      cov(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = 0.5 * (1.0 + 0.5 * m * m) * c;
    }
  }
  const double rms = std::sqrt(std::max((J * cov * J.transpose()).trace(), 1e-300));
  const double scale = o.tremor_rms_m / rms;
  for (std::size_t i = 0; i < hand_motion_detail::Tremor::kChannels; ++i) {
    for (std::size_t k = 0; k < hand_motion_detail::Tremor::kComponents; ++k) {
      tr.a_cos[i][k] *= scale;
      tr.a_sin[i][k] *= scale;
    }
  }
}

void HandMotionGenerator::natural_state_at(double t, HandAngles& angles, Pose& T_head_wrist, std::size_t& k) {
  Vec3 p, rotation;
  natural_base_at(t, angles, p, rotation, k);
  Quat q_flick = Quat::Identity();
  if (options_.flicks) {
    (void)flick(0);
    while (flicks_.back().start_s <= t) (void)flick(flicks_.size());
    const auto it = std::upper_bound(flicks_.begin(), flicks_.end(), t,
                                     [](double time, const hand_motion_detail::Flick& f) { return time < f.start_s; });
    if (it != flicks_.begin()) {  // flicks never overlap: only the latest can be under way
      const hand_motion_detail::Flick& f = *(it - 1);
      const double b = hand_motion_detail::out_and_back((t - f.start_s) / f.duration_s);
      if (b > 0.0) {
        if (f.wrist) {
          q_flick = so3_exp(f.amplitude_rad * b * f.axis_in_wrist);
        } else {
          const std::size_t f0 = first_dof_of(f.finger);
          for (std::size_t j = 0; j < 3; ++j)
            angles[f0 + hand_motion_detail::kFlexionOffsets[j]] +=
                hand_motion_detail::kFlickFlexionWeights[j] * f.amplitude_rad * b;
        }
      }
    }
  }
  Pose T_tremor;
  if (options_.tremor && options_.tremor_rms_m > 0.0) {
    const auto c = hand_motion_detail::tremor_channels(tremor_, options_.tremor_modulation, t);
    T_tremor = Pose{so3_exp(Vec3(c[3], c[4], c[5])), Vec3(c[0], c[1], c[2])};
    for (std::size_t f = 0; f < kFingerCount; ++f) {
      for (std::size_t j = 0; j < 3; ++j)
        angles[4 * f + hand_motion_detail::kFlexionOffsets[j]] +=
            hand_motion_detail::kTremorFlexionWeights[j] * c[6 + f];
    }
  }
  angles = model_.limits().clamp(angles);
  T_head_wrist = mirror_for(options_.hand, Pose{so3_exp(rotation), p} * Pose{q_flick, Vec3::Zero()} * T_tremor);
}

// --- tapping --------------------------------------------------------------------

void HandMotionGenerator::setup_tapping() {
  const auto& o = options_;
  const auto& shape = model_.shape();
  // A finger's tapping shape: MCP 20 deg, PIP 25 deg, DIP 2/3 of PIP at phi =
  // 0; phi (rad of MCP) flexes it further, PIP and DIP following.
  auto shape_finger = [](HandAngles& a, Finger f, double phi) {
    const std::size_t f0 = first_dof_of(f);
    a[f0] = deg_to_rad(20.0) + phi;
    a[f0 + 2] = deg_to_rad(25.0) + 0.6 * phi;
    a[f0 + 3] = (2.0 / 3.0) * deg_to_rad(25.0) + 0.4 * phi;
  };
  tap_flex_ = {};
  const std::size_t t0 = first_dof_of(o.tap_finger);
  tap_flex_[t0] = 1.0;
  tap_flex_[t0 + 2] = 0.6;
  tap_flex_[t0 + 3] = 0.4;
  HandAngles a = relaxed_;
  shape_finger(a, o.tap_finger, 0.0);
  auto tip_height_in_wrist = [&](const HandAngles& angles, Finger f) {
    return model_.joint_poses_in_wrist(Handedness::right, angles)[index_of(tip_of(f))].p.y();
  };
  // Palm down: the wrist frame is the head frame turned by nothing, +Y up.
  const double tap_radius = shape.fingers[static_cast<std::size_t>(o.tap_finger)].joint_radius_m[4];
  tap_wrist_height_in_head_m_ = o.table_height_in_head_m + tap_radius - tip_height_in_wrist(a, o.tap_finger);
  // The other fingers, and the thumb stretched alongside, hover tap_hover_m
  // above the table: their tips' height falls as they flex (bisection on
  // the flexion, kept within a plausible range).
  auto shape_thumb = [](HandAngles& b, double psi) {
    b[0] = deg_to_rad(10.0) + psi;  // CMC flexion
    b[1] = deg_to_rad(10.0) + psi;  // CMC abduction
    b[2] = deg_to_rad(10.0) + 0.5 * psi;
    b[3] = deg_to_rad(5.0) + 0.25 * psi;
  };
  for (Finger f : {Finger::thumb, Finger::index, Finger::middle, Finger::ring, Finger::little}) {
    if (f == o.tap_finger) continue;
    const auto& finger_shape = shape.fingers[static_cast<std::size_t>(f)];
    const double radius = finger_shape.joint_radius_m[f == Finger::thumb ? 3 : 4];
    auto set = [&](HandAngles& b, double x) {
      if (f == Finger::thumb) {
        shape_thumb(b, x);
      } else {
        shape_finger(b, f, x);
      }
    };
    auto above = [&](double x) {
      HandAngles b = a;
      set(b, x);
      return tap_wrist_height_in_head_m_ + tip_height_in_wrist(b, f) - radius -
             (o.table_height_in_head_m + o.tap_hover_m);
    };
    double lo = f == Finger::thumb ? deg_to_rad(-25.0) : -0.6;  // above(lo) > above(hi)
    double hi = f == Finger::thumb ? deg_to_rad(20.0) : 0.6;
    double x = lo;
    if (above(hi) >= 0.0) {
      x = hi;
    } else if (above(lo) > 0.0) {
      for (int i = 0; i < 50; ++i) {
        const double mid = 0.5 * (lo + hi);
        (above(mid) > 0.0 ? lo : hi) = mid;
      }
      x = lo;
    }
    set(a, x);
  }
  tap_contact_ = model_.limits().clamp(a);
}

const hand_motion_detail::Tap& HandMotionGenerator::tap(std::size_t i) {
  const auto& o = options_;
  while (taps_.size() <= i) {
    // Every draw is made for every tap (stream 5).
    hand_motion_detail::Tap tp;
    tp.lift_s = taps_.empty() ? 0.0 : taps_.back().next_lift_s;
    tp.up_s = tap_rng_.uniform(o.tap_up_min_s, o.tap_up_max_s);
    tp.phi_up = -tap_rng_.uniform(o.tap_lift_min_rad, o.tap_lift_max_rad);
    const double centre_x = 0.5 * (o.wrist_min_in_head.x() + o.wrist_max_in_head.x());
    const double centre_z = 0.5 * (o.wrist_min_in_head.z() + o.wrist_max_in_head.z());
    const double dx = tap_rng_.uniform(-o.tap_shift_m, o.tap_shift_m);
    const double dz = tap_rng_.uniform(-o.tap_shift_m, o.tap_shift_m);
    tp.wrist_xz = Eigen::Vector2d(centre_x + dx, centre_z + dz);
    tp.down_s = tap_rng_.uniform(o.tap_down_min_s, o.tap_down_max_s);
    const double dwell = tap_rng_.uniform(o.tap_dwell_min_s, o.tap_dwell_max_s);
    // Aim past the table: contact (phi = 0) is at 1 / (1 + beyond) of the move.
    tp.phi_aim = o.contact_aim_beyond * (0.0 - tp.phi_up);
    tp.down = hand_motion_detail::make_contact_move(tp.down_s, 1.0 / (1.0 + o.contact_aim_beyond), o.contact_stop_s);
    tp.contact_s = tp.lift_s + tp.up_s + tp.down.rest_s;
    tp.next_lift_s = tp.contact_s + dwell;
    taps_.push_back(tp);
  }
  return taps_[i];
}

void HandMotionGenerator::tapping_state_at(double t, HandAngles& angles, Pose& T_head_wrist, std::size_t& k,
                                           bool& contact) {
  const auto& o = options_;
  (void)tap(0);
  while (taps_.back().next_lift_s <= t) (void)tap(taps_.size());
  const auto it = std::upper_bound(taps_.begin(), taps_.end(), t,
                                   [](double time, const hand_motion_detail::Tap& tp) { return time < tp.lift_s; });
  const std::size_t i = it == taps_.begin() ? 0 : static_cast<std::size_t>(it - taps_.begin()) - 1;
  const hand_motion_detail::Tap& tp = taps_[i];
  const Eigen::Vector2d centre(0.5 * (o.wrist_min_in_head.x() + o.wrist_max_in_head.x()),
                               0.5 * (o.wrist_min_in_head.z() + o.wrist_max_in_head.z()));
  const double from_phi = i == 0 ? hand_motion_detail::kTapStartPhi : 0.0;
  const Eigen::Vector2d from_xz = i == 0 ? centre : taps_[i - 1].wrist_xz;
  const double u = t - tp.lift_s;
  double phi = 0.0;
  Eigen::Vector2d xz = tp.wrist_xz;
  if (u < tp.up_s) {  // lifting while the wrist moves to the next spot
    const double s = minimum_jerk(u / tp.up_s);
    phi = from_phi + s * (tp.phi_up - from_phi);
    xz = from_xz + s * (tp.wrist_xz - from_xz);
  } else if (u - tp.up_s < tp.down.rest_s) {  // down, aimed past the table, stopping on it
    const double s = hand_motion_detail::contact_progress(tp.down, u - tp.up_s, o.contact_stops);
    phi = std::min(0.0, tp.phi_up + s * (tp.phi_aim - tp.phi_up));
  } else {  // resting on the table
    contact = true;
  }
  angles = tap_contact_;
  if (phi != 0.0) {
    for (std::size_t d = 0; d < kHandDofCount; ++d) angles[d] += phi * tap_flex_[d];
    angles = model_.limits().clamp(angles);
  }
  T_head_wrist = mirror_for(o.hand, Pose{Quat::Identity(), Vec3(xz.x(), tap_wrist_height_in_head_m_, xz.y())});
  k = i;
}

// --- all protocols -------------------------------------------------------------

void HandMotionGenerator::state_at(double t, HandAngles& angles, Pose& T_world_wrist, std::size_t& k, bool& contact) {
  t = std::max(t, 0.0);
  contact = false;
  if (options_.protocol == MotionProtocol::natural || options_.protocol == MotionProtocol::tapping) {
    Pose T_head_wrist;
    if (options_.protocol == MotionProtocol::natural) {
      natural_state_at(t, angles, T_head_wrist, k);
    } else {
      tapping_state_at(t, angles, T_head_wrist, k, contact);
    }
    T_world_wrist = options_.T_world_head_rest * T_head_wrist;
    return;
  }
  const double interval = options_.target_interval_s;
  k = static_cast<std::size_t>(t / interval);
  const double into = t - static_cast<double>(k) * interval;
  const Keyframe& to = keyframe(k);
  Pose T_head_wrist = to.T_head_wrist;
  angles = to.angles;
  const double transition = std::min(options_.transition_s, interval);
  if (options_.protocol == MotionProtocol::pinch_grasp_contact && k % 2 == 1) {
    // Closing on a pinch, tripod or power grasp: the fingers aim past the
    // grasp and stop where the pads touch; the wrist settles as usual.
    const Keyframe& from = keyframes_[k - 1];
    if (into < grasp_move_.rest_s) {
      const double s =
          hand_motion_detail::contact_progress(grasp_move_, into, options_.contact_stops) / grasp_move_.s_contact;
      for (std::size_t i = 0; i < kHandDofCount; ++i) angles[i] = from.angles[i] + s * (to.angles[i] - from.angles[i]);
    } else {
      contact = true;
    }
    if (into < transition)
      T_head_wrist = interpolate(from.T_head_wrist, to.T_head_wrist, minimum_jerk(into / transition));
  } else if (k > 0 && into < transition) {  // after the transition the target is held exactly
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
  state_at(t, frame.angles, frame.T_world_wrist, frame.keyframe, frame.in_contact);
  frame.T_world_head = head_at(t);
  frame.pose = model_.forward(options_.hand, frame.angles, frame.T_world_wrist, t_ns);

  HandAngles a_minus, a_plus;
  Pose w_minus, w_plus;
  std::size_t unused;
  bool unused_contact;
  state_at(t - kVelocityStepS, a_minus, w_minus, unused, unused_contact);
  state_at(t + kVelocityStepS, a_plus, w_plus, unused, unused_contact);
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
