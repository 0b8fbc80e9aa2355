#pragma once
// A HandSource that plays back the HandPose streams of a session recording
// (docs/recording-format.md), so trackers' consumers (OpenXR layer, engine,
// analysis) run on recorded sessions exactly as on live ones.
#include <filesystem>
#include <string>
#include <vector>

#include "proprio/core/hand_source.hpp"
#include "proprio/core/pose_history.hpp"
#include "proprio/core/recording.hpp"

namespace proprio {

struct ReplayOptions {
  // Which HandPose streams to play. Non-empty: the stream with exactly this
  // name, or else every stream whose name contains it. Empty: per hand, the
  // streams whose name lacks "ground_truth" (tracker output), falling back to
  // the ground-truth ones. Each hand must end up with exactly one stream.
  std::string stream_name_filter;
  DurationNs time_offset_ns = 0;  // file time = t - time_offset_ns
  DurationNs max_interpolation_gap_ns = 200 * kNsPerMillisecond;  // wider gaps are reported, not bridged
  DurationNs max_prediction_ns = 0;  // past the last sample: 0 serves recorded time only
  bool loop = false;  // play the recording over and over (time wraps at its end)
};

struct FileTimeRange {
  TimeNs first_ns = 0;  // earliest and latest pose of either hand, in file time
  TimeNs last_ns = 0;
};

struct ReplayStream {
  std::string name;
  Handedness hand = Handedness::right;
  std::size_t samples = 0;  // poses loaded
};

class ReplayHandSource final : public HandSource {
 public:
  // Loads the selected poses into memory. Errors: those of RecordingReader::open,
  // Errc::not_found (no HandPose stream matches), Errc::invalid_argument (a hand
  // has poses in several selected streams), Errc::unavailable (no poses at all).
  static Result<ReplayHandSource> open(const std::filesystem::path& path, ReplayOptions options = {});

  std::string_view name() const noexcept override { return "replay"; }
  bool available(Handedness hand) const noexcept override;
  // Errc::out_of_range outside the recorded span (after the offset mapping),
  // Errc::unavailable for a hand without poses or inside a gap.
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override;
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override;

  FileTimeRange file_time_range() const noexcept { return range_; }
  DurationNs time_offset_ns() const noexcept { return offset_ns_; }
  // E.g. set_time_offset_ns(now - file_time_range().first_ns) to start playing now.
  void set_time_offset_ns(DurationNs offset_ns) noexcept { offset_ns_ = offset_ns; }

  const std::vector<ReplayStream>& streams() const noexcept { return streams_; }
  const RecordingSummary& recording_summary() const noexcept { return summary_; }
  // Poses of the selected streams left out because they were not newer than
  // the previous one (records the reader rejected: recording_summary()).
  std::size_t skipped_samples() const noexcept { return skipped_; }

 private:
  ReplayHandSource() = default;
  const PoseHistory& history(Handedness hand) const { return histories_[static_cast<std::size_t>(hand)]; }
  bool to_file_time(TimeNs t_ns, TimeNs& file_t) const noexcept;

  std::string path_;
  std::vector<PoseHistory> histories_;  // indexed by Handedness
  FileTimeRange range_;
  DurationNs offset_ns_ = 0;
  bool loop_ = false;
  std::vector<ReplayStream> streams_;
  RecordingSummary summary_;
  std::size_t skipped_ = 0;
};

}  // namespace proprio
