// Fuzzes the device plan reader (parse_plan_json) with arbitrary text: any
// input must end in an Error that says why, or a plan that validates against
// the rig, writes itself back identically, binds to a device built from it
// and yields assembly instructions, without crash, hang or outsized
// allocation. Seeds: corpus/rig_plan_json/.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/rig_plan/assembly.hpp"
#include "proprio/rig_plan/binding.hpp"
#include "proprio/rig_plan/plan_io.hpp"

namespace {

constexpr std::size_t kNodes = 64;

// A 64-node rig: a spine of 16 with four 12-node limbs off node 15.
const proprio::rig_plan::RigInput& rig() {
  static const proprio::rig_plan::RigInput input = [] {
    proprio::rig_plan::RigInput in;
    in.name = "fuzz rig";
    for (std::size_t i = 0; i < kNodes; ++i) {
      const int parent = i == 0 ? -1 : (i < 16 || (i - 16) % 12 != 0) ? static_cast<int>(i) - 1 : 15;
      in.skeleton.add("n" + std::to_string(i), parent, proprio::Vec3(0.01 * static_cast<double>(i % 5), 0.05, 0.0));
    }
    in.samples.push_back(proprio::rest_pose(in.skeleton));
    in.sample_names.push_back("rest");
    in.area_m2.assign(kNodes, 1.0);
    return in;
  }();
  return input;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 256 * 1024) return 0;  // plans are small; bigger inputs only slow the search
  using namespace proprio::rig_plan;
  auto plan = parse_plan_json(std::string_view(reinterpret_cast<const char*>(data), size), kNodes, "fuzz.json");
  if (!plan) {
    if (plan.error().message.empty()) std::abort();  // every refusal must say why
    return 0;
  }
  if (!validate_plan(*plan, kNodes)) std::abort();  // parse returns only valid plans
  const std::string text = plan_to_json(*plan);
  auto again = parse_plan_json(text, kNodes, "again.json");
  if (!again || plan_to_json(*again) != text) std::abort();  // what it writes, it reads
  // The device built exactly to the plan binds completely.
  std::vector<ObservedModule> device;
  for (std::size_t i = 0; i < plan->modules.size(); ++i) {
    const DeviceModule& m = plan->modules[i];
    device.push_back({static_cast<std::uint32_t>(i + 1), m.type == DeviceModule::Type::splitter, m.kind,
                      m.parent_module < 0 ? 0u : static_cast<std::uint32_t>(m.parent_module + 1), m.parent_outlet});
  }
  auto binding = bind_device(*plan, device);
  if (!binding || !binding->complete()) std::abort();
  if (!assembly_text(rig(), *plan) || !assembly_svg(rig(), *plan)) std::abort();
  return 0;
}
