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
                                    const HandModel& hand_model, const std::vector<DeformingSurface>& surfaces = {});

  // Entity i at `T_world_entity[i]` (the simulation moves free bodies).
  void append_scene(render::DrawList& draws, const std::vector<Pose>& T_world_entity) const;
  // The same with the frame hook's per-entity visibility and colours.
  void append_scene(render::DrawList& draws, const std::vector<Pose>& T_world_entity,
                    const std::vector<FrameContext::EntityStyle>& styles) const;
  void append_marker(render::DrawList& draws, const FrameContext::Marker& marker) const;
  void append_hand(render::DrawList& draws, const HandPose& pose, bool ghost) const;
  // Surface i (create()'s `surfaces`) at these world positions, with
  // area-weighted vertex normals; nothing when the count is not the surface's.
  void append_surface(render::DrawList& draws, std::size_t i, const std::vector<Vec3>& p_world) const;

 private:
  struct Surface {
    render::MeshId mesh = 0;
    std::vector<std::uint32_t> triangles;
    std::size_t vertex_count = 0;
    glm::vec4 color{1.0f};
  };
  std::vector<Surface> surfaces_;
  std::vector<render::MeshId> meshes_;
  std::vector<glm::vec4> colors_;
  render::UnitMeshes unit_;
  std::optional<render::SkinnedHand> skinned_hand_;  // the skinned look
  std::optional<double> floor_height_m_;
};

}  // namespace proprio::engine
