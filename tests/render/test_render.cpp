// Renderer tests on lavapipe: golden images (primitives, hands in three poses
// per side, a stereo pair), the overlay, read-back, errors, and no heap
// allocation per frame in steady state.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <new>

#include <glm/gtc/matrix_transform.hpp>

#include "golden.hpp"
#include "proprio/core/glm_interop.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/render/camera.hpp"
#include "proprio/render/hand_skin.hpp"
#include "render_fixture.hpp"

// Counts heap allocations while `g_counting` is set (the per-frame test).
namespace {
std::atomic<bool> g_counting{false};
std::atomic<long> g_allocations{0};
}  // namespace
void* operator new(std::size_t size) {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace proprio::render {
namespace {

using testing::expect_matches_golden;
using testing::RenderTest;

glm::mat4 placed(const glm::vec3& position, float yaw_deg, float pitch_deg) {
  glm::mat4 m = glm::translate(glm::mat4(1.0f), position);
  m = glm::rotate(m, glm::radians(yaw_deg), glm::vec3(0, 1, 0));
  return glm::rotate(m, glm::radians(pitch_deg), glm::vec3(1, 0, 0));
}

// The seven primitives in a row at 1 m height, 0.5 m in front.
DrawList primitives_scene(Renderer& renderer) {
  std::vector<MeshId> ids;
  {
    for (const MeshData& m : {primitives::sphere(0.05f), primitives::box(glm::vec3(0.04f, 0.035f, 0.03f)),
                              primitives::cylinder(0.035f, 0.05f), primitives::half_cylinder(0.05f, 0.05f),
                              primitives::capsule(0.03f, 0.03f), primitives::peg(0.026f, 0.0931f),
                              primitives::plate_with_hole(0.03f, glm::vec3(0.06f, 0.06f, 0.015f))}) {
      auto id = renderer.upload(m);
      EXPECT_TRUE(id) << id.error().message;
      ids.push_back(id ? *id : 0);
    }
  }
  const glm::vec4 colors[] = {{0.9f, 0.3f, 0.25f, 1}, {0.3f, 0.75f, 0.35f, 1}, {0.3f, 0.45f, 0.9f, 1},
                              {0.85f, 0.85f, 0.88f, 1}, {0.9f, 0.75f, 0.2f, 1}, {0.95f, 0.95f, 0.95f, 1},
                              {0.6f, 0.4f, 0.75f, 1}};
  DrawList d;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    d.items.push_back({ids[i], placed(glm::vec3(-0.42f + 0.14f * static_cast<float>(i), 1.0f, -0.5f), 30.0f, -35.0f),
                       colors[i]});
  }
  return d;
}

View primitives_camera(float aspect) {
  return {look_at(Vec3(0.0, 1.22, 0.05), Vec3(0.0, 1.0, -0.5)), symmetric_fov(glm::radians(45.0f), aspect)};
}

TEST_F(RenderTest, PrimitivesMatchGolden) {
  const DrawList draws = primitives_scene(*renderer_);
  const View view = primitives_camera(320.0f / 200.0f);
  const auto images = render_views(draws, std::span(&view, 1), 320, 200);
  ASSERT_EQ(images.size(), 1u);
  expect_matches_golden(images[0], "primitives");
}

// Three poses (open, fist, pointing) of each hand, tiled: left hands on the
// top row, right on the bottom. Seen from the back of the hand, fingers up:
// the right thumb is on the image's left, the left thumb on its right; the
// wrist and palm triads show +Y (green) towards the camera and +Z (blue) down
// the forearm.
TEST_F(RenderTest, HandsInThreePosesMatchGolden) {
  const HandModel model(*HandShape::from_measurements(0.19, 0.09));
  HandAngles open{}, fist{}, point{};
  for (Finger f : {Finger::index, Finger::middle, Finger::ring, Finger::little}) {
    const std::size_t k = first_dof_of(f);
    fist[k] = 1.4;      // MCP
    fist[k + 2] = 1.5;  // PIP
    fist[k + 3] = 0.9;  // DIP
    if (f != Finger::index) {
      point[k] = fist[k];
      point[k + 2] = fist[k + 2];
      point[k + 3] = fist[k + 3];
    }
  }
  fist[index_of(HandDof::thumb_mcp_flexion)] = 0.8;
  fist[index_of(HandDof::thumb_ip_flexion)] = 0.9;
  point[index_of(HandDof::thumb_mcp_flexion)] = 0.6;
  // Fingers up (wrist -Z to world +Y), back of the hand (+Y) towards the camera (+Z).
  Mat3 R;
  R.col(0) = Vec3(1, 0, 0);
  R.col(1) = Vec3(0, 0, 1);
  R.col(2) = Vec3(0, -1, 0);
  const Pose T_world_wrist{Quat(R), Vec3(0, 0, 0)};
  const View view{look_at(Vec3(0.05, 0.1, 0.33), Vec3(0, 0.095, 0)), symmetric_fov(glm::radians(45.0f), 1.0f)};

  constexpr std::uint32_t kTile = 160;
  ImageRGBA8 sheet{3 * kTile, 2 * kTile, std::vector<std::uint8_t>(std::size_t{6} * kTile * kTile * 4)};
  int row = 0;
  for (Handedness hand : {Handedness::left, Handedness::right}) {
    int col = 0;
    for (const HandAngles* angles : {&open, &fist, &point}) {
      DrawList draws;
      append_hand(draws, model.forward(hand, *angles, T_world_wrist, 0), unit_, HandStyle::for_hand(hand));
      ASSERT_GT(draws.items.size(), 40u);
      const auto images = render_views(draws, std::span(&view, 1), kTile, kTile);
      ASSERT_EQ(images.size(), 1u);
      for (std::uint32_t y = 0; y < kTile; ++y) {
        std::memcpy(sheet.at(static_cast<std::uint32_t>(col) * kTile, static_cast<std::uint32_t>(row) * kTile + y),
                    images[0].at(0, y), kTile * 4);
      }
      ++col;
    }
    ++row;
  }
  expect_matches_golden(sheet, "hands_three_poses");
}

TEST_F(RenderTest, StereoPairMatchesGoldenAndEyesDiffer) {
  const DrawList draws = primitives_scene(*renderer_);
  const Pose T_world_head = look_at(Vec3(0.0, 1.25, 0.15), Vec3(0.0, 1.0, -0.5));
  const auto views = stereo_views(T_world_head, 0.063f, symmetric_fov(glm::radians(60.0f), 1.0f));
  const auto images = render_views(draws, views, 200, 200);
  ASSERT_EQ(images.size(), 2u);
  ImageRGBA8 pair{400, 200, std::vector<std::uint8_t>(std::size_t{400} * 200 * 4)};
  for (std::uint32_t y = 0; y < 200; ++y) {
    std::memcpy(pair.at(0, y), images[0].at(0, y), 200 * 4);
    std::memcpy(pair.at(200, y), images[1].at(0, y), 200 * 4);
  }
  expect_matches_golden(pair, "stereo_pair");
  // Parallax: the left eye sees the scene shifted right.
  auto diff = compare_images(images[0], images[1]);
  ASSERT_TRUE(diff);
  EXPECT_GT(diff->fraction_over_threshold, 0.02);
}

TEST_F(RenderTest, HudTextIsDrawnOverTheScene) {
  DrawList draws;
  const View view = primitives_camera(1.0f);
  const auto blank = render_views(draws, std::span(&view, 1), 128, 64);
  draws.hud.push_back({"Touch the sphere", {8, 8}, 1.0f, {1, 1, 0.2f, 1}, true});
  const auto with_text = render_views(draws, std::span(&view, 1), 128, 64);
  ASSERT_EQ(blank.size(), 1u);
  ASSERT_EQ(with_text.size(), 1u);
  // Yellow text pixels inside the panel's box, nothing changed below it.
  int yellow = 0, changed_below = 0;
  for (std::uint32_t y = 0; y < 64; ++y) {
    for (std::uint32_t x = 0; x < 128; ++x) {
      const std::uint8_t* p = with_text[0].at(x, y);
      const std::uint8_t* b = blank[0].at(x, y);
      if (y < 20 && p[0] > 200 && p[1] > 200 && p[2] < 150) ++yellow;
      if (y > 32 && (p[0] != b[0] || p[1] != b[1] || p[2] != b[2])) ++changed_below;
    }
  }
  EXPECT_GT(yellow, 30);
  EXPECT_EQ(changed_below, 0);
}

TEST_F(RenderTest, DepthHidesTheFartherObject) {
  // A red sphere in front of a blue one on the same line of sight.
  auto sphere = renderer_->upload(primitives::sphere(0.05f));
  ASSERT_TRUE(sphere);
  DrawList draws;
  draws.items.push_back({*sphere, glm::translate(glm::mat4(1.0f), glm::vec3(0, 1, -0.6f)), {0, 0, 1, 1}});
  draws.items.push_back({*sphere, glm::translate(glm::mat4(1.0f), glm::vec3(0, 1, -0.4f)), {1, 0, 0, 1}});
  const View view{look_at(Vec3(0, 1, 0), Vec3(0, 1, -1)), symmetric_fov(glm::radians(40.0f), 1.0f)};
  const auto images = render_views(draws, std::span(&view, 1), 64, 64);
  ASSERT_EQ(images.size(), 1u);
  const std::uint8_t* centre = images[0].at(32, 32);
  EXPECT_GT(centre[0], 100);
  EXPECT_LT(centre[2], 40);
}

TEST_F(RenderTest, BadMeshIdIsAnErrorNotACrash) {
  DrawList draws;
  draws.items.push_back({9999, glm::mat4(1.0f), glm::vec4(1.0f)});
  const View view = primitives_camera(1.0f);
  auto target = OffscreenTarget::create(*renderer_, 32, 32, 1);
  ASSERT_TRUE(target);
  auto s = renderer_->render(draws, std::span(&view, 1), (*target)->views());
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("mesh 9999"), std::string::npos);
  EXPECT_FALSE(OffscreenTarget::create(*renderer_, 0, 32, 1));
  MeshData broken = primitives::box(glm::vec3(0.1f));
  broken.indices.push_back(12345);
  EXPECT_FALSE(renderer_->upload(broken));
}

// Validation layers allocate in every vkCmd*, so this runs on its own
// context without them: what is measured is the renderer and lavapipe.
TEST(RendererAllocation, SteadyStateStereoFramesDoNotAllocate) {
  ContextOptions options;
  options.device = DevicePreference::software;
  auto context = VulkanContext::create(options);
  ASSERT_TRUE(context) << context.error().message;
  auto renderer = Renderer::create(**context);
  ASSERT_TRUE(renderer);
  auto unit = UnitMeshes::upload(**renderer);
  ASSERT_TRUE(unit);
  const DrawList scene = primitives_scene(**renderer);
  const HandModel model(*HandShape::from_measurements(0.19, 0.09));
  const HandPose hand = model.forward(Handedness::right, HandAngles{}, Pose{Quat::Identity(), Vec3(0, 1, -0.4)}, 0);
  // Skinned hands too: the generated right hand, and mirrored as a left hand.
  auto skinned = SkinnedHand::upload(**renderer, generate_hand_mesh(model, Handedness::right));
  ASSERT_TRUE(skinned) << skinned.error().message;
  const HandPose right = model.forward(Handedness::right, HandAngles{}, Pose{Quat::Identity(), Vec3(0.1, 1, -0.4)}, 0);
  const HandPose left = model.forward(Handedness::left, HandAngles{}, Pose{Quat::Identity(), Vec3(-0.1, 1, -0.4)}, 0);
  const auto views = stereo_views(look_at(Vec3(0.0, 1.25, 0.15), Vec3(0.0, 1.0, -0.5)), 0.063f,
                                   symmetric_fov(glm::radians(60.0f), 1.0f));
  auto target = OffscreenTarget::create(**renderer, 96, 96, 2);
  ASSERT_TRUE(target);
  DrawList draws;
  draws.hud.push_back({"trial 3 of 20", {8, 8}, 1.0f, glm::vec4(1), true});
  auto frame = [&] {
    draws.items.clear();
    draws.skinned.clear();
    draws.skin_matrices.clear();
    draws.items.insert(draws.items.end(), scene.items.begin(), scene.items.end());
    append_hand(draws, hand, *unit, HandStyle{});
    append_skinned_hand(draws, right, *skinned, skin_color_for(Handedness::right));
    append_skinned_hand(draws, left, *skinned, skin_color_for(Handedness::left));
    return (*renderer)->render(draws, views, (*target)->views()).ok();
  };
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(frame());  // warm-up: capacities grow once
  ASSERT_TRUE((*renderer)->wait_idle());
  g_allocations = 0;
  g_counting = true;
  bool ok = true;
  for (int i = 0; i < 20 && ok; ++i) ok = frame();
  ok = ok && (*renderer)->wait_idle().ok();
  g_counting = false;
  ASSERT_TRUE(ok);
  EXPECT_EQ(g_allocations.load(), 0) << "heap allocations in 20 steady-state stereo frames";
  EXPECT_EQ((*renderer)->stats().draws_last_frame, draws.items.size() + 2);
  EXPECT_EQ(draws.skinned.size(), 2u);
  EXPECT_GT((*renderer)->stats().skinned_vertices_last_frame, 3000u);
  EXPECT_EQ((*renderer)->stats().skinned_draws_dropped, 0u);
}

}  // namespace
}  // namespace proprio::render
