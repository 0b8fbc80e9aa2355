// The MuJoCo contact simulation: the proxy hand's structure, coupling
// stability, contact forces against analytic expectations, and tunnelling.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>

#include "proprio/haptics/contact_sim.hpp"
#include "proprio/haptics/force_laws.hpp"
#include "proprio/haptics/touch_script.hpp"

namespace proprio::haptics {
namespace {

HandModel test_hand() {
  auto shape = HandShape::from_measurements(0.19, 0.09);
  EXPECT_TRUE(shape);
  return HandModel(*shape);
}

HapticScene empty_scene() {
  HapticScene s;
  s.floor_height_m.reset();
  return s;
}

// A slightly curled hand, so every joint is away from zero.
HandAngles curled() {
  HandAngles a{};
  for (std::size_t i = 0; i < kHandDofCount; ++i) {
    a[i] = is_abduction(static_cast<HandDof>(i)) ? 0.05 : 0.3;
  }
  return a;
}

double max_joint_error(const HandPose& a, const HandPose& b) {
  double e = 0;
  for (double x : joint_position_errors(a, b)) e = std::max(e, x);
  return e;
}

TEST(ContactSim, ProxyHasTheKinematicHandsStructureForBothHands) {
  const HandModel model = test_hand();
  for (Handedness hand : {Handedness::right, Handedness::left}) {
    auto sim = ContactSimulation::create(model, hand, empty_scene());
    ASSERT_TRUE(sim) << sim.error().message;
    const Pose T_world_wrist{Quat(Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized())), Vec3(0.1, 1.1, -0.3)};
    sim->reset_hand(T_world_wrist, curled());
    const HandPose expected = model.forward(hand, curled(), T_world_wrist, 0);
    const HandPose proxy = sim->proxy_pose(0);
    EXPECT_LT(max_joint_error(proxy, expected), 1e-9) << to_string(hand);
    // Joint frames too: the fingertip frame is what forces are expressed in.
    for (std::size_t j = 0; j < kHandJointCount; ++j) {
      EXPECT_LT(proxy.T_world_joint[j].q.angularDistance(expected.T_world_joint[j].q), 1e-9)
          << to_string(hand) << " " << to_string(joint_at(j));
    }
  }
}

TEST(ContactSim, FollowsTheTrackedHandInFreeSpace) {
  auto sim = ContactSimulation::create(test_hand(), Handedness::right, empty_scene());
  ASSERT_TRUE(sim) << sim.error().message;
  const Pose start{Quat::Identity(), Vec3(0, 1.2, -0.3)};
  sim->reset_hand(start, HandAngles{});
  // 10 cm/s sideways while curling the fingers over 1 s, then hold 0.5 s.
  for (int i = 0; i < 1500; ++i) {
    const double t = std::min(1.0, i * 1e-3);
    HandAngles a = curled();
    for (double& x : a) x *= t;
    sim->set_target(Pose{Quat::Identity(), start.p + Vec3(0.1 * t, 0, 0)}, a);
    sim->step();
  }
  const HandPose expected = test_hand().forward(Handedness::right, curled(), Pose{Quat::Identity(), start.p + Vec3(0.1, 0, 0)}, 0);
  EXPECT_LT(max_joint_error(sim->proxy_pose(0), expected), 0.002);
  EXPECT_EQ(sim->stats().instability_resets, 0u);
}

// Impulses on every DOF, for gain sets across the documented range: the
// motion must stay bounded and die out (no energy growth at 1 kHz).
TEST(ContactSim, CouplingIsStableAndDampedAcrossTheGainRange) {
  struct Gains { double wrist_tau, joint_k; };
  for (const Gains g : {Gains{0.005, 0.1}, Gains{0.005, 2.0}, Gains{0.02, 0.5}, Gains{0.1, 0.1}, Gains{0.1, 2.0}}) {
    ContactSimOptions o;
    o.coupling.wrist_time_constant_s = g.wrist_tau;
    o.coupling.joint_stiffness_nm_per_rad = g.joint_k;
    o.coupling.joint_damping_nms_per_rad = 2.0 * std::sqrt(g.joint_k * o.coupling.joint_armature_kg_m2);
    auto sim = ContactSimulation::create(test_hand(), Handedness::right, empty_scene(), o);
    ASSERT_TRUE(sim) << sim.error().message;
    const Pose T{Quat::Identity(), Vec3(0, 1.2, -0.3)};
    sim->reset_hand(T, curled());
    sim->set_target(T, curled());
    // The impulse: the tracked hand jumps 1.5 cm and 0.3 rad per joint for one step.
    HandAngles kicked = curled();
    for (double& x : kicked) x += 0.3;
    sim->set_target(Pose{T.q, T.p + Vec3(0.015, 0.0, 0.0)}, kicked);
    sim->step();
    sim->set_target(T, curled());
    const HandPose rest = test_hand().forward(Handedness::right, curled(), T, 0);
    double early = 0, late = 0;
    for (int i = 0; i < 1500; ++i) {
      sim->step();
      const double e = max_joint_error(sim->proxy_pose(0), rest);
      ASSERT_TRUE(std::isfinite(e));
      ASSERT_LT(e, 0.05) << "wrist tau " << g.wrist_tau << " joint k " << g.joint_k << " step " << i;
      if (i < 100) early = std::max(early, e);
      if (i >= 1300) late = std::max(late, e);
    }
    EXPECT_LT(late, 0.1 * early + 1e-4) << "wrist tau " << g.wrist_tau << " joint k " << g.joint_k;
    EXPECT_EQ(sim->stats().instability_resets, 0u);
  }
}

// The hand palm up, a 20 g block resting on the index fingertip's pad: the
// pad must carry exactly the block's weight, along its normal.
TEST(ContactSim, FingertipUnderAWeightFeelsItAlongThePadNormal) {
  const HandModel model = test_hand();
  // Palm up: the back of the hand (+Y) faces the floor, fingers point forward (-z).
  const Pose T_world_wrist{Quat(Eigen::AngleAxisd(M_PI, Vec3::UnitZ())), Vec3(0, 1.0, -0.3)};
  const HandPose pose = model.forward(Handedness::right, HandAngles{}, T_world_wrist, 0);
  const Vec3 p_dip = pose.joint(HandJoint::index_distal).p, p_tip = pose.joint(HandJoint::index_tip).p;
  const double r = 0.5 * (pose.radius_m[index_of(HandJoint::index_distal)] + pose.radius_m[index_of(HandJoint::index_tip)]);
  const double mass = 0.02;
  HapticScene scene = empty_scene();
  // Short enough to rest on the distal segment alone, clear of the
  // intermediate segment's rounded end at the DIP joint.
  SceneObject block = SceneObject::box("block", Vec3(0.004, 0.003, 0.004),
                                       Pose{Quat::Identity(), p_dip + 0.65 * (p_tip - p_dip) + Vec3(0, r + 0.003 + 0.0005, 0)});
  block.fixed = false;
  block.mass_kg = mass;
  scene.objects.push_back(block);
  // The peg-in-hole study's looser solver tolerance and point contacts
  // (no torsional friction) must feel the same weight.
  struct Variant {
    double tolerance;
    bool torsion;
  };
  for (const Variant v : {Variant{1e-8, true}, Variant{1e-5, true}, Variant{1e-5, false}}) {
    SCOPED_TRACE(fmt::format("tolerance {}, torsional friction {}", v.tolerance, v.torsion));
    ContactSimOptions o;
    o.solver_tolerance = v.tolerance;
    o.torsional_friction = v.torsion;
    auto sim = ContactSimulation::create(model, Handedness::right, scene, o);
    ASSERT_TRUE(sim) << sim.error().message;
    EXPECT_NE(sim->mjcf().find(v.torsion ? "condim=\"4\"" : "condim=\"3\""), std::string::npos);
    EXPECT_NE(o.describe().find(v.torsion ? "condim 4" : "condim 3"), std::string::npos) << o.describe();
    sim->reset_hand(T_world_wrist, HandAngles{});
    for (int i = 0; i < 1000; ++i) sim->step();
    const FingertipContact& tip = sim->fingertip(Finger::index);
    const double weight = mass * 9.81;
    EXPECT_NEAR(tip.force.normal_n, weight, 0.03 * weight);
    EXPECT_NEAR(tip.contact_normal_n, weight, 0.03 * weight) << "pad square to the load: the same force";
    EXPECT_NEAR(tip.object_normal_n, tip.contact_normal_n, 1e-12) << "the movable block is all it touches";
    EXPECT_LT(tip.force.shear_magnitude_n(), 0.05 * weight);
    EXPECT_GT(tip.contact_count, 0);
    EXPECT_LT(tip.max_penetration_m, 0.002);
    for (Finger f : {Finger::thumb, Finger::middle, Finger::ring, Finger::little}) {
      EXPECT_EQ(sim->fingertip(f).force.normal_n, 0.0) << static_cast<int>(f);
    }
    // The block is still on the finger.
    auto block_pose = sim->object_pose("block");
    ASSERT_TRUE(block_pose);
    EXPECT_NEAR(block_pose->p.y(), block.T_world_object.p.y(), 0.006);  // the finger's servos give a little
  }
}

// Fingertips pressed onto a table and dragged: shear opposes the motion and
// stays inside the friction cone.
TEST(ContactSim, SlidingGivesShearOpposingTheMotionWithinTheFrictionCone) {
  const HandModel model = test_hand();
  // The touch script's pointing hand: index straight, pitched down, the
  // other fingers curled away, so only the index tip meets the table.
  const TouchScript script(model, Handedness::right);
  Pose T0;
  HandAngles pointing;
  script.at(0.0, T0, pointing);
  const HandPose pose = model.forward(Handedness::right, pointing, T0, 0);
  double lowest = 1e9;
  for (std::size_t j = 0; j < kHandJointCount; ++j) lowest = std::min(lowest, pose.T_world_joint[j].p.y() - pose.radius_m[j]);
  const double mu = 0.6;
  HapticScene scene = empty_scene();
  SceneObject table = SceneObject::box("table", Vec3(0.5, 0.02, 0.5), Pose{Quat::Identity(), Vec3(0, lowest - 0.02, -0.3)});
  table.friction = mu;
  scene.objects.push_back(table);
  auto sim = ContactSimulation::create(model, Handedness::right, scene);
  ASSERT_TRUE(sim) << sim.error().message;
  sim->reset_hand(T0, pointing);
  // Press 1 cm down, settle, then slide along +x at 5 cm/s.
  const Pose pressed{T0.q, T0.p - Vec3(0, 0.01, 0)};
  for (int i = 0; i < 300; ++i) {
    sim->set_target(pressed, pointing);
    sim->step();
  }
  // The pitched-down pad meets the table at an angle: the contact's normal
  // force is the table's (world +y); the pad frame's normal is less.
  const FingertipContact& pressed_tip = sim->fingertip(Finger::index);
  ASSERT_GT(pressed_tip.contact_count, 0);
  EXPECT_NEAR(pressed_tip.contact_normal_n, pressed_tip.f_in_world.y(), 0.05 * pressed_tip.f_in_world.y());
  EXPECT_LT(pressed_tip.force.normal_n, 0.98 * pressed_tip.contact_normal_n);
  // As the pad feels it (what a device gets): the whole normal force is
  // pressure, more than the pad frame's projection.
  EXPECT_NEAR(pressed_tip.on_pad.normal_n, pressed_tip.contact_normal_n, 1e-9 + 1e-9 * pressed_tip.contact_normal_n);
  EXPECT_EQ(pressed_tip.object_normal_n, 0.0) << "a fixed table is not a held object";
  int touching = 0, sliding_samples = 0;
  for (int i = 0; i < 600; ++i) {
    sim->set_target(Pose{pressed.q, pressed.p + Vec3(0.05 * i * 1e-3, 0, 0)}, pointing);
    sim->step();
    if (i < 200) continue;  // static friction breaking loose
    const FingertipContact& tip = sim->fingertip(Finger::index);
    if (tip.contact_count == 0) continue;  // stick-slip can lift the tip for a step
    ++touching;
    const Vec3 f = tip.f_in_world;
    const double normal = f.y();
    const Vec3 tangential(f.x(), 0, f.z());
    ASSERT_GT(normal, 0.0);
    EXPECT_LE(tangential.norm(), mu * normal * 1.02 + 1e-6) << "step " << i;
    EXPECT_LT(f.x(), 0.0) << "shear must oppose the +x motion, step " << i;
    EXPECT_LE(tip.on_pad.shear_magnitude_n(), mu * tip.on_pad.normal_n * 1.05 + 1e-3)
        << "felt on the pad, the friction stays within its cone, step " << i;
    if (tangential.norm() > 0.8 * mu * normal) ++sliding_samples;
  }
  EXPECT_GT(touching, 360);
  // Kinetic friction: the force sits at the cone's edge while sliding.
  EXPECT_GT(sliding_samples, touching * 3 / 4);
}

TEST(ContactSim, ProxyNeverTunnelsThroughAThinPlate) {
  const HandModel model = test_hand();
  const Pose T0{Quat::Identity(), Vec3(0, 1.1, -0.3)};
  HapticScene scene = empty_scene();
  const double top = 1.05;
  scene.objects.push_back(SceneObject::box("plate", Vec3(0.4, 0.01, 0.4), Pose{Quat::Identity(), Vec3(0, top - 0.01, -0.3)}));
  auto sim = ContactSimulation::create(model, Handedness::right, scene);
  ASSERT_TRUE(sim) << sim.error().message;
  sim->reset_hand(T0, HandAngles{});
  // The tracked hand goes 30 cm down, through the plate, in 0.5 s, and stays there.
  double worst = 1e9;
  for (int i = 0; i < 2000; ++i) {
    const double t = std::min(1.0, i / 500.0);
    sim->set_target(Pose{T0.q, T0.p - Vec3(0, 0.3 * t, 0)}, HandAngles{});
    sim->step();
    const HandPose p = sim->proxy_pose(0);
    for (std::size_t j = 0; j < kHandJointCount; ++j) {
      if (j == index_of(HandJoint::palm) || j == index_of(HandJoint::wrist)) continue;
      worst = std::min(worst, p.T_world_joint[j].p.y() - p.radius_m[j] - top);
    }
  }
  EXPECT_GT(worst, -0.003) << "deepest proxy penetration";
  EXPECT_GT(sim->stats().leash_engaged_steps, 1000u);
  EXPECT_GT(sim->proxy_wrist().p.y(), top);
}

TEST(ContactSim, PegInHoleSceneIsStable) {
  auto sim = ContactSimulation::create(test_hand(), Handedness::right, HapticScene::peg_in_hole());
  ASSERT_TRUE(sim) << sim.error().message;
  auto start = sim->object_pose("peg");
  ASSERT_TRUE(start);
  for (int i = 0; i < 1000; ++i) sim->step();
  auto end = sim->object_pose("peg");
  ASSERT_TRUE(end);
  EXPECT_LT((end->p - start->p).norm(), 0.002);
  EXPECT_LT(end->q.angularDistance(start->q), 0.01);
  EXPECT_FALSE(sim->object_pose("table")->p.hasNaN());
  EXPECT_FALSE(sim->object_pose("nothing"));
  EXPECT_FALSE(sim->place_object("table", Pose{}));
  EXPECT_TRUE(sim->place_object("peg", *start));
}

// A table top as a contact plane holds what stands on it where its box
// would, and has no edges: a can beyond them stays at table height.
TEST(ContactSim, ATableTopPlaneHoldsObjectsAsItsBoxDoesButHasNoEdges) {
  const double top = 0.8;
  for (const bool plane : {false, true}) {
    SCOPED_TRACE(plane ? "plane" : "box");
    HapticScene scene = empty_scene();
    SceneObject table = SceneObject::box("table", Vec3(0.2, 0.02, 0.2), Pose{Quat::Identity(), Vec3(0, top - 0.02, 0)});
    table.contact_top_plane = plane;
    scene.objects.push_back(table);
    const Quat q_upright(Eigen::AngleAxisd(-M_PI / 2, Vec3::UnitX()));
    for (const auto& [name, x] : {std::pair{"on", 0.0}, std::pair{"beyond", 0.35}}) {
      SceneObject can = SceneObject::cylinder(name, 0.03, 0.05, Pose{q_upright, Vec3(x, top + 0.051, 0)});
      can.fixed = false;
      can.mass_kg = 0.3;
      scene.objects.push_back(can);
    }
    auto mjcf = generate_mjcf(test_hand(), Handedness::right, scene, ContactSimOptions{});
    ASSERT_TRUE(mjcf) << mjcf.error().message;
    EXPECT_EQ(mjcf->find("name=\"table\"") != std::string::npos &&
                  mjcf->find("type=\"plane\"") != std::string::npos,
              plane);
    auto sim = ContactSimulation::create(test_hand(), Handedness::right, scene);
    ASSERT_TRUE(sim) << sim.error().message;
    for (int i = 0; i < 1000; ++i) sim->step();
    EXPECT_NEAR(sim->object_pose("on")->p.y(), top + 0.05, 0.002);
    if (plane) {
      EXPECT_NEAR(sim->object_pose("beyond")->p.y(), top + 0.05, 0.002);
    } else {
      EXPECT_LT(sim->object_pose("beyond")->p.y(), top - 0.5) << "falls past the box's edge";
    }
  }
  SceneObject free_box = SceneObject::box("lid", Vec3(0.1, 0.01, 0.1), Pose{});
  free_box.fixed = false;
  free_box.contact_top_plane = true;
  ASSERT_FALSE(free_box.validate());
  EXPECT_NE(free_box.validate().error().message.find("lid"), std::string::npos);
  SceneObject ball = SceneObject::sphere("ball", 0.1, Pose{});
  ball.contact_top_plane = true;
  EXPECT_FALSE(ball.validate());
}

// A cylinder whose hand contacts go to a capsule: the palm holds it on the
// capsule's side, which is the cylinder's side, while the table still meets
// the flat base (a capsule tipped onto its dome would roll over). (A plain
// cylinder lying on the palm is no reference: libccd gives a cylinder one
// contact per geom pair, and it rolls off.)
TEST(ContactSim, ACylinderTheHandTouchesAsACapsuleStillStandsOnItsBase) {
  const HandModel model = test_hand();
  const Pose T_world_wrist{Quat(Eigen::AngleAxisd(M_PI, Vec3::UnitZ())), Vec3(0, 1.0, -0.3)};  // palm up
  const HandPose pose = model.forward(Handedness::right, HandAngles{}, T_world_wrist, 0);
  const double palm_top = T_world_wrist.p.y() + 0.6 * model.shape().palm_radius_m;
  const Vec3 p_palm = 0.5 * (T_world_wrist.p + pose.joint(HandJoint::middle_proximal).p);
  const double radius = 0.015, mass = 0.05, table_top = 0.5;
  HapticScene scene = empty_scene();
  SceneObject table = SceneObject::box("table", Vec3(0.2, 0.02, 0.2), Pose{Quat::Identity(), Vec3(0, table_top - 0.02, 0)});
  table.contact_top_plane = true;
  scene.objects.push_back(table);
  // Lying across the palm (axis along world x) ...
  SceneObject lying = SceneObject::cylinder(
      "lying", radius, 0.03,
      Pose{Quat(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitY())), Vec3(p_palm.x(), palm_top + radius + 0.0005, p_palm.z())});
  // ... and standing on the table, tipped 8 degrees onto its rim.
  const Quat q_tipped =
      Quat(Eigen::AngleAxisd(deg_to_rad(8.0), Vec3::UnitZ())) * Quat(Eigen::AngleAxisd(-M_PI / 2, Vec3::UnitX()));
  SceneObject standing = SceneObject::cylinder("standing", radius, 0.03, Pose{q_tipped, Vec3(0, table_top + 0.032, 0)});
  for (SceneObject* o : {&lying, &standing}) {
    o->fixed = false;
    o->mass_kg = mass;
    o->hand_touches_capsule = true;
    scene.objects.push_back(*o);
  }
  auto sim = ContactSimulation::create(model, Handedness::right, scene);
  ASSERT_TRUE(sim) << sim.error().message;
  EXPECT_NE(sim->mjcf().find("name=\"lying_hand\""), std::string::npos);
  sim->reset_hand(T_world_wrist, HandAngles{});
  for (int i = 0; i < 1500; ++i) sim->step();
  EXPECT_NEAR(sim->hand_force_on_object("lying").y(), mass * 9.81, 0.05 * mass * 9.81) << "the palm holds its weight";
  EXPECT_NEAR(sim->object_pose("lying")->p.y(), palm_top + radius, 0.0015) << "on its side, the cylinder's radius";
  EXPECT_EQ(sim->hand_force_on_object("standing"), Vec3::Zero()) << "the hand does not touch it";
  const Vec3 axis = sim->object_pose("standing")->q * Vec3::UnitZ();
  EXPECT_GT(axis.y(), std::cos(deg_to_rad(0.5))) << "settled back onto its flat base";
  EXPECT_NEAR(sim->object_pose("standing")->p.y(), table_top + 0.03, 0.001);

  SceneObject box = SceneObject::box("crate", Vec3(0.1, 0.1, 0.1), Pose{});
  box.hand_touches_capsule = true;
  ASSERT_FALSE(box.validate());
  EXPECT_NE(box.validate().error().message.find("crate"), std::string::npos);
  SceneObject puck = SceneObject::cylinder("puck", 0.03, 0.01, Pose{});
  puck.hand_touches_capsule = true;
  EXPECT_FALSE(puck.validate()) << "shorter than its diameter: the capsule would be a sphere";
}

// A peg a little narrower than the hole slides through it under gravity
// (the hole's axis tilted down); one wider than the hole cannot enter.
TEST(ContactSim, TightHoleAdmitsOnlyAPegThatFits) {
  for (const double clearance : {0.001, -0.003}) {
    HapticScene scene = empty_scene();
    const double hole_r = 0.02;
    // The hole's axis (object z) tilted below horizontal: 60 degrees for the
    // peg that fits; 80 for the one that does not, whose plate face is then
    // only 10 degrees off level, so it rests on the rim instead of sliding off.
    const Quat q_axis = Quat(Eigen::AngleAxisd(deg_to_rad(clearance > 0 ? 60.0 : 80.0), Vec3::UnitX()));
    scene.objects.push_back(SceneObject::plate_with_hole("plate", hole_r, Vec3(0.08, 0.08, 0.02), Pose{q_axis, Vec3(0, 1, 0)}));
    SceneObject peg = SceneObject::cylinder("peg", hole_r - clearance, 0.04, Pose{q_axis, Vec3(0, 1, 0) + q_axis * Vec3(0, 0, -0.07)});
    peg.fixed = false;
    peg.mass_kg = 0.2;
    peg.friction = 0.3;
    scene.objects.push_back(peg);
    auto sim = ContactSimulation::create(test_hand(), Handedness::right, scene);
    ASSERT_TRUE(sim) << sim.error().message;
    for (int i = 0; i < 1500; ++i) sim->step();
    const Vec3 p = sim->object_pose("peg")->p;
    const double along_axis = (q_axis.conjugate() * (p - Vec3(0, 1, 0))).z();
    if (clearance > 0) {
      EXPECT_GT(along_axis, 0.02) << "a fitting peg falls through the hole";
    } else {
      EXPECT_LT(along_axis, -0.055) << "an oversize peg stays out";
    }
  }
}

TEST(ContactSim, RejectsBadOptionsAndNonFiniteTargets) {
  ContactSimOptions o;
  o.coupling.wrist_time_constant_s = 0.001;  // below 2 timesteps
  auto bad = ContactSimulation::create(test_hand(), Handedness::right, empty_scene(), o);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("wrist_time_constant_s"), std::string::npos);
  ContactSimOptions loose;
  loose.solver_tolerance = 0.1;
  auto too_loose = ContactSimulation::create(test_hand(), Handedness::right, empty_scene(), loose);
  ASSERT_FALSE(too_loose);
  EXPECT_NE(too_loose.error().message.find("solver_tolerance"), std::string::npos);

  HapticScene dup = empty_scene();
  dup.objects.push_back(SceneObject::sphere("a", 0.01, Pose{}));
  dup.objects.push_back(SceneObject::sphere("a", 0.01, Pose{}));
  auto twice = ContactSimulation::create(test_hand(), Handedness::right, dup);
  ASSERT_FALSE(twice);
  EXPECT_NE(twice.error().message.find("'a'"), std::string::npos);

  auto sim = ContactSimulation::create(test_hand(), Handedness::right, empty_scene());
  ASSERT_TRUE(sim);
  const Pose before = sim->proxy_wrist();
  HandAngles nan_angles{};
  nan_angles[3] = std::nan("");
  sim->set_target(Pose{Quat::Identity(), Vec3(1, 1, 1)}, nan_angles);
  for (int i = 0; i < 100; ++i) sim->step();
  EXPECT_LT((sim->proxy_wrist().p - before.p).norm(), 1e-6);
}

// felt_on_pad(): a contact anywhere on the fingertip is felt as pad pressure
// (its normal force) plus shear (its friction), magnitude kept.
TEST(FeltOnPad, RollsEachContactOntoThePadKeepingItsMagnitude) {
  const auto expect_force = [](const FingertipForce& f, double normal, double x, double z, const char* what) {
    EXPECT_NEAR(f.normal_n, normal, 1e-12) << what;
    EXPECT_NEAR(f.shear_x_n, x, 1e-12) << what;
    EXPECT_NEAR(f.shear_z_n, z, 1e-12) << what;
  };
  // On the pad (normal +Y): unchanged.
  expect_force(felt_on_pad(Vec3(0.2, 1.5, -0.3), Vec3::UnitY()), 1.5, 0.2, -0.3, "pad");
  // On the tip's end (the surface pushes along +Z, toward the wrist): 16 N
  // along the finger's axis is 16 N of pad pressure; the fingertip frame's
  // projection reads zero normal.
  expect_force(felt_on_pad(Vec3(0, 0, 16.0), Vec3::UnitZ()), 16.0, 0.0, 0.0, "tip end");
  EXPECT_EQ(FingertipForce::from_tip_frame(Vec3(0, 0, 16.0)).normal_n, 0.0);
  // The end's friction toward the nail (+Y) rolls round the tip onto the pad
  // as shear toward the fingertip (-Z); across the finger (X) it stays X.
  expect_force(felt_on_pad(Vec3(0.1, 0.5, 4.0), Vec3::UnitZ()), 4.0, 0.1, -0.5, "tip end with friction");
  // On the side (+X): pressure, its friction along the finger stays along Z.
  expect_force(felt_on_pad(Vec3(2.0, 0, 0.3), Vec3::UnitX()), 2.0, 0.0, 0.3, "side");
  // On the nail (-Y): no unique roll; pressure all the same.
  expect_force(felt_on_pad(Vec3(0.1, -3.0, 0.2), -Vec3::UnitY()), 3.0, -0.1, 0.2, "nail");
  // Any normal: the contact's normal force becomes the pad pressure, its
  // friction the shear, and the magnitude is kept.
  for (int i = 0; i < 200; ++i) {
    const Vec3 n = Vec3(std::sin(0.7 * i), std::cos(1.3 * i), std::sin(2.1 * i + 0.4)).normalized();
    const Vec3 f = 3.0 * n + Vec3(std::cos(0.9 * i), std::sin(0.5 * i), std::cos(1.7 * i)).cross(n);
    const FingertipForce p = felt_on_pad(f, n);
    EXPECT_NEAR(p.normal_n, f.dot(n), 1e-9) << i;
    EXPECT_NEAR(p.in_tip_frame().norm(), f.norm(), 1e-9) << i;
  }
  EXPECT_FALSE(felt_on_pad(Vec3(std::nan(""), 0, 1), Vec3::UnitZ()).is_finite());
}

TEST(ForceLaws, HalfCylinderLawMatchesItsFormula) {
  ContactLawOptions law;  // F0 0.45 N, K 4.2 N/m
  HalfCylinderShape cyl;
  cyl.T_world_object = Pose{Quat::Identity(), Vec3(0, 0.75, -0.55)};
  const double r = 0.01;
  // Straight above the axis, 2 cm deep: normal +y, F = 0.45 + 4.2 * 0.02.
  const Quat q_pad_down = Quat::Identity();  // tip frame +Y up: the pad faces down onto the cylinder
  auto c = sphere_on_half_cylinder(law, cyl, Vec3(0, 0.75 + 0.25 + r - 0.02, -0.55), r, q_pad_down);
  ASSERT_TRUE(c.in_contact);
  EXPECT_NEAR(c.penetration_m, 0.02, 1e-12);
  EXPECT_NEAR(c.force.normal_n, 0.45 + 4.2 * 0.02, 1e-12);
  EXPECT_NEAR(c.force.shear_magnitude_n(), 0.0, 1e-12);
  // At 30 degrees around the curve, the same depth: the same magnitude, now
  // split into normal and shear for a finger whose pad still faces down.
  const double a = M_PI / 6;
  const Vec3 radial(std::sin(a), std::cos(a), 0);
  c = sphere_on_half_cylinder(law, cyl, cyl.T_world_object.p + (0.25 + r - 0.005) * radial, r, q_pad_down);
  ASSERT_TRUE(c.in_contact);
  const double F = 0.45 + 4.2 * 0.005;
  EXPECT_NEAR(c.f_in_world.norm(), F, 1e-12);
  EXPECT_NEAR(c.force.normal_n, F * std::cos(a), 1e-12);
  EXPECT_NEAR(c.force.shear_x_n, F * std::sin(a), 1e-12);
  EXPECT_NEAR(c.on_pad.normal_n, F, 1e-12) << "felt on the pad: all pressure (the law has no friction)";
  EXPECT_NEAR(c.on_pad.shear_magnitude_n(), 0.0, 1e-12);
  // The finger pointing straight down into the cylinder: the tip's end
  // touches, the fingertip frame reads no normal force, the pad feels all of it.
  const Quat q_pointing_down(Eigen::AngleAxisd(-M_PI / 2, Vec3::UnitX()));  // tip frame +Z (to the wrist) up
  c = sphere_on_half_cylinder(law, cyl, Vec3(0, 0.75 + 0.25 + r - 0.02, -0.55), r, q_pointing_down);
  ASSERT_TRUE(c.in_contact);
  EXPECT_NEAR(c.force.normal_n, 0.0, 1e-12);
  EXPECT_NEAR(c.force.shear_z_n, 0.45 + 4.2 * 0.02, 1e-12);
  EXPECT_NEAR(c.on_pad.normal_n, 0.45 + 4.2 * 0.02, 1e-12);
  // Not touching: nothing.
  EXPECT_FALSE(sphere_on_half_cylinder(law, cyl, Vec3(0, 0.75 + 0.25 + r + 0.001, -0.55), r, q_pad_down).in_contact);
  // Beyond the end cap: nothing.
  EXPECT_FALSE(sphere_on_half_cylinder(law, cyl, Vec3(0, 0.99, -0.55 - 0.3), r, q_pad_down).in_contact);
  // Saturation.
  law.max_force_n = 0.5;
  EXPECT_NEAR(sphere_on_half_cylinder(law, cyl, Vec3(0, 0.9, -0.55), r, q_pad_down).f_in_world.norm(), 0.5, 1e-12);
  // NaN position: no contact rather than a NaN force.
  EXPECT_FALSE(sphere_on_half_cylinder(law, cyl, Vec3(std::nan(""), 1, 0), r, q_pad_down).in_contact);
}

TEST(ForceLaws, PlaneLawAndValidation) {
  ContactLawOptions law;
  auto c = sphere_on_plane(law, Vec3(0, 1, 0), Vec3(0, 1, 0), Vec3(0, 1.005, 0), 0.01, Quat::Identity());
  ASSERT_TRUE(c.in_contact);
  EXPECT_NEAR(c.force.normal_n, 0.45 + 4.2 * 0.005, 1e-12);
  ContactLawOptions bad;
  bad.stiffness_n_per_m = -1;
  auto s = bad.validate();
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("4.2 N/m"), std::string::npos);
}

}  // namespace
}  // namespace proprio::haptics

namespace proprio::haptics {

namespace {

// Two flat hands facing each other across a free box: palms along world x.
struct TwoHandRig {
  static constexpr double kBoxHalfX = 0.04;
  // The right hand's palm (-Y) faces -x, the left's +x; fingers point -z.
  static Pose wrist(Handedness side, double squeeze_m, double lift_m) {
    const double s = side == Handedness::right ? 1.0 : -1.0;
    Eigen::Matrix3d R;
    R.col(0) = Vec3(0, s * -1.0, 0);
    R.col(1) = Vec3(s, 0, 0);
    R.col(2) = Vec3(0, 0, 1);
    // The palm box's surface is ~9 mm below the wrist frame's origin (palm side).
    return {Quat(R), Vec3(s * (kBoxHalfX + 0.009 - squeeze_m), 1.0 + lift_m, -0.25)};
  }
};

}  // namespace

// Issue 29: both proxies live in one world and hold the same object. Two
// palms squeeze a 200 g box and lift it; the box only rises if both hands
// press it (one palm alone pushes it sideways, it does not lift it).
TEST(ContactSim, TwoHandsInOneWorldLiftABoxTogether) {
  const HandModel model = test_hand();
  const ProxyHandSpec hands[] = {{model, Handedness::left}, {model, Handedness::right}};
  HapticScene scene = empty_scene();
  SceneObject box = SceneObject::box("box", Vec3(TwoHandRig::kBoxHalfX, 0.05, 0.06),
                                     Pose{Quat::Identity(), Vec3(0.0, 1.0, -0.30)});
  box.fixed = false;
  box.mass_kg = 0.2;
  SceneObject table = SceneObject::box("table", Vec3(0.3, 0.02, 0.3), Pose{Quat::Identity(), Vec3(0.0, 0.93, -0.30)});
  scene.objects = {table, box};
  auto sim = ContactSimulation::create(hands, scene);
  ASSERT_TRUE(sim) << sim.error().message;
  ASSERT_EQ(sim->hand_count(), 2u);
  EXPECT_EQ(sim->hand_index(Handedness::left), 0);
  EXPECT_EQ(sim->hand_index(Handedness::right), 1);
  EXPECT_NE(sim->mjcf().find("left_proxy_index_distal"), std::string::npos);
  EXPECT_NE(sim->mjcf().find("right_target_wrist"), std::string::npos);

  for (Handedness side : {Handedness::left, Handedness::right}) {
    sim->reset_hand(TwoHandRig::wrist(side, -0.01, 0.0), HandAngles{}, static_cast<std::size_t>(sim->hand_index(side)));
  }
  // Settle on the table, then squeeze (1 cm into the box), then lift 10 cm over 1 s.
  const double y0 = sim->object_pose("box")->p.y();
  for (int i = 0; i < 1500; ++i) {
    const double t = i * 1e-3;
    const double squeeze = std::clamp((t - 0.2) / 0.3, 0.0, 1.0) * 0.01;
    const double lift = std::clamp((t - 0.5) / 1.0, 0.0, 1.0) * 0.10;
    for (Handedness side : {Handedness::left, Handedness::right}) {
      sim->set_target(TwoHandRig::wrist(side, squeeze, lift), HandAngles{},
                      static_cast<std::size_t>(sim->hand_index(side)));
    }
    sim->step();
  }
  const Pose lifted = *sim->object_pose("box");
  std::printf("two hands lifted the box %.1f mm (hands rose 100 mm), box x %.1f mm, hands carry %.2f N\n",
              (lifted.p.y() - y0) * 1e3, lifted.p.x() * 1e3, sim->hand_force_on_object("box").y());
  EXPECT_GT(lifted.p.y() - y0, 0.07) << "the box rose with both hands";
  EXPECT_LT(std::abs(lifted.p.x()), 0.01) << "squeezed evenly from both sides";
  EXPECT_GT(sim->hand_force_on_object("box").y(), 1.5) << "the hands carry the box's weight (1.96 N)";
  for (std::size_t h = 0; h < 2; ++h) {
    EXPECT_GT((sim->proxy_wrist(h).p - TwoHandRig::wrist(sim->hand(h), 0.01, 0.10).p).norm(), 0.005)
        << "each proxy is held back by the box, not where its tracked hand is";
  }

  // One hand alone cannot lift it: the same motion with the left hand away.
  auto alone = ContactSimulation::create(hands, scene);
  ASSERT_TRUE(alone);
  alone->reset_hand(Pose{Quat::Identity(), Vec3(-0.5, 1.3, -0.3)}, HandAngles{}, 0);
  alone->reset_hand(TwoHandRig::wrist(Handedness::right, -0.01, 0.0), HandAngles{}, 1);
  for (int i = 0; i < 1500; ++i) {
    const double t = i * 1e-3;
    alone->set_target(Pose{Quat::Identity(), Vec3(-0.5, 1.3, -0.3)}, HandAngles{}, 0);
    alone->set_target(TwoHandRig::wrist(Handedness::right, std::clamp((t - 0.2) / 0.3, 0.0, 1.0) * 0.01,
                                        std::clamp((t - 0.5) / 1.0, 0.0, 1.0) * 0.10),
                      HandAngles{}, 1);
    alone->step();
  }
  std::printf("one hand alone moved the box up %.1f mm\n", (alone->object_pose("box")->p.y() - y0) * 1e3);
  EXPECT_LT(alone->object_pose("box")->p.y() - y0, 0.03) << "one palm does not lift the box";
}

TEST(ContactSim, CollidersAreSetMovedAndRemovedAtRunTime) {
  ContactSimOptions options;
  options.collider_slots = 2;
  auto sim = ContactSimulation::create(test_hand(), Handedness::right, empty_scene(), options);
  ASSERT_TRUE(sim) << sim.error().message;
  ASSERT_EQ(sim->collider_slot_count(), 2);
  const HandAngles flat{};
  const Pose T_world_wrist{Quat::Identity(), Vec3(0.0, 1.0, -0.3)};
  sim->reset_hand(T_world_wrist, flat);
  const Pose tip = sim->proxy_pose(0).joint(HandJoint::index_tip);
  // A sphere pushed 5 mm into the pad (the pad faces the tip frame's -Y).
  ColliderShape sphere;
  sphere.shape = ShapeKind::sphere;
  sphere.radius_m = 0.02;
  const double pad_radius = 0.5 * test_hand().shape().fingers[1].joint_radius_m[4] +
                            0.5 * test_hand().shape().fingers[1].joint_radius_m[3];
  const Pose at{Quat::Identity(), tip.p + tip.q * Vec3(0, -(pad_radius + 0.02 - 0.005), 0.005)};
  ASSERT_TRUE(sim->set_collider(0, sphere, at));
  double pressed = 0.0;
  for (int i = 0; i < 300; ++i) {
    sim->set_target(T_world_wrist, flat);
    sim->step();
    pressed = std::max(pressed, sim->fingertip(Finger::index).on_pad.normal_n);
  }
  EXPECT_GT(pressed, 0.2) << "the collider presses the index pad";
  EXPECT_GT((sim->proxy_pose(0).joint(HandJoint::index_tip).p - tip.p).norm(), 0.002) << "and pushes the proxy away";
  sim->remove_collider(0);
  for (int i = 0; i < 300; ++i) {
    sim->set_target(T_world_wrist, flat);
    sim->step();
  }
  EXPECT_LT(sim->fingertip(Finger::index).on_pad.normal_n, 1e-3) << "a removed collider touches nothing";
  // Bad slots, poses and shapes are refused without touching the model.
  EXPECT_FALSE(sim->set_collider(2, sphere, at));
  EXPECT_FALSE(sim->set_collider(-1, sphere, at));
  EXPECT_FALSE(sim->set_collider(0, sphere, Pose{Quat::Identity(), Vec3(NAN, 0, 0)}));
  ColliderShape plate = sphere;
  plate.shape = ShapeKind::plate_with_hole;
  EXPECT_FALSE(sim->set_collider(0, plate, at));
  EXPECT_FALSE(plate.validate().ok());
  sphere.friction = 3.0;
  EXPECT_FALSE(sphere.validate().ok());
  ContactSimOptions too_many;
  too_many.collider_slots = kMaxColliderSlots + 1;
  EXPECT_FALSE(too_many.validate().ok());
}

}  // namespace proprio::haptics
