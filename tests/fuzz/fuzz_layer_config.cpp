// Fuzzes the OpenXR layer's configuration (parse_layer_config: sources, the
// wrist, [haptics]) with arbitrary text. The layer reads this file inside
// other people's apps: any input must end in an Error that says why, or a
// configuration that describes itself, without crash, hang or outsized
// allocation. Seeds: corpus/layer_config/.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "proprio/openxr_layer/layer_config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 64 * 1024) return 0;  // the layer refuses configs over 1 MiB; small inputs search faster
  auto c = proprio::openxr_layer::parse_layer_config(std::string_view(reinterpret_cast<const char*>(data), size),
                                                     "fuzz.toml");
  if (c) {
    (void)c->describe();
    if (c->haptics.enabled && c->haptics.device_count() == 0) std::abort();  // parse_haptics refuses that
  } else if (c.error().message.empty()) {
    std::abort();  // every refusal must say why
  }
  return 0;
}
