#pragma once
// Helpers shared by the mock runtime's own tests (smoke_test.cpp and
// vulkan_session_test.cpp). Test code only: each test binary links the real
// OpenXR loader and reaches the runtime through XR_RUNTIME_JSON.
#include <openxr/openxr.h>

#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

namespace proprio::mock_xr::test {

// Sets (or unsets, with nullptr) an environment variable for one scope.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    if (value != nullptr) {
      setenv(name, value, 1);
    } else {
      unsetenv(name);
    }
  }
  ~ScopedEnv() {
    if (old_) {
      setenv(name_.c_str(), old_->c_str(), 1);
    } else {
      unsetenv(name_.c_str());
    }
  }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;

 private:
  std::string name_;
  std::optional<std::string> old_;
};

// A zeroed OpenXR structure of the given type (GCC's -Wextra flags `T{type}`).
template <class T>
T make(XrStructureType type) {
  T value{};
  value.type = type;
  return value;
}

template <class Handle>
Handle to_handle(uint64_t id) {
  return reinterpret_cast<Handle>(static_cast<std::uintptr_t>(id));
}

inline XrResult create_instance(std::vector<const char*> extensions, XrInstance* instance) {
  auto info = make<XrInstanceCreateInfo>(XR_TYPE_INSTANCE_CREATE_INFO);
  std::snprintf(info.applicationInfo.applicationName, XR_MAX_APPLICATION_NAME_SIZE, "mock_runtime_tests");
  info.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
  info.enabledExtensionCount = static_cast<uint32_t>(extensions.size());
  info.enabledExtensionNames = extensions.data();
  return xrCreateInstance(&info, instance);
}

inline std::vector<std::string> instance_extensions() {
  uint32_t count = 0;
  EXPECT_EQ(xrEnumerateInstanceExtensionProperties(nullptr, 0, &count, nullptr), XR_SUCCESS);
  std::vector props(count, make<XrExtensionProperties>(XR_TYPE_EXTENSION_PROPERTIES));
  EXPECT_EQ(xrEnumerateInstanceExtensionProperties(nullptr, count, &count, props.data()), XR_SUCCESS);
  std::vector<std::string> names;
  for (const auto& p : props) names.emplace_back(p.extensionName);
  return names;
}

template <class Pfn>
Pfn get_proc(XrInstance instance, const char* name) {
  PFN_xrVoidFunction f = nullptr;
  EXPECT_EQ(xrGetInstanceProcAddr(instance, name, &f), XR_SUCCESS) << name;
  return reinterpret_cast<Pfn>(f);
}

inline std::vector<XrSessionState> drain_states(XrInstance instance) {
  std::vector<XrSessionState> states;
  auto event = make<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
  while (xrPollEvent(instance, &event) == XR_SUCCESS) {
    if (event.type == XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED) {
      states.push_back(reinterpret_cast<const XrEventDataSessionStateChanged&>(event).state);
    }
    event = make<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
  }
  return states;
}

inline XrSystemId get_hmd(XrInstance instance) {
  auto info = make<XrSystemGetInfo>(XR_TYPE_SYSTEM_GET_INFO);
  info.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  EXPECT_EQ(xrGetSystem(instance, &info, &system), XR_SUCCESS);
  return system;
}

inline XrSpace create_space(XrSession session, XrReferenceSpaceType type,
                            XrPosef offset = {{0.0f, 0.0f, 0.0f, 1.0f}, {0.0f, 0.0f, 0.0f}}) {
  auto info = make<XrReferenceSpaceCreateInfo>(XR_TYPE_REFERENCE_SPACE_CREATE_INFO);
  info.referenceSpaceType = type;
  info.poseInReferenceSpace = offset;
  XrSpace space = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateReferenceSpace(session, &info, &space), XR_SUCCESS);
  return space;
}

}  // namespace proprio::mock_xr::test
