// The safety gate: clamping, watchdog, NaN handling, ramp-in, rate limiting,
// the randomized "never above the limits" property, and no allocation in the
// loop-side calls. Time is driven explicitly; nothing sleeps.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <new>
#include <string>

#include "proprio/core/random.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/safety.hpp"

// Counts heap allocations, to hold the 1 kHz calls to "no allocation".
namespace {
std::atomic<std::size_t> g_allocations{0};
}
// GCC cannot see that these replace the global pair and warns on free().
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return std::malloc(n ? n : 1);
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }

using namespace proprio;
using namespace proprio::haptics;

namespace {

constexpr DurationNs kMs = kNsPerMillisecond;

// A force_vector device with round limits, so expected values are easy to derive.
std::unique_ptr<FingertipDeviceModel> simple_device(double rate_n_per_s = 50.0, double ramp_s = 0.4) {
  DeviceLimits l;
  l.max_normal_n = 2.0;
  l.max_shear_n = 1.0;
  l.max_rate_n_per_s = rate_n_per_s;
  l.friction_coefficient = 1.0;
  l.ramp_in_s = ramp_s;
  l.watchdog_ns = 50 * kMs;
  auto m = make_force_vector_device(ForceVectorParams{}, l);
  EXPECT_TRUE(m.ok()) << (m.ok() ? "" : m.error().message);
  return std::move(*m);
}

std::unique_ptr<FingertipDeviceModel> shipped(const char* file) {
  auto m = load_device_model(std::string(PROPRIO_SOURCE_DIR) + "/config/haptics/" + file);
  EXPECT_TRUE(m.ok()) << (m.ok() ? "" : m.error().message);
  return m.ok() ? std::move(*m) : nullptr;
}

// Commands `f` every millisecond over [from, to) and returns the last output.
FingertipForce hold(SafetyGate& gate, const FingertipForce& f, TimeNs from, TimeNs to) {
  FingertipForce out;
  for (TimeNs t = from; t < to; t += kMs) {
    gate.command(f, t);
    out = gate.output(t);
  }
  return out;
}

bool is_zero(const FingertipForce& f) { return f.normal_n == 0.0 && f.shear_x_n == 0.0 && f.shear_z_n == 0.0; }

}  // namespace

TEST(SafetyGate, OutputsNothingUntilEngaged) {
  const auto dev = simple_device();
  SafetyGate gate(*dev);
  EXPECT_EQ(gate.command(FingertipForce{1.0, 0.0, 0.0}, 0), CommandVerdict::accepted);
  EXPECT_TRUE(is_zero(gate.output(0)));
  EXPECT_TRUE(is_zero(hold(gate, FingertipForce{1.0, 0.0, 0.0}, 0, 1000 * kMs)));
  EXPECT_EQ(gate.state(), GateState::disengaged);
  EXPECT_EQ(gate.ramp_scale(500 * kMs), 0.0);
}

TEST(SafetyGate, RampsInWithSmoothstepOnEngage) {
  const auto dev = simple_device(/*rate*/ 1e4, /*ramp*/ 0.4);
  SafetyGate gate(*dev);
  const TimeNs t0 = 5 * kNsPerSecond;
  const FingertipForce f{1.0, 0.3, 0.4};
  gate.command(f, t0);
  gate.engage(t0);
  // s(u) = 3u^2 - 2u^3 of u = t / 0.4 s: s(0) = 0, s(0.25) = 0.15625, s(0.5) = 0.5, s(1) = 1.
  struct Point {
    DurationNs at;
    double scale;
  };
  // Commands every millisecond (a gap would trip the watchdog), checked at the points.
  std::size_t checked = 0;
  for (DurationNs at = 0; at <= 600 * kMs; at += kMs) {
    gate.command(f, t0 + at);
    const FingertipForce out = gate.output(t0 + at);
    for (const Point p : {Point{0, 0.0}, Point{100 * kMs, 0.15625}, Point{200 * kMs, 0.5}, Point{400 * kMs, 1.0},
                          Point{600 * kMs, 1.0}}) {
      if (p.at != at) continue;
      ++checked;
      EXPECT_NEAR(out.normal_n, p.scale * 1.0, 1e-12) << p.at;
      EXPECT_NEAR(out.shear_x_n, p.scale * 0.3, 1e-12) << p.at;
      EXPECT_NEAR(out.shear_z_n, p.scale * 0.4, 1e-12) << p.at;
      EXPECT_NEAR(gate.ramp_scale(t0 + p.at), p.scale, 1e-12);
    }
  }
  EXPECT_EQ(checked, 5u);
  EXPECT_EQ(gate.state(), GateState::active);
  EXPECT_EQ(gate.stats().engagements, 1u);
}

TEST(SafetyGate, ClampsToTheDeviceLimits) {
  const auto dev = simple_device(1e4, 0.0);
  SafetyGate gate(*dev);
  gate.engage(0);
  // 3 N normal -> 2 N; shear (1.5, 2.0) has magnitude 2.5 -> 1.0, direction kept: (0.6, 0.8).
  EXPECT_EQ(gate.command(FingertipForce{3.0, 1.5, 2.0}, 0), CommandVerdict::clamped);
  const FingertipForce out = gate.output(10 * kMs);
  EXPECT_DOUBLE_EQ(out.normal_n, 2.0);
  EXPECT_DOUBLE_EQ(out.shear_x_n, 0.6);
  EXPECT_DOUBLE_EQ(out.shear_z_n, 0.8);
  EXPECT_EQ(gate.stats().clamps, 1u);
  EXPECT_EQ(gate.stats().normal_clamps, 1u);
  EXPECT_EQ(gate.stats().shear_clamps, 1u);
  // Shear without pressing: the friction cone allows none.
  EXPECT_EQ(gate.command(FingertipForce{0.0, 0.0, 0.5}, 10 * kMs), CommandVerdict::clamped);
  EXPECT_EQ(gate.stats().cone_clamps, 2u);
  EXPECT_EQ(gate.command(FingertipForce{1.0, 0.0, 0.5}, 11 * kMs), CommandVerdict::accepted);
}

TEST(SafetyGate, BandDropsShearXAndCountsIt) {
  const auto band = shipped("band_2dof.toml");
  ASSERT_TRUE(band);
  SafetyGate gate(*band);
  gate.engage(0);
  EXPECT_EQ(gate.command(FingertipForce{1.0, 0.3, 0.2}, 0), CommandVerdict::clamped);
  EXPECT_EQ(gate.stats().axis_drops, 1u);
  const FingertipForce out = hold(gate, FingertipForce{1.0, 0.3, 0.2}, kMs, 1000 * kMs);
  EXPECT_EQ(out.shear_x_n, 0.0);
  EXPECT_NEAR(out.normal_n, 1.0, 1e-12);
  EXPECT_NEAR(out.shear_z_n, 0.2, 1e-12);
}

TEST(SafetyGate, RateLimitsEachComponentAlongAStraightLine) {
  const auto dev = simple_device(/*rate*/ 50.0, /*ramp*/ 0.0);
  SafetyGate gate(*dev);
  gate.engage(0);
  EXPECT_TRUE(is_zero(hold(gate, FingertipForce{}, 0, 10 * kMs)));
  // Step to (1.0, 0, 0.8) at 10 ms. The largest component moves 50 N/s * 1 ms
  // = 0.05 N per ms, the others in proportion: after k ms, k * (0.05, 0, 0.04).
  const FingertipForce f{1.0, 0.0, 0.8};
  FingertipForce out = hold(gate, f, 10 * kMs, 11 * kMs);  // output at 10 ms: dt = 1 ms since 9 ms
  EXPECT_NEAR(out.normal_n, 0.05, 1e-12);
  EXPECT_NEAR(out.shear_z_n, 0.04, 1e-12);
  out = hold(gate, f, 11 * kMs, 20 * kMs);  // last output at 19 ms: 10 steps
  EXPECT_NEAR(out.normal_n, 0.5, 1e-12);
  EXPECT_NEAR(out.shear_z_n, 0.4, 1e-12);
  out = hold(gate, f, 20 * kMs, 40 * kMs);
  EXPECT_NEAR(out.normal_n, 1.0, 1e-12);
  EXPECT_NEAR(out.shear_z_n, 0.8, 1e-12);
  EXPECT_GE(gate.stats().rate_limited_outputs, 19u);
  // Calling output twice at the same time changes nothing.
  const FingertipForce again = gate.output(39 * kMs);
  EXPECT_EQ(again.normal_n, out.normal_n);
}

TEST(SafetyGate, WatchdogZeroesTheOutputWithin50ms) {
  const auto dev = simple_device(1e4, 0.0);
  SafetyGate gate(*dev);
  gate.engage(0);
  const FingertipForce f{1.5, 0.0, 0.0};
  const TimeNs last = 99 * kMs;
  EXPECT_NEAR(hold(gate, f, 0, last + kMs).normal_n, 1.5, 1e-12);
  // The servo loop stops commanding at 99 ms; the driver keeps asking.
  EXPECT_NEAR(gate.output(last + 49 * kMs).normal_n, 1.5, 1e-12);
  EXPECT_NEAR(gate.output(last + 50 * kMs - 1).normal_n, 1.5, 1e-12);
  EXPECT_TRUE(is_zero(gate.output(last + 50 * kMs)));
  EXPECT_EQ(gate.state(), GateState::watchdog_tripped);
  EXPECT_TRUE(is_zero(gate.output(last + 500 * kMs)));
  EXPECT_EQ(gate.stats().watchdog_trips, 1u) << "one trip per silence, however often output() is called";
  // Commands resume: the force ramps in again from zero instead of jumping back.
  const TimeNs resume = 1000 * kMs;
  gate.command(f, resume);
  EXPECT_TRUE(is_zero(gate.output(resume)));
  EXPECT_NEAR(hold(gate, f, resume + kMs, resume + 10 * kMs).normal_n, 1.5, 1e-12)
      << "ramp_in_s = 0 here, so the first step after resuming is the whole force";
}

TEST(SafetyGate, WatchdogGapSeenOnlyByCommandIsStillATripAndRampsIn) {
  const auto dev = simple_device(1e4, 0.4);
  SafetyGate gate(*dev);
  gate.engage(0);
  const FingertipForce f{1.0, 0.0, 0.0};
  hold(gate, f, 0, 1000 * kMs);
  // No output() during a 200 ms silence, then a command: counted, and eased in.
  gate.command(f, 1200 * kMs);
  EXPECT_EQ(gate.stats().watchdog_trips, 1u);
  EXPECT_TRUE(is_zero(gate.output(1200 * kMs)));
  EXPECT_NEAR(hold(gate, f, 1201 * kMs, 1401 * kMs).normal_n, 0.5, 1e-12) << "halfway through a fresh 0.4 s ramp";
}

TEST(SafetyGate, NonFiniteCommandGivesZeroAndAnError) {
  const auto dev = simple_device(1e4, 0.0);
  SafetyGate gate(*dev);
  gate.engage(0);
  EXPECT_NEAR(hold(gate, FingertipForce{1.0, 0.2, 0.0}, 0, 100 * kMs).normal_n, 1.0, 1e-12);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(gate.command(FingertipForce{1.0, nan, 0.0}, 100 * kMs), CommandVerdict::rejected_non_finite);
  EXPECT_TRUE(is_zero(gate.output(100 * kMs)));
  EXPECT_EQ(gate.state(), GateState::faulted);
  EXPECT_TRUE(is_zero(gate.output(120 * kMs)));
  EXPECT_EQ(gate.command(FingertipForce{inf, 0.0, 0.0}, 121 * kMs), CommandVerdict::rejected_non_finite);
  EXPECT_EQ(gate.stats().nan_commands, 2u);
  EXPECT_EQ(std::string(to_string(CommandVerdict::rejected_non_finite)), "rejected_non_finite");
  // A good command clears the fault; the force comes back from zero.
  EXPECT_EQ(gate.command(FingertipForce{1.0, 0.2, 0.0}, 130 * kMs), CommandVerdict::accepted);
  EXPECT_TRUE(is_zero(gate.output(130 * kMs)));
  EXPECT_NEAR(gate.output(131 * kMs).normal_n, 1.0, 1e-12);
  EXPECT_TRUE(std::string(gate.describe()).find("nan=2") != std::string::npos) << gate.describe();
}

TEST(SafetyGate, DisengageIsImmediate) {
  const auto dev = simple_device(50.0, 0.0);
  SafetyGate gate(*dev);
  gate.engage(0);
  EXPECT_GT(hold(gate, FingertipForce{2.0, 0.0, 0.0}, 0, 100 * kMs).normal_n, 1.9);
  gate.disengage();
  EXPECT_TRUE(is_zero(gate.output(100 * kMs)));
  // Engaging again eases in from zero, not from where it left off.
  gate.engage(200 * kMs);
  gate.command(FingertipForce{2.0, 0.0, 0.0}, 200 * kMs);
  EXPECT_NEAR(gate.output(201 * kMs).normal_n, 0.05, 1e-12);
  EXPECT_EQ(gate.stats().engagements, 2u);
}

// Whatever arrives, in whatever order, at whatever times: the output is within
// the limits, changes no faster than the rate limit except when it drops to
// zero, and is zero whenever the gate is disengaged, the last command was
// non-finite, or the last good command is at least watchdog_ns old.
TEST(SafetyGate, NeverExceedsTheLimitsWhateverTheInput) {
  const std::unique_ptr<FingertipDeviceModel> models[] = {shipped("band_2dof.toml"), shipped("platform_3dof.toml"),
                                                          shipped("force_vector.toml")};
  for (const auto& m : models) ASSERT_TRUE(m);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  std::size_t outputs = 0, nonzero = 0;
  for (std::uint64_t seed = 1; seed <= 300; ++seed) {
    Rng rng(mix_seed(seed, 0x5afe));
    const FingertipDeviceModel& m = *models[rng.below(3)];
    const DeviceLimits& l = m.limits();
    SafetyGate gate(m);
    TimeNs t = static_cast<TimeNs>(rng.below(1000)) * kMs;
    FingertipForce prev;
    TimeNs prev_t = t;
    bool engaged = false, faulted = false, have = false;
    TimeNs last_good = 0;
    auto component = [&]() {
      switch (rng.below(10)) {
        case 0: return nan;
        case 1: return rng.below(2) ? inf : -inf;
        case 2: return rng.uniform(-1e6, 1e6);
        case 3: return 0.0;
        default: return rng.uniform(-4.0, 4.0);
      }
    };
    for (int step = 0; step < 3000; ++step) {
      switch (rng.below(40)) {
        case 0:
          if (!engaged) {
            gate.engage(t);
            engaged = true;
          }
          break;
        case 1:
          gate.disengage();
          engaged = false;
          break;
        case 2: t += static_cast<TimeNs>(rng.below(200)) * kMs; break;  // a stall
        default: break;
      }
      if (rng.below(4) != 0) {
        FingertipForce f{component(), component(), component()};
        if (rng.below(8) != 0) f = FingertipForce{rng.uniform(-0.5, 3.5), rng.uniform(-2.5, 2.5), rng.uniform(-2.5, 2.5)};
        gate.command(f, t);
        if (f.is_finite()) {
          faulted = false;
          have = true;
          last_good = t;
        } else {
          faulted = true;
        }
      }
      const FingertipForce out = gate.output(t);
      ++outputs;
      ASSERT_TRUE(out.is_finite()) << "seed " << seed;
      ASSERT_GE(out.normal_n, 0.0) << "seed " << seed;
      ASSERT_LE(out.normal_n, l.max_normal_n) << "seed " << seed;
      ASSERT_LE(out.shear_magnitude_n(), l.max_shear_n) << "seed " << seed;
      ASSERT_LE(out.shear_magnitude_n(), l.friction_coefficient * out.normal_n) << "seed " << seed;
      if (!m.axes().shear_x) {
        ASSERT_EQ(out.shear_x_n, 0.0);
      }
      if (!engaged || faulted || !have || t - last_good >= l.watchdog_ns) {
        ASSERT_TRUE(is_zero(out)) << "seed " << seed << " step " << step;
      }
      if (!is_zero(out)) {
        ++nonzero;
        const double allowed = l.max_rate_n_per_s * ns_to_seconds(t - prev_t) + 1e-12;
        ASSERT_LE(std::abs(out.normal_n - prev.normal_n), allowed) << "seed " << seed << " step " << step;
        ASSERT_LE(std::abs(out.shear_x_n - prev.shear_x_n), allowed) << "seed " << seed << " step " << step;
        ASSERT_LE(std::abs(out.shear_z_n - prev.shear_z_n), allowed) << "seed " << seed << " step " << step;
      }
      prev = out;
      prev_t = t;
      t += static_cast<TimeNs>(rng.below(3)) * kMs / 2;  // 0, 0.5 or 1 ms: repeats and jitter
    }
  }
  // The property must not hold vacuously.
  EXPECT_GT(nonzero, outputs / 10) << nonzero << " of " << outputs;
}

TEST(SafetyGate, LoopCallsDoNotAllocate) {
  const std::unique_ptr<FingertipDeviceModel> models[] = {shipped("band_2dof.toml"), shipped("platform_3dof.toml"),
                                                          shipped("force_vector.toml")};
  for (const auto& m : models) {
    ASSERT_TRUE(m);
    SafetyGate gate(*m);
    const std::size_t before = g_allocations.load();
    gate.engage(0);
    double sink = 0.0;
    for (int k = 0; k < 1000; ++k) {
      const TimeNs t = k * kMs;
      const FingertipForce f{0.5 + 0.001 * k, 0.1, k % 100 == 0 ? std::nan("") : 0.2};
      gate.command(f, t);
      const FingertipForce out = gate.output(t);
      const MotorAngles q = m->inverse(out);
      const FingertipForce back = m->forward(q);
      const auto tau = m->load_torques(q);
      sink += back.normal_n + tau[0] + m->renderable(f).normal_n + m->rest().rad[0];
    }
    gate.disengage();
    EXPECT_EQ(g_allocations.load(), before) << m->kind();
    EXPECT_TRUE(std::isfinite(sink));
  }
}
