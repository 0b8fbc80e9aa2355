#pragma once
// What the rig commands share: a character from a glTF file (or a shipped
// example, "example:NAME") with the planning input made from it, and the
// check that a plan belongs to that character.
#include <string>

#include "proprio/core/result.hpp"
#include "proprio/render/character.hpp"
#include "proprio/rig_plan/plan.hpp"

namespace proprio::cli {

struct LoadedCharacter {
  render::Character character;
  rig_plan::RigInput input;  // skeleton, samples and skinned area per node
};

Result<LoadedCharacter> load_rig_character(const std::string& file_or_example);
Status check_plan_matches(const rig_plan::Plan& plan, const rig_plan::RigInput& input);

}  // namespace proprio::cli
