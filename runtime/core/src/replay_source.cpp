#include "proprio/core/replay_source.hpp"

#include <algorithm>
#include <array>
#include <iterator>
#include <map>
#include <mutex>
#include <optional>
#include <utility>

#include "proprio/core/file_io.hpp"

namespace proprio {

namespace {

constexpr std::string_view kGroundTruth = "ground_truth";

std::string quoted_names(const std::vector<const StreamInfo*>& streams, bool with_kind) {
  std::string out;
  for (const StreamInfo* s : streams) {
    out += (out.empty() ? "'" : ", '") + s->name + "'";
    if (with_kind) out += " (" + std::string(to_string(s->kind)) + ")";
  }
  return out.empty() ? "none" : out;
}

using PoseCounts = std::map<std::pair<StreamId, Handedness>, std::size_t>;

// Visits every HandPose in the file with its record's offset; records the
// reader rejects are left out.
template <typename F>
Result<RecordingReader> for_each_pose(const std::filesystem::path& path, F&& visit) {
  auto reader = RecordingReader::open(path);
  if (!reader) return reader.error();
  for (;;) {
    auto rec = reader->next();
    if (!rec) {
      if (rec.error().code != Errc::parse_error) return rec.error();
      continue;
    }
    if (!*rec) break;
    if (const auto* pose = std::get_if<HandPose>(&(*rec)->payload)) {
      visit((*rec)->stream, *pose, reader->last_record_offset());
    }
  }
  return reader;
}

}  // namespace

// One hand's replay: its stream, where its poses are in the file, and a window
// of consecutive poses read from there.
struct HandTrack {
  Handedness hand = Handedness::left;
  std::optional<StreamId> stream;
  std::size_t samples = 0;
  TimeNs first_ns = 0, last_ns = 0;
  std::uint64_t first_offset = 0;  // the stream's first pose record: where replay starts afresh
  struct Entry {
    TimeNs time_ns;
    std::uint64_t offset;  // a pose accepted with nothing held: reading resumes there exactly
  };
  std::vector<Entry> index;
  std::size_t stride = 1, since_entry = 0;

  // Streaming state.
  std::optional<RecordingReader> reader;
  PoseHistory window;
  TimestampGuard guard;
  HandPose held;
  bool at_end = false;
  bool failed = false;

  DurationNs max_jump_ns;

  HandTrack(const PoseHistoryOptions& ho, DurationNs max_jump) : window(ho), guard(max_jump), max_jump_ns(max_jump) {}
};

struct ReplayHandSource::Stream {
  std::mutex mutex;
  std::vector<HandTrack> hands;  // indexed by Handedness
  std::size_t max_index_entries = 4096;
};

namespace {

// Applies the time-stamp rules of one hand's stream, in file order. The same
// code indexes the file in open() and fills the windows afterwards, so both
// agree on every pose.
template <typename Accept>
void feed_pose(HandTrack& k, const HandPose& p, std::size_t& skipped, Accept&& accept) {
  const TimestampGuard::Step step = k.guard.check(p.time_ns);
  if (step.release_held) accept(k.held, false);
  if (step.reject_held) ++skipped;
  if (step.accept) {
    accept(p, true);
  } else if (step.hold) {
    k.held = p;
  } else {
    ++skipped;
  }
}

std::size_t hand_index(Handedness h) { return static_cast<std::size_t>(h); }

}  // namespace

Result<ReplayHandSource> ReplayHandSource::open(const std::filesystem::path& path, ReplayOptions options) {
  const std::string file = "'" + printable(path.string(), 300) + "'";
  if (auto v = options.validate(); !v) return v.error();

  // Pass 1 finds the streams and which hands each holds; pass 2 indexes the
  // chosen ones.
  PoseCounts counts;
  auto scan = for_each_pose(path, [&](StreamId id, const HandPose& p, std::uint64_t) { ++counts[{id, p.hand}]; });
  if (!scan) return scan.error();

  std::vector<const StreamInfo*> pose_streams, all_streams;
  for (const StreamInfo& s : scan->streams()) {
    all_streams.push_back(&s);
    if (s.kind == StreamKind::hand_pose) pose_streams.push_back(&s);
  }
  if (pose_streams.empty()) {
    return make_error(Errc::not_found, "recording " + file + " holds no hand_pose stream to replay (its streams: " +
                                           quoted_names(all_streams, true) + ")");
  }

  const std::string& filter = options.stream_name_filter;
  const bool exact = std::any_of(pose_streams.begin(), pose_streams.end(),
                                 [&](const StreamInfo* s) { return s->name == filter; });
  const auto selected = [&](const StreamInfo& s) {
    return exact ? s.name == filter : s.name.find(filter) != std::string::npos;
  };
  if (!filter.empty() && std::none_of(pose_streams.begin(), pose_streams.end(),
                                      [&](const StreamInfo* s) { return selected(*s); })) {
    return make_error(Errc::not_found, "no hand_pose stream of recording " + file + " matches '" + filter +
                                           "'; its hand_pose streams are: " + quoted_names(pose_streams, false));
  }

  ReplayHandSource src;
  std::array<std::optional<StreamId>, 2> chosen;
  for (const Handedness hand : {Handedness::left, Handedness::right}) {
    std::vector<const StreamInfo*> candidates;
    for (const StreamInfo* s : pose_streams) {
      if (counts.count({s->id, hand}) && selected(*s)) candidates.push_back(s);
    }
    if (filter.empty()) {
      std::vector<const StreamInfo*> tracked;
      std::copy_if(candidates.begin(), candidates.end(), std::back_inserter(tracked),
                   [](const StreamInfo* s) { return s->name.find(kGroundTruth) == std::string::npos; });
      if (!tracked.empty()) candidates = std::move(tracked);
    }
    if (candidates.size() > 1) {
      return make_error(Errc::invalid_argument, "recording " + file + " has " + std::string(to_string(hand)) +
                                                    "-hand poses in several streams (" +
                                                    quoted_names(candidates, false) +
                                                    "); pick one with ReplayOptions::stream_name_filter");
    }
    if (candidates.empty()) continue;
    const StreamInfo& s = *candidates.front();
    chosen[static_cast<std::size_t>(hand)] = s.id;
    src.streams_.push_back({s.name, hand, 0});
  }
  if (src.streams_.empty()) {
    return make_error(Errc::unavailable, "recording " + file + " has no hand poses in its hand_pose streams (" +
                                             quoted_names(pose_streams, false) + ")");
  }

  PoseHistoryOptions ho;
  ho.capacity = options.window_samples;
  ho.max_prediction_ns = options.max_prediction_ns;
  ho.max_interpolation_gap_ns = options.max_interpolation_gap_ns;
  auto& hands = src.stream_->hands;
  for (std::size_t h = 0; h < 2; ++h) {
    hands.emplace_back(ho, options.max_time_jump_ns);
    hands.back().hand = static_cast<Handedness>(h);
    hands.back().stream = chosen[h];
  }
  src.stream_->max_index_entries = options.max_index_entries;
  std::size_t skipped = 0;
  const auto index_pose = [&](HandTrack& k, const HandPose& p, std::uint64_t offset) {
    feed_pose(k, p, skipped, [&](const HandPose& q, bool direct) {
      if (k.samples++ == 0) k.first_ns = q.time_ns;
      k.last_ns = q.time_ns;
      // An entry only where nothing is held, so that reading can restart there
      // with the guard in the same state.
      if (!direct || k.guard.holding() || ++k.since_entry < k.stride) return;
      k.since_entry = 0;
      k.index.push_back({q.time_ns, offset});
      if (k.index.size() >= src.stream_->max_index_entries) {
        std::size_t w = 0;
        for (std::size_t r = 0; r < k.index.size(); r += 2) k.index[w++] = k.index[r];
        k.index.resize(w);
        k.stride *= 2;
      }
    });
  };
  std::array<bool, 2> seen{};
  auto load = for_each_pose(path, [&](StreamId id, const HandPose& p, std::uint64_t offset) {
    const std::size_t h = hand_index(p.hand);
    HandTrack& k = hands[h];
    if (k.stream != id) return;
    if (!seen[h]) k.first_offset = offset, seen[h] = true;
    index_pose(k, p, offset);
  });
  if (!load) return load.error();
  for (HandTrack& k : hands) {
    if (k.guard.finish()) {
      if (k.samples++ == 0) k.first_ns = k.held.time_ns;
      k.last_ns = k.held.time_ns;
    } else if (k.guard.holding()) {
      ++skipped;
    }
  }
  // The pass-1 reader knows every stream too: one reader per hand, each
  // moving through the file at its own pace.
  for (std::size_t h = 0; h < 2; ++h) {
    if (!hands[h].stream) continue;
    if (h == 0 || !hands[0].stream) {
      hands[h].reader.emplace(std::move(*scan));
    } else {
      hands[h].reader.emplace(std::move(*load));
    }
  }

  bool first = true;
  for (ReplayStream& s : src.streams_) {
    const HandTrack& k = hands[hand_index(s.hand)];
    s.samples = k.samples;
    if (k.samples == 0) continue;
    src.range_.first_ns = first ? k.first_ns : std::min(src.range_.first_ns, k.first_ns);
    src.range_.last_ns = first ? k.last_ns : std::max(src.range_.last_ns, k.last_ns);
    first = false;
  }
  if (first) {
    return make_error(Errc::unavailable, "recording " + file + " has no playable hand poses: every pose of " +
                                             quoted_names(pose_streams, false) +
                                             " was out of order or an isolated time jump");
  }
  src.summary_ = hands[hand_index(src.streams_.front().hand)].reader->summary();
  src.skipped_ = skipped;
  src.path_ = path.string();
  src.offset_ns_ = options.time_offset_ns;
  src.loop_ = options.loop;
  return src;
}

namespace {

// Reads the next pose of the hand's stream into the window. False at the end.
bool read_forward(HandTrack& k) {
  std::size_t ignored = 0;
  while (!k.at_end) {
    auto rec = k.reader->next();
    if (!rec) continue;  // a rejected record: the index pass left it out too
    bool pushed = false;
    if (!*rec) {
      k.at_end = true;
      if (k.guard.finish()) pushed = k.window.push(k.held).ok();
      return pushed;
    }
    const auto* p = std::get_if<HandPose>(&(*rec)->payload);
    if (!p || (*rec)->stream != *k.stream || p->hand != k.hand) continue;
    feed_pose(k, *p, ignored, [&](const HandPose& q, bool) { pushed = k.window.push(q).ok() || pushed; });
    if (pushed) return true;
  }
  return false;
}

// Puts the window of hand k around file time t: afterwards it holds the poses
// bracketing t (or the first pose, for t before it; or the last, for t after
// it), exactly those a fully loaded history would use.
void fill_window(HandTrack& k, TimeNs t) {
  const auto restart_at = [&](std::uint64_t offset) {
    k.window.clear();
    k.at_end = false;
    if (!k.reader->seek(offset)) k.failed = true;
  };
  const auto from_start = [&] {
    restart_at(k.first_offset);
    k.guard = TimestampGuard(k.max_jump_ns);
  };
  // The last index entry at or before t, if reading forward would pass it anyway.
  const auto entry_for = [&](TimeNs t_ns) -> const HandTrack::Entry* {
    auto it = std::upper_bound(k.index.begin(), k.index.end(), t_ns,
                               [](TimeNs v, const HandTrack::Entry& e) { return v < e.time_ns; });
    return it == k.index.begin() ? nullptr : &*std::prev(it);
  };
  const auto jump_to = [&](const HandTrack::Entry& e) {
    restart_at(e.offset);
    auto rec = k.reader->next();
    const HandPose* p = rec && *rec ? std::get_if<HandPose>(&(*rec)->payload) : nullptr;
    if (!p || p->time_ns != e.time_ns) {
      k.failed = true;  // the file changed under us
      return;
    }
    k.guard.reset(p->time_ns);
    (void)k.window.push(*p);
  };

  const bool before_window = k.window.empty() || t < k.window.oldest_time_ns();
  if (t <= k.first_ns) {
    if (k.window.empty() || k.window.oldest_time_ns() != k.first_ns) from_start();
  } else if (before_window) {
    if (const auto* e = entry_for(t)) {
      jump_to(*e);
    } else {
      from_start();
    }
  } else if (t > k.window.newest_time_ns()) {
    if (const auto* e = entry_for(t); e && e->time_ns > k.window.newest_time_ns()) jump_to(*e);
  }
  const TimeNs until = std::min(t, k.last_ns);
  while (!k.failed && (k.window.empty() || k.window.newest_time_ns() < until)) {
    if (!read_forward(k)) break;
  }
}

}  // namespace

ReplayHandSource::ReplayHandSource() : stream_(std::make_unique<Stream>()) {}
ReplayHandSource::ReplayHandSource(ReplayHandSource&&) noexcept = default;
ReplayHandSource& ReplayHandSource::operator=(ReplayHandSource&&) noexcept = default;
ReplayHandSource::~ReplayHandSource() = default;

Status ReplayOptions::validate() const {
  if (window_samples < 2) {
    return make_error(Errc::invalid_argument, "ReplayOptions: window_samples must be at least 2, got " +
                                                  std::to_string(window_samples));
  }
  if (max_index_entries < 2) {
    return make_error(Errc::invalid_argument, "ReplayOptions: max_index_entries must be at least 2, got " +
                                                  std::to_string(max_index_entries));
  }
  if (max_time_jump_ns <= 0 || max_interpolation_gap_ns < 0 || max_prediction_ns < 0) {
    return make_error(Errc::invalid_argument,
                      "ReplayOptions: max_time_jump_ns must be positive, max_interpolation_gap_ns and "
                      "max_prediction_ns not negative");
  }
  return {};
}

bool ReplayHandSource::to_file_time(TimeNs t_ns, TimeNs& file_t) const noexcept {
  if (__builtin_sub_overflow(t_ns, offset_ns_, &file_t)) return false;
  DurationNs span = 0;
  if (loop_ && !__builtin_sub_overflow(range_.last_ns, range_.first_ns, &span) && span > 0) {
    DurationNs rel = 0;
    if (__builtin_sub_overflow(file_t, range_.first_ns, &rel)) return false;
    DurationNs into = rel % span;
    if (into < 0) into += span;
    file_t = range_.first_ns + into;
  }
  return true;
}

PoseLookup ReplayHandSource::lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept {
  if (!available(hand)) return PoseLookup::empty;
  TimeNs file_t = 0;
  if (!to_file_time(t_ns, file_t)) return PoseLookup::too_old;
  std::lock_guard lock(stream_->mutex);
  HandTrack& k = stream_->hands[hand_index(hand)];
  fill_window(k, file_t);
  if (k.failed || k.window.empty()) return PoseLookup::empty;
  const PoseLookup r = k.window.lookup(file_t, out);
  if (is_usable(r)) out.time_ns = t_ns;
  if (r == PoseLookup::stale) out.time_ns += t_ns - file_t;  // back to the caller's clock
  return r;
}

bool ReplayHandSource::available(Handedness hand) const noexcept {
  const auto h = hand_index(hand);
  return stream_ && h < stream_->hands.size() && stream_->hands[h].samples > 0;
}

std::size_t ReplayHandSource::buffered_samples() const noexcept {
  std::lock_guard lock(stream_->mutex);
  std::size_t n = 0;
  for (const HandTrack& k : stream_->hands) n += k.window.size();
  return n;
}

std::size_t ReplayHandSource::index_entries() const noexcept {
  std::lock_guard lock(stream_->mutex);
  std::size_t n = 0;
  for (const HandTrack& k : stream_->hands) n += k.index.size();
  return n;
}

bool ReplayHandSource::read_failed() const noexcept {
  std::lock_guard lock(stream_->mutex);
  return std::any_of(stream_->hands.begin(), stream_->hands.end(), [](const HandTrack& k) { return k.failed; });
}

Result<HandPose> ReplayHandSource::pose_at(Handedness hand, TimeNs t_ns) {
  const std::string hand_name(to_string(hand));
  if (!available(hand)) {
    return make_error(Errc::unavailable, "replay of '" + path_ + "' has no " + hand_name + "-hand poses");
  }
  TimeNs file_t = 0;
  if (!to_file_time(t_ns, file_t)) {
    return make_error(Errc::out_of_range, "replay of '" + path_ + "': t=" + std::to_string(t_ns) +
                                              " ns minus the time offset overflows");
  }
  std::lock_guard lock(stream_->mutex);
  HandTrack& k = stream_->hands[hand_index(hand)];
  fill_window(k, file_t);
  if (k.failed || k.window.empty()) {
    return make_error(Errc::io_error, "replay of '" + path_ + "': the file changed or became unreadable after it "
                                      "was opened; open it again");
  }
  auto q = k.window.query(file_t);
  if (!q) {
    return q.error().with_context("replay of '" + path_ + "', " + hand_name + " hand at t=" +
                                  std::to_string(t_ns) + " ns (file time " + std::to_string(file_t) +
                                  " ns; the recording spans " + std::to_string(range_.first_ns) + ".." +
                                  std::to_string(range_.last_ns) + " ns, time offset " +
                                  std::to_string(offset_ns_) + " ns)");
  }
  HandPose pose = std::move(q.value().pose);
  pose.time_ns = t_ns;
  return pose;
}

std::string describe_replay_problem(const std::string& path, const RecordingSummary& summary, std::size_t skipped) {
  std::string what;
  if (summary.end == RecordingEnd::corrupt) {
    what = "is damaged: " + summary.detail;
  } else if (summary.end == RecordingEnd::truncated) {
    what = "is cut short: " + summary.detail;
  } else if (summary.end == RecordingEnd::missing_end) {
    what = "was not closed by its writer: " + summary.detail;
  } else if (summary.invalid_records > 0) {
    what = "has " + std::to_string(summary.invalid_records) + " records with invalid content";
  }
  if (skipped > 0) {
    what += (what.empty() ? "has " : "; ") + std::to_string(skipped) +
            " hand poses out of time order or with isolated time jumps, left out";
  }
  if (what.empty()) return {};
  return "replay file '" + printable(path, 300) + "' " + printable(what, 600) + "; replaying what could be read";
}

Result<ReplayCheck> check_replay_file(const std::filesystem::path& path, const ReplayOptions& options) {
  auto src = ReplayHandSource::open(path, options);
  if (!src) return src.error();
  ReplayCheck c;
  c.summary = src->recording_summary();
  c.streams = src->streams();
  c.skipped_samples = src->skipped_samples();
  c.problem = describe_replay_problem(path.string(), c.summary, c.skipped_samples);
  c.damaged = !c.problem.empty();
  return c;
}

}  // namespace proprio
