#pragma once
// Render to images in memory (headless runs, CI, golden-image tests, the
// demo's PNG frames): one colour image per view, read back to the CPU.
#include <memory>
#include <vector>

#include "proprio/render/image.hpp"
#include "proprio/render/renderer.hpp"

namespace proprio::render {

class OffscreenTarget {
 public:
  // 8-bit sRGB colour, `view_count` images (2 for stereo).
  static Result<std::unique_ptr<OffscreenTarget>> create(Renderer& renderer, std::uint32_t width,
                                                         std::uint32_t height, std::uint32_t view_count = 1);
  ~OffscreenTarget();
  OffscreenTarget(const OffscreenTarget&) = delete;
  OffscreenTarget& operator=(const OffscreenTarget&) = delete;

  std::span<const ViewTarget> views() const noexcept { return targets_; }
  VkExtent2D extent() const noexcept { return framebuffers_->extent(); }

  // Waits for the frame, copies view `view` to `out` (reusing its storage).
  Status read(std::uint32_t view, ImageRGBA8& out);

 private:
  explicit OffscreenTarget(Renderer& renderer) : renderer_(renderer) {}
  Renderer& renderer_;
  std::vector<Image> images_;
  std::unique_ptr<FramebufferSet> framebuffers_;
  std::vector<ViewTarget> targets_;
  Buffer readback_;
  VkCommandPool pool_ = VK_NULL_HANDLE;
  VkCommandBuffer cmd_ = VK_NULL_HANDLE;
  VkFence fence_ = VK_NULL_HANDLE;
};

}  // namespace proprio::render
