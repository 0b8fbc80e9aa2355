#include "proprio/core/skeleton.hpp"

#include <cassert>
#include <cmath>
#include <unordered_set>

namespace proprio {
namespace {

bool finite(const Vec3& v) { return v.allFinite(); }
bool unit(const Quat& q) { return q.coeffs().allFinite() && std::abs(q.squaredNorm() - 1.0) < 1e-6; }

}  // namespace

Status Skeleton::validate() const {
  const std::size_t n = names.size();
  if (n == 0) return make_error(Errc::invalid_argument, "the skeleton has no nodes");
  if (n > kMaxSkeletonNodes)
    return make_error(Errc::invalid_argument, "the skeleton has " + std::to_string(n) + " nodes; at most " +
                                                  std::to_string(kMaxSkeletonNodes) + " are supported");
  if (parent.size() != n || t_parent_node_m.size() != n || q_parent_node_rest.size() != n)
    return make_error(Errc::invalid_argument, "the skeleton's names, parents, offsets and rest rotations differ in count");
  std::unordered_set<std::string> seen;
  for (std::size_t i = 0; i < n; ++i) {
    const std::string label = "skeleton node " + std::to_string(i) + " ('" + names[i] + "')";
    if (names[i].empty()) return make_error(Errc::invalid_argument, "skeleton node " + std::to_string(i) + " has no name");
    if (!seen.insert(names[i]).second) return make_error(Errc::invalid_argument, label + ": the name is used twice");
    if (parent[i] < -1 || parent[i] >= static_cast<int>(i))
      return make_error(Errc::invalid_argument,
                        label + ": its parent (" + std::to_string(parent[i]) + ") must be -1 or an earlier node");
    if (!finite(t_parent_node_m[i])) return make_error(Errc::invalid_argument, label + ": its offset is not finite");
    if (!unit(q_parent_node_rest[i]))
      return make_error(Errc::invalid_argument, label + ": its rest rotation is not a unit quaternion");
  }
  return {};
}

std::vector<std::vector<int>> Skeleton::children() const {
  std::vector<std::vector<int>> out(size());
  for (std::size_t i = 0; i < size(); ++i)
    if (parent[i] >= 0) out[static_cast<std::size_t>(parent[i])].push_back(static_cast<int>(i));
  return out;
}

int Skeleton::find(std::string_view name) const {
  for (std::size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return static_cast<int>(i);
  return -1;
}

int Skeleton::add(std::string name, int parent_index, const Vec3& t_parent_node, const Quat& q_parent_node) {
  names.push_back(std::move(name));
  parent.push_back(parent_index);
  t_parent_node_m.push_back(t_parent_node);
  q_parent_node_rest.push_back(q_parent_node);
  return static_cast<int>(names.size()) - 1;
}

SkeletonPose rest_pose(const Skeleton& skeleton) {
  SkeletonPose pose;
  pose.q_parent_node = skeleton.q_parent_node_rest;
  return pose;
}

Status validate_pose(const Skeleton& skeleton, const SkeletonPose& pose) {
  if (pose.q_parent_node.size() != skeleton.size())
    return make_error(Errc::invalid_argument, "the pose has " + std::to_string(pose.q_parent_node.size()) +
                                                  " rotations for a skeleton of " + std::to_string(skeleton.size()) +
                                                  " nodes");
  for (std::size_t i = 0; i < pose.q_parent_node.size(); ++i)
    if (!unit(pose.q_parent_node[i]))
      return make_error(Errc::invalid_argument,
                        "the pose's rotation of node '" + skeleton.names[i] + "' is not a finite unit quaternion");
  if (!finite(pose.t_world_root_m)) return make_error(Errc::invalid_argument, "the pose's root translation is not finite");
  return {};
}

void forward_kinematics(const Skeleton& skeleton, const SkeletonPose& pose, std::vector<Pose>& T_world_node) {
  assert(skeleton.validate().ok() && validate_pose(skeleton, pose).ok());
  const std::size_t n = skeleton.size();
  T_world_node.resize(n);
  bool first_root = true;
  for (std::size_t i = 0; i < n; ++i) {
    Pose T_parent_node{pose.q_parent_node[i], skeleton.t_parent_node_m[i]};
    if (skeleton.parent[i] < 0) {
      if (first_root) T_parent_node.p += pose.t_world_root_m;
      first_root = false;
      T_world_node[i] = T_parent_node;
    } else {
      T_world_node[i] = T_world_node[static_cast<std::size_t>(skeleton.parent[i])] * T_parent_node;
    }
  }
}

}  // namespace proprio
