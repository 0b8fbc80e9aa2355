// The renderer's CPU side: primitive meshes (closed, outward, the right
// volume), projection conventions, image comparison and glTF files.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "proprio/render/camera.hpp"
#include "proprio/render/image.hpp"
#include "proprio/render/mesh.hpp"

namespace proprio::render {
namespace {

constexpr double kPi = 3.14159265358979;

// Signed volume by the divergence theorem: positive only if every triangle
// faces outwards, and equal to the solid's volume only if the mesh is closed.
double signed_volume(const MeshData& m) {
  double v = 0;
  for (std::size_t i = 0; i + 2 < m.indices.size(); i += 3) {
    const glm::dvec3 a = m.vertices[m.indices[i]].position, b = m.vertices[m.indices[i + 1]].position,
                     c = m.vertices[m.indices[i + 2]].position;
    v += glm::dot(a, glm::cross(b, c)) / 6.0;
  }
  return v;
}

// Every vertex normal points away from the solid: checked against the
// direction from the centroid of the face it belongs to, for convex shapes.
int normals_pointing_inwards(const MeshData& m, const glm::vec3& centre) {
  int bad = 0;
  for (const auto& v : m.vertices) {
    if (glm::dot(v.normal, v.position - centre) < -1e-5f) ++bad;
  }
  return bad;
}

TEST(Primitives, VolumesMatchTheSolidsAndFacesPointOutwards) {
  struct Case {
    MeshData mesh;
    double volume;
    double tolerance;  // relative: polygonal approximations are a bit small
  };
  const double r = 0.05, h = 0.08;
  const Case cases[] = {
      {primitives::sphere(0.05f, 64, 32), 4.0 / 3.0 * kPi * r * r * r, 0.01},
      {primitives::box(glm::vec3(0.1f, 0.2f, 0.3f)), 8 * 0.1 * 0.2 * 0.3, 1e-5},
      {primitives::cylinder(0.05f, 0.08f, 64), kPi * r * r * 2 * h, 0.01},
      {primitives::half_cylinder(0.05f, 0.08f, 64), 0.5 * kPi * r * r * 2 * h, 0.01},
      {primitives::capsule(0.05f, 0.08f, 64, 16), kPi * r * r * 2 * h + 4.0 / 3.0 * kPi * r * r * r, 0.01},
      {primitives::plate_with_hole(0.03f, glm::vec3(0.06f, 0.05f, 0.01f), 96),
       (4 * 0.06 * 0.05 - kPi * 0.03 * 0.03) * 0.02, 0.01},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.mesh.name);
    ASSERT_TRUE(c.mesh.validate());
    EXPECT_NEAR(signed_volume(c.mesh), c.volume, c.volume * c.tolerance);
  }
  EXPECT_EQ(normals_pointing_inwards(primitives::sphere(1.0f), glm::vec3(0)), 0);
  EXPECT_EQ(normals_pointing_inwards(primitives::box(glm::vec3(1.0f)), glm::vec3(0)), 0);
  EXPECT_EQ(normals_pointing_inwards(primitives::cylinder(1.0f, 1.0f), glm::vec3(0)), 0);
}

TEST(Primitives, PegIsAClosedBevelledCylinder) {
  const float radius = 0.02584f, half_length = 0.0931f;
  const MeshData peg = primitives::peg(radius, half_length);
  ASSERT_TRUE(peg.validate());
  const double full = kPi * radius * radius * 2 * half_length;
  EXPECT_GT(signed_volume(peg), 0.95 * full);
  EXPECT_LT(signed_volume(peg), full);
  EXPECT_NEAR(peg.bounds_max().z, half_length, 1e-6);
  EXPECT_NEAR(peg.bounds_max().x, radius, 1e-6);
}

TEST(Primitives, ShapesFollowTheHapticSceneFrames) {
  // Half cylinder: the +y half, flat face at y = 0.
  const MeshData half = primitives::half_cylinder(0.25f, 0.25f);
  EXPECT_NEAR(half.bounds_min().y, 0.0, 1e-6);
  EXPECT_NEAR(half.bounds_max().y, 0.25, 1e-6);
  EXPECT_NEAR(half.bounds_max().z, 0.25, 1e-6);
  // Plate: the hole runs along z, so the centre line is free on both faces.
  const MeshData plate = primitives::plate_with_hole(0.03f, glm::vec3(0.1f, 0.1f, 0.02f));
  EXPECT_NEAR(plate.bounds_max().z, 0.02, 1e-6);
  for (const auto& v : plate.vertices) EXPECT_GE(glm::length(glm::vec2(v.position)), 0.03f - 1e-5f);
}

TEST(Projection, FieldOfViewEdgesMapToTheClipBorders) {
  const Fov fov{-0.6f, 0.4f, 0.5f, -0.3f};
  const glm::mat4 p = projection(fov, 0.1f, 10.0f);
  auto ndc = [&](glm::vec3 eye) {
    const glm::vec4 c = p * glm::vec4(eye, 1.0f);
    return glm::vec3(c) / c.w;
  };
  const float z = -2.0f;  // in front (eyes look along -z)
  EXPECT_NEAR(ndc({std::tan(fov.angle_left) * -z, 0, z}).x, -1.0f, 1e-5f);
  EXPECT_NEAR(ndc({std::tan(fov.angle_right) * -z, 0, z}).x, 1.0f, 1e-5f);
  // Vulkan: up is -1 in y.
  EXPECT_NEAR(ndc({0, std::tan(fov.angle_up) * -z, z}).y, -1.0f, 1e-5f);
  EXPECT_NEAR(ndc({0, std::tan(fov.angle_down) * -z, z}).y, 1.0f, 1e-5f);
  EXPECT_NEAR(ndc({0, 0, -0.1f}).z, 0.0f, 1e-5f);
  EXPECT_NEAR(ndc({0, 0, -10.0f}).z, 1.0f, 1e-5f);
}

TEST(Camera, LookAtPointsTheEyesMinusZAtTheTarget) {
  const Pose T = look_at(Vec3(1, 2, 3), Vec3(1, 2, 0));
  EXPECT_TRUE((T.q * Vec3(0, 0, -1)).isApprox(Vec3(0, 0, -1), 1e-9));
  EXPECT_TRUE((T.q * Vec3(0, 1, 0)).isApprox(Vec3(0, 1, 0), 1e-9));
  const auto eyes = stereo_views(T, 0.064f, Fov{});
  EXPECT_NEAR((eyes[1].T_world_eye.p - eyes[0].T_world_eye.p).norm(), 0.064, 1e-7);  // ipd is a float
  EXPECT_LT(eyes[0].T_world_eye.p.x(), eyes[1].T_world_eye.p.x());  // left eye first
  const glm::mat4 v = view_matrix({T, Fov{}});
  const glm::vec4 target_in_eye = v * glm::vec4(1, 2, 0, 1);
  EXPECT_NEAR(target_in_eye.z, -3.0f, 1e-5f);
}

TEST(Images, CompareCountsDifferencesAndRejectsSizeMismatch) {
  ImageRGBA8 a{4, 2, std::vector<std::uint8_t>(32, 100)};
  ImageRGBA8 b = a;
  auto same = compare_images(a, b);
  ASSERT_TRUE(same);
  EXPECT_EQ(same->max, 0);
  b.at(1, 1)[2] = 160;
  auto diff = compare_images(a, b, 16);
  ASSERT_TRUE(diff);
  EXPECT_EQ(diff->max, 60);
  EXPECT_NEAR(diff->mean, 60.0 / 8, 1e-12);
  EXPECT_NEAR(diff->fraction_over_threshold, 1.0 / 8, 1e-12);
  EXPECT_FALSE(compare_images(a, ImageRGBA8{2, 2, std::vector<std::uint8_t>(16)}));
}

TEST(Images, PngRoundTripAndErrors) {
  const auto dir = std::filesystem::temp_directory_path() / "proprio_render_png";
  std::filesystem::create_directories(dir);
  ImageRGBA8 img{3, 2, {}};
  for (int i = 0; i < 24; ++i) img.pixels.push_back(static_cast<std::uint8_t>(i * 10));
  ASSERT_TRUE(write_png(img, dir / "a.png"));
  auto back = read_png(dir / "a.png");
  ASSERT_TRUE(back) << back.error().message;
  EXPECT_EQ(back->pixels, img.pixels);
  auto missing = read_png(dir / "missing.png");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, Errc::not_found);
  std::ofstream(dir / "broken.png") << "not a png";
  auto broken = read_png(dir / "broken.png");
  ASSERT_FALSE(broken);
  EXPECT_EQ(broken.error().code, Errc::parse_error);
  EXPECT_FALSE(write_png(ImageRGBA8{3, 2, {}}, dir / "b.png"));
}

TEST(Gltf, RoundTripKeepsTheMesh) {
  const auto dir = std::filesystem::temp_directory_path() / "proprio_render_gltf";
  std::filesystem::create_directories(dir);
  const MeshData capsule = primitives::capsule(0.02f, 0.03f);
  ASSERT_TRUE(save_gltf(capsule, dir / "capsule.gltf"));
  auto loaded = load_gltf(dir / "capsule.gltf");
  ASSERT_TRUE(loaded) << loaded.error().message;
  EXPECT_EQ(loaded->vertices.size(), capsule.vertices.size());
  EXPECT_EQ(loaded->indices, capsule.indices);
  EXPECT_NEAR(signed_volume(*loaded), signed_volume(capsule), 1e-12);
}

TEST(Gltf, BrokenFilesGiveClearErrors) {
  const auto dir = std::filesystem::temp_directory_path() / "proprio_render_gltf";
  std::filesystem::create_directories(dir);
  auto missing = load_gltf(dir / "nope.gltf");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, Errc::not_found);
  std::ofstream(dir / "garbage.gltf") << "{ this is not json";
  auto garbage = load_gltf(dir / "garbage.gltf");
  ASSERT_FALSE(garbage);
  EXPECT_EQ(garbage.error().code, Errc::parse_error);
  EXPECT_NE(garbage.error().message.find("garbage.gltf"), std::string::npos);
  // Valid JSON, but an index past the vertices.
  std::ofstream(dir / "bad_index.gltf")
      << R"({"asset":{"version":"2.0"},"buffers":[{"byteLength":40,"uri":"data:application/octet-stream;base64,)"
      << R"(AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAAAAAUAAAA="}],)"
      << R"("bufferViews":[{"buffer":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":4}],)"
      << R"("accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},)"
      << R"({"bufferView":1,"componentType":5125,"count":1,"type":"SCALAR"}],)"
      << R"("meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],"nodes":[{"mesh":0}],)"
      << R"("scenes":[{"nodes":[0]}]})";
  auto bad = load_gltf(dir / "bad_index.gltf");
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().code, Errc::parse_error);
}

}  // namespace
}  // namespace proprio::render
