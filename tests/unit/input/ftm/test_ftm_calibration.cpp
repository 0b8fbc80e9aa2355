// FTM calibration: the compass ellipsoid fit, the Earth field, the three-pose
// solve (exact and with imperfectly held poses), the pose collector, and the
// TOML file with its errors.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <vector>

#include "ftm_hand_synth.hpp"
#include "proprio/ftm/ftm_calibration.hpp"
#include "proprio/ftm/ftm_tracker.hpp"
#include "proprio/ftm/mag_calibration.hpp"

namespace proprio::ftm {
namespace {

namespace hs = hand_synth;

Vec3 cal_unit(Rng& rng) { return Vec3(rng.normal(), rng.normal(), rng.normal()).normalized(); }

MagCalibration cal_true_iron(Rng& rng) {
  // A symmetric distortion (soft iron) with gains 0.8-1.2 and a hard iron of tens of µT.
  const Quat r = hs::random_rotation(rng, M_PI);
  const Mat3 S = r.toRotationMatrix() * Vec3(rng.uniform(0.8, 1.2), rng.uniform(0.8, 1.2), rng.uniform(0.8, 1.2)).asDiagonal() *
                 r.toRotationMatrix().transpose();
  MagCalibration m;
  m.hard_iron_uT = Vec3(rng.uniform(-60, 60), rng.uniform(-60, 60), rng.uniform(-60, 60));
  m.soft_iron_inv = S.inverse();
  return m;
}

TEST(MagEllipsoidFit, RecoversHardAndSoftIron) {
  Rng rng(2711);
  for (int trial = 0; trial < 5; ++trial) {
    const MagCalibration truth = cal_true_iron(rng);
    const Mat3 S = truth.soft_iron_inv.inverse();
    std::vector<Vec3> raw;
    for (int k = 0; k < 600; ++k) {
      const Vec3 m = 48.0 * cal_unit(rng) + 0.3 * Vec3(rng.normal(), rng.normal(), rng.normal());
      raw.push_back(S * m + truth.hard_iron_uT);
    }
    auto fit = fit_mag_ellipsoid(raw);
    ASSERT_TRUE(fit.ok()) << fit.error().message;
    const auto& [cal, rep] = *fit;
    EXPECT_LT((cal.hard_iron_uT - truth.hard_iron_uT).norm(), 0.5);
    // The fit keeps volume (det 1), so it equals the truth up to one scale.
    const Mat3 P = cal.soft_iron_inv * S;
    const double s = std::cbrt(P.determinant());
    EXPECT_LT((P / s - Mat3::Identity()).norm(), 0.01);
    EXPECT_NEAR(rep.field_uT, 48.0 * s, 0.5);  // W (raw - h) = s m
    EXPECT_LT(rep.residual_rms_uT, 0.6);
    EXPECT_GT(rep.coverage, 0.9);
    EXPECT_EQ(rep.samples, raw.size());
  }
}

TEST(MagEllipsoidFit, RefusesWhatCannotBeFitted) {
  Rng rng(2712);
  std::vector<Vec3> few(20, Vec3(1, 2, 3));
  auto r = fit_mag_ellipsoid(few);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("samples"), std::string::npos);

  std::vector<Vec3> good;
  for (int k = 0; k < 300; ++k) good.push_back(45.0 * cal_unit(rng) + Vec3(10, 0, 0));
  auto with_nan = good;
  with_nan[17].y() = std::nan("");
  r = fit_mag_ellipsoid(with_nan);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("not finite"), std::string::npos);

  // One cap of the sphere only: the hand was barely turned.
  std::vector<Vec3> cap;
  while (cap.size() < 300) {
    const Vec3 u = cal_unit(rng);
    if (u.z() > 0.8) cap.push_back(45.0 * u + 0.2 * Vec3(rng.normal(), rng.normal(), rng.normal()));
  }
  r = fit_mag_ellipsoid(cap);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("figure-eight"), std::string::npos) << r.error().message;

  // A flat ring (rotation about one axis only) is no ellipsoid.
  std::vector<Vec3> ring;
  for (int k = 0; k < 300; ++k) {
    const double a = 2.0 * M_PI * k / 300.0;
    ring.push_back(Vec3(45.0 * std::cos(a), 45.0 * std::sin(a), 5.0));
  }
  EXPECT_FALSE(fit_mag_ellipsoid(ring).ok());
  MagFitOptions o;
  o.min_coverage = 2.0;
  EXPECT_NE(o.validate().error().message.find("min_coverage"), std::string::npos);
}

// A figure-eight: the whole hand (flat) turned through many orientations.
std::vector<FtmEvent> cal_figure_eight(const HandModel& m, const FtmCalibration& truth, Rng& rng, bool with_wrist) {
  std::vector<FtmEvent> ev;
  hs::HandTruth h;
  for (int k = 0; k < 800; ++k) {
    const TimeNs t = 1'000'000'000 + k * 10'000'000LL;
    h.T_world_wrist = {hs::random_rotation(rng, M_PI), Vec3(0, 1, 0)};
    const auto q = hs::imu_orientations(m, truth, h);
    for (std::size_t i = 0; i < kFtmImuCount; ++i) {
      FtmImuSample s = hs::imu_sample(t, q[i], truth, i, 0.0);
      s.mag_uT += 0.3 * Vec3(rng.normal(), rng.normal(), rng.normal());
      ev.push_back(hs::imu_event(i, s));
    }
    if (with_wrist) ev.push_back(hs::wrist_event(t, h.T_world_wrist));
  }
  return ev;
}

TEST(FtmCalibration, FigureEightGivesEachCompassAndTheEarthField) {
  Rng rng(2713);
  FtmCalibration truth = nominal_ftm_calibration(Handedness::right, 0.19, 0.1);
  for (auto& q : truth.q_imu_segment) q = hs::random_rotation(rng, deg_to_rad(20));
  for (auto& mc : truth.mag) mc = cal_true_iron(rng);
  // The true field: 50 µT at 65° dip, horizontal part 30° off -Z.
  const double dip = deg_to_rad(65), az = deg_to_rad(30);
  truth.earth_field_world_uT = 50.0 * Vec3(std::cos(dip) * std::sin(az), -std::sin(dip), -std::cos(dip) * std::cos(az));
  const HandModel m(HandShape::from_measurements(0.19, 0.1).value());
  FtmCalibration base = truth;  // the dorsum mounting is known (from a three-pose run)
  for (auto& mc : base.mag) mc = MagCalibration{};
  base.earth_field_world_uT = MahonyOptions{}.mag_ref_in_world_uT;
  const auto ev = cal_figure_eight(m, truth, rng, true);
  auto r = solve_mag_and_field(ev, base);
  ASSERT_TRUE(r.ok()) << r.error().message;
  for (std::size_t i = 0; i < kFtmImuCount; ++i) {
    EXPECT_LT((r->mag[i].hard_iron_uT - truth.mag[i].hard_iron_uT).norm(), 0.5) << i;
  }
  // The field's magnitude is the volume-preserving fit's, so compare direction
  // exactly and magnitude loosely (the true soft iron does not keep volume).
  EXPECT_LT(rad_to_deg(std::acos(std::clamp(r->earth_field_world_uT.normalized().dot(truth.earth_field_world_uT.normalized()), -1.0, 1.0))), 1.0);
  std::printf("field from the wrist tracker: %.2f uT (truth %.2f), direction error %.3f deg\n",
              r->earth_field_world_uT.norm(), truth.earth_field_world_uT.norm(),
              rad_to_deg(std::acos(std::clamp(r->earth_field_world_uT.normalized().dot(truth.earth_field_world_uT.normalized()), -1.0, 1.0))));

  // Without the wrist tracker: the dip survives, heading is put on -Z.
  auto f = solve_mag_and_field(cal_figure_eight(m, truth, rng, false), base);
  ASSERT_TRUE(f.ok()) << f.error().message;
  const Vec3 up(0, 1, 0);
  EXPECT_NEAR(rad_to_deg(dip_angle_rad(f->earth_field_world_uT, up)), 65.0, 1.0);
  EXPECT_NEAR(f->earth_field_world_uT.x(), 0.0, 1e-9);
  EXPECT_LT(f->earth_field_world_uT.z(), 0.0);

  std::vector<FtmEvent> none;
  auto bad = solve_mag_and_field(none, base);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("dorsum"), std::string::npos);
}

// Captures of the three poses as a perfect collector would see them, the hand
// held `pose_error_deg` off each known angle (uniform) and the wrist tracker
// `pose_error_deg` off in orientation.
std::array<FtmPoseCapture, 3> cal_captures(const HandModel& m, const FtmCalibration& truth, Rng& rng,
                                           double pose_error_deg) {
  std::array<FtmPoseCapture, 3> caps;
  for (std::size_t k = 0; k < 3; ++k) {
    const auto pose = static_cast<FtmCalibrationPose>(k);
    hs::HandTruth h;
    h.angles = known_angles(pose, m.shape());
    for (auto& a : h.angles) a += deg_to_rad(rng.uniform(-pose_error_deg, pose_error_deg));
    h.T_world_wrist = {hs::random_rotation(rng, M_PI), Vec3(0.1, 0.9, -0.2)};
    const auto q = hs::imu_orientations(m, truth, h);
    FtmPoseCapture& c = caps[k];
    c.pose = pose;
    c.q_world_imu = q;
    for (std::size_t b = 0; b < kFtmBendCount; ++b)
      c.capacitance_pF[b] = hs::bend_sample(0, h.angles, truth, static_cast<FtmBend>(b)).capacitance_pF;
    c.T_world_wrist = {h.T_world_wrist.q * hs::random_rotation(rng, deg_to_rad(pose_error_deg)), h.T_world_wrist.p};
    c.wrist_valid = true;
    c.samples = 400;
  }
  return caps;
}

FtmCalibration cal_truth_for_pose(Rng& rng, Handedness hand) {
  FtmCalibration truth = nominal_ftm_calibration(hand, 0.18, 0.095);
  for (auto& q : truth.q_imu_segment) q = hs::random_rotation(rng, deg_to_rad(30));
  for (std::size_t b = 0; b < kFtmBendCount; ++b) {
    truth.beta0_rad[b] = rng.uniform(-0.5, 0.5);
    truth.beta1_rad_per_pF[b] = rng.uniform(0.03, 0.08);
  }
  return truth;
}

TEST(FtmCalibration, ThreePoseRecoversMountingsAndBendLines) {
  for (Handedness hand : {Handedness::right, Handedness::left}) {
    Rng rng(hand == Handedness::right ? 2714 : 2715);
    const FtmCalibration truth = cal_truth_for_pose(rng, hand);
    const HandModel m(HandShape::from_measurements(truth.hand_length_m, truth.hand_width_m).value());
    const auto caps = cal_captures(m, truth, rng, 0.0);
    auto r = solve_three_pose(caps, nominal_ftm_calibration(hand, truth.hand_length_m, truth.hand_width_m));
    ASSERT_TRUE(r.ok()) << r.error().message;
    for (std::size_t i = 0; i < kFtmImuCount; ++i)
      EXPECT_LT(rad_to_deg(angle_between(r->q_imu_segment[i], truth.q_imu_segment[i])), 1e-6) << i;
    for (std::size_t b = 0; b < kFtmBendCount; ++b) {
      EXPECT_NEAR(r->beta0_rad[b], truth.beta0_rad[b], 1e-9);
      EXPECT_NEAR(r->beta1_rad_per_pF[b], truth.beta1_rad_per_pF[b], 1e-9);
    }
  }
}

TEST(FtmCalibration, ThreePoseWithImperfectPosesStaysWithinAFewDegrees) {
  Rng rng(2716);
  double worst_mount = 0.0, sum_mount = 0.0, worst_beta0 = 0.0, sum_angle = 0.0, worst_angle = 0.0;
  int n = 0, n_angle = 0;
  for (int trial = 0; trial < 20; ++trial) {
    const FtmCalibration truth = cal_truth_for_pose(rng, Handedness::right);
    const HandModel m(HandShape::from_measurements(truth.hand_length_m, truth.hand_width_m).value());
    auto r = solve_three_pose(cal_captures(m, truth, rng, 3.0), nominal_ftm_calibration(Handedness::right, 0.18, 0.095));
    ASSERT_TRUE(r.ok()) << r.error().message;
    // What the calibration error costs: track random poses of the true glove.
    auto t = FtmTracker::create(FtmTrackerOptions{}, *r);
    ASSERT_TRUE(t.ok());
    for (int p = 0; p < 5; ++p) {
      hs::HandTruth h;
      h.angles = hs::random_tracked_angles(rng, FtmTrackerOptions{}.synergies);
      h.T_world_wrist = {hs::random_rotation(rng, 2.0), Vec3(0, 1, 0)};
      t->reset();
      std::vector<FtmEvent> ev;
      for (int k = 0; k < 3; ++k) hs::tick(ev, m, truth, h, 1'000'000'000 + k * 5'000'000, static_cast<std::uint64_t>(k));
      for (const auto& e : ev) t->push(e);
      for (HandDof d : kFtmTrackedDofs) {
        const double e = rad_to_deg(std::abs(t->angles()[index_of(d)] - h.angles[index_of(d)]));
        sum_angle += e;
        worst_angle = std::max(worst_angle, e);
        ++n_angle;
      }
    }
    for (std::size_t i = 0; i < kFtmImuCount; ++i) {
      const double e = rad_to_deg(angle_between(r->q_imu_segment[i], truth.q_imu_segment[i]));
      worst_mount = std::max(worst_mount, e);
      sum_mount += e;
      ++n;
    }
    // Judge the bend line where it is used: the angle it gives at 0 and 90°.
    for (std::size_t b = 0; b < kFtmBendCount; ++b) {
      for (double deg : {0.0, 90.0}) {
        const double rho = (deg_to_rad(deg) - truth.beta0_rad[b]) / truth.beta1_rad_per_pF[b];
        worst_beta0 = std::max(worst_beta0, rad_to_deg(std::abs(r->beta0_rad[b] + r->beta1_rad_per_pF[b] * rho - deg_to_rad(deg))));
      }
    }
  }
  std::printf("three-pose with +-3 deg pose error: mounting error mean %.2f deg, worst %.2f deg; bend angle error "
              "worst %.2f deg\n",
              sum_mount / n, worst_mount, worst_beta0);
  std::printf("  tracking with that calibration: tracked-DOF error mean %.2f deg, worst %.2f deg\n",
              sum_angle / n_angle, worst_angle);
  EXPECT_LT(sum_angle / n_angle, 4.0);
  EXPECT_LT(sum_mount / n, 4.0);
  EXPECT_LT(worst_mount, 8.0);
  EXPECT_LT(worst_beta0, 8.0);
}

TEST(FtmCalibration, KnownPosesAreWhatTheInstructionsSay) {
  const HandShape shape = HandShape::from_measurements(0.18, 0.095).value();
  const HandModel m(shape);
  const HandAngles flat = known_angles(FtmCalibrationPose::flat, shape);
  for (double a : flat) EXPECT_EQ(a, 0.0);
  const HandAngles par = known_angles(FtmCalibrationPose::thumb_parallel, shape);
  const auto T = m.joint_poses_in_wrist(Handedness::right, par);
  const Vec3 thumb = T[index_of(HandJoint::thumb_metacarpal)].q * Vec3(0, 0, -1);
  const Vec3 index = T[index_of(HandJoint::index_proximal)].q * Vec3(0, 0, -1);
  const double flat_err = std::acos(std::clamp(
      (m.joint_poses_in_wrist(Handedness::right, flat)[index_of(HandJoint::thumb_metacarpal)].q * Vec3(0, 0, -1)).dot(index), -1.0, 1.0));
  const double par_err = std::acos(std::clamp(thumb.dot(index), -1.0, 1.0));
  std::printf("thumb_parallel: thumb metacarpal %.1f deg off the index (flat: %.1f deg)\n", rad_to_deg(par_err),
              rad_to_deg(flat_err));
  EXPECT_LT(par_err, flat_err);
  const HandAngles b90 = known_angles(FtmCalibrationPose::bend_90, shape);
  EXPECT_NEAR(rad_to_deg(b90[index_of(HandDof::index_pip_flexion)]), 90.0, 1e-9);
  EXPECT_NEAR(rad_to_deg(b90[index_of(HandDof::thumb_mcp_flexion)]), 60.0, 1e-9);
  EXPECT_EQ(b90[index_of(HandDof::thumb_cmc_flexion)], par[index_of(HandDof::thumb_cmc_flexion)]);
  EXPECT_FALSE(std::string(instruction(FtmCalibrationPose::bend_90)).empty());
}

TEST(FtmCalibration, ThreePoseRefusesBadCaptureSets) {
  Rng rng(2717);
  const FtmCalibration truth = cal_truth_for_pose(rng, Handedness::right);
  const HandModel m(HandShape::from_measurements(truth.hand_length_m, truth.hand_width_m).value());
  auto caps = cal_captures(m, truth, rng, 0.0);
  const auto base = nominal_ftm_calibration(Handedness::right, 0.18, 0.095);
  auto twice = caps;
  twice[2].pose = FtmCalibrationPose::flat;
  auto r = solve_three_pose(twice, base);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("twice"), std::string::npos);
  auto dead = caps;
  for (auto& c : dead) c.capacitance_pF[1] = 12.0;
  r = solve_three_pose(dead, base);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("index_pip"), std::string::npos);
  EXPECT_FALSE(solve_three_pose(std::span(caps).first(2), base).ok());
}

TEST(FtmCalibration, CalibratedTrackerRecoversAnglesEndToEnd) {
  Rng rng(2718);
  const FtmCalibration truth = cal_truth_for_pose(rng, Handedness::right);
  const HandModel m(HandShape::from_measurements(truth.hand_length_m, truth.hand_width_m).value());
  auto cal = solve_three_pose(cal_captures(m, truth, rng, 0.0), nominal_ftm_calibration(Handedness::right, 0.18, 0.095));
  ASSERT_TRUE(cal.ok());
  FtmTrackerOptions o;
  auto t = FtmTracker::create(o, *cal);
  ASSERT_TRUE(t.ok());
  hs::HandTruth h;
  h.angles = hs::random_tracked_angles(rng, o.synergies);
  h.T_world_wrist = {hs::random_rotation(rng, 2.0), Vec3(0, 1, 0)};
  std::vector<FtmEvent> ev;
  for (int k = 0; k < 5; ++k) hs::tick(ev, m, truth, h, 1'000'000'000 + k * 5'000'000, static_cast<std::uint64_t>(k));
  for (const auto& e : ev) t->push(e);
  for (HandDof d : kFtmTrackedDofs)
    EXPECT_NEAR(rad_to_deg(t->angles()[index_of(d)]), rad_to_deg(h.angles[index_of(d)]), 0.5) << to_string(d);
}

TEST(FtmPoseCollector, SeesStillnessAndCapturesTheHeldPose) {
  Rng rng(2719);
  const FtmCalibration truth = cal_truth_for_pose(rng, Handedness::right);
  const HandModel m(HandShape::from_measurements(truth.hand_length_m, truth.hand_width_m).value());
  hs::HandTruth h;
  h.angles = known_angles(FtmCalibrationPose::bend_90);
  h.T_world_wrist = {hs::random_rotation(rng, 1.0), Vec3(0, 1, 0)};
  FtmPoseCollector col(FtmCalibrationPose::bend_90, truth, MahonyOptions{});
  EXPECT_FALSE(col.still(500'000'000));
  EXPECT_FALSE(col.finish().ok());
  std::vector<FtmEvent> ev;
  for (int k = 0; k < 400; ++k) {
    ev.clear();
    hs::tick(ev, m, truth, h, 1'000'000'000 + k * 5'000'000LL, static_cast<std::uint64_t>(k));
    for (auto& e : ev) {
      if (e.kind == FtmEvent::Kind::imu) e.imu.gyro_radps += 0.01 * Vec3(rng.normal(), rng.normal(), rng.normal());
      col.push(e);
    }
    if (k == 100) {
      EXPECT_FALSE(col.still(500'000'000)) << "filters not settled yet";
    }
  }
  EXPECT_TRUE(col.still(500'000'000));
  auto c = col.finish();
  ASSERT_TRUE(c.ok()) << c.error().message;
  const auto q = hs::imu_orientations(m, truth, h);
  for (std::size_t i = 0; i < kFtmImuCount; ++i) EXPECT_LT(rad_to_deg(angle_between(c->q_world_imu[i], q[i])), 1.0);
  EXPECT_NEAR(c->capacitance_pF[1], hs::bend_sample(0, h.angles, truth, FtmBend::index_pip).capacitance_pF, 1e-9);
  EXPECT_TRUE(c->wrist_valid);
  EXPECT_EQ(c->samples, 1600u);

  // A hand that moves is not still.
  FtmEvent moving = ev[0];
  moving.imu.time_ns += 5'000'000;
  moving.imu.gyro_radps = Vec3(1.0, 0, 0);
  col.push(moving);
  EXPECT_FALSE(col.still(500'000'000));
  EXPECT_FALSE(std::string(instruction(FtmCalibrationPose::thumb_parallel)).empty());
}

// ---------------------------------------------------------------- files

FtmCalibration cal_example() {
  Rng rng(2720);
  FtmCalibration c = cal_truth_for_pose(rng, Handedness::left);
  for (auto& mc : c.mag) mc = cal_true_iron(rng);
  c.subject = "P07 \"quoted\"";
  c.earth_field_world_uT = Vec3(3.0, -40.0, -22.0);
  return c;
}

struct CalTempDir {
  std::filesystem::path dir;
  CalTempDir() {
    dir = std::filesystem::temp_directory_path() / ("proprio_ftm_cal_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
  }
  ~CalTempDir() {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
};

TEST(FtmCalibrationFile, RoundTripsThroughToml) {
  const FtmCalibration c = cal_example();
  ASSERT_TRUE(c.validate().ok());
  CalTempDir tmp;
  const auto path = tmp.dir / "ftm.toml";
  ASSERT_TRUE(save_ftm_calibration(path, c).ok());
  auto r = load_ftm_calibration(path);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->hand, c.hand);
  EXPECT_EQ(r->subject, c.subject);
  EXPECT_NEAR(r->hand_length_m, c.hand_length_m, 1e-6);
  EXPECT_LT((r->earth_field_world_uT - c.earth_field_world_uT).norm(), 1e-5);
  for (std::size_t i = 0; i < kFtmImuCount; ++i) {
    EXPECT_LT(angle_between(r->q_imu_segment[i], c.q_imu_segment[i]), 1e-9);
    EXPECT_LT((r->mag[i].hard_iron_uT - c.mag[i].hard_iron_uT).norm(), 1e-5);
    EXPECT_LT((r->mag[i].soft_iron_inv - c.mag[i].soft_iron_inv).norm(), 1e-7);
  }
  for (std::size_t b = 0; b < kFtmBendCount; ++b) {
    EXPECT_NEAR(r->beta0_rad[b], c.beta0_rad[b], 1e-10);
    EXPECT_NEAR(r->beta1_rad_per_pF[b], c.beta1_rad_per_pF[b], 1e-10);
  }
  EXPECT_NE(c.describe().find("left"), std::string::npos);
}

std::string cal_replace(std::string s, const std::string& from, const std::string& to) {
  const auto p = s.find(from);
  EXPECT_NE(p, std::string::npos) << from;
  if (p != std::string::npos) s.replace(p, from.size(), to);
  return s;
}

TEST(FtmCalibrationFile, BrokenFilesNameTheFileAndTheKey) {
  const std::string good = format_ftm_calibration(cal_example());
  CalTempDir tmp;
  struct Case {
    const char* what;
    std::string text;
    const char* key;
  };
  const std::string b1 = "beta1_rad_per_pF = ";
  const std::vector<Case> cases = {
      {"missing key", cal_replace(good, "\n[bend.index_pip]\nbeta0_rad", "\n[bend.index_pip]\n#beta0_rad"), "bend.index_pip.beta0_rad"},
      {"wrong type", cal_replace(good, "hand_length_m = ", "hand_length_m = \"long\" #"), "hand_length_m"},
      {"nan", cal_replace(good, "hand_width_m = ", "hand_width_m = nan #"), "hand_width_m"},
      {"short array", cal_replace(good, "hard_iron_uT = [", "hard_iron_uT = [1.0] #["), "hard_iron_uT"},
      {"not unit", cal_replace(good, "q_imu_segment_wxyz = [", "q_imu_segment_wxyz = [2.0, 0, 0, 0] #["),
       "q_imu_segment_wxyz"},
      {"nan in array", cal_replace(good, "earth_field_world_uT = [", "earth_field_world_uT = [nan, 1, 2] #["),
       "earth_field_world_uT"},
      {"bad hand", cal_replace(good, "hand = \"left\"", "hand = \"middle\""), "hand"},
      {"unknown table", cal_replace(good, "[bend.middle_pip]", "[bendx]"), "bendx"},
  };
  for (const Case& c : cases) {
    const auto path = tmp.dir / (std::string("broken_") + std::to_string(&c - cases.data()) + ".toml");
    std::ofstream(path) << c.text;
    auto r = load_ftm_calibration(path);
    ASSERT_FALSE(r.ok()) << c.what;
    EXPECT_NE(r.error().message.find(path.string()), std::string::npos) << c.what << ": " << r.error().message;
    EXPECT_NE(r.error().message.find(c.key), std::string::npos) << c.what << ": " << r.error().message;
    std::printf("%s -> %s\n", c.what, r.error().message.c_str());
  }
  auto missing = load_ftm_calibration(tmp.dir / "nope.toml");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("nope.toml"), std::string::npos);
  const auto fifo = tmp.dir / "fifo.toml";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  auto f = load_ftm_calibration(fifo);  // refused without blocking
  ASSERT_FALSE(f.ok());
  EXPECT_NE(f.error().message.find("fifo.toml"), std::string::npos);
  FtmCalibration bad = cal_example();
  bad.beta1_rad_per_pF[0] = 0.0;
  EXPECT_FALSE(save_ftm_calibration(tmp.dir / "bad.toml", bad).ok());
}

}  // namespace
}  // namespace proprio::ftm
