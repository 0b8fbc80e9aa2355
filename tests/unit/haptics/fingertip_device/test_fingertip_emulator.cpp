// The fingertip device emulator, offline and in device time (no wall clock
// anywhere): the closed-loop step response against the PD prediction from the
// motor parameters, force rendering on the default fingertip spring, the
// watchdog, clamping, the ramp-in, faults, determinism, and the fuzz seeds.
//
// The numbers quoted in docs/fingertip-hid-protocol.md §8 are what these tests
// print (look for "measured:" in the output).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "proprio/fingertip_device/fingertip_emulator.hpp"

namespace proprio::devices {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;
constexpr TimeNs kMs = kNsPerMillisecond;

FingertipPlant free_shaft() {
  return [](const std::array<double, kFingertipMaxMotors>&) { return FingertipPlantLoad{}; };
}

// No noise and no ramp: the raw closed loop.
FingertipEmulatorOptions bare_options() {
  FingertipEmulatorOptions o;
  o.fsr_noise_n = 0.0;
  o.safety.ramp_ns = 0;
  return o;
}

FingertipEmulator make(const FingertipEmulatorOptions& o, FingertipPlant plant = {}) {
  auto e = FingertipEmulator::create(o, std::move(plant));
  EXPECT_TRUE(e.ok()) << (e.ok() ? "" : e.error().message);
  return std::move(e).value();
}

// The host's side of the command stream.
struct Host {
  std::uint16_t sequence = 1;
  bool first = true;

  Bytes encode(FingertipMode mode, std::array<double, 3> values, bool enable = true, std::uint8_t flags = 0,
               std::uint8_t count = 3) {
    FingertipCommand c;
    c.sequence = sequence++;
    c.mode = mode;
    c.flags = static_cast<std::uint8_t>(flags | (enable ? fingertip_command_flags::enable : 0) |
                                        (first ? fingertip_command_flags::sequence_reset : 0));
    first = false;
    c.count = count;
    const double scale = mode == FingertipMode::force ? kFingertipMnPerN : kFingertipUradPerRad;
    for (std::size_t i = 0; i < 3; ++i) { EXPECT_TRUE(fingertip_to_wire(values[i], scale, c.values[i])); }
    c.host_time_ns = 1000 + c.sequence;
    const auto b = encode_fingertip_command(c);
    return {b.begin(), b.end()};
  }
  FingertipCommandResult send(FingertipEmulator& e, TimeNs t, FingertipMode mode, std::array<double, 3> values,
                              bool enable = true, std::uint8_t flags = 0) {
    e.advance_to(t - 1);
    return e.handle_command(encode(mode, values, enable, flags), t);
  }
};

// Runs to end_ns, repeating the command every period_ns (so the watchdog
// stays fed), and records one motor's output angle and force reading per tick.
struct Trace {
  std::vector<TimeNs> t;
  std::vector<double> angle;   // true output angle of the motor
  std::vector<double> force;   // true force on its axis
  std::vector<double> target;  // controller target
};
Trace run_commanded(FingertipEmulator& e, Host& host, FingertipMode mode, std::array<double, 3> values,
                    TimeNs end_ns, std::size_t motor = 0, TimeNs period_ns = 10 * kMs) {
  Trace tr;
  const TimeNs dt = e.control_period_ns();
  for (TimeNs t = e.now_ns() == 0 && e.stats().ticks == 0 ? 0 : e.now_ns() + dt; t <= end_ns; t += dt) {
    if (t % period_ns == 0) { EXPECT_EQ(host.send(e, t, mode, values), FingertipCommandResult::ok); }
    e.advance_to(t);
    tr.t.push_back(t);
    tr.angle.push_back(e.snapshot().motors[motor].output_angle_rad);
    tr.force.push_back(e.snapshot().fsr_force_n[motor]);
    tr.target.push_back(e.snapshot().motors[motor].target_output_rad);
  }
  return tr;
}

struct StepMetrics {
  double peak = 0.0;
  double overshoot = 0.0;  // fraction of the step
  double final_value = 0.0;
  double settling_s = 0.0;  // last time outside the band, + one tick
};
StepMetrics step_metrics(const std::vector<TimeNs>& t, const std::vector<double>& y, double start_ns, double goal,
                         double band) {
  StepMetrics m;
  m.peak = *std::max_element(y.begin(), y.end());
  m.overshoot = std::max(0.0, (m.peak - goal) / goal);
  m.final_value = y.back();
  double last_out = start_ns;
  for (std::size_t i = 0; i < y.size(); ++i) {
    if (std::abs(y[i] - goal) > band * std::abs(goal)) last_out = static_cast<double>(t[i]);
  }
  m.settling_s = (last_out - start_ns) * 1e-9;
  return m;
}

TEST(FingertipEmulatorOptions, DefaultsAreValidDescribeThemselvesAndBadOnesAreNamed) {
  FingertipEmulatorOptions o;
  ASSERT_TRUE(o.validate().ok());
  const std::string text = o.describe();
  EXPECT_NE(text.find("force_vector"), std::string::npos) << text;
  EXPECT_NE(text.find("kp"), std::string::npos) << text;
  EXPECT_NE(text.find("watchdog 50 ms"), std::string::npos) << text;
  EXPECT_FALSE(FingertipServeOptions{}.describe().empty());

  auto expect_bad = [](FingertipEmulatorOptions bad, const char* field) {
    const Status s = bad.validate();
    ASSERT_FALSE(s.ok()) << field;
    EXPECT_NE(s.error().message.find(field), std::string::npos) << s.error().message;
    EXPECT_FALSE(FingertipEmulator::create(bad).ok());
  };
  FingertipEmulatorOptions b = o;
  b.motor_count = 4;
  expect_bad(b, "motor_count");
  b = o;
  b.safety.watchdog_ns = 0;
  expect_bad(b, "safety.watchdog_ns");
  b = o;
  b.motor.resistance_ohm = -1.0;
  expect_bad(b, "motor.resistance_ohm");
  b = o;
  b.feedback_rate_hz = 300;  // does not divide 1000
  expect_bad(b, "feedback_rate_hz");
  b = o;
  b.serial = "a serial number far too long";
  expect_bad(b, "serial");
  b = o;
  b.safety.min_angle_rad = 0.1;  // rest (0) outside the limits
  expect_bad(b, "safety.min_angle_rad");
  b = o;
  b.motor.overcurrent_trip_a = 0.5;  // below the current limit
  expect_bad(b, "motor.overcurrent_trip_a");
}

TEST(FingertipEmulatorOptions, DefaultGainsAreTheDesignFor60HzAndDamping08) {
  const FingertipEmulatorOptions o;
  const FingertipControllerGains g = design_fingertip_gains(o.motor, 60.0, 0.8);
  EXPECT_DOUBLE_EQ(o.gains.kp_v_per_rad, g.kp_v_per_rad);
  EXPECT_DOUBLE_EQ(o.gains.kd_v_s_per_rad, g.kd_v_s_per_rad);
  // By hand: J = 7e-9 + 2e-7/256 kg·m², wn = 2π·60 rad/s.
  const double j = 7e-9 + 2e-7 / 256.0;
  const double wn = 2.0 * M_PI * 60.0;
  EXPECT_NEAR(g.kp_v_per_rad, wn * wn * 6.0 * j / 4.3e-3, 1e-12);
  const FingertipStepPrediction p = predict_fingertip_step(o.motor, g);
  EXPECT_NEAR(p.natural_frequency_rad_s, wn, 1e-6 * wn);
  EXPECT_NEAR(p.damping_ratio, 0.8, 1e-9);
  EXPECT_NEAR(p.overshoot, std::exp(-M_PI * 0.8 / 0.6), 1e-12);
  EXPECT_DOUBLE_EQ(p.steady_state_fraction, 1.0);
  // A spring on the output adds stiffness: faster, less damped, short of the target.
  const FingertipStepPrediction loaded = predict_fingertip_step(o.motor, g, FingertipSpringPlantOptions{}.shaft_stiffness_nm_per_rad(0));
  EXPECT_GT(loaded.natural_frequency_rad_s, p.natural_frequency_rad_s);
  EXPECT_LT(loaded.damping_ratio, p.damping_ratio);
  EXPECT_LT(loaded.steady_state_fraction, 0.95);
  std::printf("measured: PD prediction free shaft: %s\n", p.describe().c_str());
  std::printf("measured: PD prediction on the normal spring: %s\n", loaded.describe().c_str());
}

TEST(FingertipEmulator, InfoReportSaysWhatTheOptionsSay) {
  FingertipEmulatorOptions o;
  o.kind = FingertipDeviceKind::band_2dof;
  o.motor_count = 2;
  o.fsr_count = 1;
  o.hand = Handedness::left;
  o.finger = Finger::middle;
  o.serial = "LEFT-MIDDLE-2";
  o.control_rate_hz = 2000;
  o.feedback_rate_hz = 1000;
  FingertipEmulator e = make(o);
  auto info = decode_fingertip_info(e.info_report());
  ASSERT_TRUE(info.ok()) << info.error().message;
  EXPECT_EQ(info->kind, FingertipDeviceKind::band_2dof);
  EXPECT_EQ(info->motor_count, 2);
  EXPECT_EQ(info->fsr_count, 1);
  EXPECT_EQ(info->hand, Handedness::left);
  EXPECT_EQ(info->finger, Finger::middle);
  EXPECT_EQ(info->serial_view(), "LEFT-MIDDLE-2");
  EXPECT_EQ(info->control_rate_hz, 2000);
  EXPECT_EQ(info->gear_ratio_milli, 16000u);
  EXPECT_EQ(info->encoder_counts_per_rev, 1024u);
  EXPECT_EQ(info->watchdog_ms, 50);
  EXPECT_EQ(info->max_normal_force_mn, 2000u);
  EXPECT_EQ(info->max_angle_urad, 1'000'000);
  EXPECT_EQ(info->max_current_ma, 600);
  // Feedback every second tick of the 2 kHz loop.
  std::vector<FingertipEmulatedReport> out;
  e.advance_to(10 * kMs, out);
  ASSERT_EQ(out.size(), 11u);  // 0, 1, ..., 10 ms
  EXPECT_EQ(out[1].send_ns, kMs);
  EXPECT_EQ(e.stats().ticks, 21u);
}

TEST(FingertipEmulator, PdStepReachesTheTargetWithinThePredictedSettlingTime) {
  FingertipEmulatorOptions o = bare_options();
  o.gains.ki_v_per_rad_s = 0.0;  // the pure PD the prediction is for
  FingertipEmulator e = make(o, free_shaft());
  Host host;
  const double goal = 0.1;  // rad at the output: 1.6 rad at the motor, within the current limit
  const Trace tr = run_commanded(e, host, FingertipMode::motor_angles, {goal, 0, 0}, 200 * kMs);
  const StepMetrics m = step_metrics(tr.t, tr.angle, 0, goal, 0.02);
  const FingertipStepPrediction p = predict_fingertip_step(o.motor, o.gains);
  std::printf("measured: PD step 0.1 rad, free shaft: overshoot %.2f %% (predicted %.2f %%), 2 %% settling %.1f ms "
              "(predicted %.1f ms), final %.5f rad\n",
              m.overshoot * 100, p.overshoot * 100, m.settling_s * 1e3, p.settling_time_s * 1e3, m.final_value);
  // Sampling at 1 kHz and differencing the encoder add a little phase lag:
  // allow one percentage point above the continuous prediction, but the
  // response must be the underdamped one predicted, not a sluggish one.
  EXPECT_LE(m.overshoot, p.overshoot + 0.01);
  EXPECT_GE(m.overshoot, 0.5 * p.overshoot);
  EXPECT_LE(m.settling_s, p.settling_time_s);
  const double count = 2.0 * M_PI / (1024.0 * 16.0);
  EXPECT_NEAR(m.final_value, goal, 2.0 * count);
  // Nothing else moved.
  EXPECT_EQ(e.snapshot().motors[1].encoder_counts, 0);
}

TEST(FingertipEmulator, DefaultControllerSettlesStepsWithLittleOvershoot) {
  for (const double goal : {0.1, 1.0}) {
    SCOPED_TRACE(goal);
    FingertipEmulator e = make(bare_options(), free_shaft());
    Host host;
    const Trace tr = run_commanded(e, host, FingertipMode::motor_angles, {goal, 0, 0}, 200 * kMs);
    const StepMetrics m = step_metrics(tr.t, tr.angle, 0, goal, 0.02);
    std::printf("measured: default gains, step %.1f rad, free shaft: overshoot %.2f %%, 2 %% settling %.1f ms\n", goal,
                m.overshoot * 100, m.settling_s * 1e3);
    // docs §8: steps settle to 2 % within 25 ms with at most 3 % overshoot.
    EXPECT_LE(m.overshoot, 0.03);
    EXPECT_LE(m.settling_s, 0.025);
  }
}

TEST(FingertipEmulator, ForceModeRendersOneNewtonOnTheDefaultSpring) {
  FingertipEmulatorOptions o = bare_options();
  o.fsr_noise_n = 0.002;
  FingertipEmulator e = make(o);
  Host host;
  std::vector<FingertipEmulatedReport> reports;
  const TimeNs dt = e.control_period_ns();
  std::vector<TimeNs> t;
  std::vector<double> reported;
  for (TimeNs now = 0; now <= 200 * kMs; now += dt) {
    if (now % (10 * kMs) == 0) { ASSERT_EQ(host.send(e, now, FingertipMode::force, {1.0, 0, 0}), FingertipCommandResult::ok); }
    reports.clear();
    e.advance_to(now, reports);
    ASSERT_EQ(reports.size(), 1u);
    auto f = decode_fingertip_feedback(reports[0].bytes);
    ASSERT_TRUE(f.ok()) << f.error().message;
    t.push_back(now);
    reported.push_back(f->fsr_force_mn[0] / 1000.0);
    EXPECT_EQ(f->mode, FingertipMode::force);
    EXPECT_TRUE(f->has(fingertip_status::enabled));
  }
  const StepMetrics m = step_metrics(t, reported, 0, 1.0, 0.05);
  std::printf("measured: force mode 1 N normal on the default spring: reported force within 5 %% after %.1f ms, "
              "peak %.3f N, final %.4f N\n",
              m.settling_s * 1e3, m.peak, m.final_value);
  // docs §8: within 5 % after 30 ms at most, and it stays there.
  EXPECT_LE(m.settling_s, 0.030);
  EXPECT_NEAR(m.final_value, 1.0, 0.05);
  EXPECT_LE(m.peak, 1.05);
  // Shear axes stay where they were.
  EXPECT_NEAR(e.snapshot().fsr_force_n[1], 0.0, 0.01);
  EXPECT_NEAR(e.snapshot().fsr_force_n[2], 0.0, 0.01);
}

// A latched fault opens the bridges and the moving motors coast down
// geometrically; the emulator must land on exact zeros, not crawl through
// subnormal numbers (x86 runs those ~100x slower: 5% of a simulated trial).
TEST(FingertipEmulator, ACoastingMotorSettlesToExactZerosNotSubnormals) {
  FingertipEmulator e = make(bare_options());
  Host host;
  run_commanded(e, host, FingertipMode::force, {1.0, 0.3, 0}, 100 * kMs);
  e.inject_fault(FingertipInjectedFault::encoder_loss, 0);
  int subnormal = 0;
  // The viscous decay takes minutes of device time to reach 1e-308.
  for (TimeNs t = e.now_ns() + kMs; t <= 600'000 * kMs; t += kMs) {
    e.advance_to(t);
    for (const FingertipMotorTruth& m : e.snapshot().motors) {
      subnormal += std::fpclassify(m.current_a) == FP_SUBNORMAL;
      subnormal += std::fpclassify(m.output_velocity_rad_s) == FP_SUBNORMAL;
    }
  }
  EXPECT_FALSE(e.snapshot().motors[1].bridge_on) << "the fault latched";
  EXPECT_EQ(subnormal, 0);
}

TEST(FingertipEmulator, SkipToStallsTheFirmwareWithoutRunningTheMissedTicks) {
  FingertipEmulator e = make(bare_options());
  Host host;
  run_commanded(e, host, FingertipMode::force, {1.0, 0.3, 0}, 30 * kMs);
  const FingertipEmulatorSnapshot before = e.snapshot();
  const FingertipEmulatorStats stats_before = e.stats();
  e.skip_to(e.now_ns());
  EXPECT_EQ(e.stats().stalls, 0u) << "nothing was due";

  e.skip_to(530 * kMs);
  EXPECT_EQ(e.stats().stalls, 1u);
  EXPECT_EQ(e.stats().stalled_ticks, 499u) << "the ticks at 31..529 ms";
  EXPECT_EQ(e.stats().ticks, stats_before.ticks);
  EXPECT_EQ(e.stats().feedback_sent, stats_before.feedback_sent);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(e.snapshot().motors[i].output_angle_rad, before.motors[i].output_angle_rad) << "motor " << i;
  }

  std::vector<FingertipEmulatedReport> out;
  e.advance_to(530 * kMs, out);
  ASSERT_EQ(out.size(), 1u);
  auto f = decode_fingertip_feedback(out[0].bytes);
  ASSERT_TRUE(f.ok());
  EXPECT_EQ(f->device_time_us, 530'000u);
  // One control period integrated, not the 500 ms gap: the pad barely moved.
  EXPECT_NEAR(e.snapshot().motors[0].output_angle_rad, before.motors[0].output_angle_rad, 0.01);
  // No command for 500 ms of device time: the watchdog trips, as a stalled device's would.
  EXPECT_TRUE(e.snapshot().status & fingertip_status::watchdog_tripped);
}

TEST(FingertipEmulator, WatchdogReturnsToRestFiftyMillisecondsAfterTheLastCommand) {
  FingertipEmulator e = make(bare_options());
  Host host;
  // Fed until 100 ms, then silence: the last command arrives at 100 ms.
  run_commanded(e, host, FingertipMode::force, {1.0, 0.3, 0}, 100 * kMs);
  ASSERT_NEAR(e.snapshot().fsr_force_n[0], 1.0, 0.05);
  const TimeNs last = e.snapshot().last_valid_command_ns;
  ASSERT_EQ(last, 100 * kMs);
  TimeNs trip = -1;
  TimeNs below = -1;
  std::vector<FingertipEmulatedReport> out;
  for (TimeNs t = e.now_ns() + kMs; t <= 300 * kMs; t += kMs) {
    out.clear();
    e.advance_to(t, out);
    const FingertipEmulatorSnapshot& s = e.snapshot();
    if (trip < 0 && (s.status & fingertip_status::watchdog_tripped)) {
      trip = t;
      // At that very tick: not enabled, targets at rest, and the feedback says so.
      EXPECT_FALSE(s.status & fingertip_status::enabled);
      EXPECT_EQ(s.mode, FingertipMode::idle);
      for (std::size_t i = 0; i < 3; ++i) { EXPECT_EQ(s.motors[i].target_output_rad, 0.0); }
      auto f = decode_fingertip_feedback(out.at(0).bytes);
      ASSERT_TRUE(f.ok());
      EXPECT_TRUE(f->has(fingertip_status::watchdog_tripped));
      EXPECT_FALSE(f->has(fingertip_status::enabled));
    }
    if (trip < 0) {
      EXPECT_TRUE(s.status & fingertip_status::enabled) << "tripped early at " << t;
    }
    if (trip >= 0 && below < 0 && std::abs(s.fsr_force_n[0]) < 0.05 && std::abs(s.fsr_force_n[1]) < 0.05) below = t;
  }
  ASSERT_GE(trip, 0) << "the watchdog never tripped";
  EXPECT_EQ(trip - last, 50 * kMs);
  EXPECT_EQ(e.snapshot().watchdog_trip_ns, trip);
  EXPECT_EQ(e.stats().watchdog_trips, 1u);
  ASSERT_GE(below, 0);
  std::printf("measured: watchdog tripped %.1f ms after the last command; force below 50 mN %.1f ms after the trip\n",
              (trip - last) / 1e6, (below - trip) / 1e6);
  // docs §6: the force is gone (below 5 % of 1 N) within 20 ms of the trip.
  EXPECT_LE(below - trip, 20 * kMs);
}

TEST(FingertipEmulator, WatchdogCountsFromWhenTheCommandArrivedNotFromTheTick) {
  FingertipEmulator e = make(bare_options());
  Host host;
  e.advance_to(10 * kMs);
  const TimeNs arrival = 10 * kMs + 300'000;  // between two ticks
  ASSERT_EQ(e.handle_command(host.encode(FingertipMode::force, {0.5, 0, 0}), arrival), FingertipCommandResult::ok);
  TimeNs trip = -1;
  for (TimeNs t = 11 * kMs; t <= 100 * kMs && trip < 0; t += kMs) {
    e.advance_to(t);
    if (e.snapshot().status & fingertip_status::watchdog_tripped) trip = t;
  }
  ASSERT_GE(trip, 0);
  EXPECT_GE(trip - arrival, 50 * kMs);
  EXPECT_LT(trip - arrival, 51 * kMs);  // the first tick at or after 50 ms
}

TEST(FingertipEmulator, AFedWatchdogNeverTripsAndATrippedOneReEnablesWithARamp) {
  FingertipEmulatorOptions o = bare_options();
  o.safety.ramp_ns = 100 * kMs;
  FingertipEmulator e = make(o);
  Host host;
  run_commanded(e, host, FingertipMode::force, {0.5, 0, 0}, 400 * kMs, 0, 45 * kMs);
  EXPECT_EQ(e.stats().watchdog_trips, 0u);
  e.advance_to(500 * kMs);
  EXPECT_TRUE(e.snapshot().status & fingertip_status::watchdog_tripped);
  ASSERT_EQ(host.send(e, 501 * kMs, FingertipMode::force, {0.5, 0, 0}), FingertipCommandResult::ok);
  e.advance_to(501 * kMs);
  EXPECT_FALSE(e.snapshot().status & fingertip_status::watchdog_tripped);
  EXPECT_TRUE(e.snapshot().status & fingertip_status::enabled);
  EXPECT_TRUE(e.snapshot().status & fingertip_status::ramping);
  EXPECT_EQ(e.snapshot().ramp, 0.0);
}

TEST(FingertipEmulator, RampsInOverTheRampTimeAfterEnable) {
  FingertipEmulatorOptions o = bare_options();
  o.safety.ramp_ns = 100 * kMs;
  FingertipEmulator e = make(o, free_shaft());
  Host host;
  const double goal = 0.4;
  std::vector<FingertipEmulatedReport> out;
  for (TimeNs t = 0; t <= 150 * kMs; t += kMs) {
    if (t % (10 * kMs) == 0) { ASSERT_EQ(host.send(e, t, FingertipMode::motor_angles, {goal, 0, 0}), FingertipCommandResult::ok); }
    out.clear();
    e.advance_to(t, out);
    const FingertipEmulatorSnapshot& s = e.snapshot();
    const double expected_ramp = std::min(1.0, static_cast<double>(t) / (100.0 * kMs));
    ASSERT_NEAR(s.ramp, expected_ramp, 1e-9) << t;
    ASSERT_NEAR(s.motors[0].target_output_rad, expected_ramp * goal, 1e-9) << t;
    auto f = decode_fingertip_feedback(out.at(0).bytes);
    ASSERT_TRUE(f.ok());
    EXPECT_EQ(f->ramp_permille, std::lround(expected_ramp * 1000.0));
    EXPECT_EQ(f->has(fingertip_status::ramping), t < 100 * kMs) << t;
  }
  // Force mode ramps the force, not just the angle: halfway, half the force.
  FingertipEmulator fe = make(o);
  Host fh;
  run_commanded(fe, fh, FingertipMode::force, {1.0, 0, 0}, 50 * kMs);
  const double half_angle = make_spring_force_to_angles()(0.5, 0, 0)[0];
  EXPECT_NEAR(fe.snapshot().motors[0].target_output_rad, half_angle, 1e-9);
}

TEST(FingertipEmulator, ClampsForcesAndAnglesToTheLimitsAndSaysSo) {
  {
    FingertipEmulator e = make(bare_options());
    Host host;
    run_commanded(e, host, FingertipMode::force, {5.0, 3.0, 4.0}, 150 * kMs);
    const FingertipEmulatorSnapshot& s = e.snapshot();
    EXPECT_TRUE(s.status & fingertip_status::clamped);
    EXPECT_NEAR(s.fsr_force_n[0], 2.0, 0.02);  // max normal
    // The shear vector (3, 4) N keeps its direction at the 1 N limit.
    EXPECT_NEAR(s.fsr_force_n[1], 0.6, 0.02);
    EXPECT_NEAR(s.fsr_force_n[2], 0.8, 0.02);
    EXPECT_GE(e.stats().clamped_commands, 1u);
    EXPECT_EQ(e.last_feedback().status & fingertip_status::clamped, fingertip_status::clamped);
  }
  {
    FingertipEmulator e = make(bare_options(), free_shaft());
    Host host;
    run_commanded(e, host, FingertipMode::motor_angles, {2.0, -3.0, 0.5}, 150 * kMs);
    const FingertipEmulatorSnapshot& s = e.snapshot();
    EXPECT_TRUE(s.status & fingertip_status::clamped);
    EXPECT_EQ(s.motors[0].target_output_rad, 1.0);
    EXPECT_EQ(s.motors[1].target_output_rad, -1.0);
    EXPECT_EQ(s.motors[2].target_output_rad, 0.5);
    EXPECT_NEAR(s.motors[0].output_angle_rad, 1.0, 0.002);
    // A command within the limits clears the flag.
    run_commanded(e, host, FingertipMode::motor_angles, {0.2, 0.1, 0.0}, 200 * kMs);
    EXPECT_FALSE(e.snapshot().status & fingertip_status::clamped);
  }
  {
    // A negative normal force cannot be rendered: rest, flagged.
    FingertipEmulator e = make(bare_options());
    Host host;
    run_commanded(e, host, FingertipMode::force, {-1.0, 0, 0}, 50 * kMs);
    EXPECT_TRUE(e.snapshot().status & fingertip_status::clamped);
    EXPECT_EQ(e.snapshot().motors[0].target_output_rad, 0.0);
  }
}

TEST(FingertipEmulator, DisableReturnsToRest) {
  FingertipEmulator e = make(bare_options());
  Host host;
  run_commanded(e, host, FingertipMode::force, {1.0, 0, 0}, 60 * kMs);
  ASSERT_GT(e.snapshot().fsr_force_n[0], 0.9);
  ASSERT_EQ(host.send(e, 61 * kMs, FingertipMode::force, {1.0, 0, 0}, false), FingertipCommandResult::ok);
  e.advance_to(100 * kMs);
  EXPECT_FALSE(e.snapshot().status & fingertip_status::enabled);
  EXPECT_FALSE(e.snapshot().status & fingertip_status::watchdog_tripped);
  EXPECT_LT(e.snapshot().fsr_force_n[0], 0.02);
  EXPECT_EQ(e.last_feedback().mode, FingertipMode::idle);
}

TEST(FingertipEmulator, RefusesStaleDuplicateMalformedAndMiscountedCommands) {
  FingertipEmulator e = make(bare_options());
  Host host;
  host.sequence = 100;
  ASSERT_EQ(host.send(e, 0, FingertipMode::force, {0.5, 0, 0}), FingertipCommandResult::ok);
  const Bytes newest = host.encode(FingertipMode::force, {0.7, 0, 0});  // 101
  const Bytes older = [&] {
    Host h;
    h.first = false;
    h.sequence = 99;
    return h.encode(FingertipMode::force, {1.9, 0, 0});
  }();
  e.advance_to(5 * kMs);
  EXPECT_EQ(e.handle_command(newest, 5 * kMs), FingertipCommandResult::ok);
  EXPECT_EQ(e.handle_command(newest, 5 * kMs), FingertipCommandResult::stale_sequence);  // duplicate
  EXPECT_EQ(e.handle_command(older, 5 * kMs), FingertipCommandResult::stale_sequence);   // reordered
  Bytes corrupt = host.encode(FingertipMode::force, {0.7, 0, 0});
  corrupt[9] ^= 0x10;
  EXPECT_EQ(e.handle_command(corrupt, 5 * kMs), FingertipCommandResult::bad_report);
  EXPECT_EQ(e.handle_command(Bytes{0x50, 0x10}, 5 * kMs), FingertipCommandResult::bad_report);
  // Two motor angles for a three-motor device.
  EXPECT_EQ(e.handle_command(host.encode(FingertipMode::motor_angles, {0.1, 0.1, 0}, true, 0, 2), 5 * kMs),
            FingertipCommandResult::wrong_value_count);
  e.advance_to(6 * kMs);
  const FingertipFeedback& f = e.last_feedback();
  EXPECT_EQ(f.applied_sequence, 101);  // the refused ones changed nothing
  EXPECT_EQ(f.rejected_commands, 5);
  EXPECT_EQ(f.command_result, FingertipCommandResult::wrong_value_count);
  EXPECT_EQ(e.stats().link.stale, 2u);
  EXPECT_EQ(e.stats().link.crc_failures, 1u);
  EXPECT_EQ(e.stats().link.malformed, 1u);
  EXPECT_EQ(e.stats().commands_rejected, 5u);
}

TEST(FingertipEmulator, CountsCommandGapsOnTheDeviceSide) {
  FingertipEmulator e = make(bare_options());
  Host host;
  ASSERT_EQ(host.send(e, 0, FingertipMode::force, {0.1, 0, 0}), FingertipCommandResult::ok);
  host.sequence += 4;  // four commands lost on the way
  ASSERT_EQ(host.send(e, 2 * kMs, FingertipMode::force, {0.1, 0, 0}), FingertipCommandResult::ok);
  EXPECT_EQ(e.stats().link.sequence_gaps, 1u);
  EXPECT_EQ(e.stats().link.lost, 4u);
}

TEST(FingertipEmulator, EncoderLossLatchesAFaultThatClearsOnlyWhenItsCauseIsGone) {
  FingertipEmulator e = make(bare_options());
  Host host;
  run_commanded(e, host, FingertipMode::force, {1.0, 0, 0}, 50 * kMs);
  e.inject_fault(FingertipInjectedFault::encoder_loss, 1);
  e.advance_to(51 * kMs);
  const FingertipEmulatorSnapshot& s = e.snapshot();
  EXPECT_TRUE(s.status & fingertip_status::fault_encoder);
  EXPECT_FALSE(s.status & fingertip_status::enabled);
  for (std::size_t i = 0; i < 3; ++i) { EXPECT_FALSE(s.motors[i].bridge_on) << i; }
  // The bridges are open, so the pad's spring pushes the tactor back.
  e.advance_to(150 * kMs);
  EXPECT_LT(e.snapshot().fsr_force_n[0], 0.1);
  // Clearing while the encoder is still lost: the fault comes straight back.
  ASSERT_EQ(host.send(e, 151 * kMs, FingertipMode::force, {1.0, 0, 0}, true, fingertip_command_flags::clear_faults),
            FingertipCommandResult::ok);
  e.advance_to(152 * kMs);
  EXPECT_TRUE(e.snapshot().status & fingertip_status::fault_encoder);
  e.inject_fault(FingertipInjectedFault::encoder_loss, 1, false);
  ASSERT_EQ(host.send(e, 153 * kMs, FingertipMode::force, {1.0, 0, 0}, true, fingertip_command_flags::clear_faults),
            FingertipCommandResult::ok);
  e.advance_to(153 * kMs);
  EXPECT_FALSE(e.snapshot().status & fingertip_status::faults);
  EXPECT_TRUE(e.snapshot().status & fingertip_status::enabled);
}

TEST(FingertipEmulator, ShortedTerminalsTripOverCurrentAndAJammedRotorStalls) {
  {
    FingertipEmulator e = make(bare_options());
    Host host;
    run_commanded(e, host, FingertipMode::force, {1.0, 0, 0}, 40 * kMs);
    e.inject_fault(FingertipInjectedFault::terminal_short, 0);
    e.advance_to(43 * kMs);
    EXPECT_TRUE(e.snapshot().status & fingertip_status::fault_overcurrent);
    EXPECT_EQ(e.snapshot().motors[0].current_a, 0.0);  // bridge open
    EXPECT_EQ(e.stats().faults_latched, 1u);
  }
  {
    FingertipEmulator e = make(bare_options());
    Host host;
    e.inject_fault(FingertipInjectedFault::stuck, 0);
    run_commanded(e, host, FingertipMode::motor_angles, {0.5, 0, 0}, 250 * kMs);
    EXPECT_FALSE(e.snapshot().status & fingertip_status::fault_stall) << "before stall_time_ns";
    EXPECT_NEAR(std::abs(e.snapshot().motors[0].current_a), 0.6, 0.05);  // held at the current limit
    run_commanded(e, host, FingertipMode::motor_angles, {0.5, 0, 0}, 320 * kMs);
    EXPECT_TRUE(e.snapshot().status & fingertip_status::fault_stall);
    EXPECT_EQ(e.snapshot().motors[0].output_angle_rad, 0.0);
  }
}

TEST(FingertipEmulator, IsDeterministicForASeed) {
  auto stream = [](std::uint64_t seed) {
    FingertipEmulatorOptions o;
    o.seed = seed;
    FingertipEmulator e = make(o);
    Host host;
    Bytes all;
    std::vector<FingertipEmulatedReport> out;
    for (TimeNs t = 0; t <= 120 * kMs; t += kMs) {
      if (t % (7 * kMs) == 0) {
        e.advance_to(t - 1, out);
        (void)e.handle_command(host.encode(FingertipMode::force, {0.8, 0.2, -0.1}), t);
      }
      e.advance_to(t, out);
    }
    for (const auto& r : out) all.insert(all.end(), r.bytes.begin(), r.bytes.end());
    return all;
  };
  const Bytes a = stream(5);
  EXPECT_EQ(a, stream(5));
  EXPECT_NE(a, stream(6));  // force-sensor noise differs
}

TEST(FingertipEmulator, FeedbackSequencesRestartAtEveryBootAndTheClockWraps) {
  FingertipEmulatorOptions o = bare_options();
  o.boot_timestamp_us = 0xFFFFFFFFu - 2500u;  // wraps 2.5 ms after power-up
  FingertipEmulator e = make(o);
  std::vector<FingertipEmulatedReport> out;
  e.advance_to(5 * kMs, out);
  ASSERT_EQ(out.size(), 6u);
  FingertipFeedbackStream host;
  FingertipFeedback f;
  for (std::size_t i = 0; i < out.size(); ++i) {
    ASSERT_TRUE(host.push(out[i].bytes, f).accepted());
    EXPECT_EQ(f.sequence, i);
    EXPECT_EQ(f.has(fingertip_status::device_start), i == 0);
    EXPECT_EQ(f.device_time_us, static_cast<std::uint32_t>(0xFFFFFFFFu - 2500u + 1000u * i));
  }
  EXPECT_LT(f.device_time_us, 10000u);  // wrapped
  // A device that powers up later ticks from then on.
  FingertipEmulatorOptions late = bare_options();
  late.boot_time_ns = 5 * kNsPerSecond;
  FingertipEmulator later = make(late);
  std::vector<FingertipEmulatedReport> later_out;
  later.advance_to(5 * kNsPerSecond + 2 * kMs, later_out);
  ASSERT_EQ(later_out.size(), 3u);
  EXPECT_EQ(later_out[0].send_ns, 5 * kNsPerSecond);
  EXPECT_EQ(later.stats().ticks, 3u);
  out.clear();
  e.power_cycle(20 * kMs);
  e.advance_to(22 * kMs, out);
  ASSERT_FALSE(out.empty());
  // The device starts over: sequence 0, flagged, and the host sees a restart, not a loss.
  std::size_t boots = 0;
  for (const auto& r : out) {
    const FingertipStreamResult res = host.push(r.bytes, f);
    if (f.has(fingertip_status::device_start) && res.sequence.verdict == FingertipSequenceVerdict::restart) ++boots;
  }
  EXPECT_EQ(boots, 1u);
  EXPECT_EQ(f.sequence, 2);
  EXPECT_EQ(host.counters().lost, 0u);
}

// ---------------------------------------------------------------------------
// Fuzz seeds.

fs::path corpus_dir() {
  return fs::path(PROPRIO_TESTS_DIR) / "fuzz" / "corpus" / "fingertip_protocol";
}
void write_bytes(const fs::path& p, const Bytes& b) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}
Bytes read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// PROPRIO_REGEN_CORPUS=1 ctest -R FingertipSeedCorpus rewrites the seeds after a
// protocol change; commit the result.
TEST(FingertipSeedCorpus, Regenerate) {
  const char* regen = std::getenv("PROPRIO_REGEN_CORPUS");
  if (!regen || std::string(regen) != "1") GTEST_SKIP() << "set PROPRIO_REGEN_CORPUS=1 to rewrite the seeds";
  const fs::path dir = corpus_dir();
  fs::create_directories(dir);
  Host host;
  write_bytes(dir / "command_force.bin", host.encode(FingertipMode::force, {1.0, -0.25, 0.5}));
  write_bytes(dir / "command_angles.bin", host.encode(FingertipMode::motor_angles, {0.3, -0.2, 0.1}, true,
                                                      fingertip_command_flags::clear_faults));
  FingertipEmulatorOptions o;
  o.hand = Handedness::right;
  o.finger = Finger::index;
  FingertipEmulator e = make(o);
  const auto info = e.info_report();
  write_bytes(dir / "info_report.bin", Bytes(info.begin(), info.end()));
  // A session as the device's end sees it: host commands interleaved with its feedback.
  Bytes session;
  Bytes feedback_only;
  std::vector<FingertipEmulatedReport> out;
  for (TimeNs t = 0; t <= 40 * kMs; t += kMs) {
    if (t % (5 * kMs) == 0) {
      const Bytes c = host.encode(FingertipMode::force, {0.9, 0.1, 0});
      session.insert(session.end(), c.begin(), c.end());
      e.advance_to(t - 1, out);
      (void)e.handle_command(c, t);
    }
    out.clear();
    e.advance_to(t, out);
    for (const auto& r : out) {
      session.insert(session.end(), r.bytes.begin(), r.bytes.end());
      feedback_only.insert(feedback_only.end(), r.bytes.begin(), r.bytes.end());
    }
  }
  write_bytes(dir / "feedback_report.bin", Bytes(feedback_only.begin(), feedback_only.begin() + 64));
  write_bytes(dir / "stream_feedback.bin", feedback_only);
  write_bytes(dir / "stream_session.bin", session);
  // A faulted device: what the status and flags look like then.
  e.inject_fault(FingertipInjectedFault::encoder_loss, 2);
  out.clear();
  e.advance_to(45 * kMs, out);
  Bytes faulted;
  for (const auto& r : out) faulted.insert(faulted.end(), r.bytes.begin(), r.bytes.end());
  write_bytes(dir / "stream_faulted.bin", faulted);
}

TEST(FingertipSeedCorpus, EverySeedStillDecodes) {
  const fs::path dir = corpus_dir();
  ASSERT_TRUE(fs::is_directory(dir)) << dir << " is missing; run with PROPRIO_REGEN_CORPUS=1";
  std::size_t seeds = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    SCOPED_TRACE(name);
    const Bytes b = read_bytes(entry.path());
    ASSERT_EQ(b.size() % kFingertipReportSize, 0u);
    ASSERT_GT(b.size(), 0u);
    ++seeds;
    for (std::size_t at = 0; at < b.size(); at += kFingertipReportSize) {
      const auto report = std::span<const std::uint8_t>(b).subspan(at, kFingertipReportSize);
      FingertipCommand c;
      FingertipFeedback f;
      FingertipDeviceInfo i;
      EXPECT_TRUE(decode_fingertip_command(report, c).ok() || decode_fingertip_feedback(report, f).ok() ||
                  decode_fingertip_info(report, i).ok())
          << "report at byte " << at;
    }
  }
  EXPECT_GE(seeds, 7u);
}

}  // namespace
}  // namespace proprio::devices
