#include "proprio/haptics/safety.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace proprio::haptics {

namespace {

FingertipForce scaled(const FingertipForce& f, double s) noexcept {
  return FingertipForce{f.normal_n * s, f.shear_x_n * s, f.shear_z_n * s};
}

bool same(const FingertipForce& a, const FingertipForce& b) noexcept {
  return a.normal_n == b.normal_n && a.shear_x_n == b.shear_x_n && a.shear_z_n == b.shear_z_n;
}

}  // namespace

std::string_view to_string(CommandVerdict v) noexcept {
  switch (v) {
    case CommandVerdict::accepted: return "accepted";
    case CommandVerdict::clamped: return "clamped";
    case CommandVerdict::rejected_non_finite: return "rejected_non_finite";
  }
  return "invalid_verdict";
}

std::string_view to_string(GateState s) noexcept {
  switch (s) {
    case GateState::disengaged: return "disengaged";
    case GateState::waiting: return "waiting";
    case GateState::ramping: return "ramping";
    case GateState::active: return "active";
    case GateState::watchdog_tripped: return "watchdog_tripped";
    case GateState::faulted: return "faulted";
  }
  return "invalid_state";
}

std::string SafetyStats::describe() const {
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "commands=%llu clamps=%llu (normal %llu, shear %llu, cone %llu, axis %llu) nan=%llu "
                "watchdog_trips=%llu rate_limited=%llu engagements=%llu",
                static_cast<unsigned long long>(commands), static_cast<unsigned long long>(clamps),
                static_cast<unsigned long long>(normal_clamps), static_cast<unsigned long long>(shear_clamps),
                static_cast<unsigned long long>(cone_clamps), static_cast<unsigned long long>(axis_drops),
                static_cast<unsigned long long>(nan_commands), static_cast<unsigned long long>(watchdog_trips),
                static_cast<unsigned long long>(rate_limited_outputs), static_cast<unsigned long long>(engagements));
  return buf;
}

SafetyGate::SafetyGate(const FingertipDeviceModel& model) noexcept : model_(model) {}

void SafetyGate::restart(TimeNs now) noexcept {
  limited_ = {};
  ramp_start_ns_ = now;
  last_output_ns_ = now;
}

bool SafetyGate::watchdog_expired(TimeNs now) const noexcept {
  return have_command_ && now - last_command_ns_ >= model_.limits().watchdog_ns;
}

void SafetyGate::engage(TimeNs now) noexcept {
  if (engaged_) return;
  engaged_ = true;
  ++stats_.engagements;
  engage_ns_ = now;
  tripped_ = false;
  restart(now);
  state_ = GateState::waiting;
}

void SafetyGate::disengage() noexcept {
  engaged_ = false;
  tripped_ = false;
  limited_ = {};
  state_ = GateState::disengaged;
}

double SafetyGate::ramp_scale(TimeNs now) const noexcept {
  if (!engaged_) return 0.0;
  const double ramp_s = model_.limits().ramp_in_s;
  if (!(ramp_s > 0.0)) return 1.0;
  const double u = std::clamp(ns_to_seconds(now - ramp_start_ns_) / ramp_s, 0.0, 1.0);
  // Smoothstep: zero slope at both ends, so the force eases in and settles
  // without a kink the finger would feel as a tap.
  return u * u * (3.0 - 2.0 * u);
}

CommandVerdict SafetyGate::command(const FingertipForce& desired, TimeNs now) noexcept {
  ++stats_.commands;
  std::uint8_t why = kClampNone;
  clamp_to_limits(desired, model_.limits(), model_.axes(), &why);
  if (why & kClampNonFinite) {
    ++stats_.nan_commands;
    faulted_ = true;
    target_ = {};
    limited_ = {};
    if (engaged_) state_ = GateState::faulted;
    return CommandVerdict::rejected_non_finite;
  }
  const FingertipForce r = model_.renderable(desired);

  if (engaged_) {
    // A gap the watchdog would have caught counts as a trip even if no
    // output() ran during it; silence from before engaging is no fault.
    const bool gap = watchdog_expired(now);
    if (gap && !tripped_ && !faulted_ && last_command_ns_ >= engage_ns_) ++stats_.watchdog_trips;
    // Resuming after silence, a fault, or the first command after engaging:
    // ease in again from zero rather than jump to the new force.
    if (gap || tripped_ || faulted_ || !have_command_) restart(now);
  }
  faulted_ = false;
  tripped_ = false;
  target_ = r;
  have_command_ = true;
  last_command_ns_ = now;

  if (why == kClampNone && same(r, desired)) return CommandVerdict::accepted;
  ++stats_.clamps;
  if (why & (kClampNormalNegative | kClampNormalMax)) ++stats_.normal_clamps;
  if (why & kClampShearMax) ++stats_.shear_clamps;
  if (why & kClampFrictionCone) ++stats_.cone_clamps;
  if (why & kClampAxisDropped) ++stats_.axis_drops;
  return CommandVerdict::clamped;
}

FingertipForce SafetyGate::output(TimeNs now) noexcept {
  const auto zero = [this, now](GateState s) {
    state_ = s;
    limited_ = {};
    last_output_ns_ = now;
    return FingertipForce{};
  };
  if (!engaged_) return zero(GateState::disengaged);
  if (faulted_) return zero(GateState::faulted);
  if (!have_command_) return zero(GateState::waiting);
  if (watchdog_expired(now)) {
    // A stale command from before engaging: wait for a fresh one.
    if (last_command_ns_ < engage_ns_) return zero(GateState::waiting);
    if (!tripped_) {
      tripped_ = true;
      ++stats_.watchdog_trips;
    }
    return zero(GateState::watchdog_tripped);
  }

  const double dt = now > last_output_ns_ ? ns_to_seconds(now - last_output_ns_) : 0.0;
  last_output_ns_ = std::max(now, last_output_ns_);
  const double s = ramp_scale(now);
  const FingertipForce goal = scaled(target_, s);
  // Step along the straight line toward the goal, as far as the slowest
  // component allows. Both ends are renderable and the renderable set is
  // convex, so every step is renderable too (per-component stepping would
  // cut corners out of the friction cone).
  const double dn = goal.normal_n - limited_.normal_n;
  const double dx = goal.shear_x_n - limited_.shear_x_n;
  const double dz = goal.shear_z_n - limited_.shear_z_n;
  const double largest = std::max({std::abs(dn), std::abs(dx), std::abs(dz)});
  const double step = model_.limits().max_rate_n_per_s * dt;
  if (largest > step) {
    const double k = step / largest;
    limited_.normal_n += k * dn;
    limited_.shear_x_n += k * dx;
    limited_.shear_z_n += k * dz;
    ++stats_.rate_limited_outputs;
  } else {
    limited_ = goal;
  }
  state_ = s < 1.0 ? GateState::ramping : GateState::active;
  // Rounding in the steps above could leave an ulp outside the limits; the
  // final clamp makes "never above the limits" exact.
  return model_.renderable(limited_);
}

std::string SafetyGate::describe() const {
  return "safety gate for " + std::string(model_.kind()) + " (" + model_.limits().describe() + "): " +
         std::string(to_string(state_)) + ", " + stats_.describe();
}

}  // namespace proprio::haptics
