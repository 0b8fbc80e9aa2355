#pragma once
// The renderer: meshes uploaded once, then each frame a draw list rendered
// into one framebuffer per view (one per eye in stereo), with a head-locked
// text overlay. All targets (offscreen images, a window's swapchain, an
// OpenXR swapchain) hand it framebuffers from a FramebufferSet.
//
// Steady state allocates nothing: the draw list keeps its capacity, the
// command buffer, fence and overlay vertex buffer are made once, and
// pipelines are cached per colour format. One frame is in flight at a time
// (render() waits for the previous frame first).
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "proprio/render/camera.hpp"
#include "proprio/render/context.hpp"
#include "proprio/render/mesh.hpp"
#include "proprio/render/skinned_mesh.hpp"

namespace proprio::render {

using MeshId = std::uint32_t;

struct DrawItem {
  MeshId mesh = 0;
  glm::mat4 T_world_object{1.0f};  // may scale (bones, unit primitives)
  glm::vec4 color{0.8f, 0.8f, 0.8f, 1.0f};  // linear RGB; alpha < 1 blends
};

// A skinned mesh (Renderer::upload_skinned) skinned on the CPU each frame:
// its joints' skin matrices (T_world_joint * inverse_bind, one per skin
// joint, in the mesh's joint order) start at `first_matrix` in
// DrawList::skin_matrices. Drawn after the static items, in order.
struct SkinnedDrawItem {
  static constexpr std::uint32_t kSkinned = 0xFFFFFFFFu;
  MeshId mesh = 0;
  std::uint32_t first_matrix = 0;
  glm::vec4 color{0.8f, 0.8f, 0.8f, 1.0f};
  // A deforming surface (a stretch array's mesh, cloth) whose vertices the
  // caller computes: they are taken, in world space with their normals, from
  // DrawList::posed_vertices starting here instead of being skinned. Upload
  // such a mesh with Renderer::upload_deforming.
  std::uint32_t first_posed_vertex = kSkinned;
};

// A line or block of text in the overlay, in pixels from the target's
// top-left corner. `scale` multiplies the built-in 6x7-pixel font (stb_easy_font).
struct HudText {
  std::string text;  // '\n' starts a new line
  glm::vec2 position_px{16.0f, 16.0f};
  float scale = 2.0f;
  glm::vec4 color{1.0f, 1.0f, 1.0f, 1.0f};
  bool panel = true;  // a dark translucent box behind the text
};

struct DrawList {
  std::vector<DrawItem> items;
  std::vector<HudText> hud;
  std::vector<SkinnedDrawItem> skinned;
  std::vector<glm::mat4> skin_matrices;
  std::vector<Vertex> posed_vertices;  // for SkinnedDrawItem::first_posed_vertex
  glm::vec4 clear_color{0.08f, 0.09f, 0.11f, 1.0f};
  // Keeps capacity, so refilling it every frame does not allocate.
  void clear() {
    items.clear();
    hud.clear();
    skinned.clear();
    skin_matrices.clear();
    posed_vertices.clear();
  }
};

class Renderer;

// Framebuffers over a set of colour images (owned elsewhere: a swapchain's,
// or an OffscreenTarget's), with one depth buffer shared by them. The
// images end each frame in `final_layout` (TRANSFER_SRC for read-back,
// PRESENT_SRC for a window, COLOR_ATTACHMENT for OpenXR).
class FramebufferSet {
 public:
  static Result<std::unique_ptr<FramebufferSet>> create(Renderer& renderer, std::span<const VkImage> images,
                                                        VkFormat color_format, VkExtent2D extent,
                                                        VkImageLayout final_layout);
  ~FramebufferSet();
  FramebufferSet(const FramebufferSet&) = delete;
  FramebufferSet& operator=(const FramebufferSet&) = delete;

  std::size_t size() const noexcept { return framebuffers_.size(); }
  VkFramebuffer framebuffer(std::size_t i) const noexcept { return framebuffers_[i]; }
  VkImage image(std::size_t i) const noexcept { return images_[i]; }
  VkExtent2D extent() const noexcept { return extent_; }
  VkFormat color_format() const noexcept { return color_format_; }
  VkImageLayout final_layout() const noexcept { return final_layout_; }
  std::size_t pass_index() const noexcept { return pass_; }

 private:
  FramebufferSet() = default;
  VkDevice device_ = VK_NULL_HANDLE;
  std::vector<VkImage> images_;
  std::vector<VkImageView> views_;
  std::vector<VkFramebuffer> framebuffers_;
  Image depth_;
  VkExtent2D extent_{};
  VkFormat color_format_ = VK_FORMAT_UNDEFINED;
  VkImageLayout final_layout_ = VK_IMAGE_LAYOUT_UNDEFINED;
  std::size_t pass_ = 0;
};

// One view's destination: framebuffer `index` of `set`.
struct ViewTarget {
  const FramebufferSet* set = nullptr;
  std::size_t index = 0;
};

// Semaphores a window or XR frame waits on / signals (optional).
struct FrameSync {
  VkSemaphore wait = VK_NULL_HANDLE;
  VkSemaphore signal = VK_NULL_HANDLE;
};

struct RendererOptions {
  std::size_t max_hud_characters = 4096;
  // Skinned vertices per frame, all skinned draws together (a generated
  // hand has about 3000); draws past it are skipped and counted.
  std::size_t max_skinned_vertices = 65536;
  float near_m = 0.02f;
  float far_m = 50.0f;
  std::string describe() const;
};

struct RenderStats {
  std::uint64_t frames = 0;
  std::size_t draws_last_frame = 0;          // static and skinned
  std::size_t skinned_vertices_last_frame = 0;
  std::uint64_t skinned_draws_dropped = 0;  // over max_skinned_vertices, since creation
};

class Renderer {
 public:
  static Result<std::unique_ptr<Renderer>> create(VulkanContext& context, RendererOptions options = {});
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Uploads a mesh; its id is valid for the renderer's lifetime.
  Result<MeshId> upload(const MeshData& mesh);
  // Uploads a skinned mesh (its indices; the vertices stay on the CPU and
  // are skinned each frame into a host-visible buffer). Draw it with
  // DrawList::skinned, not as a DrawItem.
  Result<MeshId> upload_skinned(const SkinnedMeshData& mesh);
  // Uploads the triangles of a mesh whose vertices change every frame; draw
  // it with a SkinnedDrawItem whose first_posed_vertex is set. `mesh`'s
  // vertices only fix their count.
  Result<MeshId> upload_deforming(const MeshData& mesh);
  std::size_t mesh_count() const noexcept;

  // Records and submits one frame: views[i] into targets[i]. Returns once
  // submitted; wait_idle() (or the next render) waits for the GPU.
  Status render(const DrawList& draws, std::span<const View> views, std::span<const ViewTarget> targets,
                const FrameSync& sync = {});
  Status wait_idle();

  VulkanContext& context() noexcept { return context_; }
  const RenderStats& stats() const noexcept { return stats_; }

  // Render pass (and its pipelines) for a colour format and final layout;
  // FramebufferSet uses it. Created on first use, then cached.
  Result<std::size_t> pass_for(VkFormat color_format, VkImageLayout final_layout);
  VkRenderPass render_pass(std::size_t pass) const noexcept;

 private:
  struct GpuMesh;
  struct Pass;
  explicit Renderer(VulkanContext& context, RendererOptions options);
  Status init();
  std::uint32_t fill_hud(const DrawList& draws, std::size_t& vertex_count);
  // The index buffer (triangles, then reversed) of a CPU-posed mesh.
  Result<MeshId> upload_cpu_posed(const std::string& name, std::vector<SkinnedVertex> source,
                                  const std::vector<std::uint32_t>& triangles, std::size_t joint_count);
  // Skins every skinned draw that fits into skin_vertices_; returns the vertices written.
  std::size_t fill_skinned(const DrawList& draws);

  VulkanContext& context_;
  RendererOptions options_;
  std::vector<GpuMesh> meshes_;
  std::vector<Pass> passes_;
  VkPipelineLayout lit_layout_ = VK_NULL_HANDLE;
  VkPipelineLayout hud_layout_ = VK_NULL_HANDLE;
  VkShaderModule lit_vert_ = VK_NULL_HANDLE, lit_frag_ = VK_NULL_HANDLE;
  VkShaderModule hud_vert_ = VK_NULL_HANDLE, hud_frag_ = VK_NULL_HANDLE;
  VkCommandPool pool_ = VK_NULL_HANDLE;
  VkCommandBuffer cmd_ = VK_NULL_HANDLE;
  VkFence in_flight_ = VK_NULL_HANDLE;
  bool submitted_ = false;
  Buffer hud_vertices_;
  Buffer hud_indices_;
  std::vector<char> hud_scratch_;  // stb_easy_font's output, reused
  Buffer skin_vertices_;           // host-visible, rewritten each frame (one frame in flight)
  RenderStats stats_;
};

}  // namespace proprio::render
