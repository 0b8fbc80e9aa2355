#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "proprio/rig_eval/posing_task.hpp"
#include "proprio/rig_eval/simulated_user.hpp"

namespace proprio::rig_eval {
namespace {

constexpr double kDeg = M_PI / 180.0;

// A person who sees and moves exactly: isolates the joints' kinematics.
SimulatedUser exact_user() {
  UserModelOptions o;
  o.image_threshold_deg = 0.01;
  o.depth_threshold_deg = 0.01;
  o.perception_weber_fraction = 0.0;
  o.perception_floor_thresholds = 0.0;
  o.motor_noise_floor_deg = 0.0;
  o.motor_noise_fraction = 0.0;
  return typical_user(o);
}

// Bend `bend_deg` towards `azimuth_deg` (the swing axis' azimuth), no twist.
JointRotations one_joint_target(double bend_deg, double azimuth_deg) {
  const Vec3 axis(std::cos(azimuth_deg * kDeg), std::sin(azimuth_deg * kDeg), 0.0);
  return {Quat(Eigen::AngleAxisd(bend_deg * kDeg, axis))};
}

double direction_error_rad(const Quat& a, const Quat& b) {
  const Vec3 da = a * Vec3::UnitZ();
  const Vec3 db = b * Vec3::UnitZ();
  return std::atan2(da.cross(db).norm(), da.dot(db));
}

TEST(SimulatedUser, OursTracesTheGeodesic) {
  const PosingDevice device = make_chain_device(1);
  const JointRotations target = one_joint_target(60.0, 40.0);
  TrialOptions options;
  options.record_paths = true;
  Rng rng(1);
  const TrialResult r = simulate_trial(device, JointDesign::cardan_twist, target, exact_user(), options, rng);
  ASSERT_GE(r.path.size(), 3u);
  const Vec3 d_target = target[0] * Vec3::UnitZ();
  const Vec3 normal = Vec3::UnitZ().cross(d_target).normalized();
  for (const auto& s : r.path) {
    EXPECT_NEAR(s.d_in_inlet.dot(normal), 0.0, 1e-9);  // on the great circle through start and target
    EXPECT_NEAR(s.d_in_inlet.norm(), 1.0, 1e-9);
  }
  EXPECT_NEAR(outlet_path_length_rad(r.path, 0), 60.0 * kDeg, 1e-6);
  EXPECT_LT(direction_error_rad(r.final_pose[0], target[0]), 1e-6);
  EXPECT_EQ(r.movements, 1);
  EXPECT_FALSE(r.timed_out);
}

TEST(SimulatedUser, TwistBendTwistZigZagsOffAxis) {
  const PosingDevice device = make_chain_device(1);
  TrialOptions options;
  options.record_paths = true;
  for (const double azimuth : {20.0, 40.0, 75.0, 130.0}) {
    const JointRotations target = one_joint_target(60.0, azimuth);
    Rng rng_ours(2), rng_theirs(2);
    const TrialResult ours = simulate_trial(device, JointDesign::cardan_twist, target, exact_user(), options, rng_ours);
    const TrialResult theirs =
        simulate_trial(device, JointDesign::twist_bend_twist, target, exact_user(), options, rng_theirs);
    const double geodesic = 60.0 * kDeg;
    EXPECT_NEAR(outlet_path_length_rad(ours.path, 0), geodesic, 1e-6);
    // Bend in the hinge's plane, then swing the plane about the inlet shaft.
    EXPECT_GT(outlet_path_length_rad(theirs.path, 0), 1.1 * geodesic) << azimuth;
    EXPECT_GT(theirs.movements, ours.movements);
    EXPECT_GT(theirs.stop_time_s, ours.stop_time_s);
    // It gets there all the same.
    EXPECT_LT(direction_error_rad(theirs.final_pose[0], target[0]), 1e-3);
    EXPECT_LT(angle_between(theirs.final_pose[0], target[0]), 1e-3);
  }
}

TEST(SimulatedUser, ExactUserPosesTheWholeDeviceWithBothDesigns) {
  const PosingDevice device = make_humanoid_device();
  Rng pose_rng(3);
  const JointRotations target = sample_target_pose(device, pose_rng);
  for (const JointDesign design : {JointDesign::cardan_twist, JointDesign::twist_bend_twist}) {
    Rng rng(4);
    const TrialResult r = simulate_trial(device, design, target, exact_user(), TrialOptions{}, rng);
    EXPECT_FALSE(r.timed_out) << to_string(design);
    EXPECT_LT(r.error.back().error_m, 1e-3 * r.initial_error_m) << to_string(design);
    EXPECT_LT(mean_joint_angle_error_rad(r.final_pose, target), 0.1 * kDeg) << to_string(design);
  }
}

TEST(SimulatedUser, TypicalUserStopsWithinWhatTheyCanSee) {
  const PosingDevice device = make_chain_device(1);
  const UserModelOptions options;
  const SimulatedUser user = typical_user(options);
  // What the person cannot see: up to a threshold per component, plus a few
  // SD of perceptual noise around it.
  const double unseen = 1.75 * std::hypot(user.image_threshold_rad, user.depth_threshold_rad);
  Rng pose_rng(5);
  for (int i = 0; i < 10; ++i) {
    const JointRotations target = sample_target_pose(device, pose_rng);
    for (const JointDesign design : {JointDesign::cardan_twist, JointDesign::twist_bend_twist}) {
      Rng rng(100 + static_cast<std::uint64_t>(i));
      const TrialResult r = simulate_trial(device, design, target, user, TrialOptions{}, rng);
      EXPECT_FALSE(r.timed_out) << to_string(design);
      EXPECT_LT(direction_error_rad(r.final_pose[0], target[0]), unseen) << to_string(design) << " pose " << i;
      EXPECT_LT(r.error.back().error_m, r.initial_error_m);
    }
  }
}

TEST(SimulatedUser, ReproducibleBySeed) {
  const PosingDevice device = make_humanoid_device();
  Rng pose_rng(6);
  const JointRotations target = sample_target_pose(device, pose_rng);
  Rng p1(9), p2(9);
  const UserModelOptions options;
  const SimulatedUser u1 = draw_participant(options, p1);
  const SimulatedUser u2 = draw_participant(options, p2);
  EXPECT_EQ(u1.peak_speed_rad_s, u2.peak_speed_rad_s);
  for (const JointDesign design : {JointDesign::cardan_twist, JointDesign::twist_bend_twist}) {
    Rng a(11), b(11), c(12);
    const TrialResult ra = simulate_trial(device, design, target, u1, TrialOptions{}, a);
    const TrialResult rb = simulate_trial(device, design, target, u2, TrialOptions{}, b);
    const TrialResult rc = simulate_trial(device, design, target, u1, TrialOptions{}, c);
    ASSERT_EQ(ra.error.size(), rb.error.size());
    for (std::size_t i = 0; i < ra.error.size(); ++i) {
      EXPECT_EQ(ra.error[i].t_s, rb.error[i].t_s);
      EXPECT_EQ(ra.error[i].error_m, rb.error[i].error_m);
    }
    EXPECT_TRUE(ra.error.size() != rc.error.size() || ra.error.back().error_m != rc.error.back().error_m);
  }
}

TEST(SimulatedUser, RecordsAreTimeOrderedAndRespectTheLimit) {
  const PosingDevice device = make_humanoid_device();
  Rng pose_rng(7);
  const JointRotations target = sample_target_pose(device, pose_rng);
  TrialOptions options;
  options.time_limit_s = 8.0;  // far too short to finish
  for (const JointDesign design : {JointDesign::cardan_twist, JointDesign::twist_bend_twist}) {
    Rng rng(13);
    const TrialResult r = simulate_trial(device, design, target, typical_user(UserModelOptions{}), options, rng);
    EXPECT_TRUE(r.timed_out);
    EXPECT_DOUBLE_EQ(r.stop_time_s, 8.0);
    EXPECT_DOUBLE_EQ(r.error.front().t_s, 0.0);
    EXPECT_LE(r.error.back().t_s, 8.0);
    for (std::size_t i = 1; i < r.error.size(); ++i) EXPECT_GE(r.error[i].t_s, r.error[i - 1].t_s);
  }
}

TEST(SimulatedUser, TrialSummaryStartsAtOneHundredPercent) {
  const PosingDevice device = make_humanoid_device();
  Rng pose_rng(8);
  const JointRotations target = sample_target_pose(device, pose_rng);
  Rng rng(14);
  const TrialResult r =
      simulate_trial(device, JointDesign::twist_bend_twist, target, typical_user(UserModelOptions{}), TrialOptions{}, rng);
  const PosingTrialSummary s = summarize_trial(r, target, 0.5);
  ASSERT_FALSE(s.error_percent_trace.empty());
  EXPECT_DOUBLE_EQ(s.error_percent_trace.front(), 100.0);
  EXPECT_EQ(s.error_percent_trace.size(), static_cast<std::size_t>(std::floor(r.stop_time_s / 0.5)) + 1);
  EXPECT_LE(s.min_error_percent, s.final_error_percent);
  EXPECT_LE(s.time_to_min_s, s.stop_time_s);
  EXPECT_GT(s.work_percent_s, 0.0);
  // Work is bounded by the largest error over the trial's time.
  double worst = 0.0;
  for (const auto& e : r.error) worst = std::max(worst, e.error_m / r.initial_error_m * 100.0);
  EXPECT_LE(s.work_percent_s, worst * s.stop_time_s + 1e-9);
  EXPECT_GE(s.work_percent_s, s.min_error_percent * s.stop_time_s - 1e-9);
}

TEST(SimulatedUser, OptionsValidate) {
  UserModelOptions o;
  EXPECT_TRUE(o.validate().ok());
  EXPECT_NE(o.describe().find("deg"), std::string::npos);
  o.image_threshold_deg = 0.0;
  EXPECT_FALSE(o.validate().ok());
  o = UserModelOptions{};
  o.peak_speed_deg_s = -1.0;
  EXPECT_FALSE(o.validate().ok());
  o = UserModelOptions{};
  o.max_attempts_per_visit = 0;
  EXPECT_FALSE(o.validate().ok());
  o = UserModelOptions{};
  o.motor_noise_fraction = NAN;
  EXPECT_FALSE(o.validate().ok());
  TrialOptions t;
  EXPECT_TRUE(t.validate().ok());
  t.time_limit_s = 0.0;
  EXPECT_FALSE(t.validate().ok());
}

}  // namespace
}  // namespace proprio::rig_eval
