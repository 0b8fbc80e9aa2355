#pragma once
// A generic kinematic skeleton: named nodes in a tree, each with a rest offset
// and rest rotation relative to its parent, posed by local rotations only.
// Used by the rig device (issue 31) for characters of any topology; the hand
// has its own model (hand_model.hpp) with OpenXR's fixed 26 joints.
//
// Frames: node i's frame is T_parent_node(i) = [q_parent_node | t_parent_node_m]
// applied to its parent's; roots hang off the world. A pose replaces every
// node's local rotation (rest included) and may move the first root.
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"

namespace proprio {

// Far more nodes than any production rig (the thesis's dragon has 110 bones);
// bounds what a hostile file can make us allocate and solve.
inline constexpr std::size_t kMaxSkeletonNodes = 4096;

struct Skeleton {
  std::vector<std::string> names;                // unique, non-empty
  std::vector<int> parent;                       // -1 for a root; otherwise parent[i] < i
  std::vector<Vec3> t_parent_node_m;             // the node's origin in its parent's frame
  std::vector<Quat> q_parent_node_rest;          // the node's rest rotation in its parent's frame

  std::size_t size() const { return names.size(); }
  // Equal sizes; 1..kMaxSkeletonNodes nodes; parents earlier in the list (so
  // one forward pass poses the tree); finite offsets; unit rest rotations;
  // unique non-empty names. Messages name the node.
  Status validate() const;
  std::vector<std::vector<int>> children() const;
  int find(std::string_view name) const;  // -1 when absent
  // Appends a node and returns its index (parent must already exist or be -1).
  int add(std::string name, int parent_index, const Vec3& t_parent_node_m, const Quat& q_parent_node_rest = Quat::Identity());
};

struct SkeletonPose {
  std::vector<Quat> q_parent_node;  // one local rotation per node
  Vec3 t_world_root_m = Vec3::Zero();  // added to the first root's offset
};

SkeletonPose rest_pose(const Skeleton& skeleton);
// One unit, finite rotation per node; finite root translation.
Status validate_pose(const Skeleton& skeleton, const SkeletonPose& pose);
// T_world_node for every node; `T_world_node` is resized. The skeleton and
// pose must be valid (checked in debug builds only: this runs per frame).
void forward_kinematics(const Skeleton& skeleton, const SkeletonPose& pose, std::vector<Pose>& T_world_node);

}  // namespace proprio
