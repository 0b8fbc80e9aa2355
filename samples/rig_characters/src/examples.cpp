#include "proprio/rig_characters/examples.hpp"

#include "character_builder.hpp"

namespace proprio::rig_characters {

std::vector<std::string> example_character_names() { return {"humanoid", "quadruped", "creature"}; }

Result<render::Character> make_example_character(std::string_view name) {
  if (name == "humanoid") return detail::make_humanoid();
  if (name == "quadruped") return detail::make_quadruped();
  if (name == "creature") return detail::make_creature();
  return make_error(Errc::not_found, "no example character '" + std::string(name) +
                                         "'; the examples are humanoid, quadruped and creature");
}

}  // namespace proprio::rig_characters
