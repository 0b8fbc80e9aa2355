#pragma once
// VIST as a live HandSource. Device threads (the HID glove reader, the camera
// and its marker detector, or a session player) push sensor data from any
// thread; one worker thread owns the VistTracker, feeds it in arrival order
// and keeps a PoseHistory the consumers (OpenXR layer, engine) query without
// waiting on the tracker.
//
// Backpressure: the input queue is bounded. When the tracker falls behind,
// the oldest queued items are dropped and counted rather than letting latency
// grow without bound; the tracker then re-acquires as after a dropout.
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "proprio/core/hand_source.hpp"
#include "proprio/core/pose_history.hpp"
#include "proprio/core/time.hpp"
#include "proprio/vist/vist_session.hpp"
#include "proprio/vist/vist_tracker.hpp"

namespace proprio::vist {

class VistSessionPlayer;
struct VistSessionPlayerOptions;

struct VistHandSourceOptions {
  VistTrackerOptions tracker;
  PoseHistoryOptions history;
  std::size_t max_queued_inputs = 2048;  // ~2 s of 7 IMUs at 100 Hz plus frames

  std::string describe() const;
};

struct VistSourceStats {
  VistStats tracker;
  std::uint64_t inputs_dropped = 0;   // queue overflow
  std::uint64_t poses_published = 0;
  std::uint64_t poses_rejected = 0;   // not newer than the previous one
  std::string describe() const;
};

class VistHandSource final : public HandSource {
 public:
  static Result<std::unique_ptr<VistHandSource>> create(const ImuGloveDescription& glove,
                                                        VistHandSourceOptions options = {});
  ~VistHandSource() override;
  VistHandSource(const VistHandSource&) = delete;
  VistHandSource& operator=(const VistHandSource&) = delete;

  std::string_view name() const noexcept override { return "vist"; }
  bool available(Handedness hand) const noexcept override { return hand == options_.tracker.hand; }
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override;
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override;

  // Thread-safe, non-blocking (except for the queue's mutex).
  void push_imu(const TimedImuSample& s);
  void push_stereo_frame(VistStereoFrame frame);
  // Blocks until the worker has processed everything pushed before the call.
  void drain();
  // Feeds the source from a recorded session (VistSessionPlayer below) that
  // the source owns and stops first when it is destroyed.
  Status play_session(const std::filesystem::path& session, const VistSessionPlayerOptions& options,
                      const Clock& clock = MonotonicClock::instance());

  VistSourceStats stats() const;
  // The tracker's last_vision_fix_ns(), readable from any thread without a lock.
  TimeNs last_vision_fix_ns() const noexcept { return last_vision_fix_ns_.load(std::memory_order_acquire); }
  const VistHandSourceOptions& options() const noexcept { return options_; }

 private:
  VistHandSource(VistHandSourceOptions options, VistTracker tracker);
  void run();

  VistHandSourceOptions options_;
  VistTracker tracker_;  // worker thread only

  mutable std::mutex queue_mutex_;
  std::condition_variable queue_cv_, idle_cv_;
  std::deque<std::variant<TimedImuSample, VistStereoFrame>> queue_;
  bool busy_ = false;
  bool stop_ = false;
  std::uint64_t dropped_ = 0;

  mutable std::mutex history_mutex_;
  PoseHistory history_;
  VistSourceStats published_stats_;  // under history_mutex_
  std::atomic<TimeNs> last_vision_fix_ns_{0};

  std::thread worker_;
  std::unique_ptr<VistSessionPlayer> player_;  // declared last: destroyed first
};

// Plays a recorded VIST session (vist_session.hpp) into a VistHandSource in
// real time, its timeline shifted so the session starts when play() is called:
// the source then serves poses at CLOCK_MONOTONIC times, like a live glove.
struct VistSessionPlayerOptions {
  bool loop = true;
  double speed = 1.0;  // 0: as fast as possible (tests)
};

class VistSessionPlayer {
 public:
  static Result<std::unique_ptr<VistSessionPlayer>> start(const std::filesystem::path& session, VistHandSource& sink,
                                                          VistSessionPlayerOptions options = {},
                                                          const Clock& clock = MonotonicClock::instance());
  ~VistSessionPlayer();
  VistSessionPlayer(const VistSessionPlayer&) = delete;
  VistSessionPlayer& operator=(const VistSessionPlayer&) = delete;

  bool finished() const noexcept;  // reached the end (never while looping)
  std::uint64_t loops() const noexcept;

 private:
  VistSessionPlayer(std::filesystem::path path, VistHandSource& sink, VistSessionPlayerOptions options,
                    const Clock& clock, VistSessionReader reader);
  void run();

  std::filesystem::path path_;
  VistHandSource& sink_;
  VistSessionPlayerOptions options_;
  const Clock& clock_;
  std::optional<VistSessionReader> reader_;
  std::atomic<bool> finished_{false};
  std::atomic<std::uint64_t> loops_{0};
  std::mutex stop_mutex_;
  std::condition_variable stop_cv_;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace proprio::vist
