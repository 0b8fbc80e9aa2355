// Mahony's complementary filter on synthetic MPU-9250 data: options, start-up,
// convergence from a wrong start, gyro-bias estimation, the thesis's IMU
// bench (target: mean ZYX Euler error <= 0.8°) and bad samples.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>

#include "imu_synth.hpp"
#include "proprio/ftm/mahony_filter.hpp"

namespace proprio::ftm {
namespace mahony_test {

using namespace imu_synth;

MahonyOptions z_up_options() {
  MahonyOptions o;
  o.gravity_ref_in_world_mps2 = gravity_ref_z_up();
  o.mag_ref_in_world_uT = earth_field_uT();
  return o;
}

double euler_error_deg(const Quat& estimate, const Quat& truth) {
  const Vec3 d = euler_zyx_rad(estimate) - euler_zyx_rad(truth);
  return (std::abs(wrap_pi(d[0])) + std::abs(wrap_pi(d[1])) + std::abs(wrap_pi(d[2]))) / 3.0 / kDeg;
}

struct RunStats {
  double mean_euler_deg = 0.0, max_euler_deg = 0.0, mean_angle_deg = 0.0;
  int samples = 0;
};

// Runs the filter over all samples; statistics over samples with t >= from_s.
RunStats run(MahonyFilter& f, const std::vector<Sample>& samples, double from_s = 0.0) {
  RunStats st;
  for (const Sample& s : samples) {
    f.update(s.t_ns, s.gyro_radps, s.accel_mps2, s.mag_uT);
    if (ns_to_seconds(s.t_ns) < from_s || !f.initialised()) continue;
    const double e = euler_error_deg(f.q_world_body(), s.truth.q_world_body);
    st.mean_euler_deg += e;
    st.max_euler_deg = std::max(st.max_euler_deg, e);
    st.mean_angle_deg += angle_between(f.q_world_body(), s.truth.q_world_body) / kDeg;
    ++st.samples;
  }
  if (st.samples > 0) {
    st.mean_euler_deg /= st.samples;
    st.mean_angle_deg /= st.samples;
  }
  return st;
}

Motion at_rest(double) { return Motion{}; }

TEST(MahonyOptions, DefaultsValidateAndDescribeTheirGains) {
  const MahonyOptions o;
  EXPECT_TRUE(o.validate().ok());
  const std::string d = o.describe();
  EXPECT_NE(d.find("k_accel=1 rad/s"), std::string::npos) << d;
  EXPECT_NE(d.find("tilt crossover 0.159 Hz"), std::string::npos) << d;
  EXPECT_NE(d.find("heading crossover 0.0477 Hz"), std::string::npos) << d;
  EXPECT_NE(d.find("gated"), std::string::npos) << d;
}

TEST(MahonyOptions, RejectsWhatCannotWork) {
  auto expect_invalid = [](MahonyOptions o, const char* mentions) {
    const Status s = o.validate();
    ASSERT_FALSE(s.ok()) << mentions;
    EXPECT_NE(s.error().message.find(mentions), std::string::npos) << s.error().message;
    EXPECT_FALSE(MahonyFilter::create(o).ok());
  };
  MahonyOptions o;
  o.k_accel_radps = 0.0;
  expect_invalid(o, "k_accel_radps");
  o = {};
  o.k_bias_radps2 = std::numeric_limits<double>::quiet_NaN();
  expect_invalid(o, "k_bias_radps2");
  o = {};
  o.mag_ref_in_world_uT = Vec3(0.0, -48.0, 0.0);  // straight down: no heading
  expect_invalid(o, "vertical");
  o = {};
  o.gravity_ref_in_world_mps2 = Vec3::Zero();
  expect_invalid(o, "gravity_ref");
  o = {};
  o.max_dt_s = 0.0;
  expect_invalid(o, "max_dt_s");
  o = {};
  o.disturbance.norm_tolerance = -0.1;
  expect_invalid(o, "disturbance");
  EXPECT_TRUE(MahonyFilter::create(MahonyOptions{}).ok());
}

TEST(MahonyFilter, InitialisesFromMarkleyOnTheFirstUsableSample) {
  MahonyFilter f(z_up_options());
  const Quat q_true(Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()));
  const Vec3 accel = q_true.conjugate() * gravity_ref_z_up();
  const Vec3 mag = q_true.conjugate() * earth_field_uT();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  // No compass yet, then a NaN compass: nothing to initialise from.
  EXPECT_EQ(f.update(0, Vec3::Zero(), accel, std::nullopt), kMagAbsent | kNotInitialised);
  EXPECT_EQ(f.update(5'000'000, Vec3::Zero(), accel, Vec3(nan, 0, 0)), kMagInvalid | kNotInitialised);
  EXPECT_FALSE(f.initialised());
  EXPECT_EQ(f.update(10'000'000, Vec3::Zero(), accel, mag), kInitialised);
  ASSERT_TRUE(f.initialised());
  EXPECT_LT(angle_between(f.q_world_body(), q_true), 1e-9);
  EXPECT_EQ(f.gyro_bias_radps(), Vec3::Zero());
}

TEST(MahonyFilter, ConvergesFromAWrongStart) {
  // The first sample comes from an attitude 90° off (the IMU was moving, or
  // the compass was disturbed at power-on); the rest are the truth at rest.
  const MahonyOptions o = z_up_options();
  NoiseModel noise;
  const std::vector<Sample> samples = synthesise(60.0, at_rest, noise, 27101);
  MahonyFilter f(o);
  const Quat q_wrong(Eigen::AngleAxisd(90.0 * kDeg, Vec3(1, 1, 1).normalized()));
  ASSERT_EQ(f.update(-5'000'000, Vec3::Zero(), q_wrong.conjugate() * gravity_ref_z_up(),
                     q_wrong.conjugate() * earth_field_uT()),
            kInitialised);
  ASSERT_NEAR(angle_between(f.q_world_body(), Quat::Identity()) / kDeg, 90.0, 1e-6);
  double error_at_5s = 0.0, error_at_30s = 0.0, error_at_60s = 0.0;
  for (const Sample& s : samples) {
    f.update(s.t_ns, s.gyro_radps, s.accel_mps2, s.mag_uT);
    const double e = angle_between(f.q_world_body(), s.truth.q_world_body) / kDeg;
    if (s.t_ns == seconds_to_ns(5.0)) error_at_5s = e;
    if (s.t_ns == seconds_to_ns(30.0)) error_at_30s = e;
    error_at_60s = e;
  }
  std::printf("[ftm] wrong start 90 deg: error %.3f deg at 5 s, %.3f at 30 s, %.3f at 60 s\n", error_at_5s,
              error_at_30s, error_at_60s);
  EXPECT_LT(error_at_5s, 60.0);
  EXPECT_LT(error_at_30s, 2.0);
  EXPECT_LT(error_at_60s, 0.5);
}

TEST(MahonyFilter, EstimatesAConstantGyroBias) {
  // 1 °/s, -0.7 °/s, 0.5 °/s unknown to the filter, the IMU swaying gently
  // about all three axes (a hand at rest is never still).
  NoiseModel noise;
  noise.gyro_bias_radps = Vec3(1.0, -0.7, 0.5) * kDeg;
  auto sway = [](double t) {
    const Vec3 w0(0.9, 1.3, 0.7);
    Vec3 theta, rate;
    for (int i = 0; i < 3; ++i) {
      theta[i] = 0.2 * std::sin(w0[i] * t);
      rate[i] = 0.2 * w0[i] * std::cos(w0[i] * t);
    }
    // Small angles in three axes: q = exp(θ); its body rate is J_r(θ) θ̇.
    Motion m;
    m.q_world_body = so3_exp(theta);
    m.omega_body_radps = so3_left_jacobian(-theta) * rate;
    return m;
  };
  const std::vector<Sample> samples = synthesise(240.0, sway, noise, 27102);
  MahonyFilter f(z_up_options());
  Vec3 mean_bias = Vec3::Zero();
  int n = 0;
  RunStats st;
  for (const Sample& s : samples) {
    f.update(s.t_ns, s.gyro_radps, s.accel_mps2, s.mag_uT);
    if (s.t_ns >= seconds_to_ns(180.0)) {
      mean_bias += f.gyro_bias_radps();
      ++n;
    }
  }
  mean_bias /= n;
  const Vec3 err_dps = (mean_bias - noise.gyro_bias_radps) / kDeg;
  const Vec3 last_err_dps = (f.gyro_bias_radps() - noise.gyro_bias_radps) / kDeg;
  std::printf("[ftm] bias estimate error (mean over 180-240 s) %.4f %.4f %.4f deg/s; at 240 s %.4f %.4f %.4f\n",
              err_dps[0], err_dps[1], err_dps[2], last_err_dps[0], last_err_dps[1], last_err_dps[2]);
  EXPECT_LT(err_dps.cwiseAbs().maxCoeff(), 0.05);
  EXPECT_LT(last_err_dps.cwiseAbs().maxCoeff(), 0.1);
  EXPECT_LT(angle_between(f.q_world_body(), samples.back().truth.q_world_body) / kDeg, 0.5);
}

TEST(MahonyFilter, TracksTheThesisImuBench) {
  // §3.3.1: one IMU turned ~90° about X, then Y, then Z. MPU-9250 noise, AK8963
  // quantisation, a residual gyro bias the filter must find, the IMU 4 cm off
  // the rotation axis. Thesis on hardware: 1.567° mean ZYX Euler error.
  const BenchPlan plan;
  NoiseModel noise;
  noise.gyro_bias_radps = Vec3(0.3, -0.2, 0.25) * kDeg;
  double worst_mean = 0.0, sum_mean = 0.0;
  for (std::uint64_t seed : {27201u, 27202u, 27203u}) {
    const std::vector<Sample> samples = synthesise(plan.duration_s(), plan, noise, seed);
    MahonyFilter f(z_up_options());
    const RunStats all = run(f, samples);
    MahonyFilter g(z_up_options());
    const RunStats moving = run(g, samples, plan.rest_s);
    std::printf("[ftm] IMU bench seed %llu: mean ZYX Euler error %.3f deg (max %.3f), mean angle error %.3f deg; "
                "while moving %.3f deg; bias at end %.3f %.3f %.3f deg/s\n",
                static_cast<unsigned long long>(seed), all.mean_euler_deg, all.max_euler_deg, all.mean_angle_deg,
                moving.mean_euler_deg, f.gyro_bias_radps()[0] / kDeg, f.gyro_bias_radps()[1] / kDeg,
                f.gyro_bias_radps()[2] / kDeg);
    EXPECT_EQ(all.samples, static_cast<int>(samples.size()));
    worst_mean = std::max(worst_mean, all.mean_euler_deg);
    sum_mean += all.mean_euler_deg;
  }
  RecordProperty("mean_zyx_euler_error_deg", std::to_string(sum_mean / 3.0));
  EXPECT_LE(worst_mean, 0.8);
}

TEST(MahonyFilter, GyroOnlyWithoutCorrectionsDriftsWhichTheCorrectionsPrevent) {
  // The bench's number must come from the fusion, not from a gyro so good
  // that any filter passes: with the vector gains near zero the same data
  // drift by the bias.
  const BenchPlan plan;
  NoiseModel noise;
  noise.gyro_bias_radps = Vec3(0.3, -0.2, 0.25) * kDeg;
  const std::vector<Sample> samples = synthesise(plan.duration_s(), plan, noise, 27201);
  MahonyOptions o = z_up_options();
  o.k_accel_radps = 1e-9;
  o.k_mag_radps = 0.0;
  o.k_bias_radps2 = 0.0;
  MahonyFilter gyro_only(o);
  const RunStats drift = run(gyro_only, samples);
  MahonyFilter fused(z_up_options());
  const RunStats ok = run(fused, samples);
  std::printf("[ftm] IMU bench gyro only: %.3f deg mean ZYX Euler error; fused %.3f deg\n", drift.mean_euler_deg,
              ok.mean_euler_deg);
  EXPECT_GT(drift.mean_euler_deg, 2.0 * ok.mean_euler_deg);
}

TEST(MahonyFilter, HandlesBadTimeAndBadSamples) {
  MahonyFilter f(z_up_options());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Vec3 accel = gravity_ref_z_up(), mag = earth_field_uT();
  ASSERT_EQ(f.update(1'000'000'000, Vec3::Zero(), accel, mag), kInitialised);
  const Quat q0 = f.q_world_body();
  // Time that does not advance: ignored entirely, even with a wild gyro.
  EXPECT_EQ(f.update(1'000'000'000, Vec3(5, 5, 5), accel, mag), kTimeNotAdvancing);
  EXPECT_EQ(f.update(999'000'000, Vec3(5, 5, 5), accel, mag), kTimeNotAdvancing);
  EXPECT_LT(angle_between(f.q_world_body(), q0), 1e-12);
  EXPECT_EQ(f.last_time_ns(), 1'000'000'000);

  // A NaN gyro holds the last good rate for gyro_hold_s, then holds the attitude.
  TimeNs t = 1'000'000'000;
  const Vec3 w(0.0, 0.0, 0.5);
  t += 5'000'000;
  EXPECT_EQ(f.update(t, w, accel, std::nullopt), kMagAbsent);
  const Quat before = f.q_world_body();
  t += 5'000'000;
  std::uint32_t flags = f.update(t, Vec3(nan, 0, 0), accel, std::nullopt);
  EXPECT_TRUE(flags & kGyroInvalid);
  EXPECT_GT(angle_between(f.q_world_body(), before), 0.5 * 0.5 * 0.005);  // kept turning at ~0.5 rad/s
  for (int i = 0; i < 30; ++i) f.update(t += 5'000'000, Vec3(nan, nan, nan), accel, std::nullopt);
  const Quat held = f.q_world_body();
  f.update(t += 5'000'000, Vec3(nan, 0, 0), accel, std::nullopt);
  EXPECT_LT(angle_between(f.q_world_body(), held), 0.01 * kDeg) << "a dead gyro must not keep spinning the estimate";
  EXPECT_TRUE(f.q_world_body().coeffs().allFinite());

  // Saturated gyro, NaN accelerometer, clipped compass, linear acceleration.
  flags = f.update(t += 5'000'000, Vec3(0, 0, 34.9), accel, mag);
  EXPECT_TRUE(flags & kGyroInvalid);
  flags = f.update(t += 5'000'000, Vec3::Zero(), Vec3(nan, 0, 9.8), mag);
  EXPECT_TRUE(flags & kAccelInvalid);
  flags = f.update(t += 5'000'000, Vec3::Zero(), Vec3(0, 0, 0), mag);
  EXPECT_TRUE(flags & kAccelInvalid);
  flags = f.update(t += 5'000'000, Vec3::Zero(), accel, Vec3(4800.0, 10.0, -20.0));
  EXPECT_TRUE(flags & kMagInvalid);
  flags = f.update(t += 5'000'000, Vec3::Zero(), accel + Vec3(0.0, 0.0, 5.0), mag);
  EXPECT_TRUE(flags & kAccelRejected);
  EXPECT_FALSE(flags & kAccelInvalid);
  EXPECT_TRUE(f.q_world_body().coeffs().allFinite());
  EXPECT_TRUE(f.gyro_bias_radps().allFinite());

  // A gap longer than max_dt_s: not integrated across (a big gyro reading
  // would have turned it 50°), re-initialised from the vectors instead.
  const Quat q_new(Eigen::AngleAxisd(40.0 * kDeg, Vec3::UnitZ()));
  flags = f.update(t += 2'000'000'000, Vec3(0, 0, 0.5), q_new.conjugate() * accel, q_new.conjugate() * mag);
  EXPECT_TRUE(flags & kTimeGap);
  EXPECT_TRUE(flags & kInitialised);
  EXPECT_LT(angle_between(f.q_world_body(), q_new), 1e-6);
}

TEST(MahonyFilter, KeepsTrackingThroughScatteredBadSamples) {
  // The bench with every 7th gyro NaN, every 11th accelerometer NaN, every
  // 13th compass sample clipped and every 17th sample repeated (same time).
  const BenchPlan plan;
  NoiseModel noise;
  noise.gyro_bias_radps = Vec3(0.3, -0.2, 0.25) * kDeg;
  std::vector<Sample> samples = synthesise(plan.duration_s(), plan, noise, 27301);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  MahonyFilter f(z_up_options());
  std::uint32_t seen = 0;
  double sum = 0.0;
  for (std::size_t k = 0; k < samples.size(); ++k) {
    Sample s = samples[k];
    if (k % 7 == 3) s.gyro_radps = Vec3(nan, 0, 0);
    if (k % 11 == 5) s.accel_mps2 = Vec3(0, nan, 0);
    if (k % 13 == 6 && s.mag_uT) (*s.mag_uT)[0] = 4800.0;
    seen |= f.update(s.t_ns, s.gyro_radps, s.accel_mps2, s.mag_uT);
    if (k % 17 == 9) seen |= f.update(s.t_ns, s.gyro_radps, s.accel_mps2, s.mag_uT);
    sum += euler_error_deg(f.q_world_body(), s.truth.q_world_body);
  }
  const double mean = sum / static_cast<double>(samples.size());
  std::printf("[ftm] IMU bench with scattered bad samples: mean ZYX Euler error %.3f deg\n", mean);
  EXPECT_TRUE(seen & kGyroInvalid);
  EXPECT_TRUE(seen & kAccelInvalid);
  EXPECT_TRUE(seen & kMagInvalid);
  EXPECT_TRUE(seen & kTimeNotAdvancing);
  EXPECT_LE(mean, 1.0);
}

}  // namespace mahony_test
}  // namespace proprio::ftm
