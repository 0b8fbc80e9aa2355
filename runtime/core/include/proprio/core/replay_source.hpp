#pragma once
// A HandSource that plays back the HandPose streams of a session recording
// (docs/recording-format.md), so trackers' consumers (OpenXR layer, engine,
// analysis) run on recorded sessions exactly as on live ones.
//
// The recording is streamed, not loaded: open() indexes it in one pass, and a
// reader thread keeps a small window of poses per hand around the latest
// lookup, so memory stays the same for a 10-second and a 10-hour file, and
// lookup() never touches the file, never allocates and never waits on I/O.
#include <filesystem>
#include <memory>
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
  // A pose this much later than the previous one is an outlier (a wall-clock
  // stamp, a flipped bit) unless the next pose confirms the new timeline
  // (TimestampGuard); outliers are left out and counted in skipped_samples().
  DurationNs max_time_jump_ns = TimestampGuard::kDefaultMaxJumpNs;
  // Memory: poses kept per hand around the last lookup, and entries of the
  // per-hand index of file offsets (halved by dropping every other entry when
  // full, so a longer file only spaces the entries further apart).
  std::size_t window_samples = 256;
  std::size_t max_index_entries = 4096;

  Status validate() const;
};

struct FileTimeRange {
  TimeNs first_ns = 0;  // earliest and latest pose of either hand, in file time
  TimeNs last_ns = 0;
};

struct ReplayStream {
  std::string name;
  Handedness hand = Handedness::right;
  std::size_t samples = 0;  // poses that will be played
};

class ReplayHandSource final : public HandSource {
 public:
  // Indexes the selected poses. Errors: those of RecordingReader::open,
  // Errc::not_found (no HandPose stream matches), Errc::invalid_argument (a hand
  // has poses in several selected streams, or bad options), Errc::unavailable
  // (no poses at all).
  static Result<ReplayHandSource> open(const std::filesystem::path& path, ReplayOptions options = {});
  ReplayHandSource(ReplayHandSource&&) noexcept;
  ReplayHandSource& operator=(ReplayHandSource&&) noexcept;
  ~ReplayHandSource() override;

  std::string_view name() const noexcept override { return "replay"; }
  bool available(Handedness hand) const noexcept override;
  // Errc::out_of_range outside the recorded span (after the offset mapping),
  // Errc::unavailable for a hand without poses or inside a gap.
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override;
  // Answers from the window only. Where the reader has not caught up with t
  // yet (a jump in time, a loop starting over), it answers as for a history
  // that ends (PoseLookup::stale, with the newest pose read) or starts
  // (PoseLookup::too_old) there, and the reader moves to t. pose_at() waits
  // for the reader instead.
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override;
  // Waits until every hand's window covers t_ns, so that lookup(t_ns) answers
  // as if the whole file were loaded. False if reading failed (read_failed()).
  bool wait_until_buffered(TimeNs t_ns);
  // Tests: stops the reader thread from reading until called with false.
  void pause_reading_for_testing(bool paused);

  FileTimeRange file_time_range() const noexcept { return range_; }
  DurationNs time_offset_ns() const noexcept { return offset_ns_; }
  // E.g. set_time_offset_ns(now - file_time_range().first_ns) to start playing now.
  void set_time_offset_ns(DurationNs offset_ns) noexcept { offset_ns_ = offset_ns; }

  const std::vector<ReplayStream>& streams() const noexcept { return streams_; }
  const RecordingSummary& recording_summary() const noexcept { return summary_; }
  // Poses of the selected streams left out because they were not newer than
  // the previous one or were isolated time jumps (records the reader
  // rejected: recording_summary()).
  std::size_t skipped_samples() const noexcept { return skipped_; }
  // What the source holds in memory now: poses in the windows and index
  // entries, over both hands. Bounded by the options, whatever the file's length.
  std::size_t buffered_samples() const noexcept;
  std::size_t index_entries() const noexcept;
  // The reader failed to read the file (it changed or vanished after open());
  // lookups then answer PoseLookup::empty.
  bool read_failed() const noexcept;

 private:
  struct Stream;
  ReplayHandSource();
  bool to_file_time(TimeNs t_ns, TimeNs& file_t) const noexcept;

  std::string path_;
  std::unique_ptr<Stream> stream_;  // per-hand windows and indices, and the reader thread filling them
  FileTimeRange range_;
  DurationNs offset_ns_ = 0;
  bool loop_ = false;
  std::vector<ReplayStream> streams_;
  RecordingSummary summary_;
  std::size_t skipped_ = 0;
};

// What a replay file holds and what is wrong with it, without playing it: for
// `proprio layer status` and for the OpenXR layer's start-up warning.
struct ReplayCheck {
  RecordingSummary summary;         // integrity (clean, truncated, corrupt regions ...)
  std::vector<ReplayStream> streams;  // what would be played
  std::size_t skipped_samples = 0;  // out-of-order or outlier poses left out
  // True when something was lost or rejected (summary not clean, skipped
  // samples, or the file grew no End record); `problem` then says what.
  bool damaged = false;
  std::string problem;
};
// Errors are those of ReplayHandSource::open (not a recording, no hand poses ...).
Result<ReplayCheck> check_replay_file(const std::filesystem::path& path, const ReplayOptions& options = {});
// One line for users about a damaged replay ("" when intact), e.g.
// "'x.prec' is damaged: 1234 damaged bytes skipped ...; replaying what could be read".
std::string describe_replay_problem(const std::string& path, const RecordingSummary& summary, std::size_t skipped);

}  // namespace proprio
