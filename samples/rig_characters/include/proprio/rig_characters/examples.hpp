#pragma once
// Three characters made for the rig device (issue 31), standing in for the
// thesis's downloaded rigs (Fig. 3.9: Dancer 22 bones / 6 poses, Horse 29 / 25,
// Dragon 110 / 12): "humanoid", "quadruped" and "creature". Each is a
// skeleton in metres (Y up, facing +Z, rest rotations identity), named
// sample poses, and a skinned mesh of one tapered capsule per bone with
// weights blended across joints, so skin_area_per_node_m2 gives the thesis's
// node weights. Built deterministically in code; no randomness.
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/render/character.hpp"

namespace proprio::rig_characters {

// The names make_example_character accepts, in a fixed order.
std::vector<std::string> example_character_names();

// Errc::not_found for an unknown name (the message lists the known ones).
Result<render::Character> make_example_character(std::string_view name);

}  // namespace proprio::rig_characters
