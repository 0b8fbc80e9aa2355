// The FTM's attitude filter (issue 27 target: one update <= 2 µs per IMU
// sample) on the synthetic IMU bench: gyro + accelerometer every sample, the
// compass every other one (200/100 Hz), the disturbance detector running.
#include <benchmark/benchmark.h>

#include <vector>

#include "../unit/input/ftm/imu_synth.hpp"
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

}  // namespace proprio::ftm::ftm_bench
