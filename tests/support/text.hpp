#pragma once
// Small string checks shared by the tests (error messages, file contents).
#include <string_view>

namespace proprio::testing_support {

// Whether `needle` occurs anywhere in `haystack`.
inline bool contains(std::string_view haystack, std::string_view needle) {
  return haystack.find(needle) != std::string_view::npos;
}

}  // namespace proprio::testing_support
