// A whole XR_KHR_vulkan_enable2 session on the mock runtime, with no Proprio
// renderer: the test creates its VkInstance and VkDevice through the runtime,
// clears each acquired swapchain image to a known colour with
// vkCmdClearColorImage, submits projection layers, and reads back the PNGs the
// runtime captured (PROPRIO_MOCK_RUNTIME_CAPTURE_DIR). Vulkan's validation
// layer watches both the test's and the runtime's Vulkan calls (the runtime
// calls through the test's instance). Needs lavapipe: label "render".
#include "test_support.hpp"

#include <vulkan/vulkan.h>

#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>

#include <gtest/gtest.h>
#include <stb_image.h>

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace {
using namespace proprio::mock_xr::test;  // NOLINT(google-build-using-namespace): test helpers

#define XR_OK(call) ASSERT_EQ((call), XR_SUCCESS) << #call
#define VK_OK(call) ASSERT_EQ((call), VK_SUCCESS) << #call

struct Rgba {
  int r, g, b, a;
};

// The 8-bit value an sRGB image stores for a linear clear value.
int srgb_byte(float linear) {
  const float s = linear <= 0.0031308f ? 12.92f * linear : 1.055f * std::pow(linear, 1.0f / 2.4f) - 0.055f;
  return static_cast<int>(std::lround(s * 255.0f));
}
Rgba expected(const VkClearColorValue& c) {
  return {srgb_byte(c.float32[0]), srgb_byte(c.float32[1]), srgb_byte(c.float32[2]),
          static_cast<int>(std::lround(c.float32[3] * 255.0f))};
}

// Every pixel of the PNG is `colour` (within 1 per channel); checks its size too.
void expect_png(const std::filesystem::path& path, int width, int height, Rgba colour) {
  SCOPED_TRACE(path.string());
  int w = 0, h = 0, channels = 0;
  unsigned char* pixels = stbi_load(path.c_str(), &w, &h, &channels, 4);
  ASSERT_NE(pixels, nullptr) << "cannot read " << path;
  EXPECT_EQ(w, width);
  EXPECT_EQ(h, height);
  int wrong = 0;
  for (int i = 0; i < w * h; ++i) {
    const unsigned char* p = pixels + 4 * i;
    if (std::abs(p[0] - colour.r) > 1 || std::abs(p[1] - colour.g) > 1 || std::abs(p[2] - colour.b) > 1 ||
        std::abs(p[3] - colour.a) > 1) {
      if (wrong++ == 0) {
        ADD_FAILURE() << "pixel " << i << " is (" << int{p[0]} << ", " << int{p[1]} << ", " << int{p[2]} << ", "
                      << int{p[3]} << "), expected (" << colour.r << ", " << colour.g << ", " << colour.b << ", "
                      << colour.a << ")";
      }
    }
  }
  EXPECT_EQ(wrong, 0);
  stbi_image_free(pixels);
}

VKAPI_ATTR VkBool32 VKAPI_CALL count_messages(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                              VkDebugUtilsMessageTypeFlagsEXT, const VkDebugUtilsMessengerCallbackDataEXT* data,
                                              void* user) {
  if (severity >= VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT) {
    static_cast<std::vector<std::string>*>(user)->push_back(data->pMessage ? data->pMessage : "");
  }
  return VK_FALSE;
}

bool has_vulkan_layer(const char* name) {
  uint32_t count = 0;
  vkEnumerateInstanceLayerProperties(&count, nullptr);
  std::vector<VkLayerProperties> layers(count);
  vkEnumerateInstanceLayerProperties(&count, layers.data());
  return std::any_of(layers.begin(), layers.end(), [&](const auto& l) { return std::strcmp(l.layerName, name) == 0; });
}

class MockRuntimeVulkan : public ::testing::Test {
 protected:
  void SetUp() override {
    std::filesystem::remove_all(capture_dir_);
    std::filesystem::remove(core_validation_report_);
  }
  void TearDown() override {
    if (!HasFailure()) {
      std::filesystem::remove_all(capture_dir_);
      std::filesystem::remove(core_validation_report_);
    }
  }
  // `misuse`: also make the calls that must fail (core_validation flags some of them).
  void run_app(bool misuse);

  const std::filesystem::path capture_dir_ =
      std::filesystem::temp_directory_path() / ("mock_runtime_capture_" + std::to_string(getpid()));
  const std::filesystem::path core_validation_report_ =
      std::filesystem::temp_directory_path() / ("mock_runtime_vk_core_validation_" + std::to_string(getpid()) + ".txt");
  ScopedEnv runtime_{"XR_RUNTIME_JSON", PROPRIO_MOCK_RUNTIME_JSON};
  ScopedEnv layers_{"XR_ENABLE_API_LAYERS", nullptr};
  ScopedEnv capture_{"PROPRIO_MOCK_RUNTIME_CAPTURE_DIR", capture_dir_.c_str()};
  ScopedEnv capture_frames_{"PROPRIO_MOCK_RUNTIME_CAPTURE_FRAMES", nullptr};  // the default: 2
  ScopedEnv exit_after_{"PROPRIO_MOCK_RUNTIME_EXIT_AFTER_FRAMES", "3"};
  ScopedEnv view_size_{"PROPRIO_MOCK_RUNTIME_VIEW_SIZE", "160x90"};

  int frames_ = 0;
  std::vector<std::string> vulkan_messages_;
};

// Frame 0 shows images nobody drew (the runtime's fresh-image magenta); frames
// 1 and 2 clear view v to kColours[v]. View 0 uses R8G8B8A8_SRGB, view 1
// B8G8R8A8_SRGB, so a capture that forgets to swizzle shows the wrong colour.
constexpr std::array<VkClearColorValue, 2> kColours{{{{1.0f, 0.5f, 0.0f, 1.0f}}, {{0.0f, 0.25f, 1.0f, 1.0f}}}};

void MockRuntimeVulkan::run_app(bool misuse) {
  const auto extensions = instance_extensions();
  ASSERT_NE(std::find(extensions.begin(), extensions.end(), XR_KHR_VULKAN_ENABLE2_EXTENSION_NAME), extensions.end());
  XrInstance instance = XR_NULL_HANDLE;
  XR_OK(create_instance({XR_KHR_VULKAN_ENABLE2_EXTENSION_NAME}, &instance));
  const XrSystemId system = get_hmd(instance);

  auto requirements_of =
      get_proc<PFN_xrGetVulkanGraphicsRequirements2KHR>(instance, "xrGetVulkanGraphicsRequirements2KHR");
  auto create_vk_instance = get_proc<PFN_xrCreateVulkanInstanceKHR>(instance, "xrCreateVulkanInstanceKHR");
  auto graphics_device_of = get_proc<PFN_xrGetVulkanGraphicsDevice2KHR>(instance, "xrGetVulkanGraphicsDevice2KHR");
  auto create_vk_device = get_proc<PFN_xrCreateVulkanDeviceKHR>(instance, "xrCreateVulkanDeviceKHR");
  ASSERT_TRUE(requirements_of && create_vk_instance && graphics_device_of && create_vk_device);
  auto requirements = make<XrGraphicsRequirementsVulkan2KHR>(XR_TYPE_GRAPHICS_REQUIREMENTS_VULKAN2_KHR);
  XR_OK(requirements_of(instance, system, &requirements));

  // VkInstance through the runtime, with validation when it is installed.
  const bool validation = has_vulkan_layer("VK_LAYER_KHRONOS_validation");
  if (!validation) std::fprintf(stderr, "VK_LAYER_KHRONOS_validation is not installed: no Vulkan validation\n");
  std::vector<const char*> vk_layers, vk_extensions;
  if (validation) {
    vk_layers.push_back("VK_LAYER_KHRONOS_validation");
    vk_extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
  }
  VkApplicationInfo app{};
  app.sType = VK_STRUCTURE_TYPE_APPLICATION_INFO;
  app.pApplicationName = "mock_runtime_vulkan_tests";
  app.apiVersion = VK_API_VERSION_1_1;
  VkInstanceCreateInfo instance_info{};
  instance_info.sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO;
  instance_info.pApplicationInfo = &app;
  instance_info.enabledLayerCount = static_cast<uint32_t>(vk_layers.size());
  instance_info.ppEnabledLayerNames = vk_layers.data();
  instance_info.enabledExtensionCount = static_cast<uint32_t>(vk_extensions.size());
  instance_info.ppEnabledExtensionNames = vk_extensions.data();
  auto xr_vk_instance_info = make<XrVulkanInstanceCreateInfoKHR>(XR_TYPE_VULKAN_INSTANCE_CREATE_INFO_KHR);
  xr_vk_instance_info.systemId = system;
  xr_vk_instance_info.pfnGetInstanceProcAddr = &vkGetInstanceProcAddr;
  xr_vk_instance_info.vulkanCreateInfo = &instance_info;
  VkInstance vk_instance = VK_NULL_HANDLE;
  VkResult vk_result = VK_ERROR_UNKNOWN;
  XR_OK(create_vk_instance(instance, &xr_vk_instance_info, &vk_instance, &vk_result));
  VK_OK(vk_result);
  VkDebugUtilsMessengerEXT messenger = VK_NULL_HANDLE;
  if (validation) {
    VkDebugUtilsMessengerCreateInfoEXT messenger_info{};
    messenger_info.sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT;
    messenger_info.messageSeverity =
        VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
    messenger_info.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                                 VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT |
                                 VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
    messenger_info.pfnUserCallback = &count_messages;
    messenger_info.pUserData = &vulkan_messages_;
    auto create_messenger = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(vk_instance, "vkCreateDebugUtilsMessengerEXT"));
    ASSERT_NE(create_messenger, nullptr);
    VK_OK(create_messenger(vk_instance, &messenger_info, nullptr, &messenger));
  }

  // The physical device the runtime picks (lavapipe), and a device with one graphics queue.
  auto device_get_info = make<XrVulkanGraphicsDeviceGetInfoKHR>(XR_TYPE_VULKAN_GRAPHICS_DEVICE_GET_INFO_KHR);
  device_get_info.systemId = system;
  device_get_info.vulkanInstance = vk_instance;
  VkPhysicalDevice physical_device = VK_NULL_HANDLE;
  XR_OK(graphics_device_of(instance, &device_get_info, &physical_device));
  VkPhysicalDeviceProperties device_properties{};
  vkGetPhysicalDeviceProperties(physical_device, &device_properties);
  EXPECT_EQ(device_properties.deviceType, VK_PHYSICAL_DEVICE_TYPE_CPU) << device_properties.deviceName;
  uint32_t family_count = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(physical_device, &family_count, nullptr);
  std::vector<VkQueueFamilyProperties> families(family_count);
  vkGetPhysicalDeviceQueueFamilyProperties(physical_device, &family_count, families.data());
  uint32_t family = 0;
  while (family < family_count && (families[family].queueFlags & VK_QUEUE_GRAPHICS_BIT) == 0) ++family;
  ASSERT_LT(family, family_count);
  const float priority = 1.0f;
  VkDeviceQueueCreateInfo queue_info{};
  queue_info.sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO;
  queue_info.queueFamilyIndex = family;
  queue_info.queueCount = 1;
  queue_info.pQueuePriorities = &priority;
  VkDeviceCreateInfo device_info{};
  device_info.sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO;
  device_info.queueCreateInfoCount = 1;
  device_info.pQueueCreateInfos = &queue_info;
  auto xr_vk_device_info = make<XrVulkanDeviceCreateInfoKHR>(XR_TYPE_VULKAN_DEVICE_CREATE_INFO_KHR);
  xr_vk_device_info.systemId = system;
  xr_vk_device_info.pfnGetInstanceProcAddr = &vkGetInstanceProcAddr;
  xr_vk_device_info.vulkanPhysicalDevice = physical_device;
  xr_vk_device_info.vulkanCreateInfo = &device_info;
  VkDevice device = VK_NULL_HANDLE;
  XR_OK(create_vk_device(instance, &xr_vk_device_info, &device, &vk_result));
  VK_OK(vk_result);
  VkQueue queue = VK_NULL_HANDLE;
  vkGetDeviceQueue(device, family, 0, &queue);

  // The session.
  auto binding = make<XrGraphicsBindingVulkan2KHR>(XR_TYPE_GRAPHICS_BINDING_VULKAN2_KHR);
  binding.instance = vk_instance;
  binding.physicalDevice = physical_device;
  binding.device = device;
  binding.queueFamilyIndex = family;
  binding.queueIndex = 0;
  auto session_info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  session_info.next = &binding;
  session_info.systemId = system;
  XrSession session = XR_NULL_HANDLE;
  if (misuse) {
    binding.queueIndex = 1;  // the device has no second queue
    EXPECT_EQ(xrCreateSession(instance, &session_info, &session), XR_ERROR_GRAPHICS_DEVICE_INVALID);
    binding.queueIndex = 0;
  }
  XR_OK(xrCreateSession(instance, &session_info, &session));
  const XrSpace local = create_space(session, XR_REFERENCE_SPACE_TYPE_LOCAL);

  // One swapchain per view, of the recommended size.
  uint32_t count = 0;
  std::vector views(2, make<XrViewConfigurationView>(XR_TYPE_VIEW_CONFIGURATION_VIEW));
  XR_OK(xrEnumerateViewConfigurationViews(instance, system, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO, 2, &count,
                                          views.data()));
  ASSERT_EQ(views[0].recommendedImageRectWidth, 160u);
  ASSERT_EQ(views[0].recommendedImageRectHeight, 90u);
  const auto width = static_cast<int32_t>(views[0].recommendedImageRectWidth);
  const auto height = static_cast<int32_t>(views[0].recommendedImageRectHeight);
  int64_t formats[4]{};
  XR_OK(xrEnumerateSwapchainFormats(session, 4, &count, formats));
  ASSERT_EQ(count, 2u);
  EXPECT_EQ(formats[0], VK_FORMAT_R8G8B8A8_SRGB);
  EXPECT_EQ(formats[1], VK_FORMAT_B8G8R8A8_SRGB);
  std::array<XrSwapchain, 2> swapchains{};
  std::array<std::vector<VkImage>, 2> images;
  for (uint32_t v = 0; v < 2; ++v) {
    auto info = make<XrSwapchainCreateInfo>(XR_TYPE_SWAPCHAIN_CREATE_INFO);
    info.usageFlags = XR_SWAPCHAIN_USAGE_COLOR_ATTACHMENT_BIT | XR_SWAPCHAIN_USAGE_TRANSFER_DST_BIT |
                      XR_SWAPCHAIN_USAGE_SAMPLED_BIT;
    info.format = formats[v];
    info.sampleCount = info.faceCount = info.arraySize = info.mipCount = 1;
    info.width = static_cast<uint32_t>(width);
    info.height = static_cast<uint32_t>(height);
    XR_OK(xrCreateSwapchain(session, &info, &swapchains[v]));
    XR_OK(xrEnumerateSwapchainImages(swapchains[v], 0, &count, nullptr));
    ASSERT_EQ(count, 3u);
    std::vector xr_images(count, make<XrSwapchainImageVulkan2KHR>(XR_TYPE_SWAPCHAIN_IMAGE_VULKAN2_KHR));
    XR_OK(xrEnumerateSwapchainImages(swapchains[v], count, &count,
                                     reinterpret_cast<XrSwapchainImageBaseHeader*>(xr_images.data())));
    for (const auto& image : xr_images) images[v].push_back(image.image);
  }

  // The test's own command buffer and fence.
  VkCommandPoolCreateInfo pool_info{};
  pool_info.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
  pool_info.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pool_info.queueFamilyIndex = family;
  VkCommandPool pool = VK_NULL_HANDLE;
  VK_OK(vkCreateCommandPool(device, &pool_info, nullptr, &pool));
  VkCommandBufferAllocateInfo allocate{};
  allocate.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
  allocate.commandPool = pool;
  allocate.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  allocate.commandBufferCount = 1;
  VkCommandBuffer commands = VK_NULL_HANDLE;
  VK_OK(vkAllocateCommandBuffers(device, &allocate, &commands));
  VkFenceCreateInfo fence_info{};
  fence_info.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
  VkFence fence = VK_NULL_HANDLE;
  VK_OK(vkCreateFence(device, &fence_info, nullptr, &fence));

  // Images arrive, and must be released, in COLOR_ATTACHMENT_OPTIMAL.
  auto clear = [&](VkImage image, const VkClearColorValue& colour) {
    VK_OK(vkResetFences(device, 1, &fence));
    VK_OK(vkResetCommandBuffer(commands, 0));
    VkCommandBufferBeginInfo begin{};
    begin.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    VK_OK(vkBeginCommandBuffer(commands, &begin));
    const VkImageSubresourceRange range{VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
    VkImageMemoryBarrier barrier{};
    barrier.sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER;
    barrier.srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
    barrier.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    barrier.oldLayout = VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL;
    barrier.newLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    barrier.srcQueueFamilyIndex = barrier.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.image = image;
    barrier.subresourceRange = range;
    vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0,
                         0, nullptr, 0, nullptr, 1, &barrier);
    vkCmdClearColorImage(commands, image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, &colour, 1, &range);
    barrier.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    barrier.dstAccessMask = VK_ACCESS_COLOR_ATTACHMENT_READ_BIT | VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
    barrier.oldLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    barrier.newLayout = VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL;
    vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT, 0,
                         0, nullptr, 0, nullptr, 1, &barrier);
    VK_OK(vkEndCommandBuffer(commands));
    VkSubmitInfo submit{};
    submit.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    submit.commandBufferCount = 1;
    submit.pCommandBuffers = &commands;
    VK_OK(vkQueueSubmit(queue, 1, &submit, fence));
    VK_OK(vkWaitForFences(device, 1, &fence, VK_TRUE, UINT64_MAX));
  };

  // Swapchain call order: one image at a time, wait before release.
  uint32_t index = 0;
  auto wait_info = make<XrSwapchainImageWaitInfo>(XR_TYPE_SWAPCHAIN_IMAGE_WAIT_INFO);
  wait_info.timeout = XR_INFINITE_DURATION;
  if (misuse) {
    EXPECT_EQ(xrReleaseSwapchainImage(swapchains[0], nullptr), XR_ERROR_CALL_ORDER_INVALID);
  }
  XR_OK(xrAcquireSwapchainImage(swapchains[0], nullptr, &index));
  EXPECT_EQ(index, 0u);
  if (misuse) {
    EXPECT_EQ(xrAcquireSwapchainImage(swapchains[0], nullptr, &index), XR_ERROR_CALL_ORDER_INVALID);
    EXPECT_EQ(xrReleaseSwapchainImage(swapchains[0], nullptr), XR_ERROR_CALL_ORDER_INVALID);  // not waited
  }
  XR_OK(xrWaitSwapchainImage(swapchains[0], &wait_info));
  XR_OK(xrReleaseSwapchainImage(swapchains[0], nullptr));

  auto begin_info = make<XrSessionBeginInfo>(XR_TYPE_SESSION_BEGIN_INFO);
  begin_info.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  bool exiting = false;
  for (int loop = 0; loop < 100 && !exiting; ++loop) {
    bool running = true;
    for (XrSessionState state : drain_states(instance)) {
      if (state == XR_SESSION_STATE_READY) {
        XR_OK(xrBeginSession(session, &begin_info));
      }
      if (state == XR_SESSION_STATE_STOPPING) {
        XR_OK(xrEndSession(session));
        running = false;
      }
      if (state == XR_SESSION_STATE_EXITING) exiting = true;
    }
    if (!running || exiting) continue;

    auto frame_state = make<XrFrameState>(XR_TYPE_FRAME_STATE);
    XR_OK(xrWaitFrame(session, nullptr, &frame_state));
    XR_OK(xrBeginFrame(session, nullptr));
    ASSERT_TRUE(frame_state.shouldRender);
    auto locate_info = make<XrViewLocateInfo>(XR_TYPE_VIEW_LOCATE_INFO);
    locate_info.viewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
    locate_info.displayTime = frame_state.predictedDisplayTime;
    locate_info.space = local;
    auto view_state = make<XrViewState>(XR_TYPE_VIEW_STATE);
    std::vector located(2, make<XrView>(XR_TYPE_VIEW));
    XR_OK(xrLocateViews(session, &locate_info, &view_state, 2, &count, located.data()));

    std::array<XrCompositionLayerProjectionView, 2> layer_views{};
    for (uint32_t v = 0; v < 2; ++v) {
      if (frames_ == 0 && v == 0) {
        // Already released above, untouched: the fresh image shows.
      } else {
        XR_OK(xrAcquireSwapchainImage(swapchains[v], nullptr, &index));
        XR_OK(xrWaitSwapchainImage(swapchains[v], &wait_info));
        if (frames_ > 0) clear(images[v][index], kColours[v]);
        XR_OK(xrReleaseSwapchainImage(swapchains[v], nullptr));
      }
      layer_views[v] = make<XrCompositionLayerProjectionView>(XR_TYPE_COMPOSITION_LAYER_PROJECTION_VIEW);
      layer_views[v].pose = located[v].pose;
      layer_views[v].fov = located[v].fov;
      layer_views[v].subImage.swapchain = swapchains[v];
      layer_views[v].subImage.imageRect = {{0, 0}, {width, height}};
    }
    auto layer = make<XrCompositionLayerProjection>(XR_TYPE_COMPOSITION_LAYER_PROJECTION);
    layer.space = local;
    layer.viewCount = 2;
    layer.views = layer_views.data();
    const XrCompositionLayerBaseHeader* layers[] = {reinterpret_cast<const XrCompositionLayerBaseHeader*>(&layer)};
    auto end_info = make<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
    end_info.displayTime = frame_state.predictedDisplayTime;
    end_info.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
    end_info.layerCount = 1;
    end_info.layers = layers;
    if (misuse && frames_ == 1) {
      // A rectangle outside the image is refused, and the frame stays open.
      layer_views[1].subImage.imageRect = {{1, 0}, {width, height}};
      EXPECT_EQ(xrEndFrame(session, &end_info), XR_ERROR_SWAPCHAIN_RECT_INVALID);
      layer_views[1].subImage.imageRect = {{0, 0}, {width, height}};
    }
    XR_OK(xrEndFrame(session, &end_info));
    ++frames_;
  }
  EXPECT_TRUE(exiting);
  EXPECT_EQ(frames_, 3);  // PROPRIO_MOCK_RUNTIME_EXIT_AFTER_FRAMES

  vkDestroyFence(device, fence, nullptr);
  vkDestroyCommandPool(device, pool, nullptr);
  for (XrSwapchain swapchain : swapchains) EXPECT_EQ(xrDestroySwapchain(swapchain), XR_SUCCESS);
  if (misuse) {
    EXPECT_EQ(xrDestroySwapchain(swapchains[0]), XR_ERROR_HANDLE_INVALID);
  }
  EXPECT_EQ(xrDestroySpace(local), XR_SUCCESS);
  EXPECT_EQ(xrDestroySession(session), XR_SUCCESS);
  // The app's own Vulkan objects go after the session, then the instance.
  vkDestroyDevice(device, nullptr);
  if (messenger != VK_NULL_HANDLE) {
    auto destroy_messenger = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(vk_instance, "vkDestroyDebugUtilsMessengerEXT"));
    destroy_messenger(vk_instance, messenger, nullptr);
  }
  vkDestroyInstance(vk_instance, nullptr);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);

  for (const std::string& message : vulkan_messages_) ADD_FAILURE() << "Vulkan: " << message;

  // Frames 0 and 1 were captured (PROPRIO_MOCK_RUNTIME_CAPTURE_FRAMES defaults to 2), frame 2 not.
  expect_png(capture_dir_ / "frame_0000_view_0.png", width, height, Rgba{255, 0, 255, 255});
  expect_png(capture_dir_ / "frame_0000_view_1.png", width, height, Rgba{255, 0, 255, 255});
  expect_png(capture_dir_ / "frame_0001_view_0.png", width, height, expected(kColours[0]));
  expect_png(capture_dir_ / "frame_0001_view_1.png", width, height, expected(kColours[1]));
  EXPECT_FALSE(std::filesystem::exists(capture_dir_ / "frame_0002_view_0.png"));
}

TEST_F(MockRuntimeVulkan, ClearedImagesAreCaptured) { run_app(/*misuse=*/true); }

// The same app under Debian's core_validation layer raises no validation error.
TEST_F(MockRuntimeVulkan, RaisesNoCoreValidationError) {
  bool found = false;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(PROPRIO_XR_EXPLICIT_LAYER_DIR, ec)) {
    found |= entry.path().filename().string().starts_with("XrApiLayer_core_validation");
  }
  if (!found) GTEST_SKIP() << "openxr-layer-corevalidation is not installed in " PROPRIO_XR_EXPLICIT_LAYER_DIR;
  ScopedEnv layer_path("XR_API_LAYER_PATH", PROPRIO_XR_EXPLICIT_LAYER_DIR);
  ScopedEnv enable("XR_ENABLE_API_LAYERS", "XR_APILAYER_LUNARG_core_validation");
  ScopedEnv export_type("XR_CORE_VALIDATION_EXPORT_TYPE", "text");
  ScopedEnv file("XR_CORE_VALIDATION_FILE_NAME", core_validation_report_.c_str());
  run_app(/*misuse=*/false);
  std::ifstream in(core_validation_report_);
  const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  EXPECT_EQ(text.find("VALID_ERROR"), std::string::npos) << text;
}

}  // namespace
