#include "proprio/render/window_target.hpp"

#define GLFW_INCLUDE_VULKAN
#include <GLFW/glfw3.h>
#include <fmt/format.h>

#include <algorithm>
#include <cstdlib>

namespace proprio::render {

Result<std::unique_ptr<Window>> Window::create(const std::string& title, int width, int height) {
  if (!std::getenv("DISPLAY") && !std::getenv("WAYLAND_DISPLAY")) {
    return make_error(Errc::unavailable, "no display: $DISPLAY and $WAYLAND_DISPLAY are unset (use --headless, "
                                         "or run under xvfb-run)");
  }
  if (!glfwInit()) return make_error(Errc::unavailable, "GLFW could not initialise (no usable display?)");
  if (!glfwVulkanSupported()) {
    glfwTerminate();
    return make_error(Errc::unsupported, "GLFW finds no Vulkan loader or surface support");
  }
  glfwWindowHint(GLFW_CLIENT_API, GLFW_NO_API);
  std::unique_ptr<Window> w(new Window());
  w->window_ = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
  if (!w->window_) {
    glfwTerminate();
    return make_error(Errc::unavailable, "GLFW could not create a window");
  }
  glfwGetCursorPos(w->window_, &w->last_x_, &w->last_y_);
  glfwSetWindowUserPointer(w->window_, w.get());
  glfwSetKeyCallback(w->window_, &Window::on_key);
  return w;
}

Window::~Window() {
  if (window_) glfwDestroyWindow(window_);
  glfwTerminate();
}

std::vector<std::string> Window::required_instance_extensions() const {
  std::uint32_t count = 0;
  const char** names = glfwGetRequiredInstanceExtensions(&count);
  return std::vector<std::string>(names, names + count);
}

bool Window::should_close() const { return glfwWindowShouldClose(window_) != 0; }
void Window::request_close() { glfwSetWindowShouldClose(window_, GLFW_TRUE); }

void Window::on_key(GLFWwindow* window, int key, int /*scancode*/, int action, int /*mods*/) {
  if (action != GLFW_PRESS) return;
  auto* self = static_cast<Window*>(glfwGetWindowUserPointer(window));
  std::string name;
  if (key >= GLFW_KEY_A && key <= GLFW_KEY_Z) name = std::string(1, static_cast<char>('a' + (key - GLFW_KEY_A)));
  if (key >= GLFW_KEY_0 && key <= GLFW_KEY_9) name = std::string(1, static_cast<char>('0' + (key - GLFW_KEY_0)));
  switch (key) {
    case GLFW_KEY_SPACE: name = "space"; break;
    case GLFW_KEY_ENTER: name = "enter"; break;
    case GLFW_KEY_LEFT: name = "left"; break;
    case GLFW_KEY_RIGHT: name = "right"; break;
    case GLFW_KEY_UP: name = "up"; break;
    case GLFW_KEY_DOWN: name = "down"; break;
    case GLFW_KEY_BACKSPACE: name = "backspace"; break;
    default: break;
  }
  if (self && !name.empty()) self->pending_keys_.push_back(std::move(name));
}

WindowInput Window::poll() {
  glfwPollEvents();
  WindowInput in;
  in.keys_pressed.swap(pending_keys_);
  auto key = [&](int k) { return glfwGetKey(window_, k) == GLFW_PRESS ? 1.0f : 0.0f; };
  in.move_forward = key(GLFW_KEY_W) - key(GLFW_KEY_S);
  in.move_right = key(GLFW_KEY_D) - key(GLFW_KEY_A);
  in.move_up = key(GLFW_KEY_E) - key(GLFW_KEY_Q);
  in.fast = key(GLFW_KEY_LEFT_SHIFT) > 0;
  if (key(GLFW_KEY_ESCAPE) > 0) request_close();
  double x = 0, y = 0;
  glfwGetCursorPos(window_, &x, &y);
  const bool down = glfwGetMouseButton(window_, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS;
  if (down && dragging_) {
    in.look_dx_px = static_cast<float>(x - last_x_);
    in.look_dy_px = static_cast<float>(y - last_y_);
  }
  dragging_ = down;
  last_x_ = x;
  last_y_ = y;
  return in;
}

VkExtent2D Window::framebuffer_extent() const {
  int w = 0, h = 0;
  glfwGetFramebufferSize(window_, &w, &h);
  return {static_cast<std::uint32_t>(std::max(w, 0)), static_cast<std::uint32_t>(std::max(h, 0))};
}

Result<std::unique_ptr<WindowTarget>> WindowTarget::create(Renderer& renderer, Window& window) {
  std::unique_ptr<WindowTarget> t(new WindowTarget(renderer, window));
  VulkanContext& ctx = renderer.context();
  if (VkResult r = glfwCreateWindowSurface(ctx.instance(), window.handle(), nullptr, &t->surface_); r != VK_SUCCESS) {
    return vk_error("glfwCreateWindowSurface", r);
  }
  VkBool32 supported = VK_FALSE;
  vkGetPhysicalDeviceSurfaceSupportKHR(ctx.physical_device(), ctx.queue_family(), t->surface_, &supported);
  if (!supported) return make_error(Errc::unsupported, ctx.device_name() + " cannot present to this window");
  VkSemaphoreCreateInfo sem{VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO};
  if (VkResult r = vkCreateSemaphore(ctx.device(), &sem, nullptr, &t->image_available_); r != VK_SUCCESS) {
    return vk_error("vkCreateSemaphore", r);
  }
  if (auto s = t->create_swapchain(); !s) return s.error();
  return t;
}

WindowTarget::~WindowTarget() {
  VulkanContext& ctx = renderer_.context();
  vkDeviceWaitIdle(ctx.device());
  destroy_swapchain();
  vkDestroySemaphore(ctx.device(), image_available_, nullptr);
  if (surface_) vkDestroySurfaceKHR(ctx.instance(), surface_, nullptr);
}

void WindowTarget::destroy_swapchain() {
  const VkDevice device = renderer_.context().device();
  framebuffers_.reset();
  for (VkSemaphore s : render_finished_) vkDestroySemaphore(device, s, nullptr);
  render_finished_.clear();
  if (swapchain_) vkDestroySwapchainKHR(device, swapchain_, nullptr);
  swapchain_ = VK_NULL_HANDLE;
}

Status WindowTarget::create_swapchain() {
  VulkanContext& ctx = renderer_.context();
  const VkPhysicalDevice gpu = ctx.physical_device();
  VkSurfaceCapabilitiesKHR caps;
  vkGetPhysicalDeviceSurfaceCapabilitiesKHR(gpu, surface_, &caps);
  std::uint32_t count = 0;
  vkGetPhysicalDeviceSurfaceFormatsKHR(gpu, surface_, &count, nullptr);
  std::vector<VkSurfaceFormatKHR> formats(count);
  vkGetPhysicalDeviceSurfaceFormatsKHR(gpu, surface_, &count, formats.data());
  if (formats.empty()) return make_error(Errc::unsupported, "the window surface offers no formats");
  format_ = formats[0];
  for (const auto& f : formats) {
    if ((f.format == VK_FORMAT_B8G8R8A8_SRGB || f.format == VK_FORMAT_R8G8B8A8_SRGB) &&
        f.colorSpace == VK_COLOR_SPACE_SRGB_NONLINEAR_KHR) {
      format_ = f;
      break;
    }
  }
  VkExtent2D extent = caps.currentExtent;
  if (extent.width == 0xFFFFFFFFu) extent = window_.framebuffer_extent();
  extent.width = std::clamp(extent.width, caps.minImageExtent.width, caps.maxImageExtent.width);
  extent.height = std::clamp(extent.height, caps.minImageExtent.height, caps.maxImageExtent.height);
  if (extent.width == 0 || extent.height == 0) return make_error(Errc::unavailable, "the window is minimised");
  std::uint32_t images = caps.minImageCount + 1;
  if (caps.maxImageCount > 0) images = std::min(images, caps.maxImageCount);

  VkSwapchainCreateInfoKHR info{VK_STRUCTURE_TYPE_SWAPCHAIN_CREATE_INFO_KHR};
  info.surface = surface_;
  info.minImageCount = images;
  info.imageFormat = format_.format;
  info.imageColorSpace = format_.colorSpace;
  info.imageExtent = extent;
  info.imageArrayLayers = 1;
  info.imageUsage = VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT;
  info.imageSharingMode = VK_SHARING_MODE_EXCLUSIVE;
  info.preTransform = caps.currentTransform;
  info.compositeAlpha = VK_COMPOSITE_ALPHA_OPAQUE_BIT_KHR;
  info.presentMode = VK_PRESENT_MODE_FIFO_KHR;  // always supported; paced to the display
  info.clipped = VK_TRUE;
  if (VkResult r = vkCreateSwapchainKHR(ctx.device(), &info, nullptr, &swapchain_); r != VK_SUCCESS) {
    return vk_error("vkCreateSwapchainKHR", r);
  }
  vkGetSwapchainImagesKHR(ctx.device(), swapchain_, &count, nullptr);
  std::vector<VkImage> handles(count);
  vkGetSwapchainImagesKHR(ctx.device(), swapchain_, &count, handles.data());
  auto set = FramebufferSet::create(renderer_, handles, format_.format, extent, VK_IMAGE_LAYOUT_PRESENT_SRC_KHR);
  if (!set) return set.error();
  framebuffers_ = std::move(set).value();
  VkSemaphoreCreateInfo sem{VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO};
  render_finished_.resize(count, VK_NULL_HANDLE);
  for (auto& s : render_finished_) {
    if (VkResult r = vkCreateSemaphore(ctx.device(), &sem, nullptr, &s); r != VK_SUCCESS) {
      return vk_error("vkCreateSemaphore", r);
    }
  }
  return {};
}

VkExtent2D WindowTarget::extent() const noexcept { return framebuffers_->extent(); }

Result<WindowTarget::Frame> WindowTarget::acquire() {
  // One frame in flight: the acquire semaphore is free again once the last
  // frame's commands are done.
  if (auto s = renderer_.wait_idle(); !s) return s.error();
  const VkDevice device = renderer_.context().device();
  for (int attempt = 0; attempt < 2; ++attempt) {
    std::uint32_t index = 0;
    const VkResult r = vkAcquireNextImageKHR(device, swapchain_, UINT64_MAX, image_available_, VK_NULL_HANDLE, &index);
    if (r == VK_SUCCESS || r == VK_SUBOPTIMAL_KHR) {
      return Frame{{framebuffers_.get(), index}, {image_available_, render_finished_[index]}, index};
    }
    if (r != VK_ERROR_OUT_OF_DATE_KHR) return vk_error("vkAcquireNextImageKHR", r);
    vkDeviceWaitIdle(device);
    destroy_swapchain();
    if (auto s = create_swapchain(); !s) return s.error();
  }
  return make_error(Errc::unavailable, "the window's swapchain stays out of date");
}

Status WindowTarget::present(const Frame& frame) {
  VkPresentInfoKHR info{VK_STRUCTURE_TYPE_PRESENT_INFO_KHR};
  info.waitSemaphoreCount = 1;
  info.pWaitSemaphores = &frame.sync.signal;
  info.swapchainCount = 1;
  info.pSwapchains = &swapchain_;
  info.pImageIndices = &frame.image_index;
  const VkResult r = vkQueuePresentKHR(renderer_.context().queue(), &info);
  if (r == VK_ERROR_OUT_OF_DATE_KHR || r == VK_SUBOPTIMAL_KHR) {
    if (auto s = renderer_.wait_idle(); !s) return s;
    vkDeviceWaitIdle(renderer_.context().device());
    destroy_swapchain();
    return create_swapchain();
  }
  if (r != VK_SUCCESS) return vk_error("vkQueuePresentKHR", r);
  return {};
}

}  // namespace proprio::render
