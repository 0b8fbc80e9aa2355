#include <gtest/gtest.h>

#include <cmath>

#include "proprio/rig_device/hall_joint.hpp"
#include "proprio/rig_device/kit.hpp"

namespace proprio::rig_device {
namespace {

HallJointOptions ideal_options() {
  HallJointOptions o;
  o.kind = default_kit().joint;
  o.manufacturing_errors = false;
  o.noise = false;
  o.backlash = false;
  return o;
}

TEST(DipoleField, FallsOffAsTheInverseCubeInEveryDirection) {
  const Vec3 m(0.01, -0.02, 0.03);
  for (const Vec3& dir : {Vec3(1, 0, 0), Vec3(0, 0, 1), Vec3(0.3, -0.5, 0.8).normalized()}) {
    const Vec3 b1 = dipole_field_t(m, 0.01 * dir);
    const Vec3 b2 = dipole_field_t(m, 0.02 * dir);
    EXPECT_NEAR(b2.norm() * 8.0, b1.norm(), 1e-12 * b1.norm());
    EXPECT_LT((b2 * 8.0 - b1).norm(), 1e-12 * b1.norm());  // same direction too
  }
}

TEST(DipoleField, SymmetriesAndTheAxialToEquatorialRatio) {
  const Vec3 m(0, 0, 0.05);
  const double r = 0.006;
  const Vec3 axial = dipole_field_t(m, Vec3(0, 0, r));
  const Vec3 equatorial = dipole_field_t(m, Vec3(r, 0, 0));
  // On the axis: mu0/4pi 2m/r^3 along m; on the equator: half of it, against m.
  EXPECT_NEAR(axial.z(), kMu0Over4Pi * 2.0 * 0.05 / (r * r * r), 1e-12);
  EXPECT_NEAR(equatorial.z(), -0.5 * axial.z(), 1e-12);
  EXPECT_NEAR(equatorial.x(), 0.0, 1e-15);
  // Point symmetric in r, odd in m, linear in m.
  const Vec3 p(0.003, -0.004, 0.005), m2(0.02, 0.01, -0.03);
  EXPECT_LT((dipole_field_t(m2, p) - dipole_field_t(m2, -p)).norm(), 1e-15);
  EXPECT_LT((dipole_field_t(-m2, p) + dipole_field_t(m2, p)).norm(), 1e-15);
  EXPECT_LT((dipole_field_t(m + m2, p) - dipole_field_t(m, p) - dipole_field_t(m2, p)).norm(), 1e-12);
  EXPECT_EQ(dipole_field_t(m, Vec3::Zero()), Vec3::Zero());
}

TEST(DipoleField, MagnetMomentIsRemanenceTimesVolumeOverMu0) {
  const double v = 1e-9;
  EXPECT_NEAR(magnet_moment_am2(1.3, v), 1.3 * v / (4e-7 * M_PI), 1e-15);
}

TEST(Adc, QuantisesAroundMidScaleAndSaturates) {
  Rng rng(1);
  EXPECT_EQ(adc_counts(0.0, kBendSensitivityVPerT, 0.0, 0.0, rng), (kAdcMaxCount + 1) / 2);
  EXPECT_EQ(adc_counts(1.0, kBendSensitivityVPerT, 0.0, 0.0, rng), kAdcMaxCount);
  EXPECT_EQ(adc_counts(-1.0, kBendSensitivityVPerT, 0.0, 0.0, rng), 0);
  // One count is Vcc / 4096 of output: fields a tenth of that apart mostly
  // read the same, fields one LSB apart read one count apart.
  const double lsb_t = kSupplyV / (kAdcMaxCount + 1) / kBendSensitivityVPerT;
  const int c0 = adc_counts(0.01, kBendSensitivityVPerT, 0.0, 0.0, rng);
  EXPECT_EQ(adc_counts(0.01 + lsb_t, kBendSensitivityVPerT, 0.0, 0.0, rng), c0 + 1);
  EXPECT_EQ(adc_counts(0.01 + 10 * lsb_t, kBendSensitivityVPerT, 0.0, 0.0, rng), c0 + 10);
  int same = 0;
  for (int i = 0; i < 100; ++i) {
    same += adc_counts(0.01 + 0.001 * i * lsb_t, kBendSensitivityVPerT, 0.0, 0.0, rng) == c0;
  }
  EXPECT_GE(same, 40);
  // A sensor offset moves the code; noise spreads it.
  EXPECT_GT(adc_counts(0.0, kBendSensitivityVPerT, 0.01, 0.0, rng), (kAdcMaxCount + 1) / 2 + 10);
  double sum = 0.0, sum2 = 0.0;
  for (int i = 0; i < 2000; ++i) {
    const double c = adc_counts(0.0, kBendSensitivityVPerT, 0.0, 10 * lsb_t, rng);
    sum += c;
    sum2 += c * c;
  }
  const double mean = sum / 2000, sd = std::sqrt(sum2 / 2000 - mean * mean);
  EXPECT_NEAR(mean, 2048.0, 1.0);
  EXPECT_NEAR(sd, 10.0, 1.5);
}

TEST(Stops, KeepBothHingesAndTheShaftAngle) {
  const double limit = 70.0 * M_PI / 180.0;
  Rng rng(5);
  for (int i = 0; i < 500; ++i) {
    double bx = rng.uniform(-3, 3), by = rng.uniform(-3, 3);
    const double bx0 = bx, by0 = by;
    clamp_bends_to_stops(bx, by, limit);
    EXPECT_LE(std::abs(bx), limit + 1e-12);
    EXPECT_LE(std::abs(by), limit + 1e-12);
    EXPECT_LE(shaft_angle_rad(bx, by), limit + 1e-9);
    if (std::abs(bx0) <= limit && std::abs(by0) <= limit && shaft_angle_rad(bx0, by0) <= limit) {
      EXPECT_EQ(bx, bx0);
      EXPECT_EQ(by, by0);
    }
  }
  EXPECT_NEAR(shaft_angle_rad(0.3, 0.0), 0.3, 1e-12);
  EXPECT_NEAR(shaft_angle_rad(0.0, -0.4), 0.4, 1e-12);
}

TEST(HallJoint, OptionsValidate) {
  HallJointOptions o = ideal_options();
  EXPECT_TRUE(o.validate().ok());
  o.kind.length_out_m = 0.005;
  EXPECT_FALSE(o.validate().ok());
  EXPECT_FALSE(HallJoint::create(o).ok());
  o = ideal_options();
  o.kind.bend_limit_rad = std::nan("");
  EXPECT_FALSE(o.validate().ok());
  EXPECT_NE(ideal_options().describe().find("seed"), std::string::npos);
}

TEST(HallJoint, IdealTwistElementsAreInQuadratureAndBendsIgnoreTheInletTwist) {
  auto j = HallJoint::create(ideal_options());
  ASSERT_TRUE(j.ok());
  Rng rng(1);
  const JointEnvironment quiet;
  // Radial field ~ cos(theta) at element a, sin(theta) at element b (90 deg
  // round): turning the ring 90 deg puts b's signal, negated, at a. What the
  // bend magnet adds is the same at both (symmetric about the axis), so
  // a(t + 90) + b(t) is one constant, and the amplitude is one radius.
  double sum0 = 0.0, radius0 = 0.0;
  for (double t : {-2.5, -1.0, 0.0, 0.7, 2.0}) {
    j->move_to({t, 0.2, -0.3, 1.0});
    const HallReadings r = j->read(quiet, rng);
    j->move_to({t + M_PI / 2, 0.2, -0.3, 1.0});
    const HallReadings r90 = j->read(quiet, rng);
    const double sum = r90.twist_in[0] + r.twist_in[1];
    const double radius = std::hypot(r.twist_in[0] - 2048, r.twist_in[1] - 2048);
    if (t == -2.5) {
      sum0 = sum;
      radius0 = radius;
    }
    EXPECT_NEAR(sum, sum0, 1.5) << t;
    EXPECT_NEAR(radius, radius0, 0.02 * radius0) << t;
    EXPECT_GT(radius, 500.0);
  }
  // Bend channels: magnet and inlet ring magnet both turn with yoke 1, so
  // turning the inlet ring changes nothing the 2-D sensor sees.
  j->move_to({0.0, 0.5, 0.3, 1.0});
  const HallReadings a = j->read(quiet, rng);
  j->move_to({2.0, 0.5, 0.3, 1.0});
  const HallReadings b = j->read(quiet, rng);
  for (int c = 0; c < 2; ++c) {
    EXPECT_NEAR(a.bend[c], b.bend[c], 0.02);  // rounding of the frames may flip one conversion of 64
    EXPECT_NEAR(a.twist_out[c], b.twist_out[c], 0.02);
  }
  EXPECT_NE(a.twist_in, b.twist_in);
  // Bending moves the 2-D reading: about +-k sin(bend) around mid-scale.
  j->move_to({0.0, 0.0, 0.0, 0.0});
  const HallReadings straight = j->read(quiet, rng);
  j->move_to({0.0, 0.6, 0.0, 0.0});
  const HallReadings bent = j->read(quiet, rng);
  EXPECT_GT(std::abs(bent.bend[1] - straight.bend[1]), 500.0);
}

TEST(HallJoint, ReproducibleBySeedAndDifferentAcrossSeeds) {
  HallJointOptions o;
  o.kind = default_kit().joint;
  o.seed = 42;
  auto a = HallJoint::create(o), b = HallJoint::create(o);
  o.seed = 43;
  auto c = HallJoint::create(o);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  const JointAngles cmd{0.4, -0.3, 0.5, -1.2};
  a->move_to(cmd);
  b->move_to(cmd);
  c->move_to(cmd);
  Rng ra(9), rb(9), rc(9);
  const HallReadings x = a->read({}, ra), y = b->read({}, rb), z = c->read({}, rc);
  EXPECT_EQ(x.bend, y.bend);
  EXPECT_EQ(x.twist_in, y.twist_in);
  EXPECT_EQ(x.twist_out, y.twist_out);
  EXPECT_NE(x.bend, z.bend);  // another joint, built differently
}

TEST(HallJoint, PlayMakesHysteresis) {
  HallJointOptions o = ideal_options();
  o.backlash = true;
  auto j = HallJoint::create(o);
  ASSERT_TRUE(j.ok());
  j->move_to({-0.1, -0.1, -0.1, -0.1});
  j->move_to({0.0, 0.0, 0.0, 0.0});
  const JointAngles from_below = j->actual_angles();
  j->move_to({0.1, 0.1, 0.1, 0.1});
  j->move_to({0.0, 0.0, 0.0, 0.0});
  const JointAngles from_above = j->actual_angles();
  for (auto field : {&JointAngles::twist_in_rad, &JointAngles::bend_x_rad, &JointAngles::bend_y_rad,
                     &JointAngles::twist_out_rad}) {
    const double gap = from_above.*field - from_below.*field;
    EXPECT_GE(gap, kBacklashMinRad + kFrictionBandRad - 1e-12);
    EXPECT_LE(gap, kBacklashMaxRad + kFrictionBandRad + 1e-12);
  }
  // Without play the shafts go where they are pushed (within the stops).
  auto rigid = HallJoint::create(ideal_options());
  rigid->move_to({0.3, 0.2, -0.1, 3.0});
  EXPECT_EQ(rigid->actual_angles().bend_x_rad, 0.2);
  EXPECT_EQ(rigid->actual_angles().twist_out_rad, 3.0);
  rigid->move_to({0.0, 2.0, 0.0, 0.0});
  EXPECT_NEAR(rigid->actual_angles().bend_x_rad, default_kit().joint.bend_limit_rad, 1e-12);
}

TEST(HallJoint, AmbientFieldMovesReadingsAsTheDeviceTurns) {
  auto j = HallJoint::create(ideal_options());
  j->move_to({0.2, 0.3, 0.1, -0.5});
  Rng rng(1);
  JointEnvironment env;
  env.ambient_field_world_t = Vec3(0, 0, kEarthFieldT);
  const HallReadings up = j->read(env, rng);
  env.q_world_inlet = Quat(Eigen::AngleAxisd(M_PI, Vec3::UnitX()));
  const HallReadings down = j->read(env, rng);
  const HallReadings none = j->read({}, rng);
  double moved = 0.0;
  for (int c = 0; c < 2; ++c) {
    moved = std::max({moved, std::abs(up.bend[c] - down.bend[c]), std::abs(up.twist_in[c] - down.twist_in[c])});
    // Earth's field is small beside the magnets': a few counts at most.
    EXPECT_LT(std::abs(up.bend[c] - none.bend[c]), 5.0);
  }
  EXPECT_GT(moved, 0.5);
}

TEST(HallJoint, NeighbourMagnetsMatterLessFartherAway) {
  auto j = HallJoint::create(ideal_options());
  j->move_to({0.0, 0.2, 0.2, 0.0});
  Rng rng(1);
  const HallReadings base = j->read({}, rng);
  double previous = 1e9;
  for (double z : {0.045, 0.06, 0.09}) {
    JointEnvironment env;
    env.neighbour_magnets_inlet = {{Vec3(0, 0, z + 0.03), Vec3(0.0, 0.5, 0.0)}};
    const HallReadings r = j->read(env, rng);
    const double effect = std::abs(r.twist_out[1] - base.twist_out[1]) + std::abs(r.bend[1] - base.bend[1]);
    EXPECT_LT(effect, previous) << z;
    previous = effect;
  }
}

TEST(HallJoint, MagnetsAndOutletFollowTheAngles) {
  auto j = HallJoint::create(ideal_options());
  const JointAngles a{0.3, -0.4, 0.5, 1.1};
  j->move_to(a);
  const Pose T = j->T_inlet_outlet();
  EXPECT_LT(T.q.angularDistance(joint_rotation(a)), 1e-12);
  const auto magnets = j->magnets_in_inlet();
  ASSERT_EQ(magnets.size(), 3u);
  // The bend magnet sits at the Cardan centre, along yoke 1's axis.
  EXPECT_LT((magnets[1].p_m - Vec3(0, 0, default_kit().joint.length_in_m)).norm(), 1e-12);
  EXPECT_NEAR(magnets[1].moment_am2.normalized().z(), 1.0, 1e-12);
  // transform_magnets and its inverse.
  const Pose T2{Quat(Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized())), Vec3(0.01, 0.02, -0.03)};
  const auto back = transform_magnets(T2.inverse(), transform_magnets(T2, magnets));
  for (std::size_t i = 0; i < magnets.size(); ++i) {
    EXPECT_LT((back[i].p_m - magnets[i].p_m).norm(), 1e-15);
    EXPECT_LT((back[i].moment_am2 - magnets[i].moment_am2).norm(), 1e-15);
  }
}

TEST(HallJoint, NeighbourMagnetsOfADeviceInOneJointsInletFrame) {
  // A chain of two joints: the second's magnets, placed in the device frame
  // through the first's outlet, seen from the second's inlet are its own.
  auto a = HallJoint::create(ideal_options());
  auto b = HallJoint::create(ideal_options());
  a->move_to({0.2, 0.3, -0.2, 0.4});
  b->move_to({-0.1, 0.5, 0.1, 1.0});
  const Pose T_device_a{Quat(Eigen::AngleAxisd(0.3, Vec3::UnitY())), Vec3(0.1, 0.0, 0.0)};
  const Pose T_device_b = T_device_a * a->T_inlet_outlet();
  const auto b_in_device = transform_magnets(T_device_b, b->magnets_in_inlet());
  const auto seen = neighbour_magnets_in_inlet(T_device_b, b_in_device);
  const auto own = b->magnets_in_inlet();
  ASSERT_EQ(seen.size(), own.size());
  for (std::size_t i = 0; i < own.size(); ++i) {
    EXPECT_LT((seen[i].p_m - own[i].p_m).norm(), 1e-12);
    EXPECT_LT((seen[i].moment_am2 - own[i].moment_am2).norm(), 1e-12);
  }
  // From the first joint's inlet the second's magnets are within reach; a
  // magnet a metre off is not.
  auto near = neighbour_magnets_in_inlet(T_device_a, b_in_device);
  EXPECT_EQ(near.size(), 3u);
  EXPECT_TRUE(neighbour_magnets_in_inlet(T_device_a, {{Vec3(1.1, 0, 0), Vec3(0, 0, 1)}}).empty());
}

TEST(CalibrationJig, VisitsTheGridBothWaysWithinTheStops) {
  HallJointOptions o;
  o.kind = default_kit().joint;
  auto j = HallJoint::create(o);
  Rng rng(1);
  JigOptions jig;
  jig.bend_grid = 5;
  auto samples = run_calibration_jig(*j, jig, Vec3::Zero(), rng);
  ASSERT_TRUE(samples.ok());
  ASSERT_EQ(samples->size(), 50u);
  for (std::size_t k = 0; k < 25; ++k) {
    const JigSample& fwd = (*samples)[k];
    const JigSample& back = (*samples)[49 - k];
    EXPECT_EQ(fwd.jig_angles.bend_x_rad, back.jig_angles.bend_x_rad);
    EXPECT_EQ(fwd.jig_angles.bend_y_rad, back.jig_angles.bend_y_rad);
    EXPECT_LE(shaft_angle_rad(fwd.jig_angles.bend_x_rad, fwd.jig_angles.bend_y_rad), o.kind.bend_limit_rad + 1e-9);
    EXPECT_LE(std::abs(fwd.jig_angles.twist_in_rad), M_PI);
  }
  jig.bend_grid = 2;
  EXPECT_FALSE(run_calibration_jig(*j, jig, Vec3::Zero(), rng).ok());
  EXPECT_NE(JigOptions{}.describe().find("both ways"), std::string::npos);
}

}  // namespace
}  // namespace proprio::rig_device
