#pragma once
// The analytic world that the Proprio mock OpenXR runtime reports, shared by
// the runtime and by the tests that check what passes through a layer: a test
// computes its expected values with exactly the code the runtime used.
//
// Conventions (OpenXR: right-handed, +Y up, -Z forward, Hamilton quaternions):
//  - Time. XrTime = CLOCK_MONOTONIC ns + kXrTimeOffsetNs. The offset is
//    deliberately not zero, so a layer that confuses XrTime with monotonic
//    time gets visibly wrong answers. The motion below is a function of
//    t = XrTime * 1e-9 seconds (offset included).
//  - LOCAL has its origin at the rest eye position of a seated user, 1.6 m
//    above the floor, axes aligned with STAGE.
//  - STAGE in LOCAL is a pure translation (0, -1.6, 0): the floor under the
//    seated head. (So VIEW in STAGE has y = 1.6 + 0.02 sin(...).)
//  - VIEW in LOCAL (the head), with w(f) = 2*pi*f:
//      position  = (0.10 sin(w(0.5) t), 0.02 sin(w(0.3) t), 0.05 cos(w(0.4) t))
//      rotation  = R_y(yaw) * R_x(pitch)   (yaw about +Y first, then pitch about
//                                           the yawed +X axis)
//      yaw       = 0.3 sin(w(0.25) t)  rad
//      pitch     = 0.1 sin(w(0.35) t)  rad
//  - Velocities (XrSpaceVelocity) of a space located in a base space are
//    expressed in the base space: linear velocity is the time derivative of
//    the located position; angular velocity w satisfies dR/dt = [w]x R for the
//    located rotation R. Of the reference spaces only VIEW moves, so for VIEW
//    in LOCAL:
//      linear  = d/dt position
//      angular = (pitch' cos(yaw), yaw', -pitch' sin(yaw))
//  - A reference space created with poseInReferenceSpace P is the reference
//    space's pose composed with P: T_local_space = T_local_ref * P.
//  - Any space A located in base B: T_B_A = T_local_B^-1 * T_local_A.
//
// Devices (controllers and VIVE trackers, mirrored left/right). One truth, the
// wrist, carries every device of a hand, so a controller's grip, a wrist
// tracker and the native wrist joint all agree through fixed offsets:
//  - The right wrist in LOCAL (the left one is its mirror image, below), w(f) as above:
//      position  = (0.20 + 0.04 sin(w(0.3) t), -0.32 + 0.03 sin(w(0.45) t),
//                   -0.32 + 0.05 sin(w(0.2) t))
//      rotation  = R_y(yaw) * R_x(pitch) * R_z(roll)
//      yaw       = 0.2 sin(w(0.15) t),  pitch = -0.1 + 0.15 sin(w(0.4) t),
//      roll      = -pi/2 + 0.3 sin(w(0.35) t)  rad
//    so the hand is held palm inwards (the wrist joint's +Y, the back of the
//    hand, points to +X), about 0.32 m ahead of and 0.32 m below the eyes.
//    angular velocity = yaw' e_y + pitch' R_y e_x + roll' R_y R_x e_z.
//  - Mirror image (left from right): position (x, y, z) -> (-x, y, z),
//    quaternion (x, y, z, w) -> (x, -y, -z, w), linear velocity like a
//    position, angular velocity (x, y, z) -> (x, -y, -z). Mirroring commutes
//    with composition, so every offset below is given for the right hand and
//    mirrored for the left (tracker_to_wrist(hand), wrist_to_grip(hand)).
//  - Controller grip = wrist * kWristToGripRight: R_z(+pi/2), (0, -0.02, -0.08)
//    in the wrist frame (8 cm towards the fingers, 2 cm palmar), so the grip
//    is about (+-0.18, -0.32, -0.40) in LOCAL with a near-identity
//    orientation. Controller aim = grip * kGripToAim: R_x(0.5), (0, 0, -0.05)
//    (the same for both hands: it is its own mirror image).
//  - VIVE tracker = wrist * inverse(kTrackerToWristRight), where
//    kTrackerToWristRight (the wrist in the tracker's frame) is
//    R_y(-pi/2), (0.02, -0.035, 0): the puck sits 3.5 cm on the back of the
//    wrist, 2 cm towards the elbow, turned 90 degrees about the wrist's +Y.
//    So wrist = tracker * tracker_to_wrist(hand).
//  - Velocities of an attached frame at lever r = R_parent p_offset:
//    v = v_parent + w x r, w = w_parent.
//  - select/click: pressed while (t - phase) mod 2 s < 1 s, phase 0 for the
//    left hand (pressed exactly when sin(2 pi 0.5 t) > 0, edges aside) and
//    0.5 s for the right, computed on integer XrTime so the edges are exact
//    (select_pressed, select_last_change). Every other button and axis of
//    every device reads false / 0.
//
// Native XR_EXT_hand_tracking (when the runtime offers it), by
// PROPRIO_MOCK_RUNTIME_HAND_TRACKING:
//  - "1": a fixed, recognisable pose: every joint at kNativeJointPosition in
//    the base space, identity orientation, radius kNativeJointRadius, all
//    flags set.
//  - "moving": XR_HAND_JOINT_WRIST_EXT is wrist_pose(hand, t); every other
//    joint is a flat open hand rigidly attached to it (kNativeJointsRight, in
//    the wrist frame, mirrored for the left hand; orientation = the wrist's).
//    The hand is lost (isActive false, no location flags) while
//    (t - phase) mod 4 s >= 3.5 s, phase 0 for the left hand and 2 s for the
//    right (native_hand_tracked).
#include <openxr/openxr.h>

#include <cmath>
#include <cstdint>
#include <ctime>
#include <numbers>

namespace proprio::mock_xr {

inline constexpr int64_t kXrTimeOffsetNs = 5'000'000'000;
inline constexpr double kEyeHeightM = 1.6;

// Frame clock of xrWaitFrame: ticks at k * 1e9 / 90 ns of CLOCK_MONOTONIC.
inline constexpr int64_t kDisplayHz = 90;
inline constexpr int64_t kFramePeriodNs = 1'000'000'000 / kDisplayHz;  // 11'111'111

inline constexpr XrVector3f kNativeJointPosition{0.0f, 0.0f, -7.0f};
inline constexpr float kNativeJointRadius = 0.0777f;

constexpr XrTime xr_time_from_monotonic_ns(int64_t monotonic_ns) { return monotonic_ns + kXrTimeOffsetNs; }
constexpr int64_t monotonic_ns_from_xr_time(XrTime time) { return time - kXrTimeOffsetNs; }

inline int64_t monotonic_now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}
inline XrTime xr_time_now() { return xr_time_from_monotonic_ns(monotonic_now_ns()); }

// Monotonic time of frame tick k (floor(k * 1e9 / 90)), and the index of the
// first tick after t. Split by whole seconds so no product can overflow.
constexpr int64_t frame_tick_ns(int64_t k) {
  return (k / kDisplayHz) * 1'000'000'000 + (k % kDisplayHz) * 1'000'000'000 / kDisplayHz;
}
constexpr int64_t next_frame_tick(int64_t monotonic_ns) {
  return (monotonic_ns / 1'000'000'000) * kDisplayHz + (monotonic_ns % 1'000'000'000) * kDisplayHz / 1'000'000'000 + 1;
}

// ---- small double-precision rigid-body math (the runtime reports floats) ----
struct Vec3 {
  double x = 0, y = 0, z = 0;
};
struct Quat {  // Hamilton, (x, y, z, w)
  double x = 0, y = 0, z = 0, w = 1;
};
struct Pose {
  Quat q;
  Vec3 p;
};
// A space's pose in some base, with its velocities expressed in that base.
struct Motion {
  Pose pose;
  Vec3 linear_velocity;
  Vec3 angular_velocity;
};

constexpr Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
constexpr Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
constexpr Vec3 operator-(Vec3 a) { return {-a.x, -a.y, -a.z}; }
constexpr Vec3 cross(Vec3 a, Vec3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }

constexpr Quat operator*(Quat a, Quat b) {
  return {a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y, a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
          a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w, a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z};
}
constexpr Quat conjugate(Quat q) { return {-q.x, -q.y, -q.z, q.w}; }
inline Quat normalized(Quat q) {
  const double n = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  return {q.x / n, q.y / n, q.z / n, q.w / n};
}
// v' = q v q* for a unit quaternion, written out: v + 2 w (u x v) + 2 u x (u x v).
constexpr Vec3 rotate(Quat q, Vec3 v) {
  const Vec3 u{q.x, q.y, q.z};
  const Vec3 uv = cross(u, v);
  const Vec3 uuv = cross(u, uv);
  return {v.x + 2 * (q.w * uv.x + uuv.x), v.y + 2 * (q.w * uv.y + uuv.y), v.z + 2 * (q.w * uv.z + uuv.z)};
}
inline Quat axis_angle(Vec3 unit_axis, double angle) {
  const double s = std::sin(angle / 2);
  return {unit_axis.x * s, unit_axis.y * s, unit_axis.z * s, std::cos(angle / 2)};
}

constexpr Pose compose(const Pose& a_b, const Pose& b_c) { return {a_b.q * b_c.q, a_b.p + rotate(a_b.q, b_c.p)}; }
constexpr Pose inverse(const Pose& a_b) {
  const Quat qi = conjugate(a_b.q);
  return {qi, -rotate(qi, a_b.p)};
}

inline Pose from_xr(const XrPosef& p) {
  return {{p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w}, {p.position.x, p.position.y, p.position.z}};
}
inline XrVector3f to_xr(Vec3 v) { return {static_cast<float>(v.x), static_cast<float>(v.y), static_cast<float>(v.z)}; }
inline XrPosef to_xr(const Pose& pose) {
  const Quat q = normalized(pose.q);
  return {{static_cast<float>(q.x), static_cast<float>(q.y), static_cast<float>(q.z), static_cast<float>(q.w)},
          to_xr(pose.p)};
}
inline constexpr XrPosef kIdentityPose{{0.0f, 0.0f, 0.0f, 1.0f}, {0.0f, 0.0f, 0.0f}};

// ---- the motion ----
constexpr double seconds_from_xr_time(XrTime time) { return static_cast<double>(time) * 1e-9; }

// The head (VIEW) in LOCAL, with velocities in LOCAL.
inline Motion view_in_local(XrTime time) {
  constexpr double two_pi = 2 * std::numbers::pi;
  const double t = seconds_from_xr_time(time);
  const double wx = two_pi * 0.5, wy = two_pi * 0.3, wz = two_pi * 0.4;
  const double wyaw = two_pi * 0.25, wpitch = two_pi * 0.35;

  const double yaw = 0.3 * std::sin(wyaw * t), yaw_rate = 0.3 * wyaw * std::cos(wyaw * t);
  const double pitch = 0.1 * std::sin(wpitch * t), pitch_rate = 0.1 * wpitch * std::cos(wpitch * t);

  Motion m;
  m.pose.p = {0.10 * std::sin(wx * t), 0.02 * std::sin(wy * t), 0.05 * std::cos(wz * t)};
  m.pose.q = axis_angle({0, 1, 0}, yaw) * axis_angle({1, 0, 0}, pitch);
  m.linear_velocity = {0.10 * wx * std::cos(wx * t), 0.02 * wy * std::cos(wy * t), -0.05 * wz * std::sin(wz * t)};
  // d/dt(Ry Rx) (Ry Rx)^T = [yaw' e_y + pitch' Ry e_x]x, and Ry e_x = (cos yaw, 0, -sin yaw).
  m.angular_velocity = {pitch_rate * std::cos(yaw), yaw_rate, -pitch_rate * std::sin(yaw)};
  return m;
}

constexpr bool is_supported_reference_space(XrReferenceSpaceType type) {
  return type == XR_REFERENCE_SPACE_TYPE_VIEW || type == XR_REFERENCE_SPACE_TYPE_LOCAL ||
         type == XR_REFERENCE_SPACE_TYPE_STAGE;
}

// A supported reference space in LOCAL (identity for anything unsupported).
inline Motion reference_in_local(XrReferenceSpaceType type, XrTime time) {
  Motion m;
  if (type == XR_REFERENCE_SPACE_TYPE_VIEW) return view_in_local(time);
  if (type == XR_REFERENCE_SPACE_TYPE_STAGE) m.pose.p = {0, -kEyeHeightM, 0};
  return m;
}

// A reference space created with poseInReferenceSpace = offset, in LOCAL. Its
// origin sits at a lever arm r from the reference origin: v = v_ref + w x r.
inline Motion space_in_local(XrReferenceSpaceType type, const XrPosef& offset, XrTime time) {
  const Motion ref = reference_in_local(type, time);
  const Pose off = from_xr(offset);
  const Vec3 lever = rotate(ref.pose.q, off.p);
  return {compose(ref.pose, off), ref.linear_velocity + cross(ref.angular_velocity, lever), ref.angular_velocity};
}

// Space A in base B, both given in LOCAL, velocities expressed in B:
//   p = R_B^T (p_A - p_B)            v = R_B^T ((v_A - v_B) - w_B x (p_A - p_B))
//   R = R_B^T R_A                    w = R_B^T (w_A - w_B)
inline Motion relative_motion(const Motion& a, const Motion& b) {
  const Quat b_inv = conjugate(b.pose.q);
  const Vec3 d = a.pose.p - b.pose.p;
  return {compose(inverse(b.pose), a.pose),
          rotate(b_inv, (a.linear_velocity - b.linear_velocity) - cross(b.angular_velocity, d)),
          rotate(b_inv, a.angular_velocity - b.angular_velocity)};
}

inline Motion locate_motion(XrReferenceSpaceType space, const XrPosef& space_offset, XrReferenceSpaceType base,
                            const XrPosef& base_offset, XrTime time) {
  return relative_motion(space_in_local(space, space_offset, time), space_in_local(base, base_offset, time));
}
// Something given in LOCAL (a device, a joint) located in a reference space.
inline Motion locate_motion(const Motion& in_local, XrReferenceSpaceType base, const XrPosef& base_offset,
                            XrTime time) {
  return relative_motion(in_local, space_in_local(base, base_offset, time));
}

// What xrLocateSpace reports, in the runtime's float types.
struct Located {
  XrPosef pose;
  XrVector3f linear_velocity;
  XrVector3f angular_velocity;
};
inline Located to_xr(const Motion& m) { return {to_xr(m.pose), to_xr(m.linear_velocity), to_xr(m.angular_velocity)}; }

inline Located locate(XrReferenceSpaceType space, const XrPosef& space_offset, XrReferenceSpaceType base,
                      const XrPosef& base_offset, XrTime time) {
  return to_xr(locate_motion(space, space_offset, base, base_offset, time));
}
inline Located locate(XrReferenceSpaceType space, XrReferenceSpaceType base, XrTime time) {
  return locate(space, kIdentityPose, base, kIdentityPose, time);
}
inline Located locate(const Motion& in_local, XrReferenceSpaceType base, XrTime time) {
  return to_xr(locate_motion(in_local, base, kIdentityPose, time));
}

// ---- devices: controllers, VIVE trackers, the native hand ----
enum class Hand { left, right };

// The mirror image across LOCAL's YZ plane (x -> -x), as a proper rotation.
constexpr Vec3 mirror_point(Vec3 p) { return {-p.x, p.y, p.z}; }
constexpr Vec3 mirror_axial(Vec3 w) { return {w.x, -w.y, -w.z}; }
constexpr Quat mirror(Quat q) { return {q.x, -q.y, -q.z, q.w}; }
constexpr Pose mirror(const Pose& pose) { return {mirror(pose.q), mirror_point(pose.p)}; }
constexpr Motion mirror(const Motion& m) {
  return {mirror(m.pose), mirror_point(m.linear_velocity), mirror_axial(m.angular_velocity)};
}
constexpr Pose for_hand(Hand hand, const Pose& right) { return hand == Hand::right ? right : mirror(right); }

// A frame rigidly attached to `parent` at `offset` (in the parent's frame).
inline Motion attach(const Motion& parent, const Pose& offset) {
  const Vec3 lever = rotate(parent.pose.q, offset.p);
  return {compose(parent.pose, offset), parent.linear_velocity + cross(parent.angular_velocity, lever),
          parent.angular_velocity};
}

inline constexpr double kHalfSqrt2 = std::numbers::sqrt2 / 2;
// The wrist in a wrist tracker's frame (right hand): wrist = tracker * this.
inline constexpr Pose kTrackerToWristRight{{0, -kHalfSqrt2, 0, kHalfSqrt2}, {0.02, -0.035, 0.0}};
// A controller's grip in the wrist frame (right hand): grip = wrist * this.
inline constexpr Pose kWristToGripRight{{0, 0, kHalfSqrt2, kHalfSqrt2}, {0.0, -0.02, -0.08}};
// A controller's aim in its grip frame (both hands): aim = grip * this.
inline const Pose kGripToAim{axis_angle({1, 0, 0}, 0.5), {0.0, 0.0, -0.05}};

constexpr Pose tracker_to_wrist(Hand hand) { return for_hand(hand, kTrackerToWristRight); }
constexpr Pose wrist_to_grip(Hand hand) { return for_hand(hand, kWristToGripRight); }

// The user's wrist (the native XR_HAND_JOINT_WRIST_EXT) in LOCAL: the one
// truth every device of that hand follows.
inline Motion wrist_pose(Hand hand, XrTime time) {
  constexpr double two_pi = 2 * std::numbers::pi;
  const double t = seconds_from_xr_time(time);
  const double wx = two_pi * 0.3, wy = two_pi * 0.45, wz = two_pi * 0.2;
  const double wyaw = two_pi * 0.15, wpitch = two_pi * 0.4, wroll = two_pi * 0.35;

  const double yaw = 0.2 * std::sin(wyaw * t), yaw_rate = 0.2 * wyaw * std::cos(wyaw * t);
  const double pitch = -0.1 + 0.15 * std::sin(wpitch * t), pitch_rate = 0.15 * wpitch * std::cos(wpitch * t);
  const double roll = -std::numbers::pi / 2 + 0.3 * std::sin(wroll * t),
               roll_rate = 0.3 * wroll * std::cos(wroll * t);

  Motion m;
  m.pose.p = {0.20 + 0.04 * std::sin(wx * t), -0.32 + 0.03 * std::sin(wy * t), -0.32 + 0.05 * std::sin(wz * t)};
  m.pose.q = axis_angle({0, 1, 0}, yaw) * axis_angle({1, 0, 0}, pitch) * axis_angle({0, 0, 1}, roll);
  m.linear_velocity = {0.04 * wx * std::cos(wx * t), 0.03 * wy * std::cos(wy * t), 0.05 * wz * std::cos(wz * t)};
  // R_y e_x = (cos yaw, 0, -sin yaw); R_y R_x e_z = (cos pitch sin yaw, -sin pitch, cos pitch cos yaw).
  const double cy = std::cos(yaw), sy = std::sin(yaw), cp = std::cos(pitch), sp = std::sin(pitch);
  m.angular_velocity = {pitch_rate * cy + roll_rate * cp * sy, yaw_rate - roll_rate * sp,
                        -pitch_rate * sy + roll_rate * cp * cy};
  return hand == Hand::right ? m : mirror(m);
}

// A simple controller's grip and aim poses, and a wrist tracker's pose, in LOCAL.
inline Motion controller_grip(Hand hand, XrTime time) { return attach(wrist_pose(hand, time), wrist_to_grip(hand)); }
inline Motion controller_aim(Hand hand, XrTime time) { return attach(controller_grip(hand, time), kGripToAim); }
inline Motion tracker_pose(Hand hand, XrTime time) {
  return attach(wrist_pose(hand, time), inverse(tracker_to_wrist(hand)));
}

// select/click: pressed for 1 s of every 2 s, the right hand 0.5 s after the left.
inline constexpr int64_t kSelectPeriodNs = 2'000'000'000;
constexpr int64_t select_phase_ns(Hand hand) { return hand == Hand::left ? 0 : 500'000'000; }
constexpr int64_t positive_mod(int64_t a, int64_t m) { return ((a % m) + m) % m; }
constexpr bool select_pressed(Hand hand, XrTime time) {
  return positive_mod(time - select_phase_ns(hand), kSelectPeriodNs) < kSelectPeriodNs / 2;
}
// The last press or release at or before `time`.
constexpr XrTime select_last_change(Hand hand, XrTime time) {
  return time - positive_mod(time - select_phase_ns(hand), kSelectPeriodNs / 2);
}

// The native hand ("moving"): lost for 0.5 s of every 4 s, the right hand 2 s after the left.
inline constexpr int64_t kNativeHandPeriodNs = 4'000'000'000;
inline constexpr int64_t kNativeHandLostNs = 500'000'000;
constexpr int64_t native_hand_phase_ns(Hand hand) { return hand == Hand::left ? 0 : 2'000'000'000; }
constexpr bool native_hand_tracked(Hand hand, XrTime time) {
  return positive_mod(time - native_hand_phase_ns(hand), kNativeHandPeriodNs) < kNativeHandPeriodNs - kNativeHandLostNs;
}

// A flat open right hand in its wrist frame (+Y the back of the hand, -Z
// towards the fingers, the thumb at -X), indexed by XrHandJointEXT: joint
// position (m) and radius (m). Every joint has the wrist's orientation.
struct NativeJoint {
  Vec3 position;
  double radius;
};
inline constexpr NativeJoint kNativeJointsRight[XR_HAND_JOINT_COUNT_EXT] = {
    {{0.0, 0.0, -0.045}, 0.02},                                                   // palm
    {{0.0, 0.0, 0.0}, 0.02},                                                      // wrist
    {{-0.025, -0.01, -0.025}, 0.016}, {{-0.045, -0.01, -0.045}, 0.011},           // thumb metacarpal, proximal
    {{-0.06, -0.01, -0.065}, 0.009}, {{-0.07, -0.01, -0.085}, 0.008},             // thumb distal, tip
    {{-0.012, 0.0, -0.01}, 0.012}, {{-0.022, 0.0, -0.09}, 0.01},                  // index metacarpal, proximal
    {{-0.024, 0.0, -0.13}, 0.009}, {{-0.025, 0.0, -0.155}, 0.008}, {{-0.026, 0.0, -0.175}, 0.007},
    {{0.0, 0.0, -0.01}, 0.012}, {{0.0, 0.0, -0.095}, 0.01},                       // middle
    {{0.0, 0.0, -0.14}, 0.009}, {{0.0, 0.0, -0.168}, 0.008}, {{0.0, 0.0, -0.19}, 0.007},
    {{0.012, 0.0, -0.01}, 0.012}, {{0.02, 0.0, -0.09}, 0.01},                     // ring
    {{0.021, 0.0, -0.13}, 0.009}, {{0.022, 0.0, -0.155}, 0.008}, {{0.023, 0.0, -0.175}, 0.007},
    {{0.024, 0.0, -0.01}, 0.011}, {{0.038, 0.0, -0.08}, 0.009},                   // little
    {{0.04, 0.0, -0.11}, 0.008}, {{0.041, 0.0, -0.13}, 0.007}, {{0.042, 0.0, -0.147}, 0.006},
};

// One native joint ("moving") in LOCAL.
inline Motion native_joint(Hand hand, XrHandJointEXT joint, XrTime time) {
  const Pose offset{{}, kNativeJointsRight[joint].position};
  return attach(wrist_pose(hand, time), for_hand(hand, offset));
}

}  // namespace proprio::mock_xr
