#pragma once
// Conversions to GLM, used only at the render boundary.
#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include "proprio/core/math.hpp"

namespace proprio {

inline glm::vec3 to_glm(const Vec3& v) {
  return {static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z())};
}
// glm::quat's constructor takes (w, x, y, z) in GLM 0.9.9 without GLM_FORCE_QUAT_DATA_XYZW.
inline glm::quat to_glm(const Quat& q) {
  return glm::quat(static_cast<float>(q.w()), static_cast<float>(q.x()), static_cast<float>(q.y()),
                   static_cast<float>(q.z()));
}
inline glm::mat4 to_glm(const Pose& T) {
  glm::mat4 m = glm::mat4_cast(to_glm(T.q));
  m[3] = glm::vec4(to_glm(T.p), 1.0f);  // GLM is column-major: m[3] is the translation column
  return m;
}

inline Vec3 from_glm(const glm::vec3& v) { return {v.x, v.y, v.z}; }
inline Quat from_glm(const glm::quat& q) { return Quat(q.w, q.x, q.y, q.z).normalized(); }

}  // namespace proprio
