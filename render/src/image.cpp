#include "proprio/render/image.hpp"

#include <fmt/format.h>
#include <stb_image.h>
#include <stb_image_write.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>

namespace proprio::render {

Status write_png(const ImageRGBA8& image, const std::filesystem::path& file) {
  if (image.pixels.size() != std::size_t{image.width} * image.height * 4 || image.width == 0) {
    return make_error(Errc::invalid_argument, fmt::format("image is {}x{} but holds {} bytes", image.width,
                                                          image.height, image.pixels.size()));
  }
  std::error_code ec;
  if (file.has_parent_path()) std::filesystem::create_directories(file.parent_path(), ec);
  if (!stbi_write_png(file.string().c_str(), static_cast<int>(image.width), static_cast<int>(image.height), 4,
                      image.pixels.data(), static_cast<int>(image.width * 4))) {
    return make_error(Errc::io_error, fmt::format("could not write PNG '{}'", file.string()));
  }
  return {};
}

Result<ImageRGBA8> read_png(const std::filesystem::path& file) {
  int w = 0, h = 0, channels = 0;
  stbi_uc* data = stbi_load(file.string().c_str(), &w, &h, &channels, 4);
  if (!data) {
    std::error_code ec;
    const bool exists = std::filesystem::exists(file, ec);
    return make_error(exists ? Errc::parse_error : Errc::not_found,
                      fmt::format("could not read PNG '{}': {}", file.string(),
                                  exists ? stbi_failure_reason() : "no such file"));
  }
  ImageRGBA8 image;
  image.width = static_cast<std::uint32_t>(w);
  image.height = static_cast<std::uint32_t>(h);
  image.pixels.assign(data, data + std::size_t{image.width} * image.height * 4);
  stbi_image_free(data);
  return image;
}

Result<ImageDifference> compare_images(const ImageRGBA8& actual, const ImageRGBA8& expected, int threshold) {
  if (actual.width != expected.width || actual.height != expected.height) {
    return make_error(Errc::invalid_argument, fmt::format("image sizes differ: {}x{} vs expected {}x{}", actual.width,
                                                          actual.height, expected.width, expected.height));
  }
  ImageDifference d;
  d.visual = expected;
  const std::size_t n = std::size_t{actual.width} * actual.height;
  double sum = 0;
  std::size_t over = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint8_t* a = actual.pixels.data() + i * 4;
    const std::uint8_t* e = expected.pixels.data() + i * 4;
    int diff = 0;
    for (int c = 0; c < 3; ++c) diff = std::max(diff, std::abs(int{a[c]} - int{e[c]}));
    sum += diff;
    d.max = std::max(d.max, static_cast<double>(diff));
    if (diff > threshold) ++over;
    std::uint8_t* v = d.visual.pixels.data() + i * 4;
    if (diff > 0) {
      v[0] = static_cast<std::uint8_t>(std::min(255, 64 + diff * 4));
      v[1] = 0;
      v[2] = 0;
    } else {
      for (int c = 0; c < 3; ++c) v[c] = static_cast<std::uint8_t>(v[c] / 4);
    }
    v[3] = 255;
  }
  d.mean = n ? sum / static_cast<double>(n) : 0.0;
  d.fraction_over_threshold = n ? static_cast<double>(over) / static_cast<double>(n) : 0.0;
  return d;
}

}  // namespace proprio::render
