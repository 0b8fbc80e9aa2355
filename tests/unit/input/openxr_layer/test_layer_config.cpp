#include <gtest/gtest.h>

#include <cstdlib>

#include "proprio/openxr_layer/layer_config.hpp"
#include "support/text.hpp"

using namespace proprio;
using namespace proprio::openxr_layer;

namespace {
using proprio::testing_support::contains;
}  // namespace

TEST(LayerConfig, ExampleConfigsParseToTheirDocumentedValues) {
  auto sim = parse_layer_config(example_layer_config(), "example.toml");
  ASSERT_TRUE(sim.ok()) << sim.error().message;
  EXPECT_EQ(sim->runtime_hand_tracking, RuntimeHandTracking::automatic);
  EXPECT_EQ(sim->max_prediction_ns, 50 * kNsPerMillisecond);
  ASSERT_EQ(sim->sources.size(), 1u);
  EXPECT_EQ(sim->sources[0].type, SourceType::sim);
  EXPECT_EQ(sim->sources[0].space, ReferenceSpace::view);
  EXPECT_EQ(sim->sources[0].hands.size(), 2u);

  auto replay = parse_layer_config(example_layer_config("/data/s1.prec"), "example.toml");
  ASSERT_TRUE(replay.ok()) << replay.error().message;
  EXPECT_EQ(replay->sources[0].type, SourceType::replay);
  EXPECT_EQ(replay->sources[0].path, "/data/s1.prec");
  EXPECT_TRUE(replay->sources[0].loop);
}

TEST(LayerConfig, OffsetsAreMetresAndDegrees) {
  auto c = parse_layer_config(
      "[[source]]\ntype = \"sim\"\nspace = \"stage\"\noffset_position_m = [0.1, 1.2, -0.3]\n"
      "offset_rotation_deg = [0, 90, 0]\nhands = [\"right\"]\n",
      "t.toml");
  ASSERT_TRUE(c.ok()) << c.error().message;
  const auto& s = c->sources[0];
  EXPECT_EQ(s.space, ReferenceSpace::stage);
  EXPECT_LT((s.T_space_source.p - Vec3(0.1, 1.2, -0.3)).norm(), 1e-12);
  EXPECT_NEAR(so3_log(s.T_space_source.q).y(), M_PI / 2, 1e-9);
  ASSERT_EQ(s.hands.size(), 1u);
  EXPECT_EQ(s.hands[0], Handedness::right);
}

TEST(LayerConfig, ErrorsNameTheFileTheSourceAndTheChoices) {
  auto bad_type = parse_layer_config("[[source]]\ntype = \"glove9\"\n", "layer.toml");
  ASSERT_FALSE(bad_type.ok());
  EXPECT_TRUE(contains(bad_type.error().message, "layer.toml")) << bad_type.error().message;
  EXPECT_TRUE(contains(bad_type.error().message, "sim, replay, vist")) << bad_type.error().message;

  auto no_path = parse_layer_config("[[source]]\ntype = \"replay\"\n", "layer.toml");
  ASSERT_FALSE(no_path.ok());
  EXPECT_TRUE(contains(no_path.error().message, "path")) << no_path.error().message;

  auto bad_hand = parse_layer_config("[[source]]\ntype = \"sim\"\nhands = [\"middle\"]\n", "layer.toml");
  ASSERT_FALSE(bad_hand.ok());
  EXPECT_TRUE(contains(bad_hand.error().message, "#1")) << bad_hand.error().message;

  auto bad_mode = parse_layer_config("[layer]\nruntime_hand_tracking = \"maybe\"\n", "layer.toml");
  ASSERT_FALSE(bad_mode.ok());
  EXPECT_TRUE(contains(bad_mode.error().message, "auto, override, passthrough")) << bad_mode.error().message;

  auto bad_offset = parse_layer_config("[[source]]\ntype = \"sim\"\noffset_position_m = [1, 2]\n", "layer.toml");
  ASSERT_FALSE(bad_offset.ok());
  EXPECT_TRUE(contains(bad_offset.error().message, "3 numbers")) << bad_offset.error().message;

  EXPECT_FALSE(load_layer_config("/nonexistent/layer.toml").ok());
}

TEST(LayerConfig, DefaultPathFollowsEnvironment) {
  ::setenv("PROPRIO_LAYER_CONFIG", "/tmp/x/layer.toml", 1);
  EXPECT_EQ(default_layer_config_path(), "/tmp/x/layer.toml");
  ::unsetenv("PROPRIO_LAYER_CONFIG");
  ::setenv("XDG_CONFIG_HOME", "/tmp/xdg", 1);
  EXPECT_EQ(default_layer_config_path(), "/tmp/xdg/proprio/layer.toml");
  ::unsetenv("XDG_CONFIG_HOME");
  ::setenv("HOME", "/home/u", 1);
  EXPECT_EQ(default_layer_config_path(), "/home/u/.config/proprio/layer.toml");
}

TEST(LayerConfig, VistSourcesReplayASessionForTheRightHandByDefault) {
  auto c = parse_layer_config("[[source]]\ntype = \"vist\"\npath = \"/data/vist.prec\"\nloop = false\n", "v.toml");
  ASSERT_TRUE(c.ok()) << c.error().message;
  const auto& s = c->sources[0];
  EXPECT_EQ(s.type, SourceType::vist);
  EXPECT_EQ(s.space, ReferenceSpace::local);
  ASSERT_EQ(s.hands.size(), 1u);
  EXPECT_EQ(s.hands[0], Handedness::right);
  EXPECT_FALSE(s.loop);
  EXPECT_TRUE(contains(s.describe(), "vist source"));

  auto missing = parse_layer_config("[[source]]\ntype = \"vist\"\n", "v.toml");
  ASSERT_FALSE(missing.ok());
  EXPECT_TRUE(contains(missing.error().message, "VIST session")) << missing.error().message;
}

TEST(LayerConfig, GloveSourcesDefaultToASimulatedWearerInViewSpace) {
  auto c = parse_layer_config("[[source]]\ntype = \"glove\"\nsubject = 5\n", "g.toml");
  ASSERT_TRUE(c.ok()) << c.error().message;
  const auto& s = c->sources[0];
  EXPECT_EQ(s.type, SourceType::glove);
  EXPECT_EQ(s.space, ReferenceSpace::view);
  EXPECT_EQ(s.input, "sim");
  EXPECT_EQ(s.subject, 5);
  ASSERT_EQ(s.hands.size(), 1u);
  EXPECT_TRUE(contains(s.describe(), "glove source"));
  auto bad = parse_layer_config("[[source]]\ntype = \"glove\"\ninput = \"usb\"\n", "g.toml");
  ASSERT_FALSE(bad.ok());
  EXPECT_TRUE(contains(bad.error().message, "sim, emulated, device")) << bad.error().message;

  auto no_cal = parse_layer_config("[[source]]\ntype = \"glove\"\ninput = \"device\"\n", "g.toml");
  ASSERT_FALSE(no_cal.ok());
  EXPECT_TRUE(contains(no_cal.error().message, "calibrate glove")) << no_cal.error().message;
  auto device = parse_layer_config(
      "[[source]]\ntype = \"glove\"\ninput = \"device\"\ncalibration = \"/c.toml\"\nhand_length_m = 0.2\n", "g.toml");
  ASSERT_TRUE(device.ok()) << device.error().message;
  EXPECT_EQ(device->sources[0].calibration, "/c.toml");
  EXPECT_DOUBLE_EQ(device->sources[0].hand_length_m, 0.2);
}
