// VIST IMU-aided correspondence search (Lee 2021, §4.4): one stereo frame of
// the default 37-marker glove, priors + CPD + assignment. Thesis: 93 us.
#include <benchmark/benchmark.h>

#include <cmath>
#include <unordered_set>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/random.hpp"
#include "proprio/sim/hand_motion.hpp"
#include "proprio/sim/stereo_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "proprio/vist/correspondence.hpp"

using namespace proprio;

namespace {

struct FrameData {
  HandPose predicted;
  Pose T_world_leftcam;
  std::vector<vist::Observation3D> observations;
};

// Free-motion frames with 12-18 stereo-visible markers; the prediction is the
// truth with ~1 cm / ~3 deg wrist and ~3 deg finger errors, as in the tests.
std::vector<FrameData> make_frames(const HandShape& shape,
                                   const sim::StereoMarkerSimulator& simulator, const std::vector<PlacedMarker>& placed) {
  const HandModel model(shape);
  sim::HandMotionGenerator gen(model, sim::HandMotionOptions{});
  Rng rng(5);
  constexpr double kDeg = 3.14159265358979323846 / 180.0;
  std::vector<FrameData> frames;
  for (int k = 0; k < 3000 && frames.size() < 64; ++k) {
    const sim::HandMotionFrame mf = gen.sample(k * 33'333'333LL);
    sim::StereoGroundTruth gt;
    simulator.simulate(mf.pose, mf.T_world_head, mf.time_ns, &gt);
    std::unordered_set<std::size_t> right;
    for (const auto& t : gt.cameras[1]) right.insert(t.glove_index);
    FrameData f;
    for (const auto& t : gt.cameras[0]) {
      if (!right.count(t.glove_index)) continue;
      vist::Observation3D o;
      o.hue = static_cast<std::uint8_t>(placed[t.glove_index].hue);
      o.p_in_leftcam = t.p_in_leftcam + Vec3(rng.normal(0, 0.0015), rng.normal(0, 0.0015), rng.normal(0, 0.0015));
      o.covariance = std::pow(0.0015, 2) * Mat3::Identity();
      f.observations.push_back(o);
    }
    if (f.observations.size() < 12 || f.observations.size() > 18) continue;
    HandAngles angles = mf.angles;
    for (double& a : angles) a += rng.normal(0, 3 * kDeg);
    Pose T_wrist = mf.T_world_wrist;
    T_wrist.p += Vec3(rng.normal(0, 0.006), rng.normal(0, 0.006), rng.normal(0, 0.006));
    T_wrist.q = (T_wrist.q * so3_exp(Vec3(rng.normal(0, 0.03), rng.normal(0, 0.03), rng.normal(0, 0.03)))).normalized();
    f.predicted = model.forward(Handedness::right, model.limits().clamp(angles), T_wrist, mf.time_ns);
    f.T_world_leftcam = gt.T_world_leftcam;
    frames.push_back(std::move(f));
  }
  return frames;
}

void BM_VistCorrespondenceSearch(benchmark::State& state) {
  const ImuGloveDescription glove = ImuGloveDescription::vist_default();
  const HandShape shape = *sim::sim_subject(3)->shape();
  sim::StereoSimOptions so;
  so.facing = sim::FacingModel::linear_ramp;
  auto simulator = sim::StereoMarkerSimulator::create(glove, shape, so);
  if (!simulator.ok()) {
    state.SkipWithError(simulator.error().message.c_str());
    return;
  }
  const std::vector<PlacedMarker> placed = glove.place_markers(shape);
  const std::vector<Mat3> cov(placed.size(), std::pow(0.005, 2) * Mat3::Identity());
  const std::vector<FrameData> frames = make_frames(shape, *simulator, placed);
  if (frames.empty()) {
    state.SkipWithError("no frame with 12-18 observations");
    return;
  }
  vist::CorrespondenceSearch search;
  vist::CorrespondenceResult result;
  result.reserve(64);
  std::size_t i = 0;
  std::size_t observations = 0;
  std::size_t assigned = 0;
  for (auto _ : state) {
    const FrameData& f = frames[i];
    const Status s = search.search(f.predicted, f.T_world_leftcam, simulator->rig(), placed, cov, f.observations, result);
    benchmark::DoNotOptimize(s);
    observations += f.observations.size();
    assigned += result.assignments.size();
    i = (i + 1) % frames.size();
  }
  const auto it = static_cast<double>(state.iterations());
  state.counters["observations_per_frame"] = benchmark::Counter(static_cast<double>(observations) / it);
  state.counters["assigned_per_frame"] = benchmark::Counter(static_cast<double>(assigned) / it);
  state.SetLabel("37 markers, 12-18 observations, priors + occlusion + EM + assignment");
}
BENCHMARK(BM_VistCorrespondenceSearch)->Unit(benchmark::kMicrosecond);

}  // namespace
