#pragma once
// A HandSource that plays haptics::TouchScript on a scene: the index finger
// lands on the scene's focus point, presses, slides and lifts, over and over.
// The demo's and headless tests' "simulated tracked hand touching the
// half-cylinder"; time is read from the clock it is given, so it works in
// simulated time.
#include <memory>

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

}  // namespace proprio::engine
