#pragma once
// The FTM glove as a HandSource ("ftm"): samples go in from whoever produces
// them (a read-out board's reader thread, the simulated wearer's thread),
// hand poses come out of a PoseHistory that consumers query from any thread.
//
// The tracker runs in the producer's thread and a pose is published once per
// IMU tick (when the dorsum's sample arrives, 200 Hz): an FtmTracker frame
// costs microseconds, so a worker thread would only add latency.
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include "proprio/core/hand_source.hpp"
#include "proprio/core/pose_history.hpp"
#include "proprio/ftm/ftm_tracker.hpp"

namespace proprio::ftm {

struct FtmHandSourceOptions {
  FtmTrackerOptions tracker;
  PoseHistoryOptions history;
  Status validate() const;
  std::string describe() const;
};

struct FtmSourceStats {
  std::uint64_t imu_samples = 0;
  std::uint64_t bend_samples = 0;
  std::uint64_t wrist_samples = 0;
  std::uint64_t poses_published = 0;
  std::uint64_t poses_rejected = 0;     // not newer than the previous one
  std::uint64_t compass_disturbed = 0;  // IMU samples whose compass the detector flagged
  std::string describe() const;
};

class FtmHandSource final : public HandSource {
 public:
  static Result<std::unique_ptr<FtmHandSource>> create(FtmHandSourceOptions options, FtmCalibration calibration);

  std::string_view name() const noexcept override { return "ftm"; }
  bool available(Handedness hand) const noexcept override { return hand == options_.tracker.hand; }
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override;
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override;

  // One producer thread at a time. Returns true when a new pose was published.
  bool push(const FtmEvent& event);

  FtmSourceStats stats() const;
  const FtmHandSourceOptions& options() const noexcept { return options_; }
  // Producer thread only: the tracker, for its per-IMU flags.
  const FtmTracker& tracker() const noexcept { return tracker_; }

 private:
  FtmHandSource(FtmHandSourceOptions options, FtmTracker tracker);

  FtmHandSourceOptions options_;
  FtmTracker tracker_;  // producer thread
  HandPose pose_;
  mutable std::mutex mutex_;  // guards history_ and stats_
  PoseHistory history_;
  FtmSourceStats stats_;
};

}  // namespace proprio::ftm
