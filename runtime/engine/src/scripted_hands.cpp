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

RecentredHandSource::RecentredHandSource(std::shared_ptr<HandSource> source, Vec3 p_wrist_target_in_world)
    : source_(std::move(source)), p_target_(std::move(p_wrist_target_in_world)) {}

void RecentredHandSource::shift(HandPose& pose) noexcept {
  if (!pose.active) return;
  std::lock_guard lock(mutex_);
  if (!anchored_) {
    offset_ = p_target_ - pose.joint(HandJoint::wrist).p;
    anchored_ = true;
  }
  for (Pose& T : pose.T_world_joint) T.p += offset_;
}

Result<HandPose> RecentredHandSource::pose_at(Handedness hand, TimeNs t_ns) {
  auto pose = source_->pose_at(hand, t_ns);
  if (pose) shift(*pose);
  return pose;
}

PoseLookup RecentredHandSource::lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept {
  const PoseLookup r = source_->lookup(hand, t_ns, out);
  if (is_usable(r) || r == PoseLookup::stale) shift(out);
  return r;
}

Vec3 RecentredHandSource::offset() const noexcept {
  std::lock_guard lock(mutex_);
  return offset_;
}

Vec3 recentred_wrist_target(const Scene& scene) { return scene.p_focus_in_world + Vec3(0.0, 0.08, 0.14); }

}  // namespace proprio::engine

