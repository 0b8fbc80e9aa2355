#include "proprio/stretch_glove/glove_hand_source.hpp"

#include <cstdio>

namespace proprio::stretch_glove {

std::string GloveHandSourceOptions::describe() const {
  return tracker.describe() + "\n" + readout.describe() + "\nhistory: " + history.describe();
}

std::string GloveSourceStats::describe() const {
  char buf[192];
  std::snprintf(buf, sizeof buf, "measurements %llu (rejected %llu), poses %llu (rejected %llu); ",
                static_cast<unsigned long long>(measurements), static_cast<unsigned long long>(measurements_rejected),
                static_cast<unsigned long long>(poses_published), static_cast<unsigned long long>(poses_rejected));
  return buf + tracker.describe();
}

Result<std::unique_ptr<GloveHandSource>> GloveHandSource::create(const StretchGloveLayout& layout,
                                                                 MinMaxCalibration calibration, OnnxPoseModel model,
                                                                 GloveHandSourceOptions options) {
  auto readout = make_readout(layout, options.readout);
  if (!readout) return readout.error();
  auto tracker = GloveTracker::create(layout, std::move(calibration), std::move(model), options.tracker);
  if (!tracker) return tracker.error();
  return std::unique_ptr<GloveHandSource>(
      new GloveHandSource(std::move(options), std::move(*readout), std::move(*tracker)));
}

GloveHandSource::GloveHandSource(GloveHandSourceOptions options, MatrixReadout readout, GloveTracker tracker)
    : options_(std::move(options)),
      readout_(std::move(readout)),
      tracker_(std::move(tracker)),
      frame_(readout_.make_frame()),
      history_(options_.history) {}

bool GloveHandSource::push_measurement(std::size_t combination, double capacitance_pf, TimeNs t_ns) {
  const auto rejected_before = readout_.rejected_updates();
  const bool frame_ready = readout_.push(combination, capacitance_pf, t_ns, frame_);
  {
    std::lock_guard lock(mutex_);
    ++stats_.measurements;
    stats_.measurements_rejected += readout_.rejected_updates() - rejected_before;
  }
  return frame_ready && push_frame(frame_);
}

void GloveHandSource::add_measurement(std::size_t combination, double capacitance_pf, TimeNs t_ns) {
  const auto rejected_before = readout_.rejected_updates();
  readout_.record(combination, capacitance_pf, t_ns);
  std::lock_guard lock(mutex_);
  ++stats_.measurements;
  stats_.measurements_rejected += readout_.rejected_updates() - rejected_before;
}

bool GloveHandSource::end_burst() { return readout_.solve_due(frame_) && push_frame(frame_); }

bool GloveHandSource::push_frame(const CellFrame& frame) {
  tracker_.process(frame, pose_);
  std::lock_guard lock(mutex_);
  stats_.tracker = tracker_.stats();
  if (!pose_.active) return false;
  if (!history_.push(pose_)) {
    ++stats_.poses_rejected;
    return false;
  }
  ++stats_.poses_published;
  return true;
}

Result<HandPose> GloveHandSource::pose_at(Handedness hand, TimeNs t_ns) {
  if (!available(hand)) {
    return make_error(Errc::unavailable, std::string("the glove source serves the ") +
                                             std::string(to_string(options_.tracker.hand)) + " hand only");
  }
  std::lock_guard lock(mutex_);
  auto q = history_.query(t_ns);
  if (!q) return q.error();
  return q->pose;
}

PoseLookup GloveHandSource::lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept {
  if (!available(hand)) return PoseLookup::empty;
  std::lock_guard lock(mutex_);
  return history_.lookup(t_ns, out);
}

GloveSourceStats GloveHandSource::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

}  // namespace proprio::stretch_glove
