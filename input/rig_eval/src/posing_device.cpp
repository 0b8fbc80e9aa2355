#include "proprio/rig_eval/posing_device.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace proprio::rig_eval {
namespace {

constexpr double kDeg = M_PI / 180.0;

Quat device_about(const Vec3& axis, double angle_rad) { return Quat(Eigen::AngleAxisd(angle_rad, axis)); }

// Appends one joint at `node` with its pose range.
void add_joint(PosingDevice& d, int node, std::string name, double max_bend_deg, double twist_sd_deg) {
  d.joint_node.push_back(node);
  d.joint_names.push_back(std::move(name));
  d.max_bend_rad.push_back(max_bend_deg * kDeg);
  d.twist_sd_rad.push_back(twist_sd_deg * kDeg);
}

}  // namespace

const char* to_string(PosingDeviceKind kind) {
  switch (kind) {
    case PosingDeviceKind::humanoid6: return "humanoid6";
    case PosingDeviceKind::chain: return "chain";
  }
  return "?";
}

PosingDevice make_humanoid_device() {
  // Sizes of a hand-held device (the thesis's modules are a few cm long);
  // errors are reported in percent of the initial error, so only ratios matter.
  PosingDevice d;
  Skeleton& s = d.skeleton;
  const int torso = s.add("torso", -1, Vec3::Zero());
  add_joint(d, torso, "torso", 30.0, 20.0);
  const int neck = s.add("neck", torso, Vec3(0, 0, 0.10));
  add_joint(d, neck, "neck", 35.0, 25.0);
  const int head = s.add("head", neck, Vec3(0, 0, 0.05));
  s.add("nose", head, Vec3(0, -0.02, 0));
  for (const double side : {1.0, -1.0}) {
    const bool left = side > 0;
    // The splitter's outlet points sideways: the shoulder's inlet z is world +-x.
    const int shoulder = s.add(left ? "shoulder_l" : "shoulder_r", torso, Vec3(side * 0.04, 0, 0.09),
                               device_about(Vec3::UnitY(), side * M_PI / 2));
    add_joint(d, shoulder, left ? "shoulder_l" : "shoulder_r", 85.0, 35.0);
    const int elbow = s.add(left ? "elbow_l" : "elbow_r", shoulder, Vec3(0, 0, 0.07));
    add_joint(d, elbow, left ? "elbow_l" : "elbow_r", 85.0, 30.0);
    const int wrist = s.add(left ? "wrist_l" : "wrist_r", elbow, Vec3(0, 0, 0.06));
    s.add(left ? "thumb_l" : "thumb_r", wrist, Vec3(0.02, 0, 0));
  }
  assert(s.validate().ok());
  return d;
}

PosingDevice make_chain_device(int joints, double segment_length_m) {
  PosingDevice d;
  Skeleton& s = d.skeleton;
  int parent = -1;
  for (int j = 0; j < std::max(joints, 1); ++j) {
    const std::string name = "joint" + std::to_string(j);
    parent = s.add(name, parent, parent < 0 ? Vec3::Zero() : Vec3(0, 0, segment_length_m));
    add_joint(d, parent, name, 75.0, 30.0);
  }
  const int tip = s.add("tip", parent, Vec3(0, 0, segment_length_m));
  s.add("marker", tip, Vec3(0.3 * segment_length_m, 0, 0));
  assert(s.validate().ok());
  return d;
}

JointRotations straight_pose(const PosingDevice& device) {
  return JointRotations(device.joint_count(), Quat::Identity());
}

void device_forward_kinematics(const PosingDevice& device, const JointRotations& pose,
                               std::vector<Pose>& T_world_node) {
  assert(pose.size() == device.joint_count());
  SkeletonPose sp;
  sp.q_parent_node = device.skeleton.q_parent_node_rest;
  for (std::size_t j = 0; j < device.joint_count(); ++j) {
    const auto node = static_cast<std::size_t>(device.joint_node[j]);
    sp.q_parent_node[node] = (device.skeleton.q_parent_node_rest[node] * pose[j]).normalized();
  }
  forward_kinematics(device.skeleton, sp, T_world_node);
}

double pose_error_m(const std::vector<Pose>& a, const std::vector<Pose>& b) {
  assert(a.size() == b.size());
  double sum = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) sum += (a[i].p - b[i].p).squaredNorm();
  return std::sqrt(sum);
}

double mean_joint_angle_error_rad(const JointRotations& a, const JointRotations& b) {
  assert(a.size() == b.size());
  if (a.empty()) return 0.0;
  double sum = 0.0;
  for (std::size_t j = 0; j < a.size(); ++j) sum += angle_between(a[j], b[j]);
  return sum / static_cast<double>(a.size());
}

JointRotations sample_target_pose(const PosingDevice& device, Rng& rng) {
  JointRotations pose(device.joint_count());
  for (std::size_t j = 0; j < device.joint_count(); ++j) {
    const double bend = rng.uniform(0.25, 1.0) * device.max_bend_rad[j];
    const double azimuth = rng.uniform(0.0, 2.0 * M_PI);
    const double sd = device.twist_sd_rad[j];
    const double twist = std::clamp(rng.normal(0.0, sd), -2.0 * sd, 2.0 * sd);
    // Swing about the horizontal axis at `azimuth`, then the twist about the outlet shaft.
    const Vec3 swing_axis(std::cos(azimuth), std::sin(azimuth), 0.0);
    pose[j] = (device_about(swing_axis, bend) * device_about(Vec3::UnitZ(), twist)).normalized();
  }
  return pose;
}

}  // namespace proprio::rig_eval
