#pragma once
// Simulated stretch-glove sessions written as a training dataset for the pose
// network (`proprio sim-glove`; format: proprio/stretch_glove/dataset.hpp).
// Each session is a new donning: a calibration exploration phase, then free
// motion, measured one strip combination at a time, recovered by the matrix
// read-out and min-max calibrated from its own exploration, as at run time.
// Sessions are simulated on worker threads and written in order; the same
// seed gives the same bytes whatever the thread count.
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>

#include "proprio/core/result.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::stretch_glove_eval {

struct SimDatasetOptions {
  int subjects = sim::kSimSubjectCount;
  int first_subject = 0;
  int sessions = 3;             // donnings per subject
  double task_minutes = 5.0;    // free motion per session
  double exploration_s = 60.0;  // calibration exploration before the task
  std::uint64_t seed = 1;
  std::string layout_file;  // empty: StretchGloveLayout::thesis_default()
  std::string out;          // dataset folder
  bool force = false;       // replace a dataset already in `out`
  int threads = 0;          // 0: one per core
  // Written to meta.json's generator record.
  std::string tool = "proprio sim-glove";
  std::string version;

  // Simulated time of the whole dataset, the unit of `on_progress`.
  double total_simulated_minutes() const;
};

struct SimDatasetReport {
  std::size_t frames = 0;
  double frame_rate_hz = 0.0;
  std::size_t exploration_frames = 0, task_frames = 0;
  std::size_t sessions = 0, threads = 0;
  double elapsed_s = 0.0;
  double coverage_mean = 0.0, coverage_min = 1.0;  // min-max calibration coverage over the sessions
  std::string worst_advice;                        // "subject S session K: <advice>" of the lowest coverage
};

struct SimDatasetCallbacks {
  std::function<void(double simulated_minutes_done)> on_progress;  // from the calling thread, about 5 per second
  std::function<void()> on_sessions_written;  // every session simulated and written, before meta.json
};

// Logs the layout, simulator, session and read-out settings (info) and each
// session's calibration coverage (debug; a warning when it is poor).
Result<SimDatasetReport> write_sim_dataset(const SimDatasetOptions& options, const SimDatasetCallbacks& callbacks = {});

}  // namespace proprio::stretch_glove_eval
