#include "proprio/render/renderer.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cstring>

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wconversion"
#include <stb_easy_font.h>
#pragma GCC diagnostic pop

#include "proprio_shaders/hud_frag.h"
#include "proprio_shaders/hud_vert.h"
#include "proprio_shaders/lit_frag.h"
#include "proprio_shaders/lit_vert.h"

namespace proprio::render {
namespace {

// Mirrors lit.vert's push-constant block: 128 bytes, the guaranteed minimum.
struct LitPush {
  glm::mat4 clip_from_object;
  glm::vec4 world_rows[3];
  glm::vec4 color;
};
static_assert(sizeof(LitPush) == 128);

struct HudVertex {
  glm::vec2 position_px;
  std::uint8_t rgba[4];
};
static_assert(sizeof(HudVertex) == 12);

// stb_easy_font writes 16-byte vertices (x, y, z, rgba), four per quad, and
// needs about 270 bytes per character on average; 400 leaves headroom.
constexpr std::size_t kEasyFontBytesPerChar = 400;
constexpr std::size_t kEasyFontVertexBytes = 16;
constexpr float kPanelMarginPx = 6.0f;

std::uint8_t to_u8(float v) { return static_cast<std::uint8_t>(std::clamp(v, 0.0f, 1.0f) * 255.0f + 0.5f); }

Result<VkShaderModule> make_module(VkDevice device, const std::uint32_t* code, std::size_t bytes) {
  VkShaderModuleCreateInfo info{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
  info.codeSize = bytes;
  info.pCode = code;
  VkShaderModule module = VK_NULL_HANDLE;
  if (VkResult r = vkCreateShaderModule(device, &info, nullptr, &module); r != VK_SUCCESS) {
    return vk_error("vkCreateShaderModule", r);
  }
  return module;
}

}  // namespace

struct Renderer::GpuMesh {
  Buffer vertices;  // empty for skinned meshes: they are skinned into skin_vertices_
  Buffer indices;   // skinned: the triangles, then the same with the winding reversed (mirrored draws)
  std::uint32_t index_count = 0;
  bool skinned = false;
  std::vector<SkinnedVertex> skin_source;  // bind-space vertices
  std::size_t joint_count = 0;
};

struct Renderer::Pass {
  VkFormat color_format = VK_FORMAT_UNDEFINED;
  VkImageLayout final_layout = VK_IMAGE_LAYOUT_UNDEFINED;
  VkRenderPass render_pass = VK_NULL_HANDLE;
  VkPipeline lit = VK_NULL_HANDLE;
  VkPipeline hud = VK_NULL_HANDLE;
};

std::string RendererOptions::describe() const {
  return fmt::format("renderer: near {} m, far {} m, overlay up to {} characters, up to {} skinned vertices per frame",
                     near_m, far_m, max_hud_characters, max_skinned_vertices);
}

Renderer::Renderer(VulkanContext& context, RendererOptions options) : context_(context), options_(options) {}

Result<std::unique_ptr<Renderer>> Renderer::create(VulkanContext& context, RendererOptions options) {
  if (!(options.near_m > 0) || !(options.far_m > options.near_m)) {
    return make_error(Errc::invalid_argument, "renderer: need 0 < near < far, got " + options.describe());
  }
  std::unique_ptr<Renderer> r(new Renderer(context, options));
  if (auto s = r->init(); !s) return s.error();
  return r;
}

Status Renderer::init() {
  const VkDevice device = context_.device();
  auto lv = make_module(device, lit_vert_spv, sizeof lit_vert_spv);
  auto lf = make_module(device, lit_frag_spv, sizeof lit_frag_spv);
  auto hv = make_module(device, hud_vert_spv, sizeof hud_vert_spv);
  auto hf = make_module(device, hud_frag_spv, sizeof hud_frag_spv);
  if (!lv || !lf || !hv || !hf) return make_error(Errc::io_error, "could not create the shader modules");
  lit_vert_ = *lv;
  lit_frag_ = *lf;
  hud_vert_ = *hv;
  hud_frag_ = *hf;

  VkPushConstantRange lit_range{VK_SHADER_STAGE_VERTEX_BIT, 0, sizeof(LitPush)};
  VkPipelineLayoutCreateInfo layout{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  layout.pushConstantRangeCount = 1;
  layout.pPushConstantRanges = &lit_range;
  if (VkResult r = vkCreatePipelineLayout(device, &layout, nullptr, &lit_layout_); r != VK_SUCCESS) {
    return vk_error("vkCreatePipelineLayout", r);
  }
  VkPushConstantRange hud_range{VK_SHADER_STAGE_VERTEX_BIT, 0, sizeof(glm::vec2)};
  layout.pPushConstantRanges = &hud_range;
  if (VkResult r = vkCreatePipelineLayout(device, &layout, nullptr, &hud_layout_); r != VK_SUCCESS) {
    return vk_error("vkCreatePipelineLayout", r);
  }

  VkCommandPoolCreateInfo pool{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pool.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pool.queueFamilyIndex = context_.queue_family();
  if (VkResult r = vkCreateCommandPool(device, &pool, nullptr, &pool_); r != VK_SUCCESS) {
    return vk_error("vkCreateCommandPool", r);
  }
  VkCommandBufferAllocateInfo alloc{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  alloc.commandPool = pool_;
  alloc.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  alloc.commandBufferCount = 1;
  if (VkResult r = vkAllocateCommandBuffers(device, &alloc, &cmd_); r != VK_SUCCESS) {
    return vk_error("vkAllocateCommandBuffers", r);
  }
  VkFenceCreateInfo fence{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  if (VkResult r = vkCreateFence(device, &fence, nullptr, &in_flight_); r != VK_SUCCESS) {
    return vk_error("vkCreateFence", r);
  }

  // The overlay: vertices rewritten each frame in a mapped buffer, and a
  // fixed quad index pattern.
  hud_scratch_.resize(options_.max_hud_characters * kEasyFontBytesPerChar);
  const std::size_t max_quads = hud_scratch_.size() / (4 * kEasyFontVertexBytes) + 64;  // + panels
  auto vb = context_.create_buffer(max_quads * 4 * sizeof(HudVertex), VK_BUFFER_USAGE_VERTEX_BUFFER_BIT, true);
  if (!vb) return vb.error();
  hud_vertices_ = std::move(vb).value();
  std::vector<std::uint32_t> quad_indices;
  quad_indices.reserve(max_quads * 6);
  for (std::uint32_t q = 0; q < max_quads; ++q) {
    quad_indices.insert(quad_indices.end(), {4 * q, 4 * q + 1, 4 * q + 2, 4 * q, 4 * q + 2, 4 * q + 3});
  }
  auto ib = context_.upload_buffer(quad_indices.data(), quad_indices.size() * sizeof(std::uint32_t),
                                   VK_BUFFER_USAGE_INDEX_BUFFER_BIT);
  if (!ib) return ib.error();
  hud_indices_ = std::move(ib).value();

  if (options_.max_skinned_vertices > 0) {
    auto sb = context_.create_buffer(options_.max_skinned_vertices * sizeof(Vertex), VK_BUFFER_USAGE_VERTEX_BUFFER_BIT,
                                     true);
    if (!sb) return sb.error().with_context("skinned vertex buffer");
    skin_vertices_ = std::move(sb).value();
  }
  return {};
}

Renderer::~Renderer() {
  const VkDevice device = context_.device();
  vkDeviceWaitIdle(device);
  for (auto& p : passes_) {
    vkDestroyPipeline(device, p.lit, nullptr);
    vkDestroyPipeline(device, p.hud, nullptr);
    vkDestroyRenderPass(device, p.render_pass, nullptr);
  }
  meshes_.clear();
  hud_vertices_.reset();
  hud_indices_.reset();
  skin_vertices_.reset();
  vkDestroyFence(device, in_flight_, nullptr);
  vkDestroyCommandPool(device, pool_, nullptr);
  vkDestroyPipelineLayout(device, lit_layout_, nullptr);
  vkDestroyPipelineLayout(device, hud_layout_, nullptr);
  for (VkShaderModule m : {lit_vert_, lit_frag_, hud_vert_, hud_frag_}) vkDestroyShaderModule(device, m, nullptr);
}

Result<MeshId> Renderer::upload(const MeshData& mesh) {
  if (auto s = mesh.validate(); !s) return s.error();
  if (mesh.indices.empty()) return make_error(Errc::invalid_argument, "mesh '" + mesh.name + "' has no triangles");
  GpuMesh gpu;
  auto vb = context_.upload_buffer(mesh.vertices.data(), mesh.vertices.size() * sizeof(Vertex),
                                   VK_BUFFER_USAGE_VERTEX_BUFFER_BIT);
  if (!vb) return vb.error().with_context("uploading mesh '" + mesh.name + "'");
  auto ib = context_.upload_buffer(mesh.indices.data(), mesh.indices.size() * sizeof(std::uint32_t),
                                   VK_BUFFER_USAGE_INDEX_BUFFER_BIT);
  if (!ib) return ib.error().with_context("uploading mesh '" + mesh.name + "'");
  gpu.vertices = std::move(vb).value();
  gpu.indices = std::move(ib).value();
  gpu.index_count = static_cast<std::uint32_t>(mesh.indices.size());
  meshes_.push_back(std::move(gpu));
  return static_cast<MeshId>(meshes_.size() - 1);
}

Result<MeshId> Renderer::upload_skinned(const SkinnedMeshData& mesh) {
  if (auto s = mesh.validate(); !s) return s.error();
  return upload_cpu_posed(mesh.name, mesh.vertices, mesh.indices, mesh.joint_names.size());
}

Result<MeshId> Renderer::upload_deforming(const MeshData& mesh) {
  if (auto s = mesh.validate(); !s) return s.error();
  std::vector<SkinnedVertex> source(mesh.vertices.size());
  for (std::size_t i = 0; i < source.size(); ++i) source[i].position = mesh.vertices[i].position;
  return upload_cpu_posed(mesh.name, std::move(source), mesh.indices, 0);
}

Result<MeshId> Renderer::upload_cpu_posed(const std::string& name, std::vector<SkinnedVertex> source,
                                          const std::vector<std::uint32_t>& triangles, std::size_t joint_count) {
  if (triangles.empty()) return make_error(Errc::invalid_argument, "mesh '" + name + "' has no triangles");
  if (source.size() > options_.max_skinned_vertices) {
    return make_error(Errc::out_of_range,
                      fmt::format("mesh '{}' has {} vertices, more than the renderer's {} skinned and deforming "
                                  "vertices per frame (RendererOptions::max_skinned_vertices)",
                                  name, source.size(), options_.max_skinned_vertices));
  }
  std::vector<std::uint32_t> indices = triangles;
  for (std::size_t t = 0; t < triangles.size(); t += 3) {
    indices.insert(indices.end(), {triangles[t], triangles[t + 2], triangles[t + 1]});
  }
  auto ib = context_.upload_buffer(indices.data(), indices.size() * sizeof(std::uint32_t),
                                   VK_BUFFER_USAGE_INDEX_BUFFER_BIT);
  if (!ib) return ib.error().with_context("uploading mesh '" + name + "'");
  GpuMesh gpu;
  gpu.indices = std::move(ib).value();
  gpu.index_count = static_cast<std::uint32_t>(triangles.size());
  gpu.skinned = true;
  gpu.skin_source = std::move(source);
  gpu.joint_count = joint_count;
  meshes_.push_back(std::move(gpu));
  return static_cast<MeshId>(meshes_.size() - 1);
}

VkRenderPass Renderer::render_pass(std::size_t pass) const noexcept { return passes_[pass].render_pass; }
std::size_t Renderer::mesh_count() const noexcept { return meshes_.size(); }

Result<std::size_t> Renderer::pass_for(VkFormat color_format, VkImageLayout final_layout) {
  for (std::size_t i = 0; i < passes_.size(); ++i) {
    if (passes_[i].color_format == color_format && passes_[i].final_layout == final_layout) return i;
  }
  const VkDevice device = context_.device();
  Pass pass;
  pass.color_format = color_format;
  pass.final_layout = final_layout;

  VkAttachmentDescription attachments[2]{};
  attachments[0].format = color_format;
  attachments[0].samples = VK_SAMPLE_COUNT_1_BIT;
  attachments[0].loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
  attachments[0].storeOp = VK_ATTACHMENT_STORE_OP_STORE;
  attachments[0].stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
  attachments[0].stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  attachments[0].initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  attachments[0].finalLayout = final_layout;
  attachments[1] = attachments[0];
  attachments[1].format = context_.depth_format();
  attachments[1].storeOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  attachments[1].finalLayout = VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL;
  VkAttachmentReference color_ref{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
  VkAttachmentReference depth_ref{1, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL};
  VkSubpassDescription subpass{};
  subpass.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  subpass.colorAttachmentCount = 1;
  subpass.pColorAttachments = &color_ref;
  subpass.pDepthStencilAttachment = &depth_ref;
  // In: earlier passes (the other eye shares the depth buffer; a read-back or
  // a present may still read the colour image). Out: a read-back copies it.
  VkSubpassDependency deps[2]{};
  deps[0].srcSubpass = VK_SUBPASS_EXTERNAL;
  deps[0].dstSubpass = 0;
  deps[0].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT | VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT |
                         VK_PIPELINE_STAGE_TRANSFER_BIT;
  deps[0].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT;
  deps[0].dstStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT |
                         VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT;
  deps[0].dstAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT | VK_ACCESS_COLOR_ATTACHMENT_READ_BIT |
                          VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT;
  deps[1].srcSubpass = 0;
  deps[1].dstSubpass = VK_SUBPASS_EXTERNAL;
  deps[1].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[1].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[1].dstStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
  deps[1].dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;
  VkRenderPassCreateInfo rp{VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO};
  rp.attachmentCount = 2;
  rp.pAttachments = attachments;
  rp.subpassCount = 1;
  rp.pSubpasses = &subpass;
  rp.dependencyCount = 2;
  rp.pDependencies = deps;
  if (VkResult r = vkCreateRenderPass(device, &rp, nullptr, &pass.render_pass); r != VK_SUCCESS) {
    return vk_error("vkCreateRenderPass", r);
  }

  // Shared pipeline state.
  VkPipelineInputAssemblyStateCreateInfo assembly{VK_STRUCTURE_TYPE_PIPELINE_INPUT_ASSEMBLY_STATE_CREATE_INFO};
  assembly.topology = VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST;
  VkPipelineViewportStateCreateInfo viewport{VK_STRUCTURE_TYPE_PIPELINE_VIEWPORT_STATE_CREATE_INFO};
  viewport.viewportCount = 1;
  viewport.scissorCount = 1;
  VkPipelineRasterizationStateCreateInfo raster{VK_STRUCTURE_TYPE_PIPELINE_RASTERIZATION_STATE_CREATE_INFO};
  raster.polygonMode = VK_POLYGON_MODE_FILL;
  raster.cullMode = VK_CULL_MODE_NONE;  // open meshes (the half cylinder seen from below) stay visible
  raster.frontFace = VK_FRONT_FACE_COUNTER_CLOCKWISE;
  raster.lineWidth = 1.0f;
  VkPipelineMultisampleStateCreateInfo multisample{VK_STRUCTURE_TYPE_PIPELINE_MULTISAMPLE_STATE_CREATE_INFO};
  multisample.rasterizationSamples = VK_SAMPLE_COUNT_1_BIT;
  VkPipelineColorBlendAttachmentState blend{};
  blend.blendEnable = VK_TRUE;
  blend.srcColorBlendFactor = VK_BLEND_FACTOR_SRC_ALPHA;
  blend.dstColorBlendFactor = VK_BLEND_FACTOR_ONE_MINUS_SRC_ALPHA;
  blend.colorBlendOp = VK_BLEND_OP_ADD;
  blend.srcAlphaBlendFactor = VK_BLEND_FACTOR_ONE;
  blend.dstAlphaBlendFactor = VK_BLEND_FACTOR_ONE_MINUS_SRC_ALPHA;
  blend.alphaBlendOp = VK_BLEND_OP_ADD;
  blend.colorWriteMask = VK_COLOR_COMPONENT_R_BIT | VK_COLOR_COMPONENT_G_BIT | VK_COLOR_COMPONENT_B_BIT |
                         VK_COLOR_COMPONENT_A_BIT;
  VkPipelineColorBlendStateCreateInfo blending{VK_STRUCTURE_TYPE_PIPELINE_COLOR_BLEND_STATE_CREATE_INFO};
  blending.attachmentCount = 1;
  blending.pAttachments = &blend;
  const VkDynamicState dynamic_states[] = {VK_DYNAMIC_STATE_VIEWPORT, VK_DYNAMIC_STATE_SCISSOR};
  VkPipelineDynamicStateCreateInfo dynamic{VK_STRUCTURE_TYPE_PIPELINE_DYNAMIC_STATE_CREATE_INFO};
  dynamic.dynamicStateCount = 2;
  dynamic.pDynamicStates = dynamic_states;

  auto make_pipeline = [&](VkShaderModule vert, VkShaderModule frag, VkPipelineLayout layout,
                           const VkPipelineVertexInputStateCreateInfo& input, bool depth,
                           VkPipeline& out) -> Status {
    VkPipelineShaderStageCreateInfo stages[2]{};
    stages[0].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    stages[0].stage = VK_SHADER_STAGE_VERTEX_BIT;
    stages[0].module = vert;
    stages[0].pName = "main";
    stages[1] = stages[0];
    stages[1].stage = VK_SHADER_STAGE_FRAGMENT_BIT;
    stages[1].module = frag;
    VkPipelineDepthStencilStateCreateInfo depth_state{VK_STRUCTURE_TYPE_PIPELINE_DEPTH_STENCIL_STATE_CREATE_INFO};
    depth_state.depthTestEnable = depth ? VK_TRUE : VK_FALSE;
    depth_state.depthWriteEnable = depth ? VK_TRUE : VK_FALSE;
    depth_state.depthCompareOp = VK_COMPARE_OP_LESS;
    VkGraphicsPipelineCreateInfo info{VK_STRUCTURE_TYPE_GRAPHICS_PIPELINE_CREATE_INFO};
    info.stageCount = 2;
    info.pStages = stages;
    info.pVertexInputState = &input;
    info.pInputAssemblyState = &assembly;
    info.pViewportState = &viewport;
    info.pRasterizationState = &raster;
    info.pMultisampleState = &multisample;
    info.pDepthStencilState = &depth_state;
    info.pColorBlendState = &blending;
    info.pDynamicState = &dynamic;
    info.layout = layout;
    info.renderPass = pass.render_pass;
    if (VkResult r = vkCreateGraphicsPipelines(device, VK_NULL_HANDLE, 1, &info, nullptr, &out); r != VK_SUCCESS) {
      return vk_error("vkCreateGraphicsPipelines", r);
    }
    return {};
  };

  VkVertexInputBindingDescription lit_binding{0, sizeof(Vertex), VK_VERTEX_INPUT_RATE_VERTEX};
  VkVertexInputAttributeDescription lit_attributes[2] = {
      {0, 0, VK_FORMAT_R32G32B32_SFLOAT, offsetof(Vertex, position)},
      {1, 0, VK_FORMAT_R32G32B32_SFLOAT, offsetof(Vertex, normal)}};
  VkPipelineVertexInputStateCreateInfo lit_input{VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO};
  lit_input.vertexBindingDescriptionCount = 1;
  lit_input.pVertexBindingDescriptions = &lit_binding;
  lit_input.vertexAttributeDescriptionCount = 2;
  lit_input.pVertexAttributeDescriptions = lit_attributes;
  if (auto s = make_pipeline(lit_vert_, lit_frag_, lit_layout_, lit_input, true, pass.lit); !s) return s.error();

  VkVertexInputBindingDescription hud_binding{0, sizeof(HudVertex), VK_VERTEX_INPUT_RATE_VERTEX};
  VkVertexInputAttributeDescription hud_attributes[2] = {
      {0, 0, VK_FORMAT_R32G32_SFLOAT, offsetof(HudVertex, position_px)},
      {1, 0, VK_FORMAT_R8G8B8A8_UNORM, offsetof(HudVertex, rgba)}};
  VkPipelineVertexInputStateCreateInfo hud_input = lit_input;
  hud_input.pVertexBindingDescriptions = &hud_binding;
  hud_input.pVertexAttributeDescriptions = hud_attributes;
  if (auto s = make_pipeline(hud_vert_, hud_frag_, hud_layout_, hud_input, false, pass.hud); !s) return s.error();

  passes_.push_back(pass);
  return passes_.size() - 1;
}

// Writes the overlay's quads into the mapped vertex buffer; returns the quad count.
std::uint32_t Renderer::fill_hud(const DrawList& draws, std::size_t& vertex_count) {
  auto* out = static_cast<HudVertex*>(hud_vertices_.mapped);
  const std::size_t capacity = hud_vertices_.size / sizeof(HudVertex);
  vertex_count = 0;
  auto push_quad = [&](glm::vec2 a, glm::vec2 b, const std::uint8_t rgba[4]) {
    if (vertex_count + 4 > capacity) return;
    const glm::vec2 corners[4] = {a, {b.x, a.y}, b, {a.x, b.y}};
    for (const auto& c : corners) {
      out[vertex_count] = HudVertex{c, {rgba[0], rgba[1], rgba[2], rgba[3]}};
      ++vertex_count;
    }
  };
  for (const HudText& t : draws.hud) {
    if (t.text.empty()) continue;
    // stb_easy_font takes char*; it does not write to it.
    char* text = const_cast<char*>(t.text.c_str());
    const std::uint8_t rgba[4] = {to_u8(t.color.r), to_u8(t.color.g), to_u8(t.color.b), to_u8(t.color.a)};
    if (t.panel) {
      const glm::vec2 size(static_cast<float>(stb_easy_font_width(text)), static_cast<float>(stb_easy_font_height(text)));
      const std::uint8_t dark[4] = {10, 10, 14, 190};
      push_quad(t.position_px - kPanelMarginPx, t.position_px + size * t.scale + kPanelMarginPx, dark);
    }
    unsigned char white[4] = {255, 255, 255, 255};
    const int quads = stb_easy_font_print(0.0f, 0.0f, text, white, hud_scratch_.data(),
                                          static_cast<int>(hud_scratch_.size()));
    for (int q = 0; q < quads && vertex_count + 4 <= capacity; ++q) {
      for (int k = 0; k < 4; ++k) {
        float xy[2];
        std::memcpy(xy, hud_scratch_.data() + (static_cast<std::size_t>(q) * 4 + static_cast<std::size_t>(k)) *
                                                   kEasyFontVertexBytes,
                    sizeof xy);
        out[vertex_count] = HudVertex{t.position_px + glm::vec2(xy[0], xy[1]) * t.scale,
                                      {rgba[0], rgba[1], rgba[2], rgba[3]}};
        ++vertex_count;
      }
    }
  }
  return static_cast<std::uint32_t>(vertex_count / 4);
}

std::size_t Renderer::fill_skinned(const DrawList& draws) {
  auto* out = static_cast<Vertex*>(skin_vertices_.mapped);
  std::size_t used = 0;
  for (const SkinnedDrawItem& item : draws.skinned) {
    const GpuMesh& mesh = meshes_[item.mesh];
    const std::size_t n = mesh.skin_source.size();
    if (used + n > options_.max_skinned_vertices) {
      ++stats_.skinned_draws_dropped;
      continue;
    }
    if (item.first_posed_vertex != SkinnedDrawItem::kSkinned) {
      std::copy_n(draws.posed_vertices.begin() + item.first_posed_vertex, n, out + used);
    } else {
      skin_vertices(mesh.skin_source, std::span(draws.skin_matrices).subspan(item.first_matrix, mesh.joint_count),
                    std::span(out + used, n));
    }
    used += n;
  }
  return used;
}

Status Renderer::render(const DrawList& draws, std::span<const View> views, std::span<const ViewTarget> targets,
                        const FrameSync& sync) {
  if (views.size() != targets.size() || views.empty()) {
    return make_error(Errc::invalid_argument, fmt::format("render: {} views but {} targets", views.size(),
                                                          targets.size()));
  }
  for (std::size_t i = 0; i < draws.items.size(); ++i) {
    if (draws.items[i].mesh >= meshes_.size()) {
      return make_error(Errc::invalid_argument, fmt::format("render: draw item {} names mesh {}, but only {} are "
                                                            "uploaded", i, draws.items[i].mesh, meshes_.size()));
    }
    if (meshes_[draws.items[i].mesh].skinned) {
      return make_error(Errc::invalid_argument, fmt::format("render: draw item {} names skinned mesh {}; draw it "
                                                            "through DrawList::skinned", i, draws.items[i].mesh));
    }
  }
  for (std::size_t i = 0; i < draws.skinned.size(); ++i) {
    const SkinnedDrawItem& item = draws.skinned[i];
    if (item.mesh >= meshes_.size() || !meshes_[item.mesh].skinned) {
      return make_error(Errc::invalid_argument, fmt::format("render: skinned draw {} names mesh {}, which is not a "
                                                            "skinned mesh (Renderer::upload_skinned)", i, item.mesh));
    }
    if (item.first_posed_vertex != SkinnedDrawItem::kSkinned) {
      if (std::size_t{item.first_posed_vertex} + meshes_[item.mesh].skin_source.size() > draws.posed_vertices.size()) {
        return make_error(Errc::invalid_argument,
                          fmt::format("render: deforming draw {} needs posed vertices {} to {}, but the draw list has "
                                      "{}", i, item.first_posed_vertex,
                                      std::size_t{item.first_posed_vertex} + meshes_[item.mesh].skin_source.size(),
                                      draws.posed_vertices.size()));
      }
      continue;
    }
    if (item.first_matrix + meshes_[item.mesh].joint_count > draws.skin_matrices.size()) {
      return make_error(Errc::invalid_argument,
                        fmt::format("render: skinned draw {} needs skin matrices {} to {}, but the draw list has {}", i,
                                    item.first_matrix, item.first_matrix + meshes_[item.mesh].joint_count,
                                    draws.skin_matrices.size()));
    }
  }
  for (const auto& t : targets) {
    if (!t.set || t.index >= t.set->size()) return make_error(Errc::invalid_argument, "render: bad view target");
  }
  if (auto s = wait_idle(); !s) return s;
  const VkDevice device = context_.device();
  vkResetFences(device, 1, &in_flight_);

  std::size_t hud_vertex_count = 0;
  const std::uint32_t hud_quads = fill_hud(draws, hud_vertex_count);
  const std::size_t skinned_vertices = fill_skinned(draws);

  vkResetCommandBuffer(cmd_, 0);
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  vkBeginCommandBuffer(cmd_, &begin);
  for (std::size_t v = 0; v < views.size(); ++v) {
    const FramebufferSet& set = *targets[v].set;
    const Pass& pass = passes_[set.pass_index()];
    const VkExtent2D extent = set.extent();
    VkClearValue clears[2];
    clears[0].color = {{draws.clear_color.r, draws.clear_color.g, draws.clear_color.b, draws.clear_color.a}};
    clears[1].depthStencil = {1.0f, 0};
    VkRenderPassBeginInfo rp{VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO};
    rp.renderPass = pass.render_pass;
    rp.framebuffer = set.framebuffer(targets[v].index);
    rp.renderArea = {{0, 0}, extent};
    rp.clearValueCount = 2;
    rp.pClearValues = clears;
    vkCmdBeginRenderPass(cmd_, &rp, VK_SUBPASS_CONTENTS_INLINE);
    const VkViewport viewport{0, 0, static_cast<float>(extent.width), static_cast<float>(extent.height), 0, 1};
    const VkRect2D scissor{{0, 0}, extent};
    vkCmdSetViewport(cmd_, 0, 1, &viewport);
    vkCmdSetScissor(cmd_, 0, 1, &scissor);

    const glm::mat4 clip_from_world =
        projection(views[v].fov, options_.near_m, options_.far_m) * view_matrix(views[v]);
    vkCmdBindPipeline(cmd_, VK_PIPELINE_BIND_POINT_GRAPHICS, pass.lit);
    for (const DrawItem& item : draws.items) {
      const GpuMesh& mesh = meshes_[item.mesh];
      LitPush push;
      push.clip_from_object = clip_from_world * item.T_world_object;
      const glm::mat4 rows = glm::transpose(item.T_world_object);  // row i of M is column i of M^T
      push.world_rows[0] = rows[0];
      push.world_rows[1] = rows[1];
      push.world_rows[2] = rows[2];
      push.color = item.color;
      vkCmdPushConstants(cmd_, lit_layout_, VK_SHADER_STAGE_VERTEX_BIT, 0, sizeof push, &push);
      const VkDeviceSize offset = 0;
      vkCmdBindVertexBuffers(cmd_, 0, 1, &mesh.vertices.buffer, &offset);
      vkCmdBindIndexBuffer(cmd_, mesh.indices.buffer, 0, VK_INDEX_TYPE_UINT32);
      vkCmdDrawIndexed(cmd_, mesh.index_count, 1, 0, 0, 0);
    }
    // Skinned meshes, already in world space, in the order fill_skinned wrote them.
    std::size_t skinned_offset = 0;
    for (const SkinnedDrawItem& item : draws.skinned) {
      const GpuMesh& mesh = meshes_[item.mesh];
      if (skinned_offset + mesh.skin_source.size() > options_.max_skinned_vertices) continue;  // dropped
      LitPush push;
      push.clip_from_object = clip_from_world;
      push.world_rows[0] = glm::vec4(1, 0, 0, 0);
      push.world_rows[1] = glm::vec4(0, 1, 0, 0);
      push.world_rows[2] = glm::vec4(0, 0, 1, 0);
      push.color = item.color;
      vkCmdPushConstants(cmd_, lit_layout_, VK_SHADER_STAGE_VERTEX_BIT, 0, sizeof push, &push);
      const VkDeviceSize offset = skinned_offset * sizeof(Vertex);
      vkCmdBindVertexBuffers(cmd_, 0, 1, &skin_vertices_.buffer, &offset);
      vkCmdBindIndexBuffer(cmd_, mesh.indices.buffer, 0, VK_INDEX_TYPE_UINT32);
      // A mirrored skin (negative determinant) turns the triangles inside
      // out; the reversed copy keeps their front faces outside, which the
      // lighting's gl_FrontFacing relies on.
      const bool mirrored = item.first_posed_vertex == SkinnedDrawItem::kSkinned && mesh.joint_count > 0 &&
                            glm::determinant(glm::mat3(draws.skin_matrices[item.first_matrix])) < 0.0f;
      vkCmdDrawIndexed(cmd_, mesh.index_count, 1, mirrored ? mesh.index_count : 0, 0, 0);
      skinned_offset += mesh.skin_source.size();
    }
    if (hud_quads > 0) {
      vkCmdBindPipeline(cmd_, VK_PIPELINE_BIND_POINT_GRAPHICS, pass.hud);
      const glm::vec2 size(static_cast<float>(extent.width), static_cast<float>(extent.height));
      vkCmdPushConstants(cmd_, hud_layout_, VK_SHADER_STAGE_VERTEX_BIT, 0, sizeof size, &size);
      const VkDeviceSize offset = 0;
      vkCmdBindVertexBuffers(cmd_, 0, 1, &hud_vertices_.buffer, &offset);
      vkCmdBindIndexBuffer(cmd_, hud_indices_.buffer, 0, VK_INDEX_TYPE_UINT32);
      vkCmdDrawIndexed(cmd_, hud_quads * 6, 1, 0, 0, 0);
    }
    vkCmdEndRenderPass(cmd_);
  }
  vkEndCommandBuffer(cmd_);

  const VkPipelineStageFlags wait_stage = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.waitSemaphoreCount = sync.wait ? 1 : 0;
  submit.pWaitSemaphores = &sync.wait;
  submit.pWaitDstStageMask = &wait_stage;
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &cmd_;
  submit.signalSemaphoreCount = sync.signal ? 1 : 0;
  submit.pSignalSemaphores = &sync.signal;
  if (VkResult r = vkQueueSubmit(context_.queue(), 1, &submit, in_flight_); r != VK_SUCCESS) {
    return vk_error("vkQueueSubmit", r);
  }
  submitted_ = true;
  ++stats_.frames;
  stats_.draws_last_frame = draws.items.size() + draws.skinned.size();
  stats_.skinned_vertices_last_frame = skinned_vertices;
  return {};
}

Status Renderer::wait_idle() {
  if (!submitted_) return {};
  if (VkResult r = vkWaitForFences(context_.device(), 1, &in_flight_, VK_TRUE, UINT64_MAX); r != VK_SUCCESS) {
    return vk_error("vkWaitForFences", r);
  }
  submitted_ = false;
  return {};
}

// --- FramebufferSet ---

Result<std::unique_ptr<FramebufferSet>> FramebufferSet::create(Renderer& renderer, std::span<const VkImage> images,
                                                               VkFormat color_format, VkExtent2D extent,
                                                               VkImageLayout final_layout) {
  if (images.empty() || extent.width == 0 || extent.height == 0) {
    return make_error(Errc::invalid_argument, "framebuffer set: no images or an empty extent");
  }
  auto pass = renderer.pass_for(color_format, final_layout);
  if (!pass) return pass.error();
  const VulkanContext& ctx = renderer.context();
  std::unique_ptr<FramebufferSet> set(new FramebufferSet());
  set->device_ = ctx.device();
  set->extent_ = extent;
  set->color_format_ = color_format;
  set->final_layout_ = final_layout;
  set->pass_ = *pass;
  set->images_.assign(images.begin(), images.end());
  auto depth = ctx.create_image(extent, ctx.depth_format(), VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT,
                                VK_IMAGE_ASPECT_DEPTH_BIT);
  if (!depth) return depth.error();
  set->depth_ = std::move(depth).value();
  for (VkImage image : images) {
    auto view = ctx.create_view(image, color_format, VK_IMAGE_ASPECT_COLOR_BIT);
    if (!view) return view.error();
    set->views_.push_back(*view);
    const VkImageView attachments[2] = {*view, set->depth_.view};
    VkFramebufferCreateInfo info{VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO};
    info.renderPass = renderer.render_pass(*pass);
    info.attachmentCount = 2;
    info.pAttachments = attachments;
    info.width = extent.width;
    info.height = extent.height;
    info.layers = 1;
    VkFramebuffer fb = VK_NULL_HANDLE;
    if (VkResult r = vkCreateFramebuffer(set->device_, &info, nullptr, &fb); r != VK_SUCCESS) {
      return vk_error("vkCreateFramebuffer", r);
    }
    set->framebuffers_.push_back(fb);
  }
  return set;
}

FramebufferSet::~FramebufferSet() {
  for (VkFramebuffer fb : framebuffers_) vkDestroyFramebuffer(device_, fb, nullptr);
  for (VkImageView v : views_) vkDestroyImageView(device_, v, nullptr);
}

}  // namespace proprio::render
