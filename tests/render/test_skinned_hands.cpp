// Skinned hands: the generated hand asset, glTF round trip and errors, the
// OpenXR joint binding, the skinning maths (rest pose, rigid vertices,
// mirroring) and a golden image of skinned hands in three poses per side.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>

#include <nlohmann/json.hpp>

#include "golden.hpp"
#include "proprio/core/glm_interop.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/render/camera.hpp"
#include "proprio/render/hand_skin.hpp"
#include "render_fixture.hpp"

namespace proprio::render {
namespace skinned_hand_tests {

using testing::expect_matches_golden;
using testing::RenderTest;

HandModel adult_hand() { return HandModel(*HandShape::from_measurements(0.19, 0.09)); }

std::filesystem::path temp_dir() {
  const auto dir = std::filesystem::path(PROPRIO_GOLDEN_OUT_DIR) / "skinned_hand_tests";
  std::filesystem::create_directories(dir);
  return dir;
}

// Open, fist and pointing angles (as the joint-sphere golden uses).
struct ThreePoses {
  HandAngles open{}, fist{}, point{};
};
ThreePoses three_poses() {
  ThreePoses p;
  for (Finger f : {Finger::index, Finger::middle, Finger::ring, Finger::little}) {
    const std::size_t k = first_dof_of(f);
    p.fist[k] = 1.4;
    p.fist[k + 2] = 1.5;
    p.fist[k + 3] = 0.9;
    if (f != Finger::index) {
      p.point[k] = p.fist[k];
      p.point[k + 2] = p.fist[k + 2];
      p.point[k + 3] = p.fist[k + 3];
    }
  }
  p.fist[index_of(HandDof::thumb_mcp_flexion)] = 0.8;
  p.fist[index_of(HandDof::thumb_ip_flexion)] = 0.9;
  p.point[index_of(HandDof::thumb_mcp_flexion)] = 0.6;
  return p;
}

std::vector<Vertex> skinned(const SkinnedMeshData& mesh, const HandSkin& skin, const HandPose& pose) {
  std::vector<glm::mat4> matrices(skin.joint_count());
  EXPECT_TRUE(skin.skin_matrices(pose, matrices));
  std::vector<Vertex> out(mesh.vertices.size());
  skin_vertices(mesh.vertices, matrices, out);
  return out;
}

nlohmann::json read_json(const std::filesystem::path& file) {
  std::ifstream in(file);
  return nlohmann::json::parse(in);
}
void write_json(const nlohmann::json& j, const std::filesystem::path& file) {
  std::ofstream out(file);
  out << j.dump();
}

TEST(SkinnedHandMesh, GeneratedHandHasTheOpenXrJointsAndSaneGeometry) {
  const HandModel model = adult_hand();
  const SkinnedMeshData mesh = generate_hand_mesh(model, Handedness::right);
  ASSERT_TRUE(mesh.validate()) << mesh.validate().error().message;
  ASSERT_EQ(mesh.joint_names.size(), kHandJointCount);
  for (std::size_t i = 0; i < kHandJointCount; ++i) EXPECT_EQ(mesh.joint_names[i], to_string(joint_at(i)));
  EXPECT_GT(mesh.vertices.size(), 1500u);
  EXPECT_LT(mesh.vertices.size(), 6000u);
  // Closed and facing outwards: the signed volume is positive and about a hand's (~300-500 ml).
  double volume = 0.0;
  for (std::size_t t = 0; t < mesh.indices.size(); t += 3) {
    const glm::dvec3 a = mesh.vertices[mesh.indices[t]].position, b = mesh.vertices[mesh.indices[t + 1]].position,
                     c = mesh.vertices[mesh.indices[t + 2]].position;
    volume += glm::dot(a, glm::cross(b, c)) / 6.0;
  }
  EXPECT_GT(volume, 150e-6);
  EXPECT_LT(volume, 800e-6);
  // Every fingertip joint is just inside the mesh's end; the mesh spans the thumb to the little finger.
  const HandPose rest = model.forward(Handedness::right, HandAngles{}, Pose::identity(), 0);
  glm::vec3 lo(1e9f), hi(-1e9f);
  for (const auto& v : mesh.vertices) {
    lo = glm::min(lo, v.position);
    hi = glm::max(hi, v.position);
  }
  for (Finger f : {Finger::thumb, Finger::index, Finger::middle, Finger::ring, Finger::little}) {
    const glm::vec3 tip = to_glm(rest.joint(tip_of(f)).p);
    EXPECT_TRUE(glm::all(glm::greaterThan(tip, lo)) && glm::all(glm::lessThan(tip, hi))) << to_string(tip_of(f));
  }
  // Right hand: thumb on the wrist's -X, so the mesh reaches further to -X than the little finger's side... of the palm centre.
  EXPECT_LT(lo.x, to_glm(rest.joint(HandJoint::thumb_tip).p).x);
  // Deterministic.
  const SkinnedMeshData again = generate_hand_mesh(model, Handedness::right);
  ASSERT_EQ(again.vertices.size(), mesh.vertices.size());
  EXPECT_EQ(std::memcmp(again.vertices.data(), mesh.vertices.data(), mesh.vertices.size() * sizeof(SkinnedVertex)), 0);
  EXPECT_EQ(again.indices, mesh.indices);
}

TEST(SkinnedHandMesh, GltfRoundTripKeepsEverything) {
  const SkinnedMeshData mesh = generate_hand_mesh(adult_hand(), Handedness::right);
  const auto file = temp_dir() / "generated_hand.gltf";
  ASSERT_TRUE(save_skinned_gltf(mesh, file));
  auto loaded = load_skinned_gltf(file);
  ASSERT_TRUE(loaded) << loaded.error().message;
  EXPECT_EQ(loaded->name, mesh.name);
  EXPECT_EQ(loaded->joint_names, mesh.joint_names);
  EXPECT_EQ(loaded->indices, mesh.indices);
  ASSERT_EQ(loaded->vertices.size(), mesh.vertices.size());
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    const auto& a = mesh.vertices[i];
    const auto& b = loaded->vertices[i];
    ASSERT_EQ(a.position, b.position) << i;
    ASSERT_LT(glm::length(a.normal - b.normal), 1e-6f) << i;
    for (std::size_t k = 0; k < kMaxInfluences; ++k) {
      if (a.weights[static_cast<glm::length_t>(k)] > 0) {
        ASSERT_EQ(a.joints[k], b.joints[k]) << i;
      }
    }
    ASSERT_LT(glm::length(a.weights - b.weights), 1e-6f) << i;
  }
  ASSERT_EQ(loaded->inverse_bind.size(), mesh.inverse_bind.size());
  for (std::size_t j = 0; j < mesh.inverse_bind.size(); ++j) EXPECT_EQ(loaded->inverse_bind[j], mesh.inverse_bind[j]);
  // Static loading still reads the file (as its bind pose).
  auto as_static = load_gltf(file);
  ASSERT_TRUE(as_static) << as_static.error().message;
  EXPECT_EQ(as_static->vertices.size(), mesh.vertices.size());
}

TEST(SkinnedHandMesh, LoaderErrorsSayWhatIsWrong) {
  const auto dir = temp_dir();
  {
    auto r = load_skinned_gltf(dir / "does_not_exist.gltf");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, Errc::not_found);
  }
  {  // A static mesh has no skin.
    ASSERT_TRUE(save_gltf(primitives::box(glm::vec3(0.1f)), dir / "static_box.gltf"));
    auto r = load_skinned_gltf(dir / "static_box.gltf");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, Errc::parse_error);
    EXPECT_NE(r.error().message.find("no skinned mesh"), std::string::npos) << r.error().message;
  }
  {  // Not glTF at all.
    std::ofstream(dir / "garbage.gltf") << "{ not json";
    auto r = load_skinned_gltf(dir / "garbage.gltf");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, Errc::parse_error);
  }
  // Variations of a valid file.
  SkinnedMeshData small = generate_hand_mesh(adult_hand(), Handedness::right, HandMeshOptions{8, 0.01f, 0.8f});
  const auto good = dir / "small_hand.gltf";
  ASSERT_TRUE(save_skinned_gltf(small, good));
  const nlohmann::json base = read_json(good);
  auto variant = [&](const std::string& name, const std::function<void(nlohmann::json&)>& edit) {
    nlohmann::json j = base;
    edit(j);
    const auto file = dir / (name + ".gltf");
    write_json(j, file);
    return load_skinned_gltf(file);
  };
  {
    auto r = variant("five_influences", [](nlohmann::json& j) {
      j["meshes"][0]["primitives"][0]["attributes"]["JOINTS_1"] = 2;
      j["meshes"][0]["primitives"][0]["attributes"]["WEIGHTS_1"] = 3;
    });
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, Errc::unsupported);
    EXPECT_NE(r.error().message.find("more than 4"), std::string::npos) << r.error().message;
  }
  {
    auto r = variant("weights_past_buffer", [](nlohmann::json& j) { j["accessors"][3]["count"] = 1000000; });
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, Errc::parse_error);
    EXPECT_NE(r.error().message.find("past the end"), std::string::npos) << r.error().message;
  }
  {
    auto r = variant("float_joints", [](nlohmann::json& j) { j["accessors"][2]["componentType"] = 5126; });
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, Errc::unsupported);
    EXPECT_NE(r.error().message.find("JOINTS_0"), std::string::npos) << r.error().message;
  }
  {
    auto r = variant("no_weights", [](nlohmann::json& j) { j["meshes"][0]["primitives"][0]["attributes"].erase("WEIGHTS_0"); });
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, Errc::parse_error);
    EXPECT_NE(r.error().message.find("WEIGHTS_0"), std::string::npos) << r.error().message;
  }
  {
    auto r = variant("no_inverse_bind", [](nlohmann::json& j) { j["skins"][0].erase("inverseBindMatrices"); });
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, Errc::parse_error);
    EXPECT_NE(r.error().message.find("inverseBindMatrices"), std::string::npos) << r.error().message;
  }
  {  // Joints cut to 3: vertices name joints past the skin (and the matrices no longer match).
    auto r = variant("too_few_joints", [](nlohmann::json& j) {
      j["skins"][0]["joints"] = {1, 2, 3};
      j["accessors"][5]["count"] = 3;
    });
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, Errc::parse_error);
    EXPECT_NE(r.error().message.find("but the skin has 3 joints"), std::string::npos) << r.error().message;
  }
}

TEST(SkinnedHandMesh, JointNamesBindToOpenXrJoints) {
  EXPECT_EQ(hand_joint_from_name("index_proximal"), HandJoint::index_proximal);
  EXPECT_EQ(hand_joint_from_name("XR_HAND_JOINT_LITTLE_TIP_EXT"), HandJoint::little_tip);
  EXPECT_EQ(hand_joint_from_name("Wrist"), HandJoint::wrist);
  EXPECT_FALSE(hand_joint_from_name("forearm"));
  EXPECT_FALSE(hand_joint_from_name("XR_HAND_JOINT_EXT"));

  const HandModel model = adult_hand();
  SkinnedMeshData mesh = generate_hand_mesh(model, Handedness::right);
  auto right = HandSkin::bind(mesh);
  ASSERT_TRUE(right) << right.error().message;
  EXPECT_EQ(right->hand(), Handedness::right);
  EXPECT_EQ(right->joint_of(7), HandJoint::index_proximal);
  auto left = HandSkin::bind(generate_hand_mesh(model, Handedness::left));
  ASSERT_TRUE(left);
  EXPECT_EQ(left->hand(), Handedness::left);

  {  // An extra, unweighted joint (an armature root) is fine; OpenXR enumerant names too.
    SkinnedMeshData m = mesh;
    m.joint_names.push_back("Armature");
    m.inverse_bind.emplace_back(1.0f);
    for (auto& n : m.joint_names) {
      if (auto j = hand_joint_from_name(n)) {
        std::string upper(to_string(*j));
        for (char& ch : upper) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
        n = "XR_HAND_JOINT_" + upper + "_EXT";
      }
    }
    auto s = HandSkin::bind(m);
    ASSERT_TRUE(s) << s.error().message;
    EXPECT_FALSE(s->joint_of(26));
  }
  {
    SkinnedMeshData m = mesh;
    m.joint_names[9] = "bone.009";  // index_distal: weighted
    auto s = HandSkin::bind(m);
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message.find("'bone.009'"), std::string::npos) << s.error().message;
  }
  {
    SkinnedMeshData m = mesh;
    m.joint_names[10] = "index_distal";
    auto s = HandSkin::bind(m);
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message.find("both name 'index_distal'"), std::string::npos) << s.error().message;
  }
  {
    SkinnedMeshData m = mesh;
    for (auto& v : m.vertices) {  // move the wrist's weight to the palm, then drop the wrist's name
      for (auto& j : v.joints) {
        if (j == index_of(HandJoint::wrist)) j = static_cast<std::uint16_t>(index_of(HandJoint::palm));
      }
    }
    m.joint_names[1] = "root";
    auto s = HandSkin::bind(m);
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message.find("'wrist'"), std::string::npos) << s.error().message;
  }
}

TEST(SkinningMath, RestPoseReproducesTheBindPose) {
  const HandModel model = adult_hand();
  const SkinnedMeshData mesh = generate_hand_mesh(model, Handedness::right);
  auto skin = HandSkin::bind(mesh);
  ASSERT_TRUE(skin);
  const Pose T_world_wrist{Quat(Eigen::AngleAxisd(0.7, Vec3(0.3, 1, -0.2).normalized())), Vec3(0.1, 1.2, -0.4)};
  const glm::mat4 T = to_glm(T_world_wrist);
  const auto out = skinned(mesh, *skin, model.forward(Handedness::right, HandAngles{}, T_world_wrist, 0));
  float worst = 0, worst_normal = 0;
  for (std::size_t i = 0; i < out.size(); ++i) {
    worst = std::max(worst, glm::length(out[i].position - glm::vec3(T * glm::vec4(mesh.vertices[i].position, 1))));
    worst_normal = std::max(worst_normal, glm::length(out[i].normal - glm::mat3(T) * mesh.vertices[i].normal));
  }
  EXPECT_LT(worst, 2e-6f);  // float rounding at 1.2 m
  EXPECT_LT(worst_normal, 1e-5f);
}

TEST(SkinningMath, FullyWeightedVerticesFollowTheirJointRigidly) {
  const HandModel model = adult_hand();
  const SkinnedMeshData mesh = generate_hand_mesh(model, Handedness::right);
  auto skin = HandSkin::bind(mesh);
  ASSERT_TRUE(skin);
  const Pose T_world_wrist{Quat(Eigen::AngleAxisd(-0.4, Vec3::UnitX())), Vec3(0, 1, -0.3)};
  const HandPose fist = model.forward(Handedness::right, three_poses().fist, T_world_wrist, 0);
  const auto out = skinned(mesh, *skin, fist);
  std::size_t rigid = 0;
  float worst = 0, moved = 0;
  for (std::size_t i = 0; i < out.size(); ++i) {
    const SkinnedVertex& v = mesh.vertices[i];
    if (v.weights[0] != 1.0f) continue;
    ++rigid;
    const std::size_t j = v.joints[0];
    // Where the vertex sits in its joint's frame at bind time, carried by the posed joint.
    const glm::vec3 p_in_joint = glm::vec3(mesh.inverse_bind[j] * glm::vec4(v.position, 1));
    const glm::vec3 expected = to_glm(fist.T_world_joint[j] * from_glm(p_in_joint));
    worst = std::max(worst, glm::length(out[i].position - expected));
    moved = std::max(moved, glm::length(out[i].position - (glm::vec3(to_glm(T_world_wrist) * glm::vec4(v.position, 1)))));
  }
  EXPECT_GT(rigid, mesh.vertices.size() / 3);
  EXPECT_LT(worst, 3e-6f);
  EXPECT_GT(moved, 0.05f);  // the fist moved fingertips by centimetres
  // Blended vertices lie between their joints' rigid positions (no candy-wrapper explosion): within 2 cm of each.
  float worst_blend = 0;
  for (std::size_t i = 0; i < out.size(); ++i) {
    const SkinnedVertex& v = mesh.vertices[i];
    if (v.weights[0] == 1.0f) continue;
    const std::size_t j = v.joints[0];
    const glm::vec3 rigid_j = to_glm(fist.T_world_joint[j] *
                                     from_glm(glm::vec3(mesh.inverse_bind[j] * glm::vec4(v.position, 1))));
    worst_blend = std::max(worst_blend, glm::length(out[i].position - rigid_j));
  }
  EXPECT_LT(worst_blend, 0.02f);
}

TEST(SkinningMath, TheOtherHandIsTheMirrorImage) {
  const HandModel model = adult_hand();
  const SkinnedMeshData mesh = generate_hand_mesh(model, Handedness::right);
  auto skin = HandSkin::bind(mesh);
  ASSERT_TRUE(skin);
  // The left rest pose at the origin: the right mesh mirrored through the wrist's YZ plane.
  const auto out = skinned(mesh, *skin, model.forward(Handedness::left, HandAngles{}, Pose::identity(), 0));
  float worst = 0, worst_normal = 0;
  for (std::size_t i = 0; i < out.size(); ++i) {
    const glm::vec3 m(-1, 1, 1);
    worst = std::max(worst, glm::length(out[i].position - m * mesh.vertices[i].position));
    worst_normal = std::max(worst_normal, glm::length(out[i].normal - m * mesh.vertices[i].normal));
  }
  EXPECT_LT(worst, 1e-6f);
  EXPECT_LT(worst_normal, 1e-5f);
  // And a posed left hand matches the left mesh's own fingertips: each tip vertex pole lands near the left tip joint.
  const HandPose left_fist = model.forward(Handedness::left, three_poses().fist, Pose::identity(), 0);
  const auto fist_out = skinned(mesh, *skin, left_fist);
  for (std::size_t i = 0; i < fist_out.size(); ++i) {
    if (mesh.vertices[i].weights[0] != 1.0f || mesh.vertices[i].joints[0] != index_of(HandJoint::index_distal)) continue;
    EXPECT_LT(glm::length(fist_out[i].position - to_glm(left_fist.joint(HandJoint::index_tip).p)), 0.03f);
  }
}

TEST(SkinningMath, InactiveOrWristlessPosesDrawNothing) {
  const HandModel model = adult_hand();
  const SkinnedMeshData mesh = generate_hand_mesh(model, Handedness::right, HandMeshOptions{8, 0.01f, 0.8f});
  auto skin = HandSkin::bind(mesh);
  ASSERT_TRUE(skin);
  SkinnedHand hand;
  hand.mesh = 3;
  hand.skin = *skin;
  HandPose pose = model.forward(Handedness::right, HandAngles{}, Pose::identity(), 0);
  DrawList draws;
  append_skinned_hand(draws, pose, hand, glm::vec4(1));
  EXPECT_EQ(draws.skinned.size(), 1u);
  EXPECT_EQ(draws.skin_matrices.size(), kHandJointCount);
  draws.clear();
  pose.active = false;
  append_skinned_hand(draws, pose, hand, glm::vec4(1));
  EXPECT_TRUE(draws.skinned.empty());
  EXPECT_TRUE(draws.skin_matrices.empty());
  pose.active = true;
  pose.flags[index_of(HandJoint::wrist)] = 0;
  append_skinned_hand(draws, pose, hand, glm::vec4(1));
  EXPECT_TRUE(draws.skinned.empty());
  // A missing finger joint follows its parent.
  pose.flags[index_of(HandJoint::wrist)] = kJointFullyTracked;
  pose.flags[index_of(HandJoint::index_distal)] = 0;
  std::vector<glm::mat4> m(skin->joint_count());
  ASSERT_TRUE(skin->skin_matrices(pose, m));
  EXPECT_EQ(m[index_of(HandJoint::index_distal)], m[index_of(HandJoint::index_intermediate)]);
}

TEST_F(RenderTest, SkinnedDrawErrorsAreErrorsNotCrashes) {
  const SkinnedMeshData mesh = generate_hand_mesh(adult_hand(), Handedness::right, HandMeshOptions{8, 0.01f, 0.8f});
  auto hand = SkinnedHand::upload(*renderer_, mesh);
  ASSERT_TRUE(hand) << hand.error().message;
  auto target = OffscreenTarget::create(*renderer_, 32, 32, 1);
  ASSERT_TRUE(target);
  const View view{look_at(Vec3(0, 0, 0.3), Vec3(0, 0, 0)), symmetric_fov(glm::radians(45.0f), 1.0f)};
  DrawList draws;
  draws.items.push_back({hand->mesh, glm::mat4(1.0f), glm::vec4(1)});
  auto s = renderer_->render(draws, std::span(&view, 1), (*target)->views());
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("DrawList::skinned"), std::string::npos) << s.error().message;
  draws.clear();
  draws.skinned.push_back({unit_.sphere, 0, glm::vec4(1)});
  s = renderer_->render(draws, std::span(&view, 1), (*target)->views());
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("not a skinned mesh"), std::string::npos) << s.error().message;
  draws.clear();
  draws.skinned.push_back({hand->mesh, 0, glm::vec4(1)});
  draws.skin_matrices.resize(5);
  s = renderer_->render(draws, std::span(&view, 1), (*target)->views());
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("skin matrices"), std::string::npos) << s.error().message;
  SkinnedMeshData broken = mesh;
  broken.vertices[0].weights = glm::vec4(0.5f, 0, 0, 0);
  EXPECT_FALSE(renderer_->upload_skinned(broken));
}

// A deforming surface: the caller's vertices are drawn where it puts them,
// frame after frame, and a draw past the posed vertices is an error.
TEST_F(RenderTest, DeformingMeshDrawsTheCallersVertices) {
  MeshData quad;
  quad.name = "sheet";
  quad.vertices = {{{-0.05f, -0.05f, 0}, {0, 0, 1}}, {{0.05f, -0.05f, 0}, {0, 0, 1}},
                   {{0.05f, 0.05f, 0}, {0, 0, 1}},   {{-0.05f, 0.05f, 0}, {0, 0, 1}}};
  quad.indices = {0, 1, 2, 0, 2, 3};
  auto mesh = renderer_->upload_deforming(quad);
  ASSERT_TRUE(mesh) << mesh.error().message;
  const View view{look_at(Vec3(0, 0, 0.3), Vec3(0, 0, 0)), symmetric_fov(glm::radians(45.0f), 1.0f)};
  auto lit_pixels_left_and_right = [&](float shift_m) {
    DrawList draws;
    SkinnedDrawItem item{*mesh, 0, glm::vec4(1)};
    item.first_posed_vertex = 0;
    draws.skinned.push_back(item);
    for (auto v : quad.vertices) {
      v.position.x += shift_m;
      draws.posed_vertices.push_back(v);
    }
    const auto images = render_views(draws, std::span(&view, 1), 64, 64);
    int left = 0, right = 0;
    for (std::uint32_t y = 0; y < 64; ++y) {
      for (std::uint32_t x = 0; x < 64; ++x) {
        if (images[0].at(x, y)[0] > 100) ++(x < 32 ? left : right);
      }
    }
    return std::pair(left, right);
  };
  const auto [l0, r0] = lit_pixels_left_and_right(-0.06f);
  const auto [l1, r1] = lit_pixels_left_and_right(+0.06f);
  EXPECT_GT(l0, 100);
  EXPECT_EQ(r0, 0);
  EXPECT_EQ(l1, 0);
  EXPECT_GT(r1, 100);

  auto target = OffscreenTarget::create(*renderer_, 16, 16, 1);
  ASSERT_TRUE(target);
  DrawList short_list;
  SkinnedDrawItem item{*mesh, 0, glm::vec4(1)};
  item.first_posed_vertex = 1;  // needs vertices 1-4, the list has 4
  short_list.skinned.push_back(item);
  short_list.posed_vertices = quad.vertices;
  auto s = renderer_->render(short_list, std::span(&view, 1), (*target)->views());
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("posed vertices"), std::string::npos) << s.error().message;
}

// The generated right hand drawn in three poses (open, fist, pointing) for
// each side, tiled as the joint-sphere golden: left hands (mirrored) on top,
// right below, seen from the back of the hand, fingers up: the right thumb
// is on the image's left, the left thumb on its right.
TEST_F(RenderTest, SkinnedHandsInThreePosesMatchGolden) {
  const HandModel model = adult_hand();
  auto hand = SkinnedHand::upload(*renderer_, generate_hand_mesh(model, Handedness::right));
  ASSERT_TRUE(hand) << hand.error().message;
  const ThreePoses poses = three_poses();
  Mat3 R;
  R.col(0) = Vec3(1, 0, 0);
  R.col(1) = Vec3(0, 0, 1);
  R.col(2) = Vec3(0, -1, 0);
  const Pose T_world_wrist{Quat(R), Vec3(0, 0, 0)};
  const View view{look_at(Vec3(0.05, 0.1, 0.33), Vec3(0, 0.095, 0)), symmetric_fov(glm::radians(45.0f), 1.0f)};

  constexpr std::uint32_t kTile = 160;
  ImageRGBA8 sheet{3 * kTile, 2 * kTile, std::vector<std::uint8_t>(std::size_t{6} * kTile * kTile * 4)};
  int row = 0;
  for (Handedness side : {Handedness::left, Handedness::right}) {
    int col = 0;
    for (const HandAngles* angles : {&poses.open, &poses.fist, &poses.point}) {
      DrawList draws;
      const HandPose pose = model.forward(side, *angles, T_world_wrist, 0);
      append_skinned_hand(draws, pose, *hand, skin_color_for(side));
      ASSERT_EQ(draws.skinned.size(), 1u);
      // The wrist triad shows the joint conventions as in the joint-sphere golden.
      append_axes(draws, pose.joint(HandJoint::wrist), unit_, 0.05f, 0.002f);
      const auto images = render_views(draws, std::span(&view, 1), kTile, kTile);
      ASSERT_EQ(images.size(), 1u);
      for (std::uint32_t y = 0; y < kTile; ++y) {
        std::memcpy(sheet.at(static_cast<std::uint32_t>(col) * kTile, static_cast<std::uint32_t>(row) * kTile + y),
                    images[0].at(0, y), kTile * 4);
      }
      ++col;
    }
    ++row;
  }
  EXPECT_GT(renderer_->stats().skinned_vertices_last_frame, 1500u);
  expect_matches_golden(sheet, "skinned_hands_three_poses");
}

}  // namespace skinned_hand_tests
}  // namespace proprio::render
