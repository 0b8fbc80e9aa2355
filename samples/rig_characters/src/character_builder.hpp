#pragma once
// Shared by the example characters: a skeleton built node by node with a body
// radius per node, poses edited by node name, and the capsule skin.
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/skeleton.hpp"
#include "proprio/render/character.hpp"

namespace proprio::rig_characters::detail {

// Rotations about the parent frame's axes, in degrees (rest frames are the
// world's: +X the character's left, +Y up, +Z forward).
Quat rx(double deg);
Quat ry(double deg);
Quat rz(double deg);
// The same rotation on the character's right (side < 0): mirrored through the
// YZ plane. side > 0 returns q.
Quat mirrored(const Quat& q, double side);

class CharacterBuilder {
 public:
  explicit CharacterBuilder(std::string name) { character_.name = std::move(name); }

  // A node at t_parent_node_m from `parent` ("" for the root), with the body's
  // radius at its origin. `tip_m` (node frame), when non-zero, adds a capsule
  // from the node to there ending at `tip_radius_m`: the hand, head or hoof
  // beyond the last joint.
  void add(std::string name, std::string_view parent, const Vec3& t_parent_node_m, double radius_m,
           const Vec3& tip_m = Vec3::Zero(), double tip_radius_m = 0.0);

  SkeletonPose rest() const { return rest_pose(character_.skeleton); }
  // Turns `node` further by q (applied after its current rotation, i.e. about
  // the node's own posed axes). Unknown names are remembered and fail build().
  void turn(SkeletonPose& pose, std::string_view node, const Quat& q);
  // Turns every node "<prefix><i>" for i = first..last by q_of(i).
  template <typename F>
  void turn_chain(SkeletonPose& pose, std::string_view prefix, int first, int last, F q_of) {
    for (int i = first; i <= last; ++i) turn(pose, std::string(prefix) + std::to_string(i), q_of(i));
  }
  // Moves the root vertically so the lowest point of the body (node origins
  // and tips, less their radii) is as high as at rest: poses stand on the
  // ground instead of sinking into it or floating.
  void ground(SkeletonPose& pose) const;
  void add_pose(std::string name, SkeletonPose pose);

  // The character with its capsule mesh; fails on any unknown node name.
  Result<render::Character> build() const;

 private:
  double lowest_point_m(const SkeletonPose& pose) const;

  render::Character character_;
  std::vector<double> radius_m_;
  std::vector<Vec3> tip_m_;
  std::vector<double> tip_radius_m_;
  std::string error_;
};

// The three examples (humanoid.cpp, quadruped.cpp, creature.cpp).
Result<render::Character> make_humanoid();
Result<render::Character> make_quadruped();
Result<render::Character> make_creature();

}  // namespace proprio::rig_characters::detail
