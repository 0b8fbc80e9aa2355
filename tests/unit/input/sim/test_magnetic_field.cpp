#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "proprio/core/hand_model.hpp"
#include "proprio/sim/magnetic_field.hpp"
#include "proprio/sim/subjects.hpp"

using namespace proprio;
using namespace proprio::sim;

namespace {

MagneticDipole fixed_dipole(const Vec3& m_Am2, const Pose& T_world_dipole, const char* name = "test") {
  MagneticDipole d;
  d.name = name;
  d.moment_static_Am2 = m_Am2;
  d.T_world_dipole = fixed_pose(T_world_dipole);
  d.min_distance_m = 1e-6;
  return d;
}

EarthFieldOptions no_earth() {
  EarthFieldOptions e;
  e.magnitude_T = 0.0;
  return e;
}

}  // namespace

TEST(DipoleField, OnAxisAndEquatorialValuesAreTheAnalyticOnes) {
  const double m = 1e-3;  // A·m²
  const Vec3 moment(0.0, 0.0, m);
  for (double r : {0.005, 0.02, 0.1}) {
    // On the axis: B = μ0/4π · 2m / r³, along m.
    const Vec3 axial = dipole_field_T(moment, Vec3(0.0, 0.0, r));
    const double expected_axial = 2.0 * kMu0Over4Pi * m / (r * r * r);
    EXPECT_NEAR(axial.z(), expected_axial, 1e-12 * expected_axial) << r;
    EXPECT_NEAR(axial.head<2>().norm(), 0.0, 1e-15 * expected_axial);
    // Behind it, the same (the field is even in r).
    EXPECT_NEAR(dipole_field_T(moment, Vec3(0.0, 0.0, -r)).z(), expected_axial, 1e-12 * expected_axial);
    // In the equatorial plane: half as strong, against m.
    const Vec3 equatorial = dipole_field_T(moment, Vec3(r, 0.0, 0.0));
    EXPECT_NEAR(equatorial.z(), -0.5 * expected_axial, 1e-12 * expected_axial) << r;
    EXPECT_NEAR(equatorial.head<2>().norm(), 0.0, 1e-15 * expected_axial);
  }
  // 2·1e-7·1e-3/(0.02)³ = 25 µT, written out so a wrong constant would show.
  EXPECT_NEAR(dipole_field_T(moment, Vec3(0.0, 0.0, 0.02)).z(), 25e-6, 1e-12);
  EXPECT_EQ(dipole_field_T(moment, Vec3::Zero()), Vec3::Zero());
}

TEST(DipoleField, EnvironmentRotatesTheMomentWithThePose) {
  auto env = MagneticEnvironment::create(no_earth());
  ASSERT_TRUE(env.ok());
  // Dipole frame +Z turned onto world +X, placed at (1, 2, 3).
  const Pose T_world_dipole{so3_exp(Vec3(0.0, M_PI / 2.0, 0.0)), Vec3(1.0, 2.0, 3.0)};
  ASSERT_TRUE(env->add_dipole(fixed_dipole(Vec3(0.0, 0.0, 2e-3), T_world_dipole)).ok());
  const double r = 0.03;
  const Vec3 b = env->field_world_T(T_world_dipole.p + Vec3(r, 0.0, 0.0), 0);
  const double expected = 2.0 * kMu0Over4Pi * 2e-3 / (r * r * r);
  EXPECT_NEAR(b.x(), expected, 1e-10 * expected);
  EXPECT_NEAR(b.y(), 0.0, 1e-10 * expected);
  EXPECT_NEAR(b.z(), 0.0, 1e-10 * expected);
}

TEST(DipoleField, MinDistanceKeepsTheFieldFinite) {
  auto env = MagneticEnvironment::create(no_earth());
  ASSERT_TRUE(env.ok());
  MagneticDipole d = fixed_dipole(Vec3(0.0, 0.0, 1e-3), Pose::identity());
  d.min_distance_m = 0.01;
  ASSERT_TRUE(env->add_dipole(d).ok());
  const Vec3 at_limit = env->field_world_T(Vec3(0.0, 0.0, 0.01), 0);
  EXPECT_LT((env->field_world_T(Vec3(0.0, 0.0, 1e-4), 0) - at_limit).norm(), 1e-12 * at_limit.norm());
  EXPECT_TRUE(env->field_world_T(Vec3::Zero(), 0).allFinite());
  EXPECT_GT(at_limit.z(), env->field_world_T(Vec3(0.0, 0.0, 0.02), 0).z());
}

TEST(EarthField, MagnitudeDipAndDeclinationAreAsConfigured) {
  EarthFieldOptions o;
  ASSERT_TRUE(o.validate().ok());
  EXPECT_NEAR(o.magnitude_T, 50e-6, 1e-12);
  const Vec3 b = earth_field_world_T(o);
  EXPECT_NEAR(b.norm(), o.magnitude_T, 1e-18);
  EXPECT_NEAR(inclination_of(b), o.inclination_rad, 1e-12);
  EXPECT_LT(b.y(), 0.0) << "northern hemisphere: the field points down";
  // Horizontal part: north (-Z) turned east (+X, north x up) by the declination.
  const double heading_east_of_north = std::atan2(b.x(), -b.z());
  EXPECT_NEAR(heading_east_of_north, o.declination_rad, 1e-12);

  EarthFieldOptions south = o;
  south.inclination_rad = deg_to_rad(-30.0);
  south.declination_rad = 0.0;
  south.north_world = Vec3(1.0, 0.0, 0.0);
  const Vec3 bs = earth_field_world_T(south);
  EXPECT_NEAR(rad_to_deg(inclination_of(bs)), -30.0, 1e-9);
  EXPECT_GT(bs.y(), 0.0);
  EXPECT_NEAR(bs.z(), 0.0, 1e-18);
  EXPECT_GT(bs.x(), 0.0);
}

TEST(EarthField, ValidateNamesTheBadField) {
  EarthFieldOptions o;
  o.inclination_rad = 2.0;
  auto s = o.validate();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("inclination_rad"), std::string::npos) << s.error().message;
  o = EarthFieldOptions{};
  o.north_world = Vec3(0.0, 1.0, 0.0);
  EXPECT_FALSE(o.validate().ok());
  EXPECT_FALSE(MagneticEnvironment::create(o).ok());
  o = EarthFieldOptions{};
  o.magnitude_T = std::nan("");
  EXPECT_FALSE(o.validate().ok());
}

TEST(MagneticEnvironment, RejectsDipolesWithoutAPlace) {
  MagneticEnvironment env;
  MagneticDipole d;
  d.name = "lost";
  auto r = env.add_dipole(d);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("lost"), std::string::npos);
  d.T_world_dipole = fixed_pose(Pose::identity());
  d.min_distance_m = 0.0;
  EXPECT_FALSE(env.add_dipole(d).ok());
  EXPECT_FALSE(env.set_current(0, 0, 1.0).ok()) << "no dipole 0 was added";
}

TEST(MagneticEnvironment, CurrentScalesTheMomentFromTheTimeItIsSet) {
  auto env = MagneticEnvironment::create(no_earth());
  ASSERT_TRUE(env.ok());
  MagneticDipole d = fixed_dipole(Vec3(0.0, 0.0, 1e-4), Pose::identity());
  d.moment_per_current_Am2_per_A = Vec3(0.0, 0.0, 2e-4);
  d.current_A = [](TimeNs t) { return t < 0 ? 0.25 : 0.0; };
  const auto idx = env->add_dipole(d);
  ASSERT_TRUE(idx.ok());
  ASSERT_TRUE(env->set_current(*idx, 100, 1.5).ok());
  ASSERT_TRUE(env->set_current(*idx, 50, 0.5).ok());  // out of order: inserted before
  const Vec3 p(0.0, 0.0, 0.02);
  const double per_Am2 = 2.0 * kMu0Over4Pi / (0.02 * 0.02 * 0.02);
  EXPECT_NEAR(env->current_A(*idx, -5), 0.25, 0.0) << "the function before any set time";
  EXPECT_NEAR(env->field_world_T(p, -5).z(), per_Am2 * (1e-4 + 0.25 * 2e-4), 1e-15);
  EXPECT_NEAR(env->field_world_T(p, 10).z(), per_Am2 * 1e-4, 1e-15);
  EXPECT_NEAR(env->current_A(*idx, 50), 0.5, 0.0);
  EXPECT_NEAR(env->current_A(*idx, 99), 0.5, 0.0);
  EXPECT_NEAR(env->field_world_T(p, 1000).z(), per_Am2 * (1e-4 + 1.5 * 2e-4), 1e-15);
}

TEST(MagneticEnvironment, AttachedDipoleFollowsTheHand) {
  const HandModel model(*sim_subject(3)->shape());
  HandAngles angles{};
  const Pose T_world_wrist{so3_exp(Vec3(0.3, 0.2, -0.1)), Vec3(0.0, 1.0, -0.3)};
  const HandPose hand = model.forward(Handedness::right, angles, T_world_wrist, 0);
  auto created = MagneticEnvironment::create(no_earth());
  ASSERT_TRUE(created.ok());
  MagneticEnvironment& env = *created;
  HapticDeviceDipoleOptions ho;
  const auto idx = env.add_dipole(haptic_device_dipole(HandJoint::index_tip, ho));
  ASSERT_TRUE(idx.ok());
  EXPECT_FALSE(env.dipole_pose_world(*idx, 0, nullptr).has_value());
  EXPECT_EQ(env.field_world_T(Vec3::Zero(), 0, nullptr), Vec3::Zero()) << "no hand: the attached dipole is left out";
  const auto T = env.dipole_pose_world(*idx, 0, &hand);
  ASSERT_TRUE(T.has_value());
  const Pose expected = hand.joint(HandJoint::index_tip) * ho.T_tip_device;
  EXPECT_LT((T->p - expected.p).norm(), 1e-15);
  // 10 mm along the device's axis the field is that of its static moment.
  const Vec3 axis = T->q * Vec3::UnitZ();
  const Vec3 b = env.field_world_T(T->p + 0.01 * axis, 0, &hand);
  EXPECT_NEAR(b.dot(axis), 2.0 * kMu0Over4Pi * ho.moment_static_Am2 / 1e-6, 1e-15);
}

TEST(MagneticPresets, FingertipDeviceMeetsTheTenMillimetreRuleAtFullCurrent) {
  // The sizing in magnetic_field.hpp: at full current, on the axis (the worst
  // direction), exactly the significance threshold at 10 mm.
  const HapticDeviceDipoleOptions o;
  const double m_full = o.moment_static_Am2 + o.full_current_A * o.moment_per_current_Am2_per_A;
  const double r = kHapticSafeDistance_m;
  const double b_axis = dipole_field_T(Vec3(0.0, 0.0, m_full), Vec3(0.0, 0.0, r)).norm();
  EXPECT_NEAR(b_axis, kSignificantDisturbance_T, 1e-6 * kSignificantDisturbance_T);
  EXPECT_NEAR(kSignificantDisturbance_T / EarthFieldOptions{}.magnitude_T, 0.1, 1e-12);
  // 5 mm: eight times the threshold; 20 mm: an eighth.
  EXPECT_GT(dipole_field_T(Vec3(0.0, 0.0, m_full), Vec3(0.005, 0.0, 0.0)).norm(), kSignificantDisturbance_T);
  EXPECT_LT(dipole_field_T(Vec3(0.0, 0.0, m_full), Vec3(0.0, 0.0, 0.02)).norm(), kSignificantDisturbance_T);
}

TEST(MagneticPresets, ObjectFieldsAreTheDocumentedOnes) {
  auto env = MagneticEnvironment::create(no_earth());
  ASSERT_TRUE(env.ok());
  const auto drill = env->add_dipole(drill_dipole(fixed_pose(Pose::identity())));
  ASSERT_TRUE(drill.ok());
  EXPECT_NEAR(env->field_world_T(Vec3(0.0, 0.0, 0.1), 0).z(), 200e-6, 1e-9);

  auto env2 = MagneticEnvironment::create(no_earth());
  ASSERT_TRUE(env2.ok());
  ASSERT_TRUE(env2->add_dipole(fan_dipole(fixed_pose(Pose::identity()))).ok());
  EXPECT_NEAR(env2->field_world_T(Vec3(0.0, 0.0, 0.1), 0).z(), 10e-6, 1e-10);

  auto env3 = MagneticEnvironment::create(no_earth());
  ASSERT_TRUE(env3.ok());
  ASSERT_TRUE(env3->add_dipole(earphone_case_dipole(fixed_pose(Pose::identity()))).ok());
  EXPECT_NEAR(env3->field_world_T(Vec3(0.0, 0.0, 0.05), 0).z(), 160e-6, 1e-9);
}

TEST(ScriptedApproach, ApproachesHoldsAndRetreats) {
  ScriptedApproach s;
  s.T_world_far.p = Vec3(0.0, 1.0, -1.0);
  s.T_world_near.p = Vec3(0.0, 1.0, -0.35);
  s.T_world_near.q = so3_exp(Vec3(0.0, 0.5, 0.0));
  s.t_start_ns = 1 * kNsPerSecond;
  const Vec3 hand(0.0, 1.0, -0.3);
  EXPECT_LT((s(0).p - s.T_world_far.p).norm(), 1e-12);
  EXPECT_LT((s(s.t_start_ns).p - s.T_world_far.p).norm(), 1e-12);
  double last = (s(s.t_start_ns).p - hand).norm();
  for (TimeNs t = s.t_start_ns; t <= s.t_start_ns + s.approach_ns; t += 100 * kNsPerMillisecond) {
    const double d = (s(t).p - hand).norm();
    EXPECT_LE(d, last + 1e-12) << "the approach never backs off";
    last = d;
  }
  const TimeNs mid_hold = s.t_start_ns + s.approach_ns + s.hold_ns / 2;
  EXPECT_LT((s(mid_hold).p - s.T_world_near.p).norm(), 1e-12);
  EXPECT_LT(angle_between(s(mid_hold).q, s.T_world_near.q), 1e-9);
  const TimeNs gone = s.t_start_ns + s.approach_ns + s.hold_ns + s.retreat_ns;
  EXPECT_LT((s(gone + 1).p - s.T_world_far.p).norm(), 1e-12);
  const Vec3 halfway = s(s.t_start_ns + s.approach_ns / 2).p;
  EXPECT_NEAR(halfway.z(), -0.675, 1e-9) << "minimum-jerk is symmetric: halfway at half time";
}
