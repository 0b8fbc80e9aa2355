#include "character_builder.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <glm/glm.hpp>

namespace proprio::rig_characters::detail {
namespace {

// Capsule tessellation: enough for areas within a few per cent of the smooth
// surface, small enough that the 100-bone creature stays a ~1 MB glTF.
constexpr int kAround = 10;
constexpr int kCapRings = 3;
constexpr int kAlong = 4;
// The share of a bone's length over which its skin blends into the next bone.
constexpr double kBlend = 0.3;

double smoothstep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

glm::vec3 to_vec3(const Vec3& v) {
  return {static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z())};
}

// One tapered capsule from a (radius ra) to b (radius rb), owned by node
// `owner`: its skin blends into `child` towards b and into `grand` towards a
// (half-and-half at the joints), so bending a joint stretches the skin
// instead of tearing it.
void add_capsule(render::SkinnedMeshData& mesh, const Vec3& a, const Vec3& b, double ra, double rb, int owner,
                 int child, int grand) {
  const Vec3 ab = b - a;
  const double length = ab.norm();
  if (length < 1e-6) return;
  const Vec3 d = ab / length;
  const Vec3 u = (std::abs(d.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY()).cross(d).normalized();
  const Vec3 v = d.cross(u);  // (u, v, d) right-handed: CCW rings seen from outside
  // The profile along the axis: z, radius, and the normal's axial/radial parts.
  struct Ring {
    double z, r, n_axial, n_radial;
  };
  std::vector<Ring> rings;
  const double slope = (ra - rb) / length;
  for (int i = 1; i <= kCapRings; ++i) {
    const double th = -std::numbers::pi / 2 + std::numbers::pi / 2 * i / kCapRings;
    rings.push_back({ra * std::sin(th), ra * std::cos(th), std::sin(th), std::cos(th)});
  }
  for (int i = 1; i < kAlong; ++i) {
    const double f = static_cast<double>(i) / kAlong;
    rings.push_back({length * f, ra + (rb - ra) * f, slope, 1.0});
  }
  for (int i = 0; i < kCapRings; ++i) {
    const double th = std::numbers::pi / 2 * i / kCapRings;
    rings.push_back({length + rb * std::sin(th), rb * std::cos(th), std::sin(th), std::cos(th)});
  }

  auto vertex = [&](const Vec3& p, const Vec3& n, double z) {
    render::SkinnedVertex out;
    out.position = to_vec3(p);
    out.normal = to_vec3(n.normalized());
    const double s = std::clamp(z / length, 0.0, 1.0);
    const double w_child = child >= 0 ? 0.5 * smoothstep((s - (1.0 - kBlend)) / kBlend) : 0.0;
    const double w_grand = grand >= 0 ? 0.5 * smoothstep((kBlend - s) / kBlend) : 0.0;
    // Unused influences name joint 0, as glTF readers store them.
    out.joints = {static_cast<std::uint16_t>(owner), static_cast<std::uint16_t>(w_child > 0.0 ? child : 0),
                  static_cast<std::uint16_t>(w_grand > 0.0 ? grand : 0), 0};
    out.weights = glm::vec4(static_cast<float>(1.0 - w_child - w_grand), static_cast<float>(w_child),
                            static_cast<float>(w_grand), 0.0f);
    mesh.vertices.push_back(out);
    return static_cast<std::uint32_t>(mesh.vertices.size() - 1);
  };
  const std::uint32_t south = vertex(a - ra * d, -d, -ra);
  std::vector<std::uint32_t> first(rings.size());
  for (std::size_t k = 0; k < rings.size(); ++k) {
    first[k] = static_cast<std::uint32_t>(mesh.vertices.size());
    for (int j = 0; j < kAround; ++j) {
      const double phi = 2.0 * std::numbers::pi * j / kAround;
      const Vec3 radial = std::cos(phi) * u + std::sin(phi) * v;
      vertex(a + rings[k].z * d + rings[k].r * radial, rings[k].n_axial * d + rings[k].n_radial * radial, rings[k].z);
    }
  }
  const std::uint32_t north = vertex(b + rb * d, d, length + rb);
  auto& idx = mesh.indices;
  const auto around = static_cast<std::uint32_t>(kAround);
  for (std::uint32_t j = 0; j < around; ++j) {
    const std::uint32_t jn = (j + 1) % around;
    idx.insert(idx.end(), {south, first.front() + jn, first.front() + j});
    for (std::size_t k = 0; k + 1 < rings.size(); ++k) {
      const std::uint32_t a0 = first[k] + j, a1 = first[k] + jn, b0 = first[k + 1] + j, b1 = first[k + 1] + jn;
      idx.insert(idx.end(), {a0, a1, b0, a1, b1, b0});
    }
    idx.insert(idx.end(), {first.back() + j, first.back() + jn, north});
  }
}

}  // namespace

Quat rx(double deg) { return Quat(Eigen::AngleAxisd(deg * std::numbers::pi / 180.0, Vec3::UnitX())); }
Quat ry(double deg) { return Quat(Eigen::AngleAxisd(deg * std::numbers::pi / 180.0, Vec3::UnitY())); }
Quat rz(double deg) { return Quat(Eigen::AngleAxisd(deg * std::numbers::pi / 180.0, Vec3::UnitZ())); }

Quat mirrored(const Quat& q, double side) { return side > 0 ? q : Quat(q.w(), q.x(), -q.y(), -q.z()); }

void CharacterBuilder::add(std::string name, std::string_view parent, const Vec3& t_parent_node_m, double radius_m,
                           const Vec3& tip_m, double tip_radius_m) {
  int p = -1;
  if (!parent.empty()) {
    p = character_.skeleton.find(parent);
    if (p < 0 && error_.empty()) error_ = "node '" + name + "' has an unknown parent '" + std::string(parent) + "'";
  }
  character_.skeleton.add(std::move(name), p, t_parent_node_m);
  radius_m_.push_back(radius_m);
  tip_m_.push_back(tip_m);
  tip_radius_m_.push_back(tip_radius_m > 0.0 ? tip_radius_m : 0.7 * radius_m);
}

void CharacterBuilder::turn(SkeletonPose& pose, std::string_view node, const Quat& q) {
  const int i = character_.skeleton.find(node);
  if (i < 0) {
    if (error_.empty()) error_ = "a pose turns the unknown node '" + std::string(node) + "'";
    return;
  }
  Quat& target = pose.q_parent_node[static_cast<std::size_t>(i)];
  target = (target * q).normalized();
}

double CharacterBuilder::lowest_point_m(const SkeletonPose& pose) const {
  std::vector<Pose> T;
  forward_kinematics(character_.skeleton, pose, T);
  double low = T[0].p.y() - radius_m_[0];
  for (std::size_t i = 0; i < T.size(); ++i) {
    low = std::min(low, T[i].p.y() - radius_m_[i]);
    if (!tip_m_[i].isZero()) low = std::min(low, (T[i] * tip_m_[i]).y() - tip_radius_m_[i]);
  }
  return low;
}

void CharacterBuilder::ground(SkeletonPose& pose) const {
  pose.t_world_root_m.y() += lowest_point_m(rest()) - lowest_point_m(pose);
}

void CharacterBuilder::add_pose(std::string name, SkeletonPose pose) {
  character_.sample_names.push_back(std::move(name));
  character_.sample_poses.push_back(std::move(pose));
}

Result<render::Character> CharacterBuilder::build() const {
  if (!error_.empty())
    return make_error(Errc::invalid_argument, "example character '" + character_.name + "': " + error_);
  if (auto s = character_.skeleton.validate(); !s) return s.error();
  render::Character out = character_;
  const Skeleton& skel = out.skeleton;
  const std::size_t n = skel.size();
  std::vector<Pose> T_world_rest;
  forward_kinematics(skel, rest(), T_world_rest);

  render::SkinnedMeshData& mesh = out.mesh;
  mesh.name = out.name;
  for (std::size_t i = 0; i < n; ++i) {
    mesh.joint_names.push_back(skel.names[i]);
    // Bind space is the world at rest.
    const Eigen::Matrix4d m = T_world_rest[i].inverse().matrix();
    glm::mat4 ibm(1.0f);
    for (int c = 0; c < 4; ++c)
      for (int r = 0; r < 4; ++r) ibm[c][r] = static_cast<float>(m(r, c));
    mesh.inverse_bind.push_back(ibm);
    out.mesh_joint_node.push_back(static_cast<int>(i));
  }
  for (std::size_t i = 0; i < n; ++i) {
    const int p = skel.parent[i];
    if (p >= 0) {
      // A limb leaving the body starts barely wider than the limb: the body's
      // own bones already cover the trunk, and a trunk-sized ball at every
      // shoulder and hip would inflate the girdle's skin area.
      const double start_m = std::min(radius_m_[static_cast<std::size_t>(p)], 1.25 * radius_m_[i]);
      add_capsule(mesh, T_world_rest[static_cast<std::size_t>(p)].p, T_world_rest[i].p, start_m, radius_m_[i], p,
                  static_cast<int>(i), skel.parent[static_cast<std::size_t>(p)]);
    }
    if (!tip_m_[i].isZero()) {
      add_capsule(mesh, T_world_rest[i].p, T_world_rest[i] * tip_m_[i], radius_m_[i], tip_radius_m_[i],
                  static_cast<int>(i), -1, p);
    }
  }
  if (auto s = out.validate(); !s) return s.error();
  return out;
}

}  // namespace proprio::rig_characters::detail
