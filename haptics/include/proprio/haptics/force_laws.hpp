#pragma once
// Analytic contact force laws for simple studies, where a full contact
// simulation is not wanted: a fingertip sphere against a plane or a half
// cylinder, with the force law of Lee 2021 §2.4.2:
//
//   F = F0 + K d   along the surface normal, once the sphere touches (d > 0),
//
// where d is the penetration depth. The thesis uses F0 = 0.45 N and
// K = 0.042 N/cm. Mind the unit: 0.042 N/cm is 4.2 N/m, i.e. 1 cm of
// penetration adds only 0.042 N; Proprio takes K in N/m (stiffness_n_per_m).
// The force is then decomposed into normal and shear relative to the finger
// (its fingertip frame, fingertip_force.hpp): a surface pressing the pad
// obliquely gives both.
#include <string>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/haptics/fingertip_force.hpp"

namespace proprio::haptics {

struct ContactLawOptions {
  double onset_force_n = 0.45;      // F0: felt the moment contact begins
  double stiffness_n_per_m = 4.2;   // K (Lee 2021: 0.042 N/cm = 4.2 N/m)
  double max_force_n = 5.0;         // the law saturates here (devices clamp again)

  std::string describe() const;
  Status validate() const;
};

struct AnalyticContact {
  bool in_contact = false;
  double penetration_m = 0.0;
  Vec3 n_in_world = Vec3::Zero();  // surface normal at the contact, out of the object
  Vec3 f_in_world = Vec3::Zero();  // force on the fingertip
  FingertipForce force;             // the same in the fingertip frame
  // As the pad feels it (felt_on_pad(): the law has no friction, so all of
  // it is pad pressure, whichever part of the fingertip touches): what to
  // send a fingertip device.
  FingertipForce on_pad;
};

// A plane through p_plane_in_world with outward normal n_in_world (unit).
AnalyticContact sphere_on_plane(const ContactLawOptions& law, const Vec3& p_plane_in_world, const Vec3& n_in_world,
                                const Vec3& p_sphere_in_world, double sphere_radius_m, const Quat& q_world_tip) noexcept;

// The +y half of a cylinder along the object's z (ShapeKind::half_cylinder):
// curved surface for y >= 0, flat face at y = 0. Beyond the end caps there is
// no contact (the study's cylinder is longer than anyone reaches).
struct HalfCylinderShape {
  Pose T_world_object;
  double radius_m = 0.25;
  double half_length_m = 0.25;
};
AnalyticContact sphere_on_half_cylinder(const ContactLawOptions& law, const HalfCylinderShape& cylinder,
                                        const Vec3& p_sphere_in_world, double sphere_radius_m,
                                        const Quat& q_world_tip) noexcept;

}  // namespace proprio::haptics
