#pragma once
// Skinned triangle meshes: vertices with up to four joint influences, the
// skin's joints (by name) and their inverse bind matrices; glTF load/save
// (tinygltf) and linear-blend skinning on the CPU.
//
// Linear-blend skinning: a vertex v (in the mesh's bind space) lands at
//   sum_k weight_k * skin[joint_k] * v,   skin[j] = T_world_joint(j) * inverse_bind[j]
// and its normal at the same blend of the matrices' linear parts (exact for
// rigid and mirrored joint transforms, which is what hands use).
#include <array>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "proprio/core/result.hpp"
#include "proprio/render/mesh.hpp"

namespace proprio::render {

// glTF allows four influences per JOINTS_0/WEIGHTS_0 set; Proprio reads one set.
inline constexpr std::size_t kMaxInfluences = 4;

struct SkinnedVertex {
  glm::vec3 position{0.0f};  // bind space (the space the inverse bind matrices map from)
  glm::vec3 normal{0.0f};
  std::array<std::uint16_t, kMaxInfluences> joints{};  // indices into SkinnedMeshData::joint_names
  glm::vec4 weights{0.0f};                             // sum to 1
};

struct SkinnedMeshData {
  std::string name;
  std::vector<SkinnedVertex> vertices;
  std::vector<std::uint32_t> indices;     // triangles
  std::vector<std::string> joint_names;   // the skin's joints, in the file's order
  std::vector<glm::mat4> inverse_bind;    // one per joint: bind space -> joint frame at bind time

  // Indices in range and a multiple of 3; finite positions and normals;
  // joint indices below the joint count; weights finite, >= 0, summing to 1
  // (within 1e-3); one inverse bind matrix per joint.
  Status validate() const;
  // The mesh as it lies in bind space, unskinned (for static drawing and tests).
  MeshData bind_pose() const;
};

// The first skinned triangle mesh of a glTF 2.0 file (.gltf or .glb): the
// first node that has both a mesh and a skin. Reads POSITION (float),
// NORMAL (float; computed when absent), JOINTS_0 (unsigned byte or short),
// WEIGHTS_0 (float, or normalised unsigned byte/short; renormalised to sum
// to 1), indices, the skin's joints (their node names) and its inverse bind
// matrices (required). Errors: Errc::not_found (no file), Errc::parse_error
// (not glTF, no skinned mesh, bad accessors, joint indices past the skin),
// Errc::unsupported (JOINTS_1/WEIGHTS_1: more than four influences per
// vertex, or component types the spec does not allow).
Result<SkinnedMeshData> load_skinned_gltf(const std::filesystem::path& file);
// Writes a .gltf with embedded buffers: one node per joint (named, at its
// bind pose, children of the mesh node's scene root), a skin and the mesh.
Status save_skinned_gltf(const SkinnedMeshData& mesh, const std::filesystem::path& file);

// Linear-blend skinning of every vertex: out[i] = the skinned vertex i.
// `skin` holds one matrix per joint (T_world_joint * inverse_bind).
// Requires out.size() >= mesh.vertices.size() and skin.size() >=
// mesh.joint_names.size(); allocates nothing.
void skin_vertices(std::span<const SkinnedVertex> vertices, std::span<const glm::mat4> skin, std::span<Vertex> out);

}  // namespace proprio::render
