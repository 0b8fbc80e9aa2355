#pragma once
// One trial as the participant experiences it, shared by live runs (the
// engine's frame hook) and simulated ones: what is drawn in each phase, and
// the fingertip device channel the contact force goes through.
#include <memory>
#include <optional>
#include <vector>

#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/safety.hpp"
#include "proprio/haptics/servo_loop.hpp"
#include "proprio/perception_threshold/protocol.hpp"

namespace proprio::perception {

// One fingertip device behind its safety gate (clamp, rate limit, ramp-in,
// watchdog): the desired force goes in, the device model's motor angles go
// to the sink. Not thread-safe; one owner ticks it.
class ForceChannel {
 public:
  ForceChannel(std::shared_ptr<const haptics::FingertipDeviceModel> model,
               std::shared_ptr<haptics::FingertipSink> sink);
  void engage(TimeNs now) noexcept;
  // Zero force at once and from now on, until engage().
  void disengage(TimeNs now) noexcept;
  bool engaged() const noexcept { return gate_.engaged(); }
  void update(const haptics::FingertipForce& desired, TimeNs now) noexcept;
  // What the device renders (its force sensors, or the last command).
  haptics::FingertipForce felt() const noexcept { return sink_ ? sink_->measured() : last_sent_; }
  const haptics::SafetyGate& gate() const noexcept { return gate_; }
  // The force last sent to the device (after the gate).
  const haptics::FingertipForce& sent() const noexcept { return last_sent_; }
  std::string describe() const;

 private:
  std::shared_ptr<const haptics::FingertipDeviceModel> model_;
  std::shared_ptr<haptics::FingertipSink> sink_;
  haptics::SafetyGate gate_;
  haptics::FingertipForce last_sent_;
};

// What the participant sees at one moment of a trial.
struct TrialView {
  bool black = false;            // blind phase
  Cue cue = Cue::none;           // blind phase arrow
  struct Sphere {
    Vec3 p_in_world = Vec3::Zero();
    bool blue = true;
  };
  std::vector<Sphere> spheres;   // adaptation: the true sphere; answer: both
  // The sphere whose contact drives the device now (nullopt: none).
  std::optional<Vec3> p_haptic_centre_in_world;
};

// `p_finger_in_world`: the tracked fingertip (the true sphere's centre).
TrialView trial_view(const PerceptionProtocol& protocol, const PlacedScene& scene, const TrialPresentation& trial,
                     Phase phase, const Vec3& p_finger_in_world, Cue cue);

// The desired device force for the view's haptic sphere (zero when none or
// no contact); `q_world_tip` orients it on the finger pad.
haptics::FingertipForce haptic_force(const PerceptionProtocol& protocol, const PlacedScene& scene,
                                     const TrialView& view, const Quat& q_world_tip, double* penetration_m = nullptr);

}  // namespace proprio::perception
