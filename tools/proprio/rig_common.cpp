#include "rig_common.hpp"

#include "proprio/rig_characters/examples.hpp"

namespace proprio::cli {

Result<LoadedCharacter> load_rig_character(const std::string& file_or_example) {
  static constexpr std::string_view kExample = "example:";
  LoadedCharacter out;
  if (file_or_example.rfind(kExample, 0) == 0) {
    auto c = rig_characters::make_example_character(file_or_example.substr(kExample.size()));
    if (!c) return c.error();
    out.character = std::move(*c);
  } else {
    auto c = render::load_character_gltf(file_or_example);
    if (!c) return c.error();
    out.character = std::move(*c);
  }
  if (out.character.sample_poses.empty())
    return make_error(Errc::invalid_argument,
                      file_or_example + " has no sample poses: the rig device plans from them (store them as "
                                        "rotation keyframes of an animation)");
  out.input.name = out.character.name;
  out.input.skeleton = out.character.skeleton;
  out.input.samples = out.character.sample_poses;
  out.input.sample_names = out.character.sample_names;
  out.input.area_m2 = render::skin_area_per_node_m2(out.character);
  if (auto st = out.input.validate(); !st) return st.error().with_context(file_or_example);
  return out;
}

Status check_plan_matches(const rig_plan::Plan& plan, const rig_plan::RigInput& input) {
  if (!plan.character.empty() && plan.character != input.name)
    return make_error(Errc::invalid_argument, "the plan was made for the character '" + plan.character +
                                                  "', not for '" + input.name + "': plan this one with 'proprio rig plan'");
  if (!plan.device_poses.empty() && !input.samples.empty() && plan.device_poses.size() != input.samples.size())
    return make_error(Errc::invalid_argument,
                      "the plan has device poses for " + std::to_string(plan.device_poses.size()) +
                          " samples; the character has " + std::to_string(input.samples.size()) +
                          ": its sample poses changed since it was planned; plan it again");
  return {};
}

}  // namespace proprio::cli
