// Scene files and presets: what the engine draws and simulates.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "proprio/engine/scene.hpp"

namespace proprio::engine {
namespace {

TEST(EngineScene, PresetsMatchTheHapticScenes) {
  auto half = Scene::preset("half-cylinder");
  ASSERT_TRUE(half) << half.error().message;
  ASSERT_EQ(half->entities.size(), 1u);
  const auto& c = half->entities[0].body;
  EXPECT_EQ(c.shape, haptics::ShapeKind::half_cylinder);
  EXPECT_DOUBLE_EQ(c.radius_m, 0.25);  // Lee 2021: radius 25 cm, length 50 cm
  EXPECT_DOUBLE_EQ(c.half_length_m, 0.25);
  // The focus is the top of the curve, where the scripted finger lands.
  EXPECT_NEAR(half->p_focus_in_world.y(), c.T_world_object.p.y() + 0.25, 1e-12);
  auto peg = Scene::preset("peg-in-hole");
  ASSERT_TRUE(peg);
  const Entity* p = peg->find("peg");
  ASSERT_NE(p, nullptr);
  EXPECT_EQ(p->physics, Physics::free);
  EXPECT_TRUE(p->peg_visual);
  EXPECT_EQ(peg->haptic_scene().objects.size(), peg->entities.size());
  EXPECT_FALSE(Scene::preset("nope"));
}

TEST(EngineScene, ParsesAFileOnTopOfAPreset) {
  auto s = Scene::parse(R"(
name = "cups"
preset = "table"
floor_height = 0.0
focus = [0.1, 1.0, -0.5]
[[object]]
name = "cup"
shape = "cylinder"
radius = 0.04
half_length = 0.05
position = [0.1, 1.05, -0.5]
rotation_deg = [-90, 0, 0]
color = [0.9, 0.2, 0.2]
physics = "free"
mass = 0.2
[[object]]
name = "marker"
shape = "sphere"
radius = 0.01
physics = "none"
)",
                        "cups.toml");
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_EQ(s->name, "cups");
  ASSERT_EQ(s->entities.size(), 3u);  // table + cup + marker
  const Entity* cup = s->find("cup");
  ASSERT_NE(cup, nullptr);
  EXPECT_EQ(cup->physics, Physics::free);
  EXPECT_FALSE(cup->body.fixed);
  EXPECT_DOUBLE_EQ(cup->body.mass_kg, 0.2);
  EXPECT_FLOAT_EQ(cup->body.rgba[0], 0.9f);
  // -90 deg about x: the cylinder's axis (object z) points up (world +y).
  EXPECT_TRUE((cup->body.T_world_object.q * Vec3::UnitZ()).isApprox(Vec3::UnitY(), 1e-9));
  // Drawn-only objects are not simulated.
  EXPECT_EQ(s->haptic_scene().objects.size(), 2u);
  ASSERT_TRUE(s->floor_height_m);
}

TEST(EngineScene, BadFilesNameTheProblem) {
  struct Case {
    const char* toml;
    const char* expect;
  };
  const Case cases[] = {
      {"[[object]]\nname = \"a\"\nshape = \"donut\"\n", "donut"},
      {"[[object]]\nname = \"a\"\nshape = \"sphere\"\ncolor = [2, 0, 0]\n", "[0, 1]"},
      {"[[object]]\nname = \"a\"\nshape = \"sphere\"\nposition = [1, 2]\n", "3 numbers"},
      {"[[object]]\nname = \"a\"\nshape = \"sphere\"\n[[object]]\nname = \"a\"\nshape = \"box\"\n", "two objects"},
      {"[[object]]\nname = \"a\"\nshape = \"gltf\"\nfile = \"x.gltf\"\nphysics = \"fixed\"\n", "drawn only"},
      {"[[object]]\nname = \"a\"\nshape = \"sphere\"\nphysics = \"floating\"\n", "floating"},
      {"preset = \"moon\"\n", "moon"},
      {"[[object]]\nshape = \"sphere\"\n", "name"},
      {"this is = = not toml", "scene.toml"},
  };
  for (const auto& c : cases) {
    auto s = Scene::parse(c.toml, "scene.toml");
    ASSERT_FALSE(s) << c.toml;
    EXPECT_NE(s.error().message.find(c.expect), std::string::npos) << s.error().message;
  }
}

TEST(EngineScene, LoadsFilesAndReportsMissingOnes) {
  const auto dir = std::filesystem::temp_directory_path() / "proprio_engine_scene";
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "s.toml") << "preset = \"half-cylinder\"\nname = \"mine\"\n";
  auto s = Scene::load((dir / "s.toml").string());
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_EQ(s->name, "mine");
  auto missing = Scene::load((dir / "missing.toml").string());
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, Errc::not_found);
  EXPECT_TRUE(Scene::load("peg-in-hole"));
}

}  // namespace
}  // namespace proprio::engine
