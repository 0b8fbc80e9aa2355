#pragma once
// The one interface every tracker implements (sim, replay, vist, glove, ftm).
// Narrow on purpose, like Monado's xrt_device: consumers (OpenXR layer, engine)
// only ever ask "where is this hand at time t?".
#include <string_view>

#include "proprio/core/hand_pose.hpp"
#include "proprio/core/pose_history.hpp"
#include "proprio/core/result.hpp"

namespace proprio {

class HandSource {
 public:
  virtual ~HandSource() = default;

  virtual std::string_view name() const noexcept = 0;

  // True when the source can deliver poses for this hand now: device connected,
  // file loaded, simulation running. The OpenXR layer uses this to decide
  // whether to advertise hand tracking at all.
  virtual bool available(Handedness hand) const noexcept = 0;

  // The hand at time t_ns (CLOCK_MONOTONIC), interpolated or predicted by the
  // source. Errors are honest: Errc::out_of_range when t is outside what the
  // source can serve, Errc::unavailable when it has no data for that hand.
  virtual Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) = 0;

  // The same for hot paths (the OpenXR layer, the haptics loop): no
  // allocation, no message. Safe to call from several threads at once.
  // PoseLookup::stale fills `out` with the newest pose (and its own time) so a
  // caller can still show it, flagged as not tracked.
  virtual PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept = 0;
};

}  // namespace proprio
