#include "proprio/ftm/ftm_tracker.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace proprio::ftm {
namespace {

constexpr std::size_t kD = 0, kT = 1, kI = 2, kM = 3;  // index_of(FtmImu::...)

// Mirror through the wrist's YZ plane (as HandModel does for the left hand).
Quat mirror_q(const Quat& q) { return Quat(q.w(), q.x(), -q.y(), -q.z()); }
Pose mirror_pose(const Pose& T) { return {mirror_q(T.q), Vec3(-T.p.x(), T.p.y(), T.p.z())}; }

Quat rot_x(double a) { return Quat(Eigen::AngleAxisd(a, Vec3::UnitX())); }
Quat rot_y(double a) { return Quat(Eigen::AngleAxisd(a, Vec3::UnitY())); }

std::size_t di(HandDof d) { return index_of(d); }

}  // namespace

Status FtmTrackerOptions::validate() const {
  if (auto s = attitude.validate(); !s) return s.error().with_context("FtmTrackerOptions.attitude");
  if (!std::isfinite(synergies.dip_from_pip) || !std::isfinite(synergies.thumb_ip_from_mcp))
    return make_error(Errc::invalid_argument, "FtmTrackerOptions.synergies ratios must be finite");
  if (!(thumb_cmc_axis_offset_m >= 0.0 && thumb_cmc_axis_offset_m <= 0.03))
    return make_error(Errc::invalid_argument,
                      "FtmTrackerOptions.thumb_cmc_axis_offset_m must be in [0, 0.03] m (a few mm on a real hand)");
  if (imu_timeout_ns <= 0) return make_error(Errc::invalid_argument, "FtmTrackerOptions.imu_timeout_ns must be > 0");
  if (bend_timeout_ns <= 0) return make_error(Errc::invalid_argument, "FtmTrackerOptions.bend_timeout_ns must be > 0");
  if (wrist_timeout_ns <= 0)
    return make_error(Errc::invalid_argument, "FtmTrackerOptions.wrist_timeout_ns must be > 0");
  if (auto s = still.validate(); !s) return s.error().with_context("FtmTrackerOptions.still");
  return {};
}

std::string FtmTrackerOptions::describe() const {
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "FTM tracker: %s hand, synergies %s (DIP %.3f PIP, thumb IP %.3f MCP), thumb CMC offset %.1f mm, "
                "abduction %s, timeouts IMU %.0f ms / bend %.0f ms / wrist %.0f ms; ",
                std::string(to_string(hand)).c_str(), synergies.enabled ? "on" : "off", synergies.dip_from_pip,
                synergies.thumb_ip_from_mcp, thumb_cmc_axis_offset_m * 1e3, track_abduction ? "tracked" : "held at 0",
                static_cast<double>(imu_timeout_ns) * 1e-6, static_cast<double>(bend_timeout_ns) * 1e-6,
                static_cast<double>(wrist_timeout_ns) * 1e-6);
  return buf + std::string("turn-on gyro offset from a still start: ") +
         (still_start_gyro_bias ? still.describe() : std::string("off")) + "; " + attitude.describe();
}

Result<FtmTracker> FtmTracker::create(const FtmTrackerOptions& options, const FtmCalibration& calibration) {
  if (auto s = options.validate(); !s) return s.error();
  if (auto s = calibration.validate(); !s) return s.error();
  if (options.hand != calibration.hand) {
    return make_error(Errc::invalid_argument, "FTM tracker for the " + std::string(to_string(options.hand)) +
                                                  " hand was given a " + std::string(to_string(calibration.hand)) +
                                                  "-hand calibration");
  }
  auto shape = HandShape::from_measurements(calibration.hand_length_m, calibration.hand_width_m);
  if (!shape) return shape.error();
  MahonyOptions mo = options.attitude;
  mo.mag_ref_in_world_uT = calibration.earth_field_world_uT;
  if (auto s = mo.validate(); !s) return s.error().with_context("FTM tracker: calibrated Earth field");
  std::vector<MahonyFilter> filters;
  filters.reserve(kFtmImuCount);
  for (std::size_t i = 0; i < kFtmImuCount; ++i) {
    // The calibration's turn-on gyro offset seeds each bias integrator (it
    // keeps learning from there); zero means none was estimated.
    MahonyOptions mi = mo;
    if (!calibration.gyro_bias_radps[i].isZero()) mi.initial_bias_radps = calibration.gyro_bias_radps[i];
    filters.emplace_back(mi);
  }
  return FtmTracker(options, calibration, HandModel(*shape), std::move(filters));
}

FtmTracker::FtmTracker(const FtmTrackerOptions& options, const FtmCalibration& calibration, HandModel model,
                       std::vector<MahonyFilter> filters)
    : options_(options), calibration_(calibration), model_(std::move(model)), filters_(std::move(filters)) {
  const auto& f = model_.shape().fingers;
  q_rest_conj_[kD] = Quat::Identity();
  q_rest_conj_[kT] = f[0].q_wrist_metacarpal_rest.conjugate();
  q_rest_conj_[kI] = f[1].q_wrist_metacarpal_rest.conjugate();
  q_rest_conj_[kM] = f[2].q_wrist_metacarpal_rest.conjugate();
  const HandPose rest = model_.forward(Handedness::right, HandAngles{}, Pose::identity(), 0);
  radius_m_ = rest.radius_m;
  reset();
}

void FtmTracker::reset() noexcept {
  for (auto& f : filters_) f.reset();
  for (std::size_t i = 0; i < kFtmImuCount; ++i) {
    still_[i] = StillBiasAccumulator(options_.still);
    turn_on_state_[i] = !calibration_.gyro_bias_radps[i].isZero() ? TurnOnBias::from_calibration
                        : options_.still_start_gyro_bias         ? TurnOnBias::pending
                                                                 : TurnOnBias::off;
  }
  raw_.fill(0.0);
  angles_.fill(0.0);
  thumb_ps_rad_ = 0.0;
  q_cmc_ = Quat::Identity();
  imu_flags_.fill(0);
  imu_good_ns_.fill(0);
  imu_seen_.fill(false);
  last_accel_.fill(Vec3::Zero());
  last_gyro_.fill(Vec3::Zero());
  unchanged_since_ns_.fill(0);
  bend_good_ns_.fill(0);
  bend_seen_.fill(false);
  dof_measured_.fill(false);
  wrist_ = Pose::identity();
  wrist_good_ns_ = 0;
  wrist_seen_ = wrist_valid_now_ = false;
  last_q_world_hand_ = Quat::Identity();
  hand_seen_ = false;
  newest_ns_ = 0;
}

void FtmTracker::push(const FtmEvent& e) noexcept {
  switch (e.kind) {
    case FtmEvent::Kind::imu:
      if (e.index < kFtmImuCount) push_imu(static_cast<FtmImu>(e.index), e.imu);
      break;
    case FtmEvent::Kind::bend:
      if (e.index < kFtmBendCount) push_bend(static_cast<FtmBend>(e.index), e.bend);
      break;
    case FtmEvent::Kind::wrist: push_wrist(e.wrist); break;
  }
}

void FtmTracker::push_imu(FtmImu imu, const FtmImuSample& s) noexcept {
  const std::size_t i = index_of(imu);
  if (i >= kFtmImuCount) return;
  newest_ns_ = std::max(newest_ns_, s.time_ns);
  const bool usable =
      (s.status & ~sample_status::mag_overflow) == 0 && s.accel_mps2.allFinite() && s.gyro_radps.allFinite();
  if (!usable) {
    // Dropped before the filter: a stale, saturated or failed read says nothing new.
    imu_flags_[i] = kGyroInvalid | kAccelInvalid | kMagInvalid;
    return;
  }
  // A bus that keeps returning the same bytes: real sensors always carry noise.
  if (!imu_seen_[i] || s.accel_mps2 != last_accel_[i] || s.gyro_radps != last_gyro_[i]) {
    unchanged_since_ns_[i] = s.time_ns;
    last_accel_[i] = s.accel_mps2;
    last_gyro_[i] = s.gyro_radps;
  }
  if (turn_on_state_[i] == TurnOnBias::pending && !still_[i].add(s) && still_[i].complete()) {
    // The window is over: seed the bias from it, or leave it to the filter.
    if (const auto b = still_[i].accepted_gyro_bias()) {
      filters_[i].set_gyro_bias(*b);
      turn_on_state_[i] = TurnOnBias::estimated;
    } else {
      turn_on_state_[i] = TurnOnBias::refused;
    }
  }
  std::optional<Vec3> mag;
  if (s.mag_fresh && !(s.status & sample_status::mag_overflow) && s.mag_uT.allFinite())
    mag = calibration_.mag[i].apply(s.mag_uT);
  imu_flags_[i] = filters_[i].update(s.time_ns, s.gyro_radps, s.accel_mps2 - calibration_.accel_bias_mps2[i], mag);
  if (!(imu_flags_[i] & kTimeNotAdvancing) && filters_[i].initialised() &&
      filters_[i].q_world_body().coeffs().allFinite()) {
    imu_good_ns_[i] = s.time_ns;
    imu_seen_[i] = true;
  }
  update_imu_angles();
}

void FtmTracker::push_bend(FtmBend bend, const FtmBendSample& s) noexcept {
  const std::size_t b = index_of(bend);
  if (b >= kFtmBendCount) return;
  newest_ns_ = std::max(newest_ns_, s.time_ns);
  if (s.status != 0 || !std::isfinite(s.capacitance_pF)) return;
  const double theta = calibration_.beta0_rad[b] + calibration_.beta1_rad_per_pF[b] * s.capacitance_pF;
  if (!std::isfinite(theta)) return;
  raw_[di(dof_of(bend))] = theta;
  dof_measured_[di(dof_of(bend))] = true;
  bend_good_ns_[b] = s.time_ns;
  bend_seen_[b] = true;
  refresh_angles();
}

void FtmTracker::push_wrist(const FtmWristSample& s) noexcept {
  newest_ns_ = std::max(newest_ns_, s.time_ns);
  if (!s.valid || !s.T_world_wrist.p.allFinite() || !s.T_world_wrist.q.coeffs().allFinite() ||
      !(s.T_world_wrist.q.norm() > 0.5)) {
    wrist_valid_now_ = false;
    return;
  }
  wrist_ = {s.T_world_wrist.q.normalized(), s.T_world_wrist.p};
  wrist_good_ns_ = s.time_ns;
  wrist_seen_ = wrist_valid_now_ = true;
  // The wrist tracker only matters to the fingers when it stands in for the dorsum.
  if (!imu_ok(FtmImu::dorsum)) update_imu_angles();
}

bool FtmTracker::imu_ok(FtmImu imu) const noexcept {
  const std::size_t i = index_of(imu);
  if (i >= kFtmImuCount || !imu_seen_[i] || !filters_[i].initialised()) return false;
  if (newest_ns_ - imu_good_ns_[i] > options_.imu_timeout_ns) return false;
  return imu_good_ns_[i] - unchanged_since_ns_[i] <= options_.imu_timeout_ns;
}

bool FtmTracker::bend_ok(FtmBend bend) const noexcept {
  const std::size_t b = index_of(bend);
  return b < kFtmBendCount && bend_seen_[b] && newest_ns_ - bend_good_ns_[b] <= options_.bend_timeout_ns;
}

bool FtmTracker::wrist_ok() const noexcept {
  return wrist_seen_ && wrist_valid_now_ && newest_ns_ - wrist_good_ns_ <= options_.wrist_timeout_ns;
}

bool FtmTracker::hand_orientation(Quat& q, bool& tracked) const noexcept {
  if (imu_ok(FtmImu::dorsum)) {
    q = (filters_[kD].q_world_body() * calibration_.q_imu_segment[kD]).normalized();
    tracked = true;
    return true;
  }
  if (wrist_ok()) {
    q = wrist_.q;
    tracked = true;
    return true;
  }
  q = last_q_world_hand_;
  tracked = false;
  return hand_seen_;
}

void FtmTracker::update_imu_angles() noexcept {
  Quat q_world_hand;
  bool hand_tracked = false;
  if (hand_orientation(q_world_hand, hand_tracked) && hand_tracked) {
    last_q_world_hand_ = q_world_hand;
    hand_seen_ = true;
    const Quat q_hand_world = q_world_hand.conjugate();
    const bool left = options_.hand == Handedness::left;
    // R_h_x = R_s_hᵀ R_s_b R_b_f, in the right-hand frames HandModel's rest poses use.
    auto relative = [&](std::size_t i) {
      const Quat r = (q_hand_world * filters_[i].q_world_body() * calibration_.q_imu_segment[i]).normalized();
      return left ? mirror_q(r) : r;
    };
    if (imu_ok(FtmImu::thumb_metacarpal)) {
      const Quat q_cmc = (q_rest_conj_[kT] * relative(kT)).normalized();
      const Mat3 M = q_cmc.toRotationMatrix();
      // M = Ry(aa) Rx(-fe) Rz(ps): M(1,2) = sin fe, M(0,2)/M(2,2) = tan aa, M(1,0)/M(1,1) = tan ps.
      const double fe = std::atan2(M(1, 2), std::hypot(M(1, 0), M(1, 1)));
      const double aa = std::atan2(M(0, 2), M(2, 2));
      const double ps = std::atan2(M(1, 0), M(1, 1));
      if (std::isfinite(fe) && std::isfinite(aa) && std::isfinite(ps)) {
        raw_[di(HandDof::thumb_cmc_flexion)] = fe;
        raw_[di(HandDof::thumb_cmc_abduction)] = aa;
        thumb_ps_rad_ = ps;
        q_cmc_ = q_cmc;
        dof_measured_[di(HandDof::thumb_cmc_flexion)] = dof_measured_[di(HandDof::thumb_cmc_abduction)] = true;
      }
    }
    for (std::size_t i : {kI, kM}) {
      if (!imu_ok(static_cast<FtmImu>(i))) continue;
      const Mat3 M = (q_rest_conj_[i] * relative(i)).toRotationMatrix();
      const double aa = std::atan2(-M(2, 0), M(0, 0));
      const double fe = -std::atan2(-M(1, 2), M(1, 1));
      if (!std::isfinite(fe) || !std::isfinite(aa)) continue;
      const HandDof f = i == kI ? HandDof::index_mcp_flexion : HandDof::middle_mcp_flexion;
      const HandDof a = i == kI ? HandDof::index_mcp_abduction : HandDof::middle_mcp_abduction;
      raw_[di(f)] = fe;
      raw_[di(a)] = options_.track_abduction ? aa : 0.0;
      dof_measured_[di(f)] = dof_measured_[di(a)] = true;
    }
  }
  refresh_angles();
}

void FtmTracker::refresh_angles() noexcept {
  HandAngles a = raw_;
  if (!options_.track_abduction) a[di(HandDof::index_mcp_abduction)] = a[di(HandDof::middle_mcp_abduction)] = 0.0;
  // Ring and little follow the middle finger's flexion (the enslaving of
  // HandMotionGenerator's natural coupling); their abduction stays at rest.
  for (Finger f : {Finger::ring, Finger::little}) {
    a[first_dof_of(f) + 0] = a[di(HandDof::middle_mcp_flexion)];
    a[first_dof_of(f) + 1] = 0.0;
    a[first_dof_of(f) + 2] = a[di(HandDof::middle_pip_flexion)];
  }
  angles_ = options_.synergies.apply(a);
}

std::array<bool, kHandDofCount> FtmTracker::dof_tracked() const noexcept {
  std::array<bool, kHandDofCount> t{};
  const bool hand = imu_ok(FtmImu::dorsum) || wrist_ok();
  auto imu = [&](FtmImu i, HandDof d) { return hand && imu_ok(i) && dof_measured_[di(d)]; };
  t[di(HandDof::thumb_cmc_flexion)] = imu(FtmImu::thumb_metacarpal, HandDof::thumb_cmc_flexion);
  t[di(HandDof::thumb_cmc_abduction)] = imu(FtmImu::thumb_metacarpal, HandDof::thumb_cmc_abduction);
  t[di(HandDof::index_mcp_flexion)] = imu(FtmImu::index_proximal, HandDof::index_mcp_flexion);
  t[di(HandDof::index_mcp_abduction)] =
      options_.track_abduction && imu(FtmImu::index_proximal, HandDof::index_mcp_abduction);
  t[di(HandDof::middle_mcp_flexion)] = imu(FtmImu::middle_proximal, HandDof::middle_mcp_flexion);
  t[di(HandDof::middle_mcp_abduction)] =
      options_.track_abduction && imu(FtmImu::middle_proximal, HandDof::middle_mcp_abduction);
  for (FtmBend b : {FtmBend::thumb_mcp, FtmBend::index_pip, FtmBend::middle_pip})
    t[di(dof_of(b))] = bend_ok(b) && dof_measured_[di(dof_of(b))];
  return t;
}

void FtmTracker::estimate(HandPose& out) const noexcept {
  out.time_ns = newest_ns_;
  out.data_time_ns = newest_ns_;
  out.hand = options_.hand;
  out.has_velocity = false;
  out.radius_m = radius_m_;
  Quat q_world_hand;
  bool orient_tracked = false;
  if (!hand_orientation(q_world_hand, orient_tracked)) {
    out.active = false;
    for (auto& T : out.T_world_joint) T = Pose::identity();
    out.flags.fill(0);
    return;
  }
  out.active = true;
  const bool pos_valid = wrist_seen_;
  const bool pos_tracked = wrist_ok();
  const Pose T_world_wrist{q_world_hand, pos_valid ? wrist_.p : Vec3::Zero()};

  // Right-hand FK, the thumb replaced by its full measured rotation (and the
  // CMC axis offset), then mirrored for a left hand.
  auto T = model_.joint_poses_in_wrist(Handedness::right, angles_);
  {
    const HandShape::Finger& g = model_.shape().fingers[0];
    const Quat q_rest = q_rest_conj_[kT].conjugate();
    const double d = std::min(options_.thumb_cmc_axis_offset_m, g.bone_length_m[0]);
    const double aa = angles_[di(HandDof::thumb_cmc_abduction)];
    Quat q = (q_rest * q_cmc_).normalized();
    Vec3 p = g.p_base_in_wrist;
    T[index_of(HandJoint::thumb_metacarpal)] = {q, p};
    p += (q_rest * rot_y(aa)) * Vec3(0, 0, -d) + q * Vec3(0, 0, -(g.bone_length_m[0] - d));
    q = (q * rot_x(-angles_[di(HandDof::thumb_mcp_flexion)])).normalized();
    T[index_of(HandJoint::thumb_proximal)] = {q, p};
    p += q * Vec3(0, 0, -g.bone_length_m[1]);
    q = (q * rot_x(-angles_[di(HandDof::thumb_ip_flexion)])).normalized();
    T[index_of(HandJoint::thumb_distal)] = {q, p};
    p += q * Vec3(0, 0, -g.bone_length_m[2]);
    T[index_of(HandJoint::thumb_tip)] = {q, p};
  }
  const bool left = options_.hand == Handedness::left;
  for (std::size_t j = 0; j < kHandJointCount; ++j) {
    out.T_world_joint[j] = T_world_wrist * (left ? mirror_pose(T[j]) : T[j]);
  }

  const auto tracked = dof_tracked();
  std::uint8_t base = kOrientationValid;
  if (pos_valid) base |= kPositionValid;
  auto flags = [&](bool o, bool p) {
    std::uint8_t f = base;
    if (o && orient_tracked) f |= kOrientationTracked;
    if (p && pos_valid && pos_tracked && orient_tracked) f |= kPositionTracked;
    return f;
  };
  out.flags[index_of(HandJoint::wrist)] = flags(true, true);
  out.flags[index_of(HandJoint::palm)] = flags(true, true);
  for (std::size_t fi = 0; fi < kFingerCount; ++fi) {
    const auto f = static_cast<Finger>(fi);
    const FingerJoints fj = finger_joints(f);
    const std::size_t d0 = first_dof_of(f);
    // The DOFs each joint rotation of the chain applies (HandModel's order).
    std::array<bool, 4> rot_ok{};
    if (f == Finger::thumb) {
      rot_ok = {tracked[d0] && tracked[d0 + 1], tracked[d0 + 2], tracked[d0 + 3], true};
    } else {
      rot_ok = {true, tracked[d0] && tracked[d0 + 1], tracked[d0 + 2], tracked[d0 + 3]};
    }
    // Ring and little follow the middle finger: shown, never claimed tracked.
    const bool follower = f == Finger::ring || f == Finger::little;
    const std::size_t bones = model_.shape().fingers[fi].bone_count;
    for (std::size_t k = 0; k < fj.count; ++k) {
      bool o = true, p = true;
      for (std::size_t r = 0; r <= std::min(k, bones - 1); ++r) o = o && rot_ok[r];
      for (std::size_t r = 0; r < k; ++r) p = p && rot_ok[r];
      out.flags[index_of(fj.joints[k])] = flags(o && !follower, p && !follower);
    }
  }
  for (std::size_t j = 0; j < kHandJointCount; ++j) {
    if (!out.T_world_joint[j].p.allFinite() || !out.T_world_joint[j].q.coeffs().allFinite()) {
      out.T_world_joint[j] = T_world_wrist.p.allFinite() ? Pose{Quat::Identity(), T_world_wrist.p} : Pose::identity();
      out.flags[j] = 0;
    }
  }
}

}  // namespace proprio::ftm
