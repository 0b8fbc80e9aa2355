#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "proprio/core/config.hpp"
#include "support/text.hpp"

using namespace proprio;

namespace {
Config parse_ok(std::string_view text) {
  auto c = Config::parse(text, "test.toml");
  EXPECT_TRUE(c.ok()) << (c.ok() ? "" : c.error().message);
  return *c;
}
using proprio::testing_support::contains;
TEST(Config, CheckKeysNamesTheUnknownKeyItsPlaceAndTheAllowedOnes) {
  const Config c = parse_ok("a = 1\n[rig]\nfx = 640\nfy = 1\n");
  EXPECT_TRUE(c.check_keys("top level", {"a", "rig"}));
  auto bad = c.table("rig")->check_keys("rig", {"fx"});
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().code, Errc::invalid_argument);
  EXPECT_EQ(bad.error().message, "test.toml:4:6: unknown key 'fy' in [rig]; known keys: fx");
}

}  // namespace

TEST(Config, ReadsTypedValuesAndNestedKeys) {
  const Config c = parse_ok(R"(
name = "zed-mini"
[rig]
baseline_m = 0.063
width_px = 1280
rectified = true
fov_deg = [90, 60.0]
)");
  EXPECT_EQ(*c.get_string("name"), "zed-mini");
  EXPECT_DOUBLE_EQ(*c.get_double("rig.baseline_m"), 0.063);
  EXPECT_EQ(*c.get_int("rig.width_px"), 1280);
  EXPECT_DOUBLE_EQ(*c.get_double("rig.width_px"), 1280.0) << "integers are accepted as doubles";
  EXPECT_TRUE(*c.get_bool("rig.rectified"));
  EXPECT_EQ(*c.get_doubles("rig.fov_deg"), (std::vector<double>{90.0, 60.0}));
  auto rig = c.table("rig");
  ASSERT_TRUE(rig.ok());
  EXPECT_DOUBLE_EQ(*rig->get_double("baseline_m"), 0.063);
  EXPECT_EQ(rig->keys().size(), 4u);
}

TEST(Config, SyntaxErrorNamesFileAndLine) {
  auto c = Config::parse("a = 1\nb = = 2\n", "glove.toml");
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.error().code, Errc::parse_error);
  EXPECT_TRUE(contains(c.error().message, "glove.toml:2:")) << c.error().message;
}

TEST(Config, WrongTypeSaysWhatWasExpectedWhereAndWhatWasFound) {
  const Config c = parse_ok("[rig]\nbaseline_m = \"63mm\"\n");
  auto v = c.get_double("rig.baseline_m");
  ASSERT_FALSE(v.ok());
  EXPECT_TRUE(contains(v.error().message, "test.toml:2")) << v.error().message;
  EXPECT_TRUE(contains(v.error().message, "'rig.baseline_m' must be a number")) << v.error().message;
  EXPECT_TRUE(contains(v.error().message, "a string")) << v.error().message;
}

TEST(Config, SubTableErrorsKeepTheFullKeyPath) {
  const Config c = parse_ok("[rig.left]\nfx = true\n");
  auto left = c.table("rig.left");
  ASSERT_TRUE(left.ok());
  auto fx = left->get_double("fx");
  ASSERT_FALSE(fx.ok());
  EXPECT_TRUE(contains(fx.error().message, "'rig.left.fx'")) << fx.error().message;
}

TEST(Config, MissingRequiredKeyIsNotFound) {
  const Config c = parse_ok("x = 1\n");
  auto v = c.get_int("y");
  ASSERT_FALSE(v.ok());
  EXPECT_EQ(v.error().code, Errc::not_found);
  EXPECT_TRUE(contains(v.error().message, "'y'"));
}

TEST(Config, OptionalValuesUseFallbackButRejectBadOnes) {
  const Config c = parse_ok("rate_hz = 5000\nnoise = -1.0\n");
  EXPECT_DOUBLE_EQ(*c.get_double_or("absent", 2.5, 0.0, 10.0), 2.5);
  auto rate = c.get_int_or("rate_hz", 100, 1, 1000);
  ASSERT_FALSE(rate.ok());
  EXPECT_EQ(rate.error().code, Errc::out_of_range);
  EXPECT_TRUE(contains(rate.error().message, "[1, 1000]")) << rate.error().message;
  EXPECT_FALSE(c.get_double_or("noise", 0.1, 0.0, 1.0).ok());
}

TEST(Config, ArrayWithANonNumberPointsAtTheElement) {
  const Config c = parse_ok("v = [1.0, \"two\", 3.0]\n");
  auto v = c.get_doubles("v");
  ASSERT_FALSE(v.ok());
  EXPECT_TRUE(contains(v.error().message, "element 1")) << v.error().message;
}

TEST(Config, ArrayWithInfOrNanSaysSo) {
  for (const char* text : {"v = [1.0, inf]\n", "v = [nan, 2.0]\n"}) {
    auto v = parse_ok(text).get_doubles("v");
    ASSERT_FALSE(v.ok()) << text;
    EXPECT_TRUE(contains(v.error().message, "must be a finite number, but it is inf or nan")) << v.error().message;
  }
}

TEST(Config, ArrayOfTables) {
  const Config c = parse_ok("[[marker]]\nhue = \"red\"\n[[marker]]\nhue = 3\n");
  auto markers = c.tables("marker");
  ASSERT_TRUE(markers.ok());
  ASSERT_EQ(markers->size(), 2u);
  EXPECT_EQ(*(*markers)[0].get_string("hue"), "red");
  auto bad = (*markers)[1].get_string("hue");
  ASSERT_FALSE(bad.ok());
  EXPECT_TRUE(contains(bad.error().message, "marker[1].hue")) << bad.error().message;
}

TEST(Config, LoadFileReportsMissingFileAndReadsRealOne) {
  auto missing = Config::load_file("/nonexistent/proprio.toml");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, Errc::not_found);
  EXPECT_TRUE(contains(missing.error().message, "/nonexistent/proprio.toml"));

  const auto path = std::filesystem::temp_directory_path() / "proprio_config_test.toml";
  std::ofstream(path) << "seed = 7\n";
  auto c = Config::load_file(path);
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(*c->get_int("seed"), 7);
  std::filesystem::remove(path);
}

TEST(Config, WhereGivesTheKeysPositionOrTheFile) {
  const Config c = parse_ok("a = 1\n[rig]\nfx = 640\n");
  EXPECT_EQ(c.where("rig.fx"), "test.toml:3:6");
  EXPECT_EQ(c.where("absent"), "test.toml");
  EXPECT_EQ(c.table("rig")->where("fx"), "test.toml:3:6");
}
