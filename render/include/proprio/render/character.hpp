#pragma once
// A rigged character for the rig device (issue 31): a generic skeleton, the
// sparse sample poses that rig reduction and pose-space interpolation work
// from, and a skinned mesh whose surface gives each node its weight
// (thesis §3.3: a node's weight is the surface area it directly controls).
//
// In glTF the skeleton is the skin's joint nodes; the sample poses are the
// animations' rotation keyframes, one pose per keyframe time.
#include <cstddef>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/skeleton.hpp"
#include "proprio/render/mesh.hpp"
#include "proprio/render/skinned_mesh.hpp"

namespace proprio::render {

// The thesis's rigs come with 6-25 sample poses; pose-space interpolation
// triangulates them, so thousands would be a hostile file, not a rig.
inline constexpr std::size_t kMaxCharacterSamples = 1024;

struct Character {
  std::string name;
  Skeleton skeleton;
  std::vector<SkeletonPose> sample_poses;
  std::vector<std::string> sample_names;  // one per sample pose
  // The mesh's bind space is the world at rest: inverse_bind[j] is
  // T_world_node(rest)^-1 of its node for characters made here (a loaded
  // file keeps its own bind matrices).
  SkinnedMeshData mesh;
  std::vector<int> mesh_joint_node;  // mesh joint index -> skeleton node

  // A valid skeleton; one name per sample and at most kMaxCharacterSamples,
  // each pose valid for the skeleton; a valid mesh with triangles; one
  // skeleton node per mesh joint, distinct, named as the joint.
  Status validate() const;
};

// The first node with both a mesh and a skin (as load_skinned_gltf) makes the
// character:
// - skeleton: the skin's joint nodes. A node's parent is its nearest ancestor
//   among the joints; non-joint nodes in between (and above a root) are folded
//   into the offsets and rest rotations, so a root's offset is its world
//   transform at rest. Nodes keep the skin's order when it lists parents
//   first, else they are sorted parents first. Empty names become "node<i>".
// - sample poses: every keyframe time of an animation's rotation channels on
//   joints is one pose (rotations at that time, LINEAR or STEP; nodes the
//   animation does not rotate keep their rest rotation), named
//   "<animation>#<k>" (or by the animation's extras "proprio_sample_names",
//   which save_character_gltf writes). A translation channel on the first root
//   moves the pose's root (t_world_root_m); other translations are ignored.
// - mesh: load_skinned_gltf's, with mesh_joint_node mapping the skin's joints.
// Refused: no skinned mesh (Errc::parse_error); a broken or cyclic node
// hierarchy, duplicate joint names, non-finite transforms or keyframes
// (parse_error); non-unit scale on a joint or above one, in a node or an
// animation (unsupported: the skeleton is rigid); CUBICSPLINE rotations
// (unsupported); more than kMaxSkeletonNodes joints or kMaxCharacterSamples
// samples (unsupported). Messages name the node, animation or channel.
Result<Character> load_character_gltf(const std::filesystem::path& file);

// Writes a .gltf with embedded buffers: one node per skeleton node (its rest
// offset and rotation, children as in the skeleton; roots in the scene), the
// skinned mesh on its own node, a skin whose joints are the mesh's joints in
// order (then any skeleton node the mesh does not use, so the skeleton
// survives), and one animation "samples" holding the sample poses as
// keyframes at t = 0, 1, 2, ... (every node's rotation; the first root's
// translation when a pose moves it), with the names in its extras. The
// character must be valid; a .glb path is refused (Errc::invalid_argument).
Status save_character_gltf(const Character& character, const std::filesystem::path& file);

// Each triangle's area in bind space (m^2), a third per vertex, split between
// skeleton nodes by the vertex's skin weights; sums to the mesh's area. The
// character must be valid. One entry per skeleton node.
std::vector<double> skin_area_per_node_m2(const Character& character);

// Skin matrices (one per mesh joint) for T_world_node from forward_kinematics:
// skin[j] = T_world_node[mesh_joint_node[j]] * inverse_bind[j]. `skin` is
// resized; requires T_world_node.size() == skeleton.size().
void character_skin_matrices(const Character& character, std::span<const Pose> T_world_node,
                             std::vector<glm::mat4>& skin);
// The mesh posed by T_world_node (linear-blend skinning, skin_vertices).
// `skin` (scratch) and `out` are resized; once sized, nothing is allocated.
void skin_character(const Character& character, std::span<const Pose> T_world_node, std::vector<glm::mat4>& skin,
                    std::vector<Vertex>& out);

}  // namespace proprio::render
