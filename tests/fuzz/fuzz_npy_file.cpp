// Fuzzes the .npy reader (parse_npy) that loads array datasets: any input must
// end in an Error that says why, or an array whose shape accounts for exactly
// its values, without crash, hang or outsized allocation. Seeds:
// corpus/npy_file/.
#include <cstdint>
#include <cstdlib>
#include <span>

#include "proprio/core/npy_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 256 * 1024) return 0;
  auto a = proprio::parse_npy(std::span(data, size), "fuzz.npy", 1u << 20);
  if (!a) {
    if (a.error().message.empty()) std::abort();  // every refusal must say why
    return 0;
  }
  std::size_t n = 1;
  for (auto d : a->shape) n *= d;
  if (n != a->values.size() || a->shape.empty()) std::abort();
  return 0;
}
