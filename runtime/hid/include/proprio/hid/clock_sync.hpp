#pragma once
// ClockSync: maps a device's free-running µs counter (32 bits, wrapping every
// 71.6 min, crystal off by up to ±100 ppm) onto the host's CLOCK_MONOTONIC,
// from nothing but the times the host received the device's reports.
//
// Every receive time is the measurement time plus a latency that is never
// negative: USB polling, the host controller, the kernel and our thread's
// wake-up. Its distribution has a hard floor (the fastest path) and a long
// tail (scheduling, other USB traffic, 20 ms stalls). Averaging would carry
// the tail into the mapping; the floor is stable. So the estimator fits the
// *lower envelope* of (device time, receive time) points, the line with every
// point on or above it that is as close as possible to all of them (a linear
// program whose solution is the lower-convex-hull edge above the points' mean
// device time; TICSync, Harrison & Newman, ICRA 2011, uses the same idea).
// Its slope is the crystal's rate against the host clock; its offset is the
// measurement time plus the link's minimum latency, which no receive-side
// method can observe (set min_latency_ns if it is known; otherwise it is a
// constant offset that IMU-camera time-offset calibration absorbs).
//
// The window holds the lowest point of each bucket_ns of device time over the
// last window_ns, so an update costs O(window / bucket) and never allocates.
// Wraparound is unwrapped against the newest observation. A device that
// restarts (counter back to its boot value) or a clock that jumps is detected
// and the estimator re-locks; reset() forces that when the caller knows better
// (ImuGloveStreamDecoder saw a restart).
//
// Not thread-safe: the reader thread owns it.
#include <cstdint>
#include <limits>
#include <vector>

#include "proprio/core/time.hpp"

namespace proprio::hid {

struct ClockSyncOptions {
  // Device time the envelope spans. Seconds give a slope good to well under a
  // ppm; tens of seconds stay short against crystal drift with temperature
  // (ppm per minute), which the fit treats as constant.
  DurationNs window_ns = 10 * kNsPerSecond;
  // Each bucket keeps its lowest point. 250 ms at 200 reports/s: the minimum of
  // 50 latencies, a few µs above the floor.
  DurationNs bucket_ns = 250 * kNsPerMillisecond;
  // Subtracted from every mapped time: the link's minimum latency, if measured.
  DurationNs min_latency_ns = 0;
  // A report that arrives this much *before* the current line predicts would
  // have negative latency: the device clock jumped forward. Re-lock.
  DurationNs jump_threshold_ns = 50 * kNsPerMillisecond;
  // This many reports in a row later than jump_threshold_ns above the line:
  // the device clock jumped back by less than backwards_threshold_ns (or the
  // host lost its mind). Re-lock. Lone 20 ms stalls do not trigger it.
  std::uint32_t relock_after_late = 50;
  // The device timestamp going back by more than this is a restart (reordered
  // reports go back by a tick or two at most).
  DurationNs backwards_threshold_ns = 100 * kNsPerMillisecond;
  // A fitted slope further than this from nominal is not believed (too little
  // data yet); the nominal rate is used through the lowest point instead.
  double max_skew_ppm = 500.0;
};

enum class ClockSyncEvent : std::uint8_t {
  locked,              // first observation after construction or reset()
  tracked,             // added to the envelope
  relocked_backwards,  // device time went back: the device restarted
  relocked_jump,       // arrived before it could have been measured: device clock jumped forward
  relocked_late,       // relock_after_late reports in a row far above the line
  ignored,             // host receive time went backwards (a caller bug); nothing changed
};
const char* to_string(ClockSyncEvent event) noexcept;

struct ClockSyncStats {
  std::uint64_t observations = 0;
  std::uint64_t relocks = 0;  // re-locks after the first lock, reset() included
  std::uint64_t ignored = 0;
  std::uint64_t timestamp_wraps = 0;  // since the last lock
};

class ClockSync {
 public:
  explicit ClockSync(ClockSyncOptions options = {});

  // One report: stamped device_us by the device, read by the host at receive_ns.
  ClockSyncEvent observe(std::uint32_t device_us, TimeNs receive_ns) noexcept;

  // Host CLOCK_MONOTONIC time of the instant the device stamped device_us
  // (unwrapped against the newest observation; within ±35 min of it). Before
  // the first observation it returns 0.
  TimeNs to_host_ns(std::uint32_t device_us) const noexcept;

  // Forget everything: the next observation locks afresh.
  void reset() noexcept;

  bool locked() const noexcept { return locked_; }
  // How much faster the device counter runs than the host clock, ppm (a
  // crystal at +100 ppm reads +100).
  double skew_ppm() const noexcept;
  // Device time covered by the envelope's points, ns (grows to window_ns after a lock).
  DurationNs span_ns() const noexcept;
  // The last observation's distance above the envelope: its latency above the
  // link's minimum (before it was added; negative if it fell below).
  DurationNs last_excess_latency_ns() const noexcept { return last_excess_ns_; }
  const ClockSyncStats& stats() const noexcept { return stats_; }
  const ClockSyncOptions& options() const noexcept { return options_; }

 private:
  struct Bucket {
    std::int64_t key = std::numeric_limits<std::int64_t>::min();  // device µs / bucket width; min() = empty
    std::int64_t x_us = 0;         // device µs since the lock origin
    std::int64_t y_ns = 0;         // receive ns since the lock origin
  };
  struct Point {
    double x, y;
  };
  void lock(std::uint32_t device_us, TimeNs receive_ns) noexcept;
  void add(std::int64_t x_us, std::int64_t y_ns) noexcept;
  void refit() noexcept;
  double line_at(double x_us) const noexcept { return line_y_ + slope_ * (x_us - line_x_); }
  std::int64_t unwrap(std::uint32_t device_us) const noexcept;

  ClockSyncOptions options_;
  std::int64_t bucket_us_ = 250000;
  bool locked_ = false;
  std::int64_t origin_device_us_ = 0;  // unwrapped device time of the lock
  TimeNs origin_host_ns_ = 0;
  std::int64_t newest_device_us_ = 0;  // unwrapped
  std::int64_t newest_key_ = 0;
  TimeNs last_receive_ns_ = 0;
  std::uint32_t late_run_ = 0;
  DurationNs last_excess_ns_ = 0;
  // The envelope line: y = line_y_ + slope_ (x - line_x_), x in device µs and y
  // in host ns since the origin; slope_ is host ns per device µs (1000 nominal).
  double line_x_ = 0.0, line_y_ = 0.0, slope_ = 1000.0;
  std::vector<Bucket> buckets_;  // ring indexed by key, sized once
  std::vector<Point> points_;  // bucket minima in time order; capacity reserved once
  std::vector<Point> hull_;
  DurationNs span_ns_ = 0;
  ClockSyncStats stats_;
};

}  // namespace proprio::hid
