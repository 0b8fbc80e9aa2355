// Skinned meshes: glTF load/save through tinygltf (Debian's shared library,
// so no TINYGLTF_IMPLEMENTATION here) and linear-blend skinning on the CPU.
#include <fmt/format.h>
#include <tiny_gltf.h>

#include <cmath>
#include <cstring>
#include <optional>

#include <glm/gtc/type_ptr.hpp>

#include "gltf_write.hpp"
#include "mesh_normals.hpp"
#include "proprio/render/skinned_mesh.hpp"

namespace proprio::render {
namespace {

static_assert(sizeof(SkinnedVertex) == 48, "SkinnedVertex is written to glTF interleaved, without padding");

// One accessor's elements, read component by component.
struct SkinAccessor {
  const unsigned char* data = nullptr;
  std::size_t stride = 0;
  std::size_t count = 0;
  int component_type = 0;
  int components = 0;
  bool normalized = false;

  const unsigned char* at(std::size_t i, int k) const {
    return data + i * stride + static_cast<std::size_t>(k * tinygltf::GetComponentSizeInBytes(component_type));
  }
  // Component k of element i as a float (normalised integers map to 0-1).
  float real(std::size_t i, int k) const {
    const unsigned char* e = at(i, k);
    switch (component_type) {
      case TINYGLTF_COMPONENT_TYPE_FLOAT: { float f; std::memcpy(&f, e, 4); return f; }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return static_cast<float>(*e) / (normalized ? 255.0f : 1.0f);
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        std::uint16_t s;
        std::memcpy(&s, e, 2);
        return static_cast<float>(s) / (normalized ? 65535.0f : 1.0f);
      }
      default: return 0.0f;
    }
  }
  // Component k of element i as an unsigned integer.
  std::uint32_t integer(std::size_t i, int k) const {
    const unsigned char* e = at(i, k);
    switch (component_type) {
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return *e;
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { std::uint16_t s; std::memcpy(&s, e, 2); return s; }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: { std::uint32_t u; std::memcpy(&u, e, 4); return u; }
      default: return 0;
    }
  }
};

Result<SkinAccessor> skin_accessor(const tinygltf::Model& model, int index, int expected_type, const std::string& what) {
  if (index < 0 || static_cast<std::size_t>(index) >= model.accessors.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: accessor {} does not exist", what, index));
  }
  const auto& acc = model.accessors[static_cast<std::size_t>(index)];
  if (acc.type != expected_type) {
    return make_error(Errc::parse_error, fmt::format("{}: accessor {} has type {}, expected {}", what, index,
                                                     tinygltf::GetNumComponentsInType(acc.type),
                                                     tinygltf::GetNumComponentsInType(expected_type)));
  }
  if (acc.sparse.isSparse) {
    return make_error(Errc::unsupported, fmt::format("{}: accessor {} is sparse; sparse accessors are not supported",
                                                     what, index));
  }
  if (acc.bufferView < 0 || static_cast<std::size_t>(acc.bufferView) >= model.bufferViews.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: accessor {} has no buffer view", what, index));
  }
  const int component_bytes = tinygltf::GetComponentSizeInBytes(static_cast<std::uint32_t>(acc.componentType));
  if (component_bytes <= 0) {
    return make_error(Errc::parse_error, fmt::format("{}: accessor {} has component type {}", what, index,
                                                     acc.componentType));
  }
  const auto& bv = model.bufferViews[static_cast<std::size_t>(acc.bufferView)];
  if (bv.buffer < 0 || static_cast<std::size_t>(bv.buffer) >= model.buffers.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: buffer view {} has no buffer", what, acc.bufferView));
  }
  const auto& buffer = model.buffers[static_cast<std::size_t>(bv.buffer)];
  SkinAccessor v;
  v.component_type = acc.componentType;
  v.components = tinygltf::GetNumComponentsInType(static_cast<std::uint32_t>(acc.type));
  v.count = acc.count;
  v.normalized = acc.normalized;
  const std::size_t element = static_cast<std::size_t>(component_bytes) * static_cast<std::size_t>(v.components);
  v.stride = bv.byteStride ? bv.byteStride : element;
  const std::size_t start = bv.byteOffset + acc.byteOffset;
  if (bv.byteOffset + bv.byteLength > buffer.data.size() ||
      (acc.count > 0 && start + v.stride * (acc.count - 1) + element > bv.byteOffset + bv.byteLength)) {
    return make_error(Errc::parse_error, fmt::format("{}: accessor {} reads past the end of its buffer view", what,
                                                     index));
  }
  v.data = buffer.data.data() + start;
  return v;
}

Result<SkinAccessor> attribute(const tinygltf::Model& model, const tinygltf::Primitive& prim, const char* name,
                               int type, const std::string& what) {
  const auto it = prim.attributes.find(name);
  if (it == prim.attributes.end()) {
    return make_error(Errc::parse_error, fmt::format("{}: the skinned primitive has no {}", what, name));
  }
  return skin_accessor(model, it->second, type, fmt::format("{} ({})", what, name));
}

Status append_skinned_primitive(const tinygltf::Model& model, const tinygltf::Primitive& prim, std::size_t joint_count,
                                SkinnedMeshData& out, const std::string& what) {
  if (prim.attributes.count("JOINTS_1") || prim.attributes.count("WEIGHTS_1")) {
    return make_error(Errc::unsupported,
                      fmt::format("{}: the mesh has JOINTS_1/WEIGHTS_1, i.e. more than {} joint influences per vertex; "
                                  "limit the influences to {} when exporting",
                                  what, kMaxInfluences, kMaxInfluences));
  }
  auto pos = attribute(model, prim, "POSITION", TINYGLTF_TYPE_VEC3, what);
  if (!pos) return pos.error();
  if (pos->component_type != TINYGLTF_COMPONENT_TYPE_FLOAT) {
    return make_error(Errc::unsupported, fmt::format("{}: POSITION must be float", what));
  }
  auto joints = attribute(model, prim, "JOINTS_0", TINYGLTF_TYPE_VEC4, what);
  if (!joints) return joints.error();
  auto weights = attribute(model, prim, "WEIGHTS_0", TINYGLTF_TYPE_VEC4, what);
  if (!weights) return weights.error();
  if (joints->component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
      joints->component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) {
    return make_error(Errc::unsupported,
                      fmt::format("{}: JOINTS_0 must be unsigned byte or short, not component type {}", what,
                                  joints->component_type));
  }
  const bool float_weights = weights->component_type == TINYGLTF_COMPONENT_TYPE_FLOAT;
  const bool normalized_weights = (weights->component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                                   weights->component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) &&
                                  weights->normalized;
  if (!float_weights && !normalized_weights) {
    return make_error(Errc::unsupported,
                      fmt::format("{}: WEIGHTS_0 must be float or normalised unsigned byte/short", what));
  }
  std::optional<SkinAccessor> nrm;
  if (prim.attributes.count("NORMAL")) {
    auto n = attribute(model, prim, "NORMAL", TINYGLTF_TYPE_VEC3, what);
    if (!n) return n.error();
    if (n->component_type != TINYGLTF_COMPONENT_TYPE_FLOAT) {
      return make_error(Errc::unsupported, fmt::format("{}: NORMAL must be float", what));
    }
    nrm = *n;
  }
  const std::size_t n_vertices = pos->count;
  if (joints->count != n_vertices || weights->count != n_vertices || (nrm && nrm->count != n_vertices)) {
    return make_error(Errc::parse_error,
                      fmt::format("{}: POSITION has {} elements but JOINTS_0 {}, WEIGHTS_0 {}{}", what, n_vertices,
                                  joints->count, weights->count, nrm ? fmt::format(", NORMAL {}", nrm->count) : ""));
  }

  const auto base = static_cast<std::uint32_t>(out.vertices.size());
  for (std::size_t i = 0; i < n_vertices; ++i) {
    SkinnedVertex v;
    v.position = {pos->real(i, 0), pos->real(i, 1), pos->real(i, 2)};
    if (nrm) v.normal = {nrm->real(i, 0), nrm->real(i, 1), nrm->real(i, 2)};
    float sum = 0.0f;
    for (int k = 0; k < 4; ++k) {
      const std::uint32_t j = joints->integer(i, k);
      const float w = weights->real(i, k);
      if (!std::isfinite(w) || w < 0.0f) {
        return make_error(Errc::parse_error, fmt::format("{}: vertex {} has weight {} (must be >= 0)", what, i, w));
      }
      if (w > 0.0f && j >= joint_count) {
        return make_error(Errc::parse_error, fmt::format("{}: vertex {} names joint {}, but the skin has {} joints",
                                                         what, i, j, joint_count));
      }
      v.joints[static_cast<std::size_t>(k)] = static_cast<std::uint16_t>(w > 0.0f ? j : 0);
      v.weights[k] = w;
      sum += w;
    }
    if (!(sum > 1e-6f)) {
      return make_error(Errc::parse_error, fmt::format("{}: vertex {} has no joint weight", what, i));
    }
    v.weights /= sum;  // normalised integers do not sum to exactly 1
    out.vertices.push_back(v);
  }

  const std::size_t first_index = out.indices.size();
  if (prim.indices >= 0) {
    auto idx = skin_accessor(model, prim.indices, TINYGLTF_TYPE_SCALAR, what + " (indices)");
    if (!idx) return idx.error();
    if (idx->component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
        idx->component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
        idx->component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT) {
      return make_error(Errc::parse_error, fmt::format("{}: index component type {}", what, idx->component_type));
    }
    for (std::size_t i = 0; i < idx->count; ++i) {
      const std::uint32_t value = idx->integer(i, 0);
      if (value >= n_vertices) {
        return make_error(Errc::parse_error, fmt::format("{}: index {} is past the {} vertices", what, value, n_vertices));
      }
      out.indices.push_back(base + value);
    }
  } else {
    for (std::uint32_t i = 0; i < n_vertices; ++i) out.indices.push_back(base + i);
  }
  if ((out.indices.size() - first_index) % 3 != 0) {
    return make_error(Errc::parse_error, fmt::format("{}: the index count is not a multiple of 3", what));
  }
  if (!nrm) detail::accumulate_face_normals(out.vertices, out.indices, first_index);  // smooth normals from the faces
  detail::normalise_normals(out.vertices, base);
  return {};
}

}  // namespace

Status SkinnedMeshData::validate() const {
  if (indices.size() % 3 != 0) {
    return make_error(Errc::invalid_argument, fmt::format("skinned mesh '{}': {} indices, not a multiple of 3", name,
                                                          indices.size()));
  }
  if (inverse_bind.size() != joint_names.size()) {
    return make_error(Errc::invalid_argument, fmt::format("skinned mesh '{}': {} joints but {} inverse bind matrices",
                                                          name, joint_names.size(), inverse_bind.size()));
  }
  for (std::size_t i = 0; i < indices.size(); ++i) {
    if (indices[i] >= vertices.size()) {
      return make_error(Errc::invalid_argument, fmt::format("skinned mesh '{}': index {} ({}) is past the {} vertices",
                                                            name, i, indices[i], vertices.size()));
    }
  }
  for (std::size_t i = 0; i < vertices.size(); ++i) {
    const SkinnedVertex& v = vertices[i];
    bool finite = true;
    for (int k = 0; k < 3; ++k) finite = finite && std::isfinite(v.position[k]) && std::isfinite(v.normal[k]);
    float sum = 0.0f;
    for (int k = 0; k < 4; ++k) {
      const float w = v.weights[k];
      if (!std::isfinite(w) || w < 0.0f) finite = false;
      sum += w;
      if (w > 0.0f && v.joints[static_cast<std::size_t>(k)] >= joint_names.size()) {
        return make_error(Errc::invalid_argument, fmt::format("skinned mesh '{}': vertex {} names joint {} of {}", name,
                                                              i, v.joints[static_cast<std::size_t>(k)],
                                                              joint_names.size()));
      }
    }
    if (!finite) {
      return make_error(Errc::invalid_argument, fmt::format("skinned mesh '{}': vertex {} is not finite", name, i));
    }
    if (std::abs(sum - 1.0f) > 1e-3f) {
      return make_error(Errc::invalid_argument, fmt::format("skinned mesh '{}': vertex {}'s weights sum to {}, not 1",
                                                            name, i, sum));
    }
  }
  return {};
}

MeshData SkinnedMeshData::bind_pose() const {
  MeshData m;
  m.name = name;
  m.indices = indices;
  m.vertices.reserve(vertices.size());
  for (const SkinnedVertex& v : vertices) m.vertices.push_back({v.position, v.normal});
  return m;
}

void skin_vertices(std::span<const SkinnedVertex> vertices, std::span<const glm::mat4> skin, std::span<Vertex> out) {
  const std::size_t n = std::min(vertices.size(), out.size());
  for (std::size_t i = 0; i < n; ++i) {
    const SkinnedVertex& v = vertices[i];
    glm::mat4 m(0.0f);
    for (std::size_t k = 0; k < kMaxInfluences; ++k) {
      const float w = v.weights[static_cast<glm::length_t>(k)];
      if (w > 0.0f && v.joints[k] < skin.size()) m += w * skin[v.joints[k]];
    }
    const glm::vec3 normal = glm::mat3(m) * v.normal;
    const float length = glm::length(normal);
    out[i] = Vertex{glm::vec3(m * glm::vec4(v.position, 1.0f)), length > 1e-12f ? normal / length : v.normal};
  }
}

Result<SkinnedMeshData> load_skinned_gltf(const std::filesystem::path& file) {
  const std::string name = file.string();
  tinygltf::Model model;
  if (auto s = detail::read_gltf_file(model, file); !s) return s.error();
  const tinygltf::Node* skinned = nullptr;
  for (const auto& node : model.nodes) {
    if (node.mesh >= 0 && node.skin >= 0) {
      skinned = &node;
      break;
    }
  }
  if (!skinned) {
    return make_error(Errc::parse_error,
                      fmt::format("glTF file '{}' has no skinned mesh (no node with both a mesh and a skin); for a "
                                  "static mesh use load_gltf",
                                  name));
  }
  if (static_cast<std::size_t>(skinned->mesh) >= model.meshes.size() ||
      static_cast<std::size_t>(skinned->skin) >= model.skins.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: node '{}' names a mesh or skin that does not exist", name,
                                                     skinned->name));
  }
  const tinygltf::Skin& skin = model.skins[static_cast<std::size_t>(skinned->skin)];
  const tinygltf::Mesh& mesh = model.meshes[static_cast<std::size_t>(skinned->mesh)];
  SkinnedMeshData out;
  out.name = mesh.name.empty() ? file.stem().string() : mesh.name;
  if (skin.joints.empty()) return make_error(Errc::parse_error, fmt::format("{}: skin '{}' has no joints", name, skin.name));
  for (int j : skin.joints) {
    if (j < 0 || static_cast<std::size_t>(j) >= model.nodes.size()) {
      return make_error(Errc::parse_error, fmt::format("{}: skin '{}' names node {}, which does not exist", name,
                                                       skin.name, j));
    }
    out.joint_names.push_back(model.nodes[static_cast<std::size_t>(j)].name);
  }
  if (skin.inverseBindMatrices < 0) {
    return make_error(Errc::parse_error,
                      fmt::format("{}: skin '{}' has no inverseBindMatrices; Proprio drives joints from tracked poses "
                                  "and needs the bind pose",
                                  name, skin.name));
  }
  auto ibm = skin_accessor(model, skin.inverseBindMatrices, TINYGLTF_TYPE_MAT4, name + " (inverseBindMatrices)");
  if (!ibm) return ibm.error();
  if (ibm->component_type != TINYGLTF_COMPONENT_TYPE_FLOAT || ibm->count != skin.joints.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: inverseBindMatrices must be {} float mat4s, got {}", name,
                                                     skin.joints.size(), ibm->count));
  }
  for (std::size_t j = 0; j < ibm->count; ++j) {
    glm::mat4 m;
    for (int k = 0; k < 16; ++k) glm::value_ptr(m)[k] = ibm->real(j, k);  // column-major, as glTF
    out.inverse_bind.push_back(m);
  }
  for (const auto& prim : mesh.primitives) {
    if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1) continue;  // points and lines are not drawn
    if (auto s = append_skinned_primitive(model, prim, out.joint_names.size(), out,
                                          fmt::format("{}: mesh '{}'", name, mesh.name));
        !s) {
      return s.error();
    }
  }
  if (out.indices.empty()) return make_error(Errc::parse_error, name + ": the skinned mesh has no triangles");
  if (auto s = out.validate(); !s) return s.error().with_context(name);
  return out;
}

Status save_skinned_gltf(const SkinnedMeshData& mesh, const std::filesystem::path& file) {
  if (auto s = mesh.validate(); !s) return s;
  tinygltf::Model model;
  tinygltf::Buffer buffer;
  const std::size_t vertex_bytes = mesh.vertices.size() * sizeof(SkinnedVertex);
  const std::size_t index_bytes = mesh.indices.size() * sizeof(std::uint32_t);
  const std::size_t ibm_bytes = mesh.inverse_bind.size() * sizeof(glm::mat4);
  buffer.data.resize(vertex_bytes + index_bytes + ibm_bytes);
  std::memcpy(buffer.data.data(), mesh.vertices.data(), vertex_bytes);
  std::memcpy(buffer.data.data() + vertex_bytes, mesh.indices.data(), index_bytes);
  for (std::size_t j = 0; j < mesh.inverse_bind.size(); ++j) {
    std::memcpy(buffer.data.data() + vertex_bytes + index_bytes + j * sizeof(glm::mat4),
                glm::value_ptr(mesh.inverse_bind[j]), sizeof(glm::mat4));
  }
  model.buffers.push_back(std::move(buffer));

  tinygltf::BufferView vertices;
  vertices.buffer = 0;
  vertices.byteLength = vertex_bytes;
  vertices.byteStride = sizeof(SkinnedVertex);
  vertices.target = TINYGLTF_TARGET_ARRAY_BUFFER;
  tinygltf::BufferView indices;
  indices.buffer = 0;
  indices.byteOffset = vertex_bytes;
  indices.byteLength = index_bytes;
  indices.target = TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER;
  tinygltf::BufferView ibm_view;
  ibm_view.buffer = 0;
  ibm_view.byteOffset = vertex_bytes + index_bytes;
  ibm_view.byteLength = ibm_bytes;
  model.bufferViews = {vertices, indices, ibm_view};

  glm::vec3 lo(0.0f), hi(0.0f);
  if (!mesh.vertices.empty()) lo = hi = mesh.vertices.front().position;
  for (const auto& v : mesh.vertices) {
    lo = glm::min(lo, v.position);
    hi = glm::max(hi, v.position);
  }
  tinygltf::Accessor positions;
  positions.bufferView = 0;
  positions.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
  positions.count = mesh.vertices.size();
  positions.type = TINYGLTF_TYPE_VEC3;
  positions.minValues = {lo.x, lo.y, lo.z};
  positions.maxValues = {hi.x, hi.y, hi.z};
  tinygltf::Accessor normals = positions;
  normals.byteOffset = offsetof(SkinnedVertex, normal);
  normals.minValues.clear();
  normals.maxValues.clear();
  tinygltf::Accessor joints = normals;
  joints.byteOffset = offsetof(SkinnedVertex, joints);
  joints.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;
  joints.type = TINYGLTF_TYPE_VEC4;
  tinygltf::Accessor weights = normals;
  weights.byteOffset = offsetof(SkinnedVertex, weights);
  weights.type = TINYGLTF_TYPE_VEC4;
  tinygltf::Accessor index_accessor;
  index_accessor.bufferView = 1;
  index_accessor.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
  index_accessor.count = mesh.indices.size();
  index_accessor.type = TINYGLTF_TYPE_SCALAR;
  tinygltf::Accessor ibm;
  ibm.bufferView = 2;
  ibm.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
  ibm.count = mesh.inverse_bind.size();
  ibm.type = TINYGLTF_TYPE_MAT4;
  model.accessors = {positions, normals, joints, weights, index_accessor, ibm};

  tinygltf::Primitive prim;
  prim.attributes["POSITION"] = 0;
  prim.attributes["NORMAL"] = 1;
  prim.attributes["JOINTS_0"] = 2;
  prim.attributes["WEIGHTS_0"] = 3;
  prim.indices = 4;
  prim.mode = TINYGLTF_MODE_TRIANGLES;
  tinygltf::Mesh m;
  m.name = mesh.name;
  m.primitives.push_back(prim);
  model.meshes.push_back(m);

  tinygltf::Skin skin;
  skin.name = mesh.name + "_skin";
  skin.inverseBindMatrices = 5;
  tinygltf::Scene scene;
  // Node 0: the skinned mesh; nodes 1..: the joints at their bind poses.
  tinygltf::Node mesh_node;
  mesh_node.name = mesh.name;
  mesh_node.mesh = 0;
  mesh_node.skin = 0;
  model.nodes.push_back(mesh_node);
  scene.nodes.push_back(0);
  for (std::size_t j = 0; j < mesh.joint_names.size(); ++j) {
    tinygltf::Node joint;
    joint.name = mesh.joint_names[j];
    const glm::mat4 T_bind_joint = glm::inverse(mesh.inverse_bind[j]);
    joint.matrix.assign(glm::value_ptr(T_bind_joint), glm::value_ptr(T_bind_joint) + 16);
    skin.joints.push_back(static_cast<int>(model.nodes.size()));
    scene.nodes.push_back(static_cast<int>(model.nodes.size()));
    model.nodes.push_back(joint);
  }
  model.skins.push_back(skin);
  model.scenes.push_back(scene);
  return detail::write_gltf_file(model, file);
}

}  // namespace proprio::render
