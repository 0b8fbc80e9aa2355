// Turn-on bias estimation (imu_bias.hpp): a still start gives the gyro offset,
// a multi-orientation sphere fit the accelerometer's; moving starts and too
// few orientations are refused. Synthetic MPU-9250 noise at 200 Hz.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/ftm/ftm_calibration.hpp"
#include "proprio/ftm/ftm_tracker.hpp"
#include "proprio/ftm/imu_bias.hpp"
#include "proprio/ftm/mahony_filter.hpp"

namespace proprio::ftm {
namespace imu_bias_test {

constexpr double kG = 9.80665;
constexpr double kD2R = M_PI / 180.0;
constexpr double kRate = 200.0;
// MPU-9250 white noise per sample at 200 Hz (density · √rate).
const double kGyroSigma = 0.01 * kD2R * std::sqrt(kRate);
const double kAccelSigma = 300e-6 * kG * std::sqrt(kRate);

struct BiasTruth {
  Vec3 gyro_radps = Vec3::Zero();
  Vec3 accel_mps2 = Vec3::Zero();
};

// Samples of an IMU whose orientation (world Z up) and body rate follow
// q(t), omega(t); no linear acceleration.
std::vector<FtmImuSample> ib_samples(double duration_s, const std::function<Quat(double)>& q,
                                     const std::function<Vec3(double)>& omega_body, const BiasTruth& bias,
                                     std::uint64_t seed) {
  Rng rng(seed);
  std::vector<FtmImuSample> out;
  const int n = static_cast<int>(duration_s * kRate);
  for (int k = 0; k < n; ++k) {
    const double t = k / kRate;
    FtmImuSample s;
    s.time_ns = static_cast<TimeNs>(std::llround(t * 1e9)) + 1;
    const Vec3 noise_g(rng.normal(), rng.normal(), rng.normal());
    const Vec3 noise_a(rng.normal(), rng.normal(), rng.normal());
    s.gyro_radps = omega_body(t) + bias.gyro_radps + kGyroSigma * noise_g;
    s.accel_mps2 = q(t).conjugate() * Vec3(0.0, 0.0, kG) + bias.accel_mps2 + kAccelSigma * noise_a;
    out.push_back(s);
  }
  return out;
}

const BiasTruth kBias{Vec3(1.5, -2.0, 2.5) * kD2R, Vec3(0.3, -0.4, 0.6)};

TEST(StillBias, EstimatesTheGyroOffsetOfAStillImu) {
  const Quat tilt(Eigen::AngleAxisd(0.4, Vec3(1.0, 0.5, 0.0).normalized()));
  const auto s = ib_samples(1.5, [&](double) { return tilt; }, [](double) { return Vec3::Zero().eval(); }, kBias, 1);
  auto e = estimate_still_bias(s);
  ASSERT_TRUE(e.ok()) << e.error().message;
  // Mean of 200 samples: σ ≈ 0.14 °/s / √200 ≈ 0.01 °/s per axis; the
  // offset itself is 3.5 °/s.
  EXPECT_LT((e->gyro_bias_radps - kBias.gyro_radps).norm(), 0.08 * kD2R);
  EXPECT_GE(e->samples, 190u);
  EXPECT_LT(e->tilt_drift_rad, 0.1 * kD2R);
  // A 1 s window was used, not the whole 1.5 s.
  EXPECT_LT(e->duration_s, 1.0);
}

TEST(StillBias, RefusesAMovingStart) {
  const StillBiasOptions o;
  // Turning at 20 °/s: a mean rate no offset can have.
  const Vec3 w_fast = Vec3(0.0, 20.0, 0.0) * kD2R;
  auto fast = ib_samples(
      1.5, [&](double t) { return Quat(Eigen::AngleAxisd(w_fast.norm() * t, Vec3::UnitY())); },
      [&](double) { return w_fast; }, kBias, 2);
  auto e = estimate_still_bias(fast, o);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().code, Errc::out_of_range);
  // A slow steady turn (1 °/s about a horizontal axis) looks like an offset
  // to the gyro, and its accelerometer spread is within the noise bound; the
  // accelerometer's direction drifting between the halves gives it away.
  const Vec3 w_slow = Vec3(1.0, 0.0, 0.0) * kD2R;
  auto slow = ib_samples(
      1.5, [&](double t) { return Quat(Eigen::AngleAxisd(w_slow.norm() * t, Vec3::UnitX())); },
      [&](double) { return w_slow; }, BiasTruth{}, 3);
  e = estimate_still_bias(slow, o);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message.find("tilt drift"), std::string::npos) << e.error().message;
  // A trembling hand (2 °/s at 8 Hz) is not still either.
  auto tremor = ib_samples(
      1.5,
      [](double t) {
        return Quat(Eigen::AngleAxisd(2.0 * kD2R / (2.0 * M_PI * 8.0) * std::sin(2.0 * M_PI * 8.0 * t),
                                      Vec3::UnitX()));
      },
      [](double t) { return Vec3(2.0 * kD2R * std::cos(2.0 * M_PI * 8.0 * t), 0.0, 0.0); }, kBias, 4);
  e = estimate_still_bias(tremor, o);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message.find("gyro std"), std::string::npos) << e.error().message;
}

TEST(StillBias, NeedsTheWholeWindowAndValidOptions) {
  const auto s = ib_samples(0.5, [](double) { return Quat::Identity(); }, [](double) { return Vec3::Zero().eval(); },
                            kBias, 5);
  auto e = estimate_still_bias(s);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().code, Errc::unavailable);
  StillBiasOptions bad;
  bad.window_s = 0.0;
  const auto st = bad.validate();
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("window_s"), std::string::npos);
  EXPECT_FALSE(StillBiasOptions{}.describe().empty());
}

TEST(AccelBias, SphereFitRecoversTheOffsetFromManyOrientations) {
  // A slow tumble through many orientations (all under 1 rad/s).
  auto q = [](double t) {
    return (Quat(Eigen::AngleAxisd(1.2 * std::sin(0.31 * t), Vec3::UnitZ())) *
            Quat(Eigen::AngleAxisd(1.3 * std::sin(0.23 * t + 0.5), Vec3::UnitX())) *
            Quat(Eigen::AngleAxisd(1.4 * std::sin(0.17 * t + 1.0), Vec3::UnitY())))
        .normalized();
  };
  const auto s = ib_samples(30.0, q, [](double) { return Vec3::Zero().eval(); }, kBias, 6);
  auto e = fit_accel_bias(s);
  ASSERT_TRUE(e.ok()) << e.error().message;
  EXPECT_LT((e->bias_mps2 - kBias.accel_mps2).norm(), 0.02) << e->bias_mps2.transpose();
  EXPECT_GT(e->direction_spread, 0.03);
  EXPECT_LT(e->residual_rms_mps2, 0.06);
}

TEST(AccelBias, RefusesTooFewOrientations) {
  // Within ±3° of level: an offset across "up" cannot be told from tilt.
  auto q = [](double t) { return Quat(Eigen::AngleAxisd(3.0 * kD2R * std::sin(0.5 * t), Vec3::UnitX())); };
  const auto s = ib_samples(20.0, q, [](double) { return Vec3::Zero().eval(); }, kBias, 7);
  auto e = fit_accel_bias(s);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().code, Errc::unavailable);
  EXPECT_NE(e.error().message.find("spread"), std::string::npos) << e.error().message;
  AccelBiasFitOptions bad;
  bad.min_direction_spread = 0.5;
  ASSERT_FALSE(bad.validate().ok());
  EXPECT_NE(bad.validate().error().message.find("min_direction_spread"), std::string::npos);
}

TEST(ImuBiasInTheFilter, SeededBiasIsClampedAndUsed) {
  MahonyOptions o;
  o.max_bias_radps = 5.0 * kD2R;
  MahonyFilter f(o);
  f.set_gyro_bias(Vec3(20.0, 0.0, 0.0) * kD2R);
  EXPECT_NEAR(f.gyro_bias_radps().norm(), 5.0 * kD2R, 1e-12);
  f.set_gyro_bias(Vec3(NAN, 0.0, 0.0));
  EXPECT_NEAR(f.gyro_bias_radps().norm(), 5.0 * kD2R, 1e-12);
  // A calibration carrying offsets is accepted; a non-finite one is not.
  FtmCalibration cal = nominal_ftm_calibration(Handedness::right, 0.19, 0.10);
  cal.gyro_bias_radps[1] = Vec3(0.01, -0.02, 0.03);
  FtmTrackerOptions to;
  auto tracker = FtmTracker::create(to, cal);
  ASSERT_TRUE(tracker.ok()) << tracker.error().message;
  cal.accel_bias_mps2[0] = Vec3(NAN, 0.0, 0.0);
  EXPECT_FALSE(cal.validate().ok());
  EXPECT_FALSE(FtmTracker::create(to, cal).ok());
}

TEST(ImuBiasInTheCalibration, TurnOnOptionsValidateAndDescribe) {
  FtmTurnOnBiasOptions o;
  EXPECT_TRUE(o.validate().ok());
  EXPECT_NE(o.describe().find("agree within"), std::string::npos) << o.describe();
  o.max_pose_gyro_disagreement_radps = 0.0;
  ASSERT_FALSE(o.validate().ok());
  EXPECT_NE(o.validate().error().message.find("max_pose_gyro_disagreement_radps"), std::string::npos);
  o = {};
  o.accel_fit.min_samples = 1;
  ASSERT_FALSE(o.validate().ok());
  EXPECT_NE(o.validate().error().message.find("accel_fit"), std::string::npos);
}

// The tracker's still start: the glove lies still for the first second, each
// IMU with its own gyro offset; the seeded bias matches it. A glove that is
// turning from the start is refused and the bias left to the filter.
TEST(ImuBiasInTheTracker, StillStartSeedsEachFilterAndAMovingStartIsRefused) {
  const FtmCalibration cal = nominal_ftm_calibration(Handedness::right, 0.19, 0.10);
  FtmTrackerOptions to;
  to.attitude.k_bias_radps2 = 0.0;  // isolate the seed from the integrator
  const std::array<Vec3, kFtmImuCount> offsets{Vec3(2.0, -1.0, 0.5) * kD2R, Vec3(-3.0, 0.5, 1.0) * kD2R,
                                               Vec3(0.5, 2.5, -2.0) * kD2R, Vec3(-1.0, -1.5, 3.0) * kD2R};
  for (bool moving : {false, true}) {
    auto tracker = FtmTracker::create(to, cal);
    ASSERT_TRUE(tracker.ok()) << tracker.error().message;
    const Vec3 w = moving ? Vec3(0.0, 0.0, 30.0 * kD2R) : Vec3::Zero();
    std::array<std::vector<FtmImuSample>, kFtmImuCount> streams;
    for (std::size_t i = 0; i < kFtmImuCount; ++i) {
      BiasTruth b;
      b.gyro_radps = offsets[i];
      // World here is OpenXR (+Y up): the board lies flat, turning about up when moving.
      streams[i] = ib_samples(
          1.5, [&](double t) { return Quat(Eigen::AngleAxisd(w.norm() * t, Vec3::UnitY())); },
          [&](double) { return Vec3(0.0, w.norm(), 0.0); }, b, 10 + i);
      for (auto& smp : streams[i]) {
        // ib_samples puts gravity along its world Z; rotate Z-up into Y-up.
        smp.accel_mps2 = Quat(Eigen::AngleAxisd(-M_PI / 2.0, Vec3::UnitX())) * smp.accel_mps2;
        if (moving) smp.accel_mps2 = Vec3(0.0, kG, 0.0) + kAccelSigma * Vec3(0.01, 0.0, 0.0);
      }
    }
    for (std::size_t k = 0; k < streams[0].size(); ++k) {
      for (std::size_t i = 0; i < kFtmImuCount; ++i) tracker->push_imu(static_cast<FtmImu>(i), streams[i][k]);
    }
    for (std::size_t i = 0; i < kFtmImuCount; ++i) {
      const auto imu = static_cast<FtmImu>(i);
      if (moving) {
        EXPECT_EQ(tracker->turn_on_gyro_bias(imu), FtmTracker::TurnOnBias::refused);
        EXPECT_LT(tracker->gyro_bias_radps(imu).norm(), 1e-12);
      } else {
        EXPECT_EQ(tracker->turn_on_gyro_bias(imu), FtmTracker::TurnOnBias::estimated);
        EXPECT_LT((tracker->gyro_bias_radps(imu) - offsets[i]).norm(), 0.08 * kD2R)
            << tracker->gyro_bias_radps(imu).transpose();
      }
    }
  }
}

}  // namespace imu_bias_test
}  // namespace proprio::ftm
