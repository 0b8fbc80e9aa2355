#pragma once
// The stretch glove as a HandSource ("glove"): the read-out board's
// measurements go in (from its reader thread, or a simulator), hand poses come
// out of a PoseHistory that consumers query from any thread.
//
// The pipeline runs in the producer's thread: at ~960 measurements/s it
// solves and infers once per 16 (≈60 Hz, well under a millisecond each), so a
// separate worker would only add latency.
#include <memory>
#include <mutex>
#include <string>

#include "proprio/core/hand_source.hpp"
#include "proprio/core/pose_history.hpp"
#include "proprio/stretch_glove/glove_tracker.hpp"
#include "proprio/stretch_glove/readout.hpp"

namespace proprio::stretch_glove {

struct GloveHandSourceOptions {
  GloveTrackerOptions tracker;
  ReadoutOptions readout;
  PoseHistoryOptions history;
  std::string describe() const;
};

struct GloveSourceStats {
  GloveTrackerStats tracker;
  std::uint64_t measurements = 0;
  std::uint64_t measurements_rejected = 0;  // NaN, negative or saturated
  std::uint64_t poses_published = 0;
  std::uint64_t poses_rejected = 0;  // not newer than the previous pose
  std::string describe() const;
};

class GloveHandSource final : public HandSource {
 public:
  static Result<std::unique_ptr<GloveHandSource>> create(const StretchGloveLayout& layout,
                                                         MinMaxCalibration calibration, OnnxPoseModel model,
                                                         GloveHandSourceOptions options = {});

  std::string_view name() const noexcept override { return "glove"; }
  bool available(Handedness hand) const noexcept override { return hand == options_.tracker.hand; }
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override;
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override;

  // One producer thread at a time. Returns true when a new pose was published.
  bool push_measurement(std::size_t combination, double capacitance_pf, TimeNs t_ns);
  bool push_frame(const CellFrame& frame);
  // The same for measurements that arrive in bursts (a read-out board's
  // reports): add_measurement() only records; end_burst() makes the frame
  // that fell due during the burst, if any, from all of it (MatrixReadout::
  // record), so the pose carries the newest measurement in hand.
  void add_measurement(std::size_t combination, double capacitance_pf, TimeNs t_ns);
  bool end_burst();

  // Producer thread only (or before the first push).
  void set_wrist_provider(WristPoseProvider provider) { tracker_.set_wrist_provider(std::move(provider)); }
  GloveSourceStats stats() const;
  const GloveHandSourceOptions& options() const noexcept { return options_; }

 private:
  GloveHandSource(GloveHandSourceOptions options, MatrixReadout readout, GloveTracker tracker);

  GloveHandSourceOptions options_;
  MatrixReadout readout_;  // producer thread
  GloveTracker tracker_;   // producer thread
  CellFrame frame_;
  HandPose pose_;
  mutable std::mutex mutex_;  // guards history_ and stats_
  PoseHistory history_;
  GloveSourceStats stats_;
};

}  // namespace proprio::stretch_glove
