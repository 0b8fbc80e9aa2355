// Fuzzes the rig device kit reader (parse_kit_toml) with arbitrary text: any
// input must end in an Error that says why, or a kit that validates, describes
// itself and writes itself back to an equal kit, without crash, hang or
// outsized allocation. Seeds: corpus/rig_kit_toml/.
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "proprio/rig_device/kit.hpp"

using proprio::rig_device::Kit;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 64 * 1024) return 0;  // kits are small; bigger inputs only slow the search
  auto kit = proprio::rig_device::parse_kit_toml(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.toml");
  if (!kit) {
    if (kit.error().message.empty()) std::abort();  // every refusal must say why
    return 0;
  }
  if (!kit->validate()) std::abort();  // parse returns only valid kits
  (void)kit->describe();
  auto again = proprio::rig_device::parse_kit_toml(proprio::rig_device::kit_to_toml(*kit), "again.toml");
  if (!again) std::abort();  // what it writes, it reads
  if (again->joint_count != kit->joint_count || again->splitter_kinds.size() != kit->splitter_kinds.size() ||
      again->total_splitters() != kit->total_splitters()) {
    std::abort();
  }
  for (std::size_t k = 0; k < kit->splitter_kinds.size(); ++k) {
    const auto& a = kit->splitter_kinds[k];
    const auto& b = again->splitter_kinds[k];
    if (a.name != b.name || a.valence() != b.valence()) std::abort();
    for (std::size_t i = 0; i < a.valence(); ++i) {
      if (a.q_inlet_outlet[i].angularDistance(b.q_inlet_outlet[i]) > 1e-6) std::abort();
    }
  }
  return 0;
}
