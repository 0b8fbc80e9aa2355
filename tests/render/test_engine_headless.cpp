// The engine end to end, headless on lavapipe with validation: the scripted
// hand presses the half cylinder through the haptics loop, frames are written,
// and one frame matches its golden image.
#include <gtest/gtest.h>

#include <filesystem>
#include <functional>

#include "golden.hpp"
#include "proprio/engine/app.hpp"
#include "proprio/engine/scripted_hands.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/render/hand_skin.hpp"

namespace proprio::engine {
namespace {

struct HeadlessRun {
  AppReport report;
  std::filesystem::path dir;
};

HeadlessRun run_half_cylinder(int frames, bool haptics, const std::string& name,
                              const std::function<void(AppOptions&)>& tweak = {}) {
  auto scene = Scene::preset("half-cylinder");
  EXPECT_TRUE(scene);
  AppOptions o;
  o.output = OutputMode::headless;
  o.width = 320;
  o.height = 180;
  o.stereo = false;
  o.frames = frames;
  o.frame_rate_hz = 30;
  o.software_renderer = true;
  o.validation = true;
  o.out_dir = std::filesystem::path(PROPRIO_GOLDEN_OUT_DIR) / name;
  std::filesystem::remove_all(o.out_dir);
  if (tweak) tweak(o);
  AppInputs in;
  in.hand_model = std::make_shared<const HandModel>(*HandShape::from_measurements(0.19, 0.09));
  in.simulated_clock = std::make_shared<ManualClock>(kNsPerSecond);
  in.hands = std::make_shared<ScriptedTouchSource>(in.hand_model, Handedness::right, *scene,
                                                   in.simulated_clock->now_ns());
  if (haptics) {
    auto model = haptics::load_device_model(std::string(PROPRIO_SOURCE_DIR) + "/config/haptics/band_2dof.toml");
    EXPECT_TRUE(model);
    std::shared_ptr<const haptics::FingertipDeviceModel> shared(std::move(*model));
    auto sink = haptics::EmulatedFingertip::create(shared);
    EXPECT_TRUE(sink);
    in.haptic_channels.push_back({Finger::index, shared, std::move(*sink)});
  }
  auto app = App::create(std::move(*scene), std::move(in), o);
  EXPECT_TRUE(app) << app.error().message;
  auto report = (*app)->run();
  EXPECT_TRUE(report) << report.error().message;
  return {report ? *report : AppReport{}, o.out_dir};
}

TEST(EngineHeadless, ScriptedTouchPressesTheHalfCylinderThroughTheHapticsLoop) {
  // 2 s: the 4 s touch script's approach (1 s) and press (0.5 s) and part of the slide.
  const HeadlessRun run = run_half_cylinder(60, true, "engine_touch");
  EXPECT_EQ(run.report.frames, 60);
  ASSERT_EQ(run.report.images.size(), 60u);
  for (const auto& f : run.report.images) EXPECT_TRUE(std::filesystem::exists(f)) << f;
  EXPECT_TRUE(run.report.haptics);
  // The press meets the cylinder end-on with about 16 N of contact force; felt on
  // the pad, it is commanded at the 2-DOF band's 2 N limit, never above
  // (docs/haptics.md, config/haptics/band_2dof.toml).
  EXPECT_GT(run.report.peak_fingertip_force_n, 1.9);
  EXPECT_LE(run.report.peak_fingertip_force_n, 2.0 + 1e-9);
  // One servo tick per simulated millisecond over the 59 frame intervals.
  EXPECT_NEAR(static_cast<double>(run.report.servo.ticks), 59.0 * 1000.0 / 30.0, 1.0);
  // The pressing frame (t = 1.8 s) is the half-cylinder scene's golden.
  auto frame = render::read_png(run.report.images[54]);
  ASSERT_TRUE(frame);
  render::testing::expect_matches_golden(*frame, "half_cylinder_touch");
}

TEST(EngineHeadless, WithoutHapticsTheTrackedHandIsDrawnAsIs) {
  const HeadlessRun run = run_half_cylinder(3, false, "engine_plain");
  EXPECT_EQ(run.report.frames, 3);
  EXPECT_FALSE(run.report.haptics);
  EXPECT_EQ(run.report.peak_fingertip_force_n, 0.0);
}

// A small mono headless run without the HUD, for the frame-hook tests,
// writing into a fresh folder.
AppOptions small_hook_run(int frames, const char* name) {
  AppOptions o;
  o.output = OutputMode::headless;
  o.width = 160;
  o.height = 90;
  o.stereo = false;
  o.frames = frames;
  o.software_renderer = true;
  o.validation = true;
  o.hud = false;
  o.out_dir = std::filesystem::path(PROPRIO_GOLDEN_OUT_DIR) / name;
  std::filesystem::remove_all(o.out_dir);
  return o;
}

// A deforming surface from the frame hook: a square ahead of the eyes that
// slides from the left half of the view to the right half.
TEST(EngineHeadless, FrameHookMovesADeformingSurface) {
  auto scene = Scene::preset("empty");
  ASSERT_TRUE(scene);
  const AppOptions o = small_hook_run(2, "engine_surface");
  AppInputs in;
  in.surfaces.push_back({"sheet", {0, 1, 2, 0, 2, 3}, 4, {1, 0.2f, 0.2f, 1}});
  in.on_frame = [&](FrameContext& c) {
    ASSERT_EQ(c.surfaces.size(), 0u + (c.frame > 0));
    c.show_scene = false;
    const Vec3 ahead = c.T_world_head * Vec3(c.frame == 0 ? -0.08 : 0.08, 0, -0.3);
    const Mat3 R = c.T_world_head.q.toRotationMatrix();
    const Vec3 x = R.col(0) * 0.05, y = R.col(1) * 0.05;
    c.surfaces.assign(1, {ahead - x - y, ahead + x - y, ahead + x + y, ahead - x + y});
  };
  auto app = App::create(std::move(*scene), std::move(in), o);
  ASSERT_TRUE(app) << app.error().message;
  auto report = (*app)->run();
  ASSERT_TRUE(report) << report.error().message;
  ASSERT_EQ(report->images.size(), 2u);
  auto red_pixels = [](const render::ImageRGBA8& im, std::uint32_t x0, std::uint32_t x1) {
    int n = 0;
    for (std::uint32_t y = 0; y < im.height; ++y) {
      for (std::uint32_t x = x0; x < x1; ++x) n += im.at(x, y)[0] > 200;  // the background is black
    }
    return n;
  };
  auto first = render::read_png(report->images[0]);
  auto second = render::read_png(report->images[1]);
  ASSERT_TRUE(first && second);
  EXPECT_GT(red_pixels(*first, 0, 80), 100);
  EXPECT_EQ(red_pixels(*first, 80, 160), 0);
  EXPECT_EQ(red_pixels(*second, 0, 80), 0);
  EXPECT_GT(red_pixels(*second, 80, 160), 100);
}

TEST(EngineHeadless, FrameHookBlacksOutTheSceneDrawsMarkersAndStops) {
  auto scene = Scene::preset("half-cylinder");
  ASSERT_TRUE(scene);
  const AppOptions o = small_hook_run(10, "engine_hook");
  AppInputs in;
  int calls = 0;
  Pose head_seen;
  in.on_frame = [&](FrameContext& c) {
    ++calls;
    EXPECT_EQ(c.frame, calls - 1);
    ASSERT_NE(c.tracked, nullptr);
    EXPECT_TRUE(c.markers.empty());  // cleared before every call
    EXPECT_EQ(c.entities.size(), 1u);
    head_seen = c.T_world_head;
    c.show_scene = c.frame != 1;  // frame 1: black, with a red sphere 30 cm ahead of the eyes
    if (c.frame == 1) {
      c.markers.push_back({FrameContext::Marker::Shape::sphere,
                           Pose{Quat::Identity(), c.T_world_head * Vec3(0, 0, -0.3)}, Vec3::Constant(0.03),
                           {1, 0, 0, 1}});
    }
    c.stop = c.frame == 2;
  };
  auto app = App::create(std::move(*scene), std::move(in), o);
  ASSERT_TRUE(app) << app.error().message;
  auto report = (*app)->run();
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(calls, 3);
  EXPECT_EQ(report->frames, 3);
  EXPECT_GT(head_seen.p.y(), 0.5);  // a standing viewer's eyes
  auto black = render::read_png(report->images[1]);
  ASSERT_TRUE(black);
  const std::uint8_t* centre = black->at(80, 45);
  EXPECT_GT(centre[0], 150);  // the red marker in the middle of the view
  EXPECT_LT(centre[1], 60);
  const std::uint8_t* corner = black->at(2, 2);
  EXPECT_LT(corner[0] + corner[1] + corner[2], 10);  // everything else black
  auto normal = render::read_png(report->images[0]);
  ASSERT_TRUE(normal);
  EXPECT_GT(normal->at(2, 2)[2], 10);  // the usual background
}

// The skinned hand look: the proxy (solid) and the tracked ghost as skinned
// hands, generated or from a glTF file; the frames differ from the joint look.
TEST(EngineHeadless, SkinnedHandLookDrawsGeneratedAndGltfHands) {
  EXPECT_EQ(parse_hand_look("skinned"), HandLook::skinned);
  EXPECT_EQ(parse_hand_look("joints"), HandLook::joints);
  EXPECT_FALSE(parse_hand_look("mesh"));
  const HeadlessRun joints = run_half_cylinder(8, true, "engine_hands_joints");
  const HeadlessRun generated =
      run_half_cylinder(8, true, "engine_hands_skinned", [](AppOptions& o) { o.hand_look = HandLook::skinned; });
  const auto file = std::filesystem::path(PROPRIO_GOLDEN_OUT_DIR) / "engine_hand.gltf";
  const HandModel model(*HandShape::from_measurements(0.19, 0.09));
  ASSERT_TRUE(render::save_skinned_gltf(render::generate_hand_mesh(model, Handedness::right), file));
  const HeadlessRun from_file = run_half_cylinder(8, true, "engine_hands_gltf", [&](AppOptions& o) {
    o.hand_look = HandLook::skinned;
    o.hand_gltf = file;
  });
  ASSERT_EQ(joints.report.images.size(), 8u);
  ASSERT_EQ(generated.report.images.size(), 8u);
  ASSERT_EQ(from_file.report.images.size(), 8u);
  auto a = render::read_png(joints.report.images.back());
  auto b = render::read_png(generated.report.images.back());
  auto c = render::read_png(from_file.report.images.back());
  ASSERT_TRUE(a && b && c);
  auto joints_vs_skinned = render::compare_images(*a, *b);
  ASSERT_TRUE(joints_vs_skinned);
  EXPECT_GT(joints_vs_skinned->fraction_over_threshold, 0.005);  // the hands look different
  auto generated_vs_file = render::compare_images(*b, *c);
  ASSERT_TRUE(generated_vs_file);
  EXPECT_EQ(generated_vs_file->max, 0);  // the file is the generated hand

  AppOptions bad;
  bad.hand_gltf = file;  // with the joint look
  EXPECT_FALSE(bad.validate());
  auto scene = Scene::preset("half-cylinder");
  ASSERT_TRUE(scene);
  AppOptions missing;
  missing.output = OutputMode::headless;
  missing.software_renderer = true;
  missing.frames = 1;
  missing.hand_look = HandLook::skinned;
  missing.hand_gltf = "no_such_hand.gltf";
  auto app = App::create(std::move(*scene), AppInputs{}, missing);
  ASSERT_TRUE(app) << app.error().message;
  auto report = (*app)->run();
  ASSERT_FALSE(report);
  EXPECT_NE(report.error().message.find("no_such_hand.gltf"), std::string::npos) << report.error().message;
}

}  // namespace
}  // namespace proprio::engine
