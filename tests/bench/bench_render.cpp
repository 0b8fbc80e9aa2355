// Frame time on the machine's Vulkan device (lavapipe without a GPU): two
// hands plus 10 objects, 1280x720 per eye, stereo, headless, with and
// without reading the images back.
#include <benchmark/benchmark.h>

#include <glm/gtc/matrix_transform.hpp>

#include "proprio/core/hand_model.hpp"
#include "proprio/render/camera.hpp"
#include "proprio/render/hand_drawing.hpp"
#include "proprio/render/offscreen_target.hpp"

namespace {

using namespace proprio;
using namespace proprio::render;

void BM_RenderStereoTwoHandsTenObjects(benchmark::State& state) {
  const bool read_back = state.range(0) != 0;
  auto ctx = VulkanContext::create();
  if (!ctx) {
    state.SkipWithError(ctx.error().message.c_str());
    return;
  }
  auto renderer = Renderer::create(**ctx);
  auto unit = UnitMeshes::upload(**renderer);
  auto target = OffscreenTarget::create(**renderer, 1280, 720, 2);
  if (!renderer || !unit || !target) {
    state.SkipWithError("renderer setup failed");
    return;
  }
  std::vector<MeshId> objects;
  for (const MeshData& m : {primitives::sphere(0.05f), primitives::box(glm::vec3(0.04f)),
                            primitives::cylinder(0.035f, 0.05f), primitives::half_cylinder(0.25f, 0.25f, 64),
                            primitives::capsule(0.03f, 0.03f), primitives::peg(0.026f, 0.0931f),
                            primitives::plate_with_hole(0.03f, glm::vec3(0.06f, 0.06f, 0.015f))}) {
    objects.push_back(*(*renderer)->upload(m));
  }
  const HandModel model(*HandShape::from_measurements(0.19, 0.09));
  const HandPose left = model.forward(Handedness::left, HandAngles{}, Pose{Quat::Identity(), Vec3(-0.15, 1.1, -0.4)}, 0);
  const HandPose right = model.forward(Handedness::right, HandAngles{}, Pose{Quat::Identity(), Vec3(0.15, 1.1, -0.4)}, 0);
  const auto views = stereo_views(look_at(Vec3(0, 1.5, 0.1), Vec3(0, 1.0, -0.5)), 0.063f,
                                  symmetric_fov(glm::radians(90.0f), 1280.0f / 720.0f));
  DrawList draws;
  ImageRGBA8 image;
  for (auto _ : state) {
    draws.clear();
    for (int i = 0; i < 10; ++i) {
      const glm::mat4 m = glm::translate(glm::mat4(1.0f), glm::vec3(-0.5f + 0.11f * static_cast<float>(i), 0.9f, -0.6f));
      draws.items.push_back({objects[static_cast<std::size_t>(i) % objects.size()], m, glm::vec4(0.7f, 0.7f, 0.75f, 1)});
    }
    append_hand(draws, left, *unit, HandStyle::for_hand(Handedness::left));
    append_hand(draws, right, *unit, HandStyle::for_hand(Handedness::right));
    if (!(*renderer)->render(draws, views, (*target)->views())) state.SkipWithError("render failed");
    if (read_back) {
      for (std::uint32_t e = 0; e < 2; ++e) (void)(*target)->read(e, image);
    } else {
      (void)(*renderer)->wait_idle();
    }
  }
  state.counters["draws"] = static_cast<double>(draws.items.size());
  state.SetLabel((*ctx)->device_name());
}
BENCHMARK(BM_RenderStereoTwoHandsTenObjects)->Arg(0)->Arg(1)->ArgName("read_back")->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
