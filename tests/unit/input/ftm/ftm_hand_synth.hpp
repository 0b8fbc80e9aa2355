#pragma once
// Exact FTM readings of a hand in known angles, for the tracker and
// calibration tests and the FTM frame benchmark: HandModel FK gives each
// segment's frame, the mounting turns it into the IMU's, and the IMU reads
// gravity and the Earth field in its own axes (world: OpenXR, +Y up).
#include <array>
#include <cmath>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/random.hpp"
#include "proprio/ftm/ftm_calibration.hpp"
#include "proprio/ftm/ftm_glove.hpp"
#include "proprio/ftm/mahony_filter.hpp"

namespace proprio::ftm::hand_synth {

struct HandTruth {
  HandAngles angles{};
  Pose T_world_wrist;
};

// The world orientation of each IMU.
inline std::array<Quat, kFtmImuCount> imu_orientations(const HandModel& model, const FtmCalibration& truth,
                                                       const HandTruth& h) {
  const auto T = model.joint_poses_in_wrist(truth.hand, h.angles);
  std::array<Quat, kFtmImuCount> q;
  for (std::size_t i = 0; i < kFtmImuCount; ++i) {
    const Quat q_world_seg = h.T_world_wrist.q * T[index_of(segment_of(static_cast<FtmImu>(i)))].q;
    q[i] = (q_world_seg * truth.q_imu_segment[i].conjugate()).normalized();
  }
  return q;
}

// One IMU sample at rest in orientation q_world_imu; the raw compass undoes
// the calibration's correction (m_raw = soft_iron_inv⁻¹ m + hard_iron).
// `dither` (a few 1e-9) keeps consecutive samples from being bit-identical,
// which the tracker would take for a stuck bus.
inline FtmImuSample imu_sample(TimeNs t, const Quat& q_world_imu, const FtmCalibration& truth, std::size_t i,
                               double dither, bool mag_fresh = true) {
  const MahonyOptions o;
  FtmImuSample s;
  s.time_ns = t;
  const Quat q_imu_world = q_world_imu.conjugate();
  s.accel_mps2 = q_imu_world * o.gravity_ref_in_world_mps2 + Vec3::Constant(dither);
  s.gyro_radps = Vec3::Constant(dither);
  const Vec3 m = q_imu_world * truth.earth_field_world_uT;
  s.mag_uT = truth.mag[i].soft_iron_inv.inverse() * m + truth.mag[i].hard_iron_uT;
  s.mag_fresh = mag_fresh;
  return s;
}

inline FtmBendSample bend_sample(TimeNs t, const HandAngles& a, const FtmCalibration& truth, FtmBend b) {
  FtmBendSample s;
  s.time_ns = t;
  s.capacitance_pF = (a[index_of(dof_of(b))] - truth.beta0_rad[index_of(b)]) / truth.beta1_rad_per_pF[index_of(b)];
  return s;
}

inline FtmEvent imu_event(std::size_t i, const FtmImuSample& s) {
  FtmEvent e;
  e.kind = FtmEvent::Kind::imu;
  e.index = static_cast<std::uint8_t>(i);
  e.imu = s;
  return e;
}
inline FtmEvent bend_event(std::size_t b, const FtmBendSample& s) {
  FtmEvent e;
  e.kind = FtmEvent::Kind::bend;
  e.index = static_cast<std::uint8_t>(b);
  e.bend = s;
  return e;
}
inline FtmEvent wrist_event(TimeNs t, const Pose& T, bool valid = true) {
  FtmEvent e;
  e.kind = FtmEvent::Kind::wrist;
  e.wrist.time_ns = t;
  e.wrist.T_world_wrist = T;
  e.wrist.valid = valid;
  return e;
}

// One 200 Hz tick of the whole glove: 4 IMUs, 3 bend sensors, the wrist.
inline void tick(std::vector<FtmEvent>& out, const HandModel& model, const FtmCalibration& truth, const HandTruth& h,
                 TimeNs t, std::uint64_t k) {
  const auto q = imu_orientations(model, truth, h);
  const double dither = (k % 2 ? 1e-9 : -1e-9);
  for (std::size_t i = 0; i < kFtmImuCount; ++i) out.push_back(imu_event(i, imu_sample(t, q[i], truth, i, dither)));
  for (std::size_t b = 0; b < kFtmBendCount; ++b)
    out.push_back(bend_event(b, bend_sample(t, h.angles, truth, static_cast<FtmBend>(b))));
  out.push_back(wrist_event(t, h.T_world_wrist));
}

inline Quat random_rotation(Rng& rng, double max_angle_rad) {
  const Vec3 axis = Vec3(rng.normal(), rng.normal(), rng.normal()).normalized();
  return Quat(Eigen::AngleAxisd(rng.uniform(0.0, max_angle_rad), axis));
}

// Random angles for the DOFs the FTM measures, inside the default limits
// (shrunk by a margin); the others follow the tracker's own rules.
inline HandAngles random_tracked_angles(Rng& rng, const Synergies& syn) {
  const JointLimits lim = JointLimits::defaults();
  HandAngles a{};
  for (HandDof d : kFtmTrackedDofs) {
    const std::size_t i = index_of(d);
    const double span = lim.max_rad[i] - lim.min_rad[i];
    a[i] = rng.uniform(lim.min_rad[i] + 0.1 * span, lim.max_rad[i] - 0.1 * span);
  }
  for (Finger f : {Finger::ring, Finger::little}) {
    a[first_dof_of(f)] = a[index_of(HandDof::middle_mcp_flexion)];
    a[first_dof_of(f) + 2] = a[index_of(HandDof::middle_pip_flexion)];
  }
  return syn.apply(a);
}

}  // namespace proprio::ftm::hand_synth
