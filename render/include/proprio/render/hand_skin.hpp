#pragma once
// Skinned hands: a skinned mesh whose skin joints carry the names of the 26
// OpenXR hand joints, driven by a HandPose.
//
// Joint naming. A skin joint binds to an OpenXR joint when its glTF node name
// is the joint's name as `to_string(HandJoint)` gives it ("wrist", "palm",
// "index_proximal", "thumb_tip", ...) or the XrHandJointEXT enumerant
// ("XR_HAND_JOINT_INDEX_PROXIMAL_EXT"); case does not matter. Joints with
// other names are allowed only if no vertex is weighted to them (an armature
// root, say). Each OpenXR joint may appear once. The skin must contain the
// wrist and at least one thumb joint: their bind poses tell which hand the
// mesh was modelled as.
//
// Bind pose. The inverse bind matrices must put each joint's bind frame in
// OpenXR's convention (+Z back along the bone toward the wrist, +Y out of the
// back of the hand, X = Y x Z). The node transforms in the file are ignored:
// the tracked pose replaces them, as
//   skin[j] = T_world_joint(pose) * inverse_bind[j].
// A pose of the other hand is drawn mirrored (through the joints' YZ plane,
// as the hand model mirrors hands): skin[j] = T_world_joint * diag(-1,1,1) *
// inverse_bind[j], so one right-hand mesh serves both hands. A joint the pose
// does not mark valid follows its nearest valid ancestor (palm: the wrist);
// an inactive pose, or one without a valid wrist, draws nothing.
#include <array>
#include <optional>
#include <span>
#include <string_view>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/hand_pose.hpp"
#include "proprio/render/renderer.hpp"
#include "proprio/render/skinned_mesh.hpp"

namespace proprio::render {

// The OpenXR joint a skin joint's name denotes (see above), if any.
std::optional<HandJoint> hand_joint_from_name(std::string_view name) noexcept;

struct HandMeshOptions {
  int segments = 16;              // vertices around a finger
  float ring_spacing_m = 0.0035f; // between rings along a finger
  float blend_radii = 0.8f;       // half-width of the smooth weight blend at a joint, in joint radii
};

// A skinned hand built around `model`'s rest pose (all angles 0, the flat
// hand) of `hand`, in the wrist frame (bind space = wrist joint frame): a
// tapered tube with domed ends along each finger (the thumb's from its
// metacarpal) and a rounded palm slab from the wrist to the knuckles.
// Weights blend smoothly across each joint (over +-blend_radii joint radii);
// the palm blends from the wrist into the metacarpals. 26 skin joints in
// XrHandJointEXT order, named `to_string(HandJoint)`. Deterministic.
SkinnedMeshData generate_hand_mesh(const HandModel& model, Handedness hand, const HandMeshOptions& options = {});

// A skinned mesh bound to the OpenXR joints by name.
class HandSkin {
 public:
  // Errc::parse_error naming the offending joint when a weighted joint has
  // no OpenXR name, an OpenXR joint appears twice, or the wrist or every
  // thumb joint is missing.
  static Result<HandSkin> bind(const SkinnedMeshData& mesh);

  // The hand the mesh was modelled as (from the thumb's side in the wrist's bind frame).
  Handedness hand() const noexcept { return hand_; }
  std::size_t joint_count() const noexcept { return joint_of_skin_.size(); }
  // The OpenXR joint skin joint i drives, if any.
  std::optional<HandJoint> joint_of(std::size_t skin_joint) const noexcept;

  // One skin matrix per skin joint into out (out.size() >= joint_count()).
  // False, writing nothing, when the pose is inactive or its wrist is not
  // valid. Allocates nothing.
  bool skin_matrices(const HandPose& pose, std::span<glm::mat4> out) const noexcept;

 private:
  HandSkin() = default;
  static constexpr std::uint8_t kUnbound = 0xff;
  std::vector<std::uint8_t> joint_of_skin_;             // OpenXR joint index or kUnbound
  std::array<int, kHandJointCount> skin_of_joint_{};    // skin joint index or -1
  std::vector<glm::mat4> inverse_bind_;
  Handedness hand_ = Handedness::right;
};

// A skinned hand on the GPU: its mesh (Renderer::upload_skinned) and binding.
struct SkinnedHand {
  MeshId mesh = 0;
  std::optional<HandSkin> skin;

  // Binds and uploads `mesh`.
  static Result<SkinnedHand> upload(Renderer& renderer, const SkinnedMeshData& mesh);
};

// Appends `pose` drawn with `hand` in `color` (nothing when the pose is
// inactive, as append_hand). Allocates nothing once the draw list's
// capacities have grown.
void append_skinned_hand(DrawList& draws, const HandPose& pose, const SkinnedHand& hand, const glm::vec4& color);

// Right hands warm, left hands cool, like HandStyle::for_hand.
glm::vec4 skin_color_for(Handedness hand);

}  // namespace proprio::render
