// The FTM's attitude filter (issue 27 target: one update <= 2 µs per IMU
// sample) on the synthetic IMU bench: gyro + accelerometer every sample, the
// compass every other one (200/100 Hz), the disturbance detector running.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <vector>

#include "../unit/input/ftm/ftm_hand_synth.hpp"
#include "../unit/input/ftm/imu_synth.hpp"
#include "proprio/ftm/ftm_tracker.hpp"
#include "proprio/ftm/mahony_filter.hpp"
#include "proprio/ftm/markley.hpp"

namespace proprio::ftm::ftm_bench {

std::vector<imu_synth::Sample> bench_samples() {
  const imu_synth::BenchPlan plan;
  imu_synth::NoiseModel noise;
  noise.gyro_bias_radps = Vec3(0.3, -0.2, 0.25) * imu_synth::kDeg;
  return imu_synth::synthesise(plan.duration_s(), plan, noise, 27501);
}

MahonyOptions bench_options(bool gate) {
  MahonyOptions o;
  o.gravity_ref_in_world_mps2 = imu_synth::gravity_ref_z_up();
  o.mag_ref_in_world_uT = imu_synth::earth_field_uT();
  o.gate_mag = gate;
  return o;
}

void BM_FtmMahonyUpdate(benchmark::State& state) {
  const std::vector<imu_synth::Sample> samples = bench_samples();
  MahonyFilter f(bench_options(state.range(0) != 0));
  const TimeNs period = samples.back().t_ns + 5'000'000;
  std::size_t k = 0;
  TimeNs offset = 0;
  for (auto _ : state) {
    const imu_synth::Sample& s = samples[k];
    benchmark::DoNotOptimize(f.update(s.t_ns + offset, s.gyro_radps, s.accel_mps2, s.mag_uT));
    if (++k == samples.size()) {
      k = 0;
      offset += period;
    }
  }
  benchmark::DoNotOptimize(f.q_world_body());
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_FtmMahonyUpdate)->Arg(1)->ArgName("gated");

// The SVD prior alone (used at start-up and after gaps).
void BM_FtmMarkleyAttitude(benchmark::State& state) {
  const std::vector<imu_synth::Sample> samples = bench_samples();
  std::size_t k = 0;
  for (auto _ : state) {
    const imu_synth::Sample& s = samples[k];
    benchmark::DoNotOptimize(markley_attitude(s.accel_mps2, s.mag_uT.value_or(samples[0].mag_uT.value()),
                                              imu_synth::gravity_ref_z_up(), imu_synth::earth_field_uT()));
    k = (k + 1) % samples.size();
  }
}
BENCHMARK(BM_FtmMarkleyAttitude);

// One whole FTM frame (issue 27 target <= 20 µs): 4 IMU samples (compass on
// every one), 3 bend samples and the wrist tracker's sample pushed, then all
// 26 joints estimated into a HandPose. The hand moves through 400 distinct
// poses (2 s at 200 Hz) with calibrated, non-identity mountings.
void BM_FtmTrackerFrame(benchmark::State& state) {
  Rng rng(27601);
  FtmCalibration truth = nominal_ftm_calibration(Handedness::right, 0.19, 0.1);
  for (auto& q : truth.q_imu_segment) q = hand_synth::random_rotation(rng, 0.4);
  const HandModel model(HandShape::from_measurements(0.19, 0.1).value());
  const FtmTrackerOptions options;
  std::vector<FtmEvent> events;
  constexpr int kFrames = 400;
  constexpr std::size_t kPerFrame = kFtmImuCount + kFtmBendCount + 1;
  const HandAngles a0 = hand_synth::random_tracked_angles(rng, options.synergies);
  for (int k = 0; k < kFrames; ++k) {
    hand_synth::HandTruth h;
    const double s = std::sin(2.0 * M_PI * k / kFrames);
    for (std::size_t i = 0; i < kHandDofCount; ++i) h.angles[i] = a0[i] * (0.5 + 0.5 * s);
    h.T_world_wrist = {Quat(Eigen::AngleAxisd(0.5 * s, Vec3::UnitY())), Vec3(0.0, 1.0, 0.1 * s)};
    hand_synth::tick(events, model, truth, h, k * 5'000'000LL, static_cast<std::uint64_t>(k));
  }
  auto tracker = FtmTracker::create(options, truth);
  if (!tracker.ok()) {
    state.SkipWithError(tracker.error().message.c_str());
    return;
  }
  HandPose pose;
  const TimeNs period = kFrames * 5'000'000LL;
  TimeNs offset = 0;
  std::size_t f = 0;
  for (auto _ : state) {
    for (std::size_t j = 0; j < kPerFrame; ++j) {
      FtmEvent e = events[f * kPerFrame + j];
      e.imu.time_ns += offset;
      e.bend.time_ns += offset;
      e.wrist.time_ns += offset;
      tracker->push(e);
    }
    tracker->estimate(pose);
    benchmark::DoNotOptimize(pose);
    if (++f == kFrames) {
      f = 0;
      offset += period;
    }
  }
  state.counters["tracked_joints"] = static_cast<double>(
      std::count_if(pose.flags.begin(), pose.flags.end(), [](std::uint8_t fl) { return fl & kOrientationTracked; }));
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_FtmTrackerFrame);

}  // namespace proprio::ftm::ftm_bench
