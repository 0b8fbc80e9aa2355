#include <gtest/gtest.h>

#include <cmath>

#include "proprio/core/pose_history.hpp"

using namespace proprio;

namespace {

// Analytic motion: every joint translates at constant velocity v and rotates
// about a fixed world axis at constant rate w, from its own start offset.
const Vec3 kVelocity(0.2, -0.1, 0.05);      // m/s
const Vec3 kAngularVelocity(0.0, 1.5, 0.5);  // rad/s

Pose analytic_joint(std::size_t i, double t) {
  const Vec3 p0(0.01 * static_cast<double>(i), 1.0, -0.3);
  const Quat q0 = so3_exp(Vec3(0.1, 0.02 * static_cast<double>(i), 0.0));
  return {(so3_exp(kAngularVelocity * t) * q0).normalized(), p0 + kVelocity * t};
}

HandPose analytic_pose(TimeNs t_ns) {
  HandPose p;
  p.time_ns = t_ns;
  p.active = true;
  p.set_all_flags(kJointFullyTracked);
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    p.T_world_joint[i] = analytic_joint(i, ns_to_seconds(t_ns));
    p.radius_m[i] = 0.01;
  }
  return p;
}

PoseHistory filled_history(PoseHistoryOptions options, int samples, DurationNs step) {
  PoseHistory h(options);
  for (int k = 0; k < samples; ++k) EXPECT_TRUE(h.push(analytic_pose(k * step)).ok());
  return h;
}

}  // namespace

TEST(PoseHistory, InterpolatesAnalyticMotionBetweenSamples) {
  const DurationNs step = 10 * kNsPerMillisecond;  // 100 Hz
  PoseHistory h = filled_history({}, 50, step);
  for (TimeNs t : {TimeNs{3'000'000}, TimeNs{125'000'000}, TimeNs{333'333'333}}) {
    auto q = h.query(t);
    ASSERT_TRUE(q.ok()) << q.error().message;
    EXPECT_EQ(q->kind, PoseQueryKind::interpolated);
    EXPECT_EQ(q->pose.time_ns, t);
    for (std::size_t i = 0; i < kHandJointCount; ++i) {
      const Pose truth = analytic_joint(i, ns_to_seconds(t));
      // Constant velocity and constant-rate rotation about a fixed axis are
      // exactly what lerp + slerp reproduce.
      EXPECT_LT((q->pose.T_world_joint[i].p - truth.p).norm(), 1e-12);
      EXPECT_LT(angle_between(q->pose.T_world_joint[i].q, truth.q), 1e-9);
      EXPECT_LT((q->pose.linear_velocity_in_world[i] - kVelocity).norm(), 1e-9);
      EXPECT_LT((q->pose.angular_velocity_in_world[i] - kAngularVelocity).norm(), 1e-6);
    }
  }
}

TEST(PoseHistory, ExactTimeReturnsTheSample) {
  PoseHistory h = filled_history({}, 10, kNsPerMillisecond);
  auto q = h.query(4 * kNsPerMillisecond);
  ASSERT_TRUE(q.ok());
  EXPECT_EQ(q->kind, PoseQueryKind::exact);
}

TEST(PoseHistory, PredictsWithConstantVelocityWithinHorizon) {
  const DurationNs step = 10 * kNsPerMillisecond;
  PoseHistory h = filled_history({}, 20, step);
  const TimeNs t = h.newest_time_ns() + 30 * kNsPerMillisecond;
  auto q = h.query(t);
  ASSERT_TRUE(q.ok()) << q.error().message;
  EXPECT_EQ(q->kind, PoseQueryKind::predicted);
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    const Pose truth = analytic_joint(i, ns_to_seconds(t));
    EXPECT_LT((q->pose.T_world_joint[i].p - truth.p).norm(), 1e-9);
    EXPECT_LT(angle_between(q->pose.T_world_joint[i].q, truth.q), 1e-6);
  }
}

TEST(PoseHistory, PredictionUsesReportedVelocityWhenPresent) {
  PoseHistory h;
  HandPose p = analytic_pose(0);
  p.has_velocity = true;
  for (auto& v : p.linear_velocity_in_world) v = Vec3(1.0, 0.0, 0.0);
  for (auto& w : p.angular_velocity_in_world) w = Vec3::Zero();
  ASSERT_TRUE(h.push(p).ok());
  auto q = h.query(20 * kNsPerMillisecond);
  ASSERT_TRUE(q.ok());
  EXPECT_NEAR(q->pose.T_world_joint[0].p.x() - p.T_world_joint[0].p.x(), 0.02, 1e-12);
}

TEST(PoseHistory, RefusesToPredictBeyondHorizonAndSaysByHowMuch) {
  PoseHistoryOptions o;
  o.max_prediction_ns = 20 * kNsPerMillisecond;
  PoseHistory h = filled_history(o, 5, kNsPerMillisecond);
  auto q = h.query(h.newest_time_ns() + 25 * kNsPerMillisecond);
  ASSERT_FALSE(q.ok());
  EXPECT_EQ(q.error().code, Errc::out_of_range);
  EXPECT_NE(q.error().message.find("25.0ms"), std::string::npos) << q.error().message;
  EXPECT_NE(q.error().message.find("20.0ms"), std::string::npos) << q.error().message;
}

TEST(PoseHistory, RefusesTimesOlderThanKeptAndEvictsOldest) {
  PoseHistoryOptions o;
  o.capacity = 8;
  PoseHistory h = filled_history(o, 20, kNsPerMillisecond);
  EXPECT_EQ(h.size(), 8u);
  EXPECT_EQ(h.oldest_time_ns(), 12 * kNsPerMillisecond);
  auto q = h.query(5 * kNsPerMillisecond);
  ASSERT_FALSE(q.ok());
  EXPECT_EQ(q.error().code, Errc::out_of_range);
  EXPECT_TRUE(h.query(12 * kNsPerMillisecond + 500'000).ok());
}

TEST(PoseHistory, ReportsGapsInsteadOfBridgingThem) {
  PoseHistoryOptions o;
  o.max_interpolation_gap_ns = 50 * kNsPerMillisecond;
  PoseHistory h(o);
  ASSERT_TRUE(h.push(analytic_pose(0)).ok());
  ASSERT_TRUE(h.push(analytic_pose(200 * kNsPerMillisecond)).ok());
  auto q = h.query(100 * kNsPerMillisecond);
  ASSERT_FALSE(q.ok());
  EXPECT_EQ(q.error().code, Errc::unavailable);
}

TEST(PoseHistory, RejectsOutOfOrderSamplesAndEmptyQueries) {
  PoseHistory h;
  EXPECT_FALSE(h.query(0).ok());
  ASSERT_TRUE(h.push(analytic_pose(10)).ok());
  EXPECT_FALSE(h.push(analytic_pose(10)).ok());
  EXPECT_FALSE(h.push(analytic_pose(5)).ok());
  EXPECT_EQ(h.size(), 1u);
}

TEST(PoseHistory, InterpolatedFlagsAreTheIntersection) {
  PoseHistory h;
  HandPose a = analytic_pose(0), b = analytic_pose(kNsPerMillisecond);
  b.flags[3] = kOrientationValid | kPositionValid;  // valid but not tracked
  ASSERT_TRUE(h.push(a).ok());
  ASSERT_TRUE(h.push(b).ok());
  auto q = h.query(500'000);
  ASSERT_TRUE(q.ok());
  EXPECT_EQ(q->pose.flags[3], kOrientationValid | kPositionValid);
  EXPECT_EQ(q->pose.flags[4], kJointFullyTracked);
}

TEST(PoseHistory, OptionsDescribeThemselves) {
  EXPECT_EQ(PoseHistoryOptions{}.describe(), "capacity=256 max_prediction=50.0ms max_gap=200.0ms");
}
