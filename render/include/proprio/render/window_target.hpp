#pragma once
// A desktop window (GLFW, no OpenGL context) and the Vulkan swapchain that
// presents into it. Used when no OpenXR runtime is there: the engine flies a
// mouse/keyboard camera through the scene.
#include <memory>
#include <string>
#include <vector>

#include "proprio/render/renderer.hpp"

struct GLFWwindow;

namespace proprio::render {

// Keyboard and mouse since the last poll(): W/S forward/back, A/D left/right,
// E/Q up/down, drag with the left button to look around, Esc closes.
struct WindowInput {
  float move_forward = 0, move_right = 0, move_up = 0;  // -1, 0 or 1
  float look_dx_px = 0, look_dy_px = 0;
  bool fast = false;  // shift held
  // Key presses in order (not repeats): "a".."z", "0".."9", "space", "enter",
  // "left", "right", "up", "down", "backspace"; others are left out.
  std::vector<std::string> keys_pressed;
};

class Window {
 public:
  // Errc::unavailable when there is no display (no $DISPLAY / Wayland).
  static Result<std::unique_ptr<Window>> create(const std::string& title, int width, int height);
  ~Window();
  Window(const Window&) = delete;
  Window& operator=(const Window&) = delete;

  // The instance extensions the surface needs (after create()).
  std::vector<std::string> required_instance_extensions() const;
  bool should_close() const;
  void request_close();
  // Processes window events; returns the input since the last call.
  WindowInput poll();
  VkExtent2D framebuffer_extent() const;
  GLFWwindow* handle() const noexcept { return window_; }

 private:
  Window() = default;
  GLFWwindow* window_ = nullptr;
  double last_x_ = 0, last_y_ = 0;
  bool dragging_ = false;
  std::vector<std::string> pending_keys_;  // filled by GLFW's key callback during glfwPollEvents
  static void on_key(GLFWwindow* window, int key, int scancode, int action, int mods);
};

class WindowTarget {
 public:
  // The context must have been created with the window's instance
  // extensions and ContextOptions::swapchain = true.
  static Result<std::unique_ptr<WindowTarget>> create(Renderer& renderer, Window& window);
  ~WindowTarget();
  WindowTarget(const WindowTarget&) = delete;
  WindowTarget& operator=(const WindowTarget&) = delete;

  // Waits for the previous frame, acquires the next image. The returned sync
  // goes to Renderer::render; then present().
  struct Frame {
    ViewTarget target;
    FrameSync sync;
    std::uint32_t image_index = 0;
  };
  Result<Frame> acquire();
  Status present(const Frame& frame);
  VkExtent2D extent() const noexcept;

 private:
  WindowTarget(Renderer& renderer, Window& window) : renderer_(renderer), window_(window) {}
  Status create_swapchain();
  void destroy_swapchain();

  Renderer& renderer_;
  Window& window_;
  VkSurfaceKHR surface_ = VK_NULL_HANDLE;
  VkSwapchainKHR swapchain_ = VK_NULL_HANDLE;
  VkSurfaceFormatKHR format_{};
  std::unique_ptr<FramebufferSet> framebuffers_;
  VkSemaphore image_available_ = VK_NULL_HANDLE;
  std::vector<VkSemaphore> render_finished_;  // one per swapchain image
};

}  // namespace proprio::render
