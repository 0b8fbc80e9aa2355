// The scripted hands of simulated runs: the static thumb-index pinch of an
// upright cylinder (pinch_upright_cylinder), as the two-hand servo benchmark
// grasps the peg-in-hole peg with both hands.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "proprio/haptics/contact_sim.hpp"
#include "proprio/haptics/touch_script.hpp"

namespace proprio::haptics {
namespace {

HandModel bench_hand() {
  auto shape = HandShape::from_measurements(0.19, 0.10);
  EXPECT_TRUE(shape);
  return HandModel(*shape);
}

struct Tips {
  Vec3 thumb, index;
};
Tips tips_in_world(const HandModel& m, Handedness side, const Pose& T, const HandAngles& a) {
  const auto j = m.joint_poses_in_wrist(side, a);
  return {T * j[index_of(HandJoint::thumb_tip)].p, T * j[index_of(HandJoint::index_tip)].p};
}
// How far a tip sphere reaches into an upright cylinder (negative: clearance).
double depth(const Vec3& tip, double r_tip, const Vec3& axis_point, double radius) {
  const Vec3 d(tip.x() - axis_point.x(), 0.0, tip.z() - axis_point.z());
  return radius + r_tip - d.norm();
}

TEST(CylinderPinch, ClosedTipsSqueezeBothSidesAndTheStartTouchesNothing) {
  const HandModel m = bench_hand();
  const double r_thumb = m.shape().fingers[0].joint_radius_m[3], r_index = m.shape().fingers[1].joint_radius_m[4];
  for (Handedness side : {Handedness::left, Handedness::right}) {
    CylinderPinchOptions o;
    o.approach_from = Vec3(side == Handedness::left ? -1.0 : 1.0, 0.0, 0.0);
    auto p = pinch_upright_cylinder(m, side, o);
    ASSERT_TRUE(p) << p.error().message;
    const Tips closed = tips_in_world(m, side, p->T_world_wrist, p->closed);
    // Both tracked tips inside by about the squeeze, at the pinch's height,
    // on opposite sides of the axis.
    EXPECT_NEAR(depth(closed.thumb, r_thumb, o.p_axis_in_world, o.radius_m), o.squeeze_m, 0.003);
    EXPECT_NEAR(depth(closed.index, r_index, o.p_axis_in_world, o.radius_m), o.squeeze_m, 0.003);
    EXPECT_NEAR(closed.thumb.y(), o.p_axis_in_world.y(), 1e-9);
    EXPECT_NEAR(closed.index.y(), o.p_axis_in_world.y(), 1e-9);
    EXPECT_LT((closed.thumb - o.p_axis_in_world).dot(closed.index - o.p_axis_in_world), 0.0);
    // The wrist on the approach side, the back of the hand up rather than down.
    EXPECT_GT((p->T_world_wrist.p - o.p_axis_in_world).dot(o.approach_from), 0.05);
    EXPECT_GT((p->T_world_wrist.q * Vec3::UnitY()).y(), 0.0);
    // The start: open, both tips clear of the surface.
    const Tips start = tips_in_world(m, side, p->T_world_wrist_start, p->open);
    EXPECT_LT(depth(start.thumb, r_thumb, o.p_axis_in_world, o.radius_m), -0.001);
    EXPECT_LT(depth(start.index, r_index, o.p_axis_in_world, o.radius_m), -0.001);
  }
}

TEST(CylinderPinch, RefusesWhatTheHandCannotSpanOrBadInput) {
  const HandModel m = bench_hand();
  CylinderPinchOptions o;
  o.radius_m = 0.15;
  auto wide = pinch_upright_cylinder(m, Handedness::right, o);
  ASSERT_FALSE(wide);
  EXPECT_EQ(wide.error().code, Errc::invalid_argument);
  EXPECT_NE(wide.error().message.find("does not span"), std::string::npos) << wide.error().message;
  o = {};
  o.approach_from = Vec3::UnitY();  // not horizontal
  EXPECT_FALSE(pinch_upright_cylinder(m, Handedness::right, o));
  o = {};
  o.radius_m = std::nan("");
  EXPECT_FALSE(pinch_upright_cylinder(m, Handedness::right, o));
}

// Both hands in one world pinch the standing peg (the two-hand servo
// benchmark's setup): all four pads press it and it stays where it stood.
TEST(CylinderPinch, TwoHandsPinchThePegInOneWorld) {
  const HandModel m = bench_hand();
  const HapticScene scene = HapticScene::peg_in_hole();
  const ProxyHandSpec specs[] = {{m, Handedness::left}, {m, Handedness::right}};
  auto sim = ContactSimulation::create(specs, scene);
  ASSERT_TRUE(sim) << sim.error().message;
  auto pinches = pinch_peg_with_both_hands(m, scene);
  ASSERT_TRUE(pinches) << pinches.error().message;
  const std::array<CylinderPinch, 2>& pinch = *pinches;
  for (std::size_t h = 0; h < 2; ++h) sim->reset_hand(pinch[h].T_world_wrist_start, pinch[h].open, h);
  const Pose peg_before = *sim->object_pose("peg");
  double least_pad_n = 1e9;
  for (int i = 0; i < 2500; ++i) {
    const double closing = std::min(1.0, i / 500.0);
    for (std::size_t h = 0; h < 2; ++h) {
      const CylinderPinch& p = pinch[h];
      HandAngles a;
      for (std::size_t d = 0; d < kHandDofCount; ++d) a[d] = p.open[d] + closing * (p.closed[d] - p.open[d]);
      sim->set_target({p.T_world_wrist.q, p.T_world_wrist_start.p + closing * (p.T_world_wrist.p - p.T_world_wrist_start.p)},
                      a, h);
    }
    sim->step();
    if (i < 1500) continue;
    for (std::size_t h = 0; h < 2; ++h) {
      for (Finger f : {Finger::thumb, Finger::index}) {
        const FingertipContact& c = sim->fingertip(f, h);
        least_pad_n = std::min(least_pad_n, c.on_pad.normal_n);
        EXPECT_GT(c.contact_count, 0) << "hand " << h << " finger " << static_cast<int>(f) << " step " << i;
      }
    }
  }
  EXPECT_GT(least_pad_n, 0.1);
  const Pose peg_after = *sim->object_pose("peg");
  EXPECT_LT((peg_after.p - peg_before.p).norm(), 0.002);
  EXPECT_GT((peg_after.q * Vec3::UnitZ()).y(), 0.99);  // still upright
  EXPECT_EQ(sim->stats().instability_resets, 0u);
}

}  // namespace
}  // namespace proprio::haptics
