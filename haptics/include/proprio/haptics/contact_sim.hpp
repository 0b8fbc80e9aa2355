#pragma once
// ContactSimulation: a MuJoCo world with a proxy hand that follows the tracked
// hand through virtual coupling (Kim & Lee, IJRR 2017; Lee 2021 §3.3.3), and
// the contact force each fingertip feels.
//
// The proxy is generated as MJCF from the kinematic hand (HandModel: the
// user's bone lengths and joint limits), with capsule segments and the same
// joints as the kinematic model: CMC abduction + flexion for the thumb, MCP
// abduction + flexion for the fingers, then 1-DOF hinges. Because the
// structures match, the proxy's qpos maps straight back to HandAngles and the
// rendered hand (proxy_pose()) is an exact HandPose of the proxy.
//
// Coupling (the spring-damper between the tracked hand and the proxy):
//   * Wrist, 6 DOF: a weld equality constraint between the proxy's root body
//     and a mocap body placed at the tracked wrist. MuJoCo solves it with the
//     contacts, implicitly, so it stays stable at stiffnesses where an
//     explicit spring on xfrc_applied explodes (docs/platform-notes.md).
//   * Fingers, per joint: position servos (stiffness, torque limit) plus joint
//     damping, which the Euler integrator treats implicitly.
//   * A leash caps the coupling force: the mocap target is kept within
//     wrist_max_offset_m / _rad of the proxy, so however deep the tracked hand
//     goes into an object, the force pulling the proxy in stays bounded and the
//     (much stiffer) contacts hold it on the surface. That is why the proxy
//     never tunnels, and what makes the rendered hand penetration-free.
//   * The proxy's weight is compensated: the user's arm carries the real hand.
//
// Two hands share one world (issue 29): each proxy has its own coupling and
// fingertips, both touch the same objects, so one hand can hand a peg to the
// other or both can hold it. Proxies do not collide with each other: the
// user's real hands already stop each other, and a proxy held back by the
// other would pull the user's fingers through their own hand.
//
// Colliders (ContactSimOptions::collider_slots): kinematic shapes an app
// places and moves at run time (the OpenXR layer's XR_PROPRIO_fingertip_haptics
// colliders). They are MuJoCo mocap bodies made once with the model; a free
// slot waits far below the floor, so setting one never recompiles the model.
//
// Threading: one thread owns a ContactSimulation (the servo loop). step() and
// the accessors do not allocate, lock or throw.
#include <array>
#include <memory>
#include <span>
#include <string>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/result.hpp"
#include "proprio/haptics/fingertip_force.hpp"
#include "proprio/haptics/scene.hpp"

namespace proprio::haptics {

struct CouplingOptions {
  // Wrist weld, as MuJoCo's solref (time constant, damping ratio) and the
  // impedance d (solimp). With d = 0.9 the weld acts as a critically damped
  // spring of about d/(d^2 tau^2) = 2500 s^-2 per kg of proxy, i.e. ~1000 N/m
  // on a 0.4 kg hand. tau must stay >= 2 timesteps (MuJoCo's own stability
  // floor); 20 ms keeps the coupling 10x softer than the contacts (4 ms), so
  // contacts win and the proxy stops at the surface.
  double wrist_time_constant_s = 0.02;
  double wrist_damping_ratio = 1.0;
  double wrist_impedance = 0.9;
  // Leash: largest offset between the proxy and the target it is pulled to.
  // 2 cm at ~1000 N/m caps the pull near 20 N: enough to push a 500 g peg
  // into a tight hole, small enough that contacts (stiffer by 10x) hold.
  double wrist_max_offset_m = 0.02;
  double wrist_max_offset_rad = 0.35;
  // A tracked hand further than this from a proxy that touches nothing is
  // jumped to directly (tracking recovered after a gap); 0 disables.
  double resync_distance_m = 0.25;

  // Finger joints. Stiffness over (link inertia + armature) sets the joint
  // servo's natural frequency: sqrt(0.5 / 2e-5) = 158 rad/s (25 Hz), well
  // inside explicit-integration stability at 1 kHz (omega * dt = 0.16 << 2),
  // and damping 2*sqrt(k*I) = 0.0063 makes it critically damped. The torque
  // limit bounds what a finger can press with: ~0.6 N m at a 6-8 cm lever is
  // 8-10 N at the tip, above the peg's 5 N breaking force.
  double joint_stiffness_nm_per_rad = 0.5;
  double joint_damping_nms_per_rad = 0.0063;
  double joint_armature_kg_m2 = 2e-5;
  double joint_max_torque_nm = 0.6;

  std::string describe() const;
  Status validate() const;
};

struct ContactSimOptions {
  double timestep_s = 0.001;  // 1 kHz, the servo rate
  CouplingOptions coupling;
  // Contacts: stiffer than the coupling (see above). solref time constant
  // (>= 2 timesteps) and the solimp impedance ramp d0 -> dmax over width:
  // near-hard contacts keep penetration to a millimetre or two at grip forces.
  double contact_time_constant_s = 0.004;
  double contact_impedance_min = 0.95;
  double contact_impedance_max = 0.99;
  double contact_impedance_width_m = 0.002;
  // Grasping (MuJoCo docs, "Contact"): an elliptic cone with impratio > 1
  // makes friction stiffer than the normal direction, so held objects do not
  // creep out of the fingers.
  double impratio = 10.0;
  int solver_iterations = 50;
  // The Newton solver stops when an iteration improves its cost by less than
  // this fraction (MuJoCo's `tolerance`, default 1e-8). 1e-5 cuts a
  // peg-in-hole tick by about a fifth (solver Cholesky updates dominate);
  // the forces it leaves out are far below what a fingertip device renders.
  double solver_tolerance = 1e-8;
  // Torsional friction (MuJoCo condim 4, a "soft finger"): a contact also
  // resists spinning about its normal. Off gives condim 3, Coulomb friction
  // at a point, which is all a 3-DOF fingertip device renders; a pad's patch
  // of contacts (multiccd) still resists spin, more so the wider it is.
  bool torsional_friction = true;
  // Multi-point convex collision: a cylinder resting on a flat face gets a
  // patch of contacts, not one wobbling point (peg in hole).
  bool multiccd = true;
  // Skin-side density (kg/m^3) for the proxy's capsules; the hand's mass only
  // sets the coupling's dynamics since gravity is compensated.
  double hand_density_kg_m3 = 1000.0;
  // Fingertip force low-pass: first order, 2-5 ms (MuJoCo's contact forces
  // chatter step to step; skin does not feel above a few hundred Hz).
  double force_filter_time_constant_s = 0.003;
  // Kinematic collider slots (set_collider), at most kMaxColliderSlots.
  int collider_slots = 0;

  std::string describe() const;
  Status validate() const;
};

// The per-fingertip result of one step.
struct FingertipContact {
  // Filtered force the scene exerts on the fingertip, in its fingertip frame
  // (fingertip_force.hpp). Zero when nothing touches it.
  FingertipForce force;
  FingertipForce raw;  // unfiltered, this step
  // Filtered, the same contacts as the pad feels them (felt_on_pad(), summed
  // over the distal phalanx's contacts): what the servo loop sends to a
  // fingertip device. A press on the tip's end or side shows here as pad
  // pressure; `force` reads it as shear or a negative normal. Its normal_n is
  // contact_normal_n, and friction is its only shear.
  FingertipForce on_pad;
  Vec3 f_in_world = Vec3::Zero();  // unfiltered total force, world frame
  // Filtered, how hard the surfaces press together: the sum of the contacts'
  // normal forces along their contact normals. The fingertip frame's
  // normal_n is less whenever the pad meets the surface at an angle.
  double contact_normal_n = 0.0;
  // Filtered, the part of contact_normal_n pressing on movable scene objects
  // (what a hand can hold), not on fixed ones (a table, a plate): a held
  // object's own load, for rules such as a peg that breaks when squeezed.
  double object_normal_n = 0.0;
  int contact_count = 0;
  double max_penetration_m = 0.0;
};

struct ContactSimStats {
  std::uint64_t steps = 0;
  std::uint64_t resyncs = 0;            // proxy jumped to a far tracked hand
  std::uint64_t leash_engaged_steps = 0;  // the coupling's force cap was active
  std::uint64_t instability_resets = 0;   // MuJoCo reported bad qacc/qpos and the state was reset
  int last_contact_count = 0;
};

// One proxy hand of the world: the user's hand shape and which hand it is.
struct ProxyHandSpec {
  HandModel model;
  Handedness hand = Handedness::right;
};
inline constexpr std::size_t kMaxProxyHands = 2;
inline constexpr int kMaxColliderSlots = 64;

// A collider's shape (sizes as SceneObject's): sphere, box, capsule or
// cylinder, the axis of the last two along its z.
struct ColliderShape {
  ShapeKind shape = ShapeKind::sphere;
  Vec3 half_extents_m = Vec3(0.05, 0.05, 0.05);
  double radius_m = 0.05;
  double half_length_m = 0.05;
  double friction = 0.8;
  // The shape is one of the four, sizes in [0.1 mm, 10 m], friction in [0, 2].
  Status validate() const;
};

class ContactSimulation {
 public:
  // Builds the MuJoCo model for these hands (one or two, one per side) and
  // scene. Errors name the object or option that is wrong; a MuJoCo compile
  // error is passed on with the generated MJCF's line.
  static Result<ContactSimulation> create(std::span<const ProxyHandSpec> hands, const HapticScene& scene,
                                          const ContactSimOptions& options = {});
  static Result<ContactSimulation> create(const HandModel& hand_model, Handedness hand, const HapticScene& scene,
                                          const ContactSimOptions& options = {});
  ContactSimulation(ContactSimulation&&) noexcept;
  ContactSimulation& operator=(ContactSimulation&&) noexcept;
  ~ContactSimulation();

  // The MJCF the model was built from (for docs, debugging, MuJoCo's simulate).
  const std::string& mjcf() const;

  // Moves the proxy (and its target) to this pose at once, zero velocity.
  // `h` below: the hand's index in create()'s list (0 with one hand).
  void reset_hand(const Pose& T_world_wrist, const HandAngles& angles, std::size_t h = 0) noexcept;
  // The tracked hand the proxy is coupled to from now on. Non-finite input is
  // ignored (the previous target stays) and counted.
  void set_target(const Pose& T_world_wrist, const HandAngles& angles, std::size_t h = 0) noexcept;
  // Advances one timestep and updates the fingertip contacts.
  void step() noexcept;

  TimeNs time_ns() const noexcept;
  std::size_t hand_count() const noexcept;
  // The index of the proxy for this side, or -1 when the world has none.
  int hand_index(Handedness side) const noexcept;
  Handedness hand(std::size_t h = 0) const noexcept;
  // The proxy's kinematic model (immutable: safe to read from any thread).
  const HandModel& hand_model(std::size_t h = 0) const noexcept;
  // The proxy as a fully tracked HandPose: what to render.
  HandPose proxy_pose(TimeNs time_ns, std::size_t h = 0) const;
  Pose proxy_wrist(std::size_t h = 0) const noexcept;
  HandAngles proxy_angles(std::size_t h = 0) const noexcept;
  // Thumb, index, middle, ring, little.
  const std::array<FingertipContact, kFingerCount>& fingertips(std::size_t h = 0) const noexcept;
  const FingertipContact& fingertip(Finger finger, std::size_t h = 0) const noexcept;
  // Collider slots: shape (ColliderShape::validate() first; false for a bad
  // slot, shape or pose) and pose; a removed slot goes back below the floor.
  // Allocation-free.
  int collider_slot_count() const noexcept;
  bool set_collider(int slot, const ColliderShape& shape, const Pose& T_world_collider) noexcept;
  bool move_collider(int slot, const Pose& T_world_collider) noexcept;
  void remove_collider(int slot) noexcept;
  // A free object's pose (Errc::not_found for unknown or fixed objects).
  Result<Pose> object_pose(std::string_view name) const;
  // The free objects (scene order) and their poses by index: the servo loop
  // publishes them each tick without a name lookup.
  std::size_t free_object_count() const noexcept;
  const std::string& free_object_name(std::size_t i) const;
  Pose free_object_pose(std::size_t i) const noexcept;
  // Sets a free object's pose and zeroes its velocity (respawn).
  Status place_object(std::string_view name, const Pose& T_world_object);
  // Hangs a free object on a linear spring (N/m) and damper (N s/m) from a
  // world anchor, acting at its centre of mass (e.g. the peg-in-hole
  // familiarisation's peg "suspended in the air by a spring"). Stiffness 0
  // removes it. Not while the servo thread runs.
  Status set_object_spring(std::string_view name, const Vec3& p_anchor_in_world, double stiffness_n_per_m,
                           double damping_ns_per_m);
  // Total contact force (N, world) between the hand and the named object.
  Vec3 hand_force_on_object(std::string_view name) const;
  ContactSimStats stats() const noexcept;
  const ContactSimOptions& options() const noexcept;
  // MuJoCo's model size, for logs: bodies, geoms, DOFs.
  std::string describe_model() const;

 private:
  struct Impl;
  explicit ContactSimulation(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// The MJCF ContactSimulation compiles (exposed for tests and `proprio haptics mjcf`).
Result<std::string> generate_mjcf(std::span<const ProxyHandSpec> hands, const HapticScene& scene,
                                  const ContactSimOptions& options);
Result<std::string> generate_mjcf(const HandModel& hand_model, Handedness hand, const HapticScene& scene,
                                  const ContactSimOptions& options);

}  // namespace proprio::haptics
