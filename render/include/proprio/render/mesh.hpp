#pragma once
// Triangle meshes on the CPU: generated primitives and glTF files. Each
// primitive is built in its own frame with the same conventions as the
// haptic scene's shapes (proprio/haptics/scene.hpp), so what is drawn is what
// MuJoCo collides with. Metres; counter-clockwise front faces seen from
// outside; outward unit normals.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "proprio/core/result.hpp"

namespace proprio::render {

struct Vertex {
  glm::vec3 position;
  glm::vec3 normal;
};

struct MeshData {
  std::string name;
  std::vector<Vertex> vertices;
  std::vector<std::uint32_t> indices;  // triangles

  // Indices in range, a multiple of 3, finite positions and normals.
  Status validate() const;
  glm::vec3 bounds_min() const;
  glm::vec3 bounds_max() const;
};

namespace primitives {
// Centred on the origin.
MeshData sphere(float radius_m, int segments = 32, int rings = 16);
MeshData box(const glm::vec3& half_extents_m);
// Axis along z, from -half_length to +half_length, capped.
MeshData cylinder(float radius_m, float half_length_m, int segments = 32);
// The +y half of a cylinder along z: the flat face lies at y = 0 facing -y.
MeshData half_cylinder(float radius_m, float half_length_m, int segments = 32);
// A segment along z of half length half_length_m with hemispherical ends.
MeshData capsule(float radius_m, float half_length_m, int segments = 24, int rings = 8);
// The peg-in-hole bottle: a cylinder along z, centred, with bevelled rims
// (bevel_m) so its silhouette reads as a bottle, not a tube.
MeshData peg(float radius_m, float half_length_m, float bevel_m = 0.004f, int segments = 32);
// A plate with a round through-hole along z: half_extents_m are the outer
// half sizes (x, y) and the half thickness (z).
MeshData plate_with_hole(float hole_radius_m, const glm::vec3& half_extents_m, int segments = 48);
}  // namespace primitives

// All triangle primitives of a glTF 2.0 file (.gltf or .glb), each with its
// node transform applied, merged into one mesh. Normals are computed when the
// file has none. Errc::not_found / parse_error with tinygltf's message.
Result<MeshData> load_gltf(const std::filesystem::path& file);
// Writes a mesh as a .gltf with embedded buffers (assets, tests).
Status save_gltf(const MeshData& mesh, const std::filesystem::path& file);

}  // namespace proprio::render
