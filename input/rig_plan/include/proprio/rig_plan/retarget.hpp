#pragma once
// The retargeting function M of thesis §3.2.2 at run time: a live device's
// joint readings become a rig pose. Driven nodes follow their joints through
// the mapping in plan.hpp; every other node (and the node of a joint that is
// detached or missing) takes the pose-space interpolation of the samples
// (pose_space.hpp), or its rest rotation with the pose space off.
//
// The pose space's samples: each sample's own rotations, except on the driven
// nodes, which take the rotation the plan's fitted device pose P^D_i gives
// them through M (when the plan has device poses). Putting the device in P^D_i
// then lands exactly on sample i's blend, the fit's notion of that sample.
// Roots blend like any other node; the root translation stays at zero (the
// device senses local rotations only; the character's placement is set
// elsewhere, thesis §3.5).
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/skeleton.hpp"
#include "proprio/rig_plan/plan.hpp"
#include "proprio/rig_plan/pose_space.hpp"

namespace proprio::rig_plan {

struct RetargetOptions {
  bool pose_space = true;  // false: undriven nodes stay at rest
  PoseSpaceOptions pose_space_options;
  Status validate() const;
  std::string describe() const;
};

// q_parent_node(b) for a joint's reading, the M of plan.hpp.
Quat driven_rotation(const DeviceModule& joint, const Quat& q_parent_node_rest, const Quat& q_in_out);

class Retargeter {
 public:
  // Validates the input (RigInput::validate), the plan against its skeleton
  // (validate_plan) and the options.
  static Result<Retargeter> create(const RigInput& input, const Plan& plan, const RetargetOptions& options = {});

  // q_in_out: one entry per plan module, in plan order (splitters' entries
  // are ignored; std::nullopt: the joint is detached or missing). `pose` is
  // resized on the first call only; after that no call allocates. One
  // Retargeter per thread (it keeps a scratch mask).
  Status retarget(std::span<const std::optional<Quat>> q_in_out, SkeletonPose& pose);

  // The rig pose plan.device_poses[sample] maps to (every joint present).
  Result<SkeletonPose> device_pose_to_rig(int sample);

  const PoseSpace* pose_space() const { return pose_space_ ? &*pose_space_ : nullptr; }
  // The blend weights of the last retarget (pose space on).
  const PoseSpaceWeights& last_weights() const { return last_weights_; }
  std::size_t module_count() const { return module_count_; }

 private:
  Skeleton skeleton_;
  std::vector<DeviceModule> joints_;      // the plan's joints
  std::vector<int> joint_module_;         // their plan indices
  std::size_t module_count_ = 0;
  std::vector<std::vector<Quat>> device_poses_;
  std::optional<PoseSpace> pose_space_;
  std::vector<std::uint8_t> known_;       // per joint (= per feature node)
  PoseSpaceWeights last_weights_;
};

}  // namespace proprio::rig_plan
