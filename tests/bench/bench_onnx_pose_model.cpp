// The stretch glove's pose network through OpenCV DNN: one frame (1 x 2 x 5 x 5
// in, 25 angles out), on one OpenCV thread, for the committed fixture models
// (tests/data/stretch_model/: the default U-Net of Table C.1 at width 16 and
// the FCN baseline, as tools/stretch_glove/train.py exports them).
// Run: build/dev/tests/proprio_bench --benchmark_filter=OnnxPose
//
// Budget: 200 us per frame on one core; frames arrive at 60 Hz.
#include <benchmark/benchmark.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <string>

#include "proprio/stretch_glove/onnx_pose_model.hpp"

using namespace proprio;
using namespace proprio::stretch_glove;

namespace {

std::filesystem::path fixture_dir() {
#ifdef PROPRIO_SOURCE_DIR
  return std::filesystem::path(PROPRIO_SOURCE_DIR) / "tests" / "data" / "stretch_model";
#else
  // tests/bench/this_file.cpp -> tests/data/stretch_model
  return std::filesystem::path(__FILE__).parent_path().parent_path() / "data" / "stretch_model";
#endif
}

void run_inference(benchmark::State& state, const char* kind) {
  auto model = OnnxPoseModel::load(fixture_dir() / (std::string(kind) + ".onnx"));  // opencv_threads = 1
  if (!model) {
    state.SkipWithError(model.error().message.c_str());
    return;
  }
  std::array<float, kPoseInputSize> input{};
  std::array<float, kPoseOutputSize> output{};
  std::size_t frame = 0;
  for (auto _ : state) {
    // A slowly changing input, as consecutive glove frames are.
    input[frame % kPoseInputSize] = 0.001f * static_cast<float>(frame % 2000) - 1.0f;
    ++frame;
    if (!model->infer(input.data(), output.data())) {
      state.SkipWithError("infer failed");
      return;
    }
    benchmark::DoNotOptimize(output.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()));
}

void BM_OnnxPoseInferUNet(benchmark::State& state) { run_inference(state, "unet"); }
void BM_OnnxPoseInferFcn(benchmark::State& state) { run_inference(state, "fcn"); }

}  // namespace

BENCHMARK(BM_OnnxPoseInferUNet)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_OnnxPoseInferFcn)->Unit(benchmark::kMicrosecond);
