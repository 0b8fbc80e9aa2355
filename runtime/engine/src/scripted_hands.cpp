#include "proprio/engine/scripted_hands.hpp"

namespace proprio::engine {
namespace {
haptics::TouchScriptOptions on_focus(haptics::TouchScriptOptions o, const Scene& scene) {
  o.p_surface_in_world = scene.p_focus_in_world;
  return o;
}
}  // namespace

ScriptedTouchSource::ScriptedTouchSource(std::shared_ptr<const HandModel> model, Handedness hand, const Scene& scene,
                                         TimeNs start_ns, haptics::TouchScriptOptions options)
    : model_(std::move(model)), hand_(hand), start_ns_(start_ns), script_(*model_, hand, on_focus(options, scene)) {}

Result<HandPose> ScriptedTouchSource::pose_at(Handedness hand, TimeNs t_ns) {
  HandPose out;
  if (lookup(hand, t_ns, out) != PoseLookup::exact) {
    return make_error(Errc::unavailable, "the scripted touch drives the other hand only");
  }
  return out;
}

PoseLookup ScriptedTouchSource::lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept {
  if (hand != hand_) return PoseLookup::empty;
  out = script_.pose_at(static_cast<double>(t_ns - start_ns_) * 1e-9, t_ns);
  return PoseLookup::exact;
}

}  // namespace proprio::engine
