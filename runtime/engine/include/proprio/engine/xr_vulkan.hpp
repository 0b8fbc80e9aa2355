#pragma once
// Vulkan through OpenXR (XR_KHR_vulkan_enable2), shared by the engine's XR
// session and `proprio xr-probe`: the runtime creates the Vulkan instance and
// device itself (adding the extensions it needs), so the renderer's context
// calls the runtime through its three creation hooks.
#include <openxr/openxr.h>

#include "proprio/core/result.hpp"
#include "proprio/render/context.hpp"

namespace proprio::engine {

// The Vulkan version render::VulkanContext requests (VK_API_VERSION_1_2 in
// render/src/context.cpp): a runtime whose minimum is newer cannot work with it.
inline constexpr std::uint32_t kXrVulkanApiMajor = 1;
inline constexpr std::uint32_t kXrVulkanApiMinor = 2;

// Success when the runtime's minimum Vulkan version
// (XrGraphicsRequirementsVulkan2KHR::minApiVersionSupported) is no newer than
// the 1.2 the renderer requests. Only major.minor count: a patch level does
// not change the API, so a runtime asking for 1.2.5 is served by a 1.2 instance.
Status check_xr_vulkan_min_version(XrVersion runtime_min_api_version);

// An Error naming the OpenXR call and its result, by the instance's name for
// it when there is an instance. Runtime-side absences (no runtime, no system,
// runtime failure) are Errc::unavailable, everything else Errc::io_error.
Error xr_call_error(XrInstance instance, const char* what, XrResult result);

// `base` with create_instance, pick_physical_device and create_device set to
// XR_KHR_vulkan_enable2's calls for `system`, after asking the runtime for its
// graphics requirements (which the spec requires before xrCreateSession) and
// checking them with check_xr_vulkan_min_version. `instance` must have enabled
// XR_KHR_vulkan_enable2 and must outlive every context made from the result.
Result<render::ContextOptions> xr_vulkan_context_options(XrInstance instance, XrSystemId system,
                                                         render::ContextOptions base = {});

}  // namespace proprio::engine
