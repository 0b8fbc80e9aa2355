#pragma once
// A fake "next layer/runtime" for driving the Proprio layer's negotiation and
// dispatch directly, without the OpenXR loader: the test plays the loader,
// the layer sits in the middle, and these functions play the runtime. Its
// spaces are static (T_base_space given per test), its time is XrTime =
// monotonic ns + kTimeOffsetNs.
#include <openxr/openxr.h>

#include <atomic>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

#include "proprio/openxr_layer/loader_interfaces.hpp"
#include "proprio/core/xr_ext.hpp"

extern "C" XrResult XRAPI_CALL xrNegotiateLoaderApiLayerInterface(const XrNegotiateLoaderInfo*, const char*,
                                                                  XrNegotiateApiLayerRequest*);

namespace fake_next {

inline constexpr std::int64_t kTimeOffsetNs = 3'000'000'000;

struct State {
  std::vector<std::string> enabled_extensions;  // what reached the "runtime"
  XrPosef T_base_source{{0, 0, 0, 1}, {0, 0, 0}};  // every located space, in every base space
  bool runtime_hand_tracking = false;
  std::atomic<int> locate_space_calls{0};
  std::atomic<int> live_spaces{0};
};
inline State& state() {
  static State s;
  return s;
}

inline XrInstance instance_handle() { return reinterpret_cast<XrInstance>(0x1001); }
inline XrSession session_handle() { return reinterpret_cast<XrSession>(0x2002); }

inline XrResult XRAPI_CALL destroy_instance(XrInstance) { return XR_SUCCESS; }
inline XrResult XRAPI_CALL get_system_properties(XrInstance, XrSystemId, XrSystemProperties* p) {
  std::strcpy(p->systemName, "fake");
  for (auto* s = static_cast<XrBaseOutStructure*>(p->next); s; s = s->next) {
    if (s->type == XR_TYPE_SYSTEM_HAND_TRACKING_PROPERTIES_EXT) {
      reinterpret_cast<XrSystemHandTrackingPropertiesEXT*>(s)->supportsHandTracking = state().runtime_hand_tracking;
    }
  }
  return XR_SUCCESS;
}
inline XrResult XRAPI_CALL create_session(XrInstance, const XrSessionCreateInfo*, XrSession* s) {
  *s = session_handle();
  return XR_SUCCESS;
}
inline XrResult XRAPI_CALL destroy_session(XrSession) { return XR_SUCCESS; }
inline XrResult XRAPI_CALL create_reference_space(XrSession, const XrReferenceSpaceCreateInfo*, XrSpace* s) {
  ++state().live_spaces;
  *s = reinterpret_cast<XrSpace>(0x3003);
  return XR_SUCCESS;
}
inline XrResult XRAPI_CALL destroy_space(XrSpace) {
  --state().live_spaces;
  return XR_SUCCESS;
}
inline XrResult XRAPI_CALL locate_space(XrSpace, XrSpace, XrTime, XrSpaceLocation* l) {
  state().locate_space_calls.fetch_add(1, std::memory_order_relaxed);
  l->pose = state().T_base_source;
  l->locationFlags = XR_SPACE_LOCATION_ORIENTATION_VALID_BIT | XR_SPACE_LOCATION_POSITION_VALID_BIT |
                     XR_SPACE_LOCATION_ORIENTATION_TRACKED_BIT | XR_SPACE_LOCATION_POSITION_TRACKED_BIT;
  for (auto* s = static_cast<XrBaseOutStructure*>(l->next); s; s = s->next) {
    if (s->type == XR_TYPE_SPACE_VELOCITY) {
      auto* v = reinterpret_cast<XrSpaceVelocity*>(s);
      v->velocityFlags = XR_SPACE_VELOCITY_LINEAR_VALID_BIT | XR_SPACE_VELOCITY_ANGULAR_VALID_BIT;
      v->linearVelocity = {0, 0, 0};
      v->angularVelocity = {0, 0, 0};
    }
  }
  return XR_SUCCESS;
}
inline XrResult XRAPI_CALL convert_time(XrInstance, XrTime t, timespec* ts) {
  const std::int64_t ns = t - kTimeOffsetNs;
  ts->tv_sec = ns / 1'000'000'000;
  ts->tv_nsec = ns % 1'000'000'000;
  return XR_SUCCESS;
}

inline XrResult XRAPI_CALL get_instance_proc_addr(XrInstance, const char* name, PFN_xrVoidFunction* f) {
  const std::string n(name);
  auto give = [&](auto fn) {
    *f = reinterpret_cast<PFN_xrVoidFunction>(fn);
    return XR_SUCCESS;
  };
  if (n == "xrDestroyInstance") return give(&destroy_instance);
  if (n == "xrGetSystemProperties") return give(&get_system_properties);
  if (n == "xrCreateSession") return give(&create_session);
  if (n == "xrDestroySession") return give(&destroy_session);
  if (n == "xrCreateReferenceSpace") return give(&create_reference_space);
  if (n == "xrDestroySpace") return give(&destroy_space);
  if (n == "xrLocateSpace") return give(&locate_space);
  if (n == "xrConvertTimeToTimespecTimeKHR") return give(&convert_time);
  *f = nullptr;
  return XR_ERROR_FUNCTION_UNSUPPORTED;
}

inline XrResult XRAPI_CALL create_api_layer_instance(const XrInstanceCreateInfo* info, const XrApiLayerCreateInfo*,
                                                     XrInstance* instance) {
  state().enabled_extensions.clear();
  for (uint32_t i = 0; i < info->enabledExtensionCount; ++i) {
    const std::string e = info->enabledExtensionNames[i];
    const bool known = e == XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME || e == XR_MND_HEADLESS_EXTENSION_NAME ||
                       (state().runtime_hand_tracking && e == XR_EXT_HAND_TRACKING_EXTENSION_NAME);
    if (!known) return XR_ERROR_EXTENSION_NOT_PRESENT;
    state().enabled_extensions.push_back(e);
  }
  *instance = instance_handle();
  return XR_SUCCESS;
}

// Plays the loader: negotiates, then creates an instance through the layer.
struct Chain {
  XrNegotiateApiLayerRequest request{};
  XrApiLayerNextInfo next_info{};
  XrApiLayerCreateInfo create_info{};

  XrResult negotiate() {
    XrNegotiateLoaderInfo loader{};
    loader.structType = XR_LOADER_INTERFACE_STRUCT_LOADER_INFO;
    loader.structVersion = PROPRIO_XR_LOADER_INFO_STRUCT_VERSION;
    loader.structSize = sizeof loader;
    loader.minInterfaceVersion = 1;
    loader.maxInterfaceVersion = 1;
    loader.minApiVersion = XR_MAKE_VERSION(1, 0, 0);
    loader.maxApiVersion = XR_CURRENT_API_VERSION;
    request.structType = XR_LOADER_INTERFACE_STRUCT_API_LAYER_REQUEST;
    request.structVersion = PROPRIO_XR_API_LAYER_INFO_STRUCT_VERSION;
    request.structSize = sizeof request;
    return xrNegotiateLoaderApiLayerInterface(&loader, "XR_APILAYER_PROPRIO_hand_tracking", &request);
  }

  XrResult create_instance(std::vector<const char*> extensions, XrInstance* instance) {
    next_info.structType = XR_LOADER_INTERFACE_STRUCT_API_LAYER_NEXT_INFO;
    next_info.structVersion = PROPRIO_XR_API_LAYER_NEXT_INFO_STRUCT_VERSION;
    next_info.structSize = sizeof next_info;
    std::strcpy(next_info.layerName, "XR_APILAYER_PROPRIO_hand_tracking");
    next_info.nextGetInstanceProcAddr = &get_instance_proc_addr;
    next_info.nextCreateApiLayerInstance = &create_api_layer_instance;
    create_info.structType = XR_LOADER_INTERFACE_STRUCT_API_LAYER_CREATE_INFO;
    create_info.structVersion = PROPRIO_XR_API_LAYER_CREATE_INFO_STRUCT_VERSION;
    create_info.structSize = sizeof create_info;
    create_info.nextInfo = &next_info;
    auto info = xr_struct<XrInstanceCreateInfo>(XR_TYPE_INSTANCE_CREATE_INFO);
    std::strcpy(info.applicationInfo.applicationName, "layer dispatch test");
    info.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
    info.enabledExtensionCount = static_cast<uint32_t>(extensions.size());
    info.enabledExtensionNames = extensions.data();
    return request.createApiLayerInstance(&info, &create_info, instance);
  }

  template <typename Fn>
  Fn get(XrInstance instance, const char* name) {
    PFN_xrVoidFunction f = nullptr;
    request.getInstanceProcAddr(instance, name, &f);
    return reinterpret_cast<Fn>(f);
  }
};

inline XrTime xr_now() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<XrTime>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec + kTimeOffsetNs;
}

}  // namespace fake_next
