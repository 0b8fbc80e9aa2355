#pragma once
// What the engine shows and simulates: entities with a pose, a mesh (one of
// the haptic scene's primitives, the peg's bottle, or a glTF file), a colour,
// and optionally a physics body (fixed or free) that the proxy hand touches.
// Built in code or loaded from a scene file (TOML; docs/engine.md):
//
//   name = "my scene"
//   preset = "half-cylinder"        # optional: start from a built-in scene
//   floor_height = 0.0              # optional: a ground plane at this height
//   focus = [0.0, 1.0, -0.55]       # where cameras look and scripted hands touch
//   [[object]]
//   name = "cup"
//   shape = "cylinder"              # box sphere cylinder half_cylinder capsule plate_with_hole peg gltf
//   radius = 0.04
//   half_length = 0.05
//   position = [0.1, 1.0, -0.5]     # metres, world (+Y up)
//   rotation_deg = [-90, 0, 0]      # about x, then y, then z (world axes)
//   color = [0.9, 0.9, 0.95]        # linear RGB(A), 0-1
//   physics = "free"                # fixed (default), free, or none (drawn only)
//   mass = 0.2                      # kg, free bodies
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/haptics/scene.hpp"

namespace proprio::engine {

enum class Physics { none, fixed, free };

struct Entity {
  // Geometry, pose, colour and physical properties; `body.fixed` follows `physics`.
  haptics::SceneObject body;
  Physics physics = Physics::fixed;
  bool peg_visual = false;                 // draw a cylinder as the bevelled bottle
  std::optional<std::filesystem::path> gltf;  // drawn from this file instead (physics must be none)
};

struct Scene {
  std::string name;
  std::vector<Entity> entities;
  std::optional<double> floor_height_m;
  Vec3 p_focus_in_world = Vec3(0.0, 1.0, -0.5);

  Status validate() const;
  const Entity* find(std::string_view name) const;
  // The bodies MuJoCo simulates (entities with physics), in entity order.
  haptics::HapticScene haptic_scene() const;

  // Built-in scenes: "half-cylinder" (the perception study's target),
  // "peg-in-hole", "table", "empty".
  static Result<Scene> preset(std::string_view name);
  static std::vector<std::string> preset_names();
  static Scene from_haptic_scene(std::string name, const haptics::HapticScene& scene, const Vec3& p_focus_in_world);
  // A preset name or a .toml file. Errors name the file, the object and the key.
  static Result<Scene> load(const std::string& preset_or_file);
  static Result<Scene> parse(std::string_view toml_text, const std::string& source_name,
                             const std::filesystem::path& base_dir = {});
};

}  // namespace proprio::engine
