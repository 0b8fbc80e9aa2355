// The wrist calibration's arithmetic without OpenXR: the offset from a still
// window for each device and reference, the stillness measure, and the
// countdown / still-window / timeout state machine.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "proprio/engine/wrist_calibration.hpp"

namespace proprio::engine {
namespace wrist_calibration_test {

Quat yaw(double rad) { return Quat(Eigen::AngleAxisd(rad, Vec3::UnitY())); }
Quat axis_angle(const Vec3& axis, double rad) { return Quat(Eigen::AngleAxisd(rad, axis.normalized())); }
double angle_deg(const Quat& a, const Quat& b) { return a.angularDistance(b) * 180.0 / M_PI; }

// A rotation from three explicit columns (the wrist's axes in LOCAL).
Quat from_axes(const Vec3& x, const Vec3& y, const Vec3& z) {
  Mat3 m;
  m.col(0) = x;
  m.col(1) = y;
  m.col(2) = z;
  return Quat(m);
}

// Samples at 90 Hz over `seconds` of a device at T_local_device, with
// per-sample noise (position sigma m, rotation sigma deg), the head at T_local_view.
std::vector<WristSample> still_window(const Pose& T_local_device, const Pose& T_local_view, double seconds,
                                      double pos_sigma_m = 0.0, double rot_sigma_deg = 0.0, unsigned seed = 1) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<WristSample> w;
  for (int i = 0; i <= static_cast<int>(std::lround(seconds * 90.0)); ++i) {
    WristSample s;
    s.t_s = 10.0 + i / 90.0;
    const Vec3 dr = Vec3(n(rng), n(rng), n(rng)) * (rot_sigma_deg * M_PI / 180.0);
    s.T_local_device = {(T_local_device.q * so3_exp(dr)).normalized(),
                        T_local_device.p + Vec3(n(rng), n(rng), n(rng)) * pos_sigma_m};
    s.T_local_view = T_local_view;
    w.push_back(s);
  }
  return w;
}

WristCalibrationOptions options_for(WristDevice device, Handedness hand,
                                    WristReference reference = WristReference::pose) {
  WristCalibrationOptions o;
  o.device = device;
  o.hand = hand;
  o.reference = reference;
  return o;
}

// The user does exactly what the tracker procedure asks: with the head at yaw
// psi (and pitched, which must not matter), the wrist is level with its -Z
// along the head's level forward direction; the tracker sits d above it.
TEST(WristCalibration, TrackerPoseReferenceRecoversTheOffsetOfAHandHeldAsInstructed) {
  const Quat R_device_wrist_true = axis_angle(Vec3(0.3, -1.0, 0.2), 1.1);
  for (const double psi : {0.0, 0.7, -2.5}) {
    for (Handedness hand : {Handedness::left, Handedness::right}) {
      auto o = options_for(WristDevice::tracker, hand);
      o.wrist_below_device_m = 0.035;
      const Pose T_local_view{yaw(psi) * axis_angle(Vec3::UnitX(), 0.25), Vec3(0.02, 0.01, 0.03)};
      const Pose T_local_wrist{yaw(psi), Vec3(0.15, -0.35, -0.3)};
      Pose T_local_device;
      T_local_device.q = T_local_wrist.q * R_device_wrist_true.conjugate();
      T_local_device.p = T_local_wrist.p + Vec3(0.0, 0.035, 0.0);
      const Pose expected = T_local_device.inverse() * T_local_wrist;

      auto r = solve_wrist_calibration(still_window(T_local_device, T_local_view, 2.0), o);
      ASSERT_TRUE(r) << r.error().message;
      EXPECT_LT(angle_deg(r->T_device_wrist.q, expected.q), 1e-6) << "psi " << psi;
      EXPECT_LT((r->T_device_wrist.p - expected.p).norm(), 1e-9) << "psi " << psi;
      EXPECT_NEAR(r->T_device_wrist.p.norm(), 0.035, 1e-9);
      EXPECT_NEAR(r->head_yaw_deg, std::remainder(psi, 2 * M_PI) * 180.0 / M_PI, 1e-6);
      EXPECT_FALSE(r->assumed.empty());
      EXPECT_NE(r->assumed.find("0.035 m below"), std::string::npos) << r->assumed;
    }
  }
}

// Controller, thumb up, forearm ahead, looking along LOCAL's -Z: the right
// wrist's back (+Y) faces +X, the left one's -X; fingers (-Z) ahead. Written
// out axis by axis, so a sign slip in the solver shows.
TEST(WristCalibration, ControllerPoseReferenceUsesThumbUpAxesPerHand) {
  const Pose T_local_view{Quat::Identity(), Vec3::Zero()};
  const Quat R_device_wrist_true = axis_angle(Vec3(1.0, 0.4, -0.3), 0.8);
  for (Handedness hand : {Handedness::left, Handedness::right}) {
    const Vec3 y = hand == Handedness::right ? Vec3(1, 0, 0) : Vec3(-1, 0, 0);
    const Vec3 z(0, 0, 1);
    const Pose T_local_wrist{from_axes(y.cross(z), y, z), Vec3(0.2, -0.3, -0.25)};
    // The thumb (the wrist's -X for the right hand, +X for the left) points up.
    const Vec3 thumb = T_local_wrist.q * Vec3(hand == Handedness::right ? -1.0 : 1.0, 0.0, 0.0);
    EXPECT_NEAR(thumb.y(), 1.0, 1e-12);
    Pose T_local_device;
    T_local_device.q = T_local_wrist.q * R_device_wrist_true.conjugate();
    T_local_device.p = T_local_wrist.p + Vec3(0.0, 0.0, -0.08);  // the grip 8 cm ahead of the wrist
    const Pose expected = T_local_device.inverse() * T_local_wrist;

    auto r = solve_wrist_calibration(still_window(T_local_device, T_local_view, 2.0),
                                     options_for(WristDevice::controller, hand));
    ASSERT_TRUE(r) << r.error().message;
    EXPECT_LT(angle_deg(r->T_device_wrist.q, expected.q), 1e-6) << to_string(hand);
    EXPECT_LT((r->T_device_wrist.p - expected.p).norm(), 1e-9) << to_string(hand);
  }
}

// The answer is a property of the hand and the device, not of where in the
// room the user stands or looks: a yaw of the whole scene changes nothing.
TEST(WristCalibration, PoseReferenceIsInvariantToTurningTheWholeScene) {
  const Pose T_local_view{axis_angle(Vec3(0.1, 1.0, 0.0), 0.3), Vec3(0, 0, 0)};
  const Pose T_local_device{axis_angle(Vec3(0.5, -0.2, 1.0), 2.0), Vec3(0.1, -0.4, -0.3)};
  auto o = options_for(WristDevice::controller, Handedness::right);
  auto a = solve_wrist_calibration(still_window(T_local_device, T_local_view, 2.0), o);
  const Pose turn{yaw(1.9), Vec3(0.5, 0.0, -0.7)};
  auto b = solve_wrist_calibration(still_window(turn * T_local_device, turn * T_local_view, 2.0), o);
  ASSERT_TRUE(a && b);
  EXPECT_LT(angle_deg(a->T_device_wrist.q, b->T_device_wrist.q), 1e-6);
  EXPECT_LT((a->T_device_wrist.p - b->T_device_wrist.p).norm(), 1e-9);
}

TEST(WristCalibration, NoiseAveragesOut) {
  const Pose T_local_view{yaw(0.4), Vec3::Zero()};
  const Pose T_local_wrist{yaw(0.4), Vec3(0.1, -0.3, -0.3)};
  const Quat R_dw = axis_angle(Vec3(0, 0, 1), 0.5);
  const Pose T_local_device{T_local_wrist.q * R_dw.conjugate(), T_local_wrist.p + Vec3(0, 0.03, 0)};
  const Pose expected = T_local_device.inverse() * T_local_wrist;
  // 1 mm and 0.5 deg per sample, 181 samples: the mean's rotation error is
  // about 0.5 / sqrt(181) * sqrt(3) = 0.06 deg.
  auto r = solve_wrist_calibration(still_window(T_local_device, T_local_view, 2.0, 0.001, 0.5),
                                   options_for(WristDevice::tracker, Handedness::right));
  ASSERT_TRUE(r);
  EXPECT_LT(angle_deg(r->T_device_wrist.q, expected.q), 0.2);
  EXPECT_LT((r->T_device_wrist.p - expected.p).norm(), 0.002);
}

// The runtime's wrist joint rigidly on the device, the device moving about:
// the offset is the mean of the per-frame offsets, whatever the motion.
TEST(WristCalibration, RuntimeHandReferenceAveragesThePerFrameOffset) {
  const Pose T_device_wrist{axis_angle(Vec3(0, 1, 0), -M_PI / 2), Vec3(0.02, -0.035, 0.0)};
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<WristSample> window;
  for (int i = 0; i <= 180; ++i) {
    const double t = i / 90.0;
    WristSample s;
    s.t_s = t;
    s.T_local_device = {axis_angle(Vec3(0.3, 1.0, 0.1), 0.5 * std::sin(t)), Vec3(0.2 + 0.05 * t, -0.3, -0.3)};
    s.T_local_view = Pose{};
    // 2 mm and 1 deg of hand-tracking noise per frame.
    Pose wrist = s.T_local_device * T_device_wrist;
    wrist.q = (wrist.q * so3_exp(Vec3(n(rng), n(rng), n(rng)) * (M_PI / 180.0))).normalized();
    wrist.p += Vec3(n(rng), n(rng), n(rng)) * 0.002;
    s.T_local_wrist = wrist;
    window.push_back(s);
  }
  auto r = solve_wrist_calibration(window,
                                   options_for(WristDevice::tracker, Handedness::right, WristReference::runtime_hand));
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_LT(angle_deg(r->T_device_wrist.q, T_device_wrist.q), 0.3);
  EXPECT_LT((r->T_device_wrist.p - T_device_wrist.p).norm(), 0.001);
  EXPECT_TRUE(r->assumed.empty());
  // The scatter it reports is the noise put in: sqrt(3) * 2 mm and sqrt(3) * 1 deg.
  EXPECT_NEAR(r->offset_position_rms_m, 0.0035, 0.0008);
  EXPECT_NEAR(r->offset_rotation_rms_deg, 1.7, 0.4);

  window[50].T_local_wrist.reset();
  EXPECT_FALSE(solve_wrist_calibration(
      window, options_for(WristDevice::tracker, Handedness::right, WristReference::runtime_hand)));
}

TEST(WristCalibration, LookingStraightDownHasNoAheadAndIsRefused) {
  const Pose down{axis_angle(Vec3::UnitX(), -M_PI / 2 + 0.05), Vec3::Zero()};
  auto r =
      solve_wrist_calibration(still_window(Pose{}, down, 1.0), options_for(WristDevice::tracker, Handedness::left));
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("look ahead"), std::string::npos) << r.error().message;
  EXPECT_FALSE(
      solve_wrist_calibration(std::vector<WristSample>(2), options_for(WristDevice::tracker, Handedness::left)));
}

TEST(WristStillness, MeasuresSpeedAndSpreadsOfTheWindow) {
  const Pose device{yaw(0.3), Vec3(0.1, -0.3, -0.3)};
  auto still = still_window(device, Pose{}, 2.0, 0.0005, 0.05);
  const Stillness s = measure_stillness(still);
  EXPECT_TRUE(s.exceeded(StillnessLimits{}).empty()) << s.exceeded(StillnessLimits{});
  EXPECT_LT(s.position_spread_m, 0.003);
  EXPECT_GT(s.position_spread_m, 0.0);

  // Turning steadily at 20 deg/s about the vertical.
  auto turning = still_window(device, Pose{}, 2.0);
  for (auto& w : turning) w.T_local_device.q = yaw(20.0 * M_PI / 180.0 * (w.t_s - 10.0)) * device.q;
  const Stillness t = measure_stillness(turning);
  EXPECT_NEAR(t.peak_angular_speed_deg_s, 20.0, 0.01);
  EXPECT_NEAR(t.rotation_spread_deg, 20.0, 0.1);  // +-20 deg about the mean of a 40 deg sweep
  EXPECT_NE(t.exceeded(StillnessLimits{}).find("turning at 20.0 deg/s"), std::string::npos)
      << t.exceeded(StillnessLimits{});

  // Drifting 3 cm in 2 s: slow, but too far.
  auto drifting = still_window(device, Pose{}, 2.0);
  for (auto& w : drifting) w.T_local_device.p.x() += 0.015 * (w.t_s - 10.0);
  const Stillness d = measure_stillness(drifting);
  EXPECT_NEAR(d.position_spread_m, 0.015, 1e-9);
  EXPECT_EQ(d.peak_angular_speed_deg_s, 0.0);
  EXPECT_NE(d.exceeded(StillnessLimits{}).find("moved 15.0 mm"), std::string::npos);

  StillnessLimits loose;
  loose.max_angular_speed_deg_s = 30.0;
  loose.max_rotation_spread_deg = 30.0;
  loose.max_position_spread_m = 0.02;
  EXPECT_TRUE(t.exceeded(loose).empty());
  EXPECT_TRUE(d.exceeded(loose).empty());
}

// ---- the state machine ----

struct Recorder {
  std::vector<WristCalibrationEvent> events;
  template <typename T>
  int count() const {
    int n = 0;
    for (const auto& e : events) n += std::holds_alternative<T>(e) ? 1 : 0;
    return n;
  }
};

WristCalibrationOptions machine_options() {
  auto o = options_for(WristDevice::tracker, Handedness::right);
  o.countdown_s = 3.0;
  o.seconds = 2.0;
  o.timeout_s = 8.0;
  return o;
}

WristSample still_sample(double t, Vec3 p = Vec3(0.1, -0.3, -0.3)) {
  WristSample s;
  s.t_s = t;
  s.T_local_device = {yaw(0.2), p};
  return s;
}

TEST(WristCalibrator, CountsDownThenFinishesAfterTheWindowHeldStill) {
  Recorder rec;
  WristCalibrator c(machine_options(), [&](const WristCalibrationEvent& e) { rec.events.push_back(e); });
  // Frame i at 100 + i / 90 s: the countdown covers frames 0 to 269.
  int i = 0;
  auto t_of = [](int frame) { return 100.0 + frame / 90.0; };
  for (; i < 270; ++i) ASSERT_TRUE(c.feed(t_of(i), nullptr, "not tracked during the countdown"));
  EXPECT_EQ(rec.count<WristCalibrationCountdown>(), 3);
  EXPECT_EQ(std::get<WristCalibrationCountdown>(rec.events.front()).seconds_left, 3);
  EXPECT_EQ(rec.count<WristCalibrationMeasuring>(), 0);
  EXPECT_EQ(rec.count<WristCalibrationWaiting>(), 0);  // not tracked during the countdown is not reported
  ASSERT_TRUE(c.feed(t_of(i++), nullptr, "not tracked"));
  EXPECT_EQ(rec.count<WristCalibrationMeasuring>(), 1);
  EXPECT_EQ(rec.count<WristCalibrationWaiting>(), 1);
  double t = t_of(i);
  const double start = t;
  bool running = true;
  while (running && t < start + 5.0) {
    WristSample s = still_sample(t);
    running = c.feed(t, &s);
    t = t_of(++i);
  }
  ASSERT_TRUE(c.finished());
  ASSERT_TRUE(*c.outcome()) << c.outcome()->error().message;
  EXPECT_NEAR(t - start, 2.0, 0.03);  // the window, not more
  EXPECT_NEAR((*c.outcome())->window_s, 2.0, 0.012);
  EXPECT_GE(rec.count<WristCalibrationHolding>(), 3);
  EXPECT_EQ(rec.count<WristCalibrationMoved>(), 0);
  EXPECT_FALSE(c.feed(t, nullptr, "done"));
}

TEST(WristCalibrator, AMoveStartsTheWindowAgain) {
  auto o = machine_options();
  o.countdown_s = 0.0;
  Recorder rec;
  WristCalibrator c(o, [&](const WristCalibrationEvent& e) { rec.events.push_back(e); });
  double t = 0.0;
  bool running = true;
  double moved_until = 1.5;
  while (running && t < 10.0) {
    // Still for 1.5 s, a 5 cm jump, then still again.
    WristSample s = still_sample(t, Vec3(t < moved_until ? 0.1 : 0.15, -0.3, -0.3));
    running = c.feed(t, &s);
    t += 1.0 / 90.0;
  }
  ASSERT_TRUE(c.finished());
  ASSERT_TRUE(*c.outcome());
  EXPECT_EQ(rec.count<WristCalibrationMoved>(), 1);
  EXPECT_NEAR(t, 1.5 + 2.0, 0.05);  // a full window after the jump
  // Only poses after the jump were averaged.
  EXPECT_NEAR((*c.outcome())->stillness.position_spread_m, 0.0, 1e-12);
}

TEST(WristCalibrator, ANeverTrackedDeviceTimesOutSayingSo) {
  auto o = machine_options();
  o.countdown_s = 0.0;
  o.timeout_s = 1.0;
  WristCalibrator c(o, nullptr);
  double t = 0.0;
  while (c.feed(t, nullptr, "no pose from the tracker") && t < 5.0) t += 1.0 / 90.0;
  ASSERT_TRUE(c.finished());
  ASSERT_FALSE(*c.outcome());
  EXPECT_NEAR(t, 1.0, 0.02);
  const std::string& m = c.outcome()->error().message;
  EXPECT_NE(m.find("never became tracked within the 1 s timeout"), std::string::npos) << m;
  EXPECT_NE(m.find("right_wrist"), std::string::npos) << m;
}

TEST(WristCalibrator, AlwaysMovingTimesOutWithTheLongestStillStretch) {
  auto o = machine_options();
  o.countdown_s = 0.0;
  o.timeout_s = 3.0;
  Recorder rec;
  WristCalibrator c(o, [&](const WristCalibrationEvent& e) { rec.events.push_back(e); });
  double t = 0.0;
  bool running = true;
  while (running && t < 10.0) {
    WristSample s = still_sample(t);
    s.T_local_device.q = yaw(0.5 * t);  // 28.6 deg/s
    running = c.feed(t, &s);
    t += 1.0 / 90.0;
  }
  ASSERT_TRUE(c.finished());
  ASSERT_FALSE(*c.outcome());
  const std::string& m = c.outcome()->error().message;
  EXPECT_NE(m.find("not held still for 2 s within the 3 s timeout"), std::string::npos) << m;
  EXPECT_NE(m.find("turning at 28.6 deg/s"), std::string::npos) << m;
  // Reported at most once a second.
  EXPECT_GE(rec.count<WristCalibrationMoved>(), 3);
  EXPECT_LE(rec.count<WristCalibrationMoved>(), 4);
}

TEST(WristCalibrator, LosingTrackingMidWindowStartsItAgain) {
  auto o = machine_options();
  o.countdown_s = 0.0;
  WristCalibrator c(o, nullptr);
  // Frame i at i / 90 s; frames 91 to 107 (1.0 to 1.2 s) not tracked.
  int i = 0;
  for (bool running = true; running && i < 900; ++i) {
    WristSample s = still_sample(i / 90.0);
    running = (i > 90 && i < 108) ? c.feed(i / 90.0, nullptr, "lost") : c.feed(i / 90.0, &s);
  }
  ASSERT_TRUE(c.finished() && *c.outcome());
  EXPECT_NEAR(i - 1, 108 + 180, 1);  // the last frame fed: a whole window after tracking came back
}

TEST(WristCalibrationOptions, RefusesWhatCannotWork) {
  WristCalibrationOptions o;
  EXPECT_TRUE(o.validate());
  EXPECT_EQ(o.role(), "right_wrist");
  EXPECT_EQ(o.device_path(), "/user/vive_tracker_htcx/role/right_wrist");
  o.hand = Handedness::left;
  o.device = WristDevice::controller;
  EXPECT_EQ(o.device_path(), "/user/hand/left");
  o.tracker_role = "left_wrist";
  EXPECT_FALSE(o.validate());  // a role with a controller
  o.device = WristDevice::tracker;
  EXPECT_TRUE(o.validate());
  o.tracker_role = "left_wirst";
  EXPECT_FALSE(o.validate());
  o.tracker_role.clear();
  for (double bad : {std::nan(""), 0.1, 31.0}) {
    auto b = o;
    b.seconds = bad;
    EXPECT_FALSE(b.validate()) << bad;
  }
  auto b = o;
  b.timeout_s = 1.0;  // shorter than the window
  EXPECT_FALSE(b.validate());
  b = o;
  b.still.max_position_spread_m = INFINITY;
  EXPECT_FALSE(b.validate());
  b = o;
  b.wrist_behind_grip_m = -0.01;
  EXPECT_FALSE(b.validate());
}

}  // namespace wrist_calibration_test
}  // namespace proprio::engine
