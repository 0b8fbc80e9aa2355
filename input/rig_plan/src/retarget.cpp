#include "proprio/rig_plan/retarget.hpp"

#include <sstream>

#include "proprio/rig_plan/plan_io.hpp"

namespace proprio::rig_plan {

Status RetargetOptions::validate() const {
  if (Status s = pose_space_options.validate(); !s) return s.error().with_context("retarget options");
  return {};
}

std::string RetargetOptions::describe() const {
  std::ostringstream out;
  out << "retargeting: driven nodes by the plan's mapping; other nodes "
      << (pose_space ? "by " + pose_space_options.describe() : std::string("at rest"));
  return out.str();
}

Quat driven_rotation(const DeviceModule& joint, const Quat& q_parent_node_rest, const Quat& q_in_out) {
  const Quat delta = q_in_out * joint.q_in_out_rest.conjugate();
  return (joint.q_parent_inlet * delta * joint.q_parent_inlet.conjugate() * q_parent_node_rest).normalized();
}

Result<Retargeter> Retargeter::create(const RigInput& input, const Plan& plan, const RetargetOptions& options) {
  if (Status s = options.validate(); !s) return s.error();
  if (Status s = input.validate(); !s) return s.error();
  if (Status s = validate_plan(plan, input.skeleton.size()); !s) return s.error().with_context("the device plan");
  if (!plan.device_poses.empty() && plan.device_poses.size() != input.samples.size())
    return make_error(Errc::invalid_argument,
                      "the plan has " + std::to_string(plan.device_poses.size()) + " device poses but '" +
                          input.name + "' has " + std::to_string(input.samples.size()) +
                          " sample poses: the plan was computed for another sample set; recompute it");
  Retargeter r;
  r.skeleton_ = input.skeleton;
  r.module_count_ = plan.modules.size();
  r.device_poses_ = plan.device_poses;
  std::vector<int> feature_nodes;
  for (std::size_t i = 0; i < plan.modules.size(); ++i) {
    if (plan.modules[i].type != DeviceModule::Type::joint) continue;
    r.joints_.push_back(plan.modules[i]);
    r.joint_module_.push_back(static_cast<int>(i));
    feature_nodes.push_back(plan.modules[i].rig_node);
  }
  r.known_.assign(r.joints_.size(), 0);
  if (options.pose_space) {
    std::vector<std::vector<Quat>> rotations;
    rotations.reserve(input.samples.size());
    for (std::size_t i = 0; i < input.samples.size(); ++i) {
      std::vector<Quat> q = input.samples[i].q_parent_node;
      if (!plan.device_poses.empty())
        for (std::size_t k = 0; k < r.joints_.size(); ++k) {
          const auto b = static_cast<std::size_t>(r.joints_[k].rig_node);
          q[b] = driven_rotation(r.joints_[k], input.skeleton.q_parent_node_rest[b],
                                 plan.device_poses[i][static_cast<std::size_t>(r.joint_module_[k])]);
        }
      rotations.push_back(std::move(q));
    }
    auto space = PoseSpace::create(rotations, feature_nodes, options.pose_space_options);
    if (!space) return space.error().with_context("the pose space of '" + input.name + "'");
    r.pose_space_ = std::move(*space);
  }
  return r;
}

Status Retargeter::retarget(std::span<const std::optional<Quat>> q_in_out, SkeletonPose& pose) {
  if (q_in_out.size() != module_count_)
    return make_error(Errc::invalid_argument, "retarget: " + std::to_string(q_in_out.size()) +
                                                  " readings for a plan of " + std::to_string(module_count_) +
                                                  " modules (one per module, std::nullopt for a missing joint)");
  const std::size_t n = skeleton_.size();
  if (pose.q_parent_node.size() != n) pose.q_parent_node.resize(n);
  pose.t_world_root_m.setZero();
  // Rest first: what the pose space (or nothing) does not set stays at rest.
  for (std::size_t b = 0; b < n; ++b) pose.q_parent_node[b] = skeleton_.q_parent_node_rest[b];
  for (std::size_t k = 0; k < joints_.size(); ++k) {
    const auto& reading = q_in_out[static_cast<std::size_t>(joint_module_[k])];
    // A broken sensor's NaN is a missing joint, not a pose.
    const bool usable = reading.has_value() && reading->coeffs().allFinite() && reading->norm() > 0.5;
    known_[k] = usable ? 1 : 0;
    if (!usable) continue;
    const auto b = static_cast<std::size_t>(joints_[k].rig_node);
    pose.q_parent_node[b] = driven_rotation(joints_[k], skeleton_.q_parent_node_rest[b], reading->normalized());
  }
  if (pose_space_) last_weights_ = pose_space_->interpolate(pose.q_parent_node, known_);
  return {};
}

Result<SkeletonPose> Retargeter::device_pose_to_rig(int sample) {
  if (sample < 0 || static_cast<std::size_t>(sample) >= device_poses_.size())
    return make_error(Errc::out_of_range, "the plan has no device pose " + std::to_string(sample));
  std::vector<std::optional<Quat>> readings(module_count_);
  for (std::size_t i = 0; i < module_count_; ++i) readings[i] = device_poses_[static_cast<std::size_t>(sample)][i];
  SkeletonPose pose;
  if (Status s = retarget(readings, pose); !s) return s.error();
  return pose;
}

}  // namespace proprio::rig_plan
