// "humanoid": 22 bones, a 1.72 m adult in a T-pose (the thesis's Dancer has
// 22 bones and 6 poses, its Human 24), with eight sample poses: four walk
// phases, a reach, a wave, a crouch and a look around.
#include "character_builder.hpp"

namespace proprio::rig_characters::detail {
namespace {

struct HumanPoser {
  CharacterBuilder& b;

  // Arms hanging from the T-pose, swung forward (negative) or back (positive) about the shoulder's X.
  void arm_down(SkeletonPose& p, const char* s, double swing_deg, double elbow_deg = 15.0) {
    const double side = s[0] == 'l' ? 1.0 : -1.0;
    b.turn(p, std::string("upper_arm_") + s, rx(swing_deg) * mirrored(rz(-75.0), side));
    b.turn(p, std::string("forearm_") + s, mirrored(ry(-elbow_deg), side));  // bends the forearm forward
  }
  // Hip flexion (forward positive), knee flexion and ankle (about X).
  void leg(SkeletonPose& p, const char* s, double hip_deg, double knee_deg, double ankle_deg, double toe_deg = 0.0) {
    b.turn(p, std::string("thigh_") + s, rx(-hip_deg));
    b.turn(p, std::string("shin_") + s, rx(knee_deg));
    b.turn(p, std::string("foot_") + s, rx(ankle_deg));
    if (toe_deg != 0.0) b.turn(p, std::string("toe_") + s, rx(toe_deg));
  }
  // Contact: the `front` foot lands ahead, the other pushes off behind.
  SkeletonPose walk_contact(const char* front, const char* back) {
    SkeletonPose p = b.rest();
    leg(p, front, 25.0, 5.0, 20.0);
    leg(p, back, -15.0, 20.0, -20.0, -15.0);
    // The arm opposite the front leg swings forward; the chest turns with it.
    const double side = front[0] == 'l' ? 1.0 : -1.0;
    arm_down(p, front, 20.0);
    arm_down(p, back, -20.0, 25.0);
    b.turn(p, "chest", ry(6.0 * side));
    b.turn(p, "pelvis", ry(-4.0 * side));
    b.ground(p);
    return p;
  }
  // Passing: standing on `stance`, the other leg swings through.
  SkeletonPose walk_passing(const char* stance, const char* swing) {
    SkeletonPose p = b.rest();
    leg(p, stance, 0.0, 5.0, -5.0);
    leg(p, swing, 20.0, 55.0, -25.0);
    arm_down(p, stance, -5.0);
    arm_down(p, swing, 5.0);
    b.turn(p, "spine_2", rx(3.0));
    b.ground(p);
    return p;
  }
};

}  // namespace

Result<render::Character> make_humanoid() {
  CharacterBuilder b("humanoid");
  b.add("pelvis", "", Vec3(0.0, 0.90, 0.0), 0.13);
  b.add("spine_1", "pelvis", Vec3(0.0, 0.10, -0.01), 0.12);
  b.add("spine_2", "spine_1", Vec3(0.0, 0.12, 0.0), 0.13);
  b.add("chest", "spine_2", Vec3(0.0, 0.13, 0.01), 0.14);
  b.add("neck", "chest", Vec3(0.0, 0.17, -0.01), 0.055);
  b.add("head", "neck", Vec3(0.0, 0.09, 0.01), 0.09, Vec3(0.0, 0.13, 0.02), 0.08);
  for (const char* s : {"l", "r"}) {
    const double x = s[0] == 'l' ? 1.0 : -1.0;  // the character's left is +X
    const std::string side = s;
    b.add("clavicle_" + side, "chest", Vec3(0.03 * x, 0.13, -0.01), 0.05);
    b.add("upper_arm_" + side, "clavicle_" + side, Vec3(0.15 * x, -0.01, -0.01), 0.05);
    b.add("forearm_" + side, "upper_arm_" + side, Vec3(0.28 * x, 0.0, 0.0), 0.042);
    b.add("hand_" + side, "forearm_" + side, Vec3(0.25 * x, 0.0, 0.0), 0.035, Vec3(0.17 * x, 0.0, 0.0), 0.028);
  }
  for (const char* s : {"l", "r"}) {
    const double x = s[0] == 'l' ? 1.0 : -1.0;
    const std::string side = s;
    b.add("thigh_" + side, "pelvis", Vec3(0.095 * x, -0.06, 0.0), 0.08);
    b.add("shin_" + side, "thigh_" + side, Vec3(0.0, -0.42, 0.0), 0.055);
    b.add("foot_" + side, "shin_" + side, Vec3(0.0, -0.36, -0.02), 0.045);
    b.add("toe_" + side, "foot_" + side, Vec3(0.0, -0.03, 0.13), 0.035, Vec3(0.0, 0.0, 0.06), 0.025);
  }

  HumanPoser h{b};
  b.add_pose("walk_contact_left", h.walk_contact("l", "r"));
  b.add_pose("walk_passing_left", h.walk_passing("l", "r"));
  b.add_pose("walk_contact_right", h.walk_contact("r", "l"));
  b.add_pose("walk_passing_right", h.walk_passing("r", "l"));
  {
    SkeletonPose p = b.rest();
    b.turn(p, "upper_arm_r", rx(-15.0) * ry(85.0));  // forward and a little up
    b.turn(p, "forearm_r", ry(10.0));
    b.turn(p, "hand_r", rz(10.0));
    h.arm_down(p, "l", 10.0);
    b.turn(p, "spine_1", rx(10.0));
    b.turn(p, "spine_2", rx(10.0) * ry(-8.0));
    b.turn(p, "chest", ry(-8.0));
    h.leg(p, "r", 15.0, 20.0, 5.0);
    h.leg(p, "l", -8.0, 5.0, 3.0);
    b.ground(p);
    b.add_pose("reach_right", p);
  }
  {
    SkeletonPose p = b.rest();
    b.turn(p, "upper_arm_l", rz(55.0));
    b.turn(p, "forearm_l", rz(60.0));
    b.turn(p, "hand_l", rx(20.0) * rz(10.0));
    h.arm_down(p, "r", 0.0);
    b.turn(p, "head", ry(15.0) * rz(-5.0));
    b.turn(p, "spine_2", rz(-3.0));
    b.ground(p);
    b.add_pose("wave_left", p);
  }
  {
    SkeletonPose p = b.rest();
    for (const char* s : {"l", "r"}) h.leg(p, s, 75.0, 120.0, -45.0);
    b.turn(p, "spine_1", rx(20.0));
    b.turn(p, "spine_2", rx(15.0));
    b.turn(p, "chest", rx(5.0));
    b.turn(p, "neck", rx(-20.0));
    b.turn(p, "head", rx(-10.0));
    h.arm_down(p, "l", -50.0, 30.0);
    h.arm_down(p, "r", -50.0, 30.0);
    p.t_world_root_m.z() = -0.15;  // the hips go back over the heels
    b.ground(p);
    b.add_pose("crouch", p);
  }
  {
    SkeletonPose p = b.rest();
    b.turn(p, "spine_2", ry(8.0));
    b.turn(p, "chest", ry(10.0));
    b.turn(p, "neck", ry(30.0) * rx(-10.0));
    b.turn(p, "head", ry(25.0) * rx(-10.0));
    h.arm_down(p, "l", 0.0, 10.0);
    h.arm_down(p, "r", 5.0, 10.0);
    h.leg(p, "l", 3.0, 3.0, 0.0);
    b.ground(p);
    b.add_pose("look_around", p);
  }
  return b.build();
}

}  // namespace proprio::rig_characters::detail
