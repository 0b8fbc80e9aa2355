#pragma once
// The Vulkan context every render target shares: instance, one physical
// device, one graphics queue, and small RAII wrappers for the buffers and
// images built on it. Errors come back as Result, never as exceptions.
//
// Device choice: a discrete GPU when there is one, then an integrated one,
// then Mesa's lavapipe (a CPU rasteriser: what CI and headless machines
// have). `software` forces lavapipe, so golden images are comparable.
//
// OpenXR's XR_KHR_vulkan_enable2 wants to create the instance and the device
// itself (it adds what the runtime needs): set the three hooks and the
// context calls them instead of vkCreateInstance / vkCreateDevice.
#include <vulkan/vulkan.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"

namespace proprio::render {

enum class DevicePreference {
  automatic,  // discrete > integrated > virtual > CPU (lavapipe)
  software,   // a CPU device (lavapipe) or an error
};

struct ContextOptions {
  std::string app_name = "proprio";
  DevicePreference device = DevicePreference::automatic;
  // Khronos validation layer: on in debug builds and tests when installed
  // (Debian: vulkan-validationlayers). Every message of severity error is
  // counted; tests require zero.
  bool validation = false;
  std::vector<std::string> instance_extensions;  // e.g. GLFW's surface extensions
  bool swapchain = false;                        // VK_KHR_swapchain (window targets)

  std::function<Result<VkInstance>(const VkInstanceCreateInfo&)> create_instance;
  std::function<Result<VkPhysicalDevice>(VkInstance)> pick_physical_device;
  std::function<Result<VkDevice>(VkPhysicalDevice, const VkDeviceCreateInfo&)> create_device;

  std::string describe() const;
};

// A buffer with its own memory. Move-only; frees itself.
struct Buffer {
  VkDevice device = VK_NULL_HANDLE;
  VkBuffer buffer = VK_NULL_HANDLE;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  VkDeviceSize size = 0;
  void* mapped = nullptr;  // host-visible buffers stay mapped

  Buffer() = default;
  Buffer(Buffer&& other) noexcept { *this = std::move(other); }
  Buffer& operator=(Buffer&& other) noexcept;
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;
  ~Buffer() { reset(); }
  void reset() noexcept;
};

// A 2D image, its memory and one view. Move-only; frees itself.
struct Image {
  VkDevice device = VK_NULL_HANDLE;
  VkImage image = VK_NULL_HANDLE;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  VkImageView view = VK_NULL_HANDLE;
  VkFormat format = VK_FORMAT_UNDEFINED;
  VkExtent2D extent{};

  Image() = default;
  Image(Image&& other) noexcept { *this = std::move(other); }
  Image& operator=(Image&& other) noexcept;
  Image(const Image&) = delete;
  Image& operator=(const Image&) = delete;
  ~Image() { reset(); }
  void reset() noexcept;
};

class VulkanContext {
 public:
  static Result<std::unique_ptr<VulkanContext>> create(const ContextOptions& options = {});
  ~VulkanContext();
  VulkanContext(const VulkanContext&) = delete;
  VulkanContext& operator=(const VulkanContext&) = delete;

  VkInstance instance() const noexcept { return instance_; }
  VkPhysicalDevice physical_device() const noexcept { return physical_device_; }
  VkDevice device() const noexcept { return device_; }
  VkQueue queue() const noexcept { return queue_; }
  std::uint32_t queue_family() const noexcept { return queue_family_; }
  const VkPhysicalDeviceProperties& properties() const noexcept { return properties_; }
  std::string device_name() const { return properties_.deviceName; }
  bool is_software() const noexcept { return properties_.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU; }
  bool validation_enabled() const noexcept { return validation_enabled_; }
  // Validation messages of severity error since creation (0 without validation).
  std::uint32_t validation_errors() const noexcept { return validation_errors_.load(); }
  // The first few error messages, for test failure output.
  std::vector<std::string> validation_messages() const;
  // The best supported depth format.
  VkFormat depth_format() const noexcept { return depth_format_; }
  std::string describe() const;

  Result<Buffer> create_buffer(VkDeviceSize size, VkBufferUsageFlags usage, bool host_visible) const;
  Result<Image> create_image(VkExtent2D extent, VkFormat format, VkImageUsageFlags usage,
                             VkImageAspectFlags aspect) const;
  Result<VkImageView> create_view(VkImage image, VkFormat format, VkImageAspectFlags aspect) const;
  // Records with `record` into a one-off command buffer, submits and waits.
  // For uploads and read-backs, not the frame loop.
  Status run_once(const std::function<void(VkCommandBuffer)>& record) const;
  // Uploads bytes into a new device-local buffer through a staging buffer.
  Result<Buffer> upload_buffer(const void* data, VkDeviceSize size, VkBufferUsageFlags usage) const;

  // Called by the debug messenger.
  void on_validation_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity, const char* message);

 private:
  VulkanContext() = default;
  Result<std::uint32_t> memory_type(std::uint32_t type_bits, VkMemoryPropertyFlags flags) const;

  VkInstance instance_ = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
  VkPhysicalDevice physical_device_ = VK_NULL_HANDLE;
  VkDevice device_ = VK_NULL_HANDLE;
  VkQueue queue_ = VK_NULL_HANDLE;
  std::uint32_t queue_family_ = 0;
  VkCommandPool command_pool_ = VK_NULL_HANDLE;
  VkPhysicalDeviceProperties properties_{};
  VkPhysicalDeviceMemoryProperties memory_{};
  VkFormat depth_format_ = VK_FORMAT_UNDEFINED;
  bool validation_enabled_ = false;
  std::atomic<std::uint32_t> validation_errors_{0};
  mutable std::mutex messages_mutex_;
  std::vector<std::string> messages_;
};

// "VK_ERROR_OUT_OF_DEVICE_MEMORY" etc.
const char* to_string(VkResult result) noexcept;
// An Error naming the call and the VkResult.
Error vk_error(const char* what, VkResult result);

}  // namespace proprio::render
