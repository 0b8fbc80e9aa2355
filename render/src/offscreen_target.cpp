#include "proprio/render/offscreen_target.hpp"

#include <fmt/format.h>

#include <cstring>

namespace proprio::render {

constexpr VkFormat kOffscreenFormat = VK_FORMAT_R8G8B8A8_SRGB;

Result<std::unique_ptr<OffscreenTarget>> OffscreenTarget::create(Renderer& renderer, std::uint32_t width,
                                                                 std::uint32_t height, std::uint32_t view_count) {
  if (width == 0 || height == 0 || width > 16384 || height > 16384 || view_count == 0 || view_count > 8) {
    return make_error(Errc::invalid_argument, fmt::format("offscreen target {}x{} with {} views is out of range",
                                                          width, height, view_count));
  }
  VulkanContext& ctx = renderer.context();
  std::unique_ptr<OffscreenTarget> t(new OffscreenTarget(renderer));
  const VkExtent2D extent{width, height};
  std::vector<VkImage> handles;
  for (std::uint32_t i = 0; i < view_count; ++i) {
    auto image = ctx.create_image(extent, kOffscreenFormat,
                                  VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT,
                                  VK_IMAGE_ASPECT_COLOR_BIT);
    if (!image) return image.error();
    handles.push_back(image->image);
    t->images_.push_back(std::move(image).value());
  }
  auto set = FramebufferSet::create(renderer, handles, kOffscreenFormat, extent, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL);
  if (!set) return set.error();
  t->framebuffers_ = std::move(set).value();
  for (std::uint32_t i = 0; i < view_count; ++i) t->targets_.push_back({t->framebuffers_.get(), i});
  auto rb = ctx.create_buffer(VkDeviceSize{width} * height * 4, VK_BUFFER_USAGE_TRANSFER_DST_BIT, true);
  if (!rb) return rb.error();
  t->readback_ = std::move(rb).value();

  VkCommandPoolCreateInfo pool{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pool.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pool.queueFamilyIndex = ctx.queue_family();
  if (VkResult r = vkCreateCommandPool(ctx.device(), &pool, nullptr, &t->pool_); r != VK_SUCCESS) {
    return vk_error("vkCreateCommandPool", r);
  }
  VkCommandBufferAllocateInfo alloc{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  alloc.commandPool = t->pool_;
  alloc.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  alloc.commandBufferCount = 1;
  if (VkResult r = vkAllocateCommandBuffers(ctx.device(), &alloc, &t->cmd_); r != VK_SUCCESS) {
    return vk_error("vkAllocateCommandBuffers", r);
  }
  VkFenceCreateInfo fence{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  if (VkResult r = vkCreateFence(ctx.device(), &fence, nullptr, &t->fence_); r != VK_SUCCESS) {
    return vk_error("vkCreateFence", r);
  }
  return t;
}

OffscreenTarget::~OffscreenTarget() {
  const VkDevice device = renderer_.context().device();
  vkDeviceWaitIdle(device);
  vkDestroyFence(device, fence_, nullptr);
  vkDestroyCommandPool(device, pool_, nullptr);
}

Status OffscreenTarget::read(std::uint32_t view, ImageRGBA8& out) {
  if (view >= images_.size()) {
    return make_error(Errc::invalid_argument, fmt::format("read: view {} of {}", view, images_.size()));
  }
  if (renderer_.stats().frames == 0) return make_error(Errc::unavailable, "read: nothing has been rendered yet");
  if (auto s = renderer_.wait_idle(); !s) return s;
  const VkDevice device = renderer_.context().device();
  const Image& image = images_[view];
  vkResetCommandBuffer(cmd_, 0);
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  vkBeginCommandBuffer(cmd_, &begin);
  VkBufferImageCopy region{};
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageExtent = {image.extent.width, image.extent.height, 1};
  vkCmdCopyImageToBuffer(cmd_, image.image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, readback_.buffer, 1, &region);
  VkBufferMemoryBarrier to_host{VK_STRUCTURE_TYPE_BUFFER_MEMORY_BARRIER};
  to_host.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  to_host.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  to_host.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  to_host.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  to_host.buffer = readback_.buffer;
  to_host.size = VK_WHOLE_SIZE;
  vkCmdPipelineBarrier(cmd_, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 0, nullptr, 1, &to_host, 0,
                       nullptr);
  vkEndCommandBuffer(cmd_);
  vkResetFences(device, 1, &fence_);
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &cmd_;
  if (VkResult r = vkQueueSubmit(renderer_.context().queue(), 1, &submit, fence_); r != VK_SUCCESS) {
    return vk_error("vkQueueSubmit (read-back)", r);
  }
  if (VkResult r = vkWaitForFences(device, 1, &fence_, VK_TRUE, UINT64_MAX); r != VK_SUCCESS) {
    return vk_error("vkWaitForFences (read-back)", r);
  }
  out.width = image.extent.width;
  out.height = image.extent.height;
  out.pixels.resize(std::size_t{out.width} * out.height * 4);
  std::memcpy(out.pixels.data(), readback_.mapped, out.pixels.size());
  return {};
}

}  // namespace proprio::render
