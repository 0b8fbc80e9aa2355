// Image-level VIST camera side (docs/vist-images.md): rendering one synthetic
// 1280x720 stereo pair, and colour-blob marker detection on it, single
// threaded and with the right image on the detector's helper thread.
// Frames are rendered up front (free motion of subject 3 with clutter and
// distractors), so only detection is timed in the detection benchmarks.
#include <benchmark/benchmark.h>

#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/sim/stereo_image_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "proprio/vist/marker_detection.hpp"

using namespace proprio;

namespace {

// Poses of 20 s of free motion, one every 2/3 s, so the frames cover many
// hand poses and head positions.
std::vector<sim::HandMotionFrame> free_motion(const HandShape& shape, int frames) {
  sim::HandMotionGenerator gen(HandModel(shape), sim::HandMotionOptions{});
  std::vector<sim::HandMotionFrame> motion;
  for (int k = 0; k < frames; ++k) motion.push_back(gen.sample(k * 666'666'667LL));
  return motion;
}

struct RenderedFrames {
  std::vector<sim::StereoImageFrame> frames;
  std::size_t visible_markers = 0;  // summed over frames and cameras
};

const RenderedFrames& rendered_frames() {
  static const RenderedFrames cache = [] {
    RenderedFrames r;
    const HandShape shape = *sim::sim_subject(3)->shape();
    auto simulator = sim::StereoImageSimulator::create(ImuGloveDescription::vist_default(), shape, {});
    if (!simulator.ok()) return r;
    sim::StereoImageTruth truth;
    for (const sim::HandMotionFrame& m : free_motion(shape, 30)) {
      sim::StereoImageFrame f;
      simulator->render(m.pose, m.T_world_head, m.time_ns, f, &truth);
      if (f.dropped) continue;
      r.visible_markers += truth.drawn[0].size() + truth.drawn[1].size();
      r.frames.push_back(std::move(f));
    }
    return r;
  }();
  return cache;
}

void BM_RenderStereoPair(benchmark::State& state) {
  const HandShape shape = *sim::sim_subject(3)->shape();
  auto simulator = sim::StereoImageSimulator::create(ImuGloveDescription::vist_default(), shape, {});
  if (!simulator.ok()) {
    state.SkipWithError(simulator.error().message.c_str());
    return;
  }
  const std::vector<sim::HandMotionFrame> motion = free_motion(shape, 30);
  sim::StereoImageFrame frame;
  sim::StereoImageTruth truth;
  std::size_t i = 0;
  for (auto _ : state) {
    const sim::HandMotionFrame& m = motion[i];
    simulator->render(m.pose, m.T_world_head, m.time_ns, frame, &truth);
    benchmark::DoNotOptimize(frame.images[0].data);
    i = (i + 1) % motion.size();
  }
  state.SetLabel("1280x720 pair: wall, hand, 37-marker glove, 10 distractors, blur, noise");
}
BENCHMARK(BM_RenderStereoPair)->Unit(benchmark::kMillisecond);

// Arg 0: both images on the calling thread; 1: detect_stereo with the helper thread.
void BM_DetectStereoPair(benchmark::State& state) {
  const RenderedFrames& r = rendered_frames();
  if (r.frames.empty()) {
    state.SkipWithError("could not render frames");
    return;
  }
  vist::MarkerDetectorOptions o;
  o.parallel_stereo = state.range(0) != 0;
  auto detector = vist::MarkerDetector::create(ImuGloveDescription::vist_default().rig.camera, o);
  if (!detector.ok()) {
    state.SkipWithError(detector.error().message.c_str());
    return;
  }
  MarkerObservations left, right;
  std::size_t i = 0;
  std::size_t found = 0;
  for (auto _ : state) {
    const sim::StereoImageFrame& f = r.frames[i];
    if (!detector->detect_stereo(f.images[0], f.images[1], left, right)) {
      state.SkipWithError("detection failed");
      return;
    }
    found += left.markers.size() + right.markers.size();
    i = (i + 1) % r.frames.size();
  }
  state.counters["blobs_per_pair"] =
      benchmark::Counter(static_cast<double>(found) / static_cast<double>(state.iterations()));
  state.counters["visible_markers_per_pair"] = benchmark::Counter(
      static_cast<double>(r.visible_markers) / static_cast<double>(r.frames.size()));
  state.SetLabel(o.parallel_stereo ? "1280x720 pair, 2 threads" : "1280x720 pair, 1 thread");
}
BENCHMARK(BM_DetectStereoPair)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond)->UseRealTime();

// One image, with the coarse pass at full resolution (Arg 1) or every second
// pixel (Arg 2, the default), to show what the coarse pass buys.
void BM_DetectImage(benchmark::State& state) {
  const RenderedFrames& r = rendered_frames();
  if (r.frames.empty()) {
    state.SkipWithError("could not render frames");
    return;
  }
  vist::MarkerDetectorOptions o;
  o.coarse_step = static_cast<int>(state.range(0));
  auto detector = vist::MarkerDetector::create(ImuGloveDescription::vist_default().rig.camera, o);
  if (!detector.ok()) {
    state.SkipWithError(detector.error().message.c_str());
    return;
  }
  MarkerObservations out;
  std::size_t i = 0;
  for (auto _ : state) {
    if (!detector->detect(r.frames[i].images[0], out)) {
      state.SkipWithError("detection failed");
      return;
    }
    benchmark::DoNotOptimize(out.markers.data());
    i = (i + 1) % r.frames.size();
  }
}
BENCHMARK(BM_DetectImage)->Arg(2)->Arg(1)->Unit(benchmark::kMicrosecond);

}  // namespace
