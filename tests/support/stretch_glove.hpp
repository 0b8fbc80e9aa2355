#pragma once
// Stretch-glove helpers shared by the glove tests.
#include "proprio/glove_descriptions/stretch_glove_layout.hpp"

namespace proprio::testing_support {

// The thesis's sensor layout, built once.
inline const StretchGloveLayout& thesis_layout() {
  static const StretchGloveLayout L = StretchGloveLayout::thesis_default();
  return L;
}

}  // namespace proprio::testing_support
