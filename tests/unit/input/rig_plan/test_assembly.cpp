#include "proprio/rig_plan/assembly.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <regex>
#include <string>
#include <vector>

#include "proprio/rig_device/joint_kinematics.hpp"
#include "unit/input/rig_plan/runtime_fixtures.hpp"

namespace proprio::rig_plan::assembly_tests {
namespace {

namespace fx = test_fixtures;

std::string one_decimal_deg(double rad) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.1f", rad * 180.0 / M_PI);
  return std::string(buffer) == "-0.0" ? "0.0" : buffer;
}

int occurrences(const std::string& text, const std::string& needle) {
  int n = 0;
  for (std::size_t at = text.find(needle); at != std::string::npos; at = text.find(needle, at + 1)) ++n;
  return n;
}

// Tags balance and nest, attributes are quoted, no bare '&' or '<' in text.
// Enough XML to catch what a writer of SVG gets wrong.
::testing::AssertionResult well_formed(const std::string& xml) {
  std::vector<std::string> open;
  std::size_t i = 0;
  while (i < xml.size()) {
    if (xml[i] == '&') {
      const std::size_t semi = xml.find(';', i);
      if (semi == std::string::npos || semi - i > 6) return ::testing::AssertionFailure() << "bare & at " << i;
      i = semi + 1;
      continue;
    }
    if (xml[i] != '<') {
      if (xml[i] == '>') return ::testing::AssertionFailure() << "bare > at " << i;
      ++i;
      continue;
    }
    const std::size_t close = xml.find('>', i);
    if (close == std::string::npos) return ::testing::AssertionFailure() << "unclosed tag at " << i;
    std::string tag = xml.substr(i + 1, close - i - 1);
    i = close + 1;
    if (tag.empty()) return ::testing::AssertionFailure() << "empty tag";
    if (tag[0] == '?' || tag[0] == '!') continue;
    if (std::count(tag.begin(), tag.end(), '"') % 2 != 0 || tag.find('<') != std::string::npos)
      return ::testing::AssertionFailure() << "bad attributes in <" << tag << ">";
    if (tag[0] == '/') {
      const std::string name = tag.substr(1);
      if (open.empty() || open.back() != name)
        return ::testing::AssertionFailure() << "</" << name << "> closes " << (open.empty() ? "nothing" : open.back());
      open.pop_back();
      continue;
    }
    if (tag.back() == '/') continue;
    open.push_back(tag.substr(0, tag.find_first_of(" \t\n")));
  }
  if (!open.empty()) return ::testing::AssertionFailure() << "<" << open.back() << "> never closed";
  return ::testing::AssertionSuccess();
}

TEST(AssemblyText, OneStepPerModuleInBuildOrder) {
  const RigInput input = fx::small_input(2);
  const Plan plan = fx::small_plan(input);
  auto text = assembly_text(input, plan);
  ASSERT_TRUE(text.ok()) << text.error().message;
  std::size_t previous = 0;
  for (std::size_t i = 0; i < plan.modules.size(); ++i) {
    const std::size_t at = text->find("\n" + std::to_string(i + 1) + ". ");
    ASSERT_NE(at, std::string::npos) << "step " << i + 1;
    EXPECT_GT(at, previous);
    previous = at;
  }
  EXPECT_EQ(text->find("\n7. "), std::string::npos);
  EXPECT_NE(text->find("1. Joint (module 1): plug its inlet into the base"), std::string::npos) << *text;
  EXPECT_NE(text->find("2. Splitter T3 (module 2): plug its inlet into the outlet of module 1 (joint)"),
            std::string::npos);
  EXPECT_NE(text->find("5. Joint (module 5): plug its inlet into outlet 2 of module 2 (splitter T3)"),
            std::string::npos);
  EXPECT_NE(text->find("It drives rig node 'l_fore'"), std::string::npos);
  EXPECT_NE(text->find("outlet 1: towards 'l_arm'"), std::string::npos);
  // The rest setting is joint_angles_for's, in degrees.
  const rig_device::JointAngles a = rig_device::joint_angles_for(plan.modules[3].q_in_out_rest, 0.0);
  const std::string expected = "bend x " + one_decimal_deg(a.bend_x_rad) + ", bend y " + one_decimal_deg(a.bend_y_rad) +
                               ", outlet twist " + one_decimal_deg(a.twist_out_rad);
  EXPECT_NE(text->find(expected), std::string::npos) << expected << "\n" << *text;
  // The splitter's turn about its inlet: 0.5 rad about z.
  EXPECT_NE(text->find("turned " + one_decimal_deg(0.5) + " about the inlet shaft"), std::string::npos);
}

TEST(AssemblySvg, IsWellFormedWithOneMarkGroupPerModule) {
  RigInput input = fx::small_input(2);
  input.skeleton.names[6] = "l_fore<&\"'>";  // names are escaped
  const Plan plan = fx::small_plan(input);
  auto svg = assembly_svg(input, plan);
  ASSERT_TRUE(svg.ok()) << svg.error().message;
  EXPECT_EQ(svg->rfind("<?xml", 0), 0u);
  EXPECT_TRUE(well_formed(*svg));
  EXPECT_EQ(occurrences(*svg, "<svg "), 1);
  for (std::size_t i = 0; i < plan.modules.size(); ++i)
    EXPECT_EQ(occurrences(*svg, "<g id=\"module-" + std::to_string(i + 1) + "\""), 1) << "module " << i + 1;
  EXPECT_EQ(occurrences(*svg, "<g id=\"module-"), static_cast<int>(plan.modules.size()));
  // Two views: a red disc per joint and a blue square per splitter in each.
  EXPECT_EQ(occurrences(*svg, "fill=\"#d62728\"/>"), 2 * plan.joint_count() + 1);     // + legend
  EXPECT_EQ(occurrences(*svg, "fill=\"#1f77b4\"/>"), 2 * plan.splitter_count() + 1);
  EXPECT_NE(svg->find("l_fore&lt;&amp;&quot;&apos;&gt;"), std::string::npos);
  EXPECT_NE(svg->find("id=\"legend\""), std::string::npos);

  AssemblyOptions named;
  named.label_all_nodes = true;
  auto all = assembly_svg(input, plan, named);
  ASSERT_TRUE(all.ok());
  EXPECT_TRUE(well_formed(*all));
  EXPECT_NE(all->find(">r_fore</text>"), std::string::npos);
  EXPECT_FALSE(named.describe().empty());
}

TEST(Assembly, RefusesAPlanForAnotherRig) {
  const RigInput input = fx::small_input(2);
  Plan plan = fx::small_plan(input);
  plan.modules[5].rig_node = 12;
  EXPECT_FALSE(assembly_text(input, plan).ok());
  EXPECT_FALSE(assembly_svg(input, plan).ok());
  AssemblyOptions tiny;
  tiny.view_width_px = 3.0;
  EXPECT_FALSE(assembly_svg(input, fx::small_plan(input), tiny).ok());
}

TEST(Assembly, AnEmptyPlanSaysSo) {
  const RigInput input = fx::small_input(2);
  Plan plan = fx::small_plan(input);
  plan.modules.clear();
  plan.device_poses.clear();
  auto text = assembly_text(input, plan);
  ASSERT_TRUE(text.ok());
  EXPECT_NE(text->find("nothing to build"), std::string::npos);
  auto svg = assembly_svg(input, plan);
  ASSERT_TRUE(svg.ok());
  EXPECT_TRUE(well_formed(*svg));
}

}  // namespace
}  // namespace proprio::rig_plan::assembly_tests
