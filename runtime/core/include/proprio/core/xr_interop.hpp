#pragma once
// Conversions between Proprio's Eigen types and OpenXR structs. Header-only so
// that only code that already speaks OpenXR pays for <openxr/openxr.h>.
#include <openxr/openxr.h>

#include "proprio/core/math.hpp"

namespace proprio {

inline XrVector3f to_xr(const Vec3& v) {
  return {static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z())};
}
inline XrQuaternionf to_xr(const Quat& q) {
  return {static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()),
          static_cast<float>(q.w())};
}
inline XrPosef to_xr(const Pose& T) { return {to_xr(T.q), to_xr(T.p)}; }

inline Vec3 from_xr(const XrVector3f& v) { return {v.x, v.y, v.z}; }
// Eigen's constructor order is (w, x, y, z); XrQuaternionf's fields are x, y, z, w.
inline Quat from_xr(const XrQuaternionf& q) { return Quat(q.w, q.x, q.y, q.z).normalized(); }
inline Pose from_xr(const XrPosef& T) { return {from_xr(T.orientation), from_xr(T.position)}; }

}  // namespace proprio
