#include <gtest/gtest.h>

#include <cmath>

#include "proprio/core/random.hpp"
#include "proprio/rig_device/joint_kinematics.hpp"

namespace proprio::rig_device {
namespace {

TEST(JointKinematics, CardanAnglesRoundTrip) {
  Rng rng(7);
  for (int i = 0; i < 500; ++i) {
    const JointAngles a{rng.uniform(-M_PI, M_PI), rng.uniform(-1.5, 1.5), rng.uniform(-1.5, 1.5),
                        rng.uniform(-M_PI, M_PI)};
    const Quat q = joint_rotation(a);
    const JointAngles b = joint_angles_for(q, a.twist_in_rad);
    EXPECT_NEAR(wrap_angle_rad(b.twist_in_rad - a.twist_in_rad), 0.0, 1e-12);
    EXPECT_NEAR(b.bend_x_rad, a.bend_x_rad, 1e-9);
    EXPECT_NEAR(b.bend_y_rad, a.bend_y_rad, 1e-9);
    EXPECT_NEAR(wrap_angle_rad(b.twist_out_rad - a.twist_out_rad), 0.0, 1e-9);
    // Any inlet twist reproduces the rotation (one twist is redundant).
    const JointAngles c = joint_angles_for(q, rng.uniform(-M_PI, M_PI));
    EXPECT_LT(joint_rotation(c).angularDistance(q), 1e-9);
  }
  // At the Cardan singularity the rotation still comes back.
  const Quat q = joint_rotation({0.0, 0.4, M_PI / 2, 0.3});
  EXPECT_LT(joint_rotation(joint_angles_for(q)).angularDistance(q), 1e-9);
}

TEST(JointKinematics, TwistBendTwistRoundTrip) {
  Rng rng(8);
  for (int i = 0; i < 500; ++i) {
    const TwistBendTwistAngles a{rng.uniform(-M_PI, M_PI), rng.uniform(0.01, 3.1), rng.uniform(-M_PI, M_PI)};
    const Quat q = twist_bend_twist_rotation(a);
    const TwistBendTwistAngles b = twist_bend_twist_angles_for(q);
    EXPECT_NEAR(b.bend_rad, a.bend_rad, 1e-9);
    EXPECT_NEAR(wrap_angle_rad(b.twist_a_rad - a.twist_a_rad), 0.0, 1e-9);
    EXPECT_NEAR(wrap_angle_rad(b.twist_b_rad - a.twist_b_rad), 0.0, 1e-9);
  }
  const Quat straight = twist_bend_twist_rotation({0.5, 0.0, 0.7});
  EXPECT_LT(twist_bend_twist_rotation(twist_bend_twist_angles_for(straight)).angularDistance(straight), 1e-12);
}

TEST(JointKinematics, WrapAngle) {
  EXPECT_DOUBLE_EQ(wrap_angle_rad(M_PI), M_PI);
  EXPECT_DOUBLE_EQ(wrap_angle_rad(-M_PI), M_PI);
  EXPECT_NEAR(wrap_angle_rad(3 * M_PI + 0.1), -M_PI + 0.1, 1e-12);
  EXPECT_NEAR(wrap_angle_rad(-0.2), -0.2, 1e-15);
}

}  // namespace
}  // namespace proprio::rig_device
