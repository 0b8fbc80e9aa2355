#pragma once
// The two joint designs of Glauser et al. 2016 (thesis ch. 3, Fig. 3.3), as
// rotations from a joint's inlet shaft frame to its outlet shaft frame. The
// shaft runs along +z in both frames.
//
// Ours (the thesis's design): a twist ring, a Cardan (universal) joint whose
// two hinges are orthogonal (x, then y), and a second twist ring:
//   q_in_out = Rz(twist_in) * Rx(bend_x) * Ry(bend_y) * Rz(twist_out)
// The Cardan joint bends in any direction directly, so a user can trace the
// geodesic between two outlet directions.
//
// Theirs (Jacobson et al. 2014, twist-bend-twist): one hinge between two twists,
//   q_in_out = Rz(twist_a) * Rx(bend) * Rz(twist_b)
// Reaching a new direction means turning a twist, then the bend, then the other
// twist: the zig-zag of Fig. 3.4.
#include "proprio/core/math.hpp"

namespace proprio::rig_device {

struct JointAngles {
  double twist_in_rad = 0.0;
  double bend_x_rad = 0.0;
  double bend_y_rad = 0.0;
  double twist_out_rad = 0.0;
};

Quat joint_rotation(const JointAngles& angles);
// The angles that give q_in_out with the inlet twist held at twist_in_rad (the
// design has one redundant twist; a user leaves one ring where it is). Bends
// come back in [-pi/2, pi/2]; at the Cardan joint's singularity (bend_y =
// +-pi/2, beyond any physical joint's range) the outlet twist is set to 0.
JointAngles joint_angles_for(const Quat& q_in_out, double twist_in_rad = 0.0);

struct TwistBendTwistAngles {
  double twist_a_rad = 0.0;
  double bend_rad = 0.0;  // [0, pi]
  double twist_b_rad = 0.0;
};

Quat twist_bend_twist_rotation(const TwistBendTwistAngles& angles);
// Inverse; at bend = 0 the two twists are one (all of it goes to twist_a).
TwistBendTwistAngles twist_bend_twist_angles_for(const Quat& q_in_out);

// Wraps an angle to (-pi, pi].
double wrap_angle_rad(double angle_rad);

}  // namespace proprio::rig_device
