#include "proprio/rig_live/plan_device.hpp"

#include <algorithm>
#include <cmath>
#include <unordered_set>

#include "proprio/rig_device/joint_kinematics.hpp"

namespace proprio::rig_live {
namespace {

using rig_plan::DeviceModule;
using rig_plan::Plan;

// splitmix64: IDs that look like the hashes of programming times.
std::uint64_t mix(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

const rig_device::SplitterKind* splitter_kind(const rig_device::Kit& kit, const std::string& name) {
  for (const auto& k : kit.splitter_kinds)
    if (k.name == name) return &k;
  return nullptr;
}

double smoothstep(double s) { return s * s * (3.0 - 2.0 * s); }

}  // namespace

Result<PlanBusTree> bus_tree_for_plan(const Plan& plan, std::uint64_t seed) {
  if (plan.modules.empty()) return make_error(Errc::invalid_argument, "the plan has no modules to assemble");
  PlanBusTree out;
  std::unordered_set<std::uint32_t> used{rig_bus::kNoComponent};
  std::uint64_t state = mix(seed ^ 0x5249475F42555331ull);
  auto next_id = [&] {
    std::uint32_t id = 0;
    do {
      state = mix(state);
      id = static_cast<std::uint32_t>(state);
    } while (!used.insert(id).second);
    return id;
  };
  // Root modules plug into the base's outlet their parent_outlet names.
  int base_outlets = 0;
  for (const auto& m : plan.modules)
    if (m.parent_module < 0) base_outlets = std::max(base_outlets, m.parent_outlet + 1);
  if (base_outlets < 1 || base_outlets > static_cast<int>(rig_bus::kMaxOutlets))
    return make_error(Errc::invalid_argument, "the plan's device needs " + std::to_string(base_outlets) +
                                                  " outlets on the base; it has 1 to 8");
  rig_bus::BusComponentSpec base;
  base.id = next_id();
  base.kind = rig_bus::ComponentKind::base;
  base.kind_name = "base";
  base.q_inlet_outlet.assign(static_cast<std::size_t>(base_outlets), Quat::Identity());
  out.tree.components.push_back(base);
  for (std::size_t i = 0; i < plan.modules.size(); ++i) {
    const DeviceModule& m = plan.modules[i];
    rig_bus::BusComponentSpec c;
    c.id = next_id();
    if (m.type == DeviceModule::Type::joint) {
      c.kind = rig_bus::ComponentKind::joint;
      c.kind_name = "joint";
      c.colour_rgb = {70, 140, 230};
      c.q_inlet_outlet = {Quat::Identity()};
    } else {
      const auto* kind = splitter_kind(plan.kit, m.kind);
      if (!kind)
        return make_error(Errc::invalid_argument, "plan module " + std::to_string(i) + " is a splitter of kind '" + m.kind +
                                                      "', which the plan's kit does not have");
      c.kind = rig_bus::ComponentKind::splitter;
      c.kind_name = m.kind;
      c.colour_rgb = {230, 120, 50};
      c.q_inlet_outlet = kind->q_inlet_outlet;
    }
    if (m.parent_module < 0) {
      c.parent = 0;
      c.parent_outlet = static_cast<std::uint8_t>(std::max(0, m.parent_outlet));
    } else {
      if (m.parent_module >= static_cast<int>(i))
        return make_error(Errc::invalid_argument, "plan module " + std::to_string(i) + " comes before its parent");
      c.parent = m.parent_module + 1;
      c.parent_outlet = static_cast<std::uint8_t>(std::max(0, m.parent_outlet));
    }
    out.module_id.push_back(c.id);
    out.module_of.emplace(c.id, static_cast<int>(i));
    out.tree.components.push_back(std::move(c));
  }
  if (auto st = out.tree.validate(); !st) return st.error().with_context("the plan's device as a bus");
  return out;
}

Status AnimatorOptions::validate() const {
  if (!(seconds_per_pose >= 0.2 && seconds_per_pose <= 600.0))
    return make_error(Errc::invalid_argument, "seconds per pose must be in [0.2, 600]");
  if (!(hold_fraction >= 0.0 && hold_fraction < 1.0))
    return make_error(Errc::invalid_argument, "the hold fraction must be in [0, 1)");
  return {};
}

std::string AnimatorOptions::describe() const {
  return "animator: " + std::to_string(seconds_per_pose) + " s per sample pose, held for " +
         std::to_string(static_cast<int>(std::lround(100.0 * hold_fraction))) + " % of it";
}

Result<PlanAnimator> PlanAnimator::create(const Plan& plan, AnimatorOptions options) {
  if (auto st = options.validate(); !st) return st.error();
  if (plan.device_poses.empty()) return make_error(Errc::invalid_argument, "the plan has no fitted device poses to animate");
  PlanAnimator a;
  a.options_ = options;
  for (const auto& m : plan.modules) a.rest_.push_back(m.type == DeviceModule::Type::joint ? m.q_in_out_rest : Quat::Identity());
  for (std::size_t s = 0; s < plan.device_poses.size(); ++s) {
    if (plan.device_poses[s].size() != plan.modules.size())
      return make_error(Errc::invalid_argument, "the plan's device pose " + std::to_string(s) + " has " +
                                                    std::to_string(plan.device_poses[s].size()) + " rotations for " +
                                                    std::to_string(plan.modules.size()) + " modules");
    a.poses_.push_back(plan.device_poses[s]);
  }
  return a;
}

void PlanAnimator::segment(double t_s, std::size_t& from, std::size_t& to, double& s) const {
  // Keys: 0 = rest, then 1..S the samples, cycling 1..S after the first move.
  const double period = options_.seconds_per_pose;
  const double k = std::floor(std::max(0.0, t_s) / period);
  const double u = std::max(0.0, t_s) / period - k;
  const std::size_t n = poses_.size();
  const auto step = static_cast<std::size_t>(k);
  from = step == 0 ? 0 : 1 + (step - 1) % n;
  to = 1 + step % n;
  const double move = 1.0 - options_.hold_fraction;
  s = u < move ? smoothstep(u / move) : 1.0;
}

std::size_t PlanAnimator::target_sample(double t_s) const {
  std::size_t from = 0, to = 0;
  double s = 0.0;
  segment(t_s, from, to, s);
  return to - 1;
}

Quat PlanAnimator::q_in_out(double t_s, std::size_t module) const {
  std::size_t from = 0, to = 0;
  double s = 0.0;
  segment(t_s, from, to, s);
  return key(from)[module].slerp(s, key(to)[module]).normalized();
}

void PlanAnimator::q_in_out(double t_s, std::vector<Quat>& out) const {
  std::size_t from = 0, to = 0;
  double s = 0.0;
  segment(t_s, from, to, s);
  out.resize(rest_.size());
  for (std::size_t m = 0; m < rest_.size(); ++m) out[m] = key(from)[m].slerp(s, key(to)[m]).normalized();
}

Status EmulatedDeviceOptions::validate() const { return animator.validate(); }

std::string EmulatedDeviceOptions::describe() const {
  return std::string(hall_sensors ? "joints: simulated Hall sensors through each joint's jig calibration"
                                  : "joints: exact angles on the wire (no sensor model)") +
         "; " + animator.describe() + "; seed " + std::to_string(seed);
}

Result<std::shared_ptr<EmulatedPlanDevice>> EmulatedPlanDevice::create(const Plan& plan, const PlanBusTree& tree,
                                                                       const EmulatedDeviceOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  auto animator = PlanAnimator::create(plan, options.animator);
  if (!animator) return animator.error();
  std::shared_ptr<EmulatedPlanDevice> device(
      new EmulatedPlanDevice(std::move(*animator), tree.module_of, options.hall_sensors, options.seed));
  if (options.hall_sensors) {
    for (std::size_t m = 0; m < plan.modules.size(); ++m) {
      if (plan.modules[m].type != DeviceModule::Type::joint) continue;
      rig_device::HallJointOptions jo;
      jo.kind = plan.kit.joint;
      jo.seed = mix(options.seed * 1000003ull + m);
      auto joint = rig_device::EmulatedJoint::create(jo);
      if (!joint) return joint.error().with_context("joint module " + std::to_string(m) + "'s sensors");
      device->joints_.emplace(static_cast<int>(m), std::move(*joint));
    }
  }
  return device;
}

rig_device::JointAngles EmulatedPlanDevice::angles(TimeNs t_ns, std::uint32_t component_id) {
  const auto it = module_of_.find(component_id);
  if (it == module_of_.end()) return {};
  const double t_s = static_cast<double>(t_ns) * 1e-9;
  // Our joint has a redundant twist; the animator leaves the inlet ring alone.
  const rig_device::JointAngles commanded =
      rig_device::joint_angles_for(animator_.q_in_out(t_s, static_cast<std::size_t>(it->second)), 0.0);
  if (!hall_) return commanded;
  const auto joint = joints_.find(it->second);
  if (joint == joints_.end()) return {};
  rig_device::JointEnvironment env;
  env.ambient_field_world_t = Vec3(0.0, rig_device::kEarthFieldT * 0.4, -rig_device::kEarthFieldT * 0.9);
  return joint->second.step(commanded, env, rng_);
}

rig_bus::BusAnglesFn angles_callback(std::shared_ptr<EmulatedPlanDevice> device) {
  return [device = std::move(device)](TimeNs t_ns, std::uint32_t id) { return device->angles(t_ns, id); };
}

}  // namespace proprio::rig_live
