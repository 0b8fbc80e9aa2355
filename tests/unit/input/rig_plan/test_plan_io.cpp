#include "proprio/rig_plan/plan_io.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "support/temp_dir.hpp"
#include "unit/input/rig_plan/runtime_fixtures.hpp"

namespace proprio::rig_plan::plan_io_tests {
namespace {

namespace fx = test_fixtures;
using nlohmann::json;

bool same_quat(const Quat& a, const Quat& b) { return a.coeffs() == b.coeffs(); }  // bit for bit

void expect_same_plan(const Plan& a, const Plan& b) {
  EXPECT_EQ(a.character, b.character);
  EXPECT_EQ(a.kit.describe(), b.kit.describe());
  EXPECT_EQ(a.kit.joint.length_in_m, b.kit.joint.length_in_m);
  EXPECT_EQ(a.kit.joint.bend_limit_rad, b.kit.joint.bend_limit_rad);
  ASSERT_EQ(a.kit.splitter_kinds.size(), b.kit.splitter_kinds.size());
  for (std::size_t k = 0; k < a.kit.splitter_kinds.size(); ++k) {
    ASSERT_EQ(a.kit.splitter_kinds[k].valence(), b.kit.splitter_kinds[k].valence());
    for (std::size_t o = 0; o < a.kit.splitter_kinds[k].valence(); ++o)
      EXPECT_TRUE(same_quat(a.kit.splitter_kinds[k].q_inlet_outlet[o], b.kit.splitter_kinds[k].q_inlet_outlet[o]));
  }
  ASSERT_EQ(a.modules.size(), b.modules.size());
  for (std::size_t i = 0; i < a.modules.size(); ++i) {
    const DeviceModule &x = a.modules[i], &y = b.modules[i];
    EXPECT_EQ(x.type, y.type);
    EXPECT_EQ(x.kind, y.kind);
    EXPECT_EQ(x.rig_node, y.rig_node);
    EXPECT_EQ(x.parent_module, y.parent_module);
    EXPECT_EQ(x.parent_outlet, y.parent_outlet);
    EXPECT_TRUE(same_quat(x.q_parent_inlet, y.q_parent_inlet));
    EXPECT_TRUE(same_quat(x.q_in_out_rest, y.q_in_out_rest));
    EXPECT_EQ(x.outlet_rig_child, y.outlet_rig_child);
    EXPECT_EQ(x.angular_error_rad, y.angular_error_rad);
  }
  EXPECT_EQ(a.error_rigid, b.error_rigid);
  EXPECT_EQ(a.error_after_joint, b.error_after_joint);
  EXPECT_EQ(a.error_final, b.error_final);
  ASSERT_EQ(a.device_poses.size(), b.device_poses.size());
  for (std::size_t i = 0; i < a.device_poses.size(); ++i) {
    ASSERT_EQ(a.device_poses[i].size(), b.device_poses[i].size());
    for (std::size_t m = 0; m < a.device_poses[i].size(); ++m)
      EXPECT_TRUE(same_quat(a.device_poses[i][m], b.device_poses[i][m]));
  }
}

TEST(PlanJson, RoundTripsBitForBit) {
  const RigInput input = fx::small_input(6);
  const Plan plan = fx::small_plan(input);
  ASSERT_TRUE(validate_plan(plan, input.skeleton.size()).ok());
  const std::string text = plan_to_json(plan);
  auto back = parse_plan_json(text, input.skeleton.size(), "plan.json");
  ASSERT_TRUE(back.ok()) << back.error().message;
  expect_same_plan(plan, *back);
  EXPECT_EQ(plan_to_json(*back), text);
}

TEST(PlanJson, SavesAndLoadsAFile) {
  testing_support::TempDir dir;
  const RigInput input = fx::small_input(6);
  const Plan plan = fx::small_plan(input);
  const auto file = dir / "stick.plan.json";
  ASSERT_TRUE(save_plan(file, plan, input.skeleton.size()).ok());
  auto back = load_plan(file, input.skeleton.size());
  ASSERT_TRUE(back.ok()) << back.error().message;
  expect_same_plan(plan, *back);
  // For a smaller rig the same file is refused, naming the module.
  auto other = load_plan(file, 4);
  ASSERT_FALSE(other.ok());
  EXPECT_NE(other.error().message.find("it must lie in [-1, 3]"), std::string::npos) << other.error().message;
  EXPECT_FALSE(load_plan(dir / "absent.json", 9).ok());
  // A plan that does not validate is not written.
  Plan bad = plan;
  bad.modules[2].parent_module = 4;
  EXPECT_FALSE(save_plan(dir / "bad.json", bad, input.skeleton.size()).ok());
  EXPECT_FALSE(std::filesystem::exists(dir / "bad.json"));
}

// Edits the valid plan's JSON and expects a refusal whose message holds `needle`.
void expect_refused(const std::function<void(json&)>& edit, const std::string& needle) {
  const RigInput input = fx::small_input(3);
  json j = json::parse(plan_to_json(fx::small_plan(input)));
  edit(j);
  auto r = parse_plan_json(j.dump(), input.skeleton.size(), "hostile.json");
  ASSERT_FALSE(r.ok()) << "accepted an edit expected to fail with '" << needle << "'";
  EXPECT_NE(r.error().message.find(needle), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("hostile.json"), std::string::npos);
}

TEST(PlanJson, RefusesHostileOrInconsistentPlans) {
  expect_refused([](json& j) { j["format"] = "proprio.kit"; }, "not a rig device plan");
  expect_refused([](json& j) { j["version"] = 2; }, "version");
  expect_refused([](json& j) { j.erase("modules"); }, "plan.modules is missing");
  expect_refused([](json& j) { j["modules"][0]["rig_node"] = 9; }, "plan.modules[0].rig_node");
  expect_refused([](json& j) { j["modules"][0]["rig_node"] = -7; }, "rig_node");
  expect_refused([](json& j) { j["modules"][0]["rig_node"] = 1e300; }, "integer");
  expect_refused([](json& j) { j["modules"][0]["rig_node"] = "1"; }, "integer");
  expect_refused([](json& j) { j["modules"][2]["q_parent_inlet"] = json::array({1, 1, 0, 0}); }, "unit quaternion");
  expect_refused([](json& j) { j["modules"][2]["q_in_out_rest"] = json::array({1, 0, 0}); }, "[w, x, y, z]");
  expect_refused([](json& j) { j["modules"][2]["parent_module"] = 4; }, "does not come before");
  expect_refused([](json& j) { j["modules"][4]["parent_outlet"] = 1; }, "shares outlet 1");
  expect_refused([](json& j) { j["modules"][4]["parent_outlet"] = 3; }, "has 3 outlet(s)");
  expect_refused([](json& j) { j["modules"][5]["rig_node"] = 5; }, "another joint drives");
  expect_refused([](json& j) { j["modules"][1]["kind"] = "X9"; }, "no splitter kind 'X9'");
  expect_refused([](json& j) { j["modules"][1]["outlet_rig_child"] = json::array({3, 5}); }, "a T3 has 3");
  expect_refused([](json& j) { j["modules"][0]["type"] = "hinge"; }, "\"joint\" or \"splitter\"");
  expect_refused([](json& j) { j["kit"]["joint"]["count"] = 2; }, "the kit has 2");
  expect_refused([](json& j) { j["kit"]["joint"]["bend_limit_rad"] = 3.0; }, "kit");
  expect_refused([](json& j) { j["device_poses"][1].erase(0); }, "device pose 1");
  expect_refused([](json& j) { j["error_final"] = -1.0; }, "pose errors");
  expect_refused([](json& j) { j = json::array(); }, "object");

  const std::size_t nodes = 9;
  for (const std::string text : {"", "{", "nonsense", "{\"format\": \"proprio.rig_plan\", \"version\": 1}", "[[[]]]",
                                 "{\"format\": 1}", "null", "1e999"}) {
    auto r = parse_plan_json(text, nodes, "t.json");
    ASSERT_FALSE(r.ok()) << text;
    EXPECT_FALSE(r.error().message.empty());
  }
  // Deep nesting is refused before parsing.
  auto deep = parse_plan_json(std::string(100000, '[') + std::string(100000, ']'), nodes, "deep.json");
  ASSERT_FALSE(deep.ok());
  EXPECT_NE(deep.error().message.find("nests"), std::string::npos);
  // Brackets inside strings do not count.
  json named = json::parse(plan_to_json(fx::small_plan(fx::small_input(3))));
  named["character"] = std::string(200, '[');
  EXPECT_TRUE(parse_plan_json(named.dump(), nodes, "named.json").ok());
  EXPECT_FALSE(parse_plan_json("{}", 0, "x.json").ok());
}

TEST(PlanJson, ModulesAreLabelledFromOne) {
  const Plan plan = fx::small_plan(fx::small_input(2));
  EXPECT_EQ(module_label(plan, 0), "module 1 (joint)");
  EXPECT_EQ(module_label(plan, 1), "module 2 (splitter T3)");
  EXPECT_EQ(module_label(plan, -1), "the base");
}

TEST(PlanJson, SeedCorpusHoldsAValidPlan) {
  const auto seed = std::filesystem::path(PROPRIO_TESTS_DIR) / "fuzz/corpus/rig_plan_json/stick_figure.json";
  auto plan = load_plan(seed, 64);  // the fuzz target's rig size
  ASSERT_TRUE(plan.ok()) << plan.error().message;
  EXPECT_EQ(plan->joint_count(), 5);
}

}  // namespace
}  // namespace proprio::rig_plan::plan_io_tests
