#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <numbers>
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

// --- natural motion, tremor, flicks, contact stops -------------------------------

namespace {

HandMotionGenerator generator_with(const HandMotionOptions& o, int subject = 3) {
  return HandMotionGenerator(HandModel(*sim_subject(subject)->shape()), o);
}

HandMotionOptions natural_options(std::uint64_t seed, bool tremor, bool flicks) {
  HandMotionOptions o;
  o.protocol = MotionProtocol::natural;
  o.seed = seed;
  o.tremor = tremor;
  o.flicks = flicks;
  return o;
}

// Share of samples whose index fingertip moves slower than 1 cm/s.
double still_fraction(HandMotionGenerator& g, double seconds) {
  int still = 0, n = 0;
  for (TimeNs t = 0; t < seconds_to_ns(seconds); t += 10 * kNsPerMillisecond, ++n) {
    if (g.sample(t).pose.linear_velocity_in_world[index_of(HandJoint::index_tip)].norm() < 0.01) ++still;
  }
  return static_cast<double>(still) / n;
}

double rad_s_to_deg_s(double w) { return rad_to_deg(w); }

// Angular velocity between two orientations dt apart, world frame.
Vec3 angular_velocity(const Quat& q0, const Quat& q1, double dt) { return so3_log(q1 * q0.conjugate()) / dt; }

// Times (s) around which two generators' wrist orientations differ by more
// than a degree, as [begin, end] windows from a 10 ms scan.
std::vector<std::pair<double, double>> differing_windows(HandMotionGenerator& a, HandMotionGenerator& b,
                                                         double seconds) {
  std::vector<std::pair<double, double>> out;
  bool inside = false;
  for (TimeNs t = 0; t < seconds_to_ns(seconds); t += 10 * kNsPerMillisecond) {
    const auto fa = a.sample(t), fb = b.sample(t);
    double differ = angle_between(fa.T_world_wrist.q, fb.T_world_wrist.q);
    for (std::size_t i = 0; i < kHandDofCount; ++i) differ = std::max(differ, std::abs(fa.angles[i] - fb.angles[i]));
    const double ts = ns_to_seconds(t);
    if (differ > deg_to_rad(1.0)) {
      if (!inside) out.push_back({ts - 0.02, ts});
      out.back().second = ts + 0.02;
      inside = true;
    } else {
      inside = false;
    }
  }
  return out;
}

}  // namespace

TEST(HandMotion, NaturalMotionKeepsMovingWhereFreeMotionHolds) {
  auto free = generator(MotionProtocol::free_motion, 21);
  auto natural = generator_with(natural_options(21, false, false));
  const double free_still = still_fraction(free, 30.0);
  const double natural_still = still_fraction(natural, 30.0);
  std::printf("[ measured ] still (index tip < 1 cm/s): free_motion %.3f, natural %.3f\n", free_still, natural_still);
  EXPECT_GT(free_still, 0.6) << "free motion holds 2 s of every 3";
  EXPECT_LT(natural_still, 0.15);
  EXPECT_LT(natural_still, 0.25 * free_still);
  // Human speeds, and continuous: no jumps between 1 ms samples.
  double max_speed = 0.0, max_step = 0.0;
  Vec3 previous = natural.sample(0).pose.joint(HandJoint::index_tip).p;
  for (TimeNs t = kNsPerMillisecond; t < 10 * kNsPerSecond; t += kNsPerMillisecond) {
    const auto f = natural.sample(t);
    max_speed = std::max(max_speed, f.pose.linear_velocity_in_world[index_of(HandJoint::index_tip)].norm());
    max_step = std::max(max_step, (f.pose.joint(HandJoint::index_tip).p - previous).norm());
    previous = f.pose.joint(HandJoint::index_tip).p;
  }
  std::printf("[ measured ] natural: peak index tip speed %.2f m/s\n", max_speed);
  EXPECT_GT(max_speed, 0.3);
  EXPECT_LT(max_speed, 3.0);
  EXPECT_LT(max_step, 1.1e-3 * max_speed + 1e-9);
}

TEST(HandMotion, NaturalMotionStaysWithinLimitsAndKeepsTheCoupling) {
  for (auto hand : {Handedness::left, Handedness::right}) {
    HandMotionOptions o = natural_options(4, true, true);
    o.hand = hand;
    auto g = generator_with(o, 6);
    double dip_dev = 0.0, ring_dev = 0.0;
    int n = 0;
    for (TimeNs t = 0; t < 30 * kNsPerSecond; t += 20 * kNsPerMillisecond, ++n) {
      const auto f = g.sample(t);
      ASSERT_TRUE(g.model().limits().contains(f.angles, 1e-9)) << "t=" << t;
      Vec3 p = (o.T_world_head_rest.inverse() * f.T_world_wrist).p;
      if (hand == Handedness::left) p.x() = -p.x();
      for (int i = 0; i < 3; ++i) {
        ASSERT_GE(p[i], o.wrist_min_in_head[i] - 1e-3);  // tremor may add a fraction of a millimetre
        ASSERT_LE(p[i], o.wrist_max_in_head[i] + 1e-3);
      }
      ASSERT_LT(angle_between(f.T_world_wrist.q, o.T_world_head_rest.q), o.wrist_max_tilt_rad + deg_to_rad(80))
          << "tilt, flicks included";
      ASSERT_TRUE(f.pose.fully_valid());
      const std::size_t mid = first_dof_of(Finger::middle), ring = first_dof_of(Finger::ring);
      dip_dev += std::abs(f.angles[mid + 3] - (2.0 / 3.0) * f.angles[mid + 2]);
      ring_dev += std::abs(f.angles[ring + 2] - f.angles[mid + 2]);
    }
    // Mixtures of coupled targets stay coupled (free motion's sigmas: 8 and 15 deg).
    EXPECT_LT(dip_dev / n, deg_to_rad(10));
    EXPECT_LT(ring_dev / n, deg_to_rad(18));
  }
}

TEST(HandMotion, TremorIsAnEightToTwelveHertzOscillationOfTheConfiguredSize) {
  for (double rms : {1.0e-4, 3.0e-4}) {
    HandMotionOptions on = natural_options(9, true, false);
    on.tremor_rms_m = rms;
    auto with = generator_with(on);
    auto without = generator_with(natural_options(9, false, false));
    constexpr int kN = 1000;  // 4 s at 250 Hz
    constexpr double kDt = 0.004;
    std::vector<Vec3> d(kN);
    double sum2 = 0.0, v_sum2 = 0.0;
    const std::size_t tip = index_of(HandJoint::index_tip);
    for (int i = 0; i < kN; ++i) {
      const TimeNs t = seconds_to_ns(5.0 + i * kDt);
      const auto a = with.sample(t), b = without.sample(t);
      d[i] = a.pose.T_world_joint[tip].p - b.pose.T_world_joint[tip].p;
      sum2 += d[i].squaredNorm();
      v_sum2 += (a.pose.linear_velocity_in_world[tip] - b.pose.linear_velocity_in_world[tip]).squaredNorm();
    }
    const double measured = std::sqrt(sum2 / kN);
    const double v_rms = std::sqrt(v_sum2 / kN);
    // Power spectrum (all three axes) by a direct DFT, 0.25 Hz bins to 30 Hz.
    double in_band = 0.0, total = 0.0, peak_power = 0.0, peak_hz = 0.0;
    for (double f = 0.25; f <= 30.0; f += 0.25) {
      double power = 0.0;
      for (int axis = 0; axis < 3; ++axis) {
        double re = 0.0, im = 0.0;
        for (int i = 0; i < kN; ++i) {
          re += d[i][axis] * std::cos(2 * std::numbers::pi * f * i * kDt);
          im += d[i][axis] * std::sin(2 * std::numbers::pi * f * i * kDt);
        }
        power += re * re + im * im;
      }
      total += power;
      if (f >= 7.5 && f <= 12.5) in_band += power;
      if (power > peak_power) {
        peak_power = power;
        peak_hz = f;
      }
    }
    std::printf(
        "[ measured ] tremor %.2f mm configured: index tip RMS %.3f mm, peak %.2f Hz, %.1f%% of power in "
        "7.5-12.5 Hz, velocity RMS %.1f mm/s\n",
        rms * 1e3, measured * 1e3, peak_hz, 100 * in_band / total, v_rms * 1e3);
    EXPECT_NEAR(measured, rms, 0.35 * rms) << "flexed postures shorten the lever a little";
    EXPECT_GE(peak_hz, 8.0);
    EXPECT_LE(peak_hz, 12.0);
    EXPECT_GT(in_band / total, 0.9);
    // And in the velocities: 2 pi f times the displacement.
    EXPECT_GT(v_rms, 2 * std::numbers::pi * 8.0 * measured * 0.8);
    EXPECT_LT(v_rms, 2 * std::numbers::pi * 12.0 * measured * 1.2);
  }
}

TEST(HandMotion, WristFlicksReachTheConfiguredPeakAngularVelocity) {
  HandMotionOptions o = natural_options(13, false, true);
  o.flick_wrist_fraction = 1.0;
  o.flick_peak_min_deg_s = o.flick_peak_max_deg_s = 1400.0;
  auto with = generator_with(o);
  HandMotionOptions off = o;
  off.flicks = false;
  auto without = generator_with(off);
  const auto windows = differing_windows(with, without, 40.0);
  EXPECT_GE(windows.size(), 4u) << "one every 5-10 s";
  EXPECT_LE(windows.size(), 9u);
  constexpr double kDt = 0.25e-3;
  for (const auto& [begin, end] : windows) {
    EXPECT_LT(end - begin, 0.15 + 0.07) << "80-150 ms flicks";
    double peak = 0.0, peak_total = 0.0;
    Quat qa0 = with.sample(seconds_to_ns(begin)).T_world_wrist.q;
    Quat qb0 = without.sample(seconds_to_ns(begin)).T_world_wrist.q;
    for (double t = begin + kDt; t < end; t += kDt) {
      const Quat qa = with.sample(seconds_to_ns(t)).T_world_wrist.q;
      const Quat qb = without.sample(seconds_to_ns(t)).T_world_wrist.q;
      const Vec3 wa = angular_velocity(qa0, qa, kDt), wb = angular_velocity(qb0, qb, kDt);
      peak = std::max(peak, rad_s_to_deg_s((wa - wb).norm()));
      peak_total = std::max(peak_total, rad_s_to_deg_s(wa.norm()));
      qa0 = qa;
      qb0 = qb;
    }
    std::printf("[ measured ] wrist flick at %.2f s: peak %.0f deg/s (with the rest of the motion %.0f deg/s)\n", begin,
                peak, peak_total);
    EXPECT_NEAR(peak, 1400.0, 0.02 * 1400.0);
    EXPECT_LT(peak_total, 2000.0);
  }
}

TEST(HandMotion, FingerFlicksStayBelowTheGyroRangeEverywhere) {
  // Default flicks (1000-1500 deg/s, wrist or finger): every joint of the
  // hand turns slower than the 2000 deg/s of an MPU-9250 at full scale.
  HandMotionOptions o = natural_options(17, true, true);
  o.flick_wrist_fraction = 0.3;
  auto with = generator_with(o);
  HandMotionOptions off = o;
  off.flicks = false;
  auto without = generator_with(off);
  const auto windows = differing_windows(with, without, 60.0);
  EXPECT_GE(windows.size(), 6u);
  double overall = 0.0, finger_peak = 0.0;
  for (const auto& [begin, end] : windows) {
    double joint_peak = 0.0, tip_flick = 0.0;
    for (double t = begin; t < end; t += 0.5e-3) {
      const auto a = with.sample(seconds_to_ns(t)), b = without.sample(seconds_to_ns(t));
      for (std::size_t j = 0; j < kHandJointCount; ++j) {
        joint_peak = std::max(joint_peak, rad_s_to_deg_s(a.pose.angular_velocity_in_world[j].norm()));
      }
      for (HandJoint tip : {HandJoint::index_tip, HandJoint::middle_tip}) {
        const std::size_t j = index_of(tip);
        tip_flick = std::max(
            tip_flick,
            rad_s_to_deg_s((a.pose.angular_velocity_in_world[j] - b.pose.angular_velocity_in_world[j]).norm()));
      }
    }
    const double wrist_flick = rad_s_to_deg_s(
        (with.sample(seconds_to_ns(0.5 * (begin + end)))
             .T_world_wrist.q.angularDistance(without.sample(seconds_to_ns(0.5 * (begin + end))).T_world_wrist.q)));
    if (wrist_flick < 1e-3) finger_peak = std::max(finger_peak, tip_flick);
    overall = std::max(overall, joint_peak);
  }
  std::printf("[ measured ] flicks: fastest joint %.0f deg/s, finger flick peak %.0f deg/s\n", overall, finger_peak);
  EXPECT_LT(overall, 2000.0);
  EXPECT_GT(finger_peak, 900.0);
  EXPECT_LT(finger_peak, 1500.0 * 1.05);
  // Coarse check of the rest: nothing outside the flicks comes near.
  for (TimeNs t = 0; t < 60 * kNsPerSecond; t += 10 * kNsPerMillisecond) {
    const auto f = without.sample(t);
    for (std::size_t j = 0; j < kHandJointCount; ++j)
      ASSERT_LT(rad_s_to_deg_s(f.pose.angular_velocity_in_world[j].norm()), 1000.0);
  }
}

// One approach to contact: speeds (t, speed toward contact) until the first
// sample at rest, t_rest.
struct ApproachStats {
  double peak = 0.0;    // fastest on the way
  double before = 0.0;  // speed stop_s + 1 ms before rest: still fast if it stops abruptly
  double stop_s = 0.0;  // 90% to 1% of `before`, scaled to a whole uniform deceleration
};

ApproachStats approach_stats(const std::vector<std::pair<double, double>>& speeds, double t_rest, double stop_s) {
  ApproachStats a;
  for (const auto& [t, v] : speeds) {
    a.peak = std::max(a.peak, v);
    if (t <= t_rest - stop_s - 1e-3) a.before = v;
  }
  double t90 = t_rest, t01 = t_rest;
  for (const auto& [t, v] : speeds) {
    if (t > t_rest - stop_s - 5e-3 && v >= 0.9 * a.before) t90 = t;
  }
  for (auto it = speeds.rbegin(); it != speeds.rend() && it->first > t90 && it->second <= 0.01 * a.before; ++it) {
    t01 = it->first;
  }
  a.stop_s = (t01 - t90) / 0.89;
  return a;
}

TEST(HandMotion, TappingStopsAbruptlyOnTheTableAndNeverGoesThrough) {
  for (bool stops : {true, false}) {
    HandMotionOptions o;
    o.protocol = MotionProtocol::tapping;
    o.seed = 5;
    o.contact_stops = stops;
    auto g = generator_with(o);
    const double table = g.table_height_in_world_m();
    const std::size_t tip = index_of(HandJoint::index_tip);
    double lowest = std::numeric_limits<double>::infinity();
    int contacts = 0;
    double worst_stop = 0.0, min_stop = 1.0, max_decel = 0.0, fastest = 0.0, min_before_ratio = 1.0,
           max_before_ratio = 0.0;
    std::vector<std::pair<double, double>> speeds;  // (t, downward tip speed) since the last contact
    bool was_in_contact = false;
    double v_prev = 0.0;
    for (TimeNs t = 0; t < 6 * kNsPerSecond; t += kNsPerMillisecond / 2) {
      const auto f = g.sample(t);
      for (std::size_t j = 0; j < kHandJointCount; ++j) {
        const double bottom = f.pose.T_world_joint[j].p.y() - f.pose.radius_m[j];
        if (j == tip) lowest = std::min(lowest, bottom);
        ASSERT_GE(bottom, table - 1e-9) << to_string(static_cast<HandJoint>(j)) << " t=" << t;
      }
      const double v = -f.pose.linear_velocity_in_world[tip].y();
      if (t > 0) max_decel = std::max(max_decel, (v_prev - v) / 0.5e-3);
      v_prev = v;
      if (f.in_contact && !was_in_contact && !speeds.empty()) {
        ++contacts;
        const auto a = approach_stats(speeds, ns_to_seconds(t), o.contact_stop_s);
        worst_stop = std::max(worst_stop, a.stop_s);
        min_stop = std::min(min_stop, a.stop_s);
        fastest = std::max(fastest, a.before);
        min_before_ratio = std::min(min_before_ratio, a.before / a.peak);
        max_before_ratio = std::max(max_before_ratio, a.before / a.peak);
      }
      if (f.in_contact) {
        speeds.clear();
        // At rest on the table (the velocities' central difference reaches
        // 0.5 ms either side, into the stop or the next lift).
        if (was_in_contact) {
          EXPECT_LT(std::abs(v), 5e-3) << "t=" << t;
        }
      } else {
        speeds.push_back({ns_to_seconds(t), v});
      }
      was_in_contact = f.in_contact;
    }
    std::printf(
        "[ measured ] tapping, contact stops %s: %d taps in 6 s; lowest pad %.6f mm above the table; speed "
        "%.0f ms before rest %.0f-%.0f%% of the peak, up to %.2f m/s; its fall from 90%% to 1%% as a uniform stop: "
        "%.1f-%.1f ms; peak deceleration "
        "%.0f m/s^2\n",
        stops ? "on" : "off", contacts, (lowest - table) * 1e3, (o.contact_stop_s + 1e-3) * 1e3, 100 * min_before_ratio,
        100 * max_before_ratio, fastest, min_stop * 1e3, worst_stop * 1e3, max_decel);
    EXPECT_GE(contacts, 10) << "about 2 taps a second";
    EXPECT_NEAR(lowest, table, 1e-9) << "the pad reaches the table";
    if (stops) {
      EXPECT_GT(min_before_ratio, 0.6) << "still fast just before it stops";
      EXPECT_GT(fastest, 0.15) << "it hits the table";
      EXPECT_NEAR(worst_stop, o.contact_stop_s, 0.0015);
      EXPECT_NEAR(min_stop, o.contact_stop_s, 0.0015);
      EXPECT_GT(max_decel, 0.9 * fastest / o.contact_stop_s) << "the spike an IMU sees";
    } else {
      EXPECT_LT(max_before_ratio, 0.4) << "a minimum-jerk settle has slowed down long before";
    }
  }
}

TEST(HandMotion, PinchContactStopsWhenThePadsTouch) {
  HandMotionOptions o;
  o.protocol = MotionProtocol::pinch_grasp_contact;
  o.seed = 2;
  auto g = generator_with(o);
  HandMotionOptions smooth_options = o;
  smooth_options.protocol = MotionProtocol::pinch_grasp;
  auto smooth = generator_with(smooth_options);
  const std::size_t thumb = index_of(HandJoint::thumb_tip), index = index_of(HandJoint::index_tip);
  auto gap_of = [&](const HandPose& p) {
    return (p.T_world_joint[thumb].p - p.T_world_joint[index].p).norm() - p.radius_m[thumb] - p.radius_m[index];
  };
  // Closing speed: how fast the distance between the pads shrinks.
  auto closing_of = [&](const HandPose& p) {
    const Vec3 d = p.T_world_joint[index].p - p.T_world_joint[thumb].p;
    return -d.dot(p.linear_velocity_in_world[index] - p.linear_velocity_in_world[thumb]) / d.norm();
  };
  const double contact_gap = gap_of(g.model().forward(Handedness::right, g.pinch_angles(), Pose::identity(), 0));
  ASSERT_LT(std::abs(contact_gap), 0.002) << "the pinch solve";
  for (auto* gen : {&g, &smooth}) {
    const bool stops = gen == &g;
    std::vector<std::pair<double, double>> speeds;
    double t_rest = -1.0, min_gap = 1.0;
    for (TimeNs t = seconds_to_ns(3.0); t < seconds_to_ns(5.0); t += kNsPerMillisecond / 2) {
      const auto f = gen->sample(t);
      const double gap = gap_of(f.pose);
      min_gap = std::min(min_gap, gap);
      const bool at_rest = stops ? f.in_contact : f.angles == gen->pinch_angles();
      if (at_rest) {
        EXPECT_NEAR(gap, contact_gap, 1e-9) << "the pads stop at contact";
        if (t_rest >= 0) {
          EXPECT_LT(std::abs(closing_of(f.pose)), 1e-6) << "and stay there";
        }
        if (t_rest < 0) t_rest = ns_to_seconds(t);
      } else if (t_rest < 0) {
        speeds.push_back({ns_to_seconds(t), closing_of(f.pose)});
      }
    }
    ASSERT_GT(t_rest, 0.0) << "contact is reached";
    const auto a = approach_stats(speeds, t_rest, o.contact_stop_s);
    std::printf(
        "[ measured ] %s: pads close at up to %.3f m/s, %.3f m/s %.0f ms before rest, its fall from 90%% to 1%% as a "
        "uniform stop: %.1f ms; "
        "closest %.4f mm (contact gap %.4f mm)\n",
        stops ? "pinch-grasp-contact" : "pinch-grasp", a.peak, a.before, (o.contact_stop_s + 1e-3) * 1e3,
        a.stop_s * 1e3, min_gap * 1e3, contact_gap * 1e3);
    EXPECT_GT(min_gap, contact_gap - 1e-9) << "the pads never pass through each other";
    if (stops) {
      EXPECT_GT(a.before, 0.6 * a.peak);
      EXPECT_NEAR(a.stop_s, o.contact_stop_s, 0.0015);
    } else {
      EXPECT_LT(a.before, 0.1 * a.peak) << "pinch-grasp settles smoothly";
    }
  }
  // Same keyframes, same holds as pinch-grasp.
  for (double t : {1.9, 4.9, 7.9, 10.9, 13.9, 16.9}) {
    const auto a = g.sample(seconds_to_ns(t)), b = smooth.sample(seconds_to_ns(t));
    EXPECT_EQ(a.angles, b.angles) << t;
    EXPECT_EQ(a.T_world_wrist.p, b.T_world_wrist.p) << t;
    EXPECT_EQ(a.in_contact, t - 3.0 * std::floor(t / 3.0) > 0.5 && static_cast<int>(t / 3.0) % 2 == 1) << t;
  }
}

TEST(HandMotion, NewProtocolsAreDeterministicWhateverTheQueryOrder) {
  for (auto protocol : {MotionProtocol::natural, MotionProtocol::tapping, MotionProtocol::pinch_grasp_contact}) {
    auto a = generator(protocol, 7);
    auto b = generator(protocol, 7);
    for (TimeNs t = 0; t <= 20 * kNsPerSecond; t += 10 * kNsPerMillisecond) a.sample(t);
    for (TimeNs t : {TimeNs{19'870'000'000}, TimeNs{1'234'000'000}, TimeNs{12'345'678'901}, TimeNs{5'000'000'000}}) {
      EXPECT_EQ(bytes_of(a.sample(t)), bytes_of(b.sample(t))) << to_string(protocol) << " t=" << t;
    }
    auto c = generator(protocol, 8);
    EXPECT_NE(bytes_of(a.sample(5 * kNsPerSecond + 123)), bytes_of(c.sample(5 * kNsPerSecond + 123)))
        << to_string(protocol);
  }
}

TEST(HandMotion, EachNaturalEffectDrawsFromItsOwnStream) {
  // Tremor on or off, or other flick numbers, leave the submovements and the
  // other effects exactly as they were.
  auto all = generator_with(natural_options(3, true, true));
  auto no_flicks = generator_with(natural_options(3, true, false));
  HandMotionOptions faster = natural_options(3, true, true);
  faster.flick_peak_min_deg_s = faster.flick_peak_max_deg_s = 1200.0;
  auto other_flicks = generator_with(faster);
  auto no_tremor = generator_with(natural_options(3, false, false));
  auto base = generator_with(natural_options(3, false, false));
  int same = 0, n = 0;
  for (TimeNs t = 0; t < 20 * kNsPerSecond; t += 50 * kNsPerMillisecond, ++n) {
    const auto a = all.sample(t), b = no_flicks.sample(t), c = other_flicks.sample(t);
    if (bytes_of(a) == bytes_of(b) && bytes_of(c) == bytes_of(b)) ++same;  // outside the flicks
    EXPECT_EQ(bytes_of(no_tremor.sample(t)), bytes_of(base.sample(t)));
  }
  EXPECT_GT(same, n * 9 / 10) << "flicks take well under a tenth of the time";
  EXPECT_LT(same, n) << "but some";
}

TEST(HandMotion, NaturalVelocitiesIncludeTremorAndFlicks) {
  auto g = generator_with(natural_options(5, true, true));
  for (double ts : {3.4, 7.77, 12.05}) {
    const TimeNs t = seconds_to_ns(ts);
    const TimeNs dt = kNsPerMillisecond / 4;
    const auto a = g.sample(t - dt), b = g.sample(t + dt), c = g.sample(t);
    for (std::size_t i = 0; i < kHandJointCount; ++i) {
      const Vec3 v = (b.pose.T_world_joint[i].p - a.pose.T_world_joint[i].p) / ns_to_seconds(2 * dt);
      EXPECT_LT((c.pose.linear_velocity_in_world[i] - v).norm(), 1e-3 * (1.0 + v.norm())) << ts;
    }
  }
}

TEST(HandMotionOptions, ValidateNamesTheBadField) {
  EXPECT_TRUE(HandMotionOptions{}.validate().ok());
  auto message = [](auto change) {
    HandMotionOptions o;
    change(o);
    const Status st = o.validate();
    return st.ok() ? std::string("ok") : st.error().message;
  };
  EXPECT_NE(message([](auto& o) { o.tremor_rms_m = std::nan(""); }).find("tremor_rms_m"), std::string::npos);
  EXPECT_NE(message([](auto& o) { o.contact_stop_s = -0.01; }).find("contact_stop_s"), std::string::npos);
  EXPECT_NE(
      message([](auto& o) { o.submovement_max_s = std::numeric_limits<double>::infinity(); }).find("submovement_max_s"),
      std::string::npos);
  EXPECT_NE(message([](auto& o) { o.flick_peak_min_deg_s = 1800; }).find("flick_peak_min_deg_s"), std::string::npos);
  EXPECT_NE(message([](auto& o) { o.tap_finger = Finger::thumb; }).find("tap_finger"), std::string::npos);
  EXPECT_NE(message([](auto& o) { o.target_interval_s = 0.0; }).find("target_interval_s"), std::string::npos);
  EXPECT_NE(message([](auto& o) { o.wrist_min_in_head.x() = 1.0; }).find("workspace"), std::string::npos);
  HandMotionOptions bad;
  bad.hold_probability = 2.0;
  const auto created = HandMotionGenerator::create(HandModel(*sim_subject(0)->shape()), bad);
  ASSERT_FALSE(created.ok());
  EXPECT_EQ(created.error().code, Errc::invalid_argument);
  EXPECT_TRUE(HandMotionGenerator::create(HandModel(*sim_subject(0)->shape()), HandMotionOptions{}).ok());
  const std::string d = HandMotionOptions{}.describe();
  for (const char* field : {"protocol=free-motion", "tremor=on", "flicks=on", "contact_stops=on",
                            "submovement=0.30-1.20s", "tapping(finger=index"}) {
    EXPECT_NE(d.find(field), std::string::npos) << field << " in " << d;
  }
}

TEST(MotionProtocol, ParsesEveryProtocolsName) {
  for (auto p : kMotionProtocols) EXPECT_EQ(parse_motion_protocol(to_string(p)), p) << to_string(p);
  EXPECT_EQ(parse_motion_protocol("natural"), MotionProtocol::natural);
  EXPECT_EQ(parse_motion_protocol("tapping"), MotionProtocol::tapping);
  EXPECT_EQ(parse_motion_protocol("pinch-grasp-contact"), MotionProtocol::pinch_grasp_contact);
}
