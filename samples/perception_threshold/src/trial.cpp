#include "proprio/perception_threshold/trial.hpp"

#include <fmt/format.h>

namespace proprio::perception {

ForceChannel::ForceChannel(std::shared_ptr<const haptics::FingertipDeviceModel> model,
                           std::shared_ptr<haptics::FingertipSink> sink)
    : model_(std::move(model)), sink_(std::move(sink)), gate_(*model_) {}

void ForceChannel::engage(TimeNs now) noexcept { gate_.engage(now); }

void ForceChannel::disengage(TimeNs now) noexcept {
  gate_.disengage();
  last_sent_ = {};
  if (sink_) sink_->send(model_->rest(), {}, false, now);
}

void ForceChannel::update(const haptics::FingertipForce& desired, TimeNs now) noexcept {
  gate_.command(desired, now);
  last_sent_ = gate_.output(now);
  if (sink_) sink_->send(model_->inverse(last_sent_), last_sent_, gate_.engaged(), now);
}

std::string ForceChannel::describe() const {
  return fmt::format("{} -> {}", model_->describe(), sink_ ? sink_->describe() : "no device");
}

TrialView trial_view(const PerceptionProtocol& protocol, const PlacedScene& scene, const TrialPresentation& trial,
                     Phase phase, const Vec3& p_finger, Cue cue) {
  TrialView v;
  switch (phase) {
    case Phase::adaptation: {
      v.spheres.push_back({drawn_sphere(protocol, scene, p_finger).p_in_world, trial.true_is_blue});
      // Experiment 2 renders contact on the true sphere while adapting.
      if (trial.haptic != HapticTarget::none) v.p_haptic_centre_in_world = p_finger;
      break;
    }
    case Phase::blind:
      v.black = true;
      v.cue = cue;
      break;
    case Phase::answer: {
      const Vec3 p_false = trial.p_false_in_world(p_finger);
      v.spheres.push_back({drawn_sphere(protocol, scene, p_finger).p_in_world, trial.true_is_blue});
      v.spheres.push_back({drawn_sphere(protocol, scene, p_false).p_in_world, !trial.true_is_blue});
      if (trial.haptic == HapticTarget::true_sphere) v.p_haptic_centre_in_world = p_finger;
      if (trial.haptic == HapticTarget::false_sphere) v.p_haptic_centre_in_world = p_false;
      break;
    }
  }
  return v;
}

haptics::FingertipForce haptic_force(const PerceptionProtocol& protocol, const PlacedScene& scene,
                                     const TrialView& view, const Quat& q_world_tip, double* penetration_m) {
  if (penetration_m) *penetration_m = 0;
  if (!view.p_haptic_centre_in_world) return {};
  const auto contact = haptics::sphere_on_half_cylinder(protocol.contact_law(), scene.cylinder,
                                                        *view.p_haptic_centre_in_world, protocol.fingertip_radius_m,
                                                        q_world_tip);
  if (penetration_m) *penetration_m = contact.in_contact ? contact.penetration_m : 0.0;
  // What the device renders is the force as the pad feels it (docs/haptics.md).
  return contact.in_contact ? contact.on_pad : haptics::FingertipForce{};
}

}  // namespace proprio::perception
