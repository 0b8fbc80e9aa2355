#include "proprio/core/time.hpp"

#include <ctime>

namespace proprio {

TimeNs MonotonicClock::now_ns() const noexcept {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

MonotonicClock& MonotonicClock::instance() noexcept {
  static MonotonicClock clock;
  return clock;
}

}  // namespace proprio
