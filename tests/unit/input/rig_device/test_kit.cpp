#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "proprio/rig_device/kit.hpp"

namespace proprio::rig_device {
namespace {

std::string with_outlets(const std::string& splitter_head, int outlets) {
  std::string s = splitter_head;
  for (int i = 0; i < outlets; ++i) s += "[[splitter.outlet]]\ntilt_deg = 90\nazimuth_deg = " + std::to_string(i * 40) + "\n";
  return s;
}

TEST(Kit, DefaultIsTheThesisKitAndValid) {
  const Kit kit = default_kit();
  ASSERT_TRUE(kit.validate().ok()) << kit.validate().error().message;
  EXPECT_EQ(kit.joint_count, 18);
  EXPECT_EQ(kit.total_splitters(), 7);
  for (const SplitterKind& s : kit.splitter_kinds) {
    EXPECT_GE(s.valence(), 2u);
    // Outlets are distinct directions.
    for (std::size_t i = 0; i < s.valence(); ++i) {
      for (std::size_t j = i + 1; j < s.valence(); ++j) {
        const Vec3 di = s.q_inlet_outlet[i] * Vec3::UnitZ(), dj = s.q_inlet_outlet[j] * Vec3::UnitZ();
        EXPECT_LT(di.dot(dj), 0.99) << s.name;
      }
    }
  }
  const std::string d = kit.describe();
  EXPECT_NE(d.find("18 x joint"), std::string::npos) << d;
  EXPECT_NE(d.find("T3"), std::string::npos) << d;
}

TEST(Kit, OutletAnglesRoundTrip) {
  for (double az : {-170.0, -45.0, 0.0, 30.0, 120.0, 179.0}) {
    for (double tilt : {5.0, 30.0, 90.0, 135.0, 175.0}) {
      for (double roll : {-90.0, 0.0, 20.0, 170.0}) {
        const Quat q = outlet_rotation({az, tilt, roll});
        const OutletAngles a = outlet_angles_for(q);
        EXPECT_NEAR(a.tilt_deg, tilt, 1e-9);
        EXPECT_LT(outlet_rotation(a).angularDistance(q), 1e-9) << az << " " << tilt << " " << roll;
        // The shaft points where spherical coordinates say.
        const Vec3 d = q * Vec3::UnitZ();
        const double t = tilt * M_PI / 180.0, p = az * M_PI / 180.0;
        EXPECT_LT((d - Vec3(std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t))).norm(), 1e-12);
      }
    }
  }
  // Degenerate tilts: the rotation survives even if the split into angles does not.
  for (double tilt : {0.0, 180.0}) {
    const Quat q = outlet_rotation({40.0, tilt, 15.0});
    EXPECT_LT(outlet_rotation(outlet_angles_for(q)).angularDistance(q), 1e-9) << tilt;
  }
}

TEST(Kit, TomlRoundTrip) {
  const Kit kit = default_kit();
  const std::string text = kit_to_toml(kit);
  auto back = parse_kit_toml(text, "default.toml");
  ASSERT_TRUE(back.ok()) << back.error().message << "\n" << text;
  EXPECT_EQ(back->joint_count, kit.joint_count);
  EXPECT_EQ(back->joint.name, kit.joint.name);
  EXPECT_NEAR(back->joint.bend_limit_rad, kit.joint.bend_limit_rad, 1e-12);
  EXPECT_NEAR(back->joint.length_in_m, kit.joint.length_in_m, 1e-15);
  EXPECT_EQ(back->joint.twist_rings, kit.joint.twist_rings);
  ASSERT_EQ(back->splitter_kinds.size(), kit.splitter_kinds.size());
  EXPECT_EQ(back->splitter_counts, kit.splitter_counts);
  for (std::size_t k = 0; k < kit.splitter_kinds.size(); ++k) {
    EXPECT_EQ(back->splitter_kinds[k].name, kit.splitter_kinds[k].name);
    ASSERT_EQ(back->splitter_kinds[k].valence(), kit.splitter_kinds[k].valence());
    for (std::size_t i = 0; i < kit.splitter_kinds[k].valence(); ++i) {
      EXPECT_LT(back->splitter_kinds[k].q_inlet_outlet[i].angularDistance(kit.splitter_kinds[k].q_inlet_outlet[i]),
                1e-12);
    }
  }
  // Names with TOML's special characters survive.
  Kit odd = kit;
  odd.splitter_kinds[0].name = "Y \"fork\" \\ 2";
  auto odd_back = parse_kit_toml(kit_to_toml(odd), "odd.toml");
  ASSERT_TRUE(odd_back.ok()) << odd_back.error().message;
  EXPECT_EQ(odd_back->splitter_kinds[0].name, odd.splitter_kinds[0].name);
}

TEST(Kit, ShippedFileIsTheDefaultKit) {
  auto kit = load_kit(std::filesystem::path(PROPRIO_SOURCE_DIR) / "config/rig_device/thesis_kit.toml");
  ASSERT_TRUE(kit.ok()) << kit.error().message;
  const Kit d = default_kit();
  EXPECT_EQ(kit->joint_count, d.joint_count);
  EXPECT_EQ(kit->total_splitters(), d.total_splitters());
  ASSERT_EQ(kit->splitter_kinds.size(), d.splitter_kinds.size());
  for (std::size_t k = 0; k < d.splitter_kinds.size(); ++k) {
    EXPECT_EQ(kit->splitter_kinds[k].name, d.splitter_kinds[k].name);
    ASSERT_EQ(kit->splitter_kinds[k].valence(), d.splitter_kinds[k].valence());
    for (std::size_t i = 0; i < d.splitter_kinds[k].valence(); ++i) {
      EXPECT_LT(kit->splitter_kinds[k].q_inlet_outlet[i].angularDistance(d.splitter_kinds[k].q_inlet_outlet[i]), 1e-9);
    }
  }
}

TEST(Kit, EmptyTextIsTheDefaultJointAndNoSplitters) {
  auto kit = parse_kit_toml("", "empty.toml");
  ASSERT_TRUE(kit.ok()) << kit.error().message;
  EXPECT_EQ(kit->joint_count, 18);
  EXPECT_EQ(kit->total_splitters(), 0);
}

struct Hostile {
  const char* what;
  std::string text;
  const char* expect_in_message;
};

TEST(Kit, HostileTomlIsRefusedWithAReason) {
  const std::string ok_splitter = "[[splitter]]\nname = \"S\"\n";
  const std::vector<Hostile> cases = {
      {"syntax", "[joint\ncount = 3", "fuzz"},
      {"unknown top key", "jionts = 3\n", "jionts"},
      {"unknown joint key", "[joint]\ncuont = 3\n", "cuont"},
      {"unknown splitter key", with_outlets(ok_splitter + "valency = 3\n", 2), "valency"},
      {"unknown outlet key", ok_splitter + "[[splitter.outlet]]\nyaw = 1\n[[splitter.outlet]]\n", "yaw"},
      {"absurd joint count", "[joint]\ncount = 1000000000000\n", "count"},
      {"negative count", "[joint]\ncount = -1\n", "count"},
      {"absurd splitter count", with_outlets(ok_splitter + "count = 100000\n", 2), "count"},
      {"nan length", "[joint]\nlength_in_m = nan\n", "length_in_m"},
      {"inf length", "[joint]\nlength_out_m = inf\n", "length_out_m"},
      {"negative length", "[joint]\nlength_out_m = -0.03\n", "length_out_m"},
      {"nan angle", ok_splitter + "[[splitter.outlet]]\ntilt_deg = nan\n[[splitter.outlet]]\n", "tilt_deg"},
      {"bend limit past 90", "[joint]\nbend_limit_deg = 120\n", "bend_limit_deg"},
      {"three rings", "[joint]\ntwist_rings = 3\n", "twist_rings"},
      {"string for number", "[joint]\ncount = \"eighteen\"\n", "count"},
      {"one outlet", with_outlets(ok_splitter, 1), "outlets"},
      {"nine outlets", with_outlets(ok_splitter, 9), "outlets"},
      {"no outlets", ok_splitter, "outlet"},
      {"no name", with_outlets("[[splitter]]\ncount = 1\n", 2), "name"},
      {"empty name", with_outlets("[[splitter]]\nname = \"\"\n", 2), "name"},
      {"control character in name", with_outlets("[[splitter]]\nname = \"a\\u0007b\"\n", 2), "control"},
      {"duplicate name", with_outlets(ok_splitter, 2) + with_outlets(ok_splitter, 2), "twice"},
      {"splitter not an array", "splitter = 3\n", "splitter"},
  };
  for (const Hostile& h : cases) {
    auto kit = parse_kit_toml(h.text, "fuzz.toml");
    ASSERT_FALSE(kit.ok()) << h.what;
    EXPECT_NE(kit.error().message.find(h.expect_in_message), std::string::npos)
        << h.what << ": " << kit.error().message;
  }
  std::string many;
  for (int k = 0; k < 65; ++k) many += with_outlets("[[splitter]]\nname = \"S" + std::to_string(k) + "\"\n", 2);
  auto kit = parse_kit_toml(many, "many.toml");
  ASSERT_FALSE(kit.ok());
  EXPECT_NE(kit.error().message.find("at most"), std::string::npos) << kit.error().message;
}

TEST(Kit, ValidateNamesTheField) {
  Kit kit = default_kit();
  kit.splitter_counts.pop_back();
  ASSERT_FALSE(kit.validate().ok());
  kit = default_kit();
  kit.splitter_kinds[1].q_inlet_outlet[0] = Quat(2, 0, 0, 0);
  ASSERT_FALSE(kit.validate().ok());
  EXPECT_NE(kit.validate().error().message.find("T2"), std::string::npos) << kit.validate().error().message;
  kit = default_kit();
  kit.joint.bend_limit_rad = std::nan("");
  EXPECT_FALSE(kit.validate().ok());
}

TEST(Kit, LoadRefusesWhatIsNotAFile) {
  auto dir = load_kit("/");
  ASSERT_FALSE(dir.ok());
  auto dev = load_kit("/dev/zero");
  ASSERT_FALSE(dev.ok());
  auto missing = load_kit("/nonexistent/kit.toml");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, Errc::not_found);
}

}  // namespace
}  // namespace proprio::rig_device
