#include "proprio/haptics/scene.hpp"

#include <cmath>
#include <set>

namespace proprio::haptics {

std::string_view to_string(ShapeKind kind) noexcept {
  switch (kind) {
    case ShapeKind::box: return "box";
    case ShapeKind::sphere: return "sphere";
    case ShapeKind::cylinder: return "cylinder";
    case ShapeKind::half_cylinder: return "half_cylinder";
    case ShapeKind::capsule: return "capsule";
    case ShapeKind::plate_with_hole: return "plate_with_hole";
  }
  return "unknown";
}

namespace {

bool positive(double v) { return std::isfinite(v) && v > 0.0; }

Error object_error(const SceneObject& o, const std::string& what) {
  return {Errc::invalid_argument,
          "scene object '" + o.name + "' (" + std::string(to_string(o.shape)) + "): " + what};
}

}  // namespace

Status SceneObject::validate() const {
  if (name.empty()) return make_error(Errc::invalid_argument, "a scene object has no name; give each a unique name");
  for (char c : name) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-')) {
      return object_error(*this, "name may only use letters, digits, '_' and '-'");
    }
  }
  if (!T_world_object.p.allFinite() || !T_world_object.q.coeffs().allFinite() ||
      std::abs(T_world_object.q.norm() - 1.0) > 1e-6) {
    return object_error(*this, "pose must be finite with a unit quaternion");
  }
  if (contact_top_plane && (shape != ShapeKind::box || !fixed)) {
    return object_error(*this, "contact_top_plane is for fixed boxes only (a table top)");
  }
  if (hand_touches_capsule && (shape != ShapeKind::cylinder || !(half_length_m > radius_m))) {
    return object_error(*this, "hand_touches_capsule is for cylinders longer than their diameter");
  }
  switch (shape) {
    case ShapeKind::box:
      if (!positive(half_extents_m.x()) || !positive(half_extents_m.y()) || !positive(half_extents_m.z())) {
        return object_error(*this, "half_extents_m must all be > 0 m");
      }
      break;
    case ShapeKind::sphere:
      if (!positive(radius_m)) return object_error(*this, "radius_m must be > 0 m");
      break;
    case ShapeKind::cylinder:
    case ShapeKind::half_cylinder:
    case ShapeKind::capsule:
      if (!positive(radius_m)) return object_error(*this, "radius_m must be > 0 m");
      if (!positive(half_length_m)) return object_error(*this, "half_length_m must be > 0 m");
      break;
    case ShapeKind::plate_with_hole:
      if (!positive(hole_radius_m)) return object_error(*this, "hole_radius_m must be > 0 m");
      if (!positive(half_extents_m.z())) return object_error(*this, "the plate's half thickness (half_extents_m.z) must be > 0 m");
      if (!(half_extents_m.x() > hole_radius_m && half_extents_m.y() > hole_radius_m)) {
        return object_error(*this, "the plate (half_extents_m x, y) must be larger than the hole radius");
      }
      if (hole_segments < 8 || hole_segments > 128) return object_error(*this, "hole_segments must be in [8, 128]");
      break;
  }
  if (!fixed && !positive(mass_kg)) return object_error(*this, "a free object needs mass_kg > 0");
  if (!fixed && shape == ShapeKind::plate_with_hole) {
    return object_error(*this, "a plate with a hole must be fixed (it is built from many boxes)");
  }
  if (!(std::isfinite(friction) && friction >= 0.0 && friction <= 5.0)) {
    return object_error(*this, "friction must be in [0, 5]");
  }
  return {};
}

SceneObject SceneObject::box(std::string name, const Vec3& half_extents_m, const Pose& T_world_object) {
  SceneObject o;
  o.name = std::move(name);
  o.shape = ShapeKind::box;
  o.half_extents_m = half_extents_m;
  o.T_world_object = T_world_object;
  return o;
}

SceneObject SceneObject::sphere(std::string name, double radius_m, const Pose& T_world_object) {
  SceneObject o;
  o.name = std::move(name);
  o.shape = ShapeKind::sphere;
  o.radius_m = radius_m;
  o.T_world_object = T_world_object;
  return o;
}

SceneObject SceneObject::cylinder(std::string name, double radius_m, double half_length_m,
                                  const Pose& T_world_object) {
  SceneObject o;
  o.name = std::move(name);
  o.shape = ShapeKind::cylinder;
  o.radius_m = radius_m;
  o.half_length_m = half_length_m;
  o.T_world_object = T_world_object;
  return o;
}

SceneObject SceneObject::half_cylinder(std::string name, double radius_m, double half_length_m,
                                       const Pose& T_world_object) {
  SceneObject o = cylinder(std::move(name), radius_m, half_length_m, T_world_object);
  o.shape = ShapeKind::half_cylinder;
  return o;
}

SceneObject SceneObject::capsule(std::string name, double radius_m, double half_length_m, const Pose& T_world_object) {
  SceneObject o = cylinder(std::move(name), radius_m, half_length_m, T_world_object);
  o.shape = ShapeKind::capsule;
  return o;
}

SceneObject SceneObject::plate_with_hole(std::string name, double hole_radius_m, const Vec3& half_extents_m,
                                         const Pose& T_world_object) {
  SceneObject o;
  o.name = std::move(name);
  o.shape = ShapeKind::plate_with_hole;
  o.hole_radius_m = hole_radius_m;
  o.half_extents_m = half_extents_m;
  o.T_world_object = T_world_object;
  return o;
}

Status HapticScene::validate() const {
  std::set<std::string> names;
  for (const auto& o : objects) {
    if (auto s = o.validate(); !s) return s;
    if (!names.insert(o.name).second) {
      return make_error(Errc::invalid_argument, "scene object name '" + o.name + "' is used twice; names must be unique");
    }
    if (o.name.rfind("proxy", 0) == 0 || o.name.rfind("target", 0) == 0) {
      return make_error(Errc::invalid_argument, "scene object name '" + o.name +
                                                    "' is reserved (names starting with 'proxy' or 'target' belong to the hand)");
    }
  }
  if (floor_height_m && !std::isfinite(*floor_height_m)) {
    return make_error(Errc::invalid_argument, "floor_height_m must be finite");
  }
  if (!gravity_in_world.allFinite()) return make_error(Errc::invalid_argument, "gravity must be finite");
  return {};
}

const SceneObject* HapticScene::find(std::string_view name) const {
  for (const auto& o : objects) {
    if (o.name == name) return &o;
  }
  return nullptr;
}

HapticScene HapticScene::half_cylinder_study() {
  HapticScene scene;
  // Lying along the world's z (away from the user), curved face up: the
  // object's +y is the curved side. Its axis sits at table height so the top
  // of the curve is at 1.0 m.
  SceneObject c = SceneObject::half_cylinder("half_cylinder", 0.25, 0.25, Pose{Quat::Identity(), Vec3(0.0, 0.75, -0.55)});
  c.rgba = {0.55f, 0.65f, 0.85f, 1.0f};
  scene.objects.push_back(c);
  return scene;
}

HapticScene HapticScene::peg_in_hole(const PegInHoleOptions& o) {
  HapticScene scene;
  const double table_half_thickness = 0.02;
  SceneObject table = SceneObject::box("table", Vec3(0.45, table_half_thickness, 0.30),
                                       Pose{Quat::Identity(), Vec3(0.1, o.table_height_m - table_half_thickness, -0.45)});
  table.rgba = {0.45f, 0.35f, 0.25f, 1.0f};
  table.contact_top_plane = true;
  scene.objects.push_back(table);

  // The peg stands on its base: its axis (object z) along world +y.
  const Quat q_upright(Eigen::AngleAxisd(-M_PI / 2, Vec3::UnitX()));
  SceneObject peg = SceneObject::cylinder("peg", o.peg_radius_m, 0.5 * o.peg_length_m,
                                          Pose{q_upright, o.p_peg_in_world + Vec3(0, 0.5 * o.peg_length_m, 0)});
  peg.fixed = false;
  peg.mass_kg = o.peg_mass_kg;
  peg.rgba = {0.95f, 0.95f, 0.95f, 1.0f};
  // The fingers pinch its side, away from the ends (SceneObject).
  peg.hand_touches_capsule = true;
  scene.objects.push_back(peg);

  // A vertical plate whose hole axis (object z) points along world +x, so the
  // peg goes in sideways (a horizontally placed hole, Lee 2021 Fig. 3.7).
  const Quat q_hole_axis_x(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitY()));
  const double half_thickness = 0.5 * o.plate_thickness_m;
  SceneObject plate = SceneObject::plate_with_hole(
      "hole_plate", o.peg_radius_m + o.clearance_m, Vec3(0.12, 0.12, half_thickness),
      Pose{q_hole_axis_x, o.p_hole_in_world + Vec3(half_thickness, 0, 0)});
  plate.rgba = {0.4f, 0.6f, 0.45f, 1.0f};
  scene.objects.push_back(plate);
  return scene;
}

}  // namespace proprio::haptics
