#include "proprio/core/hand_model.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace proprio {

namespace {

constexpr std::array<std::string_view, kHandDofCount> kDofNames = {
    "thumb_cmc_flexion",  "thumb_cmc_abduction",  "thumb_mcp_flexion",  "thumb_ip_flexion",
    "index_mcp_flexion",  "index_mcp_abduction",  "index_pip_flexion",  "index_dip_flexion",
    "middle_mcp_flexion", "middle_mcp_abduction", "middle_pip_flexion", "middle_dip_flexion",
    "ring_mcp_flexion",   "ring_mcp_abduction",   "ring_pip_flexion",   "ring_dip_flexion",
    "little_mcp_flexion", "little_mcp_abduction", "little_pip_flexion", "little_dip_flexion",
};

Quat rot_x(double a) { return Quat(Eigen::AngleAxisd(a, Vec3::UnitX())); }
Quat rot_y(double a) { return Quat(Eigen::AngleAxisd(a, Vec3::UnitY())); }

// Joint rotation of a 2-DOF joint: abduction about the parent's +Y, then
// flexion about the rotated +X. Flexion curls -Z (distal) toward -Y (palmar),
// which is a negative rotation about +X.
Quat flex_abd(double flexion, double abduction) { return rot_y(abduction) * rot_x(-flexion); }

// Inverse of flex_abd. M = Ry(a) Rx(b) has M(2,0) = -sin a, M(0,0) = cos a,
// M(1,2) = -sin b, M(1,1) = cos b, so both angles are recovered exactly.
void decompose_flex_abd(const Quat& q, double& flexion, double& abduction) {
  const Mat3 M = q.toRotationMatrix();
  abduction = std::atan2(-M(2, 0), M(0, 0));
  flexion = -std::atan2(-M(1, 2), M(1, 1));
}

// Mirror through W's YZ plane keeping frames right-handed: p.x -> -p.x and
// R -> S R S with S = diag(-1, 1, 1), i.e. (w, x, y, z) -> (w, x, -y, -z).
Pose mirror(const Pose& T) {
  return {Quat(T.q.w(), T.q.x(), -T.q.y(), -T.q.z()), Vec3(-T.p.x(), T.p.y(), T.p.z())};
}

double dof(const HandAngles& a, Finger f, std::size_t k) { return a[first_dof_of(f) + k]; }

}  // namespace

std::string_view to_string(HandDof d) noexcept {
  const auto i = index_of(d);
  return i < kDofNames.size() ? kDofNames[i] : std::string_view("invalid_dof");
}

JointLimits JointLimits::defaults() {
  // Degrees; active ranges of motion rounded from common clinical tables
  // (AAOS), trimmed where a glove would not let the hand go further.
  struct Range { double lo, hi; };
  constexpr std::array<Range, kHandDofCount> deg = {{
      {-15, 50}, {-15, 45}, {-10, 60}, {-15, 85},  // thumb: CMC flex, CMC abd, MCP, IP
      {-20, 90}, {-15, 25}, {0, 110}, {-5, 80},    // index: MCP flex, MCP abd, PIP, DIP
      {-20, 90}, {-15, 15}, {0, 110}, {-5, 80},    // middle
      {-20, 90}, {-20, 15}, {0, 110}, {-5, 80},    // ring
      {-20, 90}, {-30, 15}, {0, 110}, {-5, 80},    // little (spreads ulnar: negative)
  }};
  JointLimits l;
  for (std::size_t i = 0; i < kHandDofCount; ++i) {
    l.min_rad[i] = deg_to_rad(deg[i].lo);
    l.max_rad[i] = deg_to_rad(deg[i].hi);
  }
  return l;
}

HandAngles JointLimits::clamp(const HandAngles& a) const {
  HandAngles out;
  for (std::size_t i = 0; i < kHandDofCount; ++i) out[i] = std::clamp(a[i], min_rad[i], max_rad[i]);
  return out;
}

bool JointLimits::contains(const HandAngles& a, double tolerance_rad) const {
  for (std::size_t i = 0; i < kHandDofCount; ++i) {
    if (a[i] < min_rad[i] - tolerance_rad || a[i] > max_rad[i] + tolerance_rad) return false;
  }
  return true;
}

HandAngles Synergies::apply(HandAngles a) const {
  if (!enabled) return a;
  a[index_of(HandDof::thumb_ip_flexion)] = thumb_ip_from_mcp * a[index_of(HandDof::thumb_mcp_flexion)];
  for (auto f : {Finger::index, Finger::middle, Finger::ring, Finger::little}) {
    a[first_dof_of(f) + 3] = dip_from_pip * a[first_dof_of(f) + 2];
  }
  return a;
}

Result<HandShape> HandShape::from_measurements(double L, double B) {
  if (!(L >= 0.10 && L <= 0.30)) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "hand length %.4g m is outside 0.10-0.30 m (wrist crease to middle fingertip, in metres)", L);
    return make_error(Errc::out_of_range, buf);
  }
  if (!(B >= 0.05 && B <= 0.16)) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "hand width %.4g m is outside 0.05-0.16 m (thumb MCP to ulnar edge, in metres)", B);
    return make_error(Errc::out_of_range, buf);
  }
  HandShape s;
  s.hand_length_m = L;
  s.hand_width_m = B;

  // Segment lengths as fractions of hand length: Buchholz, Armstrong &
  // Goldstein, "Anthropometric data for describing the kinematics of the human
  // hand", Ergonomics 35(3), 1992, Table 1 (joint centre to joint centre).
  // The middle finger's chain sums to 0.928 L; the remaining 0.072 L places
  // the wrist joint so that wrist to middle fingertip is exactly L.
  constexpr std::array<std::array<double, 4>, kFingerCount> ratio = {{
      {0.251, 0.196, 0.158, 0.0},    // thumb: metacarpal, proximal, distal
      {0.374, 0.265, 0.143, 0.097},  // index: metacarpal, proximal, intermediate, distal
      {0.373, 0.277, 0.170, 0.108},  // middle
      {0.336, 0.259, 0.165, 0.107},  // ring
      {0.295, 0.206, 0.117, 0.093},  // little
  }};
  // Lateral layout across the palm as fractions of hand width, and depth of
  // the MCP heads as fractions of length. Our own approximation of an average
  // adult hand (the metacarpals fan out from the carpus); not from a table.
  struct Layout { double base_x, base_z, mcp_x, mcp_z; };
  constexpr std::array<Layout, kFingerCount> layout = {{
      {-0.22, -0.02, 0.0, 0.0},  // thumb: handled below
      {-0.10, -0.066, -0.17, -0.440},
      {-0.01, -0.072, -0.01, -0.445},
      {0.07, -0.089, 0.15, -0.425},
      {0.14, -0.090, 0.29, -0.385},
  }};
  // Skin radius at the MCP as a fraction of hand width; then tapering to the tip.
  constexpr std::array<double, kFingerCount> mcp_radius = {0.11, 0.092, 0.095, 0.088, 0.075};

  for (std::size_t f = 0; f < kFingerCount; ++f) {
    HandShape::Finger& g = s.fingers[f];
    g.bone_count = (f == 0) ? 3 : 4;
    for (std::size_t b = 0; b < 4; ++b) g.bone_length_m[b] = ratio[f][b] * L;
    const double r = mcp_radius[f] * B;
    if (f == 0) {
      g.p_base_in_wrist = Vec3(layout[0].base_x * B, -0.04 * B, layout[0].base_z * L);
      // The thumb metacarpal rests pointing distally, radially and palmarly,
      // pronated about 45 deg so it flexes across the palm.
      const Vec3 z = -Vec3(-0.55, -0.30, -0.78).normalized();
      const Vec3 y = (Vec3(-0.7, 0.7, 0.0) - Vec3(-0.7, 0.7, 0.0).dot(z) * z).normalized();
      g.q_wrist_metacarpal_rest = quat_from_axes(y.cross(z), y, z);
      g.joint_radius_m = {1.2 * r, r, 0.9 * r, 0.8 * r, 0.8 * r};
    } else {
      g.p_base_in_wrist = Vec3(layout[f].base_x * B, 0.0, layout[f].base_z * L);
      const Vec3 p_mcp_target(layout[f].mcp_x * B, 0.0, layout[f].mcp_z * L);
      const Vec3 z = (g.p_base_in_wrist - p_mcp_target).normalized();
      const Vec3 y = (Vec3::UnitY() - Vec3::UnitY().dot(z) * z).normalized();
      g.q_wrist_metacarpal_rest = quat_from_axes(y.cross(z), y, z);
      g.joint_radius_m = {1.1 * r, r, 0.9 * r, 0.8 * r, 0.7 * r};
    }
  }
  s.palm_radius_m = 0.15 * B;
  s.wrist_radius_m = 0.20 * B;
  return s;
}

namespace {
// Index to little MCP in the wrist frame, for a hand of these sizes.
double mcp_spread_m(double L, double B) {
  const auto shape = HandShape::from_measurements(L, B);
  if (!shape) return 0.0;
  const auto T = HandModel(*shape).joint_poses_in_wrist(Handedness::right, HandAngles{});
  return (T[index_of(HandJoint::index_proximal)].p - T[index_of(HandJoint::little_proximal)].p).norm();
}
}  // namespace

Result<HandShape> HandShape::from_tracked_pose(const HandPose& pose) {
  if (!pose.active || !pose.fully_valid()) {
    return make_error(Errc::invalid_argument, "the hand's size needs an active pose with every joint valid");
  }
  constexpr HandJoint kChain[] = {HandJoint::middle_metacarpal, HandJoint::middle_proximal, HandJoint::middle_intermediate,
                                  HandJoint::middle_distal, HandJoint::middle_tip};
  double chain = 0.0;
  for (std::size_t i = 0; i + 1 < std::size(kChain); ++i) chain += (pose.joint(kChain[i + 1]).p - pose.joint(kChain[i]).p).norm();
  // from_measurements' middle chain is 0.928 L (Buchholz et al. 1992).
  const double L = chain / 0.928;
  const double spread = (pose.joint(HandJoint::index_proximal).p - pose.joint(HandJoint::little_proximal).p).norm();
  if (!(L >= 0.10 && L <= 0.30)) return from_measurements(L, 0.10);  // its message says why
  // The spread grows with the width; bisect for the width that gives it.
  double lo = 0.05, hi = 0.16;
  if (!(spread >= mcp_spread_m(L, lo) && spread <= mcp_spread_m(L, hi))) {
    char buf[200];
    std::snprintf(buf, sizeof buf, "index-to-little MCP spread %.1f mm does not fit a hand %.0f mm long", spread * 1e3, L * 1e3);
    return make_error(Errc::out_of_range, buf);
  }
  for (int i = 0; i < 40; ++i) {
    const double mid = 0.5 * (lo + hi);
    (mcp_spread_m(L, mid) < spread ? lo : hi) = mid;
  }
  return from_measurements(L, 0.5 * (lo + hi));
}

std::string HandShape::describe() const {
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "hand length %.1f mm, width %.1f mm; index bones %.1f/%.1f/%.1f/%.1f mm; thumb bones %.1f/%.1f/%.1f mm",
                hand_length_m * 1e3, hand_width_m * 1e3, fingers[1].bone_length_m[0] * 1e3,
                fingers[1].bone_length_m[1] * 1e3, fingers[1].bone_length_m[2] * 1e3,
                fingers[1].bone_length_m[3] * 1e3, fingers[0].bone_length_m[0] * 1e3,
                fingers[0].bone_length_m[1] * 1e3, fingers[0].bone_length_m[2] * 1e3);
  return buf;
}

HandModel::HandModel(HandShape shape, JointLimits limits) : shape_(std::move(shape)), limits_(limits) {}

std::array<Pose, kHandJointCount> HandModel::joint_poses_in_wrist(Handedness hand, const HandAngles& a) const {
  std::array<Pose, kHandJointCount> T;
  T[index_of(HandJoint::wrist)] = Pose::identity();

  for (std::size_t fi = 0; fi < kFingerCount; ++fi) {
    const auto f = static_cast<Finger>(fi);
    const HandShape::Finger& g = shape_.fingers[fi];
    const FingerJoints fj = finger_joints(f);
    // Per joint along the chain: the rotation applied at that joint.
    std::array<Quat, 4> joint_rotation;
    Quat q = g.q_wrist_metacarpal_rest;
    if (f == Finger::thumb) {
      joint_rotation = {flex_abd(dof(a, f, 0), dof(a, f, 1)), rot_x(-dof(a, f, 2)), rot_x(-dof(a, f, 3)),
                        Quat::Identity()};
    } else {
      joint_rotation = {Quat::Identity(), flex_abd(dof(a, f, 0), dof(a, f, 1)), rot_x(-dof(a, f, 2)),
                        rot_x(-dof(a, f, 3))};
    }
    Vec3 p = g.p_base_in_wrist;
    for (std::size_t k = 0; k < g.bone_count; ++k) {
      q = (q * joint_rotation[k]).normalized();
      T[index_of(fj.joints[k])] = {q, p};
      p += q * Vec3(0, 0, -g.bone_length_m[k]);
    }
    T[index_of(fj.joints[fj.count - 1])] = {q, p};  // the tip keeps the distal bone's orientation
  }

  // Palm: midway between the middle finger's metacarpal and proximal joints.
  const Pose& mc = T[index_of(HandJoint::middle_metacarpal)];
  const Pose& prox = T[index_of(HandJoint::middle_proximal)];
  T[index_of(HandJoint::palm)] = {mc.q, 0.5 * (mc.p + prox.p)};

  if (hand == Handedness::left) {
    for (auto& t : T) t = mirror(t);
  }
  return T;
}

HandPose HandModel::forward(Handedness hand, const HandAngles& angles, const Pose& T_world_wrist,
                            TimeNs time_ns) const {
  HandPose out;
  out.time_ns = time_ns;
  out.hand = hand;
  out.active = true;
  const auto T_wrist_joint = joint_poses_in_wrist(hand, angles);
  for (std::size_t i = 0; i < kHandJointCount; ++i) out.T_world_joint[i] = T_world_wrist * T_wrist_joint[i];
  out.set_all_flags(kJointFullyTracked);
  out.radius_m[index_of(HandJoint::palm)] = shape_.palm_radius_m;
  out.radius_m[index_of(HandJoint::wrist)] = shape_.wrist_radius_m;
  for (std::size_t fi = 0; fi < kFingerCount; ++fi) {
    const FingerJoints fj = finger_joints(static_cast<Finger>(fi));
    for (std::size_t k = 0; k < fj.count; ++k) out.radius_m[index_of(fj.joints[k])] = shape_.fingers[fi].joint_radius_m[k];
  }
  return out;
}

InverseKinematicsResult HandModel::inverse(const HandPose& pose) const {
  InverseKinematicsResult r;
  r.T_world_wrist = pose.joint(HandJoint::wrist);
  const Pose T_wrist_world = r.T_world_wrist.inverse();
  std::array<Pose, kHandJointCount> T;  // in the right-hand wrist frame
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    T[i] = T_wrist_world * pose.T_world_joint[i];
    if (pose.hand == Handedness::left) T[i] = mirror(T[i]);
  }
  auto rel = [&](HandJoint parent, HandJoint child) { return T[index_of(parent)].q.conjugate() * T[index_of(child)].q; };
  auto rot_x_angle = [](const Quat& q) {
    const Mat3 M = q.toRotationMatrix();
    return -std::atan2(M(2, 1), M(1, 1));  // flexion is -rotation about +X
  };

  for (std::size_t fi = 0; fi < kFingerCount; ++fi) {
    const auto f = static_cast<Finger>(fi);
    const FingerJoints fj = finger_joints(f);
    const std::size_t d = first_dof_of(f);
    if (f == Finger::thumb) {
      const Quat q_cmc = shape_.fingers[fi].q_wrist_metacarpal_rest.conjugate() * T[index_of(fj.joints[0])].q;
      decompose_flex_abd(q_cmc, r.angles[d], r.angles[d + 1]);
      r.angles[d + 2] = rot_x_angle(rel(fj.joints[0], fj.joints[1]));
      r.angles[d + 3] = rot_x_angle(rel(fj.joints[1], fj.joints[2]));
    } else {
      decompose_flex_abd(rel(fj.joints[0], fj.joints[1]), r.angles[d], r.angles[d + 1]);
      r.angles[d + 2] = rot_x_angle(rel(fj.joints[1], fj.joints[2]));
      r.angles[d + 3] = rot_x_angle(rel(fj.joints[2], fj.joints[3]));
    }
  }

  const HandPose fk = forward(pose.hand, r.angles, r.T_world_wrist, pose.time_ns);
  for (double e : joint_position_errors(fk, pose)) r.max_position_residual_m = std::max(r.max_position_residual_m, e);
  return r;
}

}  // namespace proprio
