#pragma once
// A fixed-capacity ring buffer of HandPose samples that answers "where was (or
// will be) the hand at time t?" by slerp interpolation between the bracketing
// samples, or by bounded constant-velocity prediction past the newest one.
// Not thread-safe: one owner pushes and queries (publish results through a
// Mailbox to other threads). Pushing and querying never allocate.
#include <cstddef>
#include <string>
#include <vector>

#include "proprio/core/hand_pose.hpp"
#include "proprio/core/result.hpp"

namespace proprio {

struct PoseHistoryOptions {
  std::size_t capacity = 256;                           // samples kept
  DurationNs max_prediction_ns = 50 * kNsPerMillisecond;  // furthest extrapolation past the newest sample
  DurationNs max_interpolation_gap_ns = 200 * kNsPerMillisecond;  // wider gaps are reported, not bridged

  std::string describe() const;  // "capacity=256 max_prediction=50.0ms max_gap=200.0ms"
};

enum class PoseQueryKind { exact, interpolated, predicted };
const char* to_string(PoseQueryKind k) noexcept;

// Outcome of the non-allocating lookup() used on hot paths.
enum class PoseLookup {
  exact,         // out = the sample at that time
  interpolated,  // out = between two samples
  predicted,     // out = extrapolated within max_prediction_ns
  stale,         // past the prediction horizon: out = the newest sample, with its own time
  too_old,       // before the oldest sample kept: out untouched
  gap,           // inside a gap wider than max_interpolation_gap_ns: out untouched
  empty,         // nothing pushed yet: out untouched
};
constexpr bool is_usable(PoseLookup r) noexcept {
  return r == PoseLookup::exact || r == PoseLookup::interpolated || r == PoseLookup::predicted;
}

struct PoseQuery {
  HandPose pose;  // pose.time_ns == requested time
  PoseQueryKind kind = PoseQueryKind::exact;
};

class PoseHistory {
 public:
  explicit PoseHistory(PoseHistoryOptions options = {});

  // Samples must arrive in strictly increasing time; an older or equal time is
  // rejected with Errc::invalid_argument and the history is unchanged.
  Status push(const HandPose& sample);

  // Errors (Errc::out_of_range / unavailable) say which bound was hit and by how much.
  Result<PoseQuery> query(TimeNs t_ns) const;
  // The same without allocating or building messages, for hot paths.
  PoseLookup lookup(TimeNs t_ns, HandPose& out) const noexcept;

  std::size_t size() const noexcept { return size_; }
  bool empty() const noexcept { return size_ == 0; }
  TimeNs oldest_time_ns() const;  // requires !empty()
  TimeNs newest_time_ns() const;  // requires !empty()
  const HandPose& newest() const;  // requires !empty()
  void clear() noexcept { size_ = 0; }
  const PoseHistoryOptions& options() const noexcept { return options_; }

 private:
  const HandPose& at(std::size_t i) const;  // 0 = oldest
  PoseHistoryOptions options_;
  std::vector<HandPose> ring_;
  std::size_t head_ = 0;  // index of the oldest sample in ring_
  std::size_t size_ = 0;
};

}  // namespace proprio
