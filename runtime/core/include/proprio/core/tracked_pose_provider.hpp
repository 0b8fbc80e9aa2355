#pragma once
// Poses that something outside a hand source tracks, offered to the source at
// the time it needs them. The OpenXR layer implements it from the app's XR
// runtime (the headset's VIEW pose, through XR_KHR_convert_timespec_time), so
// a head-mounted camera (VIST) knows where it was at each capture time.
#include <cstdint>

#include "proprio/core/math.hpp"
#include "proprio/core/time.hpp"

namespace proprio {

enum class TrackedPose : std::uint8_t {
  head,  // the OpenXR VIEW frame
};

class TrackedPoseProvider {
 public:
  virtual ~TrackedPoseProvider() = default;
  // `what` in the source's world frame (its tracking origin) at t_ns
  // (CLOCK_MONOTONIC). false: not known now (no XR session yet, not tracked,
  // the runtime refused); the caller drops or holds, never waits. Safe to
  // call from any thread; never blocks for longer than one runtime call.
  virtual bool locate(TrackedPose what, TimeNs t_ns, Pose& T_world_x) noexcept = 0;
};

}  // namespace proprio
