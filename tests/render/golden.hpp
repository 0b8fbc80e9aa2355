#pragma once
// Golden-image comparison for rendered frames (Magnum-style): a frame passes
// when its largest and mean per-pixel differences from the committed PNG stay
// within stated tolerances. On failure the actual frame and a diff image are
// written next to the test binary; PROPRIO_UPDATE_GOLDENS=1 rewrites the
// goldens instead (then review them with git diff and look at them).
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "proprio/render/image.hpp"

namespace proprio::render::testing {

struct Tolerance {
  // lavapipe is deterministic for a given Mesa build; other Mesa versions or
  // GPUs move edges by a pixel, so a few bright pixels are fine, a shifted
  // scene is not.
  double max_fraction_over_threshold = 0.01;  // share of pixels differing by more than 24 of 255
  double max_mean = 1.5;                      // mean per-pixel difference (0-255)
};

inline void expect_matches_golden(const ImageRGBA8& actual, const std::string& name, Tolerance tolerance = {}) {
  const std::filesystem::path golden = std::filesystem::path(PROPRIO_GOLDEN_DIR) / (name + ".png");
  const std::filesystem::path out_dir = std::filesystem::path(PROPRIO_GOLDEN_OUT_DIR);
  if (const char* update = std::getenv("PROPRIO_UPDATE_GOLDENS"); update && std::string(update) == "1") {
    ASSERT_TRUE(write_png(actual, golden)) << golden;
    std::printf("updated golden %s\n", golden.c_str());
    return;
  }
  auto expected = read_png(golden);
  ASSERT_TRUE(expected) << expected.error().message
                        << " (create it with PROPRIO_UPDATE_GOLDENS=1, see docs/engine.md)";
  auto diff = compare_images(actual, *expected, 24);
  ASSERT_TRUE(diff) << diff.error().message;
  const bool pass = diff->fraction_over_threshold <= tolerance.max_fraction_over_threshold &&
                    diff->mean <= tolerance.max_mean;
  if (!pass) {
    (void)write_png(actual, out_dir / (name + ".actual.png"));
    (void)write_png(diff->visual, out_dir / (name + ".diff.png"));
  }
  EXPECT_TRUE(pass) << name << ": " << diff->fraction_over_threshold * 100 << " % of pixels differ by more than 24 "
                    << "(allowed " << tolerance.max_fraction_over_threshold * 100 << " %), mean difference "
                    << diff->mean << " (allowed " << tolerance.max_mean << "), max " << diff->max
                    << ". Actual and diff images: " << (out_dir / name).string() << ".{actual,diff}.png";
}

}  // namespace proprio::render::testing
