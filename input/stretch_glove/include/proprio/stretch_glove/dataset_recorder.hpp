#pragma once
// Recording training data from a real glove: the read-out board's
// measurements become cell frames (the run-time read-out, so training sees
// what inference will see), each paired afterwards with the ground-truth hand
// at the frame's time from any HandSource (a hand-tracking recording replayed
// with ReplayHandSource, a live tracker): joint angles by inverse kinematics.
// Frames before exploration_end_ns are the session's exploration phase; its
// min-max calibration is computed from them as `proprio calibrate glove`
// would. The result is one DatasetSession for DatasetWriter, the format the
// Python training tools read (`proprio record glove`).
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/hand_source.hpp"
#include "proprio/stretch_board/stretch_stream.hpp"
#include "proprio/stretch_glove/dataset.hpp"
#include "proprio/stretch_glove/readout.hpp"

namespace proprio::stretch_glove {

struct DatasetRecorderStats {
  std::size_t frames = 0;               // complete cell frames captured
  std::size_t frames_invalid = 0;       // a cell could not be recovered: not kept
  std::size_t measurements_flagged = 0;  // the board flagged them (saturated, error): left out of the solve
  // After pairing:
  std::size_t paired = 0;
  std::size_t without_truth = 0;  // no ground truth at the frame's time (gap, before or after it): dropped
  std::size_t exploration = 0, task = 0;
  double ik_residual_max_m = 0.0;  // how well the truth poses fit the hand model
};

struct DatasetSessionInfo {
  int subject = 0;
  int session = 0;
  int donning = 0;
  Handedness hand = Handedness::right;
  double hand_length_m = 0.19;
  double hand_width_m = 0.09;
  TimeNs exploration_end_ns = 0;  // frames before it are the exploration phase (CLOCK_MONOTONIC)
};

class DatasetRecorder {
 public:
  static Result<DatasetRecorder> create(const StretchGloveLayout& layout, ReadoutOptions readout = {});

  // One measurement from the board's reader (StretchDevice::pop). Returns
  // true when it completed a cell frame, which is kept.
  bool push(const devices::StretchSample& m);
  std::size_t frames() const noexcept { return times_.size(); }
  const DatasetRecorderStats& stats() const noexcept { return stats_; }

  // Pairs every kept frame with `truth` at its time and computes the
  // exploration phase's calibration. Errors: no frame has ground truth
  // (Errc::unavailable, saying which time spans did not overlap), or the
  // exploration phase cannot calibrate every cell.
  Result<DatasetSession> finish(HandSource& truth, const DatasetSessionInfo& info);
  // After finish(): the time of each frame in the session (CLOCK_MONOTONIC).
  const std::vector<TimeNs>& paired_times() const noexcept { return paired_times_; }

 private:
  DatasetRecorder(StretchGloveLayout layout, MatrixReadout readout);
  StretchGloveLayout layout_;
  MatrixReadout readout_;
  CellFrame frame_;
  std::vector<TimeNs> times_;
  std::vector<float> cells_;  // frames x cell_count
  std::vector<TimeNs> paired_times_;
  DatasetRecorderStats stats_;
};

}  // namespace proprio::stretch_glove
