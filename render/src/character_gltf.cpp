// Characters for the rig device: a skinned glTF's joint hierarchy and
// animations read as a generic skeleton with sample poses, and written back.
// The mesh itself goes through load_skinned_gltf (skinned_gltf.cpp), so the
// file is parsed twice; characters are small and this keeps one mesh reader.
#include <fmt/format.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>
#include <unordered_map>
#include <unordered_set>

#include <glm/gtc/type_ptr.hpp>

#include "gltf_write.hpp"
#include "proprio/render/character.hpp"

namespace proprio::render {
namespace {
// A named namespace inside the anonymous one: this file shares a unity-build
// unit with skinned_gltf.cpp, whose anonymous helpers have similar names.
namespace character_io {

// Exporters write scale 1 as 1.0 or 0.99999994; a real scale is far larger.
constexpr double kUnitScaleTolerance = 1e-4;
// Keyframe times of different channels closer than this are one sample.
constexpr double kSameTime_s = 1e-5;

std::string node_label(const tinygltf::Model& model, int index) {
  return fmt::format("node {} ('{}')", index, printable(model.nodes[static_cast<std::size_t>(index)].name, 80));
}

// A node's local transform. Scale, shear and mirroring are refused: the
// skeleton is rigid, posed by rotations only.
Result<Pose> node_local_pose(const tinygltf::Model& model, int index) {
  const tinygltf::Node& node = model.nodes[static_cast<std::size_t>(index)];
  const std::string label = node_label(model, index);
  if (node.matrix.size() == 16) {
    Eigen::Matrix4d m;
    for (int k = 0; k < 16; ++k) m(k % 4, k / 4) = node.matrix[static_cast<std::size_t>(k)];  // column-major
    if (!m.allFinite()) return make_error(Errc::parse_error, label + ": its matrix is not finite");
    const Mat3 r = m.topLeftCorner<3, 3>();
    if ((r.transpose() * r - Mat3::Identity()).cwiseAbs().maxCoeff() > kUnitScaleTolerance || r.determinant() < 0.0 ||
        m.row(3).head<3>().cwiseAbs().maxCoeff() > 1e-9 || std::abs(m(3, 3) - 1.0) > 1e-9) {
      return make_error(Errc::unsupported,
                        label +
                            ": its matrix scales, shears or mirrors; Proprio's skeletons are rigid (unit scale). "
                            "Apply the scale to the mesh and the joint offsets when exporting");
    }
    return Pose{Quat(r).normalized(), m.col(3).head<3>()};
  }
  if (!node.matrix.empty()) {
    return make_error(Errc::parse_error,
                      fmt::format("{}: its matrix has {} numbers, not 16", label, node.matrix.size()));
  }
  Pose T;
  if (!node.translation.empty()) {
    if (node.translation.size() != 3)
      return make_error(Errc::parse_error, label + ": its translation is not 3 numbers");
    T.p = Vec3(node.translation[0], node.translation[1], node.translation[2]);
    if (!T.p.allFinite()) return make_error(Errc::parse_error, label + ": its translation is not finite");
  }
  if (!node.rotation.empty()) {
    if (node.rotation.size() != 4) return make_error(Errc::parse_error, label + ": its rotation is not 4 numbers");
    const Quat q(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);  // glTF: x, y, z, w
    if (!q.coeffs().allFinite() || q.norm() < 1e-6) {
      return make_error(Errc::parse_error, label + ": its rotation is not a finite, non-zero quaternion");
    }
    T.q = q.normalized();
  }
  if (!node.scale.empty()) {
    if (node.scale.size() != 3) return make_error(Errc::parse_error, label + ": its scale is not 3 numbers");
    for (double s : node.scale) {
      if (!std::isfinite(s) || std::abs(s - 1.0) > kUnitScaleTolerance) {
        return make_error(Errc::unsupported,
                          fmt::format("{}: its scale is ({}, {}, {}); Proprio's skeletons are rigid (unit scale). "
                                      "Apply the scale to the mesh and the joint offsets when exporting",
                                      label, node.scale[0], node.scale[1], node.scale[2]));
      }
    }
  }
  return T;
}

// Each node's parent (-1 for scene roots), refusing nodes with two parents,
// children that do not exist and cycles.
Result<std::vector<int>> node_parents(const tinygltf::Model& model) {
  const std::size_t n = model.nodes.size();
  std::vector<int> parent(n, -1);
  for (std::size_t i = 0; i < n; ++i) {
    for (int c : model.nodes[i].children) {
      if (c < 0 || static_cast<std::size_t>(c) >= n) {
        return make_error(Errc::parse_error, fmt::format("{} lists child {}, which does not exist",
                                                         node_label(model, static_cast<int>(i)), c));
      }
      if (static_cast<std::size_t>(c) == i) {
        return make_error(Errc::parse_error, node_label(model, c) + " lists itself as a child");
      }
      if (parent[static_cast<std::size_t>(c)] >= 0) {
        return make_error(Errc::parse_error,
                          fmt::format("{} is a child of both node {} and node {}; a glTF node has one parent",
                                      node_label(model, c), parent[static_cast<std::size_t>(c)], i));
      }
      parent[static_cast<std::size_t>(c)] = static_cast<int>(i);
    }
  }
  // Every node has at most one parent now, so a cycle is a loop of parents:
  // walk up from each node, marking the path, until a node already known.
  enum : unsigned char { unseen, on_path, done };
  std::vector<unsigned char> state(n, unseen);
  std::vector<int> path;
  for (std::size_t start = 0; start < n; ++start) {
    path.clear();
    int a = static_cast<int>(start);
    while (a >= 0 && state[static_cast<std::size_t>(a)] == unseen) {
      state[static_cast<std::size_t>(a)] = on_path;
      path.push_back(a);
      a = parent[static_cast<std::size_t>(a)];
    }
    if (a >= 0 && state[static_cast<std::size_t>(a)] == on_path) {
      return make_error(Errc::parse_error,
                        fmt::format("the node hierarchy has a cycle through {}", node_label(model, a)));
    }
    for (int p : path) state[static_cast<std::size_t>(p)] = done;
  }
  return parent;
}

// One accessor's elements as doubles (float, or normalised integers as the
// glTF spec maps them for animation outputs), bounds-checked.
struct RealAccessor {
  const unsigned char* data = nullptr;
  std::size_t stride = 0;
  std::size_t count = 0;
  int component_type = 0;
  int components = 0;

  double get(std::size_t i, int k) const {
    const unsigned char* e =
        data + i * stride + static_cast<std::size_t>(k * tinygltf::GetComponentSizeInBytes(component_type));
    switch (component_type) {
      case TINYGLTF_COMPONENT_TYPE_FLOAT: {
        float f;
        std::memcpy(&f, e, 4);
        return f;
      }
      case TINYGLTF_COMPONENT_TYPE_BYTE: {
        std::int8_t b;
        std::memcpy(&b, e, 1);
        return std::max(b / 127.0, -1.0);
      }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return *e / 255.0;
      case TINYGLTF_COMPONENT_TYPE_SHORT: {
        std::int16_t s;
        std::memcpy(&s, e, 2);
        return std::max(s / 32767.0, -1.0);
      }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        std::uint16_t s;
        std::memcpy(&s, e, 2);
        return s / 65535.0;
      }
      default: return std::numeric_limits<double>::quiet_NaN();
    }
  }
};

Result<RealAccessor> real_accessor(const tinygltf::Model& model, int index, int expected_type, bool allow_normalized,
                                   const std::string& what) {
  if (index < 0 || static_cast<std::size_t>(index) >= model.accessors.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: accessor {} does not exist", what, index));
  }
  const auto& acc = model.accessors[static_cast<std::size_t>(index)];
  if (acc.type != expected_type) {
    return make_error(Errc::parse_error,
                      fmt::format("{}: accessor {} has {} components, expected {}", what, index,
                                  tinygltf::GetNumComponentsInType(static_cast<std::uint32_t>(acc.type)),
                                  tinygltf::GetNumComponentsInType(static_cast<std::uint32_t>(expected_type))));
  }
  const bool is_float = acc.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT;
  const bool is_normalized_int = acc.normalized && (acc.componentType == TINYGLTF_COMPONENT_TYPE_BYTE ||
                                                    acc.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                                                    acc.componentType == TINYGLTF_COMPONENT_TYPE_SHORT ||
                                                    acc.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT);
  if (!is_float && !(allow_normalized && is_normalized_int)) {
    return make_error(Errc::unsupported,
                      fmt::format("{}: accessor {} has component type {}; expected float{}", what, index,
                                  acc.componentType, allow_normalized ? " or a normalised integer" : ""));
  }
  if (acc.sparse.isSparse) {
    return make_error(Errc::unsupported,
                      fmt::format("{}: accessor {} is sparse; sparse accessors are not supported", what, index));
  }
  if (acc.bufferView < 0 || static_cast<std::size_t>(acc.bufferView) >= model.bufferViews.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: accessor {} has no buffer view", what, index));
  }
  const auto& bv = model.bufferViews[static_cast<std::size_t>(acc.bufferView)];
  if (bv.buffer < 0 || static_cast<std::size_t>(bv.buffer) >= model.buffers.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: buffer view {} has no buffer", what, acc.bufferView));
  }
  const auto& buffer = model.buffers[static_cast<std::size_t>(bv.buffer)];
  RealAccessor v;
  v.component_type = acc.componentType;
  v.components = tinygltf::GetNumComponentsInType(static_cast<std::uint32_t>(acc.type));
  v.count = acc.count;
  const std::size_t element =
      static_cast<std::size_t>(tinygltf::GetComponentSizeInBytes(static_cast<std::uint32_t>(acc.componentType))) *
      static_cast<std::size_t>(v.components);
  v.stride = bv.byteStride ? bv.byteStride : element;
  // Written so that no sum can wrap, whatever sizes the file claims.
  const std::size_t size = buffer.data.size();
  const bool view_fits = bv.byteLength <= size && bv.byteOffset <= size - bv.byteLength;
  const std::size_t room = view_fits && acc.byteOffset <= bv.byteLength ? bv.byteLength - acc.byteOffset : 0;
  const bool fits = view_fits && acc.byteOffset <= bv.byteLength && v.stride >= element &&
                    (acc.count == 0 || (room >= element && (acc.count - 1) <= (room - element) / v.stride));
  if (!fits) {
    return make_error(Errc::parse_error, fmt::format("{}: accessor {} ({} elements) reads past the end of its buffer",
                                                     what, index, acc.count));
  }
  v.data = buffer.data.data() + bv.byteOffset + acc.byteOffset;
  return v;
}

// One animation channel's keyframes (rotations as unit quaternions,
// translations and scales as vectors in the first three components).
struct Track {
  int joint = -1;  // skin slot
  std::string path;
  bool step = false;
  std::vector<double> times_s;
  std::vector<Eigen::Vector4d> values;

  Quat rotation(std::size_t i) const { return Quat(values[i][3], values[i][0], values[i][1], values[i][2]); }
  // The value at time t: held before the first and after the last keyframe.
  Eigen::Vector4d vector_at(double t) const {
    const auto [i, u] = segment(t);
    return step || u == 0.0 ? values[i] : Eigen::Vector4d((1.0 - u) * values[i] + u * values[i + 1]);
  }
  Quat rotation_at(double t) const {
    const auto [i, u] = segment(t);
    return step || u == 0.0 ? rotation(i) : slerp(rotation(i), rotation(i + 1), u).normalized();
  }
  std::pair<std::size_t, double> segment(double t) const {
    if (t <= times_s.front()) return {0, 0.0};
    if (t >= times_s.back()) return {times_s.size() - 1, 0.0};
    const auto it = std::upper_bound(times_s.begin(), times_s.end(), t);
    const std::size_t i = static_cast<std::size_t>(it - times_s.begin()) - 1;
    return {i, (t - times_s[i]) / (times_s[i + 1] - times_s[i])};
  }
};

Result<Track> read_track(const tinygltf::Model& model, const tinygltf::Animation& anim,
                         const tinygltf::AnimationChannel& channel, int joint, const std::string& what) {
  if (channel.sampler < 0 || static_cast<std::size_t>(channel.sampler) >= anim.samplers.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: sampler {} does not exist", what, channel.sampler));
  }
  const tinygltf::AnimationSampler& sampler = anim.samplers[static_cast<std::size_t>(channel.sampler)];
  Track track;
  track.joint = joint;
  track.path = channel.target_path;
  if (sampler.interpolation == "CUBICSPLINE") {
    return make_error(Errc::unsupported, what +
                                             ": CUBICSPLINE interpolation is not supported; bake the animation "
                                             "with LINEAR or STEP keys when exporting");
  }
  if (!sampler.interpolation.empty() && sampler.interpolation != "LINEAR" && sampler.interpolation != "STEP") {
    return make_error(Errc::parse_error, fmt::format("{}: interpolation '{}' is not a glTF one", what,
                                                     printable(sampler.interpolation, 40)));
  }
  track.step = sampler.interpolation == "STEP";
  auto input = real_accessor(model, sampler.input, TINYGLTF_TYPE_SCALAR, false, what + " (keyframe times)");
  if (!input) return input.error();
  if (input->count == 0) return make_error(Errc::parse_error, what + ": no keyframes");
  // Keyframe times are strictly increasing, so each is a sample of its own.
  if (input->count > kMaxCharacterSamples) {
    return make_error(Errc::unsupported, fmt::format("{}: {} keyframes; a character has at most {} sample poses", what,
                                                     input->count, kMaxCharacterSamples));
  }
  const bool rotation = track.path == "rotation";
  auto output = real_accessor(model, sampler.output, rotation ? TINYGLTF_TYPE_VEC4 : TINYGLTF_TYPE_VEC3, rotation,
                              what + " (keyframe values)");
  if (!output) return output.error();
  if (output->count != input->count) {
    return make_error(Errc::parse_error,
                      fmt::format("{}: {} keyframe times but {} values", what, input->count, output->count));
  }
  for (std::size_t i = 0; i < input->count; ++i) {
    const double t = input->get(i, 0);
    if (!std::isfinite(t))
      return make_error(Errc::parse_error, fmt::format("{}: keyframe {}'s time is not finite", what, i));
    if (i > 0 && !(t > track.times_s.back())) {
      return make_error(Errc::parse_error,
                        fmt::format("{}: keyframe times must increase, but keyframe {} is at {} s after {} s", what, i,
                                    t, track.times_s.back()));
    }
    track.times_s.push_back(t);
    Eigen::Vector4d v = Eigen::Vector4d::Zero();
    for (int k = 0; k < output->components; ++k) v[k] = output->get(i, k);
    if (!v.allFinite())
      return make_error(Errc::parse_error, fmt::format("{}: keyframe {}'s value is not finite", what, i));
    if (rotation) {
      if (v.norm() < 1e-6)
        return make_error(Errc::parse_error, fmt::format("{}: keyframe {}'s rotation is zero", what, i));
      v.normalize();
    }
    track.values.push_back(v);
  }
  return track;
}

glm::mat4 pose_to_mat4(const Pose& T) {
  const Eigen::Matrix4d m = T.matrix();
  glm::mat4 out(1.0f);
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) out[c][r] = static_cast<float>(m(r, c));
  return out;
}

}  // namespace character_io
}  // namespace

Status Character::validate() const {
  const std::string label = fmt::format("character '{}'", name);
  if (auto s = skeleton.validate(); !s) return s.error().with_context(label);
  if (sample_poses.size() != sample_names.size()) {
    return make_error(Errc::invalid_argument, fmt::format("{}: {} sample poses but {} sample names", label,
                                                          sample_poses.size(), sample_names.size()));
  }
  if (sample_poses.size() > kMaxCharacterSamples) {
    return make_error(Errc::invalid_argument, fmt::format("{}: {} sample poses; at most {} are supported", label,
                                                          sample_poses.size(), kMaxCharacterSamples));
  }
  for (std::size_t i = 0; i < sample_poses.size(); ++i) {
    if (auto s = validate_pose(skeleton, sample_poses[i]); !s) {
      return s.error().with_context(fmt::format("{}: sample pose {} ('{}')", label, i, sample_names[i]));
    }
  }
  if (auto s = mesh.validate(); !s) return s.error().with_context(label);
  if (mesh.indices.empty()) {
    return make_error(Errc::invalid_argument,
                      label + ": the mesh has no triangles (node weights come from the skinned surface)");
  }
  if (mesh_joint_node.size() != mesh.joint_names.size()) {
    return make_error(Errc::invalid_argument, fmt::format("{}: {} mesh joints but {} entries in mesh_joint_node", label,
                                                          mesh.joint_names.size(), mesh_joint_node.size()));
  }
  std::vector<bool> used(skeleton.size(), false);
  for (std::size_t j = 0; j < mesh_joint_node.size(); ++j) {
    const int node = mesh_joint_node[j];
    if (node < 0 || static_cast<std::size_t>(node) >= skeleton.size()) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{}: mesh joint {} ('{}') maps to node {}, not one of the {}", label, j,
                                    mesh.joint_names[j], node, skeleton.size()));
    }
    if (used[static_cast<std::size_t>(node)]) {
      return make_error(Errc::invalid_argument, fmt::format("{}: two mesh joints map to node '{}'", label,
                                                            skeleton.names[static_cast<std::size_t>(node)]));
    }
    used[static_cast<std::size_t>(node)] = true;
    if (mesh.joint_names[j] != skeleton.names[static_cast<std::size_t>(node)]) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{}: mesh joint {} is named '{}' but its node is '{}'", label, j,
                                    mesh.joint_names[j], skeleton.names[static_cast<std::size_t>(node)]));
    }
  }
  return {};
}

Result<Character> load_character_gltf(const std::filesystem::path& file) {
  using namespace character_io;
  const std::string where = printable(file.string());
  tinygltf::Model model;
  if (auto s = detail::read_gltf_file(model, file); !s) return s.error();

  int skinned = -1;
  for (std::size_t i = 0; i < model.nodes.size(); ++i) {
    if (model.nodes[i].mesh >= 0 && model.nodes[i].skin >= 0) {
      skinned = static_cast<int>(i);
      break;
    }
  }
  if (skinned < 0) {
    return make_error(Errc::parse_error,
                      fmt::format("glTF file '{}' has no skinned mesh (no node with both a mesh and a skin); a "
                                  "character needs a skeleton (the skin's joints) and a surface",
                                  where));
  }
  const int skin_index = model.nodes[static_cast<std::size_t>(skinned)].skin;
  if (static_cast<std::size_t>(skin_index) >= model.skins.size()) {
    return make_error(Errc::parse_error, fmt::format("{}: {} names skin {}, which does not exist", where,
                                                     node_label(model, skinned), skin_index));
  }
  const tinygltf::Skin& skin = model.skins[static_cast<std::size_t>(skin_index)];
  const std::size_t n = skin.joints.size();
  if (n == 0) return make_error(Errc::parse_error, fmt::format("{}: the skin has no joints", where));
  if (n > kMaxSkeletonNodes) {
    return make_error(Errc::unsupported,
                      fmt::format("{}: the skin has {} joints; at most {} are supported", where, n, kMaxSkeletonNodes));
  }
  std::unordered_map<int, int> slot_of_node;  // glTF node -> skin slot
  for (std::size_t s = 0; s < n; ++s) {
    const int g = skin.joints[s];
    if (g < 0 || static_cast<std::size_t>(g) >= model.nodes.size()) {
      return make_error(Errc::parse_error,
                        fmt::format("{}: skin joint {} is node {}, which does not exist", where, s, g));
    }
    if (!slot_of_node.emplace(g, static_cast<int>(s)).second) {
      return make_error(Errc::parse_error, fmt::format("{}: the skin lists {} twice", where, node_label(model, g)));
    }
  }
  auto parents = node_parents(model);
  if (!parents) return parents.error().with_context(where);
  const std::vector<int>& parent = *parents;

  // World transforms at rest of the joints and everything above them, from
  // the top down (memoised: chains of helper nodes are walked once).
  std::vector<std::optional<Pose>> world(model.nodes.size());
  std::vector<int> chain;
  auto world_of = [&](int g) -> Result<Pose> {
    chain.clear();
    for (int a = g; a >= 0 && !world[static_cast<std::size_t>(a)]; a = parent[static_cast<std::size_t>(a)])
      chain.push_back(a);
    for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
      auto local = node_local_pose(model, *it);
      if (!local) return local.error();
      const int p = parent[static_cast<std::size_t>(*it)];
      world[static_cast<std::size_t>(*it)] = p < 0 ? *local : *world[static_cast<std::size_t>(p)] * *local;
    }
    return *world[static_cast<std::size_t>(g)];
  };

  // Skin slot -> parent slot (nearest joint ancestor) and the fixed transform
  // C from that parent's frame (or the world) to the joint's glTF parent.
  // The nearest joint at or above each node (-1: none), memoised like the
  // world transforms, so long helper chains are not walked once per joint.
  constexpr int kUnknown = -2;
  std::vector<int> joint_at_or_above(model.nodes.size(), kUnknown);
  auto anchor_of = [&](int g) {
    chain.clear();
    int a = g;
    while (a >= 0 && joint_at_or_above[static_cast<std::size_t>(a)] == kUnknown && !slot_of_node.count(a)) {
      chain.push_back(a);
      a = parent[static_cast<std::size_t>(a)];
    }
    const int found = a < 0 ? -1 : (slot_of_node.count(a) ? a : joint_at_or_above[static_cast<std::size_t>(a)]);
    for (int c : chain) joint_at_or_above[static_cast<std::size_t>(c)] = found;
    return found;
  };

  std::vector<int> slot_parent(n, -1);
  std::vector<Pose> C(n);
  std::vector<Pose> T_parent_joint(n);
  for (std::size_t s = 0; s < n; ++s) {
    const int g = skin.joints[s];
    auto T_world_g = world_of(g);
    if (!T_world_g) return T_world_g.error().with_context(where);
    const int gp = parent[static_cast<std::size_t>(g)];
    const int a = gp >= 0 ? anchor_of(gp) : -1;
    const Pose T_world_anchor = a >= 0 ? *world[static_cast<std::size_t>(a)] : Pose::identity();
    const Pose T_world_gp = gp >= 0 ? *world[static_cast<std::size_t>(gp)] : Pose::identity();
    slot_parent[s] = a >= 0 ? slot_of_node.at(a) : -1;
    C[s] = T_world_anchor.inverse() * T_world_gp;
    T_parent_joint[s] = T_world_anchor.inverse() * *T_world_g;
  }

  // Skeleton order: the skin's when it lists parents first, else depth-first.
  std::vector<int> order(n);  // skeleton index -> skin slot
  bool parents_first = true;
  for (std::size_t s = 0; s < n; ++s) parents_first = parents_first && slot_parent[s] < static_cast<int>(s);
  if (parents_first) {
    for (std::size_t s = 0; s < n; ++s) order[s] = static_cast<int>(s);
  } else {
    std::vector<std::vector<int>> kids(n);
    std::vector<int> stack;
    for (std::size_t s = n; s-- > 0;) {
      if (slot_parent[s] >= 0)
        kids[static_cast<std::size_t>(slot_parent[s])].push_back(static_cast<int>(s));
      else
        stack.push_back(static_cast<int>(s));
    }
    // kids and stack hold slots in reverse, so popping visits them in skin order.
    order.clear();
    while (!stack.empty()) {
      const int s = stack.back();
      stack.pop_back();
      order.push_back(s);
      for (int k : kids[static_cast<std::size_t>(s)]) stack.push_back(k);
    }
  }
  std::vector<int> index_of_slot(n);
  for (std::size_t i = 0; i < n; ++i) index_of_slot[static_cast<std::size_t>(order[i])] = static_cast<int>(i);

  Character character;
  std::unordered_set<std::string> names;
  for (std::size_t i = 0; i < n; ++i) {
    const auto s = static_cast<std::size_t>(order[i]);
    const int g = skin.joints[s];
    std::string name = model.nodes[static_cast<std::size_t>(g)].name;
    if (name.empty()) name = fmt::format("node{}", g);
    if (!names.insert(name).second) {
      return make_error(Errc::parse_error, fmt::format("{}: two joints are named '{}'; joint names must be unique",
                                                       where, printable(name, 80)));
    }
    const int p = slot_parent[s] >= 0 ? index_of_slot[static_cast<std::size_t>(slot_parent[s])] : -1;
    character.skeleton.add(std::move(name), p, T_parent_joint[s].p, T_parent_joint[s].q.normalized());
  }
  if (auto s = character.skeleton.validate(); !s) return s.error().with_context(where);

  // Sample poses: one per keyframe time of each animation's joint rotations.
  // Channels may share accessors, so the keyframes read are bounded too: no
  // more than the largest output (every node in every sample) could need.
  constexpr std::size_t kMaxKeyframesRead = kMaxSkeletonNodes * kMaxCharacterSamples;
  std::size_t total_samples = 0, keyframes_read = 0;
  for (std::size_t a = 0; a < model.animations.size(); ++a) {
    const tinygltf::Animation& anim = model.animations[a];
    const std::string anim_name = anim.name.empty() ? fmt::format("animation{}", a) : anim.name;
    const std::string anim_label = fmt::format("{}: animation {} ('{}')", where, a, printable(anim_name, 80));
    std::vector<Track> rotations;
    std::optional<Track> root_translation;
    std::vector<bool> rotated(n, false);
    for (std::size_t c = 0; c < anim.channels.size(); ++c) {
      const tinygltf::AnimationChannel& channel = anim.channels[c];
      const std::string what = fmt::format("{}, channel {}", anim_label, c);
      if (channel.target_node < 0 || static_cast<std::size_t>(channel.target_node) >= model.nodes.size()) {
        return make_error(Errc::parse_error,
                          fmt::format("{}: targets node {}, which does not exist", what, channel.target_node));
      }
      const auto slot = slot_of_node.find(channel.target_node);
      if (slot == slot_of_node.end()) continue;  // props and helpers do not pose the skeleton
      const int index = index_of_slot[static_cast<std::size_t>(slot->second)];
      const std::string what_node = fmt::format("{} ({} of '{}')", what, channel.target_path,
                                                character.skeleton.names[static_cast<std::size_t>(index)]);
      const bool rotation = channel.target_path == "rotation";
      const bool scale = channel.target_path == "scale";
      const bool root_move = channel.target_path == "translation" && index == 0;
      if (!rotation && !scale && !root_move) continue;
      if (rotation && rotated[static_cast<std::size_t>(slot->second)]) {
        return make_error(Errc::parse_error, what_node + ": a second rotation channel for the same node");
      }
      if (rotation) rotated[static_cast<std::size_t>(slot->second)] = true;
      auto track = read_track(model, anim, channel, slot->second, what_node);
      if (!track) return track.error();
      keyframes_read += track->times_s.size();
      if (keyframes_read > kMaxKeyframesRead) {
        return make_error(Errc::unsupported,
                          fmt::format("{}: the animations hold more than {} keyframes; a character "
                                      "has at most {} nodes in {} sample poses",
                                      what, kMaxKeyframesRead, kMaxSkeletonNodes, kMaxCharacterSamples));
      }
      if (scale) {
        for (const auto& v : track->values) {
          if ((v.head<3>() - Vec3::Ones()).cwiseAbs().maxCoeff() > kUnitScaleTolerance) {
            return make_error(Errc::unsupported,
                              fmt::format("{}: animates scale to ({}, {}, {}); Proprio's skeletons are rigid (unit "
                                          "scale)",
                                          what_node, v[0], v[1], v[2]));
          }
        }
      } else if (rotation) {
        rotations.push_back(std::move(*track));
      } else {
        root_translation = std::move(*track);
      }
    }
    if (rotations.empty()) continue;
    std::vector<double> times;
    for (const Track& t : rotations) times.insert(times.end(), t.times_s.begin(), t.times_s.end());
    std::sort(times.begin(), times.end());
    std::vector<double> keys;
    for (double t : times)
      if (keys.empty() || t - keys.back() > kSameTime_s) keys.push_back(t);
    total_samples += keys.size();
    if (total_samples > kMaxCharacterSamples) {
      return make_error(Errc::unsupported, fmt::format("{}: the animations hold more than {} keyframe times; a "
                                                       "character has at most {} sample poses",
                                                       anim_label, kMaxCharacterSamples, kMaxCharacterSamples));
    }
    std::vector<std::string> stored_names;
    if (anim.extras.IsObject() && anim.extras.Has("proprio_sample_names")) {
      const tinygltf::Value& list = anim.extras.Get("proprio_sample_names");
      if (list.IsArray() && list.ArrayLen() == keys.size()) {
        for (std::size_t k = 0; k < keys.size(); ++k) {
          const tinygltf::Value& v = list.Get(static_cast<int>(k));
          if (!v.IsString()) break;
          stored_names.push_back(v.Get<std::string>());
        }
        if (stored_names.size() != keys.size()) stored_names.clear();
      }
    }
    for (std::size_t k = 0; k < keys.size(); ++k) {
      SkeletonPose pose = rest_pose(character.skeleton);
      for (const Track& track : rotations) {
        const auto s = static_cast<std::size_t>(track.joint);
        pose.q_parent_node[static_cast<std::size_t>(index_of_slot[s])] =
            (C[s].q * track.rotation_at(keys[k])).normalized();
      }
      if (root_translation) {
        const auto s = static_cast<std::size_t>(order[0]);
        const Vec3 t_local = root_translation->vector_at(keys[k]).head<3>();
        pose.t_world_root_m = C[s] * t_local - character.skeleton.t_parent_node_m[0];
      }
      character.sample_poses.push_back(std::move(pose));
      character.sample_names.push_back(stored_names.empty() ? fmt::format("{}#{}", anim_name, k) : stored_names[k]);
    }
  }

  auto mesh = load_skinned_gltf(file);
  if (!mesh) return mesh.error();
  if (mesh->joint_names.size() != n) {
    return make_error(Errc::parse_error,
                      fmt::format("{}: the mesh has {} joints but the skin {}", where, mesh->joint_names.size(), n));
  }
  character.mesh = std::move(*mesh);
  character.mesh_joint_node.resize(n);
  for (std::size_t s = 0; s < n; ++s) {
    const int index = index_of_slot[s];
    character.mesh_joint_node[s] = index;
    character.mesh.joint_names[s] = character.skeleton.names[static_cast<std::size_t>(index)];
  }

  const int scene = model.defaultScene >= 0 && static_cast<std::size_t>(model.defaultScene) < model.scenes.size()
                        ? model.defaultScene
                        : (model.scenes.empty() ? -1 : 0);
  if (scene >= 0 && !model.scenes[static_cast<std::size_t>(scene)].name.empty()) {
    character.name = model.scenes[static_cast<std::size_t>(scene)].name;
  } else {
    character.name = character.mesh.name.empty() ? file.stem().string() : character.mesh.name;
  }
  if (auto s = character.validate(); !s) return s.error().with_context(where);
  return character;
}

Status save_character_gltf(const Character& character, const std::filesystem::path& file) {
  using namespace character_io;
  if (auto s = character.validate(); !s) return s;
  if (file.extension() == ".glb") {
    // The loader reads .glb as binary glTF; this writes text with embedded buffers.
    return make_error(Errc::invalid_argument, fmt::format("'{}': characters are saved as .gltf (text with embedded "
                                                          "buffers), not .glb",
                                                          printable(file.string())));
  }
  const Skeleton& skel = character.skeleton;
  const SkinnedMeshData& mesh = character.mesh;
  const std::size_t n = skel.size();
  const std::size_t samples = character.sample_poses.size();

  // Skin joints: the mesh's, in order (JOINTS_0 indexes them), then the
  // skeleton nodes the mesh does not use, bound at their rest pose.
  std::vector<int> joints(character.mesh_joint_node.begin(), character.mesh_joint_node.end());
  std::vector<glm::mat4> inverse_bind = mesh.inverse_bind;
  {
    std::vector<bool> in_skin(n, false);
    for (int j : joints) in_skin[static_cast<std::size_t>(j)] = true;
    std::vector<Pose> T_world_rest;
    forward_kinematics(skel, rest_pose(skel), T_world_rest);
    for (std::size_t i = 0; i < n; ++i) {
      if (in_skin[i]) continue;
      joints.push_back(static_cast<int>(i));
      inverse_bind.push_back(pose_to_mat4(T_world_rest[i].inverse()));
    }
  }
  bool root_moves = false;
  for (const SkeletonPose& p : character.sample_poses) root_moves = root_moves || !p.t_world_root_m.isZero();

  const std::size_t vertex_bytes = mesh.vertices.size() * sizeof(SkinnedVertex);
  const std::size_t index_bytes = mesh.indices.size() * sizeof(std::uint32_t);
  const std::size_t ibm_bytes = inverse_bind.size() * sizeof(glm::mat4);
  const std::size_t time_bytes = samples * sizeof(float);
  const std::size_t rotation_bytes = n * samples * 4 * sizeof(float);
  const std::size_t translation_bytes = root_moves ? samples * 3 * sizeof(float) : 0;
  tinygltf::Buffer buffer;
  buffer.data.resize(vertex_bytes + index_bytes + ibm_bytes + time_bytes + rotation_bytes + translation_bytes);
  unsigned char* out = buffer.data.data();
  std::memcpy(out, mesh.vertices.data(), vertex_bytes);
  std::memcpy(out + vertex_bytes, mesh.indices.data(), index_bytes);
  for (std::size_t j = 0; j < inverse_bind.size(); ++j) {
    std::memcpy(out + vertex_bytes + index_bytes + j * sizeof(glm::mat4), glm::value_ptr(inverse_bind[j]),
                sizeof(glm::mat4));
  }
  const std::size_t time_offset = vertex_bytes + index_bytes + ibm_bytes;
  const std::size_t rotation_offset = time_offset + time_bytes;
  const std::size_t translation_offset = rotation_offset + rotation_bytes;
  for (std::size_t k = 0; k < samples; ++k) {
    const float t = static_cast<float>(k);
    std::memcpy(out + time_offset + k * sizeof(float), &t, sizeof(float));
    const SkeletonPose& pose = character.sample_poses[k];
    for (std::size_t i = 0; i < n; ++i) {
      const Quat& q = pose.q_parent_node[i];
      const float xyzw[4] = {static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()),
                             static_cast<float>(q.w())};
      std::memcpy(out + rotation_offset + (i * samples + k) * sizeof(xyzw), xyzw, sizeof(xyzw));
    }
    if (root_moves) {
      const Vec3 t_root = skel.t_parent_node_m[0] + pose.t_world_root_m;
      const float xyz[3] = {static_cast<float>(t_root.x()), static_cast<float>(t_root.y()),
                            static_cast<float>(t_root.z())};
      std::memcpy(out + translation_offset + k * sizeof(xyz), xyz, sizeof(xyz));
    }
  }

  tinygltf::Model model;
  model.buffers.push_back(std::move(buffer));
  auto view = [&](std::size_t offset, std::size_t length, int stride, int target) {
    tinygltf::BufferView v;
    v.buffer = 0;
    v.byteOffset = offset;
    v.byteLength = length;
    v.byteStride = static_cast<std::size_t>(stride);
    v.target = target;
    model.bufferViews.push_back(v);
    return static_cast<int>(model.bufferViews.size()) - 1;
  };
  auto accessor = [&](int buffer_view, std::size_t offset, int component, std::size_t count, int type) {
    tinygltf::Accessor a;
    a.bufferView = buffer_view;
    a.byteOffset = offset;
    a.componentType = component;
    a.count = count;
    a.type = type;
    model.accessors.push_back(a);
    return static_cast<int>(model.accessors.size()) - 1;
  };
  const int vertex_view = view(0, vertex_bytes, sizeof(SkinnedVertex), TINYGLTF_TARGET_ARRAY_BUFFER);
  const int index_view = view(vertex_bytes, index_bytes, 0, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
  const int ibm_view = view(vertex_bytes + index_bytes, ibm_bytes, 0, 0);

  tinygltf::Primitive prim;
  prim.mode = TINYGLTF_MODE_TRIANGLES;
  prim.attributes["POSITION"] = accessor(vertex_view, offsetof(SkinnedVertex, position), TINYGLTF_COMPONENT_TYPE_FLOAT,
                                         mesh.vertices.size(), TINYGLTF_TYPE_VEC3);
  {
    glm::vec3 lo = mesh.vertices.front().position, hi = lo;
    for (const auto& v : mesh.vertices) {
      lo = glm::min(lo, v.position);
      hi = glm::max(hi, v.position);
    }
    model.accessors.back().minValues = {lo.x, lo.y, lo.z};  // glTF requires POSITION's bounds
    model.accessors.back().maxValues = {hi.x, hi.y, hi.z};
  }
  prim.attributes["NORMAL"] = accessor(vertex_view, offsetof(SkinnedVertex, normal), TINYGLTF_COMPONENT_TYPE_FLOAT,
                                       mesh.vertices.size(), TINYGLTF_TYPE_VEC3);
  prim.attributes["JOINTS_0"] =
      accessor(vertex_view, offsetof(SkinnedVertex, joints), TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT,
               mesh.vertices.size(), TINYGLTF_TYPE_VEC4);
  prim.attributes["WEIGHTS_0"] = accessor(vertex_view, offsetof(SkinnedVertex, weights), TINYGLTF_COMPONENT_TYPE_FLOAT,
                                          mesh.vertices.size(), TINYGLTF_TYPE_VEC4);
  prim.indices =
      accessor(index_view, 0, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, mesh.indices.size(), TINYGLTF_TYPE_SCALAR);
  tinygltf::Mesh gltf_mesh;
  gltf_mesh.name = mesh.name;
  gltf_mesh.primitives.push_back(prim);
  model.meshes.push_back(gltf_mesh);

  tinygltf::Skin skin;
  skin.name = character.name + "_skin";
  skin.inverseBindMatrices =
      accessor(ibm_view, 0, TINYGLTF_COMPONENT_TYPE_FLOAT, inverse_bind.size(), TINYGLTF_TYPE_MAT4);
  skin.joints = joints;
  model.skins.push_back(skin);

  tinygltf::Scene scene;
  scene.name = character.name;
  const auto kids = skel.children();
  for (std::size_t i = 0; i < n; ++i) {
    tinygltf::Node node;
    node.name = skel.names[i];
    const Vec3& t = skel.t_parent_node_m[i];
    const Quat& q = skel.q_parent_node_rest[i];
    node.translation = {t.x(), t.y(), t.z()};
    node.rotation = {q.x(), q.y(), q.z(), q.w()};
    node.children = kids[i];
    if (skel.parent[i] < 0) scene.nodes.push_back(static_cast<int>(i));
    model.nodes.push_back(std::move(node));
  }
  tinygltf::Node mesh_node;  // its own transform is ignored for skinned meshes (glTF 2.0 §3.7.3)
  mesh_node.name = mesh.name.empty() ? character.name + "_mesh" : mesh.name;
  mesh_node.mesh = 0;
  mesh_node.skin = 0;
  scene.nodes.push_back(static_cast<int>(model.nodes.size()));
  model.nodes.push_back(std::move(mesh_node));
  model.scenes.push_back(scene);

  if (samples > 0) {
    tinygltf::Animation anim;
    anim.name = "samples";
    const int times =
        accessor(view(time_offset, time_bytes, 0, 0), 0, TINYGLTF_COMPONENT_TYPE_FLOAT, samples, TINYGLTF_TYPE_SCALAR);
    model.accessors.back().minValues = {0.0};  // glTF requires an animation input's bounds
    model.accessors.back().maxValues = {static_cast<double>(samples - 1)};
    const int rotation_view = view(rotation_offset, rotation_bytes, 0, 0);
    auto channel = [&](int output, int node, const char* path) {
      tinygltf::AnimationSampler sampler;
      sampler.input = times;
      sampler.output = output;
      sampler.interpolation = "LINEAR";
      anim.samplers.push_back(sampler);
      tinygltf::AnimationChannel ch;
      ch.sampler = static_cast<int>(anim.samplers.size()) - 1;
      ch.target_node = node;
      ch.target_path = path;
      anim.channels.push_back(ch);
    };
    for (std::size_t i = 0; i < n; ++i) {
      channel(accessor(rotation_view, i * samples * 4 * sizeof(float), TINYGLTF_COMPONENT_TYPE_FLOAT, samples,
                       TINYGLTF_TYPE_VEC4),
              static_cast<int>(i), "rotation");
    }
    if (root_moves) {
      channel(accessor(view(translation_offset, translation_bytes, 0, 0), 0, TINYGLTF_COMPONENT_TYPE_FLOAT, samples,
                       TINYGLTF_TYPE_VEC3),
              0, "translation");
    }
    tinygltf::Value::Array names;
    for (const std::string& s : character.sample_names) names.emplace_back(s);
    tinygltf::Value::Object extras;
    extras.emplace("proprio_sample_names", tinygltf::Value(std::move(names)));
    anim.extras = tinygltf::Value(std::move(extras));
    model.animations.push_back(std::move(anim));
  }
  return detail::write_gltf_file(model, file);
}

std::vector<double> skin_area_per_node_m2(const Character& character) {
  const SkinnedMeshData& mesh = character.mesh;
  std::vector<double> area(character.skeleton.size(), 0.0);
  for (std::size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
    const SkinnedVertex* v[3] = {&mesh.vertices[mesh.indices[t]], &mesh.vertices[mesh.indices[t + 1]],
                                 &mesh.vertices[mesh.indices[t + 2]]};
    const glm::dvec3 a(v[0]->position), b(v[1]->position), c(v[2]->position);
    const double third = glm::length(glm::cross(b - a, c - a)) / 6.0;
    for (const SkinnedVertex* vertex : v) {
      for (std::size_t k = 0; k < kMaxInfluences; ++k) {
        const double w = vertex->weights[static_cast<glm::length_t>(k)];
        if (w > 0.0) area[static_cast<std::size_t>(character.mesh_joint_node[vertex->joints[k]])] += third * w;
      }
    }
  }
  return area;
}

void character_skin_matrices(const Character& character, std::span<const Pose> T_world_node,
                             std::vector<glm::mat4>& skin) {
  const std::size_t joints = character.mesh.joint_names.size();
  skin.resize(joints);
  for (std::size_t j = 0; j < joints; ++j) {
    skin[j] = character_io::pose_to_mat4(T_world_node[static_cast<std::size_t>(character.mesh_joint_node[j])]) *
              character.mesh.inverse_bind[j];
  }
}

void skin_character(const Character& character, std::span<const Pose> T_world_node, std::vector<glm::mat4>& skin,
                    std::vector<Vertex>& out) {
  character_skin_matrices(character, T_world_node, skin);
  out.resize(character.mesh.vertices.size());
  skin_vertices(character.mesh.vertices, skin, out);
}

}  // namespace proprio::render
