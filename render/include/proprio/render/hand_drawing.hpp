#pragma once
// Hands from a HandPose: a sphere per joint with the joint's radius and a
// cylinder per bone (sphere + cylinder + sphere reads as a capsule), plus
// optional axis triads at the wrist and palm that make OpenXR's joint
// conventions visible: x red, y green (back of the hand), z blue (towards
// the wrist, along the bones).
#include "proprio/core/hand_pose.hpp"
#include "proprio/render/renderer.hpp"

namespace proprio::render {

// Unit meshes that hands and scenes scale per draw.
struct UnitMeshes {
  MeshId sphere = 0;    // radius 1
  MeshId cylinder = 0;  // radius 1, z from -0.5 to 0.5
  MeshId box = 0;       // half extents 0.5

  static Result<UnitMeshes> upload(Renderer& renderer);
};

struct HandStyle {
  glm::vec4 joint_color{0.95f, 0.62f, 0.35f, 1.0f};
  glm::vec4 bone_color{0.85f, 0.55f, 0.32f, 1.0f};
  glm::vec4 untracked_color{0.45f, 0.45f, 0.48f, 1.0f};  // joints without the TRACKED flags
  float bone_radius_fraction = 0.7f;  // of the smaller joint radius at the bone's ends
  bool axes = true;
  float axis_length_m = 0.05f;  // long enough to stick out of the palm and wrist spheres
  float axis_thickness_m = 0.002f;

  // Right hands warm, left hands cool, so a mirrored hand shows at once.
  static HandStyle for_hand(Handedness hand);
};

// Appends draw items for `pose` (nothing when it is not active).
void append_hand(DrawList& draws, const HandPose& pose, const UnitMeshes& meshes, const HandStyle& style);
// An axis triad for any pose (x red, y green, z blue).
void append_axes(DrawList& draws, const Pose& T_world_frame, const UnitMeshes& meshes, float length_m,
                 float thickness_m);

}  // namespace proprio::render
