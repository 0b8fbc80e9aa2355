#pragma once
// Views in OpenXR's terms, so the XR, window and headless paths share one
// code path: an eye pose in the world (the eye looks along its -z, +y up, as
// XrView::pose) and four field-of-view angles (XrFovf: left and down are
// negative). Projections follow Vulkan's clip space: y down, depth 0 (near)
// to 1 (far).
#include <array>

#include <glm/glm.hpp>

#include "proprio/core/math.hpp"

namespace proprio::render {

struct Fov {
  float angle_left = -0.785f;  // radians
  float angle_right = 0.785f;
  float angle_up = 0.785f;
  float angle_down = -0.785f;
};

struct View {
  Pose T_world_eye;
  Fov fov;
};

// A symmetric field of view from the vertical angle and width / height.
Fov symmetric_fov(float vertical_fov_rad, float aspect);
glm::mat4 projection(const Fov& fov, float near_m = 0.02f, float far_m = 50.0f);
glm::mat4 view_matrix(const View& view);  // world -> eye

// An eye at `p_eye_in_world` looking at `p_target_in_world`, with world +y up
// (falls back to +z when looking straight up or down).
Pose look_at(const Vec3& p_eye_in_world, const Vec3& p_target_in_world);

// Two eyes `ipd_m` apart along the head's x axis (left eye first, as
// OpenXR's view order for PRIMARY_STEREO).
std::array<View, 2> stereo_views(const Pose& T_world_head, float ipd_m, const Fov& fov);

}  // namespace proprio::render
