#pragma once
// The stretch glove on simulated subjects, through the real run-time
// pipeline (read-out, calibration, ONNX model, hand), scored against the
// simulator's ground-truth joint angles. `proprio bench glove`, the tests and
// the demo run it. Training and the thesis's Table 5.1 scenarios that need a
// model per subject (personalised, fine-tuned) live in tools/stretch_glove.
//
// Simulated accuracy is not real-world accuracy: the simulator's skin model
// is plausible, not measured, and real gloves slip, crease and age.
#include <array>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/hand_source.hpp"
#include "proprio/core/pose_history.hpp"
#include "proprio/core/time.hpp"
#include "proprio/glove_descriptions/stretch_glove_layout.hpp"
#include "proprio/stretch_glove/glove_tracker.hpp"
#include "proprio/sim/stretch_glove_sim.hpp"

namespace proprio::stretch_glove_eval {

// The shipped generic model is trained on these simulated subjects; the others are held out.
inline constexpr int kFirstHeldOutSubject = 10;

enum class CalibrationMode : std::uint8_t {
  session,  // the thesis's on-the-fly min-max from this session's exploration phase (scenario 4)
  global,   // min-max over the training data, from the model's sidecar (scenario 3)
};
std::string_view to_string(CalibrationMode m) noexcept;

struct GloveSessionSpec {
  int subject = kFirstHeldOutSubject;
  int session = 0;  // the donning
  double exploration_s = 60.0;
  double task_s = 120.0;
  std::uint64_t seed = 1;
  CalibrationMode calibration = CalibrationMode::session;
  sim::StretchFaults faults;
};

struct GloveSessionResult {
  GloveSessionSpec spec;
  std::size_t frames = 0;  // scored task frames
  double mean_deg = 0.0;   // mean absolute joint-angle error over the 20 DoFs, network output (no 1€ filter)
  double p95_deg = 0.0;
  double filtered_mean_deg = 0.0;  // the same after the 1€ filter (what an app sees, lag included)
  std::array<double, kHandDofCount> dof_mean_deg{};
  double calibration_coverage = 0.0;  // exploration coverage (calibration.hpp), 0-1
  double task_seconds = 0.0;
  double pipeline_seconds = 0.0;      // wall time in read-out + tracker over the task
  std::size_t pipeline_frames = 0;
  stretch_glove::GloveTrackerStats tracker;
  std::vector<float> errors_deg;  // per frame and DoF, for pooling
};

Result<GloveSessionResult> run_glove_session(const StretchGloveLayout& layout, const std::filesystem::path& model,
                                             const GloveSessionSpec& spec);

struct GloveAggregate {
  std::size_t sessions = 0, frames = 0;
  double mean_deg = 0.0, p95_deg = 0.0, filtered_mean_deg = 0.0;
  std::array<double, kHandDofCount> dof_mean_deg{};
  double pipeline_us_per_frame = 0.0;
};
GloveAggregate aggregate(const std::vector<GloveSessionResult>& sessions);


// The exploration phase of a simulated wearer through the real read-out and
// calibrator: the min-max calibration `proprio calibrate glove` would save.
struct SimulatedCalibration {
  stretch_glove::MinMaxCalibration calibration;
  stretch_glove::CalibrationProgress progress;
};
Result<SimulatedCalibration> calibrate_simulated(const StretchGloveLayout& layout, int subject, std::uint64_t seed,
                                                 double exploration_s, std::string source = {});

// A simulated subject wearing the stretch glove, live: the exploration phase
// runs first (off-line, in well under a second) for the min-max calibration,
// then the free-motion task is measured in real time and fed to a
// GloveHandSource, as a read-out board's reader thread would. The OpenXR
// layer's `glove` source with `input = "sim"` is this.
struct SimGloveSourceOptions {
  int subject = 3;
  std::uint64_t seed = 1;
  std::filesystem::path model;
  StretchGloveLayout layout = StretchGloveLayout::thesis_default();
  double exploration_s = 60.0;
  stretch_glove::GloveTrackerOptions tracker;  // hand and size are the subject's
  PoseHistoryOptions history;
};
Result<std::unique_ptr<HandSource>> make_sim_glove_source(const SimGloveSourceOptions& options,
                                                          const Clock& clock = MonotonicClock::instance());

}  // namespace proprio::stretch_glove_eval
