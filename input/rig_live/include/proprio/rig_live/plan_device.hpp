#pragma once
// A plan's device, assembled in simulation: the bus tree of its modules (as
// the emulated bus runs it), a scripted animator who poses the device through
// the plan's fitted device poses, and the joints' angles as the joints' own
// microcontrollers report them (the Hall-sensor joint simulator and its jig
// calibration, rig_device::EmulatedJoint). `proprio rig emulate`, `rig live`
// and `bench rig` share it. The animator is the ground truth: the host side
// never sees it.
#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/rig_bus/bus_emulator.hpp"
#include "proprio/rig_device/joint_accuracy.hpp"
#include "proprio/rig_plan/plan.hpp"

namespace proprio::rig_live {

// The plan's modules as a bus tree: [0] the base (one outlet per device root),
// then one component per plan module in plan order. IDs stand for the
// programming-time hashes of the real parts: distinct, seeded.
struct PlanBusTree {
  rig_bus::BusTree tree;
  std::vector<std::uint32_t> module_id;  // plan module -> component ID
  std::unordered_map<std::uint32_t, int> module_of;  // component ID -> plan module
};
Result<PlanBusTree> bus_tree_for_plan(const rig_plan::Plan& plan, std::uint64_t seed = 1);

struct AnimatorOptions {
  double seconds_per_pose = 3.0;  // from one sample pose to the next
  double hold_fraction = 0.35;    // of that, held still at the pose
  Status validate() const;
  std::string describe() const;
};

// Cycles rest -> sample 0 -> sample 1 -> ... -> sample 0 ..., each move a
// smoothstep slerp per joint (an animator turning every joint at once, as the
// thesis's users do with two hands and a chain). q_in_out per plan module;
// splitters stay at identity.
class PlanAnimator {
 public:
  static Result<PlanAnimator> create(const rig_plan::Plan& plan, AnimatorOptions options = {});
  void q_in_out(double t_s, std::vector<Quat>& out) const;
  Quat q_in_out(double t_s, std::size_t module) const;
  std::size_t modules() const { return rest_.size(); }
  // The sample pose the animator is at or heading to at t_s.
  std::size_t target_sample(double t_s) const;

 private:
  PlanAnimator() = default;
  void segment(double t_s, std::size_t& from, std::size_t& to, double& s) const;
  const std::vector<Quat>& key(std::size_t k) const { return k == 0 ? rest_ : poses_[k - 1]; }
  AnimatorOptions options_;
  std::vector<Quat> rest_;
  std::vector<std::vector<Quat>> poses_;
};

struct EmulatedDeviceOptions {
  bool hall_sensors = true;  // the joints' Hall sensors and calibration; false: exact angles on the wire
  AnimatorOptions animator;
  std::uint64_t seed = 1;
  Status validate() const;
  std::string describe() const;
};

// The angles each joint of the plan's device reports at emulator time t:
// the animator's pose through each joint's sensors and calibration. Owned
// by the bus emulator's callback (one thread); the Earth-like ambient field
// is on, the device standing upright.
class EmulatedPlanDevice {
 public:
  static Result<std::shared_ptr<EmulatedPlanDevice>> create(const rig_plan::Plan& plan, const PlanBusTree& tree,
                                                            const EmulatedDeviceOptions& options);
  rig_device::JointAngles angles(TimeNs t_ns, std::uint32_t component_id);
  const PlanAnimator& animator() const { return animator_; }

 private:
  EmulatedPlanDevice(PlanAnimator animator, std::unordered_map<std::uint32_t, int> module_of, bool hall, std::uint64_t seed)
      : animator_(std::move(animator)), module_of_(std::move(module_of)), hall_(hall), rng_(seed) {}
  PlanAnimator animator_;
  std::unordered_map<std::uint32_t, int> module_of_;
  std::unordered_map<int, rig_device::EmulatedJoint> joints_;
  bool hall_;
  Rng rng_;
};

// The bus emulator's callback; it keeps the device alive.
rig_bus::BusAnglesFn angles_callback(std::shared_ptr<EmulatedPlanDevice> device);

}  // namespace proprio::rig_live
