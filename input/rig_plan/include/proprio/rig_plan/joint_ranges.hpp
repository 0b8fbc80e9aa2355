#pragma once
// Joints have mechanical stops (rig_device::JointKind::bend_limit_rad: per
// hinge and between the shafts), which the thesis's reduction does not know
// about: a device shaped exactly like the rig at rest can need a joint bent
// past its stop at rest already (a thigh hanging 90 degrees off a hip
// splitter's outlet), and the sample poses then ask for more.
//
// Each joint's rest setting is free ("the remaining rotational offset" of
// thesis §3.2.2 goes on the outgoing joint): changing it turns everything
// plugged in after the joint, so the modules below are re-expressed to keep
// their own outlets where they were, and every sample still maps to the same
// rig pose (the retargeting M of plan.hpp is unchanged). center_joint_ranges
// uses that freedom, joint by joint from the base, for the joints whose rest
// or sample settings come within a margin of the stop: the rest setting moves
// to the centre (minimax on the sphere) of the outlet directions the samples
// ask for, so the joint has room both ways. The device at rest then no longer
// copies the rig at rest exactly; the assembly instructions give the new
// settings.
#include <string>
#include <vector>

#include "proprio/rig_device/kit.hpp"
#include "proprio/rig_plan/plan.hpp"

namespace proprio::rig_plan {

// The angle between a joint's shafts for q_in_out (the Cardan joint's stop
// limits it; it bounds both hinges).
double shaft_angle_rad(const Quat& q_in_out);

struct JointRangeReport {
  struct Joint {
    int module = -1;
    double rest_shaft_rad = 0.0;
    double max_shaft_rad = 0.0;   // over the rest setting and the fitted sample poses
    int samples_past_stop = 0;    // fitted device poses this joint cannot reach
  };
  double limit_rad = 0.0;
  std::vector<Joint> joints;       // one per joint module, in plan order
  int joints_past_stop = 0;        // joints with any sample (or the rest) past the stop
  // Lines for the joints past their stop; node names from the skeleton when given.
  std::string describe(const Plan& plan, const Skeleton* skeleton = nullptr) const;
};

JointRangeReport joint_range_report(const Plan& plan);

// Re-centres the rest settings of joints whose settings come within
// margin_rad of the kit's stop (see the top of the file). Requires a plan
// with one device pose per sample (or none). Returns how many joints moved.
int center_joint_ranges(Plan& plan, double margin_rad = 0.1);

}  // namespace proprio::rig_plan
