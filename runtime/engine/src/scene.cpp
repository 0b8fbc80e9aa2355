#include "proprio/engine/scene.hpp"

#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

#include "proprio/core/config.hpp"
#include "proprio/core/file_io.hpp"

namespace proprio::engine {
namespace {

using haptics::SceneObject;
using haptics::ShapeKind;

// The first error among several parsed values, in argument order.
template <typename... Results>
Status first_error(const Results&... results) {
  Status status;
  ((status = (status.ok() && !results.ok()) ? Status(results.error()) : status), ...);
  return status;
}

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

Result<Vec3> get_vec3(const Config& c, std::string_view key, const Vec3& fallback) {
  if (!c.contains(key)) return fallback;
  auto v = c.get_doubles(key);
  if (!v) return v.error();
  if (v->size() != 3) {
    return make_error(Errc::invalid_argument, fmt::format("{}: '{}' needs 3 numbers, got {}", c.where(key), key,
                                                          v->size()));
  }
  const Vec3 out((*v)[0], (*v)[1], (*v)[2]);
  if (!out.allFinite()) return make_error(Errc::invalid_argument, c.where(key) + ": not finite");
  return out;
}

struct ShapeName {
  const char* name;
  ShapeKind kind;
};
constexpr ShapeName kShapes[] = {{"box", ShapeKind::box},
                                 {"sphere", ShapeKind::sphere},
                                 {"cylinder", ShapeKind::cylinder},
                                 {"half_cylinder", ShapeKind::half_cylinder},
                                 {"capsule", ShapeKind::capsule},
                                 {"plate_with_hole", ShapeKind::plate_with_hole}};

Result<Entity> parse_object(const Config& c, const std::filesystem::path& base_dir) {
  Entity e;
  if (auto k = c.check_keys("object", {"name", "shape", "file", "radius", "half_length", "hole_radius",
                                       "half_extents", "position", "rotation_deg", "mass", "friction", "physics",
                                       "color"});
      !k) {
    return k.error();
  }
  auto name = c.get_string("name");
  if (!name) return name.error();
  auto shape = c.get_string("shape");
  if (!shape) return shape.error();
  SceneObject& b = e.body;
  b.name = *name;
  bool known = false;
  for (const auto& s : kShapes) {
    if (*shape == s.name) {
      b.shape = s.kind;
      known = true;
    }
  }
  if (*shape == "peg") {  // physics: a cylinder; drawn as the bottle
    b.shape = ShapeKind::cylinder;
    e.peg_visual = true;
    known = true;
  }
  if (*shape == "gltf") {
    auto file = c.get_string("file");
    if (!file) return file.error().with_context("object '" + b.name + "' (shape gltf)");
    e.gltf = std::filesystem::path(*file).is_absolute() ? std::filesystem::path(*file) : base_dir / *file;
    known = true;
  }
  if (!known) {
    return make_error(Errc::invalid_argument,
                      fmt::format("{}: object '{}' has shape '{}'; expected box, sphere, cylinder, half_cylinder, "
                                  "capsule, plate_with_hole, peg or gltf",
                                  c.where("shape"), b.name, *shape));
  }
  auto radius = c.get_double_or("radius", b.radius_m, 1e-4, 100.0);
  auto half_length = c.get_double_or("half_length", b.half_length_m, 1e-4, 100.0);
  auto hole = c.get_double_or("hole_radius", b.hole_radius_m, 0.0, 100.0);
  auto half_extents = get_vec3(c, "half_extents", b.half_extents_m);
  auto position = get_vec3(c, "position", Vec3::Zero());
  auto rotation = get_vec3(c, "rotation_deg", Vec3::Zero());
  auto mass = c.get_double_or("mass", b.mass_kg, 1e-4, 1e4);
  auto friction = c.get_double_or("friction", b.friction, 0.0, 10.0);
  auto physics = c.get_string_or("physics", e.gltf ? "none" : "fixed");
  if (auto s = first_error(radius, half_length, hole, half_extents, position, rotation, mass, friction, physics); !s) {
    return s.error().with_context("object '" + b.name + "'");
  }
  b.radius_m = *radius;
  b.half_length_m = *half_length;
  b.hole_radius_m = *hole;
  b.half_extents_m = *half_extents;
  b.mass_kg = *mass;
  b.friction = *friction;
  const Vec3 r = *rotation * kDegToRad;
  const Quat q = Eigen::AngleAxisd(r.z(), Vec3::UnitZ()) * Eigen::AngleAxisd(r.y(), Vec3::UnitY()) *
                 Eigen::AngleAxisd(r.x(), Vec3::UnitX());
  b.T_world_object = Pose{q.normalized(), *position};
  if (c.contains("color")) {
    auto color = c.get_doubles("color");
    if (!color) return color.error();
    if (color->size() != 3 && color->size() != 4) {
      return make_error(Errc::invalid_argument, c.where("color") + ": color needs 3 or 4 numbers in [0, 1]");
    }
    for (std::size_t i = 0; i < color->size(); ++i) {
      if (!((*color)[i] >= 0.0 && (*color)[i] <= 1.0)) {
        return make_error(Errc::invalid_argument, c.where("color") + ": color components must be in [0, 1]");
      }
      b.rgba[i] = static_cast<float>((*color)[i]);
    }
  }
  if (*physics == "none") {
    e.physics = Physics::none;
  } else if (*physics == "fixed") {
    e.physics = Physics::fixed;
  } else if (*physics == "free") {
    e.physics = Physics::free;
  } else {
    return make_error(Errc::invalid_argument, fmt::format("{}: physics '{}': expected fixed, free or none",
                                                          c.where("physics"), *physics));
  }
  b.fixed = e.physics != Physics::free;
  return e;
}

}  // namespace

Status Scene::validate() const {
  std::set<std::string> names;
  for (const Entity& e : entities) {
    if (!names.insert(e.body.name).second) {
      return make_error(Errc::invalid_argument, fmt::format("scene '{}': two objects are named '{}'", name, e.body.name));
    }
    if (e.gltf && e.physics != Physics::none) {
      return make_error(Errc::invalid_argument, fmt::format("scene '{}': object '{}' is a glTF mesh, which is drawn "
                                                            "only; set physics = \"none\"", name, e.body.name));
    }
    if (e.physics != Physics::none || !e.gltf) {
      if (auto s = e.body.validate(); !s) return s.error().with_context("scene '" + name + "'");
    }
  }
  if (!p_focus_in_world.allFinite()) return make_error(Errc::invalid_argument, "scene focus is not finite");
  return {};
}

const Entity* Scene::find(std::string_view n) const {
  for (const Entity& e : entities) {
    if (e.body.name == n) return &e;
  }
  return nullptr;
}

haptics::HapticScene Scene::haptic_scene() const {
  haptics::HapticScene h;
  h.floor_height_m = floor_height_m;
  for (const Entity& e : entities) {
    if (e.physics != Physics::none) h.objects.push_back(e.body);
  }
  return h;
}

Scene Scene::from_haptic_scene(std::string scene_name, const haptics::HapticScene& hs, const Vec3& p_focus_in_world) {
  Scene s;
  s.name = std::move(scene_name);
  s.floor_height_m = hs.floor_height_m;
  s.p_focus_in_world = p_focus_in_world;
  for (const auto& o : hs.objects) {
    Entity e;
    e.body = o;
    e.physics = o.fixed ? Physics::fixed : Physics::free;
    e.peg_visual = o.name == "peg";
    s.entities.push_back(e);
  }
  return s;
}

std::vector<std::string> Scene::preset_names() { return {"half-cylinder", "peg-in-hole", "table", "empty"}; }

Result<Scene> Scene::preset(std::string_view n) {
  if (n == "half-cylinder") {
    const auto hs = haptics::HapticScene::half_cylinder_study();
    const SceneObject& c = *hs.find("half_cylinder");
    return from_haptic_scene("half-cylinder", hs, c.T_world_object.p + Vec3(0, c.radius_m, 0));
  }
  if (n == "peg-in-hole") {
    const auto hs = haptics::HapticScene::peg_in_hole();
    const SceneObject& peg = *hs.find("peg");
    return from_haptic_scene("peg-in-hole", hs, peg.T_world_object.p + Vec3(0, peg.half_length_m, 0));
  }
  if (n == "table") {
    haptics::HapticScene hs;
    SceneObject table = SceneObject::box("table", Vec3(0.4, 0.02, 0.4), Pose{Quat::Identity(), Vec3(0, 0.98, -0.55)});
    table.rgba = {0.45f, 0.35f, 0.25f, 1.0f};
    hs.objects.push_back(table);
    return from_haptic_scene("table", hs, Vec3(0, 1.0, -0.55));
  }
  if (n == "empty") return from_haptic_scene("empty", haptics::HapticScene{}, Vec3(0, 1.0, -0.5));
  return make_error(Errc::not_found, fmt::format("no built-in scene '{}' (built in: half-cylinder, peg-in-hole, "
                                                 "table, empty; or give a .toml scene file)", n));
}

Result<Scene> Scene::parse(std::string_view toml_text, const std::string& source_name,
                           const std::filesystem::path& base_dir) {
  auto cfg = Config::parse(toml_text, source_name);
  if (!cfg) return cfg.error();
  if (auto k = cfg->check_keys("top level", {"preset", "name", "floor_height", "focus", "object"}); !k) {
    return k.error();
  }
  Scene scene;
  auto preset_name = cfg->get_string_or("preset", "empty");
  if (!preset_name) return preset_name.error();
  auto base = preset(*preset_name);
  if (!base) return base.error().with_context(cfg->where("preset"));
  scene = std::move(base).value();
  auto name = cfg->get_string_or("name", std::filesystem::path(source_name).stem().string());
  if (!name) return name.error();
  scene.name = *name;
  if (cfg->contains("floor_height")) {
    auto floor = cfg->get_double("floor_height");
    if (!floor) return floor.error();
    scene.floor_height_m = *floor;
  }
  auto focus = get_vec3(*cfg, "focus", scene.p_focus_in_world);
  if (!focus) return focus.error();
  scene.p_focus_in_world = *focus;
  if (cfg->contains("object")) {
    auto objects = cfg->tables("object");
    if (!objects) return objects.error();
    for (const Config& o : *objects) {
      auto e = parse_object(o, base_dir);
      if (!e) return e.error();
      scene.entities.push_back(std::move(e).value());
    }
  }
  if (auto s = scene.validate(); !s) return s.error().with_context(source_name);
  return scene;
}

Result<Scene> Scene::load(const std::string& preset_or_file) {
  const std::filesystem::path path(preset_or_file);
  if (path.extension() != ".toml") return preset(preset_or_file);
  auto text = read_input_file(path, "scene file", 16 * kMiB);
  if (!text) return text.error();
  return parse(*text, path.string(), path.parent_path());
}

}  // namespace proprio::engine
