// The stretch glove's latency on the device path: from a capacitance
// measurement to the pose built on it being servable (HandPose::ready_time_ns
// - data_time_ns), with a simulated wearer behind the emulated read-out board,
// the in-memory HID link (0.2-1.0 ms per report) and the real driver and
// pipeline (stretch_glove_eval's emulated input). Real time: one iteration
// streams state.range(0) seconds; the first second is not counted.
//
// Counters (ms): p50, p99, max of that latency as the pipeline sees it
// (data_time_ns is the measurement's host time from the driver's clock
// alignment), and true_*: from the instant the emulated board really made the
// measurement (its schedule: measurement k at time zero + k / 960 s; the frame's
// newest measurement ends a 12-measurement report since the read-out solves
// at report ends). clock_bias: data_time_ns less that instant.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>
#include <vector>

#include "proprio/stretch_board/stretch_protocol.hpp"
#include "proprio/stretch_glove_eval/glove_evaluation.hpp"

namespace {

using namespace proprio;

double percentile_ms(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
}

void BM_StretchGloveEmulatedLatency(benchmark::State& state) {
  stretch_glove_eval::EmulatedGloveSourceOptions o;
  o.wearer.model = std::filesystem::path(PROPRIO_SOURCE_DIR) / "config/models/stretch_glove_generic.onnx";
  o.wearer.exploration_s = 30.0;
  const DurationNs run_ns = state.range(0) * kNsPerSecond;
  const double period_ns = 1e9 / devices::kStretchDefaultRateHz;
  std::vector<double> latency, true_latency, bias;
  std::uint64_t poses = 0;
  for (auto _ : state) {
    auto source = stretch_glove_eval::make_emulated_glove_source(o);
    if (!source) {
      state.SkipWithError(source.error().message.c_str());
      return;
    }
    const Handedness hand = (*source)->available(Handedness::right) ? Handedness::right : Handedness::left;
    const TimeNs t0 = (*source)->time_zero_ns();
    const auto& clock = MonotonicClock::instance();
    TimeNs last_time = 0;
    // Poll the newest pose every 0.5 ms (poses come every 12.5-25 ms): each is seen.
    while (clock.now_ns() < t0 + run_ns) {
      std::this_thread::sleep_for(std::chrono::microseconds(500));
      HandPose p;
      // Far in the future: the newest pose itself, its own times untouched.
      if ((*source)->lookup(hand, clock.now_ns() + kNsPerSecond, p) != PoseLookup::stale) continue;
      if (p.time_ns == last_time) continue;
      last_time = p.time_ns;
      if (p.time_ns < t0 + kNsPerSecond) continue;
      ++poses;
      // The last measurement of the report nearest the pose's data time (no restarts here).
      const double per_report = static_cast<double>(devices::kStretchMeasurementsPerReport);
      const double k_data = static_cast<double>(p.data_time_ns - t0) / period_ns;
      const double k = per_report * std::round((k_data - (per_report - 1)) / per_report) + (per_report - 1);
      const double measured_ns = static_cast<double>(t0) + k * period_ns;
      latency.push_back(1e-6 * static_cast<double>(p.ready_time_ns - p.data_time_ns));
      true_latency.push_back(1e-6 * (static_cast<double>(p.ready_time_ns) - measured_ns));
      bias.push_back(1e-6 * (static_cast<double>(p.data_time_ns) - measured_ns));
    }
  }
  state.counters["poses"] = static_cast<double>(poses);
  state.counters["p50_ms"] = percentile_ms(latency, 0.50);
  state.counters["p99_ms"] = percentile_ms(latency, 0.99);
  state.counters["max_ms"] = percentile_ms(latency, 1.0);
  state.counters["true_p50_ms"] = percentile_ms(true_latency, 0.50);
  state.counters["true_p99_ms"] = percentile_ms(true_latency, 0.99);
  state.counters["true_max_ms"] = percentile_ms(true_latency, 1.0);
  state.counters["clock_bias_p50_ms"] = percentile_ms(bias, 0.50);
}
BENCHMARK(BM_StretchGloveEmulatedLatency)->Arg(10)->Iterations(1)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
