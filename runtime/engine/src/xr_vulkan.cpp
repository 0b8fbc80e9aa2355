#define XR_USE_GRAPHICS_API_VULKAN
#include <vulkan/vulkan.h>
// clang-format off
#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>
// clang-format on

#include "proprio/engine/xr_vulkan.hpp"

#include <fmt/format.h>

#include "xr_util.hpp"

namespace proprio::engine {

using detail::xr_load;

Status check_xr_vulkan_min_version(XrVersion runtime_min_api_version) {
  const auto major = XR_VERSION_MAJOR(runtime_min_api_version);
  const auto minor = XR_VERSION_MINOR(runtime_min_api_version);
  if (major < kXrVulkanApiMajor || (major == kXrVulkanApiMajor && minor <= kXrVulkanApiMinor)) return {};
  return make_error(Errc::unsupported,
                    fmt::format("the OpenXR runtime needs Vulkan {}.{}.{} or newer (XR_KHR_vulkan_enable2 "
                                "minApiVersionSupported), but Proprio's renderer creates a Vulkan {}.{} instance; "
                                "use a runtime (or runtime version) that accepts Vulkan {}.{}",
                                major, minor, XR_VERSION_PATCH(runtime_min_api_version), kXrVulkanApiMajor,
                                kXrVulkanApiMinor, kXrVulkanApiMajor, kXrVulkanApiMinor));
}

Error xr_call_error(XrInstance instance, const char* what, XrResult result) {
  char name[XR_MAX_RESULT_STRING_SIZE] = "";
  if (instance != XR_NULL_HANDLE && XR_FAILED(xrResultToString(instance, result, name))) name[0] = '\0';
  const Errc code = (result == XR_ERROR_RUNTIME_UNAVAILABLE || result == XR_ERROR_FORM_FACTOR_UNAVAILABLE ||
                     result == XR_ERROR_FORM_FACTOR_UNSUPPORTED || result == XR_ERROR_RUNTIME_FAILURE)
                        ? Errc::unavailable
                        : Errc::io_error;
  return make_error(code,
                    fmt::format("{} failed: {} ({})", what, name[0] ? name : "XrResult", static_cast<int>(result)));
}

Result<render::ContextOptions> xr_vulkan_context_options(XrInstance instance, XrSystemId system,
                                                         render::ContextOptions base) {
  const auto get_requirements =
      xr_load<PFN_xrGetVulkanGraphicsRequirements2KHR>(instance, "xrGetVulkanGraphicsRequirements2KHR");
  const auto create_vk_instance = xr_load<PFN_xrCreateVulkanInstanceKHR>(instance, "xrCreateVulkanInstanceKHR");
  const auto get_vk_device = xr_load<PFN_xrGetVulkanGraphicsDevice2KHR>(instance, "xrGetVulkanGraphicsDevice2KHR");
  const auto create_vk_device = xr_load<PFN_xrCreateVulkanDeviceKHR>(instance, "xrCreateVulkanDeviceKHR");
  if (!get_requirements || !create_vk_instance || !get_vk_device || !create_vk_device) {
    return make_error(Errc::unsupported,
                      "the OpenXR runtime lists XR_KHR_vulkan_enable2 but lacks its functions (or the instance did "
                      "not enable the extension)");
  }
  XrGraphicsRequirementsVulkan2KHR requirements{XR_TYPE_GRAPHICS_REQUIREMENTS_VULKAN2_KHR};
  if (const XrResult r = get_requirements(instance, system, &requirements); XR_FAILED(r)) {
    return xr_call_error(instance, "xrGetVulkanGraphicsRequirements2KHR", r);
  }
  if (auto version = check_xr_vulkan_min_version(requirements.minApiVersionSupported); !version) {
    return version.error();
  }

  // The hooks hold the handles and function pointers by value: the options
  // stay usable after this returns, for as long as the XrInstance lives.
  base.create_instance = [=](const VkInstanceCreateInfo& info) -> Result<VkInstance> {
    XrVulkanInstanceCreateInfoKHR xi{XR_TYPE_VULKAN_INSTANCE_CREATE_INFO_KHR};
    xi.systemId = system;
    xi.pfnGetInstanceProcAddr = &vkGetInstanceProcAddr;
    xi.vulkanCreateInfo = &info;
    VkInstance vk_instance = VK_NULL_HANDLE;
    VkResult vr = VK_SUCCESS;
    if (const XrResult r = create_vk_instance(instance, &xi, &vk_instance, &vr); XR_FAILED(r)) {
      return xr_call_error(instance, "xrCreateVulkanInstanceKHR", r);
    }
    if (vr != VK_SUCCESS) return render::vk_error("vkCreateInstance (through OpenXR)", vr);
    return vk_instance;
  };
  base.pick_physical_device = [=](VkInstance vk_instance) -> Result<VkPhysicalDevice> {
    XrVulkanGraphicsDeviceGetInfoKHR gi{XR_TYPE_VULKAN_GRAPHICS_DEVICE_GET_INFO_KHR};
    gi.systemId = system;
    gi.vulkanInstance = vk_instance;
    VkPhysicalDevice device = VK_NULL_HANDLE;
    if (const XrResult r = get_vk_device(instance, &gi, &device); XR_FAILED(r)) {
      return xr_call_error(instance, "xrGetVulkanGraphicsDevice2KHR", r);
    }
    return device;
  };
  base.create_device = [=](VkPhysicalDevice physical, const VkDeviceCreateInfo& info) -> Result<VkDevice> {
    XrVulkanDeviceCreateInfoKHR di{XR_TYPE_VULKAN_DEVICE_CREATE_INFO_KHR};
    di.systemId = system;
    di.pfnGetInstanceProcAddr = &vkGetInstanceProcAddr;
    di.vulkanPhysicalDevice = physical;
    di.vulkanCreateInfo = &info;
    VkDevice device = VK_NULL_HANDLE;
    VkResult vr = VK_SUCCESS;
    if (const XrResult r = create_vk_device(instance, &di, &device, &vr); XR_FAILED(r)) {
      return xr_call_error(instance, "xrCreateVulkanDeviceKHR", r);
    }
    if (vr != VK_SUCCESS) return render::vk_error("vkCreateDevice (through OpenXR)", vr);
    return device;
  };
  return base;
}

}  // namespace proprio::engine
