// "creature": 99 bones, a winged, eight-legged dragon-like animal about 4 m
// long (the thesis's Dragon has 110 bones and 12 poses): body, a ten-bone
// neck, head with jaw and two horns, two wings of thirteen bones each, eight
// legs of four segments and an eighteen-bone tail. Twelve sample poses: four
// walk phases, three flight phases, strike, coil, rear, look back, crouch.
#include <cmath>
#include <numbers>

#include "character_builder.hpp"

namespace proprio::rig_characters::detail {
namespace {

constexpr int kNeck = 10;
constexpr int kTail = 18;
constexpr int kLegPairs = 4;
constexpr int kFingers = 3;

struct CreaturePoser {
  CharacterBuilder& b;

  static std::string leg_node(int k, const char* s, const char* segment) {
    return "leg_" + std::to_string(k) + s + "_" + segment;
  }
  // A leg swung forward (positive) about the vertical at its hip, lifted
  // (positive raises the knee), the lower leg kept near vertical.
  void leg(SkeletonPose& p, int k, const char* s, double swing_deg, double lift_deg) {
    const double side = s[0] == 'l' ? 1.0 : -1.0;
    b.turn(p, leg_node(k, s, "coxa"), mirrored(ry(-swing_deg), side));
    b.turn(p, leg_node(k, s, "femur"), mirrored(rz(lift_deg), side));
    b.turn(p, leg_node(k, s, "tibia"), mirrored(rz(-0.6 * lift_deg), side));
  }
  // Alternating tetrapod gait: legs 1l, 2r, 3l, 4r move together.
  void gait(SkeletonPose& p, double swing_a, double lift_a, double swing_b, double lift_b) {
    for (int k = 1; k <= kLegPairs; ++k) {
      const bool a_left = k % 2 == 1;
      leg(p, k, "l", a_left ? swing_a : swing_b, a_left ? lift_a : lift_b);
      leg(p, k, "r", a_left ? swing_b : swing_a, a_left ? lift_b : lift_a);
    }
  }
  // Wings: raised (positive) at the shoulder and the elbow, fingers spread.
  void wings(SkeletonPose& p, double shoulder_deg, double elbow_deg, double spread_deg, double fold_deg = 0.0) {
    for (const char* s : {"l", "r"}) {
      const double side = s[0] == 'l' ? 1.0 : -1.0;
      const std::string w = std::string("wing_") + s;
      b.turn(p, w + "_1", mirrored(ry(fold_deg) * rz(shoulder_deg), side));
      b.turn(p, w + "_2", mirrored(rz(elbow_deg), side));
      b.turn(p, w + "_3", mirrored(ry(-1.5 * fold_deg), side));
      for (int f = 1; f <= kFingers; ++f) {
        b.turn(p, w + "_finger" + std::to_string(f) + "_1", mirrored(ry(spread_deg * (f - 2)), side));
        b.turn_chain(p, w + "_finger" + std::to_string(f) + "_", 2, 3,
                     [&](int) { return mirrored(rz(0.3 * elbow_deg), side); });
      }
    }
  }
  // A smooth bend along a chain: total degrees about X and Y (to the
  // character's left positive), weighted by `shape`. About X, positive bends
  // a forward chain (neck) down and a backward one (tail) up.
  template <typename Shape>
  void bend(SkeletonPose& p, const char* prefix, int count, double x_deg, double y_deg, Shape shape) {
    double total = 0.0;
    for (int i = 1; i <= count; ++i) total += shape(static_cast<double>(i) / count);
    b.turn_chain(p, prefix, 1, count, [&](int i) {
      const double w = shape(static_cast<double>(i) / count) / total;
      return ry(y_deg * w) * rx(x_deg * w);
    });
  }
};

double even(double) { return 1.0; }
double towards_tip(double u) { return 0.3 + u; }
double towards_base(double u) { return 1.3 - u; }

}  // namespace

Result<render::Character> make_creature() {
  CharacterBuilder b("creature");
  b.add("pelvis", "", Vec3(0.0, 1.20, -0.60), 0.30);
  b.add("spine_1", "pelvis", Vec3(0.0, 0.02, 0.35), 0.32);
  b.add("spine_2", "spine_1", Vec3(0.0, 0.02, 0.35), 0.32);
  b.add("spine_3", "spine_2", Vec3(0.0, 0.02, 0.35), 0.30);
  b.add("chest", "spine_3", Vec3(0.0, 0.03, 0.35), 0.28);
  for (int i = 1; i <= kNeck; ++i) {
    // Rising steeply from the chest, levelling out towards the head.
    const Vec3 t(0.0, 0.15 - 0.01 * i, 0.10 + 0.012 * i);
    b.add("neck_" + std::to_string(i), i == 1 ? "chest" : "neck_" + std::to_string(i - 1), t, 0.17 - 0.008 * i);
  }
  b.add("head", "neck_" + std::to_string(kNeck), Vec3(0.0, 0.06, 0.10), 0.13, Vec3(0.0, -0.02, 0.45), 0.08);
  b.add("jaw", "head", Vec3(0.0, -0.09, 0.05), 0.06, Vec3(0.0, -0.03, 0.38), 0.04);
  for (const char* s : {"l", "r"}) {
    const double x = s[0] == 'l' ? 1.0 : -1.0;
    const std::string h = std::string("horn_") + s + "_";
    b.add(h + "1", "head", Vec3(0.07 * x, 0.10, 0.0), 0.03);
    b.add(h + "2", h + "1", Vec3(0.02 * x, 0.10, -0.08), 0.025);
    b.add(h + "3", h + "2", Vec3(0.01 * x, 0.06, -0.10), 0.02, Vec3(0.0, 0.02, -0.08), 0.008);
  }
  for (const char* s : {"l", "r"}) {
    const double x = s[0] == 'l' ? 1.0 : -1.0;
    const std::string w = std::string("wing_") + s;
    b.add(w + "_1", "chest", Vec3(0.22 * x, 0.22, 0.0), 0.08);
    b.add(w + "_2", w + "_1", Vec3(0.50 * x, 0.05, -0.05), 0.06);
    b.add(w + "_3", w + "_2", Vec3(0.70 * x, 0.0, 0.05), 0.045);
    b.add(w + "_4", w + "_3", Vec3(0.25 * x, 0.0, 0.0), 0.035);
    for (int f = 1; f <= kFingers; ++f) {
      // Fanned backwards: the first finger continues the arm, the last points to the tail.
      const double angle = 0.55 * (f - 1);
      const Vec3 dir(x * std::cos(angle), 0.0, -std::sin(angle));
      const std::string finger = w + "_finger" + std::to_string(f) + "_";
      b.add(finger + "1", w + "_4", 0.10 * dir, 0.025);
      b.add(finger + "2", finger + "1", 0.50 * dir, 0.02);
      b.add(finger + "3", finger + "2", 0.45 * dir, 0.016, 0.40 * dir, 0.008);
    }
  }
  const char* leg_hosts[kLegPairs] = {"chest", "spine_3", "spine_1", "pelvis"};
  for (int k = 1; k <= kLegPairs; ++k) {
    for (const char* s : {"l", "r"}) {
      const double x = s[0] == 'l' ? 1.0 : -1.0;
      auto node = [&](const char* segment) { return CreaturePoser::leg_node(k, s, segment); };
      b.add(node("coxa"), leg_hosts[k - 1], Vec3(0.22 * x, -0.10, 0.0), 0.09);
      b.add(node("femur"), node("coxa"), Vec3(0.30 * x, 0.15, 0.0), 0.07);
      b.add(node("tibia"), node("femur"), Vec3(0.25 * x, -0.55, 0.0), 0.05);
      b.add(node("tarsus"), node("tibia"), Vec3(0.05 * x, -0.45, 0.0), 0.035, Vec3(0.02 * x, -0.15, 0.0), 0.02);
    }
  }
  for (int i = 1; i <= kTail; ++i) {
    const double length = 0.30 * std::pow(0.95, i - 1);
    const Vec3 t(0.0, i <= 8 ? -0.04 : 0.0, -length);
    const double radius = 0.22 * std::pow(0.9, i - 1) + 0.01;
    const std::string parent = i == 1 ? "pelvis" : "tail_" + std::to_string(i - 1);
    if (i < kTail)
      b.add("tail_" + std::to_string(i), parent, t, radius);
    else
      b.add("tail_" + std::to_string(i), parent, t, radius, Vec3(0.0, 0.0, -0.15), 0.005);
  }

  CreaturePoser c{b};
  auto grounded = [&](const char* name, SkeletonPose p) {
    b.ground(p);
    b.add_pose(name, std::move(p));
  };
  auto flying = [&](const char* name, SkeletonPose p, double height_m) {
    p.t_world_root_m.y() += height_m;
    b.add_pose(name, std::move(p));
  };
  // Walk: one gait cycle in four phases, the tail and neck swaying against it.
  const double swing_a[4] = {20.0, 20.0, -20.0, -20.0};
  const double lift_a[4] = {25.0, 0.0, 0.0, 0.0};
  for (int phase = 0; phase < 4; ++phase) {
    SkeletonPose p = b.rest();
    const int other = (phase + 2) % 4;
    c.gait(p, swing_a[phase], lift_a[phase], swing_a[other], lift_a[other]);
    const double sway = std::sin(std::numbers::pi / 2 * phase);
    c.bend(p, "tail_", kTail, -10.0, 40.0 * sway, towards_tip);
    c.bend(p, "neck_", kNeck, 10.0, -15.0 * sway, even);
    c.bend(p, "spine_", 3, 0.0, 6.0 * sway, even);
    c.wings(p, -20.0, -10.0, -10.0, 60.0);  // folded along the body
    grounded(("walk_" + std::to_string(phase + 1)).c_str(), p);
  }
  {  // flight: downstroke start (wings high), end (wings low), and a glide
    SkeletonPose p = b.rest();
    c.wings(p, 55.0, 20.0, 12.0);
    c.gait(p, -30.0, 40.0, -30.0, 40.0);
    c.bend(p, "neck_", kNeck, 35.0, 0.0, even);
    c.bend(p, "tail_", kTail, -10.0, 0.0, even);
    flying("fly_wings_up", p, 1.5);
  }
  {
    SkeletonPose p = b.rest();
    c.wings(p, -45.0, -15.0, 8.0);
    c.gait(p, -30.0, 40.0, -30.0, 40.0);
    c.bend(p, "neck_", kNeck, 40.0, 0.0, even);
    c.bend(p, "tail_", kTail, 10.0, 0.0, even);
    flying("fly_wings_down", p, 1.7);
  }
  {
    SkeletonPose p = b.rest();
    c.wings(p, 5.0, 0.0, 15.0);
    c.gait(p, -40.0, 45.0, -40.0, 45.0);
    c.bend(p, "neck_", kNeck, 55.0, 20.0, even);
    b.turn(p, "head", ry(10.0));
    c.bend(p, "tail_", kTail, 0.0, -25.0, towards_tip);
    flying("glide", p, 2.0);
  }
  {  // strike: the neck lunges forward and down, jaw open, tail raised over the back
    SkeletonPose p = b.rest();
    c.bend(p, "neck_", kNeck, 70.0, 0.0, towards_base);
    b.turn(p, "head", rx(-15.0));
    b.turn(p, "jaw", rx(30.0));
    c.bend(p, "tail_", kTail, 110.0, 0.0, towards_tip);
    c.gait(p, 15.0, 0.0, -10.0, 0.0);
    c.leg(p, 1, "l", 35.0, 30.0);
    c.leg(p, 1, "r", 35.0, 30.0);
    c.wings(p, 30.0, 10.0, 10.0);
    grounded("strike", p);
  }
  {  // coil: tail wrapped round, neck curled back the other way
    SkeletonPose p = b.rest();
    c.bend(p, "tail_", kTail, 0.0, 300.0, even);
    c.bend(p, "neck_", kNeck, 20.0, -120.0, even);
    b.turn(p, "head", rx(15.0));
    c.bend(p, "spine_", 3, 0.0, 20.0, even);
    c.gait(p, 0.0, -15.0, 0.0, -15.0);
    c.wings(p, -20.0, -10.0, -10.0, 70.0);
    grounded("coil", p);
  }
  {  // rear up and roar
    SkeletonPose p = b.rest();
    b.turn(p, "pelvis", rx(-30.0));
    c.leg(p, 1, "l", 40.0, 60.0);
    c.leg(p, 1, "r", 40.0, 60.0);
    c.leg(p, 2, "l", 30.0, 45.0);
    c.leg(p, 2, "r", 30.0, 45.0);
    c.bend(p, "neck_", kNeck, 10.0, 0.0, even);
    b.turn(p, "head", rx(-20.0));
    b.turn(p, "jaw", rx(35.0));
    c.bend(p, "tail_", kTail, 35.0, 0.0, towards_base);
    c.wings(p, 35.0, 25.0, 15.0);
    grounded("rear_roar", p);
  }
  {  // look back over the left flank
    SkeletonPose p = b.rest();
    c.bend(p, "neck_", kNeck, 15.0, 160.0, even);
    b.turn(p, "head", ry(20.0));
    c.bend(p, "spine_", 3, 0.0, 15.0, even);
    c.bend(p, "tail_", kTail, 0.0, 60.0, towards_tip);
    c.wings(p, -20.0, -10.0, -10.0, 60.0);
    grounded("look_back", p);
  }
  {  // crouch: legs splayed, body low, wings folded, head watching forward
    SkeletonPose p = b.rest();
    c.gait(p, 0.0, -25.0, 0.0, -25.0);
    c.bend(p, "neck_", kNeck, 60.0, 0.0, even);
    b.turn(p, "head", rx(-40.0));
    c.bend(p, "tail_", kTail, 15.0, -30.0, towards_tip);
    c.wings(p, -25.0, -15.0, -10.0, 75.0);
    grounded("crouch", p);
  }
  return b.build();
}

}  // namespace proprio::rig_characters::detail
