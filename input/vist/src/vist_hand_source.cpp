#include "proprio/vist/vist_hand_source.hpp"

#include "proprio/core/file_io.hpp"
#include "proprio/core/replay_source.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>

#include "proprio/core/log.hpp"

namespace proprio::vist {

std::string VistHandSourceOptions::describe() const {
  char buf[96];
  std::snprintf(buf, sizeof buf, "max_queued_inputs=%zu history: ", max_queued_inputs);
  return "VIST source: " + std::string(buf) + history.describe() + "\n" + tracker.describe();
}

std::string VistSourceStats::describe() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "poses published %llu (rejected %llu), inputs dropped on overflow %llu\n",
                static_cast<unsigned long long>(poses_published), static_cast<unsigned long long>(poses_rejected),
                static_cast<unsigned long long>(inputs_dropped));
  return buf + tracker.describe();
}

Result<std::unique_ptr<VistHandSource>> VistHandSource::create(const ImuGloveDescription& glove,
                                                               VistHandSourceOptions options) {
  if (options.max_queued_inputs < 16) {
    return make_error(Errc::invalid_argument, "VIST source: max_queued_inputs must be at least 16");
  }
  auto tracker = VistTracker::create(glove, options.tracker);
  if (!tracker) return tracker.error();
  return std::unique_ptr<VistHandSource>(new VistHandSource(std::move(options), std::move(*tracker)));
}

VistHandSource::VistHandSource(VistHandSourceOptions options, VistTracker tracker)
    : options_(std::move(options)), tracker_(std::move(tracker)), history_(options_.history) {
  worker_ = std::thread([this] { run(); });
}

VistHandSource::~VistHandSource() {
  player_.reset();
  {
    std::lock_guard lock(queue_mutex_);
    stop_ = true;
  }
  queue_cv_.notify_all();
  worker_.join();
}

void VistHandSource::push_imu(const TimedImuSample& s) {
  {
    std::lock_guard lock(queue_mutex_);
    if (queue_.size() >= options_.max_queued_inputs) {
      queue_.pop_front();
      ++dropped_;
    }
    queue_.emplace_back(s);
  }
  queue_cv_.notify_one();
}

void VistHandSource::push_stereo_frame(VistStereoFrame frame) {
  {
    std::lock_guard lock(queue_mutex_);
    if (queue_.size() >= options_.max_queued_inputs) {
      queue_.pop_front();
      ++dropped_;
    }
    queue_.emplace_back(std::move(frame));
  }
  queue_cv_.notify_one();
}

void VistHandSource::drain() {
  std::unique_lock lock(queue_mutex_);
  idle_cv_.wait(lock, [&] { return (queue_.empty() && !busy_) || stop_; });
}

void VistHandSource::run() {
  std::deque<std::variant<TimedImuSample, VistStereoFrame>> batch;
  for (;;) {
    std::uint64_t dropped = 0;
    {
      std::unique_lock lock(queue_mutex_);
      busy_ = false;
      idle_cv_.notify_all();
      queue_cv_.wait(lock, [&] { return stop_ || !queue_.empty(); });
      if (stop_) return;
      batch.swap(queue_);
      busy_ = true;
      dropped = dropped_;
    }
    std::uint64_t published = 0, rejected = 0;
    std::optional<HandPose> newest;
    for (auto& item : batch) {
      if (auto* imu = std::get_if<TimedImuSample>(&item)) {
        if (tracker_.add_imu(*imu)) {
          // Publish each pose: consumers interpolate between them.
          std::lock_guard lock(history_mutex_);
          if (history_.push(tracker_.pose())) {
            ++published;
          } else {
            ++rejected;
          }
        }
      } else {
        auto& f = std::get<VistStereoFrame>(item);
        tracker_.add_stereo_frame(f.capture_time_ns, f.left, f.right, f.T_world_leftcam);
      }
      last_vision_fix_ns_.store(tracker_.last_vision_fix_ns(), std::memory_order_release);
    }
    batch.clear();
    std::lock_guard lock(history_mutex_);
    published_stats_.tracker = tracker_.stats();
    published_stats_.inputs_dropped = dropped;
    published_stats_.poses_published += published;
    published_stats_.poses_rejected += rejected;
  }
}

Result<HandPose> VistHandSource::pose_at(Handedness hand, TimeNs t_ns) {
  if (!available(hand)) {
    return make_error(Errc::unavailable, std::string("the VIST source tracks the ") +
                                             std::string(to_string(options_.tracker.hand)) + " hand only");
  }
  std::lock_guard lock(history_mutex_);
  auto q = history_.query(t_ns);
  if (!q) return q.error();
  return q->pose;
}

PoseLookup VistHandSource::lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept {
  if (!available(hand)) return PoseLookup::empty;
  std::lock_guard lock(history_mutex_);
  return history_.lookup(t_ns, out);
}

VistSourceStats VistHandSource::stats() const {
  std::lock_guard lock(history_mutex_);
  return published_stats_;
}

Status VistHandSource::play_session(const std::filesystem::path& session, const VistSessionPlayerOptions& options,
                                    const Clock& clock) {
  player_.reset();
  auto p = VistSessionPlayer::start(session, *this, options, clock);
  if (!p) return p.error();
  player_ = std::move(*p);
  return {};
}

// ---------------------------------------------------------------------------

Result<std::unique_ptr<VistSessionPlayer>> VistSessionPlayer::start(const std::filesystem::path& session,
                                                                    VistHandSource& sink,
                                                                    VistSessionPlayerOptions options,
                                                                    const Clock& clock) {
  if (!(options.speed >= 0.0) || !std::isfinite(options.speed)) {
    return make_error(Errc::invalid_argument, "VIST session player: speed must be >= 0 (0: as fast as possible)");
  }
  auto reader = VistSessionReader::open(session);
  if (!reader) return reader.error();
  if (reader->info().hand != sink.options().tracker.hand) {
    return make_error(Errc::invalid_argument, session.string() + " holds a " +
                                                  std::string(to_string(reader->info().hand)) +
                                                  " hand; the VIST source tracks the " +
                                                  std::string(to_string(sink.options().tracker.hand)) + " hand");
  }
  return std::unique_ptr<VistSessionPlayer>(
      new VistSessionPlayer(session, sink, options, clock, std::move(*reader)));
}

VistSessionPlayer::VistSessionPlayer(std::filesystem::path path, VistHandSource& sink,
                                     VistSessionPlayerOptions options, const Clock& clock, VistSessionReader reader)
    : path_(std::move(path)), sink_(sink), options_(options), clock_(clock), reader_(std::move(reader)) {
  thread_ = std::thread([this] { run(); });
}

VistSessionPlayer::~VistSessionPlayer() {
  {
    std::lock_guard lock(stop_mutex_);
    stop_ = true;
  }
  stop_cv_.notify_all();
  thread_.join();
}

bool VistSessionPlayer::finished() const noexcept { return finished_.load(); }
std::uint64_t VistSessionPlayer::loops() const noexcept { return loops_.load(); }

void VistSessionPlayer::run() {
  // Session time t maps to clock time offset + (t - first) / speed. Each
  // loop starts 1 s after the previous one ended, so times keep increasing.
  const TimeNs start_ns = clock_.now_ns();
  TimeNs offset_ns = 0;
  // A plain value and a flag: GCC 12 warns (falsely) about an optional read in the lambda below.
  TimeNs first_ns = 0;
  bool have_first = false;
  TimeNs last_shifted_ns = start_ns;
  auto wait_until = [&](TimeNs target_ns) {
    if (options_.speed == 0.0) {
      std::lock_guard lock(stop_mutex_);
      return !stop_;
    }
    std::unique_lock lock(stop_mutex_);
    const TimeNs now = clock_.now_ns();
    if (target_ns > now) stop_cv_.wait_for(lock, std::chrono::nanoseconds(target_ns - now), [&] { return stop_; });
    return !stop_;
  };
  for (;;) {
    auto item = reader_->next();
    if (!item) {
      logger().warn("VIST session player: {}: {}", printable(path_.string(), 300), printable(item.error().message, 400));
      continue;
    }
    if (!*item) {
      // Known only once the file has been read: a damaged or cut-short session, said once.
      if (loops_.load() == 0) {
        if (const std::string problem = describe_replay_problem(path_.string(), reader_->summary(), 0);
            !problem.empty()) {
          logger().warn("VIST session player: {}", problem);
        }
      }
      if (!options_.loop) break;
      auto reopened = VistSessionReader::open(path_);
      if (!reopened) {
        logger().error("VIST session player: cannot reopen {} to loop: {}", path_.string(),
                       reopened.error().message);
        break;
      }
      reader_.emplace(std::move(*reopened));
      loops_.fetch_add(1);
      have_first = false;
      continue;
    }
    auto shift = [&](TimeNs t) {
      if (!have_first) {
        have_first = true;
        first_ns = t;
        offset_ns = (loops_.load() == 0 ? start_ns : last_shifted_ns + kNsPerSecond) - t;
      }
      const double speed = options_.speed == 0.0 ? 1.0 : options_.speed;
      const TimeNs shifted = first_ns + offset_ns +
                             static_cast<TimeNs>(std::llround(static_cast<double>(t - first_ns) / speed));
      last_shifted_ns = std::max(last_shifted_ns, shifted);
      return shifted;
    };
    if (auto* imu = std::get_if<TimedImuSample>(&**item)) {
      TimedImuSample s = *imu;
      s.time_ns = shift(s.time_ns);
      if (!wait_until(s.time_ns)) return;
      sink_.push_imu(s);
    } else if (auto* f = std::get_if<VistStereoFrame>(&**item)) {
      // Frames are stored where they arrived: after the IMU samples that came before them.
      VistStereoFrame frame = std::move(*f);
      frame.capture_time_ns = shift(frame.capture_time_ns);
      sink_.push_stereo_frame(std::move(frame));
    }
    std::lock_guard lock(stop_mutex_);
    if (stop_) return;
  }
  finished_.store(true);
}

}  // namespace proprio::vist
