#pragma once
// CPU images (8-bit RGBA, sRGB-encoded, rows top to bottom), PNG files, and
// the comparison that golden-image tests use.
#include <cstdint>
#include <filesystem>
#include <vector>

#include "proprio/core/result.hpp"

namespace proprio::render {

struct ImageRGBA8 {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::vector<std::uint8_t> pixels;  // width * height * 4

  std::uint8_t* at(std::uint32_t x, std::uint32_t y) { return pixels.data() + (std::size_t{y} * width + x) * 4; }
  const std::uint8_t* at(std::uint32_t x, std::uint32_t y) const {
    return pixels.data() + (std::size_t{y} * width + x) * 4;
  }
};

Status write_png(const ImageRGBA8& image, const std::filesystem::path& file);
Result<ImageRGBA8> read_png(const std::filesystem::path& file);

// Per-pixel difference: for each pixel, the largest absolute channel
// difference (0-255) over R, G and B. Alpha is ignored.
struct ImageDifference {
  double max = 0;   // largest per-pixel difference
  double mean = 0;  // mean per-pixel difference over the image
  double fraction_over_threshold = 0;  // share of pixels whose difference exceeds `threshold`
  ImageRGBA8 visual;  // the expected image, dimmed, with differing pixels in red (brightness = size)
};
// Errc::invalid_argument when the sizes differ.
Result<ImageDifference> compare_images(const ImageRGBA8& actual, const ImageRGBA8& expected, int threshold = 16);

}  // namespace proprio::render
