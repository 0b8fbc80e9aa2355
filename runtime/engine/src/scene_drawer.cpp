#include "scene_drawer.hpp"

#include <glm/gtc/matrix_transform.hpp>

#include "proprio/core/glm_interop.hpp"

namespace proprio::engine {
namespace {

using haptics::ShapeKind;

render::MeshData mesh_for(const Entity& e) {
  const auto& b = e.body;
  const auto r = static_cast<float>(b.radius_m);
  const auto hl = static_cast<float>(b.half_length_m);
  switch (b.shape) {
    case ShapeKind::box: return render::primitives::box(to_glm(b.half_extents_m));
    case ShapeKind::sphere: return render::primitives::sphere(r);
    case ShapeKind::cylinder: return e.peg_visual ? render::primitives::peg(r, hl) : render::primitives::cylinder(r, hl);
    case ShapeKind::half_cylinder: return render::primitives::half_cylinder(r, hl, 64);
    case ShapeKind::capsule: return render::primitives::capsule(r, hl);
    case ShapeKind::plate_with_hole:
      return render::primitives::plate_with_hole(static_cast<float>(b.hole_radius_m), to_glm(b.half_extents_m));
  }
  return render::primitives::box(glm::vec3(0.01f));
}

}  // namespace

Result<SceneDrawer> SceneDrawer::create(render::Renderer& renderer, const Scene& scene, const AppOptions& options,
                                        const HandModel& hand_model, const std::vector<DeformingSurface>& surfaces) {
  SceneDrawer d;
  for (const DeformingSurface& s : surfaces) {
    render::MeshData mesh;
    mesh.name = s.name;
    mesh.vertices.assign(s.vertex_count, render::Vertex{glm::vec3(0.0f), glm::vec3(0, 0, 1)});
    mesh.indices = s.triangles;
    auto id = renderer.upload_deforming(mesh);
    if (!id) return id.error().with_context("deforming surface '" + s.name + "'");
    d.surfaces_.push_back({*id, s.triangles, s.vertex_count, glm::vec4(s.rgba[0], s.rgba[1], s.rgba[2], s.rgba[3])});
  }
  if (options.hand_look == HandLook::skinned) {
    Result<render::SkinnedMeshData> mesh =
        options.hand_gltf.empty()
            ? Result<render::SkinnedMeshData>(render::generate_hand_mesh(hand_model, Handedness::right))
            : render::load_skinned_gltf(options.hand_gltf);
    if (!mesh) return mesh.error().with_context("skinned hand");
    auto hand = render::SkinnedHand::upload(renderer, *mesh);
    if (!hand) return hand.error().with_context("skinned hand");
    d.skinned_hand_ = std::move(hand).value();
  }
  auto unit = render::UnitMeshes::upload(renderer);
  if (!unit) return unit.error();
  d.unit_ = *unit;
  d.floor_height_m_ = scene.floor_height_m;
  for (const Entity& e : scene.entities) {
    Result<render::MeshData> mesh = e.gltf ? render::load_gltf(*e.gltf) : Result<render::MeshData>(mesh_for(e));
    if (!mesh) return mesh.error().with_context("scene object '" + e.body.name + "'");
    auto id = renderer.upload(*mesh);
    if (!id) return id.error().with_context("scene object '" + e.body.name + "'");
    d.meshes_.push_back(*id);
    d.colors_.emplace_back(e.body.rgba[0], e.body.rgba[1], e.body.rgba[2], e.body.rgba[3]);
  }
  return d;
}

void SceneDrawer::append_scene(render::DrawList& draws, const std::vector<Pose>& T_world_entity) const {
  append_scene(draws, T_world_entity, {});
}

void SceneDrawer::append_scene(render::DrawList& draws, const std::vector<Pose>& T_world_entity,
                               const std::vector<FrameContext::EntityStyle>& styles) const {
  if (floor_height_m_) {
    const glm::mat4 floor = glm::scale(
        glm::translate(glm::mat4(1.0f), glm::vec3(0.0f, static_cast<float>(*floor_height_m_) - 0.005f, -0.5f)),
        glm::vec3(6.0f, 0.01f, 6.0f));
    draws.items.push_back({unit_.box, floor, {0.32f, 0.34f, 0.36f, 1.0f}});
  }
  for (std::size_t i = 0; i < meshes_.size() && i < T_world_entity.size(); ++i) {
    if (i < styles.size()) {
      if (!styles[i].visible) continue;
      const auto& c = styles[i].rgba;
      const Pose& T = styles[i].T_world_entity ? *styles[i].T_world_entity : T_world_entity[i];
      draws.items.push_back({meshes_[i], to_glm(T), {c[0], c[1], c[2], c[3]}});
    } else {
      draws.items.push_back({meshes_[i], to_glm(T_world_entity[i]), colors_[i]});
    }
  }
}

void SceneDrawer::append_marker(render::DrawList& draws, const FrameContext::Marker& m) const {
  using Shape = FrameContext::Marker::Shape;
  glm::vec3 scale;
  render::MeshId mesh = unit_.sphere;
  switch (m.shape) {
    case Shape::sphere: scale = glm::vec3(static_cast<float>(m.size_m.x())); break;
    case Shape::box:  // the unit box has half extents 0.5
      mesh = unit_.box;
      scale = 2.0f * to_glm(m.size_m);
      break;
    case Shape::cylinder:  // unit cylinder: radius 1, length 1
      mesh = unit_.cylinder;
      scale = glm::vec3(static_cast<float>(m.size_m.x()), static_cast<float>(m.size_m.x()),
                        2.0f * static_cast<float>(m.size_m.z()));
      break;
  }
  draws.items.push_back({mesh, glm::scale(to_glm(m.T_world_marker), scale), {m.rgba[0], m.rgba[1], m.rgba[2], m.rgba[3]}});
}

void SceneDrawer::append_hand(render::DrawList& draws, const HandPose& pose, bool ghost) const {
  if (skinned_hand_) {
    glm::vec4 color = render::skin_color_for(pose.hand);
    if (ghost) color.a = 0.3f;
    render::append_skinned_hand(draws, pose, *skinned_hand_, color);
    return;
  }
  render::HandStyle style = render::HandStyle::for_hand(pose.hand);
  if (ghost) {
    style.joint_color.a = style.bone_color.a = style.untracked_color.a = 0.3f;
    style.axes = false;
  }
  render::append_hand(draws, pose, unit_, style);
}

void SceneDrawer::append_surface(render::DrawList& draws, std::size_t i, const std::vector<Vec3>& p_world) const {
  if (i >= surfaces_.size() || p_world.size() != surfaces_[i].vertex_count || p_world.empty()) return;
  const Surface& s = surfaces_[i];
  // Written straight into the draw list (which keeps its capacity), so a
  // deforming surface allocates nothing per frame either.
  const std::size_t first = draws.posed_vertices.size();
  for (const Vec3& p : p_world) draws.posed_vertices.push_back({to_glm(p), glm::vec3(0.0f)});
  render::Vertex* v = draws.posed_vertices.data() + first;
  for (std::size_t t = 0; t + 2 < s.triangles.size(); t += 3) {
    const auto a = s.triangles[t], b = s.triangles[t + 1], c = s.triangles[t + 2];
    const glm::vec3 n = glm::cross(v[b].position - v[a].position, v[c].position - v[a].position);  // |n| = 2 area
    v[a].normal += n;
    v[b].normal += n;
    v[c].normal += n;
  }
  for (std::size_t k = 0; k < s.vertex_count; ++k) {
    const float len = glm::length(v[k].normal);
    v[k].normal = len > 0.0f ? v[k].normal / len : glm::vec3(0, 0, 1);
  }
  render::SkinnedDrawItem item{s.mesh, 0, s.color};
  item.first_posed_vertex = static_cast<std::uint32_t>(first);
  draws.skinned.push_back(item);
}

}  // namespace proprio::engine
