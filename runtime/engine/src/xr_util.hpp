#pragma once
// OpenXR helpers shared by the engine's XR session, its Vulkan hooks and the
// probe. Include after <openxr/openxr.h> (and the platform header where needed).
#include <openxr/openxr.h>
#include <openxr/openxr_reflection.h>

#include <cstring>
#include <vector>

namespace proprio::engine::detail {

// An instance function by name; nullptr when the instance does not have it.
template <typename Fn>
Fn xr_load(XrInstance instance, const char* name) {
  PFN_xrVoidFunction f = nullptr;
  if (XR_FAILED(xrGetInstanceProcAddr(instance, name, &f))) return nullptr;
  return reinterpret_cast<Fn>(f);
}

inline bool has_extension(const std::vector<XrExtensionProperties>& exts, const char* name) {
  for (const auto& e : exts) {
    if (std::strcmp(e.extensionName, name) == 0) return true;
  }
  return false;
}

// The XrResult's name without an instance (xrResultToString needs one).
inline const char* xr_result_name(XrResult r) {
  switch (r) {
#define PROPRIO_XR_RESULT_CASE(name, value) \
  case name: return #name;
    XR_LIST_ENUM_XrResult(PROPRIO_XR_RESULT_CASE)
#undef PROPRIO_XR_RESULT_CASE
        default : return "unknown XrResult";
  }
}

inline const char* xr_session_state_name(XrSessionState s) {
  switch (s) {
#define PROPRIO_XR_STATE_CASE(name, value) \
  case name: return #name;
    XR_LIST_ENUM_XrSessionState(PROPRIO_XR_STATE_CASE)
#undef PROPRIO_XR_STATE_CASE
        default : return "unknown state";
  }
}

}  // namespace proprio::engine::detail
