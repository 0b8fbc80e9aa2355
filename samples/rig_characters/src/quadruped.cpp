// "quadruped": 30 bones, a horse-sized animal (hips 1.1 m, poll 1.8 m; the
// thesis's Horse has 29 bones and 25 poses) with twelve sample poses:
// four gallop and two trot phases, two walk steps, sit, rear up, look back
// and graze.
#include "character_builder.hpp"

namespace proprio::rig_characters::detail {
namespace {

struct QuadPoser {
  CharacterBuilder& b;

  // A leg swung forward (positive) about the hip or shoulder, its lower
  // joints folded (front: knee and fetlock fold back; hind: stifle back,
  // hock forward, as a horse's do).
  void front(SkeletonPose& p, const char* s, double swing_deg, double knee_deg, double fetlock_deg = 0.0) {
    const std::string side = s;
    b.turn(p, "front_upper_" + side, rx(-swing_deg));
    b.turn(p, "front_fore_" + side, rx(knee_deg));
    b.turn(p, "front_cannon_" + side, rx(0.5 * knee_deg));
    b.turn(p, "front_hoof_" + side, rx(fetlock_deg));
  }
  void hind(SkeletonPose& p, const char* s, double swing_deg, double stifle_deg, double hock_deg = 0.0) {
    const std::string side = s;
    b.turn(p, "hind_thigh_" + side, rx(-swing_deg));
    b.turn(p, "hind_shin_" + side, rx(stifle_deg));
    b.turn(p, "hind_cannon_" + side, rx(-hock_deg));
    b.turn(p, "hind_hoof_" + side, rx(0.5 * hock_deg));
  }
  // Positive arches the back (middle up), negative hollows it.
  void back(SkeletonPose& p, double arch_deg) {
    b.turn(p, "spine_1", rx(-arch_deg));
    b.turn(p, "spine_2", rx(arch_deg));
    b.turn(p, "chest", rx(arch_deg));
  }
  // Neck forward/down (positive) spread over its three bones, and the head.
  void neck(SkeletonPose& p, double neck_deg, double head_deg, double turn_deg = 0.0) {
    b.turn_chain(p, "neck_", 1, 3, [&](int) { return ry(turn_deg / 3.0) * rx(neck_deg / 3.0); });
    b.turn(p, "head", rx(head_deg));
  }
  // Tail up (positive), curving more towards the tip.
  void tail(SkeletonPose& p, double up_deg, double sway_deg = 0.0) {
    b.turn_chain(p, "tail_", 1, 5, [&](int i) { return ry(sway_deg * i / 15.0) * rx(up_deg * i / 15.0); });
  }
};

}  // namespace

Result<render::Character> make_quadruped() {
  CharacterBuilder b("quadruped");
  b.add("pelvis", "", Vec3(0.0, 1.10, -0.55), 0.22);
  b.add("spine_1", "pelvis", Vec3(0.0, 0.03, 0.28), 0.24);
  b.add("spine_2", "spine_1", Vec3(0.0, 0.0, 0.28), 0.25);
  b.add("chest", "spine_2", Vec3(0.0, 0.02, 0.28), 0.25);
  // The neck's root sits at the withers, so bending neck_1 lowers the whole neck.
  b.add("neck_1", "chest", Vec3(0.0, 0.08, 0.16), 0.16);
  b.add("neck_2", "neck_1", Vec3(0.0, 0.22, 0.16), 0.13);
  b.add("neck_3", "neck_2", Vec3(0.0, 0.22, 0.14), 0.10);
  b.add("head", "neck_3", Vec3(0.0, 0.14, 0.08), 0.10, Vec3(0.0, -0.12, 0.38), 0.07);
  b.add("jaw", "head", Vec3(0.0, -0.06, 0.06), 0.05, Vec3(0.0, -0.06, 0.28), 0.035);
  b.add("tail_1", "pelvis", Vec3(0.0, 0.04, -0.20), 0.07);
  for (int i = 2; i <= 5; ++i) {
    const Vec3 t(0.0, -0.06, -0.12);
    const std::string name = "tail_" + std::to_string(i);
    if (i < 5)
      b.add(name, "tail_" + std::to_string(i - 1), t, 0.07 - 0.01 * i);
    else
      b.add(name, "tail_4", t, 0.025, Vec3(0.0, -0.10, -0.08), 0.02);
  }
  for (const char* s : {"l", "r"}) {
    const double x = s[0] == 'l' ? 1.0 : -1.0;
    const std::string side = s;
    b.add("front_upper_" + side, "chest", Vec3(0.16 * x, -0.22, 0.06), 0.10);
    b.add("front_fore_" + side, "front_upper_" + side, Vec3(0.0, -0.30, -0.03), 0.07);
    b.add("front_cannon_" + side, "front_fore_" + side, Vec3(0.0, -0.30, 0.0), 0.045);
    b.add("front_hoof_" + side, "front_cannon_" + side, Vec3(0.0, -0.22, 0.02), 0.04, Vec3(0.0, -0.05, 0.05), 0.035);
  }
  for (const char* s : {"l", "r"}) {
    const double x = s[0] == 'l' ? 1.0 : -1.0;
    const std::string side = s;
    b.add("hind_thigh_" + side, "pelvis", Vec3(0.16 * x, -0.18, -0.02), 0.12);
    b.add("hind_shin_" + side, "hind_thigh_" + side, Vec3(0.0, -0.32, -0.08), 0.07);
    b.add("hind_cannon_" + side, "hind_shin_" + side, Vec3(0.0, -0.30, 0.02), 0.045);
    b.add("hind_hoof_" + side, "hind_cannon_" + side, Vec3(0.0, -0.20, 0.02), 0.04, Vec3(0.0, -0.05, 0.05), 0.035);
  }

  QuadPoser q{b};
  auto finish = [&](const char* name, SkeletonPose p) {
    b.ground(p);
    b.add_pose(name, std::move(p));
  };
  {  // gallop: gathered, all four legs under the body
    SkeletonPose p = b.rest();
    q.front(p, "l", -10.0, 15.0, 10.0);
    q.front(p, "r", -15.0, 10.0, 5.0);
    q.hind(p, "l", 30.0, 10.0, 20.0);
    q.hind(p, "r", 22.0, 10.0, 15.0);
    q.back(p, 6.0);
    q.neck(p, 15.0, 10.0);
    q.tail(p, 20.0);
    finish("gallop_gather", p);
  }
  {  // hinds push off, fronts reach
    SkeletonPose p = b.rest();
    q.front(p, "l", 45.0, 20.0, -10.0);
    q.front(p, "r", 35.0, 35.0, 0.0);
    q.hind(p, "l", -20.0, 5.0, 5.0);
    q.hind(p, "r", -30.0, 10.0, 0.0);
    q.back(p, -3.0);
    q.neck(p, 25.0, 5.0);
    q.tail(p, 30.0);
    finish("gallop_hind_push", p);
  }
  {  // extended: fronts far forward, hinds far back
    SkeletonPose p = b.rest();
    q.front(p, "l", 50.0, 10.0, -15.0);
    q.front(p, "r", 40.0, 15.0, -10.0);
    q.hind(p, "l", -40.0, 0.0, 0.0);
    q.hind(p, "r", -35.0, 5.0, 0.0);
    q.back(p, -6.0);
    q.neck(p, 30.0, 0.0);
    q.tail(p, 35.0);
    finish("gallop_extend", p);
  }
  {  // leading front lands, hinds swing through
    SkeletonPose p = b.rest();
    q.front(p, "l", 10.0, 0.0, -5.0);
    q.front(p, "r", -10.0, 50.0, 20.0);
    q.hind(p, "l", 20.0, 60.0, 40.0);
    q.hind(p, "r", 10.0, 50.0, 35.0);
    q.back(p, 3.0);
    q.neck(p, 5.0, 15.0);
    q.tail(p, 25.0);
    finish("gallop_front_land", p);
  }
  for (int k = 0; k < 2; ++k) {  // trot: diagonal pairs move together
    const char* lead = k == 0 ? "l" : "r";
    const char* other = k == 0 ? "r" : "l";
    SkeletonPose p = b.rest();
    q.front(p, lead, 25.0, 60.0, 30.0);
    q.hind(p, other, 20.0, 45.0, 35.0);
    q.front(p, other, -10.0, 0.0, 0.0);
    q.hind(p, lead, -15.0, 5.0, 0.0);
    q.neck(p, 10.0, 5.0);
    q.tail(p, 15.0, k == 0 ? 10.0 : -10.0);
    finish(k == 0 ? "trot_left_diagonal" : "trot_right_diagonal", p);
  }
  for (int k = 0; k < 2; ++k) {  // walk: one leg lifted at a time
    const char* lead = k == 0 ? "l" : "r";
    const char* other = k == 0 ? "r" : "l";
    SkeletonPose p = b.rest();
    q.front(p, lead, 20.0, 45.0, 20.0);
    q.front(p, other, -8.0, 0.0, 0.0);
    q.hind(p, lead, -12.0, 5.0, 0.0);
    q.hind(p, other, 12.0, 10.0, 5.0);
    q.neck(p, 12.0, 8.0, k == 0 ? 8.0 : -8.0);
    q.tail(p, -5.0, k == 0 ? -8.0 : 8.0);
    finish(k == 0 ? "walk_left_front" : "walk_right_front", p);
  }
  {  // sit: hindquarters down, the front upright
    SkeletonPose p = b.rest();
    b.turn(p, "pelvis", rx(-35.0));
    for (const char* s : {"l", "r"}) {
      q.front(p, s, -35.0, 0.0, 0.0);
      q.hind(p, s, 90.0, 130.0, 60.0);
    }
    q.neck(p, 30.0, 10.0);
    q.tail(p, -60.0);
    finish("sit", p);
  }
  {  // rear up on the hind legs, fronts folded
    SkeletonPose p = b.rest();
    b.turn(p, "pelvis", rx(-50.0));
    for (const char* s : {"l", "r"}) {
      q.front(p, s, 30.0, 90.0, 30.0);
      q.hind(p, s, -40.0, 25.0, 15.0);
    }
    q.back(p, -4.0);
    q.neck(p, 35.0, 15.0);
    q.tail(p, -45.0);
    finish("rear_up", p);
  }
  {  // look back over the left shoulder
    SkeletonPose p = b.rest();
    b.turn(p, "spine_2", ry(8.0));
    b.turn(p, "chest", ry(10.0));
    q.neck(p, -10.0, 10.0, 100.0);
    b.turn(p, "head", ry(30.0));
    q.front(p, "l", 5.0, 10.0, 0.0);
    q.tail(p, 0.0, -15.0);
    finish("look_back_left", p);
  }
  {  // graze: head down to the ground
    SkeletonPose p = b.rest();
    b.turn(p, "pelvis", rx(8.0));
    b.turn(p, "neck_1", rx(85.0));
    b.turn(p, "neck_2", rx(35.0));
    b.turn(p, "neck_3", rx(20.0));
    b.turn(p, "head", rx(-55.0));  // the muzzle points down, not back
    q.front(p, "l", 15.0, 0.0, 0.0);
    q.front(p, "r", -8.0, 0.0, 0.0);
    q.tail(p, -15.0);
    finish("graze", p);
  }
  return b.build();
}

}  // namespace proprio::rig_characters::detail
