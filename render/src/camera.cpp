#include "proprio/render/camera.hpp"

#include <cmath>

#include "proprio/core/glm_interop.hpp"

namespace proprio::render {

Fov symmetric_fov(float vertical_fov_rad, float aspect) {
  const float half_v = vertical_fov_rad * 0.5f;
  const float half_h = std::atan(std::tan(half_v) * aspect);
  return {-half_h, half_h, half_v, -half_v};
}

glm::mat4 projection(const Fov& fov, float near_m, float far_m) {
  const float l = std::tan(fov.angle_left), r = std::tan(fov.angle_right);
  const float u = std::tan(fov.angle_up), d = std::tan(fov.angle_down);
  const float w = r - l;
  const float h = d - u;  // negative: Vulkan's y points down
  glm::mat4 m(0.0f);
  m[0][0] = 2.0f / w;
  m[2][0] = (r + l) / w;
  m[1][1] = 2.0f / h;
  m[2][1] = (u + d) / h;
  m[2][2] = -far_m / (far_m - near_m);
  m[3][2] = -(far_m * near_m) / (far_m - near_m);
  m[2][3] = -1.0f;
  return m;
}

glm::mat4 view_matrix(const View& view) { return to_glm(view.T_world_eye.inverse()); }

Pose look_at(const Vec3& p_eye_in_world, const Vec3& p_target_in_world) {
  const Vec3 forward = (p_target_in_world - p_eye_in_world).normalized();
  Vec3 up = Vec3::UnitY();
  if (std::abs(forward.dot(up)) > 0.999) up = Vec3::UnitZ();
  const Vec3 x = forward.cross(up).normalized();
  const Vec3 y = x.cross(forward);
  Mat3 R;
  R.col(0) = x;
  R.col(1) = y;
  R.col(2) = -forward;
  return {Quat(R).normalized(), p_eye_in_world};
}

std::array<View, 2> stereo_views(const Pose& T_world_head, float ipd_m, const Fov& fov) {
  const double half = 0.5 * ipd_m;
  return {View{T_world_head * Pose{Quat::Identity(), Vec3(-half, 0, 0)}, fov},
          View{T_world_head * Pose{Quat::Identity(), Vec3(half, 0, 0)}, fov}};
}

}  // namespace proprio::render
