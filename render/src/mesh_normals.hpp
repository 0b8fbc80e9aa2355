#pragma once
// Vertex normals from faces, shared by the glTF loaders and the generated
// hand: for meshes (or parts) that come without normals.
#include <cstddef>

#include <glm/glm.hpp>

namespace proprio::render::detail {

// Adds each triangle's area-weighted normal (indices from first_index on) to its three vertices.
template <typename Vertices, typename Indices>
void accumulate_face_normals(Vertices& vertices, const Indices& indices, std::size_t first_index) {
  for (std::size_t t = first_index; t + 2 < indices.size(); t += 3) {
    auto& a = vertices[indices[t]];
    auto& b = vertices[indices[t + 1]];
    auto& c = vertices[indices[t + 2]];
    const glm::vec3 n = glm::cross(b.position - a.position, c.position - a.position);
    a.normal += n;
    b.normal += n;
    c.normal += n;
  }
}

// Unit length from first_vertex on; a zero normal (a vertex in no triangle) becomes +Y.
template <typename Vertices>
void normalise_normals(Vertices& vertices, std::size_t first_vertex) {
  for (std::size_t i = first_vertex; i < vertices.size(); ++i) {
    auto& n = vertices[i].normal;
    n = glm::length(n) > 0 ? glm::normalize(n) : glm::vec3(0, 1, 0);
  }
}

}  // namespace proprio::render::detail
