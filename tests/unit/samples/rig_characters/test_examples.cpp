// The example characters: valid, sized like the animals they stand for, with
// distinct grounded sample poses that keep every bone's length, a closed
// outward skin whose area splits over the nodes, and a glTF round trip.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "proprio/rig_characters/examples.hpp"
#include "support/temp_dir.hpp"

namespace proprio::rig_characters {
namespace {

using render::Character;
using testing_support::TempDir;

struct Expected {
  std::string name;
  std::size_t min_bones, max_bones, min_poses, max_poses;
  double min_height_m, max_height_m;  // of the skeleton's nodes at rest
};

class ExampleCharacter : public ::testing::TestWithParam<Expected> {};

std::vector<Vec3> positions(const Character& c, const SkeletonPose& pose) {
  std::vector<Pose> T;
  forward_kinematics(c.skeleton, pose, T);
  std::vector<Vec3> out;
  for (const Pose& t : T) out.push_back(t.p);
  return out;
}

TEST(ExampleCharacters, NamesAreKnownAndUnknownNamesAreRefused) {
  const auto names = example_character_names();
  EXPECT_EQ(names.size(), 3u);
  for (const auto& n : names) EXPECT_TRUE(make_example_character(n)) << n;
  auto bad = make_example_character("unicorn");
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().code, Errc::not_found);
}

TEST_P(ExampleCharacter, IsValidAndSizedLikeItsAnimal) {
  const Expected e = GetParam();
  auto c = make_example_character(e.name);
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_TRUE(c->validate());
  EXPECT_EQ(c->name, e.name);
  EXPECT_GE(c->skeleton.size(), e.min_bones);
  EXPECT_LE(c->skeleton.size(), e.max_bones);
  EXPECT_GE(c->sample_poses.size(), e.min_poses);
  EXPECT_LE(c->sample_poses.size(), e.max_poses);
  EXPECT_EQ(std::set<std::string>(c->sample_names.begin(), c->sample_names.end()).size(), c->sample_names.size());
  const auto p = positions(*c, rest_pose(c->skeleton));
  double top = -1e9, bottom = 1e9;
  for (const Vec3& x : p) {
    top = std::max(top, x.y());
    bottom = std::min(bottom, x.y());
  }
  EXPECT_GE(top, e.min_height_m);
  EXPECT_LE(top, e.max_height_m);
  EXPECT_GE(bottom, 0.0);
  EXPECT_LT(bottom, 0.3);  // the lowest joints (ankles) near the ground
  // Every skeleton node drives skin (its weight in rig reduction).
  EXPECT_EQ(c->mesh_joint_node.size(), c->skeleton.size());
}

TEST_P(ExampleCharacter, PosesAreDistinctKeepBoneLengthsAndStayAboveGround) {
  auto c = make_example_character(GetParam().name);
  ASSERT_TRUE(c) << c.error().message;
  const Skeleton& s = c->skeleton;
  const auto rest = positions(*c, rest_pose(s));
  double rest_low = 1e9;
  for (const Vec3& x : rest) rest_low = std::min(rest_low, x.y());
  std::vector<std::vector<Vec3>> posed;
  for (std::size_t k = 0; k < c->sample_poses.size(); ++k) {
    const std::string& name = c->sample_names[k];
    ASSERT_TRUE(validate_pose(s, c->sample_poses[k])) << name;
    const auto x = positions(*c, c->sample_poses[k]);
    double moved = 0.0, low = 1e9;
    for (std::size_t i = 0; i < s.size(); ++i) {
      if (s.parent[i] >= 0) {
        const double length = (x[i] - x[static_cast<std::size_t>(s.parent[i])]).norm();
        EXPECT_NEAR(length, s.t_parent_node_m[i].norm(), 1e-9) << name << " " << s.names[i];
      }
      moved = std::max(moved, (x[i] - rest[i]).norm());
      low = std::min(low, x[i].y());
    }
    EXPECT_GT(moved, 0.05) << name << " is the rest pose";
    // Standing poses keep the body on the ground; flying ones lift it.
    EXPECT_GT(low, -0.05) << name << " sinks into the ground";
    if (name.rfind("fly", 0) != 0 && name != "glide") {
      EXPECT_LT(low, rest_low + 0.3) << name << " floats";
    }
    // No node flies off: the whole body stays within a few body lengths.
    for (std::size_t i = 0; i < s.size(); ++i) EXPECT_LT((x[i] - rest[i]).norm(), 6.0) << name << " " << s.names[i];
    posed.push_back(x);
  }
  for (std::size_t a = 0; a < posed.size(); ++a) {
    for (std::size_t b = a + 1; b < posed.size(); ++b) {
      double d = 0.0;
      for (std::size_t i = 0; i < s.size(); ++i) d = std::max(d, (posed[a][i] - posed[b][i]).norm());
      EXPECT_GT(d, 0.02) << c->sample_names[a] << " and " << c->sample_names[b] << " are the same pose";
    }
  }
}

TEST_P(ExampleCharacter, SkinIsClosedOutwardAndItsAreaSplitsOverTheNodes) {
  auto c = make_example_character(GetParam().name);
  ASSERT_TRUE(c) << c.error().message;
  const auto& m = c->mesh;
  double area = 0.0, volume = 0.0;
  for (std::size_t t = 0; t < m.indices.size(); t += 3) {
    const glm::dvec3 a(m.vertices[m.indices[t]].position), b(m.vertices[m.indices[t + 1]].position),
        d(m.vertices[m.indices[t + 2]].position);
    area += 0.5 * glm::length(glm::cross(b - a, d - a));
    volume += glm::dot(a, glm::cross(b, d)) / 6.0;
  }
  EXPECT_GT(volume, 0.0);  // counter-clockwise seen from outside, as glTF expects
  const auto per_node = skin_area_per_node_m2(*c);
  ASSERT_EQ(per_node.size(), c->skeleton.size());
  double sum = 0.0;
  for (std::size_t i = 0; i < per_node.size(); ++i) {
    EXPECT_GT(per_node[i], 0.0) << c->skeleton.names[i];
    sum += per_node[i];
  }
  EXPECT_NEAR(sum, area, 1e-7 * area);  // summed in another order
  // The torso covers more skin than a finger-sized end bone.
  const auto largest = std::max_element(per_node.begin(), per_node.end()) - per_node.begin();
  const auto smallest = std::min_element(per_node.begin(), per_node.end()) - per_node.begin();
  EXPECT_GT(per_node[static_cast<std::size_t>(largest)], 5.0 * per_node[static_cast<std::size_t>(smallest)]);
  // The vertex normals agree with the winding (shading and culling match).
  double agreement = 0.0;
  for (std::size_t t = 0; t < m.indices.size(); t += 3) {
    const glm::vec3 a = m.vertices[m.indices[t]].position, b = m.vertices[m.indices[t + 1]].position,
                    d = m.vertices[m.indices[t + 2]].position;
    const glm::vec3 face = glm::cross(b - a, d - a);
    const glm::vec3 n =
        m.vertices[m.indices[t]].normal + m.vertices[m.indices[t + 1]].normal + m.vertices[m.indices[t + 2]].normal;
    agreement += glm::dot(face, n) > 0.0f ? 1.0 : 0.0;
  }
  EXPECT_GT(agreement / (m.indices.size() / 3.0), 0.99);
}

TEST_P(ExampleCharacter, SkinnedPosesMoveTheSurfaceWithTheBones) {
  auto c = make_example_character(GetParam().name);
  ASSERT_TRUE(c) << c.error().message;
  std::vector<Pose> T;
  std::vector<glm::mat4> skin;
  std::vector<render::Vertex> out;
  forward_kinematics(c->skeleton, rest_pose(c->skeleton), T);
  render::skin_character(*c, T, skin, out);
  for (std::size_t i = 0; i < out.size(); ++i) {
    ASSERT_LT(glm::length(out[i].position - c->mesh.vertices[i].position), 1e-4f) << i;
  }
  // A vertex fully weighted to one node keeps its distance to that node.
  const auto rest = positions(*c, rest_pose(c->skeleton));
  for (const SkeletonPose& pose : c->sample_poses) {
    forward_kinematics(c->skeleton, pose, T);
    render::skin_character(*c, T, skin, out);
    for (std::size_t i = 0; i < out.size(); i += 7) {
      const auto& v = c->mesh.vertices[i];
      if (v.weights[0] < 0.9999f) continue;
      const auto node = static_cast<std::size_t>(c->mesh_joint_node[v.joints[0]]);
      const double before = (Vec3(v.position.x, v.position.y, v.position.z) - rest[node]).norm();
      const double after = (Vec3(out[i].position.x, out[i].position.y, out[i].position.z) - T[node].p).norm();
      EXPECT_NEAR(before, after, 1e-4);
    }
  }
}

TEST_P(ExampleCharacter, SurvivesAGltfRoundTrip) {
  auto c = make_example_character(GetParam().name);
  ASSERT_TRUE(c) << c.error().message;
  TempDir dir;
  const auto file = dir / (GetParam().name + ".gltf");
  ASSERT_TRUE(render::save_character_gltf(*c, file));
  auto back = render::load_character_gltf(file);
  ASSERT_TRUE(back) << back.error().message;
  EXPECT_EQ(back->name, c->name);
  EXPECT_EQ(back->skeleton.names, c->skeleton.names);
  EXPECT_EQ(back->skeleton.parent, c->skeleton.parent);
  for (std::size_t i = 0; i < c->skeleton.size(); ++i) {
    EXPECT_LT((back->skeleton.t_parent_node_m[i] - c->skeleton.t_parent_node_m[i]).norm(), 1e-9);
    EXPECT_LT(angle_between(back->skeleton.q_parent_node_rest[i], c->skeleton.q_parent_node_rest[i]), 1e-9);
  }
  EXPECT_EQ(back->sample_names, c->sample_names);
  ASSERT_EQ(back->sample_poses.size(), c->sample_poses.size());
  for (std::size_t k = 0; k < c->sample_poses.size(); ++k) {
    double worst = 0.0;
    for (std::size_t i = 0; i < c->skeleton.size(); ++i) {
      worst =
          std::max(worst, angle_between(back->sample_poses[k].q_parent_node[i], c->sample_poses[k].q_parent_node[i]));
    }
    EXPECT_LT(worst, 1e-5) << c->sample_names[k];
    EXPECT_LT((back->sample_poses[k].t_world_root_m - c->sample_poses[k].t_world_root_m).norm(), 1e-5);
  }
  EXPECT_EQ(back->mesh_joint_node, c->mesh_joint_node);
  EXPECT_EQ(back->mesh.joint_names, c->mesh.joint_names);
  EXPECT_EQ(back->mesh.indices, c->mesh.indices);
  ASSERT_EQ(back->mesh.vertices.size(), c->mesh.vertices.size());
  for (std::size_t i = 0; i < c->mesh.vertices.size(); ++i) {
    EXPECT_EQ(back->mesh.vertices[i].position, c->mesh.vertices[i].position);
    EXPECT_EQ(back->mesh.vertices[i].joints, c->mesh.vertices[i].joints);
    EXPECT_LT(glm::length(back->mesh.vertices[i].weights - c->mesh.vertices[i].weights), 1e-6f);
  }
  for (std::size_t j = 0; j < c->mesh.inverse_bind.size(); ++j) {
    EXPECT_EQ(back->mesh.inverse_bind[j], c->mesh.inverse_bind[j]);
  }
  const auto a = render::skin_area_per_node_m2(*c), b = render::skin_area_per_node_m2(*back);
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], b[i], 1e-6 * a[i]);
}

TEST_P(ExampleCharacter, IsDeterministic) {
  auto a = make_example_character(GetParam().name);
  auto b = make_example_character(GetParam().name);
  ASSERT_TRUE(a && b);
  ASSERT_EQ(a->mesh.vertices.size(), b->mesh.vertices.size());
  for (std::size_t i = 0; i < a->mesh.vertices.size(); ++i) {
    ASSERT_EQ(a->mesh.vertices[i].position, b->mesh.vertices[i].position);
  }
  for (std::size_t k = 0; k < a->sample_poses.size(); ++k) {
    for (std::size_t i = 0; i < a->skeleton.size(); ++i) {
      ASSERT_EQ(a->sample_poses[k].q_parent_node[i].coeffs(), b->sample_poses[k].q_parent_node[i].coeffs());
    }
  }
}

INSTANTIATE_TEST_SUITE_P(All, ExampleCharacter,
                         ::testing::Values(Expected{"humanoid", 20, 25, 6, 10, 1.4, 1.8},
                                           Expected{"quadruped", 27, 33, 10, 14, 1.3, 2.0},
                                           Expected{"creature", 90, 110, 12, 12, 1.5, 3.5}),
                         [](const auto& test) { return test.param.name; });

}  // namespace
}  // namespace proprio::rig_characters
