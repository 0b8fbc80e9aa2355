// VIST left-right stereo matching (Lee 2021, §4.3.3): one rectified stereo
// frame of the default 37-marker glove, 1-DOF CPD per hue, outlier tests and
// triangulation. Thesis: 85 µs per frame; target here <= 50 µs.
#include <benchmark/benchmark.h>

#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/sim/stereo_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "proprio/vist/stereo_matching.hpp"

using namespace proprio;

namespace {

void BM_VistStereoMatching(benchmark::State& state) {
  const HandShape shape = *sim::sim_subject(3)->shape();
  const ImuGloveDescription glove = ImuGloveDescription::vist_default();
  auto simulator = sim::StereoMarkerSimulator::create(glove, shape, {});
  auto matcher = vist::StereoMatcher::create(glove.rig, {});
  if (!simulator.ok() || !matcher.ok()) {
    state.SkipWithError("setup failed");
    return;
  }
  // Frames generated up front, so only matching is timed: the first 30 s of
  // free motion with 15-20 blobs in each camera (the busy frames).
  sim::HandMotionGenerator gen(HandModel(shape), sim::HandMotionOptions{});
  std::vector<sim::StereoFrame> frames;
  for (int k = 0; k < 900 && frames.size() < 64; ++k) {
    const sim::HandMotionFrame m = gen.sample(k * 33'333'333LL);
    sim::StereoFrame f = simulator->simulate(m.pose, m.T_world_head, m.time_ns);
    const std::size_t nl = f.cameras[0].markers.size(), nr = f.cameras[1].markers.size();
    if (nl >= 15 && nl <= 20 && nr >= 15 && nr <= 20) frames.push_back(std::move(f));
  }
  if (frames.empty()) {
    state.SkipWithError("no frame with 15-20 blobs per camera");
    return;
  }
  std::vector<vist::StereoPoint> out;
  std::size_t i = 0, blobs = 0, matched = 0;
  for (auto _ : state) {
    const sim::StereoFrame& f = frames[i];
    matcher->match(f.cameras[0], f.cameras[1], out);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
    blobs += f.cameras[0].markers.size() + f.cameras[1].markers.size();
    matched += out.size();
    i = (i + 1) % frames.size();
  }
  const double n = static_cast<double>(state.iterations());
  state.counters["blobs_per_frame"] = benchmark::Counter(static_cast<double>(blobs) / n);
  state.counters["matched_per_frame"] = benchmark::Counter(static_cast<double>(matched) / n);
  state.SetLabel("37-marker glove, 15-20 blobs per camera");
}
BENCHMARK(BM_VistStereoMatching);

}  // namespace
