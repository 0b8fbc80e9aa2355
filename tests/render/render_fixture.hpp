#pragma once
// One lavapipe context with validation for a whole test binary: creating a
// Vulkan instance costs ~100 ms, and every test must end with zero
// validation errors (checked in TearDown).
#include <gtest/gtest.h>

#include <memory>

#include "proprio/render/context.hpp"
#include "proprio/render/hand_drawing.hpp"
#include "proprio/render/offscreen_target.hpp"
#include "proprio/render/renderer.hpp"

namespace proprio::render::testing {

class RenderTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    ContextOptions options;
    options.device = DevicePreference::software;  // goldens are lavapipe's
    options.validation = true;
    auto ctx = VulkanContext::create(options);
    ASSERT_TRUE(ctx) << ctx.error().message;
    context_ = std::move(ctx).value();
    auto renderer = Renderer::create(*context_);
    ASSERT_TRUE(renderer) << renderer.error().message;
    renderer_ = std::move(renderer).value();
    auto unit = UnitMeshes::upload(*renderer_);
    ASSERT_TRUE(unit) << unit.error().message;
    unit_ = *unit;
  }
  static void TearDownTestSuite() {
    renderer_.reset();
    context_.reset();
  }
  void TearDown() override {
    ASSERT_TRUE(renderer_->wait_idle());
    EXPECT_EQ(context_->validation_errors(), 0u) << "Vulkan validation errors; first: "
                                                 << (context_->validation_messages().empty()
                                                         ? std::string()
                                                         : context_->validation_messages().front());
  }

  // Renders `draws` from `views` into a new offscreen target and reads view i back.
  static std::vector<ImageRGBA8> render_views(const DrawList& draws, std::span<const View> views, std::uint32_t w,
                                              std::uint32_t h) {
    auto target = OffscreenTarget::create(*renderer_, w, h, static_cast<std::uint32_t>(views.size()));
    EXPECT_TRUE(target) << target.error().message;
    if (!target) return {};
    auto s = renderer_->render(draws, views, (*target)->views());
    EXPECT_TRUE(s) << s.error().message;
    std::vector<ImageRGBA8> images(views.size());
    for (std::uint32_t i = 0; i < views.size(); ++i) EXPECT_TRUE((*target)->read(i, images[i]));
    return images;
  }

  static inline std::unique_ptr<VulkanContext> context_;
  static inline std::unique_ptr<Renderer> renderer_;
  static inline UnitMeshes unit_;
};

}  // namespace proprio::render::testing
