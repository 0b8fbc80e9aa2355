#pragma once
// Time is int64 nanoseconds on CLOCK_MONOTONIC everywhere (see docs/architecture.md).
// A sample carries the time it was *measured*, not when it arrived.
#include <atomic>
#include <cstdint>

namespace proprio {

using TimeNs = std::int64_t;
using DurationNs = std::int64_t;

constexpr DurationNs kNsPerSecond = 1'000'000'000;
constexpr DurationNs kNsPerMillisecond = 1'000'000;

constexpr double ns_to_seconds(DurationNs ns) noexcept { return static_cast<double>(ns) * 1e-9; }
// Rounds to the nearest nanosecond so that k/rate sampling grids are exact.
constexpr DurationNs seconds_to_ns(double seconds) noexcept {
  const double ns = seconds * 1e9;
  return static_cast<DurationNs>(ns < 0 ? ns - 0.5 : ns + 0.5);
}

// The time source every component takes by reference, so tests can drive it.
class Clock {
 public:
  virtual ~Clock() = default;
  virtual TimeNs now_ns() const noexcept = 0;
};

// CLOCK_MONOTONIC, the clock OpenXR's XR_KHR_convert_timespec_time maps from.
class MonotonicClock final : public Clock {
 public:
  TimeNs now_ns() const noexcept override;
  static MonotonicClock& instance() noexcept;
};

// A clock that only moves when told to. Thread-safe so a test can advance it
// while a worker thread reads it.
class ManualClock final : public Clock {
 public:
  explicit ManualClock(TimeNs start_ns = 0) noexcept : now_(start_ns) {}
  TimeNs now_ns() const noexcept override { return now_.load(std::memory_order_acquire); }
  void set(TimeNs t_ns) noexcept { now_.store(t_ns, std::memory_order_release); }
  void advance(DurationNs dt_ns) noexcept { now_.fetch_add(dt_ns, std::memory_order_acq_rel); }

 private:
  std::atomic<TimeNs> now_;
};

}  // namespace proprio
