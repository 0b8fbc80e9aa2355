// The layer config's `ftm` source (issue 27 §4): defaults, keys and errors.
#include <gtest/gtest.h>

#include "proprio/openxr_layer/layer_config.hpp"
#include "support/text.hpp"

namespace proprio::openxr_layer {
namespace layer_config_ftm_test {

using proprio::testing_support::contains;

TEST(LayerConfigFtm, DefaultsToASimulatedRightHandedWearerInViewSpace) {
  auto c = parse_layer_config("[[source]]\ntype = \"ftm\"\nsubject = 4\nseed = 9\n", "f.toml");
  ASSERT_TRUE(c.ok()) << c.error().message;
  const auto& s = c->sources[0];
  EXPECT_EQ(s.type, SourceType::ftm);
  EXPECT_EQ(s.space, ReferenceSpace::view);
  EXPECT_EQ(s.input, "sim");
  EXPECT_EQ(s.subject, 4);
  EXPECT_EQ(s.seed, 9u);
  EXPECT_TRUE(s.track_abduction);
  EXPECT_TRUE(s.calibration.empty());
  ASSERT_EQ(s.hands.size(), 1u);
  EXPECT_EQ(s.hands[0], Handedness::right);
  EXPECT_TRUE(contains(s.describe(), "ftm source")) << s.describe();
  EXPECT_TRUE(contains(s.describe(), "abduction tracked")) << s.describe();
}

TEST(LayerConfigFtm, ReadsEmulatedKeysAndAbduction) {
  auto c = parse_layer_config("[[source]]\ntype = \"ftm\"\ninput = \"emulated\"\nhands = [\"left\"]\n"
                              "abduction = false\ntruth_path = \"/tmp/t.csv\"\nunplug_s = [1.0, 0.5]\n",
                              "f.toml");
  ASSERT_TRUE(c.ok()) << c.error().message;
  const auto& s = c->sources[0];
  EXPECT_EQ(s.input, "emulated");
  EXPECT_EQ(s.hands[0], Handedness::left);
  EXPECT_FALSE(s.track_abduction);
  EXPECT_EQ(s.truth_path, "/tmp/t.csv");
  ASSERT_EQ(s.unplugs.size(), 1u);
  EXPECT_DOUBLE_EQ(s.unplugs[0].duration_s, 0.5);
}

TEST(LayerConfigFtm, RefusesWhatAnFtmSourceCannotUse) {
  struct Case {
    const char* toml;
    const char* says;
  };
  const Case cases[] = {
      {"[[source]]\ntype = \"ftm\"\nhands = [\"left\", \"right\"]\n", "one glove"},
      {"[[source]]\ntype = \"ftm\"\ninput = \"device\"\n", "proprio calibrate ftm"},
      {"[[source]]\ntype = \"ftm\"\ninput = \"device\"\ncalibration = \"\"\n", "empty"},
      {"[[source]]\ntype = \"ftm\"\ninput = \"device\"\ncalibration = \"c.toml\"\nsubject = 2\n", "simulated wearer"},
      {"[[source]]\ntype = \"ftm\"\ninput = \"sim\"\nunplug_s = [1.0, 0.5]\n", "emulated"},
      {"[[source]]\ntype = \"ftm\"\ninput = \"usb\"\n", "sim, emulated, device"},
      {"[[source]]\ntype = \"ftm\"\nabduction = \"no\"\n", "abduction"},
      {"[[source]]\ntype = \"ftm\"\nmodel = \"m.onnx\"\n", "model"},
  };
  for (const auto& k : cases) {
    auto c = parse_layer_config(k.toml, "f.toml");
    ASSERT_FALSE(c.ok()) << k.toml;
    EXPECT_TRUE(contains(c.error().message, k.says)) << k.toml << " -> " << c.error().message;
  }
}

}  // namespace layer_config_ftm_test
}  // namespace proprio::openxr_layer
