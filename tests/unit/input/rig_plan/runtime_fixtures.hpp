#pragma once
// A small hand-made character and device plan for the rig_plan runtime tests
// (pose space, retargeting, plan files, binding, assembly).
//
//   root - spine - chest -+- neck - head
//                         +- l_arm - l_fore
//                         +- r_arm - r_fore
// Plan (parents first): 1 joint on spine (base), 2 T3 splitter on chest,
// 3 joint on neck (T3 outlet 0), 4 joint on l_arm (outlet 1), 5 joint on
// r_arm (outlet 2), 6 joint on l_fore (after joint 4).
// The device poses invert the mapping M for each sample, so sample i's driven
// rotations are exactly what device pose i gives.
#include <cmath>
#include <string>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/skeleton.hpp"
#include "proprio/rig_device/kit.hpp"
#include "proprio/rig_plan/plan.hpp"

namespace proprio::rig_plan::test_fixtures {

inline Quat random_rotation(Rng& rng, double max_angle_rad) {
  Vec3 axis(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1));
  if (axis.norm() < 1e-3) axis = Vec3::UnitX();
  return so3_exp(axis.normalized() * rng.uniform(0.0, max_angle_rad));
}

inline Skeleton small_skeleton() {
  Skeleton s;
  const Quat tilt = so3_exp(Vec3(0.0, 0.0, 0.1));
  s.add("root", -1, Vec3(0, 0.9, 0));
  s.add("spine", 0, Vec3(0, 0.2, 0));
  s.add("chest", 1, Vec3(0, 0.25, 0.02), tilt);
  s.add("neck", 2, Vec3(0, 0.2, 0));
  s.add("head", 3, Vec3(0, 0.15, 0.03));
  s.add("l_arm", 2, Vec3(0.18, 0.1, 0));
  s.add("l_fore", 5, Vec3(0.25, 0, 0));
  s.add("r_arm", 2, Vec3(-0.18, 0.1, 0), tilt.conjugate());
  s.add("r_fore", 7, Vec3(-0.25, 0, 0));
  return s;
}

inline RigInput small_input(int samples = 8, std::uint64_t seed = 31) {
  RigInput input;
  input.name = "stick figure";
  input.skeleton = small_skeleton();
  Rng rng(seed);
  for (int i = 0; i < samples; ++i) {
    SkeletonPose pose = rest_pose(input.skeleton);
    for (Quat& q : pose.q_parent_node) q = (random_rotation(rng, 0.9) * q).normalized();
    input.samples.push_back(pose);
    input.sample_names.push_back("pose " + std::to_string(i));
  }
  input.area_m2.assign(input.skeleton.size(), 0.01);
  return input;
}

inline Quat mapping_inverse(const DeviceModule& joint, const Quat& q_parent_node_rest, const Quat& q_parent_node) {
  // q_node = (I D I^-1) q_rest  =>  D = I^-1 q_node q_rest^-1 I;  q_in_out = D q_in_out_rest
  const Quat delta = joint.q_parent_inlet.conjugate() * q_parent_node * q_parent_node_rest.conjugate() * joint.q_parent_inlet;
  return (delta * joint.q_in_out_rest).normalized();
}

inline Plan small_plan(const RigInput& input) {
  Plan plan;
  plan.character = input.name;
  plan.kit = rig_device::default_kit();
  Rng rng(7);
  const auto joint = [&](int node, int parent, int outlet) {
    DeviceModule m;
    m.type = DeviceModule::Type::joint;
    m.kind = "joint";
    m.rig_node = node;
    m.parent_module = parent;
    m.parent_outlet = outlet;
    m.q_parent_inlet = random_rotation(rng, 2.0);
    m.q_in_out_rest = random_rotation(rng, 0.6);
    return m;
  };
  plan.modules.push_back(joint(1, -1, 0));
  DeviceModule t3;
  t3.type = DeviceModule::Type::splitter;
  t3.kind = "T3";
  t3.rig_node = 2;
  t3.parent_module = 0;
  t3.parent_outlet = 0;
  t3.q_parent_inlet = random_rotation(rng, 1.0);
  t3.q_in_out_rest = so3_exp(Vec3(0, 0, 0.5));
  t3.outlet_rig_child = {3, 5, 7};
  t3.angular_error_rad = 0.05;
  plan.modules.push_back(t3);
  plan.modules.push_back(joint(3, 1, 0));
  plan.modules.push_back(joint(5, 1, 1));
  plan.modules.push_back(joint(7, 1, 2));
  plan.modules.push_back(joint(6, 3, 0));
  plan.error_rigid = 0.02;
  plan.error_after_joint = {0.01, 0.006, 0.004, 0.003, 0.002};
  plan.error_final = 0.002;
  for (const SkeletonPose& sample : input.samples) {
    std::vector<Quat> device(plan.modules.size(), Quat::Identity());
    for (std::size_t m = 0; m < plan.modules.size(); ++m) {
      const DeviceModule& module = plan.modules[m];
      if (module.type != DeviceModule::Type::joint) continue;
      const auto b = static_cast<std::size_t>(module.rig_node);
      device[m] = mapping_inverse(module, input.skeleton.q_parent_node_rest[b], sample.q_parent_node[b]);
    }
    plan.device_poses.push_back(device);
  }
  return plan;
}

inline std::vector<std::vector<Quat>> rotations_of(const RigInput& input) {
  std::vector<std::vector<Quat>> out;
  for (const SkeletonPose& p : input.samples) out.push_back(p.q_parent_node);
  return out;
}

}  // namespace proprio::rig_plan::test_fixtures
