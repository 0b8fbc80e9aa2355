#pragma once
// Hand sources made for the engine. ScriptedTouchSource plays haptics::TouchScript on a scene: the index finger
// lands on the scene's focus point, presses, slides and lifts, over and over.
// The demo's and headless tests' "simulated tracked hand touching the
// half-cylinder"; time is read from the clock it is given, so it works in
// simulated time.
#include <memory>
#include <mutex>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/hand_source.hpp"
#include "proprio/engine/scene.hpp"
#include "proprio/haptics/touch_script.hpp"

namespace proprio::engine {

class ScriptedTouchSource final : public HandSource {
 public:
  ScriptedTouchSource(std::shared_ptr<const HandModel> model, Handedness hand, const Scene& scene, TimeNs start_ns,
                      haptics::TouchScriptOptions options = {});
  std::string_view name() const noexcept override { return "touch"; }
  bool available(Handedness hand) const noexcept override { return hand == hand_; }
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override;
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override;

 private:
  std::shared_ptr<const HandModel> model_;
  Handedness hand_;
  TimeNs start_ns_;
  haptics::TouchScript script_;
};

// A source whose coordinates are not the scene's (the stretch glove's wrist
// fixed below a head at the origin, a VIST session's own world) moved so that
// the first usable wrist pose lands at `p_wrist_target_in_world`, as a VR
// "recentre" does: one translation, fixed from then on, orientation kept.
// Before the first pose the wrapped source's answer passes through unmoved.
class RecentredHandSource final : public HandSource {
 public:
  RecentredHandSource(std::shared_ptr<HandSource> source, Vec3 p_wrist_target_in_world);
  std::string_view name() const noexcept override { return source_->name(); }
  bool available(Handedness hand) const noexcept override { return source_->available(hand); }
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override;
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override;
  // The translation applied (zero until the first usable pose).
  Vec3 offset() const noexcept;

 private:
  void shift(HandPose& pose) noexcept;
  std::shared_ptr<HandSource> source_;
  Vec3 p_target_;
  mutable std::mutex mutex_;  // guards offset_ (lookups may come from several threads)
  bool anchored_ = false;
  Vec3 offset_ = Vec3::Zero();
};

// Where recentred hands put the wrist: above and in front of the scene's
// focus, so the fingers reach over it.
Vec3 recentred_wrist_target(const Scene& scene);

}  // namespace proprio::engine
