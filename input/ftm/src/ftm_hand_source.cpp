#include "proprio/ftm/ftm_hand_source.hpp"

#include <cstdio>

namespace proprio::ftm {

Status FtmHandSourceOptions::validate() const { return tracker.validate(); }

std::string FtmHandSourceOptions::describe() const {
  return tracker.describe() + "\nhistory: " + history.describe();
}

std::string FtmSourceStats::describe() const {
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "samples: %llu IMU, %llu bend, %llu wrist; poses %llu (rejected %llu); compass flagged disturbed "
                "in %llu IMU samples",
                static_cast<unsigned long long>(imu_samples), static_cast<unsigned long long>(bend_samples),
                static_cast<unsigned long long>(wrist_samples), static_cast<unsigned long long>(poses_published),
                static_cast<unsigned long long>(poses_rejected), static_cast<unsigned long long>(compass_disturbed));
  return buf;
}

Result<std::unique_ptr<FtmHandSource>> FtmHandSource::create(FtmHandSourceOptions options,
                                                             FtmCalibration calibration) {
  if (auto ok = options.validate(); !ok) return ok.error();
  auto tracker = FtmTracker::create(options.tracker, calibration);
  if (!tracker) return tracker.error();
  return std::unique_ptr<FtmHandSource>(new FtmHandSource(std::move(options), std::move(*tracker)));
}

FtmHandSource::FtmHandSource(FtmHandSourceOptions options, FtmTracker tracker)
    : options_(std::move(options)), tracker_(std::move(tracker)), history_(options_.history) {}

bool FtmHandSource::push(const FtmEvent& event) {
  tracker_.push(event);
  const bool dorsum_tick = event.kind == FtmEvent::Kind::imu && event.index == index_of(FtmImu::dorsum);
  bool disturbed = false;
  if (event.kind == FtmEvent::Kind::imu && event.index < kFtmImuCount) {
    disturbed = tracker_.mag_disturbed(static_cast<FtmImu>(event.index));
  }
  if (dorsum_tick) tracker_.estimate(pose_);
  std::lock_guard lock(mutex_);
  switch (event.kind) {
    case FtmEvent::Kind::imu: ++stats_.imu_samples; break;
    case FtmEvent::Kind::bend: ++stats_.bend_samples; break;
    case FtmEvent::Kind::wrist: ++stats_.wrist_samples; break;
  }
  if (disturbed) ++stats_.compass_disturbed;
  if (!dorsum_tick || !pose_.active) return false;
  if (!history_.push(pose_)) {
    ++stats_.poses_rejected;
    return false;
  }
  ++stats_.poses_published;
  return true;
}

Result<HandPose> FtmHandSource::pose_at(Handedness hand, TimeNs t_ns) {
  if (!available(hand)) {
    return make_error(Errc::unavailable, std::string("the ftm source serves the ") +
                                             std::string(to_string(options_.tracker.hand)) + " hand only");
  }
  std::lock_guard lock(mutex_);
  auto q = history_.query(t_ns);
  if (!q) return q.error();
  return q->pose;
}

PoseLookup FtmHandSource::lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept {
  if (!available(hand)) return PoseLookup::empty;
  std::lock_guard lock(mutex_);
  return history_.lookup(t_ns, out);
}

FtmSourceStats FtmHandSource::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

}  // namespace proprio::ftm
