// Fuzzes the stretch sensor array layout reader (StripArrayLayout::parse) with
// arbitrary text: any input must end in an Error that says why, or a layout
// that validates, describes its readability and writes itself back, without
// crash, hang or outsized allocation. Seeds: corpus/stretch_array_layout/.
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "proprio/stretch_array/array_layout.hpp"

using proprio::stretch_array::StripArrayLayout;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 64 * 1024) return 0;  // layouts are small; bigger inputs only slow the search
  auto layout = StripArrayLayout::parse(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.toml");
  if (!layout) {
    if (layout.error().message.empty()) std::abort();  // every refusal must say why
    return 0;
  }
  if (!layout->validate()) std::abort();  // parse returns only valid layouts
  // The readability check is an SVD of (n k + n + k) x cells: bound it.
  if (layout->cell_count() <= 400 && layout->top_strips.size() * layout->bottom_strips.size() <= 400) {
    (void)proprio::stretch_array::check_layout(*layout).describe();
  }
  auto again = StripArrayLayout::parse(layout->to_toml(), "again.toml");
  if (!again || again->cell_count() != layout->cell_count()) std::abort();  // what it writes, it reads
  return 0;
}
