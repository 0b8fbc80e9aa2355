// Fuzzes Proprio's TOML reader (Config, over toml++) with arbitrary text: any
// input must end in an Error or a Config whose every key can be read through
// every typed getter, without crash, hang or outsized allocation. Seeds:
// corpus/config_toml/ (shipped configs and hand-written edge cases).
#include <cstdint>
#include <string>
#include <string_view>

#include "proprio/core/config.hpp"

using namespace proprio;

namespace {

void walk(const Config& c, int depth) {
  if (depth > 8) return;  // toml++ bounds nesting itself; this bounds our recursion
  for (const std::string& key : c.keys()) {
    (void)c.get_bool(key);
    (void)c.get_int(key);
    (void)c.get_double(key);
    (void)c.get_string(key);
    (void)c.get_doubles(key);
    (void)c.get_strings(key);
    (void)c.get_double_or(key, 0.0, -1.0, 1.0);
    (void)c.get_int_or(key, 0, -1, 1);
    (void)c.where(key);
    if (auto t = c.table(key)) walk(*t, depth + 1);
    if (auto ts = c.tables(key)) {
      for (const Config& t : *ts) walk(t, depth + 1);
    }
  }
  (void)c.check_keys("fuzz", {"a", "b"}, "hint");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 64 * 1024) return 0;  // configs are small; bigger inputs only slow the search
  auto c = Config::parse(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.toml");
  if (c) {
    walk(*c, 0);
  } else if (c.error().message.empty()) {
    std::abort();  // every refusal must say why
  }
  return 0;
}
