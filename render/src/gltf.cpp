// glTF through tinygltf (Debian ships it as a shared library, so no
// TINYGLTF_IMPLEMENTATION here).
#include <fmt/format.h>
#include <tiny_gltf.h>

#include <cstddef>
#include <cstring>
#include <optional>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>

#include "gltf_write.hpp"
#include "mesh_normals.hpp"
#include "proprio/render/mesh.hpp"

namespace proprio::render {
namespace {

// Reads accessor element i as `count` floats (positions, normals) or as an index.
struct AccessorView {
  const unsigned char* data = nullptr;
  std::size_t stride = 0;
  std::size_t count = 0;
  int component_type = 0;
};

Result<AccessorView> view_of(const tinygltf::Model& model, int accessor_index, int expected_type,
                             const std::string& what) {
  if (accessor_index < 0 || static_cast<std::size_t>(accessor_index) >= model.accessors.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: accessor {} does not exist", what, accessor_index));
  }
  const auto& acc = model.accessors[static_cast<std::size_t>(accessor_index)];
  if (acc.type != expected_type || acc.bufferView < 0 ||
      static_cast<std::size_t>(acc.bufferView) >= model.bufferViews.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: accessor {} has an unexpected type or no buffer view", what,
                                                     accessor_index));
  }
  const auto& bv = model.bufferViews[static_cast<std::size_t>(acc.bufferView)];
  if (bv.buffer < 0 || static_cast<std::size_t>(bv.buffer) >= model.buffers.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: buffer view {} has no buffer", what, acc.bufferView));
  }
  const auto& buffer = model.buffers[static_cast<std::size_t>(bv.buffer)];
  AccessorView v;
  v.component_type = acc.componentType;
  v.count = acc.count;
  const std::size_t element = static_cast<std::size_t>(tinygltf::GetComponentSizeInBytes(acc.componentType)) *
                              static_cast<std::size_t>(tinygltf::GetNumComponentsInType(acc.type));
  v.stride = bv.byteStride ? bv.byteStride : element;
  const std::size_t start = bv.byteOffset + acc.byteOffset;
  if (acc.count > 0 && (start + v.stride * (acc.count - 1) + element > buffer.data.size() ||
                        bv.byteOffset + bv.byteLength > buffer.data.size())) {
    return make_error(Errc::parse_error, fmt::format("{}: accessor {} reads past the end of its buffer", what,
                                                     accessor_index));
  }
  v.data = buffer.data.data() + start;
  return v;
}

glm::mat4 node_matrix(const tinygltf::Node& node) {
  if (node.matrix.size() == 16) {
    glm::dmat4 m = glm::make_mat4(node.matrix.data());
    return glm::mat4(m);
  }
  glm::mat4 t(1.0f), r(1.0f), s(1.0f);
  if (node.translation.size() == 3) {
    t[3] = glm::vec4(static_cast<float>(node.translation[0]), static_cast<float>(node.translation[1]),
                     static_cast<float>(node.translation[2]), 1.0f);
  }
  if (node.rotation.size() == 4) {  // glTF: x, y, z, w
    r = glm::mat4_cast(glm::quat(static_cast<float>(node.rotation[3]), static_cast<float>(node.rotation[0]),
                                 static_cast<float>(node.rotation[1]), static_cast<float>(node.rotation[2])));
  }
  if (node.scale.size() == 3) {
    s = glm::mat4(1.0f);
    s[0][0] = static_cast<float>(node.scale[0]);
    s[1][1] = static_cast<float>(node.scale[1]);
    s[2][2] = static_cast<float>(node.scale[2]);
  }
  return t * r * s;
}

Status append_mesh(const tinygltf::Model& model, const tinygltf::Mesh& mesh, const glm::mat4& world, MeshData& out,
                   const std::string& file) {
  const glm::mat3 normal_matrix = glm::transpose(glm::inverse(glm::mat3(world)));
  for (const auto& prim : mesh.primitives) {
    if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1) continue;  // points and lines are not drawn
    const auto pos_it = prim.attributes.find("POSITION");
    if (pos_it == prim.attributes.end()) {
      return make_error(Errc::parse_error, fmt::format("{}: mesh '{}' has a primitive without POSITION", file, mesh.name));
    }
    auto pos = view_of(model, pos_it->second, TINYGLTF_TYPE_VEC3, file);
    if (!pos) return pos.error();
    if (pos->component_type != TINYGLTF_COMPONENT_TYPE_FLOAT) {
      return make_error(Errc::unsupported, fmt::format("{}: only float positions are supported", file));
    }
    std::optional<AccessorView> nrm;
    if (auto it = prim.attributes.find("NORMAL"); it != prim.attributes.end()) {
      auto v = view_of(model, it->second, TINYGLTF_TYPE_VEC3, file);
      if (!v) return v.error();
      if (v->count != pos->count || v->component_type != TINYGLTF_COMPONENT_TYPE_FLOAT) {
        return make_error(Errc::parse_error, fmt::format("{}: NORMAL does not match POSITION", file));
      }
      nrm = *v;
    }
    const auto base = static_cast<std::uint32_t>(out.vertices.size());
    for (std::size_t i = 0; i < pos->count; ++i) {
      glm::vec3 p, n(0.0f);
      std::memcpy(&p, pos->data + i * pos->stride, sizeof p);
      if (nrm) std::memcpy(&n, nrm->data + i * nrm->stride, sizeof n);
      const glm::vec3 nw = normal_matrix * n;
      out.vertices.push_back({glm::vec3(world * glm::vec4(p, 1.0f)),
                              glm::length(nw) > 0 ? glm::normalize(nw) : glm::vec3(0.0f)});
    }
    const std::size_t first_index = out.indices.size();
    if (prim.indices >= 0) {
      auto idx = view_of(model, prim.indices, TINYGLTF_TYPE_SCALAR, file);
      if (!idx) return idx.error();
      for (std::size_t i = 0; i < idx->count; ++i) {
        const unsigned char* e = idx->data + i * idx->stride;
        std::uint32_t value = 0;
        switch (idx->component_type) {
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: value = *e; break;
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { std::uint16_t s; std::memcpy(&s, e, 2); value = s; break; }
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: std::memcpy(&value, e, 4); break;
          default: return make_error(Errc::parse_error, fmt::format("{}: index component type {}", file, idx->component_type));
        }
        if (value >= pos->count) {
          return make_error(Errc::parse_error, fmt::format("{}: index {} is past the {} vertices", file, value, pos->count));
        }
        out.indices.push_back(base + value);
      }
    } else {
      for (std::uint32_t i = 0; i < pos->count; ++i) out.indices.push_back(base + i);
    }
    if (!nrm) {  // smooth normals from the faces
      detail::accumulate_face_normals(out.vertices, out.indices, first_index);
      detail::normalise_normals(out.vertices, base);
    }
  }
  return {};
}

Status visit(const tinygltf::Model& model, int node_index, const glm::mat4& parent, MeshData& out,
             const std::string& file, int depth) {
  if (node_index < 0 || static_cast<std::size_t>(node_index) >= model.nodes.size() || depth > 64) {
    return make_error(Errc::parse_error, fmt::format("{}: bad node index {} (or a cycle)", file, node_index));
  }
  const auto& node = model.nodes[static_cast<std::size_t>(node_index)];
  const glm::mat4 world = parent * node_matrix(node);
  if (node.mesh >= 0) {
    if (static_cast<std::size_t>(node.mesh) >= model.meshes.size()) {
      return make_error(Errc::parse_error, fmt::format("{}: node {} names mesh {}", file, node_index, node.mesh));
    }
    if (auto s = append_mesh(model, model.meshes[static_cast<std::size_t>(node.mesh)], world, out, file); !s) return s;
  }
  for (int child : node.children) {
    if (auto s = visit(model, child, world, out, file, depth + 1); !s) return s;
  }
  return {};
}

}  // namespace

Result<MeshData> load_gltf(const std::filesystem::path& file) {
  tinygltf::Model model;
  if (auto s = detail::read_gltf_file(model, file); !s) return s.error();
  MeshData mesh;
  mesh.name = file.stem().string();
  const std::string name = file.string();
  if (!model.scenes.empty()) {
    const std::size_t scene = model.defaultScene >= 0 ? static_cast<std::size_t>(model.defaultScene) : 0;
    if (scene >= model.scenes.size()) return make_error(Errc::parse_error, name + ": default scene does not exist");
    for (int n : model.scenes[scene].nodes) {
      if (auto s = visit(model, n, glm::mat4(1.0f), mesh, name, 0); !s) return s.error();
    }
  } else {
    for (const auto& m : model.meshes) {
      if (auto s = append_mesh(model, m, glm::mat4(1.0f), mesh, name); !s) return s.error();
    }
  }
  if (mesh.indices.empty()) return make_error(Errc::parse_error, name + ": no triangles");
  if (auto s = mesh.validate(); !s) return s.error().with_context(name);
  return mesh;
}

Status save_gltf(const MeshData& mesh, const std::filesystem::path& file) {
  if (auto s = mesh.validate(); !s) return s;
  tinygltf::Model model;
  tinygltf::Buffer buffer;
  const std::size_t vertex_bytes = mesh.vertices.size() * sizeof(Vertex);
  const std::size_t index_bytes = mesh.indices.size() * sizeof(std::uint32_t);
  buffer.data.resize(vertex_bytes + index_bytes);
  std::memcpy(buffer.data.data(), mesh.vertices.data(), vertex_bytes);
  std::memcpy(buffer.data.data() + vertex_bytes, mesh.indices.data(), index_bytes);
  model.buffers.push_back(std::move(buffer));

  tinygltf::BufferView vertices;
  vertices.buffer = 0;
  vertices.byteLength = vertex_bytes;
  vertices.byteStride = sizeof(Vertex);
  vertices.target = TINYGLTF_TARGET_ARRAY_BUFFER;
  tinygltf::BufferView indices;
  indices.buffer = 0;
  indices.byteOffset = vertex_bytes;
  indices.byteLength = index_bytes;
  indices.target = TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER;
  model.bufferViews = {vertices, indices};

  const glm::vec3 lo = mesh.bounds_min(), hi = mesh.bounds_max();
  tinygltf::Accessor positions;
  positions.bufferView = 0;
  positions.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
  positions.count = mesh.vertices.size();
  positions.type = TINYGLTF_TYPE_VEC3;
  positions.minValues = {lo.x, lo.y, lo.z};
  positions.maxValues = {hi.x, hi.y, hi.z};
  tinygltf::Accessor normals = positions;
  normals.byteOffset = offsetof(Vertex, normal);
  normals.minValues.clear();
  normals.maxValues.clear();
  tinygltf::Accessor index_accessor;
  index_accessor.bufferView = 1;
  index_accessor.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
  index_accessor.count = mesh.indices.size();
  index_accessor.type = TINYGLTF_TYPE_SCALAR;
  model.accessors = {positions, normals, index_accessor};

  tinygltf::Primitive prim;
  prim.attributes["POSITION"] = 0;
  prim.attributes["NORMAL"] = 1;
  prim.indices = 2;
  prim.mode = TINYGLTF_MODE_TRIANGLES;
  tinygltf::Mesh m;
  m.name = mesh.name;
  m.primitives.push_back(prim);
  model.meshes.push_back(m);
  tinygltf::Node node;
  node.mesh = 0;
  model.nodes.push_back(node);
  tinygltf::Scene scene;
  scene.nodes.push_back(0);
  model.scenes.push_back(scene);
  return detail::write_gltf_file(model, file);
}

}  // namespace proprio::render
