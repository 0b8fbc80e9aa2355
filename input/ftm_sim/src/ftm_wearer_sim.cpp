#include "proprio/ftm_sim/ftm_wearer_sim.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "proprio/sim/subjects.hpp"

namespace proprio::ftm_sim {
namespace {

// Random streams, one per effect (mix_seed(seed, stream)).
enum Stream : std::uint64_t {
  kMotionStream = 1,
  kPoseErrorStream = 2,
  kWobbleStream = 3,
  kResidualStream = 4,
  kBendDonningStream = 5,
  kBendNoiseStream = 6,  // + sensor index * 16
  kWristJitterStream = 7,
  kWristDropoutStream = 8,
  kImuStream = 9,
  kFigureEightStream = 10,
  kSoftTissueStream = 11,
};

constexpr double kTwoPi = 2.0 * M_PI;

Error ftm_sim_bad_option(const char* file, int line, const char* field, double value, const char* hint) {
  char buf[320];
  std::snprintf(buf, sizeof buf, "%s:%d: FtmWearerOptions.%s = %g is not usable: %s", file, line, field, value, hint);
  return make_error(Errc::invalid_argument, buf);
}
#define FTM_SIM_BAD(field, value, hint) ftm_sim_bad_option(__FILE__, __LINE__, field, value, hint)

double ftm_sim_truncated_normal(Rng& rng, double bound) {
  for (;;) {
    const double z = rng.normal();
    if (std::abs(z) <= bound) return z;
  }
}

Pose ftm_sim_mirror(Handedness hand, const Pose& T_right) {
  if (hand == Handedness::right) return T_right;
  return {Quat(T_right.q.w(), T_right.q.x(), -T_right.q.y(), -T_right.q.z()),
          Vec3(-T_right.p.x(), T_right.p.y(), T_right.p.z())};
}

// τ at which the minimum-jerk profile reaches `level` (bisection).
double ftm_sim_mj_inverse(double level) {
  double lo = 0.0, hi = 1.0;
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (sim::minimum_jerk(mid) < level ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

constexpr std::array<HandJoint, 3> kDeviceTips = {HandJoint::thumb_tip, HandJoint::index_tip, HandJoint::middle_tip};
// DOFs that carry a synergy residual: thumb IP, then the four DIPs.
constexpr std::array<HandDof, 5> kDistalDofs = {HandDof::thumb_ip_flexion, HandDof::index_dip_flexion,
                                                HandDof::middle_dip_flexion, HandDof::ring_dip_flexion,
                                                HandDof::little_dip_flexion};

}  // namespace

std::string_view to_string(FtmPhase p) noexcept {
  switch (p) {
    case FtmPhase::figure_eight: return "figure_eight";
    case FtmPhase::pose_flat: return "pose_flat";
    case FtmPhase::pose_thumb_parallel: return "pose_thumb_parallel";
    case FtmPhase::pose_bend_90: return "pose_bend_90";
    case FtmPhase::task: return "task";
  }
  return "?";
}

std::string_view to_string(FtmMagneticObject::Kind k) noexcept {
  switch (k) {
    case FtmMagneticObject::Kind::drill: return "drill";
    case FtmMagneticObject::Kind::fan: return "fan";
    case FtmMagneticObject::Kind::earphone_case: return "earphone_case";
  }
  return "?";
}

std::vector<FtmMagneticObject> FtmMagneticOptions::figure_4_14_objects(TimeNs first_ns) {
  std::vector<FtmMagneticObject> v;
  const FtmMagneticObject::Kind kinds[] = {FtmMagneticObject::Kind::drill, FtmMagneticObject::Kind::fan,
                                           FtmMagneticObject::Kind::earphone_case};
  TimeNs t = first_ns;
  for (auto k : kinds) {
    FtmMagneticObject o;
    o.kind = k;
    o.t_start_ns = t;
    o.current_A = k == FtmMagneticObject::Kind::fan ? 0.5 : 1.0;
    v.push_back(o);
    t += 12 * kNsPerSecond;
  }
  return v;
}

sim::ImuNoiseOptions FtmWearerOptions::default_imu() {
  sim::ImuNoiseOptions o;
  o.sample_rate_hz = ftm::kFtmImuRateHz;
  o.magnetometer.enabled = true;
  o.magnetometer.output = sim::MagnetometerOutput::raw;
  return o;
}

Status FtmWearerOptions::validate() const {
  if (protocol != sim::MotionProtocol::free_motion && protocol != sim::MotionProtocol::pinch_grasp) {
    return FTM_SIM_BAD("protocol", static_cast<double>(protocol), "use free_motion or pinch_grasp");
  }
  if (subject.subject_index >= sim::kSimSubjectCount || subject.subject_index < -1) {
    return FTM_SIM_BAD("subject.subject_index", subject.subject_index, "use -1 or 0..14");
  }
  if (!std::isfinite(task_s) || task_s <= 0.0 || task_s > (driven_task ? 86400.0 : 3600.0)) {
    return FTM_SIM_BAD("task_s", task_s, driven_task ? "use a duration in (0, 86400] s" : "use a duration in (0, 3600] s");
  }
  if (auto st = imu.validate(); !st) return st.error().with_context("FtmWearerOptions.imu");
  if (auto st = soft_tissue.validate(); !st) return st.error().with_context("FtmWearerOptions.soft_tissue");
  if (!imu.magnetometer.enabled) {
    return FTM_SIM_BAD("imu.magnetometer.enabled", 0.0, "the FTM's MPU-9250s have a compass; enable it");
  }
  if (magnetic.enable_device_leads && (!(magnetic.lead_separation_m > 0.0) || !magnetic.lead_offset_m.allFinite())) {
    return FTM_SIM_BAD("magnetic.lead_separation_m", magnetic.lead_separation_m, "must be > 0 (and the offset finite)");
  }
  if (imu.sample_rate_hz < imu.magnetometer.sample_rate_hz) {
    return FTM_SIM_BAD("imu.sample_rate_hz", imu.sample_rate_hz, "must be >= the compass rate");
  }
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  auto nonneg = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (!positive(bend.rate_hz) || bend.rate_hz > 1e5) return FTM_SIM_BAD("bend.rate_hz", bend.rate_hz, "use (0, 1e5] Hz");
  if (!positive(bend.c0_pF)) return FTM_SIM_BAD("bend.c0_pF", bend.c0_pF, "must be > 0");
  if (!positive(bend.gain_per_rad)) return FTM_SIM_BAD("bend.gain_per_rad", bend.gain_per_rad, "must be > 0");
  if (!std::isfinite(bend.nonlinearity_per_rad2) || std::abs(bend.nonlinearity_per_rad2) > 0.5 * bend.gain_per_rad) {
    return FTM_SIM_BAD("bend.nonlinearity_per_rad2", bend.nonlinearity_per_rad2,
                       "keep |n| <= g/2 so C stays monotonic over the joint's range");
  }
  if (!nonneg(bend.gain_sigma) || bend.gain_sigma > 0.3) return FTM_SIM_BAD("bend.gain_sigma", bend.gain_sigma, "use [0, 0.3]");
  if (!nonneg(bend.offset_sigma_pF)) return FTM_SIM_BAD("bend.offset_sigma_pF", bend.offset_sigma_pF, "must be >= 0");
  if (!nonneg(bend.noise_sigma_pF)) return FTM_SIM_BAD("bend.noise_sigma_pF", bend.noise_sigma_pF, "must be >= 0");
  if (!nonneg(bend.lowpass_tau_s)) return FTM_SIM_BAD("bend.lowpass_tau_s", bend.lowpass_tau_s, "must be >= 0");
  if (!std::isfinite(bend.contact_artefact_pF)) return FTM_SIM_BAD("bend.contact_artefact_pF", bend.contact_artefact_pF, "must be finite");
  if (!positive(wrist.rate_hz) || wrist.rate_hz > 2000.0) return FTM_SIM_BAD("wrist.rate_hz", wrist.rate_hz, "use (0, 2000] Hz");
  if (!nonneg(wrist.jitter_sigma_m)) return FTM_SIM_BAD("wrist.jitter_sigma_m", wrist.jitter_sigma_m, "must be >= 0");
  if (!nonneg(wrist.jitter_sigma_rad)) return FTM_SIM_BAD("wrist.jitter_sigma_rad", wrist.jitter_sigma_rad, "must be >= 0");
  if (!nonneg(wrist.latency_s) || wrist.latency_s > 1.0) return FTM_SIM_BAD("wrist.latency_s", wrist.latency_s, "use [0, 1] s");
  if (!positive(wrist.dropout_mean_interval_s)) {
    return FTM_SIM_BAD("wrist.dropout_mean_interval_s", wrist.dropout_mean_interval_s, "must be > 0");
  }
  if (!positive(wrist.dropout_mean_duration_s)) {
    return FTM_SIM_BAD("wrist.dropout_mean_duration_s", wrist.dropout_mean_duration_s, "must be > 0");
  }
  if (auto st = magnetic.earth.validate(); !st) return st.error().with_context("FtmWearerOptions.magnetic.earth");
  if (!nonneg(magnetic.device.full_current_A)) {
    return FTM_SIM_BAD("magnetic.device.full_current_A", magnetic.device.full_current_A, "must be >= 0");
  }
  if (!positive(magnetic.disturbed_angle_rad)) {
    return FTM_SIM_BAD("magnetic.disturbed_angle_rad", magnetic.disturbed_angle_rad, "must be > 0");
  }
  if (!positive(magnetic.disturbed_magnitude_fraction)) {
    return FTM_SIM_BAD("magnetic.disturbed_magnitude_fraction", magnetic.disturbed_magnitude_fraction, "must be > 0");
  }
  for (const auto& o : magnetic.objects) {
    if (o.approach_ns <= 0 || o.hold_ns < 0 || o.retreat_ns <= 0) {
      return FTM_SIM_BAD("magnetic.objects[].approach_ns", static_cast<double>(o.approach_ns),
                         "approach and retreat must be > 0, hold >= 0");
    }
    if (!positive(o.near_distance_m)) {
      return FTM_SIM_BAD("magnetic.objects[].near_distance_m", o.near_distance_m, "must be > 0");
    }
    if (!std::isfinite(o.current_A)) return FTM_SIM_BAD("magnetic.objects[].current_A", o.current_A, "must be finite");
  }
  const auto& c = calibration;
  if (c.enabled) {
    if (!positive(c.figure_eight_s)) return FTM_SIM_BAD("calibration.figure_eight_s", c.figure_eight_s, "must be > 0");
    if (c.figure_eight_s < 4.0) {
      return FTM_SIM_BAD("calibration.figure_eight_s", c.figure_eight_s, "needs >= 4 s (1.5 s ramps at each end)");
    }
    if (!positive(c.pose_transition_s)) return FTM_SIM_BAD("calibration.pose_transition_s", c.pose_transition_s, "must be > 0");
    if (!positive(c.pose_hold_s)) return FTM_SIM_BAD("calibration.pose_hold_s", c.pose_hold_s, "must be > 0");
    if (!positive(c.task_transition_s)) return FTM_SIM_BAD("calibration.task_transition_s", c.task_transition_s, "must be > 0");
  }
  if (!nonneg(c.pose_error_sigma_rad) || c.pose_error_sigma_rad > deg_to_rad(20.0)) {
    return FTM_SIM_BAD("calibration.pose_error_sigma_rad", c.pose_error_sigma_rad, "use [0, 20°]");
  }
  if (!nonneg(c.wobble_amplitude_rad)) return FTM_SIM_BAD("calibration.wobble_amplitude_rad", c.wobble_amplitude_rad, "must be >= 0");
  if (!nonneg(c.wrist_wobble_m)) return FTM_SIM_BAD("calibration.wrist_wobble_m", c.wrist_wobble_m, "must be >= 0");
  if (!nonneg(c.wrist_wobble_rad)) return FTM_SIM_BAD("calibration.wrist_wobble_rad", c.wrist_wobble_rad, "must be >= 0");
  if (!nonneg(synergy.dip_residual_sigma_rad)) {
    return FTM_SIM_BAD("synergy.dip_residual_sigma_rad", synergy.dip_residual_sigma_rad, "must be >= 0");
  }
  if (!nonneg(synergy.thumb_ip_residual_sigma_rad)) {
    return FTM_SIM_BAD("synergy.thumb_ip_residual_sigma_rad", synergy.thumb_ip_residual_sigma_rad, "must be >= 0");
  }
  return Status::success();
}

std::string FtmWearerOptions::describe() const {
  char buf[1400];
  std::snprintf(
      buf, sizeof buf,
      "ftm wearer: hand=%s seed=%llu subject=%d (%.3f x %.3f m) protocol=%s task=%.1fs | calibration %s "
      "(figure-eight %.1fs, poses %.1f+%.1fs, error %.1fdeg%s, wobble %.1fdeg%s) | synergy residuals %s "
      "(DIP %.1fdeg, thumb IP %.1fdeg) | bend %.0fHz C0=%.1fpF g=%.3f/rad n=%.4f/rad2 spread %.0f%%/%.2fpF%s "
      "noise %.3fpF%s lowpass %.0fms%s artefact %.2fpF%s nonlinearity%s | wrist %.0fHz jitter %.2fmm/%.2fdeg%s "
      "latency %.0fms%s dropouts every %.1fs for %.2fs%s | magnetic: devices %s contact current %s (%.2fA), "
      "%zu objects %s, disturbed > %.1fdeg or %.1f%%",
      hand == Handedness::right ? "right" : "left", static_cast<unsigned long long>(seed), subject.subject_index,
      subject.hand_length_m, subject.hand_width_m, std::string(sim::to_string(protocol)).c_str(), task_s,
      calibration.enabled ? "on" : "off", calibration.figure_eight_s, calibration.pose_transition_s,
      calibration.pose_hold_s, rad_to_deg(calibration.pose_error_sigma_rad),
      calibration.enable_pose_error ? "" : " (off)", rad_to_deg(calibration.wobble_amplitude_rad),
      calibration.enable_wobble ? "" : " (off)", synergy.enable_residuals ? "on" : "off",
      rad_to_deg(synergy.dip_residual_sigma_rad), rad_to_deg(synergy.thumb_ip_residual_sigma_rad), bend.rate_hz,
      bend.c0_pF, bend.gain_per_rad, bend.nonlinearity_per_rad2, bend.gain_sigma * 100.0, bend.offset_sigma_pF,
      bend.enable_donning_spread ? "" : " (off)", bend.noise_sigma_pF, bend.enable_noise ? "" : " (off)",
      bend.lowpass_tau_s * 1e3, bend.enable_lowpass ? "" : " (off)", bend.contact_artefact_pF,
      bend.enable_contact_artefact ? "" : " (off)", bend.enable_nonlinearity ? " on" : " off", wrist.rate_hz,
      wrist.jitter_sigma_m * 1e3, rad_to_deg(wrist.jitter_sigma_rad), wrist.enable_jitter ? "" : " (off)",
      wrist.latency_s * 1e3, wrist.enable_latency ? "" : " (off)", wrist.dropout_mean_interval_s,
      wrist.dropout_mean_duration_s, wrist.enable_dropouts ? "" : " (off)",
      magnetic.enable_fingertip_devices ? "on" : "off", magnetic.enable_contact_current ? "on" : "off",
      magnetic.device.full_current_A, magnetic.objects.size(), magnetic.enable_objects ? "on" : "off",
      rad_to_deg(magnetic.disturbed_angle_rad), magnetic.disturbed_magnitude_fraction * 100.0);
  std::string extra;
  if (driven_task) extra += " | task driven (drive())";
  if (subject.shape) extra += " | explicit hand shape";
  if (magnetic.enable_device_leads) {
    char lb[160];
    std::snprintf(lb, sizeof lb, " | device leads: offset %.1f/%.1f/%.1f mm, separation %.2f mm",
                  1e3 * magnetic.lead_offset_m.x(), 1e3 * magnetic.lead_offset_m.y(), 1e3 * magnetic.lead_offset_m.z(),
                  1e3 * magnetic.lead_separation_m);
    extra += lb;
  }
  return buf + extra + " | soft tissue: " + soft_tissue.describe() + " | imu: " + imu.describe();
}

// ---------------------------------------------------------------------------

namespace {
sim::HandMotionOptions ftm_sim_motion_options(const FtmWearerOptions& o) {
  sim::HandMotionOptions m;
  m.protocol = o.protocol;
  m.hand = o.hand;
  m.seed = mix_seed(o.seed, kMotionStream);
  m.natural_coupling = true;
  // The distal residuals are ours (FtmSynergyOptions), so they can be sized
  // to the measured R² and switched off; the generator's are zeroed.
  m.dip_deviation_rad = 0.0;
  m.thumb_ip_deviation_rad = 0.0;
  return m;
}
}  // namespace

FtmWearerSimulator::FtmWearerSimulator(FtmWearerOptions options, HandModel model)
    : options_(std::move(options)), model_(model), motion_(std::move(model), ftm_sim_motion_options(options_)) {}

Result<std::unique_ptr<FtmWearerSimulator>> FtmWearerSimulator::create(FtmWearerOptions options) {
  if (auto st = options.validate(); !st) return st.error();
  Result<HandShape> shape = Error{};
  if (options.subject.shape) {
    shape = *options.subject.shape;
  } else if (options.subject.subject_index >= 0) {
    auto subj = sim::sim_subject(options.subject.subject_index);
    if (!subj) return subj.error();
    shape = subj->shape();
  } else {
    shape = HandShape::from_measurements(options.subject.hand_length_m, options.subject.hand_width_m);
  }
  if (!shape) return shape.error().with_context("FtmWearerOptions.subject");
  std::unique_ptr<FtmWearerSimulator> s(new FtmWearerSimulator(std::move(options), HandModel(*shape)));
  if (auto st = s->init(); !st) return st.error();
  return s;
}

Status FtmWearerSimulator::init() {
  const auto& o = options_;
  const auto& cal = o.calibration;
  const JointLimits& lim = model_.limits();
  const auto first = motion_.sample(0);
  relaxed_ = first.angles;
  T_world_wrist_rest_ = first.T_world_wrist;

  // Phases.
  TimeNs t = 0;
  if (cal.enabled) {
    const TimeNs f8 = seconds_to_ns(cal.figure_eight_s);
    phases_.push_back({FtmPhase::figure_eight, 0, f8, 0});
    t = f8;
    const TimeNs tr = seconds_to_ns(cal.pose_transition_s), hold = seconds_to_ns(cal.pose_hold_s);
    for (FtmPhase p : {FtmPhase::pose_flat, FtmPhase::pose_thumb_parallel, FtmPhase::pose_bend_90}) {
      phases_.push_back({p, t, t + tr + hold, t + tr});
      t += tr + hold;
    }
  }
  task_begin_ns_ = t;
  end_ns_ = t + seconds_to_ns(o.task_s);
  phases_.push_back({FtmPhase::task, task_begin_ns_, end_ns_, task_begin_ns_});

  // Instructed poses (§3.2.3). 1: everything straight and aligned. 2: the
  // thumb straight and parallel to the fingers: CMC angles that bring the
  // thumb metacarpal's long axis closest to the index proximal phalanx's
  // (a 1° grid over the CMC range). 3: PIPs and thumb MCP at 90°; the
  // model's thumb MCP stops at its limit (60°, AAOS), so the instruction
  // there is the limit. Distal joints at their synergy values.
  HandAngles flat{};
  flat.fill(0.0);
  HandAngles parallel = flat;
  {
    const auto joints = model_.joint_poses_in_wrist(Handedness::right, flat);
    const Vec3 finger_dir = joints[index_of(HandJoint::index_proximal)].q * Vec3(0, 0, -1);
    double best = 1e9;
    const std::size_t cf = index_of(HandDof::thumb_cmc_flexion), ca = index_of(HandDof::thumb_cmc_abduction);
    for (double f = lim.min_rad[cf]; f <= lim.max_rad[cf]; f += deg_to_rad(1.0)) {
      for (double a = lim.min_rad[ca]; a <= lim.max_rad[ca]; a += deg_to_rad(1.0)) {
        HandAngles x = flat;
        x[cf] = f;
        x[ca] = a;
        const auto j = model_.joint_poses_in_wrist(Handedness::right, x);
        const Vec3 thumb_dir = j[index_of(HandJoint::thumb_metacarpal)].q * Vec3(0, 0, -1);
        const double err = std::acos(std::clamp(thumb_dir.dot(finger_dir), -1.0, 1.0));
        if (err < best) {
          best = err;
          parallel = x;
        }
      }
    }
  }
  HandAngles bend90 = parallel;
  for (Finger f : {Finger::index, Finger::middle, Finger::ring, Finger::little}) {
    bend90[first_dof_of(f) + 2] = deg_to_rad(90.0);
    bend90[first_dof_of(f) + 3] = deg_to_rad(60.0);
  }
  bend90[index_of(HandDof::thumb_mcp_flexion)] = std::min(deg_to_rad(90.0), lim.max_rad[index_of(HandDof::thumb_mcp_flexion)]);
  bend90[index_of(HandDof::thumb_ip_flexion)] = 0.5 * bend90[index_of(HandDof::thumb_mcp_flexion)];
  instructed_ = {flat, parallel, bend90};

  Rng pose_rng(mix_seed(o.seed, kPoseErrorStream));
  for (std::size_t p = 0; p < 3; ++p) {
    HandAngles h = instructed_[p];
    for (std::size_t i = 0; i < kHandDofCount; ++i) {
      const double z = ftm_sim_truncated_normal(pose_rng, 3.0);  // drawn whatever the switch
      if (cal.enable_pose_error) h[i] += cal.pose_error_sigma_rad * z;
    }
    held_[p] = lim.clamp(h);
  }
  Rng wobble_rng(mix_seed(o.seed, kWobbleStream));
  for (auto& ph : wobble_phase_) ph = wobble_rng.uniform(0.0, kTwoPi);
  Rng f8_rng(mix_seed(o.seed, kFigureEightStream));
  for (auto& ph : figure_eight_phase_) ph = f8_rng.uniform(0.0, kTwoPi);

  // Magnetic environment: the fingertip devices and the scripted objects.
  auto env = sim::MagneticEnvironment::create(o.magnetic.earth);
  if (!env) return env.error();
  env_ = std::make_shared<sim::MagneticEnvironment>(std::move(*env));
  if (o.magnetic.enable_fingertip_devices) {
    for (std::size_t d = 0; d < 3; ++d) {
      sim::CurrentFunction current;
      if (o.magnetic.enable_contact_current && o.protocol == sim::MotionProtocol::pinch_grasp) {
        const double full = o.magnetic.device.full_current_A;
        current = [this, d, full](TimeNs tt) { return full * contact_level(d, tt); };
      }
      auto idx = env_->add_dipole(sim::haptic_device_dipole(kDeviceTips[d], o.magnetic.device, std::move(current)));
      if (!idx) return idx.error();
      device_dipole_[d] = *idx;
      if (o.magnetic.enable_device_leads) {
        sim::CurrentLeadPair leads = sim::fingertip_device_leads(kDeviceTips[d], *idx);
        leads.p_joint_offset_m = o.magnetic.lead_offset_m;
        leads.separation_m = o.magnetic.lead_separation_m;
        if (auto l = env_->add_lead_pair(std::move(leads)); !l) return l.error().with_context("FtmMagneticOptions");
      }
    }
  }

  // IMUs mid-segment on the back of each segment, 4 mm above the skin (half
  // the board and its rubber strap). The dorsum's halfway between the wrist
  // and the middle finger's knuckle.
  const HandShape& shape = model_.shape();
  std::vector<PlacedImu> placed;
  {
    HandAngles zero{};
    zero.fill(0.0);
    const auto joints = model_.joint_poses_in_wrist(o.hand, zero);
    const Vec3 mcp = joints[index_of(HandJoint::middle_proximal)].p;
    placed.push_back({0, HandJoint::wrist,
                      Pose{Quat::Identity(), Vec3(0.5 * mcp.x(), shape.palm_radius_m + 0.004, 0.5 * mcp.z())}});
    const auto& th = shape.fingers[static_cast<std::size_t>(Finger::thumb)];
    placed.push_back({1, HandJoint::thumb_metacarpal,
                      Pose{Quat::Identity(), Vec3(0.0, th.joint_radius_m[0] + 0.004, -0.5 * th.bone_length_m[0])}});
    for (Finger f : {Finger::index, Finger::middle}) {
      const auto& fs = shape.fingers[static_cast<std::size_t>(f)];
      placed.push_back({placed.size(), f == Finger::index ? HandJoint::index_proximal : HandJoint::middle_proximal,
                        Pose{Quat::Identity(), Vec3(0.0, fs.joint_radius_m[1] + 0.004, -0.5 * fs.bone_length_m[1])}});
    }
  }

  if (o.magnetic.enable_objects) {
    for (const auto& obj : o.magnetic.objects) {
      sim::ScriptedApproach a;
      a.t_start_ns = obj.t_start_ns;
      a.approach_ns = obj.approach_ns;
      a.hold_ns = obj.hold_ns;
      a.retreat_ns = obj.retreat_ns;
      // In the dorsum IMU's nominal frame (+Y out of the back of the hand),
      // the object's axis (+Z) pointing at the hand.
      const Quat q_down = Quat::FromTwoVectors(Vec3::UnitZ(), -Vec3::UnitY());
      a.T_world_near = Pose{q_down, Vec3(0.0, obj.near_distance_m, 0.0)};
      a.T_world_far = Pose{q_down, Vec3(0.0, obj.near_distance_m + 1.0, 0.0)};
      const Pose T_wrist_imu = placed[0].T_segment_imu;
      sim::PoseFunction where;
      if (obj.follow_hand) {
        where = [this, a, T_wrist_imu](TimeNs tt) {
          HandAngles unused{};
          return wrist_at(tt, unused) * T_wrist_imu * a(tt);
        };
      } else {
        const TimeNs t_mid = obj.t_start_ns + obj.approach_ns + obj.hold_ns / 2;
        HandAngles unused{};
        const Pose T_world_imu_mid = wrist_at(std::clamp<TimeNs>(t_mid, 0, end_ns_), unused) * T_wrist_imu;
        where = [a, T_world_imu_mid](TimeNs tt) { return T_world_imu_mid * a(tt); };
      }
      const double amps = obj.current_A;
      sim::MagneticDipole dip;
      switch (obj.kind) {
        case FtmMagneticObject::Kind::drill: dip = sim::drill_dipole(where, [amps](TimeNs) { return amps; }); break;
        case FtmMagneticObject::Kind::fan: dip = sim::fan_dipole(where, [amps](TimeNs) { return amps; }); break;
        case FtmMagneticObject::Kind::earphone_case: dip = sim::earphone_case_dipole(where); break;
      }
      if (auto idx = env_->add_dipole(std::move(dip)); !idx) return idx.error();
    }
  }

  std::vector<sim::SkinMount> mounts;
  for (const PlacedImu& p : placed) mounts.push_back({p.segment, p.T_segment_imu.p, false});
  auto imu = sim::ImuSimulator::create([this](TimeNs tt) { return pose_at(tt); }, std::move(placed), o.imu,
                                       mix_seed(o.seed, kImuStream), 0);
  if (!imu) return imu.error().with_context("FTM wearer IMUs");
  imu_sim_.emplace(std::move(*imu));
  sim::SoftTissueOptions tissue = o.soft_tissue;
  if (o.driven_task) tissue.wobble = false;  // the wobble integrates ahead of the driven motion
  if (tissue.any()) {
    auto st = sim::SoftTissue::create([this](TimeNs tt) { return pose_at(tt); }, std::move(mounts), tissue,
                                      mix_seed(o.seed, kSoftTissueStream));
    if (!st) return st.error().with_context("FTM wearer soft tissue");
    soft_tissue_.emplace(std::move(*st));
    imu_sim_->set_mount_offsets([this](std::size_t i, const HandPose& pose, TimeNs tt) {
      return soft_tissue_->offset(i, pose, tt);
    });
  }
  imu_sim_->set_magnetic_environment(env_);

  // Bend sensors: per-donning constants, noise streams.
  Rng don(mix_seed(o.seed, kBendDonningStream));
  for (std::size_t b = 0; b < ftm::kFtmBendCount; ++b) {
    const double zg = ftm_sim_truncated_normal(don, 3.0), zo = ftm_sim_truncated_normal(don, 3.0);
    const bool on = o.bend.enable_donning_spread;
    bend_gain_[b] = o.bend.gain_per_rad * (1.0 + (on ? o.bend.gain_sigma * zg : 0.0));
    bend_c0_[b] = o.bend.c0_pF + (on ? o.bend.offset_sigma_pF * zo : 0.0);
    bend_noise_rng_[b] = Rng(mix_seed(o.seed, kBendNoiseStream + 16 * b));
  }
  wrist_jitter_rng_ = Rng(mix_seed(o.seed, kWristJitterStream));
  wrist_dropout_rng_ = Rng(mix_seed(o.seed, kWristDropoutStream));
  wrist_last_ = T_world_wrist_rest_;
  return Status::success();
}

FtmPhase FtmWearerSimulator::phase_at(TimeNs t) const {
  for (const auto& p : phases_) {
    if (t < p.end_ns) return p.phase;
  }
  return FtmPhase::task;
}

HandAngles FtmWearerSimulator::instructed_angles(FtmPhase pose) const {
  const auto i = static_cast<std::size_t>(pose);
  return (i >= 1 && i <= 3) ? instructed_[i - 1] : HandAngles{};
}
HandAngles FtmWearerSimulator::held_angles(FtmPhase pose) const {
  const auto i = static_cast<std::size_t>(pose);
  return (i >= 1 && i <= 3) ? held_[i - 1] : HandAngles{};
}

std::array<double, 5> FtmWearerSimulator::residual_of_keyframe(std::size_t k) const {
  std::array<double, 5> r{};
  if (!options_.synergy.enable_residuals) return r;
  Rng rng(mix_seed(mix_seed(options_.seed, kResidualStream), k));
  for (std::size_t i = 0; i < r.size(); ++i) {
    const double sigma = i == 0 ? options_.synergy.thumb_ip_residual_sigma_rad : options_.synergy.dip_residual_sigma_rad;
    r[i] = sigma * ftm_sim_truncated_normal(rng, 3.0);
  }
  return r;
}

double FtmWearerSimulator::contact_level(std::size_t device, TimeNs t) const {
  // Pinch-grasp keyframes cycle relaxed, pinch, relaxed, tripod, relaxed,
  // power. A device's fingertip holds the object from when the closing move
  // is 90 % done until the opening move is 10 % done, with 30 ms edges (the
  // device ramps its motors). Pinch: thumb and index; tripod and power: all three.
  if (options_.protocol != sim::MotionProtocol::pinch_grasp || t < task_begin_ns_) return 0.0;
  static const double on_frac = ftm_sim_mj_inverse(0.9), off_frac = ftm_sim_mj_inverse(0.1);
  const auto& mo = motion_.options();
  const double interval = mo.target_interval_s, transition = std::min(mo.transition_s, interval);
  const double tau = ns_to_seconds(t - task_begin_ns_);
  const auto k = static_cast<std::int64_t>(tau / interval);
  constexpr double kEdge = 0.03;
  double level = 0.0;
  for (std::int64_t j = std::max<std::int64_t>(k - 1, 0); j <= k; ++j) {
    const auto c = j % 6;
    if (c != 1 && c != 3 && c != 5) continue;
    if (c == 1 && device == 2) continue;  // plain pinch: no middle finger
    const double t_on = static_cast<double>(j) * interval + on_frac * transition;
    const double t_off = static_cast<double>(j + 1) * interval + off_frac * transition;
    const double l = std::clamp((tau - t_on) / kEdge, 0.0, 1.0) * std::clamp((t_off - tau) / kEdge, 0.0, 1.0);
    level = std::max(level, l);
  }
  return level;
}

Pose FtmWearerSimulator::wrist_at(TimeNs t, HandAngles& a) const {
  // The IMU simulator, the dipoles riding on the hand, the bend sensors and
  // truth_at ask for the same instants several times; the motion generator's
  // sample() is the costly part, so recent answers are kept.
  for (const auto& m : memo_) {
    if (m.valid && m.t == t) {
      a = m.angles;
      return m.wrist;
    }
  }
  MemoEntry& slot = memo_[memo_next_];
  memo_next_ = (memo_next_ + 1) % memo_.size();
  slot.wrist = compute_wrist_at(t, slot.angles);
  slot.t = t;
  slot.valid = true;
  a = slot.angles;
  return slot.wrist;
}

Pose FtmWearerSimulator::compute_wrist_at(TimeNs t, HandAngles& a) const {
  const auto& cal = options_.calibration;
  const JointLimits& lim = model_.limits();
  t = std::max<TimeNs>(t, 0);
  const double ts = ns_to_seconds(t);

  // Calibration state (poses, wobble) at t, for pose phases and the task's lead-in.
  auto wobble_env = [&](double env, HandAngles& x, Pose& w) {
    if (!cal.enable_wobble || env <= 0.0) return;
    for (std::size_t i = 0; i < kHandDofCount; ++i) {
      const double f1 = 0.3 + 0.013 * static_cast<double>(i), f2 = 0.9 + 0.011 * static_cast<double>(i);
      x[i] += env * cal.wobble_amplitude_rad *
              (0.7 * std::sin(kTwoPi * f1 * ts + wobble_phase_[2 * i]) + 0.3 * std::sin(kTwoPi * f2 * ts + wobble_phase_[2 * i + 1]));
    }
    Vec3 dp, dr;
    for (int k = 0; k < 3; ++k) {
      const auto kk = static_cast<std::size_t>(k);
      dp[k] = env * cal.wrist_wobble_m * std::sin(kTwoPi * (0.23 + 0.05 * k) * ts + wobble_phase_[40 + kk]);
      dr[k] = env * cal.wrist_wobble_rad * std::sin(kTwoPi * (0.31 + 0.07 * k) * ts + wobble_phase_[43 + kk]);
    }
    w = Pose{(so3_exp(dr) * w.q).normalized(), w.p + dp};
  };

  if (t >= task_begin_ns_ && options_.driven_task) {
    Pose w = driven_at(t, a);
    a = lim.clamp(a);
    const double lead = ns_to_seconds(t - task_begin_ns_);
    if (cal.enabled && lead < cal.task_transition_s) {
      HandAngles c = held_[2];
      Pose cw = T_world_wrist_rest_;
      wobble_env(1.0, c, cw);
      c = lim.clamp(c);
      const double s = sim::minimum_jerk(lead / cal.task_transition_s);
      for (std::size_t i = 0; i < kHandDofCount; ++i) a[i] = c[i] + s * (a[i] - c[i]);
      w = interpolate(cw, w, s);
    }
    return w;
  }
  if (t >= task_begin_ns_) {
    const TimeNs tau_ns = t - task_begin_ns_;
    const auto frame = motion_.sample(tau_ns);
    a = frame.angles;
    // Synergy residuals, moved with the generator's keyframe transitions.
    const auto& mo = motion_.options();
    const double tau = ns_to_seconds(tau_ns), transition = std::min(mo.transition_s, mo.target_interval_s);
    const std::size_t k = frame.keyframe;
    std::array<double, 5> r = residual_of_keyframe(k);
    const double into = tau - static_cast<double>(k) * mo.target_interval_s;
    if (k > 0 && into < transition) {
      const auto r0 = residual_of_keyframe(k - 1);
      const double s = sim::minimum_jerk(into / transition);
      for (std::size_t i = 0; i < r.size(); ++i) r[i] = r0[i] + s * (r[i] - r0[i]);
    }
    for (std::size_t i = 0; i < r.size(); ++i) a[index_of(kDistalDofs[i])] += r[i];
    a = lim.clamp(a);
    Pose w = frame.T_world_wrist;
    const double lead = ns_to_seconds(tau_ns);
    if (cal.enabled && lead < cal.task_transition_s) {
      HandAngles c = held_[2];
      Pose cw = T_world_wrist_rest_;
      wobble_env(1.0, c, cw);
      c = lim.clamp(c);
      const double s = sim::minimum_jerk(lead / cal.task_transition_s);
      for (std::size_t i = 0; i < kHandDofCount; ++i) a[i] = c[i] + s * (a[i] - c[i]);
      w = interpolate(cw, w, s);
    }
    return w;
  }

  const FtmPhase ph = phase_at(t);
  if (ph == FtmPhase::figure_eight) {
    a = relaxed_;
    const double dur = cal.figure_eight_s, ramp = 1.5;
    const double env = sim::minimum_jerk(ts / ramp) * sim::minimum_jerk((dur - ts) / ramp);
    const auto& p = figure_eight_phase_;
    const double yaw = env * cal.figure_eight_yaw_rad * std::sin(kTwoPi * 0.21 * ts + p[0]);
    const double pitch = env * cal.figure_eight_pitch_rad * std::sin(kTwoPi * 0.29 * ts + p[1]);
    const double roll = env * cal.figure_eight_roll_rad * std::sin(kTwoPi * 0.17 * ts + p[2]);
    const double w8 = kTwoPi * 0.25 * ts + p[3];
    const Vec3 dp(env * cal.figure_eight_path_m * std::sin(w8), env * 0.5 * cal.figure_eight_path_m * std::sin(2.0 * w8),
                  0.0);
    const Quat dq = so3_exp(yaw * Vec3::UnitY()) * so3_exp(pitch * Vec3::UnitX()) * so3_exp(roll * Vec3::UnitZ());
    const Pose delta = ftm_sim_mirror(options_.hand, Pose{dq, dp});
    return Pose{(delta.q * T_world_wrist_rest_.q).normalized(), T_world_wrist_rest_.p + delta.p};
  }
  // A pose phase: move from the previous state into the held pose, then hold.
  const auto i = static_cast<std::size_t>(ph) - 1;
  const FtmPhaseSpan& span = phases_[i + 1];
  const HandAngles& from = i == 0 ? relaxed_ : held_[i - 1];
  const double s = sim::minimum_jerk(ns_to_seconds(t - span.begin_ns) / cal.pose_transition_s);
  for (std::size_t j = 0; j < kHandDofCount; ++j) a[j] = from[j] + s * (held_[i][j] - from[j]);
  Pose w = T_world_wrist_rest_;
  wobble_env(i == 0 ? s : 1.0, a, w);
  a = lim.clamp(a);
  return w;
}

HandAngles FtmWearerSimulator::angles_at(TimeNs t) const {
  HandAngles a{};
  (void)wrist_at(t, a);
  return a;
}

HandPose FtmWearerSimulator::pose_at(TimeNs t) const {
  HandAngles a{};
  const Pose w = wrist_at(t, a);
  return model_.forward(options_.hand, a, w, t);
}

FtmWearerSimulator::Truth FtmWearerSimulator::truth_at(TimeNs t) const {
  Truth tr;
  tr.time_ns = t;
  const Pose w = wrist_at(t, tr.angles);
  tr.pose = model_.forward(options_.hand, tr.angles, w, t);
  tr.phase = phase_at(t);
  const Vec3 earth = env_->earth_field_world_T();
  const auto mounts = imu_sim_->mountings();
  for (std::size_t i = 0; i < ftm::kFtmImuCount && i < mounts.size(); ++i) {
    const Vec3 p = (tr.pose.joint(mounts[i].segment) * mounts[i].T_segment_imu).p;
    const Vec3 d = env_->disturbance_world_T(p, t, &tr.pose);
    const Vec3 total = earth + d;
    tr.mag_disturbance_uT[i] = d.norm() * 1e6;
    const double angle = std::acos(std::clamp(total.normalized().dot(earth.normalized()), -1.0, 1.0));
    const double dmag = std::abs(total.norm() - earth.norm()) / earth.norm();
    const Vec3 up = Vec3::UnitY();  // OpenXR world
    const Vec3 h_total = total - total.dot(up) * up, h_earth = earth - earth.dot(up) * up;
    tr.mag_heading_deviation_rad[i] = std::atan2(h_total.cross(h_earth).norm(), h_total.dot(h_earth));
    tr.mag_norm_deviation[i] = dmag;
    auto dip = [&up](const Vec3& f) { return std::asin(std::clamp(-f.normalized().dot(up), -1.0, 1.0)); };
    tr.mag_dip_deviation_rad[i] = std::abs(dip(total) - dip(earth));
    tr.mag_disturbed[i] = angle > options_.magnetic.disturbed_angle_rad ||
                          dmag > options_.magnetic.disturbed_magnitude_fraction;
  }
  for (std::size_t d = 0; d < 3; ++d) {
    tr.contact[d] = contact_level(d, t);
    tr.fingertip_current_A[d] = device_dipole_[d] ? env_->current_A(*device_dipole_[d], t) : 0.0;
  }
  return tr;
}

void FtmWearerSimulator::set_fingertip_current(Finger f, TimeNs from_ns, double amperes) {
  const auto d = static_cast<std::size_t>(f);
  if (d >= 3 || !device_dipole_[d]) return;
  (void)env_->set_current(*device_dipole_[d], from_ns, amperes);
}

void FtmWearerSimulator::drive(TimeNs t_ns, const Pose& T_world_wrist, const HandAngles& angles) {
  if (!options_.driven_task) return;
  const TimeNs before = driven_until_ns();
  if (!driven_.empty() && t_ns <= before) {
    if (t_ns < before) return;  // time runs forward only
    driven_.back() = {t_ns, T_world_wrist, angles};
  } else {
    driven_.push_back({t_ns, T_world_wrist, angles});
  }
  // Answers for times after the previous newest sample were a hold (or the
  // rest pose); they change now.
  for (auto& m : memo_) {
    if (m.valid && (before < 0 || m.t >= before)) m.valid = false;
  }
  while (driven_begin_ + 1 < driven_.size() && driven_[driven_begin_ + 1].t < t_ns - 2 * kNsPerSecond) ++driven_begin_;
  if (driven_begin_ > 4096) {
    driven_.erase(driven_.begin(), driven_.begin() + static_cast<std::ptrdiff_t>(driven_begin_));
    driven_begin_ = 0;
  }
}

Pose FtmWearerSimulator::driven_at(TimeNs t, HandAngles& a) const {
  if (driven_begin_ >= driven_.size()) {
    a = relaxed_;
    return T_world_wrist_rest_;
  }
  const auto first = driven_.begin() + static_cast<std::ptrdiff_t>(driven_begin_);
  auto hi = std::lower_bound(first, driven_.end(), t, [](const DrivenSample& d, TimeNs x) { return d.t < x; });
  if (hi == driven_.end()) {
    a = driven_.back().angles;
    return driven_.back().wrist;
  }
  if (hi == first || hi->t == t) {
    a = hi->angles;
    return hi->wrist;
  }
  const auto lo = hi - 1;
  const double s = static_cast<double>(t - lo->t) / static_cast<double>(hi->t - lo->t);
  for (std::size_t i = 0; i < kHandDofCount; ++i) a[i] = lo->angles[i] + s * (hi->angles[i] - lo->angles[i]);
  return interpolate(lo->wrist, hi->wrist, s);
}

double FtmWearerSimulator::bend_capacitance_truth_pF(ftm::FtmBend b, TimeNs t) const {
  return bend_capacitance_of(b, angles_at(t)[index_of(dof_of(b))], t);
}

double FtmWearerSimulator::bend_capacitance_of(ftm::FtmBend b, double theta, TimeNs t) const {
  const auto i = index_of(b);
  const auto& o = options_.bend;
  const double n = o.enable_nonlinearity ? o.nonlinearity_per_rad2 : 0.0;
  double c = bend_c0_[i] * (1.0 + bend_gain_[i] * theta + n * theta * theta);
  if (o.enable_contact_artefact) c += o.contact_artefact_pF * contact_level(i, t);
  return c;
}

void FtmWearerSimulator::generate_until(TimeNs T) {
  // IMUs: a tick's readings lie within ±0.45 period of its nominal time.
  const DurationNs imu_period = options_.imu.period_ns();
  while (imu_sim_->next_nominal_time_ns() - imu_period / 2 <= T) {
    const auto readings = imu_sim_->next();
    for (std::size_t i = 0; i < readings.size(); ++i) {
      const auto& r = readings[i];
      ftm::FtmEvent e;
      e.kind = ftm::FtmEvent::Kind::imu;
      e.index = static_cast<std::uint8_t>(i);
      e.imu.time_ns = r.time_ns;
      e.imu.accel_mps2 = r.sample.accel_mps2;
      e.imu.gyro_radps = r.sample.gyro_radps;
      e.imu.mag_uT = r.sample.mag_T ? Vec3(*r.sample.mag_T * 1e6) : Vec3(Vec3::Zero());
      e.imu.mag_fresh = r.mag_fresh;
      e.imu.status = static_cast<std::uint8_t>((r.accel_saturated ? ftm::sample_status::accel_saturated : 0) |
                                               (r.gyro_saturated ? ftm::sample_status::gyro_saturated : 0) |
                                               (r.mag_overflow ? ftm::sample_status::mag_overflow : 0));
      pending_.push_back(e);
    }
  }
  // Bend sensors on the board's 1 kHz grid.
  const auto& bo = options_.bend;
  const double bend_dt = 1.0 / bo.rate_hz;
  const double alpha = (bo.enable_lowpass && bo.lowpass_tau_s > 0.0) ? 1.0 - std::exp(-bend_dt / bo.lowpass_tau_s) : 1.0;
  for (;;) {
    const TimeNs tb = static_cast<TimeNs>(std::llround(static_cast<double>(bend_tick_) * 1e9 / bo.rate_hz));
    if (tb > T) break;
    const HandAngles a = angles_at(tb);  // once per tick, not per sensor
    for (std::size_t b = 0; b < ftm::kFtmBendCount; ++b) {
      const auto fb = static_cast<ftm::FtmBend>(b);
      const double c = bend_capacitance_of(fb, a[index_of(dof_of(fb))], tb);
      bend_state_pF_[b] = bend_started_ ? bend_state_pF_[b] + alpha * (c - bend_state_pF_[b]) : c;
      const double z = bend_noise_rng_[b].normal();
      ftm::FtmEvent e;
      e.kind = ftm::FtmEvent::Kind::bend;
      e.index = static_cast<std::uint8_t>(b);
      e.bend.time_ns = tb;
      e.bend.capacitance_pF = bend_state_pF_[b] + (bo.enable_noise ? bo.noise_sigma_pF * z : 0.0);
      pending_.push_back(e);
    }
    bend_started_ = true;
    ++bend_tick_;
  }
  // Wrist tracker.
  const auto& wo = options_.wrist;
  const double wdt = 1.0 / wo.rate_hz;
  for (;;) {
    const TimeNs tw = static_cast<TimeNs>(std::llround(static_cast<double>(wrist_tick_) * 1e9 / wo.rate_hz));
    if (tw > T) break;
    // Draw everything every tick so one switch does not shift another's stream.
    Vec3 jp, jr;
    for (int k = 0; k < 3; ++k) jp[k] = wrist_jitter_rng_.normal();
    for (int k = 0; k < 3; ++k) jr[k] = wrist_jitter_rng_.normal();
    const double u = wrist_dropout_rng_.uniform01();
    if (wo.enable_dropouts) {
      wrist_dropped_ = wrist_dropped_ ? !(u < wdt / wo.dropout_mean_duration_s) : (u < wdt / wo.dropout_mean_interval_s);
    }
    const TimeNs src = tw - (wo.enable_latency ? seconds_to_ns(wo.latency_s) : 0);
    HandAngles unused{};
    Pose w = wrist_at(src, unused);
    if (wo.enable_jitter) w = Pose{(so3_exp(wo.jitter_sigma_rad * jr) * w.q).normalized(), w.p + wo.jitter_sigma_m * jp};
    ftm::FtmEvent e;
    e.kind = ftm::FtmEvent::Kind::wrist;
    e.wrist.time_ns = tw;
    e.wrist.valid = !wrist_dropped_;
    // A lost tracker repeats its last pose, flagged invalid.
    if (e.wrist.valid) wrist_last_ = w;
    e.wrist.T_world_wrist = wrist_last_;
    pending_.push_back(e);
    ++wrist_tick_;
  }
}

void FtmWearerSimulator::advance(TimeNs t_ns, std::vector<ftm::FtmEvent>& out) {
  const TimeNs T = std::min(t_ns, end_ns_);
  if (T < 0) return;
  generate_until(T);
  std::stable_sort(pending_.begin(), pending_.end(), [](const ftm::FtmEvent& a, const ftm::FtmEvent& b) {
    if (a.time_ns() != b.time_ns()) return a.time_ns() < b.time_ns();
    if (a.kind != b.kind) return a.kind < b.kind;
    return a.index < b.index;
  });
  std::size_t n = 0;
  while (n < pending_.size() && pending_[n].time_ns() <= T) ++n;
  out.insert(out.end(), pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(n));
  pending_.erase(pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(n));
}

std::string FtmWearerSimulator::describe() const {
  char buf[256];
  std::snprintf(buf, sizeof buf, " | phases %zu, task from %.2fs to %.2fs | C0 %.2f/%.2f/%.2f pF", phases_.size(),
                ns_to_seconds(task_begin_ns_), ns_to_seconds(end_ns_), bend_c0_[0], bend_c0_[1], bend_c0_[2]);
  return options_.describe() + buf + " | " + env_->describe();
}

}  // namespace proprio::ftm_sim
