#pragma once
// The device a simulated user poses in the hardware comparison of thesis §3.3
// ("Hardware comparison", App. A.3): a small tree of joints whose outlet
// bones are drawn on screen, with a semi-transparent target pose over it.
//
// Frames: world z is up, the screen's camera looks along world +y, so the
// image plane is world x-z and depth is world y. Each joint is a skeleton node
// whose local rotation is q_rest * q_in_out: q_rest turns the parent's frame
// into the joint's inlet shaft frame (the splitter's outlet direction), q_in_out
// is the joint's own rotation (joint_kinematics.hpp), shaft along +z.
// Terminal bones carry a short sideways marker node (a thumb, a nose) so that
// their twist shows on screen, as a character's hand or face would show it.
#include <cstdint>
#include <string>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/skeleton.hpp"

namespace proprio::rig_eval {

enum class PosingDeviceKind {
  humanoid6,  // torso, neck, two shoulders, two elbows on a splitter: 6 joints, 12 nodes
  chain,      // `chain_joints` joints in a row (tests, single-joint kinematics)
};
const char* to_string(PosingDeviceKind kind);

struct PosingDevice {
  Skeleton skeleton;
  std::vector<int> joint_node;        // skeleton node of each joint, proximal before distal
  std::vector<std::string> joint_names;
  // How far a realistic pose bends each joint (the outlet's angle from the
  // inlet shaft) and how much it twists it: shoulders and elbows range
  // widely, the torso and neck less (what character poses do).
  std::vector<double> max_bend_rad;
  std::vector<double> twist_sd_rad;

  std::size_t joint_count() const { return joint_node.size(); }
};

PosingDevice make_humanoid_device();
// segment_length_m: distance between successive joints.
PosingDevice make_chain_device(int joints, double segment_length_m = 0.06);

// A device pose: one q_in_out per joint (inlet to outlet shaft frame).
using JointRotations = std::vector<Quat>;

JointRotations straight_pose(const PosingDevice& device);
// T_world_node for the device in `pose`.
void device_forward_kinematics(const PosingDevice& device, const JointRotations& pose,
                               std::vector<Pose>& T_world_node);
// The thesis's pose error (eq. 3.1 / A.2 with unit node weights): the L2 norm
// of the stacked node-position differences, sqrt(sum_b |n_b - n~_b|^2), m.
double pose_error_m(const std::vector<Pose>& T_world_node_a, const std::vector<Pose>& T_world_node_b);
// Mean over joints of the absolute rotation angle between the two poses' q_in_out, rad.
double mean_joint_angle_error_rad(const JointRotations& a, const JointRotations& b);

// A realistic target pose: per joint the outlet bends by an angle drawn
// uniformly in [0.25, 1] x max_bend towards a uniformly drawn azimuth and
// twists by a normal draw (twist_sd, clipped at 2 SD). Seeded.
JointRotations sample_target_pose(const PosingDevice& device, Rng& rng);

}  // namespace proprio::rig_eval
