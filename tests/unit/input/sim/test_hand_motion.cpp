#include <gtest/gtest.h>

#include <cstring>
#include <vector>

#include "proprio/sim/hand_motion.hpp"
#include "proprio/sim/subjects.hpp"

using namespace proprio;
using namespace proprio::sim;

namespace {

HandMotionGenerator generator(MotionProtocol protocol, std::uint64_t seed, int subject = 3,
                              Handedness hand = Handedness::right) {
  HandMotionOptions o;
  o.protocol = protocol;
  o.seed = seed;
  o.hand = hand;
  return HandMotionGenerator(HandModel(*sim_subject(subject)->shape()), o);
}

// Raw bytes of everything a frame carries, for bit-exact comparison.
std::vector<unsigned char> bytes_of(const HandMotionFrame& f) {
  std::vector<unsigned char> out;
  auto put = [&](const void* p, std::size_t n) {
    const auto* c = static_cast<const unsigned char*>(p);
    out.insert(out.end(), c, c + n);
  };
  put(f.angles.data(), sizeof(double) * f.angles.size());
  for (const auto& T : f.pose.T_world_joint) {
    put(T.q.coeffs().data(), 4 * sizeof(double));
    put(T.p.data(), 3 * sizeof(double));
  }
  for (const auto& v : f.pose.linear_velocity_in_world) put(v.data(), 3 * sizeof(double));
  put(f.T_world_head.p.data(), 3 * sizeof(double));
  return out;
}

}  // namespace

TEST(MinimumJerk, BoundaryValuesAndSymmetry) {
  EXPECT_DOUBLE_EQ(minimum_jerk(0.0), 0.0);
  EXPECT_DOUBLE_EQ(minimum_jerk(1.0), 1.0);
  EXPECT_NEAR(minimum_jerk(0.5), 0.5, 1e-15);
  EXPECT_NEAR(minimum_jerk(0.3) + minimum_jerk(0.7), 1.0, 1e-15);
  const double h = 1e-6;
  EXPECT_NEAR((minimum_jerk(h) - minimum_jerk(0)) / h, 0.0, 1e-6) << "starts at rest";
  EXPECT_NEAR((minimum_jerk(1) - minimum_jerk(1 - h)) / h, 0.0, 1e-6) << "ends at rest";
  EXPECT_NEAR((minimum_jerk(0.5 + h) - minimum_jerk(0.5 - h)) / (2 * h), 1.875, 1e-6) << "peak speed 15/8";
}

TEST(HandMotion, SameSeedGivesIdenticalBytesWhateverTheSampleRate) {
  auto a = generator(MotionProtocol::free_motion, 7);
  auto b = generator(MotionProtocol::free_motion, 7);
  // a walks forward at 100 Hz; b jumps straight to the probe times.
  for (TimeNs t = 0; t <= 10 * kNsPerSecond; t += 10 * kNsPerMillisecond) a.sample(t);
  for (TimeNs t : {TimeNs{9'870'000'000}, TimeNs{1'234'000'000}, TimeNs{5'000'000'000}}) {
    EXPECT_EQ(bytes_of(a.sample(t)), bytes_of(b.sample(t))) << "t=" << t;
  }
  auto c = generator(MotionProtocol::free_motion, 8);
  EXPECT_NE(bytes_of(a.sample(5 * kNsPerSecond)), bytes_of(c.sample(5 * kNsPerSecond)));
}

TEST(HandMotion, FreeMotionReachesANewTargetEveryIntervalAndHolds) {
  auto g = generator(MotionProtocol::free_motion, 11);
  const auto& o = g.options();
  ASSERT_DOUBLE_EQ(o.target_interval_s, 3.0);
  HandAngles previous_target{};
  for (int k = 1; k <= 5; ++k) {
    const TimeNs held_from = seconds_to_ns(3.0 * k + o.transition_s + 0.01);
    const TimeNs held_to = seconds_to_ns(3.0 * (k + 1) - 0.01);
    const auto f0 = g.sample(held_from), f1 = g.sample(held_to);
    EXPECT_EQ(f0.keyframe, static_cast<std::size_t>(k));
    EXPECT_EQ(f0.angles, f1.angles) << "holds the target";
    EXPECT_LT(f0.pose.linear_velocity_in_world[index_of(HandJoint::index_tip)].norm(), 1e-9);
    double change = 0;
    for (std::size_t i = 0; i < kHandDofCount; ++i) change += std::abs(f0.angles[i] - previous_target[i]);
    EXPECT_GT(change, deg_to_rad(20)) << "a new random target at keyframe " << k;
    previous_target = f0.angles;
    // Mid-transition the hand is between the two targets and moving.
    const auto mid = g.sample(seconds_to_ns(3.0 * k + 0.5 * o.transition_s));
    EXPECT_GT(mid.pose.linear_velocity_in_world[index_of(HandJoint::index_tip)].norm(), 0.01);
  }
}

TEST(HandMotion, StaysWithinJointLimitsAndTheWristWorkspace) {
  for (auto protocol : {MotionProtocol::free_motion, MotionProtocol::pinch_grasp, MotionProtocol::wrist_sweep}) {
    for (auto hand : {Handedness::left, Handedness::right}) {
      auto g = generator(protocol, 3, 5, hand);
      const auto& o = g.options();
      for (TimeNs t = 0; t < 30 * kNsPerSecond; t += 50 * kNsPerMillisecond) {
        const auto f = g.sample(t);
        ASSERT_TRUE(g.model().limits().contains(f.angles, 1e-9)) << to_string(protocol) << " t=" << t;
        Vec3 p = (o.T_world_head_rest.inverse() * f.T_world_wrist).p;
        if (hand == Handedness::left) p.x() = -p.x();
        for (int i = 0; i < 3; ++i) {
          ASSERT_GE(p[i], o.wrist_min_in_head[i] - 1e-9) << to_string(protocol);
          ASSERT_LE(p[i], o.wrist_max_in_head[i] + 1e-9) << to_string(protocol);
        }
        ASSERT_TRUE(f.pose.fully_valid());
      }
    }
  }
}

TEST(HandMotion, VelocitiesMatchTheMotion) {
  auto g = generator(MotionProtocol::wrist_sweep, 5);
  const TimeNs t = seconds_to_ns(3.4);
  const TimeNs dt = kNsPerMillisecond;
  const auto a = g.sample(t - dt), b = g.sample(t + dt), c = g.sample(t);
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    const Vec3 v = (b.pose.T_world_joint[i].p - a.pose.T_world_joint[i].p) / ns_to_seconds(2 * dt);
    EXPECT_LT((c.pose.linear_velocity_in_world[i] - v).norm(), 1e-3 * (1.0 + v.norm()));
  }
  EXPECT_GT(c.pose.linear_velocity_in_world[index_of(HandJoint::wrist)].norm(), 0.01) << "the wrist is moving";
}

TEST(HandMotion, PinchBringsThumbAndIndexPadsTogetherForEverySubject) {
  for (int id = 0; id < kSimSubjectCount; ++id) {
    HandMotionOptions o;
    o.protocol = MotionProtocol::pinch_grasp;
    HandMotionGenerator g(HandModel(*sim_subject(id)->shape()), o);
    const HandPose p = g.model().forward(Handedness::right, g.pinch_angles(), Pose::identity(), 0);
    const double gap = (p.joint(HandJoint::thumb_tip).p - p.joint(HandJoint::index_tip).p).norm() -
                       p.radius_m[index_of(HandJoint::thumb_tip)] - p.radius_m[index_of(HandJoint::index_tip)];
    EXPECT_LT(std::abs(gap), 0.002) << "subject " << id << " gap " << gap;
    EXPECT_TRUE(g.model().limits().contains(g.pinch_angles(), 1e-9));
    // The pinch keyframe is actually visited: keyframe 1 holds it.
    const auto f = g.sample(seconds_to_ns(o.target_interval_s * 1.9));
    EXPECT_EQ(f.angles, g.pinch_angles());
  }
}

TEST(HandMotion, HeadSwaysSlightlyAroundRest) {
  auto g = generator(MotionProtocol::free_motion, 1);
  double max_offset = 0;
  for (TimeNs t = 0; t < 20 * kNsPerSecond; t += 100 * kNsPerMillisecond) {
    max_offset = std::max(max_offset, (g.sample(t).T_world_head.p - g.options().T_world_head_rest.p).norm());
  }
  EXPECT_GT(max_offset, 0.003);
  EXPECT_LT(max_offset, 0.02);
}

TEST(SimSubjects, SpanTheSeedsHandSizes) {
  double min_l = 1, max_l = 0, min_w = 1, max_w = 0;
  for (int id = 0; id < kSimSubjectCount; ++id) {
    auto s = sim_subject(id);
    ASSERT_TRUE(s.ok());
    min_l = std::min(min_l, s->hand_length_m);
    max_l = std::max(max_l, s->hand_length_m);
    min_w = std::min(min_w, s->hand_width_m);
    max_w = std::max(max_w, s->hand_width_m);
    EXPECT_TRUE(s->shape().ok());
  }
  EXPECT_NEAR(min_l, 0.170, 1e-12);
  EXPECT_NEAR(max_l, 0.205, 1e-12);
  EXPECT_NEAR(min_w, 0.090, 1e-12);
  EXPECT_NEAR(max_w, 0.110, 1e-12);
  auto bad = sim_subject(kSimSubjectCount);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("0-14"), std::string::npos);
}

TEST(MotionProtocol, ParsesItsOwnNames) {
  for (auto p : {MotionProtocol::free_motion, MotionProtocol::pinch_grasp, MotionProtocol::wrist_sweep}) {
    EXPECT_EQ(parse_motion_protocol(to_string(p)), p);
  }
  EXPECT_FALSE(parse_motion_protocol("freemotion").has_value());
}
