// Characters in glTF: the skeleton, sample poses and mesh read from small
// hand-written files (including hostile ones), written and read back, and the
// per-node skin area and CPU skinning.
#include <gtest/gtest.h>

#include <cctype>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/render/character.hpp"
#include "support/temp_dir.hpp"

namespace proprio::render {
namespace {

using testing_support::TempDir;

std::string base64(const std::vector<unsigned char>& bytes) {
  static const char* alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned v = (bytes[i] << 16) | (bytes[i + 1] << 8) | bytes[i + 2];
    for (int k = 3; k >= 0; --k) out += alphabet[(v >> (6 * k)) & 63];
  }
  if (i + 1 == bytes.size()) {
    const unsigned v = bytes[i] << 16;
    out += alphabet[(v >> 18) & 63];
    out += alphabet[(v >> 12) & 63];
    out += "==";
  } else if (i + 2 == bytes.size()) {
    const unsigned v = (bytes[i] << 16) | (bytes[i + 1] << 8);
    out += alphabet[(v >> 18) & 63];
    out += alphabet[(v >> 12) & 63];
    out += alphabet[(v >> 6) & 63];
    out += '=';
  }
  return out;
}

template <typename T>
void append(std::vector<unsigned char>& out, const std::vector<T>& values) {
  const auto* p = reinterpret_cast<const unsigned char*>(values.data());
  out.insert(out.end(), p, p + values.size() * sizeof(T));
}

// A one-triangle skinned mesh on two joints ("a" at (0,1,0), its child "b"
// 0.5 above) with one animation, written as .gltf text. Tests change the
// pieces to make hostile files.
struct TinyGltf {
  std::string nodes = R"([{"name":"mesh","mesh":0,"skin":0},{"name":"a","children":[2],"translation":[0,1,0]},)"
                      R"({"name":"b","translation":[0,0.5,0]}])";
  std::string skin_joints = "[1,2]";
  std::string scenes = R"([{"name":"tiny","nodes":[0,1]}])";
  std::string interpolation = "LINEAR";
  std::string animation_name = "wave";
  int rotation_target = 2;
  std::vector<float> times{0.0f, 1.0f};
  // x, y, z, w per keyframe: b turns 45 degrees about Z.
  std::vector<float> rotations{0, 0, 0, 1, 0, 0, 0.38268343f, 0.92387953f};
  bool with_animation = true;
  // Scale keyframes on b (a second sampler), and extra channels, when set.
  std::vector<float> scales{1, 1, 1, 2, 2, 2};
  bool scale_channel = false;
  std::string extra_channels;
  long long declared_buffer_bytes = -1;  // >= 0 overrides the buffer's byteLength
  long long times_count = -1;            // >= 0 overrides the times accessor's count
  std::size_t truncate_buffer_to = std::numeric_limits<std::size_t>::max();
  std::function<void(std::vector<unsigned char>&)> mutate_buffer;  // applied to the finished buffer

  std::string text() const {
    std::vector<unsigned char> buffer;
    append(buffer, std::vector<float>{0, 1, 0, 0.2f, 1, 0, 0, 1.5f, 0});  // POSITION
    const std::size_t joints_at = buffer.size();
    append(buffer, std::vector<std::uint8_t>{0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0});  // JOINTS_0
    const std::size_t weights_at = buffer.size();
    append(buffer, std::vector<float>{1, 0, 0, 0, 1, 0, 0, 0, 0.5f, 0.5f, 0, 0});  // WEIGHTS_0
    const std::size_t ibm_at = buffer.size();
    // Inverse bind: a at (0,1,0), b at (0,1.5,0), bind space = world.
    append(buffer, std::vector<float>{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, -1,    0, 1,
                                      1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, -1.5f, 0, 1});
    const std::size_t times_at = buffer.size();
    append(buffer, times);
    const std::size_t rotations_at = buffer.size();
    append(buffer, rotations);
    const std::size_t scales_at = buffer.size();
    append(buffer, scales);
    const std::size_t total = buffer.size();
    if (buffer.size() > truncate_buffer_to) buffer.resize(truncate_buffer_to);
    if (mutate_buffer) mutate_buffer(buffer);

    auto view = [](std::size_t offset, std::size_t length) {
      return "{\"buffer\":0,\"byteOffset\":" + std::to_string(offset) + ",\"byteLength\":" + std::to_string(length) +
             "}";
    };
    std::string s = "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":" + scenes + ",\"nodes\":" + nodes +
                    ",\"skins\":[{\"joints\":" + skin_joints + ",\"inverseBindMatrices\":3}]";
    s += R"(,"meshes":[{"name":"tri","primitives":[{"attributes":{"POSITION":0,"JOINTS_0":1,"WEIGHTS_0":2}}]}])";
    s += ",\"accessors\":[";
    s += R"({"bufferView":0,"componentType":5126,"count":3,"type":"VEC3"},)";
    s += R"({"bufferView":1,"componentType":5121,"count":3,"type":"VEC4"},)";
    s += R"({"bufferView":2,"componentType":5126,"count":3,"type":"VEC4"},)";
    s += R"({"bufferView":3,"componentType":5126,"count":2,"type":"MAT4"},)";
    s += R"({"bufferView":4,"componentType":5126,"count":)" +
         std::to_string(times_count >= 0 ? times_count : static_cast<long long>(times.size())) +
         R"(,"type":"SCALAR"},)";
    s += R"({"bufferView":5,"componentType":5126,"count":)" + std::to_string(rotations.size() / 4) +
         R"(,"type":"VEC4"},)";
    s += R"({"bufferView":6,"componentType":5126,"count":)" + std::to_string(scales.size() / 3) + R"(,"type":"VEC3"}])";
    s += ",\"bufferViews\":[" + view(0, joints_at) + "," + view(joints_at, weights_at - joints_at) + "," +
         view(weights_at, ibm_at - weights_at) + "," + view(ibm_at, times_at - ibm_at) + "," +
         view(times_at, rotations_at - times_at) + "," + view(rotations_at, scales_at - rotations_at) + "," +
         view(scales_at, total - scales_at) + "]";
    s += ",\"buffers\":[{\"byteLength\":" +
         std::to_string(declared_buffer_bytes >= 0 ? declared_buffer_bytes : static_cast<long long>(total)) +
         ",\"uri\":\"data:application/octet-stream;base64," + base64(buffer) + "\"}]";
    if (with_animation) {
      s += ",\"animations\":[{\"name\":\"" + animation_name +
           "\",\"samplers\":[{\"input\":4,\"output\":5,"
           "\"interpolation\":\"" +
           interpolation +
           "\"},{\"input\":4,\"output\":6}],\"channels\":[{\"sampler\":0,"
           "\"target\":{\"node\":" +
           std::to_string(rotation_target) + ",\"path\":\"rotation\"}}" +
           (scale_channel ? R"(,{"sampler":1,"target":{"node":2,"path":"scale"}})" : "") + extra_channels + "]}]";
    }
    return s + "}";
  }
};

double angle(const Quat& a, const Quat& b) { return angle_between(a, b); }

TEST(CharacterGltf, LoadsSkeletonPosesAndMesh) {
  TempDir dir;
  auto c = load_character_gltf(dir.write("tiny.gltf", TinyGltf{}.text()));
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_EQ(c->name, "tiny");
  ASSERT_EQ(c->skeleton.size(), 2u);
  EXPECT_EQ(c->skeleton.names, (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(c->skeleton.parent, (std::vector<int>{-1, 0}));
  EXPECT_LT((c->skeleton.t_parent_node_m[0] - Vec3(0, 1, 0)).norm(), 1e-12);
  EXPECT_LT((c->skeleton.t_parent_node_m[1] - Vec3(0, 0.5, 0)).norm(), 1e-12);
  ASSERT_EQ(c->sample_poses.size(), 2u);
  EXPECT_EQ(c->sample_names, (std::vector<std::string>{"wave#0", "wave#1"}));
  // The animation rotates b only; a keeps its rest rotation.
  EXPECT_LT(angle(c->sample_poses[1].q_parent_node[0], Quat::Identity()), 1e-9);
  EXPECT_NEAR(angle(c->sample_poses[1].q_parent_node[1], Quat::Identity()), std::numbers::pi / 4, 1e-6);
  EXPECT_LT(angle(c->sample_poses[0].q_parent_node[1], Quat::Identity()), 1e-6);
  EXPECT_EQ(c->mesh.indices.size(), 3u);
  EXPECT_EQ(c->mesh_joint_node, (std::vector<int>{0, 1}));
  EXPECT_TRUE(c->validate());
}

TEST(CharacterGltf, HelperAndArmatureNodesFoldIntoOffsets) {
  TinyGltf g;
  // node 3: an armature above a (turned 90 degrees about Y, moved along X);
  // node 4: a helper between a and b (0.25 up, turned 90 degrees about X).
  g.nodes = R"([{"name":"mesh","mesh":0,"skin":0},{"name":"a","children":[4],"translation":[0,1,0]},)"
            R"({"name":"b","translation":[0,0.25,0]},)"
            R"({"name":"armature","children":[1],"translation":[1,0,0],"rotation":[0,0.70710678,0,0.70710678]},)"
            R"({"name":"helper","children":[2],"translation":[0,0.25,0],"rotation":[0.70710678,0,0,0.70710678]}])";
  g.scenes = R"([{"nodes":[0,3]}])";
  TempDir dir;
  auto c = load_character_gltf(dir.write("armature.gltf", g.text()));
  ASSERT_TRUE(c) << c.error().message;
  ASSERT_EQ(c->skeleton.size(), 2u);
  // The root's offset is its world transform at rest.
  EXPECT_LT((c->skeleton.t_parent_node_m[0] - Vec3(1, 1, 0)).norm(), 1e-9);
  EXPECT_LT(angle(c->skeleton.q_parent_node_rest[0], Quat(Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitY()))),
            1e-9);
  // b hangs from a through the helper: 0.25 up, then 0.25 along the helper's turned Y (= a's Z).
  EXPECT_LT((c->skeleton.t_parent_node_m[1] - Vec3(0, 0.25, 0.25)).norm(), 1e-9);
  // A pose's rotation of b includes the helper's fixed turn.
  const Quat helper(Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitX()));
  const Quat key(Eigen::AngleAxisd(std::numbers::pi / 4, Vec3::UnitZ()));
  EXPECT_LT(angle(c->sample_poses[1].q_parent_node[1], helper * key), 1e-6);
  EXPECT_EQ(c->name, "tri");  // the scene has no name: the mesh's
}

TEST(CharacterGltf, ALongChainOfHelpersAboveTheRootFoldsIntoItsOffset) {
  TinyGltf g;
  constexpr int kHelpers = 2000;
  g.nodes = R"([{"name":"mesh","mesh":0,"skin":0},{"name":"a","children":[2],"translation":[0,1,0]},)"
            R"({"name":"b","translation":[0,0.5,0]})";
  for (int h = 0; h < kHelpers; ++h) {
    const int child = h + 1 < kHelpers ? 3 + h + 1 : 1;  // the last helper holds a
    g.nodes += ",{\"name\":\"h" + std::to_string(h) + "\",\"children\":[" + std::to_string(child) +
               "],\"translation\":[0.001,0,0]}";
  }
  g.nodes += "]";
  g.scenes = R"([{"nodes":[0,3]}])";
  TempDir dir;
  auto c = load_character_gltf(dir.write("helpers.gltf", g.text()));
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_LT((c->skeleton.t_parent_node_m[0] - Vec3(0.001 * kHelpers, 1, 0)).norm(), 1e-9);
  EXPECT_LT((c->skeleton.t_parent_node_m[1] - Vec3(0, 0.5, 0)).norm(), 1e-12);
}

TEST(CharacterGltf, SkinListingChildrenFirstIsSortedParentsFirst) {
  TinyGltf g;
  g.skin_joints = "[2,1]";  // b before its parent a
  TempDir dir;
  auto c = load_character_gltf(dir.write("reversed.gltf", g.text()));
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_EQ(c->skeleton.names, (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(c->skeleton.parent, (std::vector<int>{-1, 0}));
  // Mesh joint 0 is b now (the skin's order), node 1.
  EXPECT_EQ(c->mesh_joint_node, (std::vector<int>{1, 0}));
  EXPECT_EQ(c->mesh.joint_names, (std::vector<std::string>{"b", "a"}));
  EXPECT_TRUE(c->validate());
}

TEST(CharacterGltf, StepAndLinearKeysSampleEveryKeyframeTime) {
  TinyGltf g;
  g.times = {0.0f, 0.5f, 2.0f};
  g.rotations = {0, 0, 0, 1, 0, 0, 0.38268343f, 0.92387953f, 0, 0, 0.70710678f, 0.70710678f};
  TempDir dir;
  auto linear = load_character_gltf(dir.write("linear.gltf", g.text()));
  ASSERT_TRUE(linear) << linear.error().message;
  ASSERT_EQ(linear->sample_poses.size(), 3u);
  EXPECT_NEAR(angle(linear->sample_poses[2].q_parent_node[1], Quat::Identity()), std::numbers::pi / 2, 1e-6);
  g.interpolation = "STEP";
  auto step = load_character_gltf(dir.write("step.gltf", g.text()));
  ASSERT_TRUE(step) << step.error().message;
  ASSERT_EQ(step->sample_poses.size(), 3u);
  for (std::size_t k = 0; k < 3; ++k) {
    EXPECT_LT(angle(step->sample_poses[k].q_parent_node[1], linear->sample_poses[k].q_parent_node[1]), 1e-6);
  }
}

// A character with rest rotations, a root that moves in one pose, named
// samples, mesh joints in another order than the skeleton and a node the
// mesh does not use.
Character handmade() {
  Character c;
  c.name = "handmade";
  c.skeleton.add("root", -1, Vec3(0.1, 0.9, -0.2), Quat(Eigen::AngleAxisd(0.3, Vec3::UnitY())));
  c.skeleton.add("upper", 0, Vec3(0, 0.4, 0), Quat(Eigen::AngleAxisd(-0.2, Vec3::UnitX())));
  c.skeleton.add("lower", 1, Vec3(0, 0.35, 0.02));
  c.skeleton.add("unskinned", 0, Vec3(0.2, 0, 0));
  for (int k = 0; k < 3; ++k) {
    SkeletonPose p = rest_pose(c.skeleton);
    p.q_parent_node[1] = p.q_parent_node[1] * Quat(Eigen::AngleAxisd(0.4 * k, Vec3(1, 0.5, 0).normalized()));
    p.q_parent_node[2] = Quat(Eigen::AngleAxisd(-0.3 * k, Vec3::UnitZ()));
    if (k == 2) p.t_world_root_m = Vec3(0.0, -0.1, 0.05);
    c.sample_poses.push_back(p);
    c.sample_names.push_back("pose " + std::to_string(k));
  }
  std::vector<Pose> T;
  forward_kinematics(c.skeleton, rest_pose(c.skeleton), T);
  c.mesh.name = "handmade_mesh";
  c.mesh.joint_names = {"lower", "root", "upper"};
  c.mesh_joint_node = {2, 0, 1};
  for (int node : c.mesh_joint_node) {
    const Eigen::Matrix4d m = T[static_cast<std::size_t>(node)].inverse().matrix();
    glm::mat4 ibm;
    for (int col = 0; col < 4; ++col)
      for (int r = 0; r < 4; ++r) ibm[col][r] = static_cast<float>(m(r, col));
    c.mesh.inverse_bind.push_back(ibm);
  }
  // A strip of quads up the chain, each vertex blended between two joints.
  for (int i = 0; i <= 4; ++i) {
    for (int side = 0; side < 2; ++side) {
      SkinnedVertex v;
      v.position = {side ? 0.05f : -0.05f, 0.9f + 0.18f * static_cast<float>(i), -0.2f};
      v.normal = {0, 0, 1};
      const float t = static_cast<float>(i) / 4.0f;
      v.joints = {1, 2, 0, 0};  // root, upper, lower
      v.weights = {(1.0f - t) * (1.0f - t), 2.0f * t * (1.0f - t), t * t, 0.0f};
      c.mesh.vertices.push_back(v);
    }
  }
  for (std::uint32_t i = 0; i < 4; ++i) {
    const std::uint32_t a = 2 * i;
    c.mesh.indices.insert(c.mesh.indices.end(), {a, a + 1, a + 2, a + 1, a + 3, a + 2});
  }
  return c;
}

TEST(CharacterGltf, RoundTripKeepsSkeletonPosesNamesAndMesh) {
  const Character c = handmade();
  ASSERT_TRUE(c.validate()) << c.validate().error().message;
  TempDir dir;
  ASSERT_TRUE(save_character_gltf(c, dir / "handmade.gltf"));
  auto back = load_character_gltf(dir / "handmade.gltf");
  ASSERT_TRUE(back) << back.error().message;
  EXPECT_EQ(back->name, c.name);
  ASSERT_EQ(back->skeleton.names, c.skeleton.names);
  EXPECT_EQ(back->skeleton.parent, c.skeleton.parent);
  for (std::size_t i = 0; i < c.skeleton.size(); ++i) {
    EXPECT_LT((back->skeleton.t_parent_node_m[i] - c.skeleton.t_parent_node_m[i]).norm(), 1e-9) << i;
    EXPECT_LT(angle(back->skeleton.q_parent_node_rest[i], c.skeleton.q_parent_node_rest[i]), 1e-9) << i;
  }
  EXPECT_EQ(back->sample_names, c.sample_names);
  ASSERT_EQ(back->sample_poses.size(), c.sample_poses.size());
  for (std::size_t k = 0; k < c.sample_poses.size(); ++k) {
    for (std::size_t i = 0; i < c.skeleton.size(); ++i) {
      EXPECT_LT(angle(back->sample_poses[k].q_parent_node[i], c.sample_poses[k].q_parent_node[i]), 1e-6);
    }
    EXPECT_LT((back->sample_poses[k].t_world_root_m - c.sample_poses[k].t_world_root_m).norm(), 1e-6);
  }
  // The mesh keeps its joints in order; the unskinned node is appended to the skin.
  ASSERT_EQ(back->mesh.joint_names.size(), 4u);
  EXPECT_EQ(std::vector<std::string>(back->mesh.joint_names.begin(), back->mesh.joint_names.begin() + 3),
            c.mesh.joint_names);
  EXPECT_EQ(back->mesh.joint_names[3], "unskinned");
  EXPECT_EQ(std::vector<int>(back->mesh_joint_node.begin(), back->mesh_joint_node.begin() + 3), c.mesh_joint_node);
  EXPECT_EQ(back->mesh.indices, c.mesh.indices);
  ASSERT_EQ(back->mesh.vertices.size(), c.mesh.vertices.size());
  for (std::size_t i = 0; i < c.mesh.vertices.size(); ++i) {
    EXPECT_EQ(back->mesh.vertices[i].position, c.mesh.vertices[i].position);
    EXPECT_LT(glm::length(back->mesh.vertices[i].weights - c.mesh.vertices[i].weights), 1e-6f);
  }
  // The area per node does not depend on the appended joint.
  const auto a = skin_area_per_node_m2(c), b = skin_area_per_node_m2(*back);
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], b[i], 1e-9);
}

TEST(CharacterGltf, SkinAreaSumsToTheMeshAreaAndFollowsTheWeights) {
  const Character c = handmade();
  const auto area = skin_area_per_node_m2(c);
  ASSERT_EQ(area.size(), c.skeleton.size());
  double total = 0.0;
  for (std::size_t t = 0; t < c.mesh.indices.size(); t += 3) {
    const glm::dvec3 a(c.mesh.vertices[c.mesh.indices[t]].position), b(c.mesh.vertices[c.mesh.indices[t + 1]].position),
        d(c.mesh.vertices[c.mesh.indices[t + 2]].position);
    total += 0.5 * glm::length(glm::cross(b - a, d - a));
  }
  double sum = 0.0;
  for (double a : area) {
    EXPECT_GE(a, 0.0);
    sum += a;
  }
  EXPECT_NEAR(sum, total, 1e-7 * total);  // summed in another order
  EXPECT_EQ(area[3], 0.0);                // no vertex is weighted to the unskinned node
  EXPECT_GT(area[0], 0.0);
  EXPECT_GT(area[2], 0.0);
}

TEST(CharacterGltf, SkinningAtRestIsTheBindPoseAndFollowsABentJoint) {
  const Character c = handmade();
  std::vector<Pose> T;
  forward_kinematics(c.skeleton, rest_pose(c.skeleton), T);
  std::vector<glm::mat4> skin;
  std::vector<Vertex> out;
  skin_character(c, T, skin, out);
  ASSERT_EQ(out.size(), c.mesh.vertices.size());
  for (std::size_t i = 0; i < out.size(); ++i)
    EXPECT_LT(glm::length(out[i].position - c.mesh.vertices[i].position), 1e-5f);
  // Turning the whole character about its root by 90 degrees turns every vertex with it.
  SkeletonPose p = rest_pose(c.skeleton);
  const Quat turn(Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitY()));
  p.q_parent_node[0] = turn * p.q_parent_node[0];
  forward_kinematics(c.skeleton, p, T);
  skin_character(c, T, skin, out);
  const Vec3 root = c.skeleton.t_parent_node_m[0];
  for (std::size_t i = 0; i < out.size(); ++i) {
    const glm::vec3 b = c.mesh.vertices[i].position;
    const Vec3 expected = root + turn * (Vec3(b.x, b.y, b.z) - root);
    EXPECT_LT((Vec3(out[i].position.x, out[i].position.y, out[i].position.z) - expected).norm(), 1e-5) << i;
  }
}

TEST(CharacterGltf, ValidateNamesWhatIsWrong) {
  Character c = handmade();
  c.sample_names.pop_back();
  EXPECT_FALSE(c.validate());
  c = handmade();
  c.mesh_joint_node[0] = 1;  // two joints on "upper", and the names disagree
  EXPECT_FALSE(c.validate());
  c = handmade();
  c.sample_poses[1].q_parent_node[2] = Quat(0, 0, 0, 0);
  const auto s = c.validate();
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("pose 1"), std::string::npos) << s.error().message;
  TempDir dir;
  EXPECT_FALSE(save_character_gltf(c, dir / "bad.gltf"));
  EXPECT_FALSE(std::filesystem::exists(dir / "bad.gltf"));
  EXPECT_FALSE(save_character_gltf(handmade(), dir / "binary.glb"));  // would be text under a binary name
}

// Hostile files: each is refused with an error that says what is wrong.
void expect_refused(const TinyGltf& g, const std::string& words, const char* label) {
  TempDir dir;
  auto c = load_character_gltf(dir.write("hostile.gltf", g.text()));
  ASSERT_FALSE(c) << label;
  EXPECT_NE(c.error().message.find(words), std::string::npos) << label << ": " << c.error().message;
}

TEST(CharacterGltf, RefusesMissingSkin) {
  TinyGltf g;
  g.nodes = R"([{"name":"mesh","mesh":0},{"name":"a","children":[2]},{"name":"b"}])";
  expect_refused(g, "no skinned mesh", "no skin");
}

TEST(CharacterGltf, RefusesBrokenHierarchies) {
  TinyGltf g;
  g.nodes = R"([{"name":"mesh","mesh":0,"skin":0},{"name":"a","children":[2]},{"name":"b","children":[1]}])";
  g.scenes = R"([{"nodes":[0]}])";
  expect_refused(g, "cycle", "a <-> b");
  g.nodes = R"([{"name":"mesh","mesh":0,"skin":0},{"name":"a","children":[2]},{"name":"b","children":[2]}])";
  expect_refused(g, "itself", "b is its own child");
  g.nodes = R"([{"name":"mesh","mesh":0,"skin":0,"children":[2]},{"name":"a","children":[2]},{"name":"b"}])";
  expect_refused(g, "one parent", "b has two parents");
  g.nodes = R"([{"name":"mesh","mesh":0,"skin":0},{"name":"a","children":[7]},{"name":"b"}])";
  expect_refused(g, "does not exist", "child 7");
  g = TinyGltf{};
  g.skin_joints = "[1,9]";
  expect_refused(g, "does not exist", "joint 9");
  g.skin_joints = "[1,1]";
  expect_refused(g, "twice", "joint listed twice");
  g = TinyGltf{};
  g.nodes = R"([{"name":"mesh","mesh":0,"skin":0},{"name":"x","children":[2]},{"name":"x"}])";
  expect_refused(g, "unique", "duplicate names");
}

TEST(CharacterGltf, RefusesNonUnitScale) {
  TinyGltf g;
  g.nodes = R"([{"name":"mesh","mesh":0,"skin":0},{"name":"a","children":[2]},{"name":"b","scale":[2,2,2]}])";
  TempDir dir;
  auto c = load_character_gltf(dir.write("scaled.gltf", g.text()));
  ASSERT_FALSE(c);
  EXPECT_EQ(c.error().code, Errc::unsupported);
  EXPECT_NE(c.error().message.find("'b'"), std::string::npos) << c.error().message;
  // Above the skeleton too, and hidden in a matrix.
  g.nodes = R"([{"name":"mesh","mesh":0,"skin":0},{"name":"a","children":[2]},{"name":"b"},)"
            R"({"name":"armature","children":[1],"scale":[0.01,0.01,0.01]}])";
  expect_refused(g, "scale", "armature scale");
  g.nodes = R"([{"name":"mesh","mesh":0,"skin":0},{"name":"a","children":[2]},)"
            R"({"name":"b","matrix":[1,0,0,0, 0,3,0,0, 0,0,1,0, 0,0,0,1]}])";
  expect_refused(g, "scales", "matrix scale");
}

TEST(CharacterGltf, RefusesBadKeyframes) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  TinyGltf g;
  g.rotations[5] = nan;
  expect_refused(g, "not finite", "NaN rotation");
  g = TinyGltf{};
  g.times[1] = nan;
  expect_refused(g, "not finite", "NaN time");
  g = TinyGltf{};
  g.times = {1.0f, 0.5f};
  expect_refused(g, "increase", "times going back");
  g = TinyGltf{};
  g.rotations = {0, 0, 0, 0, 0, 0, 0, 1};
  expect_refused(g, "zero", "zero quaternion");
  g = TinyGltf{};
  g.interpolation = "CUBICSPLINE";
  expect_refused(g, "CUBICSPLINE", "cubic spline");
  g = TinyGltf{};
  g.scale_channel = true;
  expect_refused(g, "animates scale", "scale keyframes");
  g = TinyGltf{};
  g.extra_channels = R"(,{"sampler":0,"target":{"node":2,"path":"rotation"}})";
  expect_refused(g, "second rotation channel", "two rotation channels on b");
  g = TinyGltf{};
  g.extra_channels = R"(,{"sampler":5,"target":{"node":1,"path":"rotation"}})";
  expect_refused(g, "sampler 5", "missing sampler");
}

TEST(CharacterGltf, UnitScaleKeyframesAndChannelsOnOtherNodesAreAccepted) {
  TinyGltf g;
  g.scale_channel = true;
  g.scales = {1, 1, 1, 1.00001f, 1, 1};
  // A translation on b (not the root) is ignored: the skeleton is posed by rotations.
  g.extra_channels = R"(,{"sampler":1,"target":{"node":2,"path":"translation"}})";
  TempDir dir;
  auto c = load_character_gltf(dir.write("unit_scale.gltf", g.text()));
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_EQ(c->sample_poses.size(), 2u);
  EXPECT_TRUE(c->sample_poses[1].t_world_root_m.isZero());
}

TEST(CharacterGltf, RefusesHugeCounts) {
  TinyGltf g;
  g.times_count = 1000000000;  // far past the buffer
  expect_refused(g, "past the end", "huge accessor count");
  // More keyframes than a character has samples, with real data behind them.
  g = TinyGltf{};
  g.times.clear();
  g.rotations.clear();
  for (int k = 0; k < 1100; ++k) {
    g.times.push_back(static_cast<float>(k));
    g.rotations.insert(g.rotations.end(), {0, 0, 0, 1});
  }
  expect_refused(g, "at most 1024", "1100 keyframes");
  // More joints than any skeleton may have.
  g = TinyGltf{};
  std::string joints = "[";
  for (std::size_t i = 0; i < kMaxSkeletonNodes + 1; ++i) joints += (i ? ",1" : "1");
  g.skin_joints = joints + "]";
  expect_refused(g, "at most", "too many joints");
}

TEST(CharacterGltf, RefusesTruncatedBuffers) {
  TinyGltf g;
  g.truncate_buffer_to = 100;  // the data stops inside the inverse bind matrices
  TempDir dir;
  auto c = load_character_gltf(dir.write("short.gltf", g.text()));
  EXPECT_FALSE(c);
  g = TinyGltf{};
  g.declared_buffer_bytes = 1 << 20;
  c = load_character_gltf(dir.write("claims_more.gltf", g.text()));
  EXPECT_FALSE(c);
  EXPECT_FALSE(load_character_gltf(dir.write("cut.gltf", TinyGltf{}.text().substr(0, 400))));
  EXPECT_FALSE(load_character_gltf(dir / "missing.gltf"));
}

// Deterministic mutations of a valid file, in its bytes (every float, index
// and joint the loader reads) and in its JSON numbers: each load either
// yields a valid character or an error that says something.
TEST(CharacterGltf, MutatedFilesLoadValidOrFailWithAMessage) {
  TempDir dir;
  Rng rng(31);
  int loaded = 0, refused = 0;
  for (int trial = 0; trial < 300; ++trial) {
    TinyGltf g;
    g.mutate_buffer = [&](std::vector<unsigned char>& bytes) {
      const int flips = 1 + static_cast<int>(rng.below(4));
      for (int k = 0; k < flips; ++k) bytes[rng.below(bytes.size())] = static_cast<unsigned char>(rng.below(256));
    };
    std::string text = g.text();
    if (trial % 3 == 0) {  // and a JSON digit changed, outside the base64 data
      const std::size_t data = text.find("base64,");
      for (int k = 0; k < 8; ++k) {
        const std::size_t at = rng.below(data);
        if (std::isdigit(static_cast<unsigned char>(text[at]))) {
          text[at] = static_cast<char>('0' + rng.below(10));
          break;
        }
      }
    }
    auto c = load_character_gltf(dir.write("mutated.gltf", text));
    if (c) {
      ++loaded;
      EXPECT_TRUE(c->validate()) << trial;
    } else {
      ++refused;
      EXPECT_FALSE(c.error().message.empty()) << trial;
    }
  }
  // Both outcomes occur: the mutations reach the checks without always breaking the file.
  EXPECT_GT(loaded, 0);
  EXPECT_GT(refused, 0);
}

}  // namespace
}  // namespace proprio::render
