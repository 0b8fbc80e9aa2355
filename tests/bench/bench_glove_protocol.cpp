// The glove's HID path on the host: one report decoded (latency), a recorded
// stream decoded through ImuGloveStreamDecoder (throughput, in reports and bytes
// per second), hid::ClockSync per observation, and the emulator per tick.
// Run: build/dev/tests/proprio_bench --benchmark_filter=Glove
//
// For scale: a 7-IMU glove at 100 Hz sends 200 reports/s, so the host's
// budget per report is 5 ms.
#include <benchmark/benchmark.h>

#include <array>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/hid/clock_sync.hpp"
#include "proprio/imu_glove_board/imu_glove_emulator.hpp"
#include "proprio/imu_glove_board/imu_glove_protocol.hpp"
#include "proprio/imu_glove_board/imu_glove_stream.hpp"

using namespace proprio;
using namespace proprio::devices;

namespace {

std::vector<ImuSample> moving_tick(std::int64_t k, std::size_t imus = 7) {
  std::vector<ImuSample> out(imus);
  for (std::size_t i = 0; i < imus; ++i) {
    const double t = 0.01 * static_cast<double>(k) + static_cast<double>(i);
    out[i].sensor_id = static_cast<std::uint16_t>(i);
    out[i].accel_mps2 = Vec3(std::sin(t), 9.8 * std::cos(0.1 * t), 0.3 * t - std::floor(0.3 * t));
    out[i].gyro_radps = Vec3(2.0 * std::sin(3 * t), -std::cos(t), 0.5);
  }
  return out;
}

// The reports of n ticks of an emulated 7-IMU glove, back to back.
std::vector<std::array<std::uint8_t, kImuGloveDataReportSize>> emulated_reports(std::int64_t ticks) {
  auto emu = ImuGloveEmulator::create({});
  std::vector<ImuGloveEmulatedReport> out;
  for (std::int64_t k = 0; k < ticks; ++k) (void)emu->tick(k * 10 * kNsPerMillisecond, moving_tick(k), out);
  std::vector<std::array<std::uint8_t, kImuGloveDataReportSize>> bytes;
  for (const auto& r : out) bytes.push_back(r.bytes);
  return bytes;
}

// One 64-byte IMU data report: length/ID/version checks, CRC-16 over 62
// bytes, field checks and unpacking (no scaling).
void BM_GloveDecodeDataReport(benchmark::State& state) {
  const auto reports = emulated_reports(1);
  ImuGloveDataReport out;
  for (auto _ : state) {
    benchmark::DoNotOptimize(decode_data_report(reports[0], out));
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(kImuGloveDataReportSize));
  state.SetLabel("one report, 4 IMUs");
}
BENCHMARK(BM_GloveDecodeDataReport);

// Throughput over a recorded stream: 10 s of a 7-IMU glove (2000 reports)
// through the stream decoder: decode, sequence accounting, SI conversion of
// every sample, per-IMU statistics. Time per report = 1 / items_per_second.
void BM_GloveStreamDecodeThroughput(benchmark::State& state) {
  const auto reports = emulated_reports(1000);
  std::array<ImuGloveSample, kImuGloveImusPerReport> out;
  std::size_t samples = 0;
  for (auto _ : state) {
    ImuGloveStreamDecoder decoder;
    TimeNs t = 0;
    for (const auto& r : reports) {
      t += 5 * kNsPerMillisecond;
      samples += decoder.push(r, out, t).sample_count;
    }
    benchmark::DoNotOptimize(samples);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(reports.size()));
  state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(reports.size() * kImuGloveDataReportSize));
  state.counters["samples_per_s"] =
      benchmark::Counter(static_cast<double>(samples), benchmark::Counter::kIsRate);
  state.SetLabel("items = reports");
}
BENCHMARK(BM_GloveStreamDecodeThroughput)->Unit(benchmark::kMicrosecond);

void BM_GloveCrc16(benchmark::State& state) {
  const auto reports = emulated_reports(1);
  for (auto _ : state) benchmark::DoNotOptimize(hid::crc16_ccitt(std::span(reports[0]).first(62)));
  state.SetBytesProcessed(state.iterations() * 62);
}
BENCHMARK(BM_GloveCrc16);

// One hid::ClockSync observation plus one mapping, in steady state (a full 10 s
// window: 40 buckets, hull refit every observation).
void BM_GloveClockSyncObserve(benchmark::State& state) {
  hid::ClockSync sync;
  Rng rng(1);
  TimeNs host = 1'000'000 * kNsPerSecond;
  std::uint32_t device = 0;
  auto step = [&] {
    device += 5000;
    host += 5'000'000 + static_cast<TimeNs>(rng.below(1'000'000));
  };
  for (int i = 0; i < 4000; ++i) {
    step();
    sync.observe(device, host);
  }
  for (auto _ : state) {
    step();
    benchmark::DoNotOptimize(sync.observe(device, host));
    benchmark::DoNotOptimize(sync.to_host_ns(device));
  }
}
BENCHMARK(BM_GloveClockSyncObserve);

// Firmware side: quantise 7 IMUs, build and CRC two reports.
void BM_GloveEmulatorTick(benchmark::State& state) {
  auto emu = ImuGloveEmulator::create({});
  const auto tick = moving_tick(3);
  std::vector<ImuGloveEmulatedReport> out;
  out.reserve(4);
  std::int64_t k = 0;
  for (auto _ : state) {
    out.clear();
    (void)emu->tick(++k * 10 * kNsPerMillisecond, tick, out);
    benchmark::DoNotOptimize(out.data());
  }
  state.SetItemsProcessed(state.iterations());
  state.SetLabel("items = ticks (7 IMUs, 2 reports)");
}
BENCHMARK(BM_GloveEmulatorTick);

}  // namespace
