#include "proprio/render/hand_skin.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <string>

#include "mesh_normals.hpp"
#include "proprio/core/glm_interop.hpp"
#include "proprio/core/hand_joint.hpp"

namespace proprio::render {
namespace {

constexpr float kPiF = 3.14159265358979f;

float smooth01(float edge0, float edge1, float x) {
  const float t = std::clamp((x - edge0) / (edge1 - edge0), 0.0f, 1.0f);
  return t * t * (3.0f - 2.0f * t);
}

// Up to four (joint, weight) pairs, merged and normalised into a vertex.
struct Influences {
  std::array<std::uint16_t, kMaxInfluences> joints{};
  std::array<float, kMaxInfluences> weights{};
  std::size_t count = 0;

  void add(HandJoint j, float w) {
    if (!(w > 1e-6f)) return;
    const auto id = static_cast<std::uint16_t>(index_of(j));
    for (std::size_t k = 0; k < count; ++k) {
      if (joints[k] == id) {
        weights[k] += w;
        return;
      }
    }
    if (count < kMaxInfluences) {
      joints[count] = id;
      weights[count] = w;
      ++count;
    }
  }
  void write(SkinnedVertex& v) const {
    float sum = 0.0f;
    for (std::size_t k = 0; k < count; ++k) sum += weights[k];
    v.joints = {};
    v.weights = glm::vec4(0.0f);
    for (std::size_t k = 0; k < count; ++k) {
      v.joints[k] = joints[k];
      v.weights[static_cast<glm::length_t>(k)] = weights[k] / sum;
    }
  }
};

// Builds closed parts (tubes, the palm) and keeps each one's triangles
// facing outwards.
class HandMeshBuilder {
 public:
  explicit HandMeshBuilder(SkinnedMeshData& mesh) : mesh_(mesh) {}

  void begin_part() {
    first_vertex_ = mesh_.vertices.size();
    first_index_ = mesh_.indices.size();
  }
  std::uint32_t add(const glm::vec3& p, const Influences& inf) {
    SkinnedVertex v;
    v.position = p;
    inf.write(v);
    mesh_.vertices.push_back(v);
    return static_cast<std::uint32_t>(mesh_.vertices.size() - 1);
  }
  void triangle(std::uint32_t a, std::uint32_t b, std::uint32_t c) { mesh_.indices.insert(mesh_.indices.end(), {a, b, c}); }
  // Rings of `n` vertices each (consecutive), closed by a pole at each end.
  void connect_rings(std::uint32_t first_ring, std::size_t rings, std::size_t n, std::uint32_t pole_start,
                     std::uint32_t pole_end) {
    const auto N = static_cast<std::uint32_t>(n);
    for (std::uint32_t k = 0; k < N; ++k) {
      const std::uint32_t k1 = (k + 1) % N;
      triangle(pole_start, first_ring + k1, first_ring + k);
      for (std::uint32_t r = 0; r + 1 < rings; ++r) {
        const std::uint32_t a = first_ring + r * N + k, b = first_ring + r * N + k1;
        const std::uint32_t c = a + N, d = b + N;
        triangle(a, b, d);
        triangle(a, d, c);
      }
      const std::uint32_t last = first_ring + static_cast<std::uint32_t>(rings - 1) * N;
      triangle(pole_end, last + k, last + k1);
    }
  }
  // Flips the part's triangles if its signed volume is negative, then
  // gives its vertices smooth normals.
  void end_part() {
    double volume = 0.0;
    for (std::size_t t = first_index_; t + 2 < mesh_.indices.size(); t += 3) {
      const glm::dvec3 a = mesh_.vertices[mesh_.indices[t]].position;
      const glm::dvec3 b = mesh_.vertices[mesh_.indices[t + 1]].position;
      const glm::dvec3 c = mesh_.vertices[mesh_.indices[t + 2]].position;
      volume += glm::dot(a, glm::cross(b, c));
    }
    if (volume < 0) {
      for (std::size_t t = first_index_; t + 2 < mesh_.indices.size(); t += 3) {
        std::swap(mesh_.indices[t + 1], mesh_.indices[t + 2]);
      }
    }
    detail::accumulate_face_normals(mesh_.vertices, mesh_.indices, first_index_);
    detail::normalise_normals(mesh_.vertices, first_vertex_);
  }

 private:
  SkinnedMeshData& mesh_;
  std::size_t first_vertex_ = 0;
  std::size_t first_index_ = 0;
};

// A tapered tube along a chain of joints at their bind positions: points[k]
// with radii[k]; the bone from points[k] to points[k+1] follows bones[k].
// The tube runs from arc length `s_begin` to the last point and is closed by
// domes (`dome_begin` and the last radius long).
struct Chain {
  std::vector<glm::vec3> points;
  std::vector<float> radii;
  std::vector<HandJoint> bones;   // points.size() - 1
  std::vector<glm::vec3> up;      // per bone: its joint's +Y (back of the hand) at bind time
  float s_begin = 0.0f;
  float dome_begin = 0.0f;
};

void add_tube(HandMeshBuilder& builder, const Chain& c, const HandMeshOptions& o) {
  const std::size_t n_points = c.points.size();
  std::vector<float> S(n_points, 0.0f);
  for (std::size_t k = 1; k < n_points; ++k) S[k] = S[k - 1] + glm::length(c.points[k] - c.points[k - 1]);
  const float s_end = S.back();

  struct Station {
    glm::vec3 centre, tangent, up;
    float radius;
    Influences inf;
  };
  auto station_at = [&](float s) {
    std::size_t k = 0;
    while (k + 2 < n_points && s > S[k + 1]) ++k;
    const float len = std::max(S[k + 1] - S[k], 1e-6f);
    const float t = std::clamp((s - S[k]) / len, 0.0f, 1.0f);
    Station st;
    st.centre = glm::mix(c.points[k], c.points[k + 1], t);
    st.radius = glm::mix(c.radii[k], c.radii[k + 1], t);
    glm::vec3 tangent = glm::normalize(c.points[k + 1] - c.points[k]);
    glm::vec3 up = c.up[k];
    st.inf.add(c.bones[k], 1.0f);
    // Smooth blends across the interior joints near s.
    for (std::size_t j = 1; j + 1 < n_points; ++j) {
      const float h = std::max(o.blend_radii * c.radii[j], 1e-4f);
      const float d = s - S[j];
      if (std::abs(d) >= h) continue;
      const float w = smooth01(-h, h, d);  // 0: the bone before joint j, 1: the bone after it
      st.inf = Influences{};
      st.inf.add(c.bones[j - 1], 1.0f - w);
      st.inf.add(c.bones[j], w);
      tangent = glm::normalize(glm::mix(glm::normalize(c.points[j] - c.points[j - 1]),
                                        glm::normalize(c.points[j + 1] - c.points[j]), w));
      up = glm::mix(c.up[j - 1], c.up[j], w);
    }
    st.tangent = tangent;
    st.up = glm::normalize(up - glm::dot(up, tangent) * tangent);
    return st;
  };

  const int segments = std::max(o.segments, 6);
  builder.begin_part();
  auto ring = [&](const Station& st, const glm::vec3& centre, float radius) {
    const glm::vec3 side = glm::cross(st.up, st.tangent);
    for (int i = 0; i < segments; ++i) {
      const float a = 2.0f * kPiF * static_cast<float>(i) / static_cast<float>(segments);
      // Slightly flattened: fingers are wider than they are thick.
      builder.add(centre + radius * (std::cos(a) * side + 0.85f * std::sin(a) * st.up), st.inf);
    }
  };
  constexpr int kDomeRings = 4;
  const Station first = station_at(c.s_begin);
  const Station last = station_at(s_end);
  const auto first_ring = static_cast<std::uint32_t>(
      builder.add(first.centre - first.tangent * c.dome_begin, first.inf) + 1);  // the start pole, then rings
  std::size_t rings = 0;
  for (int k = kDomeRings - 1; k >= 1; --k) {  // the start dome, pole side first
    const float phi = 0.5f * kPiF * static_cast<float>(k) / kDomeRings;
    ring(first, first.centre - first.tangent * (c.dome_begin * std::sin(phi)), first.radius * std::cos(phi));
    ++rings;
  }
  const int steps = std::max(1, static_cast<int>(std::ceil((s_end - c.s_begin) / o.ring_spacing_m)));
  for (int i = 0; i <= steps; ++i) {
    const Station st = station_at(c.s_begin + (s_end - c.s_begin) * static_cast<float>(i) / static_cast<float>(steps));
    ring(st, st.centre, st.radius);
    ++rings;
  }
  for (int k = 1; k < kDomeRings; ++k) {  // the end dome
    const float phi = 0.5f * kPiF * static_cast<float>(k) / kDomeRings;
    ring(last, last.centre + last.tangent * (last.radius * std::sin(phi)), last.radius * std::cos(phi));
    ++rings;
  }
  const std::uint32_t end_pole = builder.add(last.centre + last.tangent * last.radius, last.inf);
  builder.connect_rings(first_ring, rings, static_cast<std::size_t>(segments), first_ring - 1, end_pole);
  builder.end_part();
}

// The palm: a rounded slab lofted from the wrist to the knuckle line, in the
// wrist frame (fingers along -Z, back of the hand +Y).
void add_palm(HandMeshBuilder& builder, const HandPose& rest, const HandShape& shape) {
  struct Knuckle {
    float x, z, r;
    HandJoint metacarpal;
  };
  std::vector<Knuckle> knuckles;
  for (Finger f : {Finger::index, Finger::middle, Finger::ring, Finger::little}) {
    const auto fj = finger_joints(f);
    const glm::vec3 p = to_glm(rest.joint(fj.joints[1]).p);
    knuckles.push_back({p.x, p.z, static_cast<float>(rest.radius_m[index_of(fj.joints[1])]), fj.joints[0]});
  }
  std::sort(knuckles.begin(), knuckles.end(), [](const Knuckle& a, const Knuckle& b) { return a.x < b.x; });
  const float x_lo = knuckles.front().x - 0.8f * knuckles.front().r;
  const float x_hi = knuckles.back().x + 0.8f * knuckles.back().r;
  const float cx1 = 0.5f * (x_lo + x_hi), a1 = 0.5f * (x_hi - x_lo);
  const auto wrist_r = static_cast<float>(shape.wrist_radius_m);
  const auto palm_r = static_cast<float>(shape.palm_radius_m);
  const float a0 = std::max(1.4f * wrist_r, 0.72f * a1), cx0 = 0.35f * cx1;
  const float b0 = 0.8f * wrist_r, b1 = 0.85f * palm_r;
  const float z0 = 0.3f * wrist_r;
  // Knuckle-line z at lateral position x (piecewise linear, clamped).
  auto knuckle_z = [&](float x) {
    if (x <= knuckles.front().x) return knuckles.front().z;
    for (std::size_t k = 0; k + 1 < knuckles.size(); ++k) {
      if (x <= knuckles[k + 1].x) {
        const float t = (x - knuckles[k].x) / std::max(knuckles[k + 1].x - knuckles[k].x, 1e-6f);
        return glm::mix(knuckles[k].z, knuckles[k + 1].z, t);
      }
    }
    return knuckles.back().z;
  };
  // Wrist near s = 0, the metacarpals (by lateral position) towards the knuckles.
  auto weights_at = [&](float x, float s) {
    Influences inf;
    const float w_wrist = 1.0f - smooth01(0.0f, 0.5f, s);
    inf.add(HandJoint::wrist, w_wrist);
    const float rest_w = 1.0f - w_wrist;
    if (x <= knuckles.front().x) {
      inf.add(knuckles.front().metacarpal, rest_w);
    } else if (x >= knuckles.back().x) {
      inf.add(knuckles.back().metacarpal, rest_w);
    } else {
      for (std::size_t k = 0; k + 1 < knuckles.size(); ++k) {
        if (x <= knuckles[k + 1].x) {
          const float t = (x - knuckles[k].x) / std::max(knuckles[k + 1].x - knuckles[k].x, 1e-6f);
          inf.add(knuckles[k].metacarpal, rest_w * (1.0f - t));
          inf.add(knuckles[k + 1].metacarpal, rest_w * t);
          break;
        }
      }
    }
    return inf;
  };
  constexpr int kSegments = 28;
  constexpr int kStations = 10;
  constexpr int kDomeRings = 3;
  constexpr float kExponent = 0.5f;  // superellipse: |cos|^0.5 makes a rounded box
  // A point of the section at station s (0 wrist, 1 knuckles), angle a,
  // shrunk by `scale` and pushed `dz_fraction` of the thickness past the end.
  auto point = [&](float s, float a, float scale, float dz_fraction) {
    const float c = std::cos(a), sn = std::sin(a);
    const float ex = std::copysign(std::pow(std::abs(c), kExponent), c);
    const float ey = std::copysign(std::pow(std::abs(sn), kExponent), sn);
    const float half_w = glm::mix(a0, a1, s), half_t = glm::mix(b0, b1, s);
    const float x = glm::mix(cx0, cx1, s) + scale * half_w * ex;
    const float y = -0.15f * half_t + scale * half_t * ey;
    const float z = glm::mix(z0, knuckle_z(x), s) + (s < 0.5f ? 1.0f : -1.0f) * dz_fraction * half_t;
    return glm::vec3(x, y, z);
  };
  builder.begin_part();
  const std::uint32_t start_pole = builder.add(point(0.0f, 0.0f, 0.0f, 1.0f), weights_at(cx0, 0.0f));
  const std::uint32_t first_ring = start_pole + 1;
  std::size_t rings = 0;
  auto ring = [&](float s, float scale, float dz) {
    for (int i = 0; i < kSegments; ++i) {
      const float a = 2.0f * kPiF * static_cast<float>(i) / kSegments;
      const glm::vec3 p = point(s, a, scale, dz);
      builder.add(p, weights_at(p.x, s));
    }
    ++rings;
  };
  for (int k = kDomeRings - 1; k >= 1; --k) {
    const float phi = 0.5f * kPiF * static_cast<float>(k) / kDomeRings;
    ring(0.0f, std::cos(phi), std::sin(phi));
  }
  for (int i = 0; i <= kStations; ++i) ring(static_cast<float>(i) / kStations, 1.0f, 0.0f);
  for (int k = 1; k < kDomeRings; ++k) {
    const float phi = 0.5f * kPiF * static_cast<float>(k) / kDomeRings;
    ring(1.0f, std::cos(phi), 0.6f * std::sin(phi));
  }
  const std::uint32_t end_pole = builder.add(point(1.0f, 0.0f, 0.0f, 0.6f), weights_at(cx1, 1.0f));
  builder.connect_rings(first_ring, rings, kSegments, start_pole, end_pole);
  builder.end_part();
}

std::string lower(std::string_view s) {
  std::string out(s);
  for (char& ch : out) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return out;
}

}  // namespace

std::optional<HandJoint> hand_joint_from_name(std::string_view name) noexcept {
  std::string n = lower(name);
  constexpr std::string_view kPrefix = "xr_hand_joint_", kSuffix = "_ext";
  if (n.size() > kPrefix.size() + kSuffix.size() && n.compare(0, kPrefix.size(), kPrefix) == 0 &&
      n.compare(n.size() - kSuffix.size(), kSuffix.size(), kSuffix) == 0) {
    n = n.substr(kPrefix.size(), n.size() - kPrefix.size() - kSuffix.size());
  }
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    if (n == to_string(joint_at(i))) return joint_at(i);
  }
  return std::nullopt;
}

SkinnedMeshData generate_hand_mesh(const HandModel& model, Handedness hand, const HandMeshOptions& options) {
  const HandPose rest = model.forward(hand, HandAngles{}, Pose::identity(), 0);
  SkinnedMeshData mesh;
  mesh.name = fmt::format("proprio_{}_hand", to_string(hand));
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    mesh.joint_names.emplace_back(to_string(joint_at(i)));
    mesh.inverse_bind.push_back(glm::inverse(to_glm(rest.T_world_joint[i])));
  }
  HandMeshBuilder builder(mesh);
  for (std::size_t f = 0; f < kFingerCount; ++f) {
    const auto fj = finger_joints(static_cast<Finger>(f));
    Chain c;
    for (std::size_t k = 0; k < fj.count; ++k) {
      const std::size_t j = index_of(fj.joints[k]);
      c.points.push_back(to_glm(rest.T_world_joint[j].p));
      c.radii.push_back(static_cast<float>(rest.radius_m[j]));
      if (k + 1 < fj.count) {
        c.bones.push_back(fj.joints[k]);
        c.up.push_back(glm::mat3(to_glm(rest.T_world_joint[j]))[1]);
      }
    }
    if (static_cast<Finger>(f) == Finger::thumb) {
      // The thumb's metacarpal is part of the visible thumb (the thenar bulge).
      c.s_begin = 0.0f;
      c.dome_begin = c.radii[0];
    } else {
      // From just inside the palm at the knuckle.
      c.s_begin = glm::length(c.points[1] - c.points[0]) - 1.2f * c.radii[1];
      c.dome_begin = 0.5f * c.radii[1];
    }
    add_tube(builder, c, options);
  }
  add_palm(builder, rest, model.shape());
  return mesh;
}

Result<HandSkin> HandSkin::bind(const SkinnedMeshData& mesh) {
  if (auto s = mesh.validate(); !s) return s.error();
  std::vector<bool> weighted(mesh.joint_names.size(), false);
  for (const SkinnedVertex& v : mesh.vertices) {
    for (std::size_t k = 0; k < kMaxInfluences; ++k) {
      if (v.weights[static_cast<glm::length_t>(k)] > 0.0f) weighted[v.joints[k]] = true;
    }
  }
  HandSkin skin;
  skin.skin_of_joint_.fill(-1);
  skin.inverse_bind_ = mesh.inverse_bind;
  for (std::size_t i = 0; i < mesh.joint_names.size(); ++i) {
    const auto joint = hand_joint_from_name(mesh.joint_names[i]);
    if (!joint) {
      if (weighted[i]) {
        return make_error(Errc::parse_error,
                          fmt::format("skinned hand '{}': joint {} '{}' carries vertex weights but is not an OpenXR "
                                      "hand joint; name it like 'index_proximal' or "
                                      "'XR_HAND_JOINT_INDEX_PROXIMAL_EXT'",
                                      mesh.name, i, mesh.joint_names[i]));
      }
      skin.joint_of_skin_.push_back(kUnbound);
      continue;
    }
    const std::size_t x = index_of(*joint);
    if (skin.skin_of_joint_[x] >= 0) {
      return make_error(Errc::parse_error, fmt::format("skinned hand '{}': joints {} and {} both name '{}'", mesh.name,
                                                       skin.skin_of_joint_[x], i, to_string(*joint)));
    }
    skin.skin_of_joint_[x] = static_cast<int>(i);
    skin.joint_of_skin_.push_back(static_cast<std::uint8_t>(x));
  }
  const int wrist = skin.skin_of_joint_[index_of(HandJoint::wrist)];
  int thumb = -1;
  for (HandJoint j : {HandJoint::thumb_proximal, HandJoint::thumb_distal, HandJoint::thumb_tip,
                      HandJoint::thumb_metacarpal}) {
    if (thumb < 0) thumb = skin.skin_of_joint_[index_of(j)];
  }
  if (wrist < 0 || thumb < 0) {
    return make_error(Errc::parse_error,
                      fmt::format("skinned hand '{}': the skin needs a 'wrist' joint and a thumb joint (their bind "
                                  "poses tell a left from a right hand)",
                                  mesh.name));
  }
  // The thumb lies on the wrist's -X for a right hand, +X for a left one.
  const glm::vec4 p_thumb_in_wrist = mesh.inverse_bind[static_cast<std::size_t>(wrist)] *
                                     glm::inverse(mesh.inverse_bind[static_cast<std::size_t>(thumb)])[3];
  skin.hand_ = p_thumb_in_wrist.x < 0.0f ? Handedness::right : Handedness::left;
  return skin;
}

std::optional<HandJoint> HandSkin::joint_of(std::size_t skin_joint) const noexcept {
  if (skin_joint >= joint_of_skin_.size() || joint_of_skin_[skin_joint] == kUnbound) return std::nullopt;
  return joint_at(joint_of_skin_[skin_joint]);
}

bool HandSkin::skin_matrices(const HandPose& pose, std::span<glm::mat4> out) const noexcept {
  constexpr std::uint8_t kValid = kPositionValid | kOrientationValid;
  auto valid = [&](std::size_t j) { return (pose.flags[j] & kValid) == kValid; };
  const std::size_t wrist = index_of(HandJoint::wrist);
  if (!pose.active || !valid(wrist) || out.size() < joint_of_skin_.size()) return false;
  glm::mat4 mirror(1.0f);
  if (pose.hand != hand_) mirror[0][0] = -1.0f;
  // T_world_joint * mirror * inverse_bind for each OpenXR joint in the skin,
  // the nearest valid ancestor's for a joint the pose lacks. Parents come
  // before children in XrHandJointEXT order except the palm (index 0),
  // whose ancestor is the wrist (index 1), so the wrist goes first.
  std::array<glm::mat4, kHandJointCount> delta{};  // bind space -> world, per OpenXR joint
  std::array<bool, kHandJointCount> have{};
  auto compute = [&](std::size_t j) {
    const int s = skin_of_joint_[j];
    if (valid(j) && s >= 0) {
      delta[j] = to_glm(pose.T_world_joint[j]) * mirror * inverse_bind_[static_cast<std::size_t>(s)];
      have[j] = true;
      return;
    }
    // Follow the nearest ancestor whose delta exists.
    const auto parent = j == index_of(HandJoint::palm) ? std::optional<HandJoint>(HandJoint::wrist)
                                                       : parent_of(joint_at(j));
    if (parent && have[index_of(*parent)]) {
      delta[j] = delta[index_of(*parent)];
      have[j] = true;
    }
  };
  compute(wrist);
  if (!have[wrist]) return false;
  compute(index_of(HandJoint::palm));
  for (std::size_t j = 2; j < kHandJointCount; ++j) compute(j);
  for (std::size_t i = 0; i < joint_of_skin_.size(); ++i) {
    const std::uint8_t x = joint_of_skin_[i];
    // Unbound joints carry no weight; the wrist's matrix keeps every matrix's
    // handedness the same (the renderer reads the first one's).
    out[i] = x != kUnbound && have[x] ? delta[x] : delta[wrist];
  }
  return true;
}

Result<SkinnedHand> SkinnedHand::upload(Renderer& renderer, const SkinnedMeshData& mesh) {
  auto skin = HandSkin::bind(mesh);
  if (!skin) return skin.error();
  auto id = renderer.upload_skinned(mesh);
  if (!id) return id.error();
  SkinnedHand h;
  h.mesh = *id;
  h.skin = std::move(skin).value();
  return h;
}

void append_skinned_hand(DrawList& draws, const HandPose& pose, const SkinnedHand& hand, const glm::vec4& color) {
  if (!pose.active || !hand.skin) return;
  const std::size_t first = draws.skin_matrices.size();
  draws.skin_matrices.resize(first + hand.skin->joint_count());
  if (!hand.skin->skin_matrices(pose, std::span(draws.skin_matrices).subspan(first))) {
    draws.skin_matrices.resize(first);
    return;
  }
  draws.skinned.push_back({hand.mesh, static_cast<std::uint32_t>(first), color});
}

glm::vec4 skin_color_for(Handedness hand) {
  return hand == Handedness::left ? glm::vec4(0.42f, 0.62f, 0.9f, 1.0f) : glm::vec4(0.93f, 0.66f, 0.5f, 1.0f);
}

}  // namespace proprio::render
