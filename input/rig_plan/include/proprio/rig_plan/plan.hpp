#pragma once
// A device plan: which module of a kit goes where on a character's rig, and
// how the assembled device's rotations map back onto the rig (thesis ch. 3.2.2,
// App. A.2). Computed by reduce_rig (rig_reduction.hpp), saved as JSON
// (plan_io.hpp), bound to a live device's topology and turned into rig poses
// by the retargeter (retarget.hpp).
//
// Frames and the mapping M (eq. A.3) used everywhere:
// - A joint module j drives one rig node b (plan.modules[j].rig_node): the node
//   whose local rotation it sets. Rig nodes between two driven nodes keep their
//   rest (or pose-space interpolated) local rotation; they move rigidly with
//   their parent, as during fitting.
// - q_parent_inlet: the joint's inlet shaft frame (shaft along +z) in the frame
//   of b's rig parent at rest. q_in_out_rest: the joint's own rotation when the
//   character is at rest (the assembly instructions tell the user to set it).
// - A reading q_in_out gives Delta = q_in_out * q_in_out_rest^-1 in the inlet
//   frame, and b's local rotation becomes
//       q_parent_node(b) = (q_parent_inlet * Delta * q_parent_inlet^-1) * q_parent_node_rest(b).
#include <string>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/skeleton.hpp"
#include "proprio/rig_device/kit.hpp"

namespace proprio::rig_plan {

// What a plan is computed from: the character's skeleton, its sample poses and
// the skinned surface area bound to each node (m^2; from the skin weights).
struct RigInput {
  std::string name;
  Skeleton skeleton;
  std::vector<SkeletonPose> samples;
  std::vector<std::string> sample_names;
  std::vector<double> area_m2;  // one per node, >= 0
  Status validate() const;
};

struct DeviceModule {
  enum class Type { joint, splitter };
  Type type = Type::joint;
  std::string kind;            // "joint" or the splitter kind's name
  int rig_node = -1;           // joint: the node it drives; splitter: the branching node it sits on
  int parent_module = -1;      // -1 for the device's root module (it plugs into the base)
  int parent_outlet = 0;       // which outlet of the parent (0 for a joint parent)
  Quat q_parent_inlet = Quat::Identity();  // joints: see the header comment
  Quat q_in_out_rest = Quat::Identity();   // joints: rest setting; splitters: the splitter's orientation about its inlet
  std::vector<int> outlet_rig_child;       // splitters: per outlet, the rig child node its branch follows (-1 unused)
  double angular_error_rad = 0.0;          // splitters: the remaining outlet mismatch after Kabsch
};

struct Plan {
  std::string character;
  rig_device::Kit kit;
  std::vector<DeviceModule> modules;   // parents before children
  // Pose error (eq. 3.1, summed over the samples, in m^2 weighted) with no
  // joint, then after each joint the greedy phase placed (Fig. 3.7's curve),
  // and of the final device.
  double error_rigid = 0.0;
  std::vector<double> error_after_joint;
  double error_final = 0.0;
  // The fitted device poses P^D: per sample, one q_in_out per module (identity for splitters).
  std::vector<std::vector<Quat>> device_poses;
  int joint_count() const;
  int splitter_count() const;
};

}  // namespace proprio::rig_plan
