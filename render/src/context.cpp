#include "proprio/render/context.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cstring>
#include <optional>

#include "proprio/core/log.hpp"

namespace proprio::render {
namespace {

constexpr const char* kValidationLayer = "VK_LAYER_KHRONOS_validation";
constexpr std::size_t kKeptMessages = 16;

VKAPI_ATTR VkBool32 VKAPI_CALL debug_callback(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                              VkDebugUtilsMessageTypeFlagsEXT /*types*/,
                                              const VkDebugUtilsMessengerCallbackDataEXT* data, void* user) {
  static_cast<VulkanContext*>(user)->on_validation_message(severity, data->pMessage ? data->pMessage : "");
  return VK_FALSE;
}

bool has_layer(const char* name) {
  std::uint32_t count = 0;
  vkEnumerateInstanceLayerProperties(&count, nullptr);
  std::vector<VkLayerProperties> layers(count);
  vkEnumerateInstanceLayerProperties(&count, layers.data());
  return std::any_of(layers.begin(), layers.end(), [&](const auto& l) { return std::strcmp(l.layerName, name) == 0; });
}

bool has_instance_extension(const char* name) {
  std::uint32_t count = 0;
  vkEnumerateInstanceExtensionProperties(nullptr, &count, nullptr);
  std::vector<VkExtensionProperties> exts(count);
  vkEnumerateInstanceExtensionProperties(nullptr, &count, exts.data());
  return std::any_of(exts.begin(), exts.end(),
                     [&](const auto& e) { return std::strcmp(e.extensionName, name) == 0; });
}

int device_rank(VkPhysicalDeviceType type, DevicePreference preference) {
  if (preference == DevicePreference::software) return type == VK_PHYSICAL_DEVICE_TYPE_CPU ? 0 : -1;
  switch (type) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return 4;
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return 3;
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return 2;
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return 1;
    default: return 0;
  }
}

std::optional<std::uint32_t> graphics_family(VkPhysicalDevice device) {
  std::uint32_t count = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(device, &count, nullptr);
  std::vector<VkQueueFamilyProperties> families(count);
  vkGetPhysicalDeviceQueueFamilyProperties(device, &count, families.data());
  for (std::uint32_t i = 0; i < count; ++i) {
    if (families[i].queueFlags & VK_QUEUE_GRAPHICS_BIT) return i;
  }
  return std::nullopt;
}

}  // namespace

const char* to_string(VkResult result) noexcept {
  switch (result) {
#define PROPRIO_VK_CASE(x) case x: return #x;
    PROPRIO_VK_CASE(VK_SUCCESS)
    PROPRIO_VK_CASE(VK_NOT_READY)
    PROPRIO_VK_CASE(VK_TIMEOUT)
    PROPRIO_VK_CASE(VK_INCOMPLETE)
    PROPRIO_VK_CASE(VK_SUBOPTIMAL_KHR)
    PROPRIO_VK_CASE(VK_ERROR_OUT_OF_HOST_MEMORY)
    PROPRIO_VK_CASE(VK_ERROR_OUT_OF_DEVICE_MEMORY)
    PROPRIO_VK_CASE(VK_ERROR_INITIALIZATION_FAILED)
    PROPRIO_VK_CASE(VK_ERROR_DEVICE_LOST)
    PROPRIO_VK_CASE(VK_ERROR_MEMORY_MAP_FAILED)
    PROPRIO_VK_CASE(VK_ERROR_LAYER_NOT_PRESENT)
    PROPRIO_VK_CASE(VK_ERROR_EXTENSION_NOT_PRESENT)
    PROPRIO_VK_CASE(VK_ERROR_FEATURE_NOT_PRESENT)
    PROPRIO_VK_CASE(VK_ERROR_INCOMPATIBLE_DRIVER)
    PROPRIO_VK_CASE(VK_ERROR_FORMAT_NOT_SUPPORTED)
    PROPRIO_VK_CASE(VK_ERROR_SURFACE_LOST_KHR)
    PROPRIO_VK_CASE(VK_ERROR_OUT_OF_DATE_KHR)
#undef PROPRIO_VK_CASE
    default: return "VkResult(other)";
  }
}

Error vk_error(const char* what, VkResult result) {
  const Errc code = result == VK_ERROR_INCOMPATIBLE_DRIVER || result == VK_ERROR_EXTENSION_NOT_PRESENT ||
                            result == VK_ERROR_FEATURE_NOT_PRESENT || result == VK_ERROR_LAYER_NOT_PRESENT
                        ? Errc::unsupported
                        : Errc::io_error;
  return make_error(code, fmt::format("{} failed: {}", what, to_string(result)));
}

std::string ContextOptions::describe() const {
  return fmt::format("vulkan context: app '{}', device {}, validation {}, {} extra instance extension(s), swapchain {}{}",
                     app_name, device == DevicePreference::software ? "software (lavapipe)" : "automatic",
                     validation ? "on" : "off", instance_extensions.size(), swapchain ? "yes" : "no",
                     create_instance ? ", instance/device created through OpenXR" : "");
}

Buffer& Buffer::operator=(Buffer&& other) noexcept {
  if (this != &other) {
    reset();
    device = std::exchange(other.device, VK_NULL_HANDLE);
    buffer = std::exchange(other.buffer, VK_NULL_HANDLE);
    memory = std::exchange(other.memory, VK_NULL_HANDLE);
    size = std::exchange(other.size, 0);
    mapped = std::exchange(other.mapped, nullptr);
  }
  return *this;
}

void Buffer::reset() noexcept {
  if (device == VK_NULL_HANDLE) return;
  if (mapped) vkUnmapMemory(device, memory);
  vkDestroyBuffer(device, buffer, nullptr);
  vkFreeMemory(device, memory, nullptr);
  device = VK_NULL_HANDLE;
  buffer = VK_NULL_HANDLE;
  memory = VK_NULL_HANDLE;
  mapped = nullptr;
  size = 0;
}

Image& Image::operator=(Image&& other) noexcept {
  if (this != &other) {
    reset();
    device = std::exchange(other.device, VK_NULL_HANDLE);
    image = std::exchange(other.image, VK_NULL_HANDLE);
    memory = std::exchange(other.memory, VK_NULL_HANDLE);
    view = std::exchange(other.view, VK_NULL_HANDLE);
    format = other.format;
    extent = other.extent;
  }
  return *this;
}

void Image::reset() noexcept {
  if (device == VK_NULL_HANDLE) return;
  vkDestroyImageView(device, view, nullptr);
  vkDestroyImage(device, image, nullptr);
  vkFreeMemory(device, memory, nullptr);
  device = VK_NULL_HANDLE;
  image = VK_NULL_HANDLE;
  memory = VK_NULL_HANDLE;
  view = VK_NULL_HANDLE;
}

Result<std::unique_ptr<VulkanContext>> VulkanContext::create(const ContextOptions& options) {
  std::unique_ptr<VulkanContext> ctx(new VulkanContext());

  std::vector<const char*> layers;
  std::vector<const char*> extensions;
  for (const auto& e : options.instance_extensions) extensions.push_back(e.c_str());
  if (options.validation) {
    if (has_layer(kValidationLayer) && has_instance_extension(VK_EXT_DEBUG_UTILS_EXTENSION_NAME)) {
      layers.push_back(kValidationLayer);
      extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
      ctx->validation_enabled_ = true;
    } else {
      logger().warn("Vulkan validation requested, but {} is not installed (Debian: vulkan-validationlayers); running without",
               kValidationLayer);
    }
  }

  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.pApplicationName = options.app_name.c_str();
  app.pEngineName = "proprio";
  app.apiVersion = VK_API_VERSION_1_2;
  VkInstanceCreateInfo instance_info{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  instance_info.pApplicationInfo = &app;
  instance_info.enabledLayerCount = static_cast<std::uint32_t>(layers.size());
  instance_info.ppEnabledLayerNames = layers.data();
  instance_info.enabledExtensionCount = static_cast<std::uint32_t>(extensions.size());
  instance_info.ppEnabledExtensionNames = extensions.data();
  if (options.create_instance) {
    auto instance = options.create_instance(instance_info);
    if (!instance) return instance.error().with_context("creating the Vulkan instance through OpenXR");
    ctx->instance_ = *instance;
  } else if (VkResult r = vkCreateInstance(&instance_info, nullptr, &ctx->instance_); r != VK_SUCCESS) {
    Error e = vk_error("vkCreateInstance", r);
    e.message += " (is a Vulkan driver installed? Debian: mesa-vulkan-drivers provides lavapipe)";
    return e;
  }

  if (ctx->validation_enabled_) {
    VkDebugUtilsMessengerCreateInfoEXT info{VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
    info.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
    info.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                       VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
    info.pfnUserCallback = debug_callback;
    info.pUserData = ctx.get();
    auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(ctx->instance_, "vkCreateDebugUtilsMessengerEXT"));
    if (create) create(ctx->instance_, &info, nullptr, &ctx->messenger_);
  }

  if (options.pick_physical_device) {
    auto device = options.pick_physical_device(ctx->instance_);
    if (!device) return device.error().with_context("choosing the Vulkan device through OpenXR");
    ctx->physical_device_ = *device;
  } else {
    std::uint32_t count = 0;
    vkEnumeratePhysicalDevices(ctx->instance_, &count, nullptr);
    std::vector<VkPhysicalDevice> devices(count);
    vkEnumeratePhysicalDevices(ctx->instance_, &count, devices.data());
    int best_rank = -1;
    std::string seen;
    for (VkPhysicalDevice d : devices) {
      VkPhysicalDeviceProperties p;
      vkGetPhysicalDeviceProperties(d, &p);
      seen += fmt::format("{}'{}'", seen.empty() ? "" : ", ", p.deviceName);
      if (p.apiVersion < VK_API_VERSION_1_2 || !graphics_family(d)) continue;
      const int rank = device_rank(p.deviceType, options.device);
      if (rank > best_rank) {
        best_rank = rank;
        ctx->physical_device_ = d;
      }
    }
    if (ctx->physical_device_ == VK_NULL_HANDLE) {
      return make_error(Errc::unsupported,
                        fmt::format("no {}Vulkan 1.2 device with a graphics queue (devices: {}); install "
                                    "mesa-vulkan-drivers for lavapipe",
                                    options.device == DevicePreference::software ? "software (CPU) " : "",
                                    seen.empty() ? "none" : seen));
    }
  }
  vkGetPhysicalDeviceProperties(ctx->physical_device_, &ctx->properties_);
  vkGetPhysicalDeviceMemoryProperties(ctx->physical_device_, &ctx->memory_);
  const auto family = graphics_family(ctx->physical_device_);
  if (!family) return make_error(Errc::unsupported, ctx->device_name() + " has no graphics queue");
  ctx->queue_family_ = *family;

  for (VkFormat f : {VK_FORMAT_D32_SFLOAT, VK_FORMAT_D24_UNORM_S8_UINT, VK_FORMAT_D16_UNORM}) {
    VkFormatProperties fp;
    vkGetPhysicalDeviceFormatProperties(ctx->physical_device_, f, &fp);
    if (fp.optimalTilingFeatures & VK_FORMAT_FEATURE_DEPTH_STENCIL_ATTACHMENT_BIT) {
      ctx->depth_format_ = f;
      break;
    }
  }
  if (ctx->depth_format_ == VK_FORMAT_UNDEFINED) return make_error(Errc::unsupported, "no depth format");

  const float priority = 1.0f;
  VkDeviceQueueCreateInfo queue_info{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
  queue_info.queueFamilyIndex = ctx->queue_family_;
  queue_info.queueCount = 1;
  queue_info.pQueuePriorities = &priority;
  std::vector<const char*> device_extensions;
  if (options.swapchain) device_extensions.push_back(VK_KHR_SWAPCHAIN_EXTENSION_NAME);
  VkDeviceCreateInfo device_info{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
  device_info.queueCreateInfoCount = 1;
  device_info.pQueueCreateInfos = &queue_info;
  device_info.enabledExtensionCount = static_cast<std::uint32_t>(device_extensions.size());
  device_info.ppEnabledExtensionNames = device_extensions.data();
  if (options.create_device) {
    auto device = options.create_device(ctx->physical_device_, device_info);
    if (!device) return device.error().with_context("creating the Vulkan device through OpenXR");
    ctx->device_ = *device;
  } else if (VkResult r = vkCreateDevice(ctx->physical_device_, &device_info, nullptr, &ctx->device_);
             r != VK_SUCCESS) {
    return vk_error("vkCreateDevice", r);
  }
  vkGetDeviceQueue(ctx->device_, ctx->queue_family_, 0, &ctx->queue_);

  VkCommandPoolCreateInfo pool_info{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pool_info.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pool_info.queueFamilyIndex = ctx->queue_family_;
  if (VkResult r = vkCreateCommandPool(ctx->device_, &pool_info, nullptr, &ctx->command_pool_); r != VK_SUCCESS) {
    return vk_error("vkCreateCommandPool", r);
  }
  logger().debug("{}", ctx->describe());
  return ctx;
}

VulkanContext::~VulkanContext() {
  if (device_ != VK_NULL_HANDLE) {
    vkDeviceWaitIdle(device_);
    vkDestroyCommandPool(device_, command_pool_, nullptr);
    vkDestroyDevice(device_, nullptr);
  }
  if (messenger_ != VK_NULL_HANDLE) {
    auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance_, "vkDestroyDebugUtilsMessengerEXT"));
    if (destroy) destroy(instance_, messenger_, nullptr);
  }
  if (instance_ != VK_NULL_HANDLE) vkDestroyInstance(instance_, nullptr);
}

void VulkanContext::on_validation_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity, const char* message) {
  if (severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT) {
    validation_errors_.fetch_add(1);
    logger().error("Vulkan validation: {}", message);
    std::lock_guard lock(messages_mutex_);
    if (messages_.size() < kKeptMessages) messages_.emplace_back(message);
  } else {
    logger().warn("Vulkan validation: {}", message);
  }
}

std::vector<std::string> VulkanContext::validation_messages() const {
  std::lock_guard lock(messages_mutex_);
  return messages_;
}

std::string VulkanContext::describe() const {
  static constexpr const char* kTypes[] = {"other", "integrated GPU", "discrete GPU", "virtual GPU", "CPU"};
  const auto type = static_cast<std::size_t>(properties_.deviceType);
  return fmt::format("Vulkan device '{}' ({}), API {}.{}.{}, validation {}", properties_.deviceName,
                     type < 5 ? kTypes[type] : "unknown", VK_API_VERSION_MAJOR(properties_.apiVersion),
                     VK_API_VERSION_MINOR(properties_.apiVersion), VK_API_VERSION_PATCH(properties_.apiVersion),
                     validation_enabled_ ? "on" : "off");
}

Result<std::uint32_t> VulkanContext::memory_type(std::uint32_t type_bits, VkMemoryPropertyFlags flags) const {
  for (std::uint32_t i = 0; i < memory_.memoryTypeCount; ++i) {
    if ((type_bits & (1u << i)) && (memory_.memoryTypes[i].propertyFlags & flags) == flags) return i;
  }
  return make_error(Errc::unsupported, fmt::format("no Vulkan memory type with flags {:#x}", flags));
}

Result<Buffer> VulkanContext::create_buffer(VkDeviceSize size, VkBufferUsageFlags usage, bool host_visible) const {
  Buffer b;
  b.device = device_;
  b.size = size;
  VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  info.size = size;
  info.usage = usage;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  if (VkResult r = vkCreateBuffer(device_, &info, nullptr, &b.buffer); r != VK_SUCCESS) return vk_error("vkCreateBuffer", r);
  VkMemoryRequirements req;
  vkGetBufferMemoryRequirements(device_, b.buffer, &req);
  const VkMemoryPropertyFlags flags = host_visible
                                          ? VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
                                          : VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT;
  auto type = memory_type(req.memoryTypeBits, flags);
  if (!type) return type.error();
  VkMemoryAllocateInfo alloc{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  alloc.allocationSize = req.size;
  alloc.memoryTypeIndex = *type;
  if (VkResult r = vkAllocateMemory(device_, &alloc, nullptr, &b.memory); r != VK_SUCCESS) {
    return vk_error("vkAllocateMemory", r);
  }
  vkBindBufferMemory(device_, b.buffer, b.memory, 0);
  if (host_visible) {
    if (VkResult r = vkMapMemory(device_, b.memory, 0, VK_WHOLE_SIZE, 0, &b.mapped); r != VK_SUCCESS) {
      return vk_error("vkMapMemory", r);
    }
  }
  return b;
}

Result<VkImageView> VulkanContext::create_view(VkImage image, VkFormat format, VkImageAspectFlags aspect) const {
  VkImageViewCreateInfo info{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
  info.image = image;
  info.viewType = VK_IMAGE_VIEW_TYPE_2D;
  info.format = format;
  info.subresourceRange = {aspect, 0, 1, 0, 1};
  VkImageView view = VK_NULL_HANDLE;
  if (VkResult r = vkCreateImageView(device_, &info, nullptr, &view); r != VK_SUCCESS) {
    return vk_error("vkCreateImageView", r);
  }
  return view;
}

Result<Image> VulkanContext::create_image(VkExtent2D extent, VkFormat format, VkImageUsageFlags usage,
                                          VkImageAspectFlags aspect) const {
  Image img;
  img.device = device_;
  img.format = format;
  img.extent = extent;
  VkImageCreateInfo info{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
  info.imageType = VK_IMAGE_TYPE_2D;
  info.format = format;
  info.extent = {extent.width, extent.height, 1};
  info.mipLevels = 1;
  info.arrayLayers = 1;
  info.samples = VK_SAMPLE_COUNT_1_BIT;
  info.tiling = VK_IMAGE_TILING_OPTIMAL;
  info.usage = usage;
  info.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  if (VkResult r = vkCreateImage(device_, &info, nullptr, &img.image); r != VK_SUCCESS) return vk_error("vkCreateImage", r);
  VkMemoryRequirements req;
  vkGetImageMemoryRequirements(device_, img.image, &req);
  auto type = memory_type(req.memoryTypeBits, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  if (!type) return type.error();
  VkMemoryAllocateInfo alloc{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  alloc.allocationSize = req.size;
  alloc.memoryTypeIndex = *type;
  if (VkResult r = vkAllocateMemory(device_, &alloc, nullptr, &img.memory); r != VK_SUCCESS) {
    return vk_error("vkAllocateMemory", r);
  }
  vkBindImageMemory(device_, img.image, img.memory, 0);
  auto view = create_view(img.image, format, aspect);
  if (!view) return view.error();
  img.view = *view;
  return img;
}

Status VulkanContext::run_once(const std::function<void(VkCommandBuffer)>& record) const {
  VkCommandBufferAllocateInfo alloc{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  alloc.commandPool = command_pool_;
  alloc.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  alloc.commandBufferCount = 1;
  VkCommandBuffer cmd = VK_NULL_HANDLE;
  if (VkResult r = vkAllocateCommandBuffers(device_, &alloc, &cmd); r != VK_SUCCESS) {
    return vk_error("vkAllocateCommandBuffers", r);
  }
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  vkBeginCommandBuffer(cmd, &begin);
  record(cmd);
  vkEndCommandBuffer(cmd);
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &cmd;
  VkResult r = vkQueueSubmit(queue_, 1, &submit, VK_NULL_HANDLE);
  if (r == VK_SUCCESS) r = vkQueueWaitIdle(queue_);
  vkFreeCommandBuffers(device_, command_pool_, 1, &cmd);
  if (r != VK_SUCCESS) return vk_error("one-off submit", r);
  return {};
}

Result<Buffer> VulkanContext::upload_buffer(const void* data, VkDeviceSize size, VkBufferUsageFlags usage) const {
  auto staging = create_buffer(size, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, true);
  if (!staging) return staging.error();
  std::memcpy(staging->mapped, data, size);
  auto buffer = create_buffer(size, usage | VK_BUFFER_USAGE_TRANSFER_DST_BIT, false);
  if (!buffer) return buffer.error();
  const VkBuffer src = staging->buffer, dst = buffer->buffer;
  if (auto s = run_once([&](VkCommandBuffer cmd) {
        const VkBufferCopy region{0, 0, size};
        vkCmdCopyBuffer(cmd, src, dst, 1, &region);
      });
      !s) {
    return s.error();
  }
  return std::move(buffer).value();
}

}  // namespace proprio::render
