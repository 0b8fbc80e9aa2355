#include "proprio/render/mesh.hpp"

#include <fmt/format.h>

#include <cmath>
#include <limits>

namespace proprio::render {
namespace {

constexpr float kPi = 3.14159265358979f;

void add_quad(MeshData& m, std::uint32_t a, std::uint32_t b, std::uint32_t c, std::uint32_t d) {
  m.indices.insert(m.indices.end(), {a, b, c, a, c, d});
}

// A ring of `segments + 1` vertices (the seam duplicated) at height z, from
// angle a0 to a1 about z, radius r, with the given normal's z and radial parts.
std::uint32_t add_ring(MeshData& m, float r, float z, float a0, float a1, int segments, float n_radial, float n_z) {
  const auto first = static_cast<std::uint32_t>(m.vertices.size());
  for (int i = 0; i <= segments; ++i) {
    const float a = a0 + (a1 - a0) * static_cast<float>(i) / static_cast<float>(segments);
    const glm::vec3 radial(std::cos(a), std::sin(a), 0.0f);
    m.vertices.push_back({radial * r + glm::vec3(0, 0, z), glm::normalize(radial * n_radial + glm::vec3(0, 0, n_z))});
  }
  return first;
}

// Joins two rings of `segments + 1` vertices; outward faces when ring b is
// further along +z than ring a and angles grow counter-clockwise about +z.
void join_rings(MeshData& m, std::uint32_t a, std::uint32_t b, int segments) {
  for (int i = 0; i < segments; ++i) {
    const auto u = static_cast<std::uint32_t>(i);
    add_quad(m, a + u, a + u + 1, b + u + 1, b + u);
  }
}

// A flat fan closing a ring at height z, facing +z (up = true) or -z.
void add_cap(MeshData& m, float r, float z, float a0, float a1, int segments, bool up) {
  const glm::vec3 n(0, 0, up ? 1.0f : -1.0f);
  const auto centre = static_cast<std::uint32_t>(m.vertices.size());
  m.vertices.push_back({glm::vec3(0, 0, z), n});
  const std::uint32_t ring = add_ring(m, r, z, a0, a1, segments, 0.0f, n.z);
  for (int i = 0; i < segments; ++i) {
    const auto u = static_cast<std::uint32_t>(i);
    if (up) {
      m.indices.insert(m.indices.end(), {centre, ring + u, ring + u + 1});
    } else {
      m.indices.insert(m.indices.end(), {centre, ring + u + 1, ring + u});
    }
  }
}

void add_face(MeshData& m, const glm::vec3& origin, const glm::vec3& u, const glm::vec3& v) {
  const glm::vec3 n = glm::normalize(glm::cross(u, v));
  const auto first = static_cast<std::uint32_t>(m.vertices.size());
  m.vertices.push_back({origin, n});
  m.vertices.push_back({origin + u, n});
  m.vertices.push_back({origin + u + v, n});
  m.vertices.push_back({origin + v, n});
  add_quad(m, first, first + 1, first + 2, first + 3);
}

}  // namespace

Status MeshData::validate() const {
  if (indices.size() % 3 != 0) {
    return make_error(Errc::invalid_argument, fmt::format("mesh '{}': {} indices is not a whole number of triangles",
                                                          name, indices.size()));
  }
  for (std::size_t i = 0; i < indices.size(); ++i) {
    if (indices[i] >= vertices.size()) {
      return make_error(Errc::invalid_argument, fmt::format("mesh '{}': index {} at {} is past its {} vertices", name,
                                                            indices[i], i, vertices.size()));
    }
  }
  for (std::size_t i = 0; i < vertices.size(); ++i) {
    const auto& v = vertices[i];
    for (int k = 0; k < 3; ++k) {
      if (!std::isfinite(v.position[k]) || !std::isfinite(v.normal[k])) {
        return make_error(Errc::invalid_argument, fmt::format("mesh '{}': vertex {} is not finite", name, i));
      }
    }
  }
  return {};
}

glm::vec3 MeshData::bounds_min() const {
  glm::vec3 lo(std::numeric_limits<float>::max());
  for (const auto& v : vertices) lo = glm::min(lo, v.position);
  return lo;
}
glm::vec3 MeshData::bounds_max() const {
  glm::vec3 hi(std::numeric_limits<float>::lowest());
  for (const auto& v : vertices) hi = glm::max(hi, v.position);
  return hi;
}

namespace primitives {

MeshData sphere(float radius_m, int segments, int rings) {
  MeshData m;
  m.name = "sphere";
  for (int j = 0; j <= rings; ++j) {
    const float polar = kPi * static_cast<float>(j) / static_cast<float>(rings);  // from +z down
    for (int i = 0; i <= segments; ++i) {
      const float a = 2.0f * kPi * static_cast<float>(i) / static_cast<float>(segments);
      const glm::vec3 n(std::sin(polar) * std::cos(a), std::sin(polar) * std::sin(a), std::cos(polar));
      m.vertices.push_back({n * radius_m, n});
    }
  }
  const auto row = static_cast<std::uint32_t>(segments + 1);
  for (int j = 0; j < rings; ++j) {
    for (int i = 0; i < segments; ++i) {
      const auto a = static_cast<std::uint32_t>(j) * row + static_cast<std::uint32_t>(i);
      // Ring j is above ring j + 1 (further along +z).
      add_quad(m, a + row, a + row + 1, a + 1, a);
    }
  }
  return m;
}

MeshData box(const glm::vec3& h) {
  MeshData m;
  m.name = "box";
  const glm::vec3 x(2 * h.x, 0, 0), y(0, 2 * h.y, 0), z(0, 0, 2 * h.z);
  add_face(m, glm::vec3(h.x, -h.y, -h.z), y, z);    // +x
  add_face(m, glm::vec3(-h.x, -h.y, -h.z), z, y);   // -x
  add_face(m, glm::vec3(-h.x, h.y, -h.z), z, x);    // +y
  add_face(m, glm::vec3(-h.x, -h.y, -h.z), x, z);   // -y
  add_face(m, glm::vec3(-h.x, -h.y, h.z), x, y);    // +z
  add_face(m, glm::vec3(-h.x, -h.y, -h.z), y, x);   // -z
  return m;
}

MeshData cylinder(float radius_m, float half_length_m, int segments) {
  MeshData m;
  m.name = "cylinder";
  const std::uint32_t bottom = add_ring(m, radius_m, -half_length_m, 0, 2 * kPi, segments, 1, 0);
  const std::uint32_t top = add_ring(m, radius_m, half_length_m, 0, 2 * kPi, segments, 1, 0);
  join_rings(m, bottom, top, segments);
  add_cap(m, radius_m, half_length_m, 0, 2 * kPi, segments, true);
  add_cap(m, radius_m, -half_length_m, 0, 2 * kPi, segments, false);
  return m;
}

MeshData half_cylinder(float radius_m, float half_length_m, int segments) {
  MeshData m;
  m.name = "half_cylinder";
  // Angles 0..pi about z sweep the +y half.
  const std::uint32_t bottom = add_ring(m, radius_m, -half_length_m, 0, kPi, segments, 1, 0);
  const std::uint32_t top = add_ring(m, radius_m, half_length_m, 0, kPi, segments, 1, 0);
  join_rings(m, bottom, top, segments);
  add_cap(m, radius_m, half_length_m, 0, kPi, segments, true);
  add_cap(m, radius_m, -half_length_m, 0, kPi, segments, false);
  // The flat face at y = 0, facing -y.
  add_face(m, glm::vec3(-radius_m, 0, -half_length_m), glm::vec3(2 * radius_m, 0, 0),
           glm::vec3(0, 0, 2 * half_length_m));
  return m;
}

MeshData capsule(float radius_m, float half_length_m, int segments, int rings) {
  MeshData m;
  m.name = "capsule";
  // Latitude rings from the top pole to the bottom one; the equator ring of
  // each hemisphere is shifted by +-half_length, which makes the side wall.
  std::vector<std::uint32_t> ring_starts;
  for (int j = 0; j <= 2 * rings + 1; ++j) {
    const bool upper = j <= rings;
    const int k = upper ? j : j - 1;
    const float polar = kPi * static_cast<float>(k) / static_cast<float>(2 * rings);
    const float z_offset = upper ? half_length_m : -half_length_m;
    ring_starts.push_back(static_cast<std::uint32_t>(m.vertices.size()));
    for (int i = 0; i <= segments; ++i) {
      const float a = 2.0f * kPi * static_cast<float>(i) / static_cast<float>(segments);
      const glm::vec3 n(std::sin(polar) * std::cos(a), std::sin(polar) * std::sin(a), std::cos(polar));
      m.vertices.push_back({n * radius_m + glm::vec3(0, 0, z_offset), n});
    }
  }
  for (std::size_t j = 0; j + 1 < ring_starts.size(); ++j) join_rings(m, ring_starts[j + 1], ring_starts[j], segments);
  return m;
}

MeshData peg(float radius_m, float half_length_m, float bevel_m, int segments) {
  MeshData m;
  m.name = "peg";
  const float b = std::min(bevel_m, std::min(radius_m, half_length_m) * 0.5f);
  const float inner = radius_m - b;
  const float s = std::sqrt(0.5f);
  const std::uint32_t r0 = add_ring(m, inner, -half_length_m, 0, 2 * kPi, segments, s, -s);
  const std::uint32_t r1 = add_ring(m, radius_m, -half_length_m + b, 0, 2 * kPi, segments, s, -s);
  const std::uint32_t r2 = add_ring(m, radius_m, -half_length_m + b, 0, 2 * kPi, segments, 1, 0);
  const std::uint32_t r3 = add_ring(m, radius_m, half_length_m - b, 0, 2 * kPi, segments, 1, 0);
  const std::uint32_t r4 = add_ring(m, radius_m, half_length_m - b, 0, 2 * kPi, segments, s, s);
  const std::uint32_t r5 = add_ring(m, inner, half_length_m, 0, 2 * kPi, segments, s, s);
  join_rings(m, r0, r1, segments);
  join_rings(m, r2, r3, segments);
  join_rings(m, r4, r5, segments);
  add_cap(m, inner, half_length_m, 0, 2 * kPi, segments, true);
  add_cap(m, inner, -half_length_m, 0, 2 * kPi, segments, false);
  return m;
}

MeshData plate_with_hole(float hole_radius_m, const glm::vec3& h, int segments) {
  MeshData m;
  m.name = "plate_with_hole";
  // Outer side faces.
  const glm::vec3 x(2 * h.x, 0, 0), y(0, 2 * h.y, 0), z(0, 0, 2 * h.z);
  add_face(m, glm::vec3(h.x, -h.y, -h.z), y, z);
  add_face(m, glm::vec3(-h.x, -h.y, -h.z), z, y);
  add_face(m, glm::vec3(-h.x, h.y, -h.z), z, x);
  add_face(m, glm::vec3(-h.x, -h.y, -h.z), x, z);
  // Front (+z) and back (-z): each outer-rectangle point joined to the hole's
  // rim at the same angle. The rectangle point is where the ray at that angle
  // leaves the plate, which keeps every quad convex.
  for (const float side : {1.0f, -1.0f}) {
    const glm::vec3 n(0, 0, side);
    const auto rim = static_cast<std::uint32_t>(m.vertices.size());
    for (int i = 0; i <= segments; ++i) {
      const float a = 2.0f * kPi * static_cast<float>(i) / static_cast<float>(segments);
      const glm::vec2 d(std::cos(a), std::sin(a));
      m.vertices.push_back({glm::vec3(d * hole_radius_m, side * h.z), n});
      const float t = std::min(h.x / std::max(std::abs(d.x), 1e-6f), h.y / std::max(std::abs(d.y), 1e-6f));
      m.vertices.push_back({glm::vec3(d * t, side * h.z), n});
    }
    for (int i = 0; i < segments; ++i) {
      const auto k = rim + 2 * static_cast<std::uint32_t>(i);
      if (side > 0) {
        add_quad(m, k, k + 1, k + 3, k + 2);
      } else {
        add_quad(m, k, k + 2, k + 3, k + 1);
      }
    }
  }
  // Each corner lies between two neighbouring rays; the quads above stop at
  // the chord between them, so one triangle per corner and side closes it.
  const float step = 2.0f * kPi / static_cast<float>(segments);
  const auto on_rectangle = [&](int i) {
    const glm::vec2 d(std::cos(step * static_cast<float>(i)), std::sin(step * static_cast<float>(i)));
    return d * std::min(h.x / std::max(std::abs(d.x), 1e-6f), h.y / std::max(std::abs(d.y), 1e-6f));
  };
  for (const float side : {1.0f, -1.0f}) {
    const glm::vec3 n(0, 0, side);
    for (const glm::vec2 corner : {glm::vec2(h.x, h.y), glm::vec2(-h.x, h.y), glm::vec2(-h.x, -h.y),
                                   glm::vec2(h.x, -h.y)}) {
      float a = std::atan2(corner.y, corner.x);
      if (a < 0) a += 2 * kPi;
      const int i0 = static_cast<int>(std::floor(a / step));
      const auto first = static_cast<std::uint32_t>(m.vertices.size());
      m.vertices.push_back({glm::vec3(on_rectangle(i0), side * h.z), n});
      m.vertices.push_back({glm::vec3(corner, side * h.z), n});
      m.vertices.push_back({glm::vec3(on_rectangle(i0 + 1), side * h.z), n});
      if (side > 0) {
        m.indices.insert(m.indices.end(), {first, first + 1, first + 2});
      } else {
        m.indices.insert(m.indices.end(), {first, first + 2, first + 1});
      }
    }
  }
  // The hole's wall faces inward (towards the axis).
  const auto wall = static_cast<std::uint32_t>(m.vertices.size());
  for (int i = 0; i <= segments; ++i) {
    const float a = 2.0f * kPi * static_cast<float>(i) / static_cast<float>(segments);
    const glm::vec3 radial(std::cos(a), std::sin(a), 0.0f);
    m.vertices.push_back({radial * hole_radius_m + glm::vec3(0, 0, -h.z), -radial});
    m.vertices.push_back({radial * hole_radius_m + glm::vec3(0, 0, h.z), -radial});
  }
  for (int i = 0; i < segments; ++i) {
    const auto k = wall + 2 * static_cast<std::uint32_t>(i);
    add_quad(m, k, k + 1, k + 3, k + 2);
  }
  return m;
}

}  // namespace primitives
}  // namespace proprio::render
