#include "proprio/stretch_glove/dataset_recorder.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "proprio/stretch_glove/calibration.hpp"

namespace proprio::stretch_glove {

Result<DatasetRecorder> DatasetRecorder::create(const StretchGloveLayout& layout, ReadoutOptions readout) {
  auto r = make_readout(layout, readout);
  if (!r) return r.error();
  return DatasetRecorder(layout, std::move(*r));
}

DatasetRecorder::DatasetRecorder(StretchGloveLayout layout, MatrixReadout readout)
    : layout_(std::move(layout)), readout_(std::move(readout)), frame_(readout_.make_frame()) {}

bool DatasetRecorder::push(const devices::StretchSample& m) {
  double value = m.capacitance_pf;
  if (m.status != devices::StretchMeasurementStatus::ok) {
    // The read-out leaves NaN rows out of the solve, as the run-time pipeline does.
    value = std::numeric_limits<double>::quiet_NaN();
    ++stats_.measurements_flagged;
  }
  if (!readout_.push(m.combination, value, m.time_ns, frame_)) return false;
  ++stats_.frames;
  if (!frame_.all_valid()) {
    ++stats_.frames_invalid;
    return false;
  }
  times_.push_back(frame_.time_ns);
  cells_.insert(cells_.end(), frame_.cells_pf.begin(), frame_.cells_pf.end());
  return true;
}

Result<DatasetSession> DatasetRecorder::finish(HandSource& truth, const DatasetSessionInfo& info) {
  auto shape = HandShape::from_measurements(info.hand_length_m, info.hand_width_m);
  if (!shape) return shape.error();
  const HandModel model(*shape);
  auto calibrator = MinMaxCalibrator::create(layout_);
  if (!calibrator) return calibrator.error();

  const std::size_t n_cells = layout_.cell_count();
  DatasetSession s;
  s.subject = info.subject;
  s.session = info.session;
  s.donning = info.donning;
  s.hand_length_m = info.hand_length_m;
  s.hand_width_m = info.hand_width_m;
  stats_.paired = stats_.without_truth = stats_.exploration = stats_.task = 0;
  stats_.ik_residual_max_m = 0.0;
  paired_times_.clear();
  // The calibration takes every exploration frame, with ground truth or not:
  // it needs none, and its median filters want consecutive frames.
  for (std::size_t f = 0; f < times_.size() && times_[f] < info.exploration_end_ns; ++f) {
    calibrator->add(std::span<const float>(cells_).subspan(f * n_cells, n_cells));
  }
  HandPose pose;
  for (std::size_t f = 0; f < times_.size(); ++f) {
    if (!is_usable(truth.lookup(info.hand, times_[f], pose)) || !pose.active) {
      ++stats_.without_truth;
      continue;
    }
    const InverseKinematicsResult ik = model.inverse(pose);
    stats_.ik_residual_max_m = std::max(stats_.ik_residual_max_m, ik.max_position_residual_m);
    const auto cells = std::span<const float>(cells_).subspan(f * n_cells, n_cells);
    const bool exploring = times_[f] < info.exploration_end_ns;
    ++(exploring ? stats_.exploration : stats_.task);
    s.cells.insert(s.cells.end(), cells.begin(), cells.end());
    for (double a : ik.angles) s.angles.push_back(static_cast<float>(a));
    s.phase.push_back(exploring ? 0 : 1);
    paired_times_.push_back(times_[f]);
    ++stats_.paired;
  }
  if (stats_.paired == 0) {
    std::string span = "no frames were captured";
    if (!times_.empty()) {
      span = "the glove's frames span " + std::to_string(1e-9 * static_cast<double>(times_.front())) + " to " +
             std::to_string(1e-9 * static_cast<double>(times_.back())) + " s (CLOCK_MONOTONIC)";
    }
    return make_error(Errc::unavailable, "recording: no frame has a ground-truth " + std::string(to_string(info.hand)) +
                                             " hand at its time from source '" + std::string(truth.name()) + "'; " +
                                             span + ". Record the ground truth at the same time, on the same clock");
  }
  auto calibration = calibrator->finish("proprio record glove (exploration phase)");
  if (!calibration) return calibration.error();
  s.calibration = std::move(*calibration);
  return s;
}

}  // namespace proprio::stretch_glove
