// The engine end to end, headless on lavapipe with validation: the scripted
// hand presses the half cylinder through the haptics loop, frames are written,
// and one frame matches its golden image.
#include <gtest/gtest.h>

#include <filesystem>

#include "golden.hpp"
#include "proprio/engine/app.hpp"
#include "proprio/engine/scripted_hands.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"

namespace proprio::engine {
namespace {

struct HeadlessRun {
  AppReport report;
  std::filesystem::path dir;
};

HeadlessRun run_half_cylinder(int frames, bool haptics, const std::string& name) {
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
  // 1 cm into the surface with the default coupling: about 0.8 N (docs/haptics.md).
  EXPECT_GT(run.report.peak_fingertip_force_n, 0.5);
  EXPECT_LT(run.report.peak_fingertip_force_n, 1.5);
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

}  // namespace
}  // namespace proprio::engine
