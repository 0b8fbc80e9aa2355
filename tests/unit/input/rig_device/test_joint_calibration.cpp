#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "proprio/rig_device/joint_calibration.hpp"
#include "proprio/rig_device/kit.hpp"

namespace proprio::rig_device {
namespace {

constexpr double kDeg = M_PI / 180.0;

JointAngles random_within_stops(double limit, Rng& rng) {
  JointAngles a;
  do {
    a.bend_x_rad = rng.uniform(-limit, limit);
    a.bend_y_rad = rng.uniform(-limit, limit);
  } while (shaft_angle_rad(a.bend_x_rad, a.bend_y_rad) > limit);
  a.twist_in_rad = rng.uniform(-M_PI, M_PI);
  a.twist_out_rad = rng.uniform(-M_PI, M_PI);
  return a;
}

double worst_error_deg(const JointAngles& a, const JointAngles& b) {
  return std::max({std::abs(a.bend_x_rad - b.bend_x_rad), std::abs(a.bend_y_rad - b.bend_y_rad),
                   std::abs(wrap_angle_rad(a.twist_in_rad - b.twist_in_rad)),
                   std::abs(wrap_angle_rad(a.twist_out_rad - b.twist_out_rad))}) /
         kDeg;
}

struct Calibrated {
  HallJoint joint;
  JointCalibration calibration;
};

Calibrated calibrated_joint(std::uint64_t seed, bool disturbances) {
  HallJointOptions o;
  o.kind = default_kit().joint;
  o.seed = seed;
  o.manufacturing_errors = o.noise = o.backlash = disturbances;
  auto joint = HallJoint::create(o);
  EXPECT_TRUE(joint.ok());
  Rng rng(seed + 100);
  auto samples = run_calibration_jig(*joint, JigOptions{}, Vec3(0, 0, kShieldedJigFieldT), rng);
  EXPECT_TRUE(samples.ok());
  auto cal = JointCalibration::fit(*samples, o.kind.bend_limit_rad, "J" + std::to_string(seed));
  EXPECT_TRUE(cal.ok()) << cal.error().message;
  return {std::move(*joint), std::move(*cal)};
}

TEST(JointCalibration, InvertsItsOwnForwardModel) {
  Calibrated c = calibrated_joint(3, true);
  Rng rng(1);
  for (int i = 0; i < 300; ++i) {
    const JointAngles a = random_within_stops(default_kit().joint.bend_limit_rad, rng);
    const JointAngles back = c.calibration.angles(c.calibration.predict(a));
    EXPECT_LT(worst_error_deg(a, back), 1e-4) << i;
  }
}

TEST(JointCalibration, ThePreviousReportsAnglesOnlyHelp) {
  // Along a slow sweep that grazes the stops, starting from the last
  // report's angles too never does worse than starting from the table alone.
  Calibrated c = calibrated_joint(9, true);
  const double limit = default_kit().joint.bend_limit_rad;
  Rng rng(3);
  JointAngles previous;
  double worst_plain = 0.0, worst_hinted = 0.0;
  for (int k = 0; k <= 400; ++k) {
    const double phase = 2.0 * M_PI * k / 400.0;
    JointAngles cmd{0.5 * phase, 0.98 * limit * std::cos(phase), 0.98 * limit * std::sin(phase), -phase};
    clamp_bends_to_stops(cmd.bend_x_rad, cmd.bend_y_rad, limit);
    c.joint.move_to(cmd);
    const HallReadings r = c.joint.read({}, rng);
    const JointAngles plain = c.calibration.angles(r);
    const JointAngles hinted = k == 0 ? plain : c.calibration.angles(r, previous);
    worst_plain = std::max(worst_plain, worst_error_deg(plain, c.joint.actual_angles()));
    worst_hinted = std::max(worst_hinted, worst_error_deg(hinted, c.joint.actual_angles()));
    previous = hinted;
  }
  EXPECT_LE(worst_hinted, worst_plain + 0.01);
  EXPECT_LT(worst_hinted, 1.0);
}

TEST(JointCalibration, HeldOutAnglesOfARealisticJointWithinTheThesisAccuracy) {
  // One as-built joint with noise and play, read at angles the jig never
  // visited (its own quiet field; the full benchmark adds neighbours and
  // Earth's field, test_joint_accuracy.cpp).
  for (std::uint64_t seed : {11u, 12u}) {
    Calibrated c = calibrated_joint(seed, true);
    Rng rng(seed);
    std::vector<double> errors;
    for (int i = 0; i < 400; ++i) {
      const JointAngles target = random_within_stops(default_kit().joint.bend_limit_rad, rng);
      c.joint.move_to(target);
      const JointAngles est = c.calibration.angles(c.joint.read({}, rng));
      errors.push_back(worst_error_deg(est, c.joint.actual_angles()));
    }
    std::sort(errors.begin(), errors.end());
    double mean = 0.0;
    for (double e : errors) mean += e / static_cast<double>(errors.size());
    EXPECT_LT(mean, 0.3) << seed;
    EXPECT_LT(errors[errors.size() * 99 / 100], 0.5) << seed;
    // The jig's data fit to about a count.
    for (double r : c.calibration.fit_rms_counts()) EXPECT_LT(r, 3.0);
  }
}

TEST(JointCalibration, TomlRoundTripGivesTheSameAngles) {
  Calibrated c = calibrated_joint(5, true);
  const std::string text = c.calibration.to_toml();
  auto back = JointCalibration::parse_toml(text, "cal.toml");
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back->joint_id(), "J5");
  EXPECT_EQ(back->bend_limit_rad(), c.calibration.bend_limit_rad());
  EXPECT_EQ(back->fit_rms_counts(), c.calibration.fit_rms_counts());
  Rng rng(2);
  for (int i = 0; i < 50; ++i) {
    c.joint.move_to(random_within_stops(default_kit().joint.bend_limit_rad, rng));
    const HallReadings r = c.joint.read({}, rng);
    const JointAngles x = c.calibration.angles(r), y = back->angles(r);
    EXPECT_EQ(x.bend_x_rad, y.bend_x_rad);
    EXPECT_EQ(x.bend_y_rad, y.bend_y_rad);
    EXPECT_EQ(x.twist_in_rad, y.twist_in_rad);
    EXPECT_EQ(x.twist_out_rad, y.twist_out_rad);
  }
}

std::string replace_once(std::string s, const std::string& from, const std::string& to) {
  const auto at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) s.replace(at, from.size(), to);
  return s;
}

TEST(JointCalibration, HostileTomlIsRefusedWithAReason) {
  const std::string good = calibrated_joint(6, false).calibration.to_toml();
  ASSERT_TRUE(JointCalibration::parse_toml(good, "good.toml").ok());
  const struct {
    const char* what;
    std::string text;
    const char* expect;
  } cases[] = {
      {"other format", replace_once(good, "proprio-rig-joint-calibration", "something-else"), "format"},
      {"future version", replace_once(good, "version = 1", "version = 2"), "version"},
      {"unknown key", good + "extra = 1\n", "extra"},
      {"unknown table key", replace_once(good, "[bend]\n", "[bend]\nz = [1.0]\n"), "'z'"},
      {"short coefficients", replace_once(good, "x = [", "x = [1.0, 2.0]\nold_x = ["), "old_x"},
      {"too few coefficients", replace_once(good, "a = [", "a = [1.0]\nignored = ["), "ignored"},
      {"nan coefficient", replace_once(good, "x = [", "x = [nan, "), "bend.x"},
      {"huge coefficient", replace_once(good, "y = [", "y = [1e300, "), "bend.y"},
      {"missing table", replace_once(good, "[twist_in]", "[twist_inn]"), "twist_in"},
      {"bend limit past 1.5", replace_once(good, "bend_limit_rad = ", "bend_limit_rad = 3.0\n#"), "bend_limit_rad"},
      {"not toml", "format = \"proprio-rig-joint-calibration\"\nversion = [", "hostile.toml"},
  };
  for (const auto& c : cases) {
    auto r = JointCalibration::parse_toml(c.text, "hostile.toml");
    ASSERT_FALSE(r.ok()) << c.what;
    EXPECT_FALSE(r.error().message.empty());
    EXPECT_NE(r.error().message.find(c.expect), std::string::npos) << c.what << ": " << r.error().message;
  }
  // The right count but wrong length in one array is named too.
  auto wrong = JointCalibration::parse_toml(replace_once(good, "b = [", "b = [0.5, "), "hostile.toml");
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.error().message.find("coefficients"), std::string::npos) << wrong.error().message;
  EXPECT_FALSE(JointCalibration::load("/dev/zero").ok());
}

TEST(JointCalibration, FitRefusesDataThatCannotPinTheModel) {
  HallJointOptions o;
  o.kind = default_kit().joint;
  auto joint = HallJoint::create(o);
  Rng rng(1);
  auto samples = run_calibration_jig(*joint, JigOptions{}, Vec3::Zero(), rng);
  ASSERT_TRUE(samples.ok());
  // Too few poses.
  std::vector<JigSample> few(samples->begin(), samples->begin() + 20);
  EXPECT_FALSE(JointCalibration::fit(few, o.kind.bend_limit_rad).ok());
  // Many poses, one place: rank deficient, and the message says which channel.
  std::vector<JigSample> same(200, samples->front());
  auto r = JointCalibration::fit(same, o.kind.bend_limit_rad);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("channel"), std::string::npos) << r.error().message;
  // Non-finite data and a bad id.
  std::vector<JigSample> nan = *samples;
  nan[3].readings.bend[0] = std::nan("");
  EXPECT_FALSE(JointCalibration::fit(nan, o.kind.bend_limit_rad).ok());
  EXPECT_FALSE(JointCalibration::fit(*samples, o.kind.bend_limit_rad, "bad\nid").ok());
  EXPECT_FALSE(JointCalibration::fit(*samples, 2.0).ok());
}

}  // namespace
}  // namespace proprio::rig_device
