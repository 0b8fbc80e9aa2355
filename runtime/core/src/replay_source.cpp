#include "proprio/core/replay_source.hpp"

#include <algorithm>
#include <array>
#include <condition_variable>
#include <iterator>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <system_error>
#include <thread>
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

// Times of the poses in a hand's window, oldest first: the reader thread's own
// copy, so that it decides what to read next without taking the lock.
class TimeRing {
 public:
  explicit TimeRing(std::size_t capacity) : t_(capacity) {}
  void clear() noexcept { head_ = size_ = 0; }
  void push(TimeNs t) noexcept {
    if (size_ == t_.size()) {
      head_ = (head_ + 1) % t_.size();
      --size_;
    }
    t_[(head_ + size_++) % t_.size()] = t;
  }
  bool empty() const noexcept { return size_ == 0; }
  bool full() const noexcept { return size_ == t_.size(); }
  std::size_t size() const noexcept { return size_; }
  TimeNs oldest() const noexcept { return t_[head_]; }
  TimeNs newest() const noexcept { return t_[(head_ + size_ - 1) % t_.size()]; }
  TimeNs at(std::size_t i) const noexcept { return t_[(head_ + i) % t_.size()]; }  // 0 = oldest
  std::size_t count_after(TimeNs t) const noexcept {
    std::size_t n = 0;
    while (n < size_ && t_[(head_ + size_ - 1 - n) % t_.size()] > t) ++n;
    return n;
  }

 private:
  std::vector<TimeNs> t_;
  std::size_t head_ = 0, size_ = 0;
};

// One hand's replay: its stream, where its poses are in the file, and a window
// of consecutive poses that the reader thread keeps around the latest lookup.
struct HandTrack {
  // Fixed once open() returns.
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
  DurationNs max_jump_ns;

  // The reader thread's alone (open()'s before the thread starts).
  std::optional<RecordingReader> reader;
  TimestampGuard guard;
  HandPose held;
  std::array<HandPose, 2> pending;  // accepted, not yet in the window (the guard may release two at once)
  std::size_t pending_count = 0;
  bool at_end = false;
  TimeRing times;

  // Shared, under Stream::mutex; only the reader thread changes the window.
  PoseHistory window;
  TimeNs requested_ns = 0;  // file time of the latest lookup
  bool failed = false;
  // While the reader waits: requests in [quiet_from_ns, quiet_until_ns) give
  // it nothing to do, so they need not wake it (most lookups, frame to frame).
  TimeNs quiet_from_ns = 0, quiet_until_ns = 0;

  HandTrack(const PoseHistoryOptions& ho, DurationNs max_jump)
      : max_jump_ns(max_jump), guard(max_jump), times(ho.capacity), window(ho) {}
  bool playable() const noexcept { return stream && samples > 0; }
};

// Lookups come from the host app's frame thread (the OpenXR layer), which must
// never wait on the disk nor allocate: a reader thread does all file reading
// and keeps each hand's window ahead of (and a little behind) the latest
// lookup; lookups only copy from the window under a short lock.
struct ReplayHandSource::Stream {
  std::mutex mutex;
  std::condition_variable wake;      // to the reader: a request moved, or stop
  std::condition_variable progress;  // to waiters: a window changed or a read failed
  std::vector<HandTrack> hands;      // indexed by Handedness
  std::size_t max_index_entries = 4096;
  std::uint64_t requests = 0;  // counts request moves
  bool stop = false;
  bool paused = false;
  std::thread thread;

  ~Stream() {
    {
      std::lock_guard lock(mutex);
      stop = true;
    }
    wake.notify_all();
    if (thread.joinable()) thread.join();
  }

  // Under the lock: points hand k's reader at file time t. True if it moved.
  bool request(HandTrack& k, TimeNs t) noexcept {
    if (k.requested_ns == t) return false;
    k.requested_ns = t;
    if (t >= k.quiet_from_ns && t < k.quiet_until_ns) return false;
    ++requests;
    return true;
  }
  // Under the lock: the window answers for t exactly as the whole stream would.
  static bool covered(const HandTrack& k, TimeNs t) noexcept {
    if (k.window.empty()) return false;
    return (t >= k.window.oldest_time_ns() || k.window.oldest_time_ns() == k.first_ns) &&
           (t <= k.window.newest_time_ns() || k.window.newest_time_ns() == k.last_ns);
  }
  // Waits (not on hot paths) until hand k's window covers t; false if reading failed.
  bool wait_covered(std::unique_lock<std::mutex>& lock, HandTrack& k, TimeNs t) {
    if (request(k, t)) wake.notify_one();
    progress.wait(lock, [&] {
      if (k.failed || stop || paused || covered(k, t)) return true;
      if (request(k, t)) wake.notify_one();  // another caller moved it meanwhile
      return false;
    });
    return !k.failed && !k.window.empty();
  }

  bool step(HandTrack& k);
  void set_quiet_range(HandTrack& k) noexcept;
  void run() noexcept;
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

  // The first window is read here, so that playing from the start answers at
  // once; the reader thread takes over from there.
  Stream& st = *src.stream_;
  for (HandTrack& k : hands) k.requested_ns = k.first_ns;
  for (bool worked = true; worked;) {
    worked = false;
    for (HandTrack& k : hands) {
      if (k.playable()) worked = st.step(k) || worked;
    }
  }
  try {
    st.thread = std::thread([&st] { st.run(); });
  } catch (const std::system_error& e) {
    return make_error(Errc::unavailable, "cannot start the reader thread to replay " + file + ": " + e.what());
  }
  return src;
}

namespace {

// Reads the hand's stream on to its next accepted pose(s), into k.pending.
// False at the end of the file, or on a read error (then k.at_end and failed).
bool read_forward(HandTrack& k, bool& failed) {
  std::size_t ignored = 0;
  while (!k.at_end) {
    auto rec = k.reader->next();
    if (!rec) {
      if (rec.error().code == Errc::parse_error) continue;  // a rejected record: the index pass left it out too
      failed = k.at_end = true;
      return false;
    }
    if (!*rec) {
      k.at_end = true;
      if (k.guard.finish()) k.pending[k.pending_count++] = k.held;
      break;
    }
    const auto* p = std::get_if<HandPose>(&(*rec)->payload);
    if (!p || (*rec)->stream != *k.stream || p->hand != k.hand) continue;
    feed_pose(k, *p, ignored, [&](const HandPose& q, bool) { k.pending[k.pending_count++] = q; });
    if (k.pending_count > 0) return true;
  }
  return k.pending_count > 0;
}

// The last index entry at or before t, if any.
const HandTrack::Entry* entry_for(const HandTrack& k, TimeNs t) {
  auto it = std::upper_bound(k.index.begin(), k.index.end(), t,
                             [](TimeNs v, const HandTrack::Entry& e) { return v < e.time_ns; });
  return it == k.index.begin() ? nullptr : &*std::prev(it);
}

}  // namespace

// One piece of work for hand k: moving its reader to where the request is
// (the window then starts afresh), and/or one more pose into the window. The
// window ends up holding the poses bracketing the requested time (or the
// first pose, before it; the last, after it), exactly those a fully loaded
// history would use, plus up to half its capacity ahead and a quarter behind.
// False when there is nothing to do until the request moves.
bool ReplayHandSource::Stream::step(HandTrack& k) {
  TimeNs t = 0;
  {
    std::lock_guard lock(mutex);
    if (k.failed || paused || stop) return false;
    t = k.requested_ns;
  }
  const auto fail = [&] {
    {
      std::lock_guard lock(mutex);
      k.failed = true;  // the file changed or vanished under us
    }
    progress.notify_all();
    return false;
  };
  const auto push = [&](const HandPose& p) {
    if (!k.times.empty() && p.time_ns <= k.times.newest()) return;  // cannot happen: the guard orders them
    {
      std::lock_guard lock(mutex);
      (void)k.window.push(p);
    }
    k.times.push(p.time_ns);
    progress.notify_all();
  };
  const auto restart_at = [&](std::uint64_t offset) {
    {
      std::lock_guard lock(mutex);
      k.window.clear();
    }
    k.times.clear();
    k.pending_count = 0;
    k.at_end = false;
    return k.reader->seek(offset).ok();
  };
  const auto from_start = [&] {
    if (!restart_at(k.first_offset)) return false;
    k.guard = TimestampGuard(k.max_jump_ns);
    bool read_error = false;
    if (!read_forward(k, read_error) || k.pending[0].time_ns != k.first_ns) return false;
    return true;  // pending[0] goes in below
  };
  const auto jump_to = [&](const HandTrack::Entry& e) {
    if (!restart_at(e.offset)) return false;
    auto rec = k.reader->next();
    const HandPose* p = rec && *rec ? std::get_if<HandPose>(&(*rec)->payload) : nullptr;
    if (!p || p->time_ns != e.time_ns) return false;
    k.guard.reset(p->time_ns);
    push(*p);
    return true;
  };

  bool worked = false;
  if (t <= k.first_ns) {
    if (k.times.empty() || k.times.oldest() != k.first_ns) {
      if (!from_start()) return fail();
      worked = true;
    }
  } else if (k.times.empty() || t < k.times.oldest()) {
    const HandTrack::Entry* e = entry_for(k, t);
    if (!(e ? jump_to(*e) : from_start())) return fail();
    worked = true;
  } else if (t > k.times.newest()) {
    if (const auto* e = entry_for(k, t); e && e->time_ns > k.times.newest()) {
      if (!jump_to(*e)) return fail();
      worked = true;
    }
  }

  const std::size_t cap = k.window.options().capacity;
  const std::size_t ahead = k.times.count_after(t);
  const bool short_of_t = k.times.empty() || k.times.newest() < std::min(t, k.last_ns);
  const bool room = !k.times.full() || k.times.size() - ahead > std::max<std::size_t>(1, cap / 4);
  if (!short_of_t && ahead >= std::max<std::size_t>(1, cap / 2)) return worked;
  if (!room) return worked;
  if (k.pending_count == 0) {
    if (k.at_end) {
      // Read to the end without reaching the last pose open() saw: the file changed.
      if (k.times.empty() || k.times.newest() != k.last_ns) return fail();
      return worked;
    }
    bool read_error = false;
    if (!read_forward(k, read_error)) {
      if (read_error || k.times.empty() || k.times.newest() != k.last_ns) return fail();
      return true;
    }
  }
  push(k.pending[0]);
  if (--k.pending_count > 0) k.pending[0] = k.pending[1];
  return true;
}

// Under the lock, with the reader idle: the requests for which step(k) would
// still have nothing to do (the inverse of its conditions).
void ReplayHandSource::Stream::set_quiet_range(HandTrack& k) noexcept {
  constexpr TimeNs kMin = std::numeric_limits<TimeNs>::min(), kMax = std::numeric_limits<TimeNs>::max();
  k.quiet_from_ns = 0;
  k.quiet_until_ns = 0;  // empty: every move wakes the reader
  if (k.failed) {
    k.quiet_from_ns = kMin;
    k.quiet_until_ns = kMax;
    return;
  }
  if (k.times.empty()) return;
  k.quiet_from_ns = k.times.oldest() == k.first_ns ? kMin : k.times.oldest();
  if (k.at_end && k.pending_count == 0 && k.times.newest() == k.last_ns) {
    k.quiet_until_ns = kMax;
    return;
  }
  const std::size_t cap = k.window.options().capacity, n = k.times.size();
  const std::size_t ahead = std::max<std::size_t>(1, cap / 2), behind = std::max<std::size_t>(1, cap / 4);
  const TimeNs needs_more_from = n >= ahead ? k.times.at(n - ahead) : kMin;
  const TimeNs has_room_from = k.times.full() ? k.times.at(behind) : kMin;
  k.quiet_until_ns = std::max(needs_more_from, has_room_from);
}

void ReplayHandSource::Stream::run() noexcept {
  try {
    std::unique_lock lock(mutex);
    while (!stop) {
      const std::uint64_t seen = requests;
      lock.unlock();
      bool worked = false;
      for (HandTrack& k : hands) {
        if (k.playable()) worked = step(k) || worked;
      }
      lock.lock();
      if (worked) continue;
      for (HandTrack& k : hands) set_quiet_range(k);
      wake.wait(lock, [&] { return stop || requests != seen; });
      for (HandTrack& k : hands) k.quiet_from_ns = k.quiet_until_ns = 0;
    }
  } catch (...) {
    // Out of memory on the reader thread: lookups answer PoseLookup::empty.
    {
      std::lock_guard lock(mutex);
      for (HandTrack& k : hands) k.failed = true;
    }
    progress.notify_all();
  }
}

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
  Stream& s = *stream_;
  HandTrack& k = s.hands[hand_index(hand)];
  PoseLookup r = PoseLookup::empty;
  bool moved = false;
  {
    std::lock_guard lock(s.mutex);
    moved = s.request(k, file_t);
    if (k.failed || k.window.empty()) {
      r = PoseLookup::empty;
    } else if (Stream::covered(k, file_t)) {
      r = k.window.lookup(file_t, out);
    } else if (file_t < k.window.oldest_time_ns()) {
      r = PoseLookup::too_old;  // the reader goes back for it
    } else {
      out = k.window.newest();  // the reader has not got that far yet
      r = PoseLookup::stale;
    }
  }
  if (moved) s.wake.notify_one();
  if (is_usable(r)) out.time_ns = t_ns;
  if (r == PoseLookup::stale) out.time_ns += t_ns - file_t;  // back to the caller's clock
  if (is_usable(r) || r == PoseLookup::stale) {
    // A recorded pose counts as measured, and servable, when its time comes on the caller's clock.
    out.data_time_ns += t_ns - file_t;
    out.ready_time_ns = out.data_time_ns;
  }
  return r;
}

bool ReplayHandSource::available(Handedness hand) const noexcept {
  const auto h = hand_index(hand);
  return stream_ && h < stream_->hands.size() && stream_->hands[h].samples > 0;
}

bool ReplayHandSource::wait_until_buffered(TimeNs t_ns) {
  TimeNs file_t = 0;
  if (!to_file_time(t_ns, file_t)) return false;
  Stream& s = *stream_;
  std::unique_lock lock(s.mutex);
  bool ok = true;
  for (HandTrack& k : s.hands) {
    if (k.playable()) ok = s.wait_covered(lock, k, file_t) && ok;
  }
  return ok;
}

void ReplayHandSource::pause_reading_for_testing(bool paused) {
  {
    std::lock_guard lock(stream_->mutex);
    stream_->paused = paused;
    ++stream_->requests;
  }
  stream_->wake.notify_all();
  stream_->progress.notify_all();
}

std::size_t ReplayHandSource::buffered_samples() const noexcept {
  std::lock_guard lock(stream_->mutex);
  std::size_t n = 0;
  for (const HandTrack& k : stream_->hands) n += k.window.size();
  return n;
}

std::size_t ReplayHandSource::index_entries() const noexcept {
  std::size_t n = 0;  // fixed since open()
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
  Stream& s = *stream_;
  HandTrack& k = s.hands[hand_index(hand)];
  std::unique_lock lock(s.mutex);
  if (!s.wait_covered(lock, k, file_t)) {
    return make_error(Errc::io_error, "replay of '" + path_ + "': the file changed or became unreadable after it "
                                      "was opened; open it again");
  }
  auto q = k.window.query(file_t);
  lock.unlock();
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
