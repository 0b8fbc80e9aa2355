#pragma once
// Uploads a scene's meshes once and appends its entities, the floor and the
// hands to a draw list each frame.
#include <vector>

#include "proprio/engine/app.hpp"
#include "proprio/engine/scene.hpp"
#include "proprio/render/hand_drawing.hpp"
#include "proprio/render/hand_skin.hpp"
#include "proprio/render/renderer.hpp"

namespace proprio::engine {

class SceneDrawer {
 public:
  // Hands as options.hand_look says; the skinned look loads options.hand_gltf
  // or generates a hand from `hand_model`.
  static Result<SceneDrawer> create(render::Renderer& renderer, const Scene& scene, const AppOptions& options,
                                    const HandModel& hand_model);

  // Entity i at `T_world_entity[i]` (the simulation moves free bodies).
  void append_scene(render::DrawList& draws, const std::vector<Pose>& T_world_entity) const;
  // The same with the frame hook's per-entity visibility and colours.
  void append_scene(render::DrawList& draws, const std::vector<Pose>& T_world_entity,
                    const std::vector<FrameContext::EntityStyle>& styles) const;
  void append_marker(render::DrawList& draws, const FrameContext::Marker& marker) const;
  void append_hand(render::DrawList& draws, const HandPose& pose, bool ghost) const;

 private:
  std::vector<render::MeshId> meshes_;
  std::vector<glm::vec4> colors_;
  render::UnitMeshes unit_;
  std::optional<render::SkinnedHand> skinned_hand_;  // the skinned look
  std::optional<double> floor_height_m_;
};

}  // namespace proprio::engine
