#pragma once
// What the proxy hand can touch: primitives placed in the world, fixed or free
// (a free object is a rigid body with mass that the hand can push, grasp and
// drop). ContactSimulation turns a HapticScene into MuJoCo bodies and geoms.
//
// Frames and units follow the architecture: world is right-handed, +Y up,
// metres, kilograms. Each shape's own frame is given with it.
#include <array>
#include <optional>
#include <string>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"

namespace proprio::haptics {

enum class ShapeKind {
  box,            // half_extents_m along the object's x, y, z
  sphere,         // radius_m
  cylinder,       // radius_m, axis along the object's z, half_length_m
  half_cylinder,  // radius_m, half_length_m: the +y half of a cylinder along z (flat face at y = 0, facing -y)
  capsule,        // radius_m, half_length_m of the segment along z
  // A plate with a round through-hole along the object's z: hole_radius_m,
  // half_extents_m = the plate's outer half sizes (x, y) and half thickness (z).
  // Built from box segments around the hole (hole_segments), which keeps the
  // collision exact for a cylinder peg (MuJoCo has no concave primitives).
  plate_with_hole,
};
std::string_view to_string(ShapeKind kind) noexcept;

struct SceneObject {
  std::string name;  // unique; also the MuJoCo body name
  ShapeKind shape = ShapeKind::box;
  Vec3 half_extents_m = Vec3(0.05, 0.05, 0.05);
  double radius_m = 0.05;
  double half_length_m = 0.05;
  double hole_radius_m = 0.0;
  int hole_segments = 24;
  Pose T_world_object;
  // Fixed objects are world geometry; free objects are bodies with a free joint.
  bool fixed = true;
  double mass_kg = 0.1;  // free objects; inertia from the shape with uniform density
  // Sliding friction against skin. Human fingertip on plastic or glass is
  // about 0.5-1.0 (Derler & Gerhardt, Tribology Letters 2012).
  double friction = 0.8;
  // Fixed boxes only: in contacts the box is the half-space below its +y
  // face, an infinite plane, so nothing falls past its edges. MuJoCo
  // collides planes with every primitive in closed form, while a box against
  // a cylinder goes through libccd: for a peg standing on a table box that
  // was a fifth of the whole simulation's instructions (callgrind). The box
  // is still what is drawn.
  bool contact_top_plane = false;
  // Cylinders only: the hand touches a capsule of the same radius whose caps
  // end flush with the end faces, while other objects (table, plate) still
  // meet the exact cylinder. The side is the same surface over all but a
  // radius at each end; the end faces become domes for the hand. MuJoCo
  // 2.2.2 collides capsules with capsules and boxes in closed form, but a
  // cylinder against any finger segment goes through libccd's MPR: 18% of a
  // held peg's simulation (callgrind), with one approximate contact per pair.
  bool hand_touches_capsule = false;
  std::array<float, 4> rgba{0.7f, 0.7f, 0.75f, 1.0f};

  // Checks sizes, mass and name; the message names the object and the field.
  Status validate() const;

  static SceneObject box(std::string name, const Vec3& half_extents_m, const Pose& T_world_object);
  static SceneObject sphere(std::string name, double radius_m, const Pose& T_world_object);
  static SceneObject cylinder(std::string name, double radius_m, double half_length_m, const Pose& T_world_object);
  static SceneObject half_cylinder(std::string name, double radius_m, double half_length_m,
                                   const Pose& T_world_object);
  static SceneObject capsule(std::string name, double radius_m, double half_length_m, const Pose& T_world_object);
  static SceneObject plate_with_hole(std::string name, double hole_radius_m, const Vec3& half_extents_m,
                                     const Pose& T_world_object);
};

struct HapticScene {
  std::vector<SceneObject> objects;
  // A ground plane at y = floor_height_m (none when empty).
  std::optional<double> floor_height_m = 0.0;
  Vec3 gravity_in_world = Vec3(0.0, -9.81, 0.0);

  Status validate() const;
  const SceneObject* find(std::string_view name) const;

  // Presets. Positions are in a standing user's world: the hand works about
  // 1 m above the floor, 0.4 m in front (-z).

  // The perception study's target (Lee 2021 §2.2.2): a half cylinder of
  // radius 25 cm and height (length) 50 cm, lying horizontally.
  static HapticScene half_cylinder_study();

  struct PegInHoleOptions {
    // Lee 2021 §3.3.3: a round bottle, 186.2 mm tall, radius 25.84 mm, 500 g.
    double peg_radius_m = 0.02584;
    double peg_length_m = 0.1862;
    double peg_mass_kg = 0.5;
    // Radial clearance between peg and hole (the thesis does not state one).
    double clearance_m = 0.002;
    // The hole's plate is vertical, so the hole's axis is horizontal.
    double plate_thickness_m = 0.06;
    Vec3 p_peg_in_world = Vec3(0.0, 0.85, -0.40);   // the peg's base centre, standing upright
    Vec3 p_hole_in_world = Vec3(0.25, 1.0, -0.45);  // the hole's centre, on the plate's front face
    double table_height_m = 0.85;
  };
  // A table, an upright peg on it, and a vertical plate with a round hole
  // whose axis points along +x (towards the peg's side).
  static HapticScene peg_in_hole(const PegInHoleOptions& options);
  static HapticScene peg_in_hole() { return peg_in_hole(PegInHoleOptions{}); }
};

}  // namespace proprio::haptics
