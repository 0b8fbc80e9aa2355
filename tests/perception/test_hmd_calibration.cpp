// HMD calibration by reaching without seeing: targets in the published
// ranges, the rigid fit recovering a known graphics-to-HMD transform, and
// clear errors for data that cannot determine it.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "proprio/hmd_calibration/calibration.hpp"

namespace proprio::hmd_calibration {
namespace {

constexpr double kPi = 3.14159265358979323846;
const Pose kTrue{Quat(Eigen::AngleAxisd(0.05, Vec3(0.3, 1.0, -0.2).normalized())), Vec3(0.01, -0.02, 0.035)};

TEST(HmdCalibration, TargetsLieInThePublishedRanges) {
  TargetOptions o;
  const auto targets = calibration_targets(o);
  ASSERT_EQ(targets.size(), 100u);
  for (const Vec3& p : targets) {
    const double r = p.norm();
    EXPECT_GE(r, 0.30 - 1e-12);
    EXPECT_LE(r, 0.50 + 1e-12);
    const double phi = std::asin(p.y() / r);
    const double theta = std::atan2(p.x(), -p.z());
    EXPECT_LE(std::abs(phi), 30 * kPi / 180 + 1e-9);
    EXPECT_LE(std::abs(theta), 30 * kPi / 180 + 1e-9);
  }
  EXPECT_EQ(calibration_targets(o), targets);  // seeded
}

TEST(HmdCalibration, RecoversTheTransformExactlyWithoutNoiseAndClosely500Reaches) {
  const auto targets = calibration_targets({});
  auto exact = fit_hmd_graphics(targets, simulate_reaching(kTrue, targets, 0.0, 1));
  ASSERT_TRUE(exact) << exact.error().message;
  EXPECT_LT((exact->T_hmd_graphics.p - kTrue.p).norm(), 1e-9);
  EXPECT_LT(exact->T_hmd_graphics.q.angularDistance(kTrue.q), 1e-9);
  EXPECT_LT(exact->rms_m, 1e-9);
  // The thesis's 5 participants x 100 reaches, 1.5 cm of proprioceptive error each.
  std::vector<Vec3> cmd, finger;
  for (std::uint64_t p = 0; p < 5; ++p) {
    TargetOptions o;
    o.seed = 10 + p;
    const auto t = calibration_targets(o);
    const auto f = simulate_reaching(kTrue, t, 0.015, 100 + p);
    cmd.insert(cmd.end(), t.begin(), t.end());
    finger.insert(finger.end(), f.begin(), f.end());
  }
  auto noisy = fit_hmd_graphics(cmd, finger);
  ASSERT_TRUE(noisy);
  EXPECT_LT((noisy->T_hmd_graphics.p - kTrue.p).norm(), 0.005);
  EXPECT_LT(noisy->T_hmd_graphics.q.angularDistance(kTrue.q), 1.0 * kPi / 180);
  // RMS residual of 3-D N(0, 1.5 cm) per axis is about 2.6 cm.
  EXPECT_NEAR(noisy->rms_m, 0.015 * std::sqrt(3.0), 0.003);
  EXPECT_EQ(noisy->pairs, 500);
}

TEST(HmdCalibration, UndeterminedOrBrokenDataIsAnError) {
  std::vector<Vec3> line{Vec3(0, 0, -0.3), Vec3(0, 0, -0.4), Vec3(0, 0, -0.5)};
  auto collinear = fit_hmd_graphics(line, line);
  ASSERT_FALSE(collinear);
  EXPECT_NE(collinear.error().message.find("collinear"), std::string::npos);
  EXPECT_FALSE(fit_hmd_graphics({Vec3::Zero(), Vec3::UnitX()}, {Vec3::Zero(), Vec3::UnitX()}));
  const auto targets = calibration_targets({});
  auto reaches = simulate_reaching(kTrue, targets, 0.0, 1);
  reaches.pop_back();
  EXPECT_FALSE(fit_hmd_graphics(targets, reaches));
  reaches = simulate_reaching(kTrue, targets, 0.0, 1);
  reaches[3].x() = std::nan("");
  EXPECT_FALSE(fit_hmd_graphics(targets, reaches));
}

TEST(HmdCalibration, SavedCalibrationLoadsBack) {
  const auto targets = calibration_targets({});
  auto fit = fit_hmd_graphics(targets, simulate_reaching(kTrue, targets, 0.0, 1));
  ASSERT_TRUE(fit);
  const auto path = std::filesystem::path(PROPRIO_TEST_OUT_DIR) / "hmd_calibration.toml";
  std::filesystem::create_directories(path.parent_path());
  ASSERT_TRUE(save_calibration(path, *fit));
  auto loaded = load_calibration(path);
  ASSERT_TRUE(loaded) << loaded.error().message;
  EXPECT_LT((loaded->p - kTrue.p).norm(), 1e-5);
  EXPECT_LT(loaded->q.angularDistance(kTrue.q), 1e-6);
  EXPECT_FALSE(load_calibration(path.parent_path() / "missing.toml"));
}

}  // namespace
}  // namespace proprio::hmd_calibration
