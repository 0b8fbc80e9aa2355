#pragma once
// The safety gate: one per device, host side, between the servo loop and the
// driver. Whatever the servo loop asks for, what leaves the gate is within the
// device's limits (renderable(), so normal in [0, max], |shear| <= max and
// <= mu * normal), changes by at most max_rate_n_per_s per component, ramps in
// over ramp_in_s after engaging, and is zero when the gate is disengaged, when
// no fresh command came for watchdog_ns, or after a non-finite command.
//
// Recovery: after a watchdog trip or a non-finite command, the next good
// command restarts the ramp-in from zero, so force never snaps back.
// Going to zero for safety (disengage, watchdog, NaN) is immediate, not
// rate-limited: zero is always safe to send.
//
// command() and output() are noexcept and allocation-free (the 1 kHz loop).
// Not thread-safe: the servo loop's thread owns its gates.
#include <cstdint>
#include <string>
#include <string_view>

#include "proprio/core/time.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/fingertip_force.hpp"

namespace proprio::haptics {

enum class CommandVerdict : std::uint8_t {
  accepted,             // renderable as asked
  clamped,              // accepted after renderable() changed it (see SafetyStats for why)
  rejected_non_finite,  // a NaN/inf component: the output is zero until the next good command
};
std::string_view to_string(CommandVerdict v) noexcept;

// What the gate is doing, as of the last command()/output().
enum class GateState : std::uint8_t {
  disengaged,
  waiting,           // engaged, no command yet
  ramping,           // ramp-in in progress
  active,
  watchdog_tripped,  // engaged, commands stopped: output zero
  faulted,           // engaged, last command non-finite: output zero
};
std::string_view to_string(GateState s) noexcept;

struct SafetyStats {
  std::uint64_t commands = 0;          // command() calls
  std::uint64_t clamps = 0;            // commands renderable() changed
  std::uint64_t normal_clamps = 0;     // ... negative or above max_normal_n
  std::uint64_t shear_clamps = 0;      // ... |shear| above max_shear_n
  std::uint64_t cone_clamps = 0;       // ... |shear| above mu * normal
  std::uint64_t axis_drops = 0;        // ... a component the device lacks
  std::uint64_t nan_commands = 0;      // non-finite commands (errors)
  std::uint64_t watchdog_trips = 0;    // episodes of commands stopping for watchdog_ns
  std::uint64_t rate_limited_outputs = 0;
  std::uint64_t engagements = 0;

  std::string describe() const;
};

class SafetyGate {
 public:
  // The model must outlive the gate; its limits() are the gate's limits.
  explicit SafetyGate(const FingertipDeviceModel& model) noexcept;

  // Starts a ramp-in (scale 0 -> 1 over ramp_in_s, smoothstep) at `now`.
  // Engaging an engaged gate restarts nothing.
  void engage(TimeNs now) noexcept;
  // Output zero from now on, immediately.
  void disengage() noexcept;
  bool engaged() const noexcept { return engaged_; }

  // Records a fresh command measured/issued at `now`. Commands are recorded
  // while disengaged too, so engaging mid-stream ramps into the current one.
  CommandVerdict command(const FingertipForce& desired, TimeNs now) noexcept;

  // The force to send at `now`: advances the rate limiter by the time since
  // the last output() and applies the ramp. Calling it twice with the same
  // `now` returns the same force.
  FingertipForce output(TimeNs now) noexcept;

  GateState state() const noexcept { return state_; }
  // Ramp-in scale in [0, 1] at `now` (1 once ramped in; 0 before engaging).
  double ramp_scale(TimeNs now) const noexcept;
  const SafetyStats& stats() const noexcept { return stats_; }
  const DeviceLimits& limits() const noexcept { return model_.limits(); }
  const FingertipDeviceModel& model() const noexcept { return model_; }
  std::string describe() const;

 private:
  void restart(TimeNs now) noexcept;  // zero the limiter and ramp in from `now`
  bool watchdog_expired(TimeNs now) const noexcept;

  const FingertipDeviceModel& model_;
  SafetyStats stats_;
  GateState state_ = GateState::disengaged;
  bool engaged_ = false;
  bool have_command_ = false;
  bool faulted_ = false;
  bool tripped_ = false;
  FingertipForce target_;    // last good command after renderable()
  FingertipForce limited_;   // rate limiter state (before the final clamp)
  TimeNs last_command_ns_ = 0;
  TimeNs last_output_ns_ = 0;
  TimeNs ramp_start_ns_ = 0;
  TimeNs engage_ns_ = 0;
};

}  // namespace proprio::haptics
