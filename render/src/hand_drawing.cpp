#include "proprio/render/hand_drawing.hpp"

#include <glm/gtc/matrix_transform.hpp>

#include "proprio/core/glm_interop.hpp"
#include "proprio/core/hand_joint.hpp"

namespace proprio::render {
namespace {

bool tracked(std::uint8_t flags) {
  constexpr std::uint8_t kTracked = kOrientationTracked | kPositionTracked;
  return (flags & kTracked) == kTracked;
}
bool position_valid(std::uint8_t flags) { return (flags & kPositionValid) != 0; }

// A transform taking the unit cylinder (z from -0.5 to 0.5, radius 1) onto
// the segment a-b with the given radius.
glm::mat4 segment_transform(const glm::vec3& a, const glm::vec3& b, float radius) {
  const glm::vec3 d = b - a;
  const float length = glm::length(d);
  const glm::vec3 z = length > 1e-6f ? d / length : glm::vec3(0, 0, 1);
  const glm::vec3 helper = std::abs(z.y) < 0.9f ? glm::vec3(0, 1, 0) : glm::vec3(1, 0, 0);
  const glm::vec3 x = glm::normalize(glm::cross(helper, z));
  const glm::vec3 y = glm::cross(z, x);
  glm::mat4 m(1.0f);
  m[0] = glm::vec4(x * radius, 0);
  m[1] = glm::vec4(y * radius, 0);
  m[2] = glm::vec4(z * length, 0);
  m[3] = glm::vec4((a + b) * 0.5f, 1);
  return m;
}

}  // namespace

Result<UnitMeshes> UnitMeshes::upload(Renderer& renderer) {
  UnitMeshes m;
  auto sphere = renderer.upload(primitives::sphere(1.0f, 20, 12));
  auto cylinder = renderer.upload(primitives::cylinder(1.0f, 0.5f, 16));
  auto box = renderer.upload(primitives::box(glm::vec3(0.5f)));
  if (!sphere) return sphere.error();
  if (!cylinder) return cylinder.error();
  if (!box) return box.error();
  m.sphere = *sphere;
  m.cylinder = *cylinder;
  m.box = *box;
  return m;
}

HandStyle HandStyle::for_hand(Handedness hand) {
  HandStyle s;
  if (hand == Handedness::left) {
    s.joint_color = {0.35f, 0.6f, 0.95f, 1.0f};
    s.bone_color = {0.3f, 0.52f, 0.85f, 1.0f};
  }
  return s;
}

void append_axes(DrawList& draws, const Pose& T_world_frame, const UnitMeshes& meshes, float length_m,
                 float thickness_m) {
  const glm::mat4 frame = to_glm(T_world_frame);
  const glm::vec4 colors[3] = {{0.9f, 0.15f, 0.1f, 1}, {0.15f, 0.8f, 0.2f, 1}, {0.15f, 0.3f, 0.95f, 1}};
  for (int axis = 0; axis < 3; ++axis) {
    glm::vec3 scale(thickness_m);
    scale[axis] = length_m;
    glm::vec3 offset(0.0f);
    offset[axis] = 0.5f * length_m;
    const glm::mat4 m = glm::scale(glm::translate(frame, offset), scale);
    draws.items.push_back({meshes.box, m, colors[axis]});
  }
}

void append_hand(DrawList& draws, const HandPose& pose, const UnitMeshes& meshes, const HandStyle& style) {
  if (!pose.active) return;
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    if (!position_valid(pose.flags[i])) continue;
    const float r = static_cast<float>(pose.radius_m[i] > 0 ? pose.radius_m[i] : 0.008);
    const glm::vec3 p = to_glm(pose.T_world_joint[i].p);
    glm::mat4 m(r);
    m[3] = glm::vec4(p, 1.0f);
    draws.items.push_back({meshes.sphere, m, tracked(pose.flags[i]) ? style.joint_color : style.untracked_color});

    const auto parent = parent_of(joint_at(i));
    // The palm is not a bone end: metacarpals start at the wrist.
    if (!parent || *parent == HandJoint::palm || !position_valid(pose.flags[index_of(*parent)])) continue;
    const std::size_t j = index_of(*parent);
    const float bone_r =
        style.bone_radius_fraction * static_cast<float>(std::min(pose.radius_m[i], pose.radius_m[j]));
    const bool both_tracked = tracked(pose.flags[i]) && tracked(pose.flags[j]);
    draws.items.push_back({meshes.cylinder,
                           segment_transform(to_glm(pose.T_world_joint[j].p), p, bone_r > 0 ? bone_r : 0.005f),
                           both_tracked ? style.bone_color : style.untracked_color});
  }
  if (style.axes) {
    for (HandJoint j : {HandJoint::wrist, HandJoint::palm}) {
      if (position_valid(pose.flags[index_of(j)])) {
        append_axes(draws, pose.joint(j), meshes, style.axis_length_m, style.axis_thickness_m);
      }
    }
  }
}

}  // namespace proprio::render
