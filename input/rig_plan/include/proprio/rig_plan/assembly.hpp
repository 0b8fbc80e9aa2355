#pragma once
// Assembly instructions for a device plan (thesis Fig. 3.6 right, Fig. 3.9):
// what to plug where, in build order, and a picture of the character with the
// driven nodes and splitters numbered the same way.
//
// Build order is plan order (parents first, so every step plugs into a module
// already built); module k of the text is mark k of the picture and "module k"
// in binding messages (module_label, plan_io.hpp).
//
// Text, per step: the module, where it plugs in (base, or which outlet of
// which module), the rig node it drives (joints) or sits on (splitters, with
// the rig branch each outlet follows), and its rest setting: for a joint the
// ring and hinge angles of q_in_out_rest in degrees (rig_device::
// joint_angles_for, inlet twist held at 0); for a splitter its turn about the
// inlet shaft.
//
// Picture (SVG): the rest skeleton in a front view (x right, y up) and a side
// view (z right, y up) at one scale, bones as lines, each joint a red disc
// and each splitter a blue square on its node, both numbered; a legend lists
// the numbers. Each module's marks are one group <g id="module-k">.
#include <string>

#include "proprio/core/result.hpp"
#include "proprio/rig_plan/plan.hpp"

namespace proprio::rig_plan {

struct AssemblyOptions {
  double view_width_px = 480.0;   // each of the two views
  double view_height_px = 520.0;
  bool label_all_nodes = false;   // name every rig node in the picture, not only the marked ones
  Status validate() const;
  std::string describe() const;
};

// Both check the skeleton and the plan against it (validate_plan).
Result<std::string> assembly_text(const RigInput& input, const Plan& plan);
Result<std::string> assembly_svg(const RigInput& input, const Plan& plan, const AssemblyOptions& options = {});

}  // namespace proprio::rig_plan
