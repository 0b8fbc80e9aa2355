// The stretch read-out board's HID path: one report encoded and decoded
// (latency), a recorded stream through StretchStreamDecoder (throughput, in
// reports and measurements per second), and the emulator per report.
// Run: build/dev/tests/proprio_bench --benchmark_filter=Stretch
//
// For scale: the thesis board measures 960 times a second, 12 measurements to
// a report, so the host gets 80 reports/s: a budget of 12.5 ms per report.
#include <benchmark/benchmark.h>

#include <array>
#include <cmath>
#include <vector>

#include "proprio/stretch_board/stretch_emulator.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"
#include "proprio/stretch_board/stretch_stream.hpp"

using namespace proprio;
using namespace proprio::devices;

namespace {

double drifting_pf(std::size_t combination, TimeNs t_ns) {
  return 20.0 + 0.5 * static_cast<double>(combination) + 2.0 * std::sin(4.4 * ns_to_seconds(t_ns));
}

// The reports of `seconds` of the thesis glove's board (13 x 14 strips, 960/s), back to back.
std::vector<std::array<std::uint8_t, kStretchDataReportSize>> emulated_reports(double seconds) {
  auto emu = StretchEmulator::create({}, drifting_pf);
  std::vector<StretchEmulatedReport> out;
  emu->advance_to(seconds_to_ns(seconds), out);
  std::vector<std::array<std::uint8_t, kStretchDataReportSize>> bytes;
  for (const auto& r : out) bytes.push_back(r.bytes);
  return bytes;
}

// One 64-byte measurement report: length/ID/version checks, CRC-16 over 62
// bytes, field checks (count, strips, 12 combinations) and unpacking.
void BM_StretchDecodeDataReport(benchmark::State& state) {
  const auto reports = emulated_reports(0.02);
  StretchDataReport out;
  for (auto _ : state) {
    benchmark::DoNotOptimize(decode_stretch_data_report(reports[0], out));
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(kStretchDataReportSize));
  state.SetLabel("one report, 12 measurements");
}
BENCHMARK(BM_StretchDecodeDataReport);

// The firmware's side of the same: pack 12 measurements and the CRC.
void BM_StretchEncodeDataReport(benchmark::State& state) {
  StretchDataReport r = *decode_stretch_data_report(emulated_reports(0.02)[0]);
  std::uint32_t k = 0;
  for (auto _ : state) {
    r.sequence = k++;
    benchmark::DoNotOptimize(encode_stretch_data_report(r));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_StretchEncodeDataReport);

// Throughput over a recorded stream: 10 s of the thesis board (800 reports,
// 9600 measurements) through the stream decoder: decode, sequence and loss
// accounting, per-measurement device times, pF scaling, statistics.
// Time per report = 1 / items_per_second.
void BM_StretchStreamDecodeThroughput(benchmark::State& state) {
  const auto reports = emulated_reports(10.0);
  std::array<StretchSample, kStretchMeasurementsPerReport> out;
  std::size_t samples = 0;
  for (auto _ : state) {
    StretchStreamDecoder decoder;
    TimeNs t = 0;
    for (const auto& r : reports) {
      t += 12'500'000;
      samples += decoder.push(r, out, t).sample_count;
    }
    benchmark::DoNotOptimize(samples);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(reports.size()));
  state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(reports.size() * kStretchDataReportSize));
  state.counters["measurements_per_s"] = benchmark::Counter(static_cast<double>(samples), benchmark::Counter::kIsRate);
  state.SetLabel("items = reports");
}
BENCHMARK(BM_StretchStreamDecodeThroughput)->Unit(benchmark::kMicrosecond);

// Firmware side, emulated: 12 measurements (provider, quantisation, fault
// draws), one report built and CRC'd.
void BM_StretchEmulatorReport(benchmark::State& state) {
  auto emu = StretchEmulator::create({}, drifting_pf);
  std::vector<StretchEmulatedReport> out;
  out.reserve(8);
  TimeNs t = 0;
  for (auto _ : state) {
    out.clear();
    t += 12'500'000;  // 12 measurements at 960/s
    emu->advance_to(t, out);
    benchmark::DoNotOptimize(out.data());
  }
  state.SetItemsProcessed(state.iterations());
  state.SetLabel("items = reports (12 measurements)");
}
BENCHMARK(BM_StretchEmulatorReport);

}  // namespace
