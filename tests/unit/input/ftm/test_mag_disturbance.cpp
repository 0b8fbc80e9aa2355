// The VQF-style magnetic-disturbance detector on its own (thresholds, hold
// time, expiry) and inside the filter: a magnet approaching a slowly turning
// IMU, the gated filter against the plain one.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "imu_synth.hpp"
#include "proprio/ftm/mag_disturbance.hpp"
#include "proprio/ftm/mahony_filter.hpp"

namespace proprio::ftm {
namespace mag_disturbance_test {

using namespace imu_synth;

constexpr TimeNs kStep = 10'000'000;  // 100 Hz compass

TEST(MagDisturbanceOptions, DefaultsValidateAndDescribe) {
  const MagDisturbanceOptions o;
  EXPECT_TRUE(o.validate().ok());
  EXPECT_NE(o.describe().find("8 %"), std::string::npos) << o.describe();
  MagDisturbanceOptions bad;
  bad.dip_tolerance_rad = 0.0;
  EXPECT_FALSE(bad.validate().ok());
  bad = {};
  bad.max_rejection_s = 0.2;  // shorter than the hold time
  EXPECT_FALSE(bad.validate().ok());
  bad = {};
  bad.hold_s = -1.0;
  EXPECT_FALSE(bad.validate().ok());
}

TEST(MagDisturbanceDetector, FlagsMagnitudeAndDipChangesBeyondTheirTolerances) {
  const Vec3 up = Vec3::UnitZ(), ref = earth_field_uT();
  MagDisturbanceOptions o;
  o.lowpass_tau_s = 0.0;  // judge each sample as it is
  o.hold_s = 0.0;
  MagDisturbanceDetector d(o, ref, up);
  EXPECT_NEAR(d.reference_dip_rad() / kDeg, 60.0, 1e-9);
  TimeNs t = 0;
  EXPECT_FALSE(d.update(t += kStep, ref, up));
  EXPECT_FALSE(d.update(t += kStep, 1.06 * ref, up)) << "6 % is inside the 8 % tolerance";
  EXPECT_TRUE(d.update(t += kStep, 1.10 * ref, up));
  EXPECT_FALSE(d.update(t += kStep, 0.94 * ref, up));
  EXPECT_TRUE(d.update(t += kStep, 0.90 * ref, up));
  // Same magnitude, dip 60° -> 54° and 50° (tolerance 8°).
  const Vec3 east = Vec3::UnitY();
  EXPECT_FALSE(d.update(t += kStep, Quat(Eigen::AngleAxisd(-6.0 * kDeg, east)) * ref, up));
  EXPECT_TRUE(d.update(t += kStep, Quat(Eigen::AngleAxisd(-10.0 * kDeg, east)) * ref, up));
  // Turning the sensor does not change magnitude or dip: no flag.
  const Quat q(Eigen::AngleAxisd(2.0, Vec3(0.3, -0.5, 0.8).normalized()));
  EXPECT_FALSE(d.update(t += kStep, q.conjugate() * ref, q.conjugate() * up));
  // Non-finite input changes nothing.
  EXPECT_FALSE(d.update(t += kStep, Vec3(NAN, 0, 0), up));
}

TEST(MagDisturbanceDetector, HoldsTheFlagAndGivesUpAfterMaxRejection) {
  const Vec3 up = Vec3::UnitZ(), ref = earth_field_uT();
  MagDisturbanceOptions o;  // hold 0.5 s, low-pass 0.05 s, give up after 60 s
  MagDisturbanceDetector d(o, ref, up);
  TimeNs t = 0;
  for (int i = 0; i < 100; ++i) ASSERT_FALSE(d.update(t += kStep, ref, up));
  for (int i = 0; i < 50; ++i) d.update(t += kStep, 1.5 * ref, up);
  EXPECT_TRUE(d.disturbed());
  // Back to normal: the low-pass takes a few samples, then the hold 0.5 s.
  int flagged_after = 0;
  for (int i = 0; i < 100; ++i) flagged_after += d.update(t += kStep, ref, up) ? 1 : 0;
  EXPECT_GE(flagged_after, 50);
  EXPECT_LE(flagged_after, 60);
  EXPECT_FALSE(d.disturbed());
  // A lasting change: flagged for 60 s, then accepted.
  bool expired_early = false;
  for (int i = 0; i < 5900; ++i) {
    d.update(t += kStep, 1.5 * ref, up);
    expired_early |= d.rejection_expired();
  }
  EXPECT_FALSE(expired_early);
  for (int i = 0; i < 200; ++i) d.update(t += kStep, 1.5 * ref, up);
  EXPECT_TRUE(d.disturbed());
  EXPECT_TRUE(d.rejection_expired());
}

// An IMU yawing slowly (±30°, 0.1 Hz) on a table while a magnet (0.1 A·m², a
// small neodymium magnet or a tool's motor) approaches from 60 cm to 8 cm in
// 3 s, stays 10 s, and leaves in 3 s (Fig. 4.14 of the thesis: drill, fan,
// earphone case).
struct DipoleScenario {
  double approach_start_s = 20.0, approach_s = 3.0, stay_s = 10.0;
  Vec3 direction = Vec3(0.6, 0.5, 0.62).normalized();  // from the IMU towards the magnet
  Vec3 moment_Am2 = 0.1 * Vec3(-0.8, 0.2, 0.55).normalized();
  double far_m = 0.6, near_m = 0.08;

  double distance(double t) const {
    const double u = t - approach_start_s;
    if (u < 0.0) return far_m;
    if (u < approach_s) return far_m - raised_cosine(u, approach_s, far_m - near_m)[0];
    if (u < approach_s + stay_s) return near_m;
    if (u < 2.0 * approach_s + stay_s) return near_m + raised_cosine(u - approach_s - stay_s, approach_s, far_m - near_m)[0];
    return far_m;
  }
  Vec3 field(double t, const Vec3& p) const {
    return dipole_field_uT(moment_Am2, distance(t) * direction, p);
  }
  bool close(double t) const {
    const double u = t - approach_start_s - approach_s;
    return u >= 0.0 && u < stay_s;
  }
};

Motion yawing(double t) {
  const double a = 30.0 * kDeg, w = 2.0 * M_PI * 0.1;
  Motion m;
  m.q_world_body = Quat(Eigen::AngleAxisd(a * std::sin(w * t), Vec3::UnitZ()));
  m.omega_body_radps = Vec3(0.0, 0.0, a * w * std::cos(w * t));
  return m;
}

double heading_error_deg(const Quat& estimate, const Quat& truth) {
  return std::abs(wrap_pi(euler_zyx_rad(estimate)[0] - euler_zyx_rad(truth)[0])) / kDeg;
}

struct DipoleRun {
  int strong = 0, strong_flagged = 0, quiet = 0, quiet_flagged = 0;
  double gated_max = 0.0, plain_max = 0.0, gated_mean = 0.0, plain_mean = 0.0, max_disturbance_uT = 0.0;
  double detection() const { return static_cast<double>(strong_flagged) / strong; }
  double false_alarm() const { return static_cast<double>(quiet_flagged) / quiet; }
};

// The same samples through the gated filter and the plain one. "Strong":
// compass samples whose disturbance exceeds 10 % of the Earth field; "quiet":
// under 1 %. Heading errors over the 10 s the magnet is closest.
DipoleRun run_dipole(const DipoleScenario& scenario, std::uint64_t seed) {
  NoiseModel noise;
  noise.gyro_bias_radps = Vec3(0.3, -0.2, 0.25) * kDeg;
  const std::vector<Sample> samples =
      synthesise(50.0, yawing, noise, seed, [&](double t, const Vec3& p) { return scenario.field(t, p); });
  MahonyOptions gated_options;
  gated_options.gravity_ref_in_world_mps2 = gravity_ref_z_up();
  gated_options.mag_ref_in_world_uT = earth_field_uT();
  MahonyOptions plain_options = gated_options;
  plain_options.gate_mag = false;
  MahonyFilter gated(gated_options), plain(plain_options);
  DipoleRun r;
  int close_n = 0;
  for (const Sample& s : samples) {
    const std::uint32_t fg = gated.update(s.t_ns, s.gyro_radps, s.accel_mps2, s.mag_uT);
    const std::uint32_t fp = plain.update(s.t_ns, s.gyro_radps, s.accel_mps2, s.mag_uT);
    if (!s.mag_uT) continue;
    const bool flagged = (fg & kMagDisturbed) != 0;
    EXPECT_EQ((fg & kMagGated) != 0, flagged);
    EXPECT_FALSE(fp & kMagGated);
    const double rel = s.disturbance_world_uT.norm() / earth_field_uT().norm();
    r.max_disturbance_uT = std::max(r.max_disturbance_uT, s.disturbance_world_uT.norm());
    if (rel > 0.10) {
      ++r.strong;
      r.strong_flagged += flagged ? 1 : 0;
    } else if (rel < 0.01) {
      ++r.quiet;
      r.quiet_flagged += flagged ? 1 : 0;
    }
    if (scenario.close(ns_to_seconds(s.t_ns))) {
      const double eg = heading_error_deg(gated.q_world_body(), s.truth.q_world_body);
      const double ep = heading_error_deg(plain.q_world_body(), s.truth.q_world_body);
      r.gated_max = std::max(r.gated_max, eg);
      r.plain_max = std::max(r.plain_max, ep);
      r.gated_mean += eg;
      r.plain_mean += ep;
      ++close_n;
    }
  }
  r.gated_mean /= close_n;
  r.plain_mean /= close_n;
  return r;
}

TEST(MagDisturbance, GatedFilterKeepsHeadingWhileAMagnetApproaches) {
  const DipoleScenario scenario;
  const DipoleRun r = run_dipole(scenario, 27401);
  std::printf("[ftm] dipole: peak disturbance %.1f uT; detector flags %.1f %% of samples disturbed > 10 %% of the "
              "field (%d), %.2f %% false alarms on samples < 1 %% (%d)\n",
              r.max_disturbance_uT, 100.0 * r.detection(), r.strong, 100.0 * r.false_alarm(), r.quiet);
  std::printf("[ftm] dipole: heading error during the 10 s near the magnet: gated mean %.2f max %.2f deg, "
              "plain mean %.2f max %.2f deg\n",
              r.gated_mean, r.gated_max, r.plain_mean, r.plain_max);
  RecordProperty("gated_heading_max_deg", std::to_string(r.gated_max));
  RecordProperty("plain_heading_max_deg", std::to_string(r.plain_max));
  ASSERT_GT(r.strong, 900);
  EXPECT_GE(r.detection(), 0.95);
  EXPECT_LE(r.false_alarm(), 0.01);
  EXPECT_LE(r.gated_max, 3.0);
  EXPECT_GT(r.plain_max, 3.0 * r.gated_max);
  EXPECT_GT(r.plain_max, 5.0);
}

TEST(MagDisturbance, BlindSpotAFieldTurnedAboutTheVerticalIsNotDetected) {
  // The limitation the header states: a magnet due east of the IMU, its
  // moment east too, adds a horizontal field perpendicular to the Earth's
  // horizontal field. Near 12.6 cm that is ~10 µT: the magnitude changes by
  // ~2 % and the dip by ~2°, both inside tolerance, while heading is pulled
  // by ~20°. Nothing single-magnetometer can tell; gating must at least never
  // make it worse than the plain filter.
  DipoleScenario scenario;
  scenario.direction = Vec3::UnitY();
  scenario.moment_Am2 = 0.1 * Vec3::UnitY();
  scenario.near_m = 0.126;
  const DipoleRun r = run_dipole(scenario, 27402);
  std::printf("[ftm] blind spot: peak disturbance %.1f uT, flagged %.1f %% of samples > 10 %%; heading error near "
              "the magnet: gated mean %.2f max %.2f deg, plain mean %.2f max %.2f deg\n",
              r.max_disturbance_uT, 100.0 * r.detection(), r.gated_mean, r.gated_max, r.plain_mean, r.plain_max);
  EXPECT_LT(r.detection(), 0.5) << "if this detects now, update the header's blind-spot note";
  EXPECT_GT(r.plain_max, 5.0);
  EXPECT_LE(r.gated_max, r.plain_max + 0.5);
}

}  // namespace mag_disturbance_test
}  // namespace proprio::ftm
