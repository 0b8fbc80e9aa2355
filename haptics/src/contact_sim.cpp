#include "proprio/haptics/contact_sim.hpp"

#include <mujoco/mujoco.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iomanip>
#include <mutex>
#include <sstream>
#include <vector>

#include "proprio/core/log.hpp"

namespace proprio::haptics {

// ---------------------------------------------------------------------------
// Options.

std::string CouplingOptions::describe() const {
  std::ostringstream s;
  s << "coupling: wrist weld tau " << wrist_time_constant_s * 1e3 << " ms, zeta " << wrist_damping_ratio
    << ", impedance " << wrist_impedance << ", leash " << wrist_max_offset_m * 1e3 << " mm / "
    << rad_to_deg(wrist_max_offset_rad) << " deg, resync beyond " << resync_distance_m * 1e3 << " mm; joints k "
    << joint_stiffness_nm_per_rad << " N m/rad, c " << joint_damping_nms_per_rad << " N m s/rad, armature "
    << joint_armature_kg_m2 << " kg m^2, torque limit " << joint_max_torque_nm << " N m";
  return s.str();
}

namespace {

Status bad_option(const std::string& name, const std::string& rule, double value) {
  std::ostringstream s;
  s << "haptics option " << name << " = " << value << ": " << rule;
  return make_error(Errc::invalid_argument, s.str());
}

bool finite_positive(double v) { return std::isfinite(v) && v > 0.0; }

}  // namespace

Status CouplingOptions::validate() const {
  if (!finite_positive(wrist_time_constant_s)) return bad_option("wrist_time_constant_s", "must be > 0 s", wrist_time_constant_s);
  if (!finite_positive(wrist_damping_ratio)) return bad_option("wrist_damping_ratio", "must be > 0", wrist_damping_ratio);
  if (!(wrist_impedance > 0.0 && wrist_impedance < 1.0)) {
    return bad_option("wrist_impedance", "must be in (0, 1) (MuJoCo solimp)", wrist_impedance);
  }
  if (!finite_positive(wrist_max_offset_m)) return bad_option("wrist_max_offset_m", "must be > 0 m", wrist_max_offset_m);
  if (!finite_positive(wrist_max_offset_rad)) return bad_option("wrist_max_offset_rad", "must be > 0 rad", wrist_max_offset_rad);
  if (!(std::isfinite(resync_distance_m) && resync_distance_m >= 0.0)) {
    return bad_option("resync_distance_m", "must be >= 0 m (0 disables)", resync_distance_m);
  }
  if (!finite_positive(joint_stiffness_nm_per_rad)) return bad_option("joint_stiffness_nm_per_rad", "must be > 0", joint_stiffness_nm_per_rad);
  if (!(std::isfinite(joint_damping_nms_per_rad) && joint_damping_nms_per_rad >= 0.0)) {
    return bad_option("joint_damping_nms_per_rad", "must be >= 0", joint_damping_nms_per_rad);
  }
  if (!(std::isfinite(joint_armature_kg_m2) && joint_armature_kg_m2 >= 0.0)) {
    return bad_option("joint_armature_kg_m2", "must be >= 0", joint_armature_kg_m2);
  }
  if (!finite_positive(joint_max_torque_nm)) return bad_option("joint_max_torque_nm", "must be > 0 N m", joint_max_torque_nm);
  return {};
}

std::string ContactSimOptions::describe() const {
  std::ostringstream s;
  s << "contact sim: step " << timestep_s * 1e3 << " ms, Newton solver, sparse Jacobian, elliptic cone, impratio " << impratio
    << ", " << solver_iterations << " iterations, tolerance " << solver_tolerance << ", multiccd "
    << (multiccd ? "on" : "off") << "; contacts condim " << (torsional_friction ? "4 (torsional friction)" : "3")
    << ", tau "
    << contact_time_constant_s * 1e3 << " ms, impedance " << contact_impedance_min << " -> " << contact_impedance_max
    << " over " << contact_impedance_width_m * 1e3 << " mm; fingertip force filter " << force_filter_time_constant_s * 1e3
    << " ms\n  " << coupling.describe();
  return s.str();
}

Status ContactSimOptions::validate() const {
  if (!(timestep_s >= 1e-4 && timestep_s <= 0.01)) return bad_option("timestep_s", "must be in [0.1, 10] ms", timestep_s);
  if (auto s = coupling.validate(); !s) return s;
  // MuJoCo clamps solref time constants below 2 timesteps (refsafe): say so
  // instead of silently getting a softer simulation than configured.
  if (!(coupling.wrist_time_constant_s >= 2.0 * timestep_s)) {
    return bad_option("wrist_time_constant_s", "must be >= 2 timesteps (MuJoCo's stability floor)", coupling.wrist_time_constant_s);
  }
  if (!(contact_time_constant_s >= 2.0 * timestep_s)) {
    return bad_option("contact_time_constant_s", "must be >= 2 timesteps (MuJoCo's stability floor)", contact_time_constant_s);
  }
  if (!(contact_impedance_min > 0.0 && contact_impedance_min <= contact_impedance_max && contact_impedance_max < 1.0)) {
    return bad_option("contact_impedance_min/max", "need 0 < min <= max < 1", contact_impedance_min);
  }
  if (!finite_positive(contact_impedance_width_m)) return bad_option("contact_impedance_width_m", "must be > 0 m", contact_impedance_width_m);
  if (!(impratio >= 1.0 && impratio <= 100.0)) return bad_option("impratio", "must be in [1, 100]", impratio);
  if (solver_iterations < 1 || solver_iterations > 1000) {
    return bad_option("solver_iterations", "must be in [1, 1000]", solver_iterations);
  }
  if (!(solver_tolerance >= 1e-12 && solver_tolerance <= 1e-3)) {
    return bad_option("solver_tolerance", "must be in [1e-12, 1e-3]", solver_tolerance);
  }
  if (!finite_positive(hand_density_kg_m3)) return bad_option("hand_density_kg_m3", "must be > 0", hand_density_kg_m3);
  if (!(force_filter_time_constant_s >= 0.0 && force_filter_time_constant_s <= 0.05)) {
    return bad_option("force_filter_time_constant_s", "must be in [0, 50] ms", force_filter_time_constant_s);
  }
  if (collider_slots < 0 || collider_slots > kMaxColliderSlots) {
    return bad_option("collider_slots", "must be in [0, " + std::to_string(kMaxColliderSlots) + "]", collider_slots);
  }
  return {};
}

// ---------------------------------------------------------------------------
// MJCF generation.

namespace {

// Left hands mirror the right through the wrist frame's YZ plane (HandModel).
Pose mirrored(const Pose& T) { return {Quat(T.q.w(), T.q.x(), -T.q.y(), -T.q.z()), Vec3(-T.p.x(), T.p.y(), T.p.z())}; }

// Names of one hand's bodies, joints and geoms start with its prefix: none
// in a one-hand world (the names `proprio haptics mjcf` always printed),
// "left_"/"right_" with two.
std::string hand_prefix(std::span<const ProxyHandSpec> hands, std::size_t h) {
  if (hands.size() == 1) return {};
  return hands[h].hand == Handedness::left ? "left_" : "right_";
}

// Per DOF: the hinge's name.
std::string dof_joint_name(const std::string& pre, std::size_t dof) {
  return pre + "proxy_" + std::string(to_string(static_cast<HandDof>(dof)));
}

struct Mjcf {
  std::ostringstream s;
  Mjcf() { s << std::setprecision(9); }
  Mjcf& vec(const Vec3& v) {
    s << v.x() << ' ' << v.y() << ' ' << v.z();
    return *this;
  }
  Mjcf& quat(const Quat& q) {
    s << q.w() << ' ' << q.x() << ' ' << q.y() << ' ' << q.z();
    return *this;
  }
  Mjcf& pose_attrs(const Pose& T) {
    s << " pos=\"";
    vec(T.p);
    s << "\" quat=\"";
    quat(T.q);
    s << '"';
    return *this;
  }
  Mjcf& rgba(const std::array<float, 4>& c) {
    s << " rgba=\"" << c[0] << ' ' << c[1] << ' ' << c[2] << ' ' << c[3] << '"';
    return *this;
  }
};

// Object geoms are in contact group 1 and touch everything; hand geoms
// (contype 2) touch objects but not each other.
constexpr const char* kObjectContact = R"( contype="1" conaffinity="3")";
constexpr const char* kHandContact = R"( contype="2" conaffinity="1")";
// A cylinder whose hand contacts go to its capsule (hand_touches_capsule):
// the cylinder meets objects (bit 1) and other such cylinders (bit 4), never
// the hand (bit 2); the capsule meets only the hand.
constexpr const char* kObjectOnlyContact = R"( contype="4" conaffinity="5")";
constexpr const char* kHandOnlyContact = R"( contype="0" conaffinity="2")";

void half_cylinder_mesh(Mjcf& m, const SceneObject& o) {
  // The +y half of a cylinder along z: a convex solid, so MuJoCo's convex
  // hull collision is exact up to the tessellation (64 facets over 180 deg:
  // the chord sits at most r(1 - cos(1.4 deg)) = 0.3 mm * r/1m inside).
  constexpr int kArc = 64;
  m.s << "    <mesh name=\"" << o.name << "_mesh\" vertex=\"";
  for (int end = -1; end <= 1; end += 2) {
    for (int i = 0; i <= kArc; ++i) {
      const double a = M_PI * i / kArc;
      m.vec(Vec3(o.radius_m * std::cos(a), o.radius_m * std::sin(a), end * o.half_length_m));
      m.s << ' ';
    }
  }
  m.s << "\"/>\n";
}

void object_geoms(Mjcf& m, const SceneObject& o, const std::string& indent) {
  const auto common = [&](const std::string& geom_name, const char* contact = kObjectContact) {
    m.s << " name=\"" << geom_name << "\" friction=\"" << o.friction << " 0.005 0.0001\"" << contact;
    m.rgba(o.rgba);
  };
  switch (o.shape) {
    case ShapeKind::box:
      if (o.contact_top_plane) {
        // The plane's normal (its z) is the box's +y; its size only sets how MuJoCo draws it.
        m.s << indent << "<geom type=\"plane\" size=\"" << o.half_extents_m.x() << ' ' << o.half_extents_m.z()
            << " 1\" pos=\"0 " << o.half_extents_m.y() << " 0\" zaxis=\"0 1 0\"";
      } else {
        m.s << indent << "<geom type=\"box\" size=\"";
        m.vec(o.half_extents_m);
        m.s << '"';
      }
      common(o.name);
      m.s << "/>\n";
      break;
    case ShapeKind::sphere:
      m.s << indent << "<geom type=\"sphere\" size=\"" << o.radius_m << '"';
      common(o.name);
      m.s << "/>\n";
      break;
    case ShapeKind::cylinder:
    case ShapeKind::capsule:
      m.s << indent << "<geom type=\"" << (o.shape == ShapeKind::cylinder ? "cylinder" : "capsule") << "\" size=\""
          << o.radius_m << ' ' << o.half_length_m << '"';
      if (o.hand_touches_capsule) {
        common(o.name, kObjectOnlyContact);
        m.s << "/>\n" << indent << "<geom type=\"capsule\" size=\"" << o.radius_m << ' ' << o.half_length_m - o.radius_m << '"';
        common(o.name + "_hand", kHandOnlyContact);
        m.s << "/>\n";
        break;
      }
      common(o.name);
      m.s << "/>\n";
      break;
    case ShapeKind::half_cylinder:
      m.s << indent << "<geom type=\"mesh\" mesh=\"" << o.name << "_mesh\"";
      common(o.name);
      m.s << "/>\n";
      break;
    case ShapeKind::plate_with_hole: {
      // A ring of boxes whose inner faces circumscribe the hole (a peg of the
      // hole's radius fits exactly), reaching out to S*sqrt(2) so the four
      // outer slabs beyond S close the plate without gaps at the diagonals.
      const int n = o.hole_segments;
      const double a = M_PI / n;
      const double r = o.hole_radius_m;
      const double slab_start = r + 0.01;
      const double ring_out = slab_start * std::sqrt(2.0) + 0.002;
      const double hz = o.half_extents_m.z();
      const double radial_half = 0.5 * (ring_out - r);
      const double tangential_half = ring_out * std::tan(a) + 0.001;
      // A fixed plate's ring is a body of its own: MuJoCo 2.2.2 has no
      // mid-phase, so every hand segment the broad phase finds near the
      // plate's body is tested against each of its geoms. The slabs' body
      // spans the plate, the ring's only the hole.
      std::string ring_indent = indent;
      if (o.fixed) {
        m.s << indent << "<body name=\"" << o.name << "_ring\">\n";
        ring_indent += "  ";
      }
      for (int i = 0; i < n; ++i) {
        const double phi = 2.0 * a * i;
        const Vec3 centre((r + radial_half) * std::cos(phi), (r + radial_half) * std::sin(phi), 0.0);
        const Quat q(Eigen::AngleAxisd(phi, Vec3::UnitZ()));
        m.s << ring_indent << "<geom type=\"box\" size=\"" << radial_half << ' ' << tangential_half << ' ' << hz << '"';
        m.pose_attrs({q, centre});
        common(o.name + "_ring" + std::to_string(i));
        m.s << "/>\n";
      }
      if (o.fixed) m.s << indent << "</body>\n";
      const double X = o.half_extents_m.x(), Y = o.half_extents_m.y();
      const double S = slab_start;
      struct Slab { Vec3 centre, half; };
      const Slab slabs[] = {
          {Vec3(-0.5 * (X + S), 0, 0), Vec3(0.5 * (X - S), Y, hz)},
          {Vec3(0.5 * (X + S), 0, 0), Vec3(0.5 * (X - S), Y, hz)},
          {Vec3(0, 0.5 * (Y + S), 0), Vec3(S, 0.5 * (Y - S), hz)},
          {Vec3(0, -0.5 * (Y + S), 0), Vec3(S, 0.5 * (Y - S), hz)},
      };
      int k = 0;
      for (const Slab& sl : slabs) {
        m.s << indent << "<geom type=\"box\" size=\"";
        m.vec(sl.half);
        m.s << "\" pos=\"";
        m.vec(sl.centre);
        m.s << '"';
        common(o.name + "_slab" + std::to_string(k++));
        m.s << "/>\n";
      }
      break;
    }
  }
}

Status check_plate(const SceneObject& o) {
  if (o.shape != ShapeKind::plate_with_hole) return {};
  const double ring_out = (o.hole_radius_m + 0.01) * std::sqrt(2.0) + 0.002;
  if (o.half_extents_m.x() < ring_out || o.half_extents_m.y() < ring_out) {
    std::ostringstream s;
    s << "scene object '" << o.name << "': the plate's half extents must be at least " << ring_out * 1e3
      << " mm for a hole of radius " << o.hole_radius_m * 1e3 << " mm";
    return make_error(Errc::invalid_argument, s.str());
  }
  return {};
}

}  // namespace

Result<std::string> generate_mjcf(const HandModel& hand_model, Handedness hand, const HapticScene& scene,
                                  const ContactSimOptions& o) {
  const ProxyHandSpec one[] = {{hand_model, hand}};
  return generate_mjcf(one, scene, o);
}

namespace {

// One proxy hand and its coupling target, inside <worldbody>.
void proxy_hand_bodies(Mjcf& m, const ProxyHandSpec& spec, const std::string& pre, const ContactSimOptions& o) {
  const HandModel& hand_model = spec.model;
  const HandShape& shape = hand_model.shape();
  const JointLimits& limits = hand_model.limits();
  const bool left = spec.hand == Handedness::left;
  const auto side = [&](const Pose& T) { return left ? mirrored(T) : T; };
  // The coupling target, placed each step at the (leashed) tracked wrist.
  m.s << "    <body name=\"" << pre << "target_wrist\" mocap=\"true\"/>\n";
  // The proxy hand. Zero angles at the world origin; ContactSimulation places it.
  const auto T_wrist_joint = hand_model.joint_poses_in_wrist(Handedness::right, HandAngles{});
  auto joint_p = [&](HandJoint j) { return T_wrist_joint[index_of(j)].p; };
  m.s << "    <body name=\"" << pre << "proxy_wrist\">\n"
      << "      <freejoint name=\"" << pre << "proxy_root\"/>\n";
  {
    // The palm: a box from the wrist to the knuckles, as wide as index to little.
    const Vec3 pi = joint_p(HandJoint::index_proximal), pl = joint_p(HandJoint::little_proximal);
    const Vec3 pm = joint_p(HandJoint::middle_proximal);
    const double r = shape.fingers[1].joint_radius_m[1];
    const Vec3 centre(0.5 * (pi.x() + pl.x()), 0.0, 0.5 * pm.z());
    const Vec3 half(0.5 * std::abs(pi.x() - pl.x()) + r, 0.6 * shape.palm_radius_m, 0.5 * std::abs(pm.z()));
    m.s << "      <geom name=\"" << pre << "proxy_palm\" type=\"box\" size=\"";
    m.vec(half);
    m.s << "\" pos=\"";
    m.vec(left ? Vec3(-centre.x(), centre.y(), centre.z()) : centre);
    m.s << "\" density=\"" << o.hand_density_kg_m3 << "\" friction=\"0.1 0.005 0.0001\"" << kHandContact
        << " rgba=\"0.9 0.75 0.65 1\"/>\n";
  }
  const Vec3 abd_axis = left ? Vec3(0, -1, 0) : Vec3(0, 1, 0);
  const auto hinge = [&](std::size_t dof, const Vec3& axis, const std::string& indent) {
    m.s << indent << "<joint name=\"" << dof_joint_name(pre, dof) << "\" type=\"hinge\" axis=\"";
    m.vec(axis);
    m.s << "\" limited=\"true\" range=\"" << limits.min_rad[dof] << ' ' << limits.max_rad[dof] << "\" damping=\""
        << o.coupling.joint_damping_nms_per_rad << "\" armature=\"" << o.coupling.joint_armature_kg_m2 << "\"/>\n";
  };
  const auto segment = [&](const std::string& name, double length, double radius, const std::string& indent) {
    m.s << indent << "<geom name=\"" << name << "\" type=\"capsule\" fromto=\"0 0 0 0 0 " << -length << "\" size=\""
        << radius << "\" density=\"" << o.hand_density_kg_m3 << "\" friction=\"0.1 0.005 0.0001\"" << kHandContact
        << " rgba=\"0.9 0.75 0.65 1\"/>\n";
  };
  const Vec3 flex_axis(-1, 0, 0);  // flexion is a negative rotation about +X (HandModel)
  for (std::size_t fi = 0; fi < kFingerCount; ++fi) {
    const auto f = static_cast<Finger>(fi);
    const HandShape::Finger& g = shape.fingers[fi];
    const std::size_t d = first_dof_of(f);
    const std::string fname(to_string(f));
    const auto radius = [&](std::size_t k) { return 0.5 * (g.joint_radius_m[k] + g.joint_radius_m[k + 1]); };
    std::string indent = "      ";
    std::size_t bones_open = 0;
    // The thumb's chain starts at its metacarpal (CMC: abduction then
    // flexion; then MCP, IP). A finger's metacarpal is inside the palm box,
    // so its chain starts at the proximal bone (MCP: abduction then flexion;
    // then PIP, DIP). `first` is the first body's index into bone_length_m.
    static constexpr const char* kThumbBones[] = {"metacarpal", "proximal", "distal"};
    static constexpr const char* kFingerBones[] = {"proximal", "intermediate", "distal"};
    const bool thumb = f == Finger::thumb;
    const char* const* bones = thumb ? kThumbBones : kFingerBones;
    const std::size_t first = thumb ? 0 : 1;
    const Quat q_rest = g.q_wrist_metacarpal_rest;
    const Pose T_wrist_first{q_rest, thumb ? g.p_base_in_wrist
                                           : g.p_base_in_wrist + q_rest * Vec3(0, 0, -g.bone_length_m[0])};
    for (std::size_t k = 0; k < 3; ++k) {
      const std::size_t b = first + k;
      const Pose T_local = k == 0 ? side(T_wrist_first) : Pose{Quat::Identity(), Vec3(0, 0, -g.bone_length_m[b - 1])};
      m.s << indent << "<body name=\"" << pre << "proxy_" << fname << '_' << bones[k] << '"';
      m.pose_attrs(T_local);
      m.s << ">\n";
      indent += "  ";
      if (k == 0) {
        hinge(d + 1, abd_axis, indent);
        hinge(d + 0, flex_axis, indent);
      } else {
        hinge(d + 1 + k, flex_axis, indent);
      }
      segment(pre + "proxy_" + fname + '_' + bones[k], g.bone_length_m[b], radius(b), indent);
      ++bones_open;
    }
    while (bones_open-- > 0) {
      indent.resize(indent.size() - 2);
      m.s << indent << "</body>\n";
    }
  }
  m.s << "    </body>\n";
}

// One proxy hand's wrist weld (inside <equality>) and joint servos (inside <actuator>).
void proxy_hand_weld(Mjcf& m, const std::string& pre, const ContactSimOptions& o) {
  const CouplingOptions& c = o.coupling;
  m.s << "    <weld name=\"" << pre << "wrist_coupling\" body1=\"" << pre << "proxy_wrist\" body2=\"" << pre
      << "target_wrist\" solref=\"" << c.wrist_time_constant_s << ' ' << c.wrist_damping_ratio << "\" solimp=\""
      << c.wrist_impedance << ' ' << c.wrist_impedance << " 0.001\"/>\n";
}

void proxy_hand_servos(Mjcf& m, const ProxyHandSpec& spec, const std::string& pre, const ContactSimOptions& o) {
  const CouplingOptions& c = o.coupling;
  const JointLimits& limits = spec.model.limits();
  for (std::size_t dof = 0; dof < kHandDofCount; ++dof) {
    m.s << "    <position name=\"" << dof_joint_name(pre, dof) << "_servo\" joint=\"" << dof_joint_name(pre, dof)
        << "\" kp=\"" << c.joint_stiffness_nm_per_rad << "\" ctrllimited=\"true\" ctrlrange=\"" << limits.min_rad[dof]
        << ' ' << limits.max_rad[dof] << "\" forcelimited=\"true\" forcerange=\"" << -c.joint_max_torque_nm << ' '
        << c.joint_max_torque_nm << "\"/>\n";
  }
}

// A collider slot: a mocap body parked far below the floor (contacts
// between two static bodies are never made, so it touches nothing there).
constexpr double kParkedY = -1000.0;

}  // namespace

Status ColliderShape::validate() const {
  const ColliderShape& o = *this;
  switch (o.shape) {
    case ShapeKind::sphere:
    case ShapeKind::box:
    case ShapeKind::capsule:
    case ShapeKind::cylinder: break;
    default:
      return make_error(Errc::invalid_argument, "a collider is a sphere, box, capsule or cylinder, not a " +
                                                    std::string(to_string(o.shape)));
  }
  const auto size_ok = [](double v) { return std::isfinite(v) && v >= 1e-4 && v <= 10.0; };
  if (o.shape == ShapeKind::box) {
    for (int k = 0; k < 3; ++k) {
      if (!size_ok(o.half_extents_m[k])) {
        return make_error(Errc::invalid_argument, "a box collider's half extents must be in [0.1 mm, 10 m]");
      }
    }
  } else if (!size_ok(o.radius_m)) {
    return make_error(Errc::invalid_argument, "a collider's radius must be in [0.1 mm, 10 m]");
  }
  if ((o.shape == ShapeKind::capsule || o.shape == ShapeKind::cylinder) && !size_ok(o.half_length_m)) {
    return make_error(Errc::invalid_argument, "a capsule or cylinder collider's half length must be in [0.1 mm, 10 m]");
  }
  if (!(std::isfinite(o.friction) && o.friction >= 0.0 && o.friction <= 2.0)) {
    return make_error(Errc::invalid_argument, "a collider's friction must be in [0, 2]");
  }
  return {};
}

Result<std::string> generate_mjcf(std::span<const ProxyHandSpec> hands, const HapticScene& scene,
                                  const ContactSimOptions& o) {
  if (auto s = o.validate(); !s) return s.error();
  if (auto s = scene.validate(); !s) return s.error();
  for (const auto& obj : scene.objects) {
    if (auto s = check_plate(obj); !s) return s.error();
  }
  if (hands.empty() || hands.size() > kMaxProxyHands ||
      (hands.size() == 2 && hands[0].hand == hands[1].hand)) {
    return make_error(Errc::invalid_argument, "a contact simulation has one proxy hand, or two of opposite sides");
  }
  Mjcf m;
  // A sparse constraint Jacobian although MuJoCo's auto picks dense below 60
  // DOFs: a contact row touches only the wrist, one finger chain and the
  // object, and callgrind counted 13% fewer instructions per peg-in-hole tick.
  // The model runs without gravity; step() applies each movable object's
  // weight at its centre of mass instead. The proxy hand then floats, as the
  // coupling wants it to, with no weight to cancel again: MuJoCo 2.2.2 turns
  // every body's applied force into joint forces through that body's own
  // Jacobian, which for the 17 hand bodies cost 4.7% of a peg-in-hole trial.
  m.s << "<mujoco model=\"proprio_haptics\">\n"
      << "  <compiler angle=\"radian\" inertiafromgeom=\"auto\"/>\n"
      << "  <option timestep=\"" << o.timestep_s << "\" integrator=\"Euler\" solver=\"Newton\" jacobian=\"sparse\" cone=\"elliptic\" impratio=\""
      << o.impratio << "\" iterations=\"" << o.solver_iterations << "\" tolerance=\"" << o.solver_tolerance
      << "\" gravity=\"0 0 0\">\n"
      << "    <flag multiccd=\"" << (o.multiccd ? "enable" : "disable") << "\"/>\n"
      << "  </option>\n"
      << "  <size nconmax=\"400\" njmax=\"2400\" nstack=\"2000000\"/>\n"
      << "  <default>\n"
      << "    <geom condim=\"" << (o.torsional_friction ? 4 : 3) << "\" solref=\"" << o.contact_time_constant_s << " 1\" solimp=\"" << o.contact_impedance_min
      << ' ' << o.contact_impedance_max << ' ' << o.contact_impedance_width_m << "\"/>\n"
      << "  </default>\n";

  bool any_mesh = false;
  for (const auto& obj : scene.objects) any_mesh |= obj.shape == ShapeKind::half_cylinder;
  if (any_mesh) {
    m.s << "  <asset>\n";
    for (const auto& obj : scene.objects) {
      if (obj.shape == ShapeKind::half_cylinder) half_cylinder_mesh(m, obj);
    }
    m.s << "  </asset>\n";
  }

  m.s << "  <worldbody>\n";
  if (scene.floor_height_m) {
    m.s << "    <geom name=\"floor\" type=\"plane\" size=\"0 0 1\" pos=\"0 " << *scene.floor_height_m
        << " 0\" zaxis=\"0 1 0\" friction=\"0.8 0.005 0.0001\"" << kObjectContact << "/>\n";
  }
  for (const auto& obj : scene.objects) {
    m.s << "    <body name=\"" << obj.name << '"';
    m.pose_attrs(obj.T_world_object);
    m.s << ">\n";
    if (!obj.fixed) {
      m.s << "      <freejoint name=\"" << obj.name << "_free\"/>\n";
    }
    object_geoms(m, obj, "      ");
    if (!obj.fixed) {
      // Geoms set the shape; mass is given, so scale the density to it.
      m.s << "      <inertial pos=\"0 0 0\" mass=\"" << obj.mass_kg << "\" diaginertia=\"";
      const double mass = obj.mass_kg;
      Vec3 I;
      switch (obj.shape) {
        case ShapeKind::sphere: I.setConstant(0.4 * mass * obj.radius_m * obj.radius_m); break;
        case ShapeKind::box: {
          const Vec3 e = 2.0 * obj.half_extents_m;
          I = mass / 12.0 * Vec3(e.y() * e.y() + e.z() * e.z(), e.x() * e.x() + e.z() * e.z(), e.x() * e.x() + e.y() * e.y());
          break;
        }
        default: {  // cylinder-like along z
          const double r2 = obj.radius_m * obj.radius_m, L = 2.0 * obj.half_length_m;
          const double Ixy = mass * (3.0 * r2 + L * L) / 12.0;
          I = Vec3(Ixy, Ixy, 0.5 * mass * r2);
        }
      }
      m.vec(I);
      m.s << "\"/>\n";
    }
    m.s << "    </body>\n";
  }

  for (int k = 0; k < o.collider_slots; ++k) {
    m.s << "    <body name=\"collider_" << k << "\" mocap=\"true\" pos=\"0 " << kParkedY << " 0\">\n"
        << "      <geom name=\"collider_" << k << "\" type=\"sphere\" size=\"0.01\" friction=\"0.8 0.005 0.0001\""
        << kObjectContact << " rgba=\"0.4 0.6 0.9 1\"/>\n"
        << "    </body>\n";
  }
  for (std::size_t h = 0; h < hands.size(); ++h) proxy_hand_bodies(m, hands[h], hand_prefix(hands, h), o);
  m.s << "  </worldbody>\n"
      << "  <equality>\n";
  for (std::size_t h = 0; h < hands.size(); ++h) proxy_hand_weld(m, hand_prefix(hands, h), o);
  m.s << "  </equality>\n"
      << "  <actuator>\n";
  for (std::size_t h = 0; h < hands.size(); ++h) proxy_hand_servos(m, hands[h], hand_prefix(hands, h), o);
  m.s << "  </actuator>\n"
      << "</mujoco>\n";
  return m.s.str();
}

// ---------------------------------------------------------------------------
// The simulation.

namespace {

// MuJoCo reports warnings through a global hook; route them to our log once.
void install_mujoco_log_hooks() {
  static std::once_flag once;
  std::call_once(once, [] {
    mju_user_warning = [](const char* msg) { logger().warn("MuJoCo: {}", msg); };
  });
}

}  // namespace
// Named, not anonymous: Impl holds them, and in a unity build GCC warns about
// members of anonymous-namespace types.
namespace contact_sim_detail {
struct ModelDeleter {
  void operator()(mjModel* m) const noexcept { mj_deleteModel(m); }
};
struct DataDeleter {
  void operator()(mjData* d) const noexcept { mj_deleteData(d); }
};
}  // namespace contact_sim_detail
namespace {
using contact_sim_detail::DataDeleter;
using contact_sim_detail::ModelDeleter;

Result<std::unique_ptr<mjModel, ModelDeleter>> compile(const std::string& xml) {
  // 2.2.2 has no mj_addBufferVFS: make an empty file and copy the text in.
  // mjVFS is ~2 MB, hence the heap.
  auto vfs = std::make_unique<mjVFS>();
  mj_defaultVFS(vfs.get());
  const char* kName = "proprio_haptics.xml";
  if (mj_makeEmptyFileVFS(vfs.get(), kName, static_cast<int>(xml.size())) != 0) {
    return make_error(Errc::io_error, "MuJoCo could not create its in-memory model file");
  }
  const int i = mj_findFileVFS(vfs.get(), kName);
  std::memcpy(vfs->filedata[i], xml.data(), xml.size());
  char error[1024] = "";
  mjModel* m = mj_loadXML(kName, vfs.get(), error, sizeof(error));
  mj_deleteVFS(vfs.get());
  if (!m) {
    return make_error(Errc::parse_error, std::string("MuJoCo rejected the generated scene: ") + error +
                                             " (see ContactSimulation::mjcf() or `proprio haptics mjcf`)");
  }
  return std::unique_ptr<mjModel, ModelDeleter>(m);
}

Quat quat_from(const mjtNum* q) { return Quat(q[0], q[1], q[2], q[3]); }
Vec3 vec_from(const mjtNum* v) { return Vec3(v[0], v[1], v[2]); }

bool finite_pose(const Pose& T) { return T.p.allFinite() && T.q.coeffs().allFinite() && T.q.norm() > 0.5; }

// First-order low-pass, one step: y += alpha (x - y), per component.
void low_pass(FingertipForce& y, const FingertipForce& x, double alpha) noexcept {
  y.normal_n += alpha * (x.normal_n - y.normal_n);
  y.shear_x_n += alpha * (x.shear_x_n - y.shear_x_n);
  y.shear_z_n += alpha * (x.shear_z_n - y.shear_z_n);
}

}  // namespace


// One proxy hand's part of the model and its per-step state.
struct ContactSimulation::Impl {
  struct Hand {
    Hand(HandModel m, Handedness s) : model(std::move(m)), side(s) {}
    HandModel model;
    Handedness side = Handedness::right;
    int root_qpos = 0, root_dof = 0;
    int mocap = 0;
    int root_body = 0;
    std::array<int, kHandDofCount> dof_qpos{};
    std::array<int, kHandDofCount> dof_actuator{};
    std::array<int, kFingerCount> tip_body{};
    Pose target_wrist;
    HandAngles target_angles{};
    std::array<FingertipContact, kFingerCount> tips{};
  };

  ContactSimOptions options;
  std::vector<Hand> hands;
  std::string xml;
  std::unique_ptr<mjModel, ModelDeleter> model;
  std::unique_ptr<mjData, DataDeleter> data;

  std::vector<int> geom_tip;      // per geom: hand * kFingerCount + finger for a distal phalanx, or -1
  std::vector<int> geom_hand;     // per geom: the proxy it belongs to, or -1
  // Bodies of movable scene objects, which step() gives their weight.
  std::vector<int> weighted_bodies;
  Vec3 gravity_in_world = Vec3::Zero();
  std::vector<int> object_body_of_geom;  // per geom: scene body id, or -1
  std::vector<bool> geom_on_free_object;  // per geom: part of a movable scene object
  std::vector<int> free_bodies;          // free scene objects, scene order
  std::vector<std::string> free_names;
  std::vector<int> collider_geom, collider_mocap;  // per slot

  ContactSimStats stats;
  std::uint64_t rejected_targets = 0;
  std::array<int, mjNWARNING> warnings_seen{};
  struct Spring {
    int body = -1, dof = 0;
    Vec3 anchor = Vec3::Zero();
    double k = 0.0, c = 0.0;
  };
  std::vector<Spring> springs;  // sized once by set_object_spring, never in step()

  explicit Impl(ContactSimOptions o) : options(std::move(o)) {}

  void write_hand_state(const Hand& hd, const Pose& T_world_wrist, const HandAngles& angles) {
    mjtNum* qpos = data->qpos + hd.root_qpos;
    for (int k = 0; k < 3; ++k) qpos[k] = T_world_wrist.p[k];
    const Quat q = T_world_wrist.q.normalized();
    qpos[3] = q.w();
    qpos[4] = q.x();
    qpos[5] = q.y();
    qpos[6] = q.z();
    const HandAngles clamped = hd.model.limits().clamp(angles);
    for (std::size_t i = 0; i < kHandDofCount; ++i) data->qpos[hd.dof_qpos[i]] = clamped[i];
    for (int k = 0; k < 6; ++k) data->qvel[hd.root_dof + k] = 0.0;
    for (std::size_t i = 0; i < kHandDofCount; ++i) {
      data->qvel[model->jnt_dofadr[model->actuator_trnid[2 * hd.dof_actuator[i]]]] = 0.0;
    }
  }

  Pose proxy_wrist(const Hand& hd) const {
    const mjtNum* qpos = data->qpos + hd.root_qpos;
    return {quat_from(qpos + 3).normalized(), vec_from(qpos)};
  }

  void set_mocap(int mocap, const Pose& T) {
    for (int k = 0; k < 3; ++k) data->mocap_pos[3 * mocap + k] = T.p[k];
    data->mocap_quat[4 * mocap + 0] = T.q.w();
    data->mocap_quat[4 * mocap + 1] = T.q.x();
    data->mocap_quat[4 * mocap + 2] = T.q.y();
    data->mocap_quat[4 * mocap + 3] = T.q.z();
  }

  // The leash: the weld pulls toward a point at most max_offset from the proxy.
  void place_target(Hand& hd) {
    const Pose proxy = proxy_wrist(hd);
    Vec3 offset = hd.target_wrist.p - proxy.p;
    bool leashed = false;
    const double dist = offset.norm();
    if (dist > options.coupling.wrist_max_offset_m) {
      offset *= options.coupling.wrist_max_offset_m / dist;
      leashed = true;
    }
    Quat q = hd.target_wrist.q;
    const double angle = proxy.q.angularDistance(hd.target_wrist.q);
    if (angle > options.coupling.wrist_max_offset_rad) {
      q = proxy.q.slerp(options.coupling.wrist_max_offset_rad / angle, hd.target_wrist.q);
      leashed = true;
    }
    if (leashed) ++stats.leash_engaged_steps;
    set_mocap(hd.mocap, {q, proxy.p + offset});
  }

  bool hand_touches_anything(std::size_t h) const {
    const int hi = static_cast<int>(h);
    for (int i = 0; i < data->ncon; ++i) {
      const mjContact& c = data->contact[i];
      if (geom_hand[static_cast<std::size_t>(c.geom1)] == hi || geom_hand[static_cast<std::size_t>(c.geom2)] == hi) return true;
    }
    return false;
  }

  // Resets the applied force of every movable body to its weight.
  void apply_weights() {
    for (int b : weighted_bodies) {
      const double mass = model->body_mass[b];
      for (int k = 0; k < 3; ++k) data->xfrc_applied[6 * b + k] = mass * gravity_in_world[k];
      for (int k = 3; k < 6; ++k) data->xfrc_applied[6 * b + k] = 0.0;
    }
  }

  void update_fingertips() {
    constexpr std::size_t kTips = kMaxProxyHands * kFingerCount;
    std::array<Vec3, kTips> f_world, f_on_pad;
    f_world.fill(Vec3::Zero());
    f_on_pad.fill(Vec3::Zero());
    std::array<Quat, kTips> q_tip_world;
    for (std::size_t h = 0; h < hands.size(); ++h) {
      for (std::size_t fi = 0; fi < kFingerCount; ++fi) {
        q_tip_world[h * kFingerCount + fi] = quat_from(data->xquat + 4 * hands[h].tip_body[fi]).conjugate();
      }
    }
    std::array<int, kTips> count{};
    std::array<double, kTips> depth{}, pressing{}, pressing_objects{};
    for (int i = 0; i < data->ncon; ++i) {
      const mjContact& c = data->contact[i];
      const int f1 = geom_tip[static_cast<std::size_t>(c.geom1)];
      const int f2 = geom_tip[static_cast<std::size_t>(c.geom2)];
      if (f1 < 0 && f2 < 0) continue;
      mjtNum local[6];
      mj_contactForce(model.get(), data.get(), i, local);
      // The contact frame's rows are normal, tangent 1, tangent 2; the normal
      // points from geom1 to geom2 and the force acts on geom2 (-f on geom1).
      Vec3 f = Vec3::Zero();
      for (int r = 0; r < 3; ++r) f += local[r] * Vec3(c.frame[3 * r], c.frame[3 * r + 1], c.frame[3 * r + 2]);
      const Vec3 n(c.frame[0], c.frame[1], c.frame[2]);
      // `into` is the way the normal force pushes the finger: +n on geom2, -n on geom1.
      const auto add = [&](int tip, const Vec3& force, const Vec3& into, int other_geom) {
        const auto ti = static_cast<std::size_t>(tip);
        f_world[ti] += force;
        f_on_pad[ti] += felt_on_pad(q_tip_world[ti] * force, q_tip_world[ti] * into).in_tip_frame();
        ++count[ti];
        depth[ti] = std::max(depth[ti], -c.dist);
        pressing[ti] += local[0];
        if (geom_on_free_object[static_cast<std::size_t>(other_geom)]) pressing_objects[ti] += local[0];
      };
      if (f2 >= 0) add(f2, f, n, c.geom1);
      if (f1 >= 0) add(f1, -f, -n, c.geom2);
    }
    const double dt = options.timestep_s, tau = options.force_filter_time_constant_s;
    const double alpha = dt / (tau + dt);
    for (std::size_t h = 0; h < hands.size(); ++h) {
      for (std::size_t fi = 0; fi < kFingerCount; ++fi) {
        const std::size_t ti = h * kFingerCount + fi;
        FingertipContact& tip = hands[h].tips[fi];
        tip.f_in_world = f_world[ti];
        tip.raw = FingertipForce::from_tip_frame(q_tip_world[ti] * f_world[ti]);
        low_pass(tip.force, tip.raw, alpha);
        low_pass(tip.on_pad, FingertipForce::from_tip_frame(f_on_pad[ti]), alpha);
        tip.contact_normal_n += alpha * (pressing[ti] - tip.contact_normal_n);
        tip.object_normal_n += alpha * (pressing_objects[ti] - tip.object_normal_n);
        tip.contact_count = count[ti];
        tip.max_penetration_m = depth[ti];
      }
    }
  }

  int body_of(std::string_view name) const {
    char buf[256];
    if (name.size() >= sizeof(buf)) return -1;
    std::memcpy(buf, name.data(), name.size());
    buf[name.size()] = '\0';
    return mj_name2id(model.get(), mjOBJ_BODY, buf);
  }

  bool is_hand_body(int b) const {
    for (const Hand& hd : hands) {
      int r = b;
      while (r != 0 && r != hd.root_body) r = model->body_parentid[r];
      if (r == hd.root_body) return true;
    }
    return false;
  }
};

Result<ContactSimulation> ContactSimulation::create(const HandModel& hand_model, Handedness hand,
                                                    const HapticScene& scene, const ContactSimOptions& options) {
  const ProxyHandSpec one[] = {{hand_model, hand}};
  return create(one, scene, options);
}

Result<ContactSimulation> ContactSimulation::create(std::span<const ProxyHandSpec> hands, const HapticScene& scene,
                                                    const ContactSimOptions& options) {
  install_mujoco_log_hooks();
  auto xml = generate_mjcf(hands, scene, options);
  if (!xml) return xml.error();
  auto model = compile(*xml);
  if (!model) return model.error();
  auto impl = std::make_unique<Impl>(options);
  impl->xml = std::move(*xml);
  impl->model = std::move(*model);
  impl->data.reset(mj_makeData(impl->model.get()));
  if (!impl->data) return make_error(Errc::io_error, "MuJoCo could not allocate its simulation data");
  const mjModel* m = impl->model.get();
  const auto id = [m](mjtObj type, const std::string& name) { return mj_name2id(m, type, name.c_str()); };

  impl->geom_tip.assign(static_cast<std::size_t>(m->ngeom), -1);
  impl->geom_hand.assign(static_cast<std::size_t>(m->ngeom), -1);
  impl->object_body_of_geom.assign(static_cast<std::size_t>(m->ngeom), -1);
  for (std::size_t h = 0; h < hands.size(); ++h) {
    const std::string pre = hand_prefix(hands, h);
    Impl::Hand hd(hands[h].model, hands[h].hand);
    const int root_joint = id(mjOBJ_JOINT, pre + "proxy_root");
    hd.root_qpos = m->jnt_qposadr[root_joint];
    hd.root_dof = m->jnt_dofadr[root_joint];
    hd.mocap = m->body_mocapid[id(mjOBJ_BODY, pre + "target_wrist")];
    hd.root_body = id(mjOBJ_BODY, pre + "proxy_wrist");
    for (std::size_t dof = 0; dof < kHandDofCount; ++dof) {
      const std::string name = dof_joint_name(pre, dof);
      hd.dof_qpos[dof] = m->jnt_qposadr[id(mjOBJ_JOINT, name)];
      hd.dof_actuator[dof] = id(mjOBJ_ACTUATOR, name + "_servo");
    }
    for (std::size_t fi = 0; fi < kFingerCount; ++fi) {
      const std::string distal = pre + "proxy_" + std::string(to_string(static_cast<Finger>(fi))) + "_distal";
      hd.tip_body[fi] = id(mjOBJ_BODY, distal);
      impl->geom_tip[static_cast<std::size_t>(id(mjOBJ_GEOM, distal))] = static_cast<int>(h * kFingerCount + fi);
    }
    impl->hands.push_back(std::move(hd));
  }
  // The scene object a body belongs to: its ancestor just below the world.
  const auto top_level_body = [m](int b) {
    while (m->body_parentid[b] != 0) b = m->body_parentid[b];
    return b;
  };
  for (int g = 0; g < m->ngeom; ++g) {
    const int b = m->geom_bodyid[g];
    for (std::size_t h = 0; h < impl->hands.size(); ++h) {
      if (b != 0 && top_level_body(b) == impl->hands[h].root_body) impl->geom_hand[static_cast<std::size_t>(g)] = static_cast<int>(h);
    }
    if (impl->geom_hand[static_cast<std::size_t>(g)] >= 0 || b == 0) continue;
    // A geom of a nested body (a plate's ring) belongs to the scene object.
    impl->object_body_of_geom[static_cast<std::size_t>(g)] = top_level_body(b);
  }
  for (const SceneObject& o : scene.objects) {
    if (o.fixed) continue;
    const int b = id(mjOBJ_BODY, o.name);
    if (b > 0) {
      impl->free_bodies.push_back(b);
      impl->free_names.push_back(o.name);
    }
  }
  impl->gravity_in_world = scene.gravity_in_world;
  for (int b = 1; b < m->nbody; ++b) {
    const int top = top_level_body(b);
    if (std::find(impl->free_bodies.begin(), impl->free_bodies.end(), top) != impl->free_bodies.end()) {
      impl->weighted_bodies.push_back(b);
    }
  }
  impl->geom_on_free_object.assign(static_cast<std::size_t>(m->ngeom), false);
  for (int g = 0; g < m->ngeom; ++g) {
    const int b = impl->object_body_of_geom[static_cast<std::size_t>(g)];
    impl->geom_on_free_object[static_cast<std::size_t>(g)] =
        b > 0 && std::find(impl->free_bodies.begin(), impl->free_bodies.end(), b) != impl->free_bodies.end();
  }
  for (int k = 0; k < options.collider_slots; ++k) {
    const std::string name = "collider_" + std::to_string(k);
    impl->collider_geom.push_back(id(mjOBJ_GEOM, name));
    impl->collider_mocap.push_back(m->body_mocapid[id(mjOBJ_BODY, name)]);
  }
  for (int k = 0; k < mjNWARNING; ++k) impl->warnings_seen[static_cast<std::size_t>(k)] = impl->data->warning[k].number;

  ContactSimulation sim(std::move(impl));
  for (std::size_t h = 0; h < sim.hand_count(); ++h) {
    // Side by side, 20 cm apart when there are two.
    const double x = sim.hand_count() == 1 ? 0.0 : (sim.hand(h) == Handedness::left ? -0.1 : 0.1);
    sim.reset_hand(Pose{Quat::Identity(), Vec3(x, 1.2, -0.3)}, HandAngles{}, h);
  }
  return sim;
}

ContactSimulation::ContactSimulation(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ContactSimulation::ContactSimulation(ContactSimulation&&) noexcept = default;
ContactSimulation& ContactSimulation::operator=(ContactSimulation&&) noexcept = default;
ContactSimulation::~ContactSimulation() = default;

const std::string& ContactSimulation::mjcf() const { return impl_->xml; }

void ContactSimulation::reset_hand(const Pose& T_world_wrist, const HandAngles& angles, std::size_t h) noexcept {
  Impl& s = *impl_;
  if (h >= s.hands.size() || !finite_pose(T_world_wrist)) {
    ++s.rejected_targets;
    return;
  }
  Impl::Hand& hd = s.hands[h];
  hd.target_wrist = {T_world_wrist.q.normalized(), T_world_wrist.p};
  hd.target_angles = hd.model.limits().clamp(angles);
  s.write_hand_state(hd, hd.target_wrist, hd.target_angles);
  for (std::size_t i = 0; i < kHandDofCount; ++i) s.data->ctrl[hd.dof_actuator[i]] = hd.target_angles[i];
  s.place_target(hd);
  mj_forward(s.model.get(), s.data.get());
  for (auto& tip : hd.tips) tip = FingertipContact{};
}

void ContactSimulation::set_target(const Pose& T_world_wrist, const HandAngles& angles, std::size_t h) noexcept {
  Impl& s = *impl_;
  bool finite = h < s.hands.size() && finite_pose(T_world_wrist);
  for (double a : angles) finite &= std::isfinite(a);
  if (!finite) {
    ++s.rejected_targets;
    return;
  }
  Impl::Hand& hd = s.hands[h];
  hd.target_wrist = {T_world_wrist.q.normalized(), T_world_wrist.p};
  hd.target_angles = hd.model.limits().clamp(angles);
}

void ContactSimulation::step() noexcept {
  Impl& s = *impl_;
  const CouplingOptions& c = s.options.coupling;
  for (std::size_t h = 0; h < s.hands.size(); ++h) {
    Impl::Hand& hd = s.hands[h];
    if (c.resync_distance_m > 0.0 && (hd.target_wrist.p - s.proxy_wrist(hd).p).norm() > c.resync_distance_m &&
        !s.hand_touches_anything(h)) {
      s.write_hand_state(hd, hd.target_wrist, hd.target_angles);
      ++s.stats.resyncs;
    }
    for (std::size_t i = 0; i < kHandDofCount; ++i) s.data->ctrl[hd.dof_actuator[i]] = hd.target_angles[i];
    s.place_target(hd);
  }
  s.apply_weights();
  // A spring's body is a free object's, so apply_weights() has just reset it.
  for (const Impl::Spring& sp : s.springs) {
    const Vec3 p = vec_from(s.data->xipos + 3 * sp.body);
    const Vec3 v = vec_from(s.data->qvel + sp.dof);  // a free joint's linear velocity is in world axes
    const Vec3 f = sp.k * (sp.anchor - p) - sp.c * v;
    for (int k = 0; k < 3; ++k) s.data->xfrc_applied[6 * sp.body + k] += f[k];
  }
  mj_step(s.model.get(), s.data.get());
  ++s.stats.steps;

  // MuJoCo resets the whole state itself on a bad qacc/qpos; put the hands
  // back where the user's are, and count it.
  bool reset = false;
  for (int k : {mjWARN_BADQACC, mjWARN_BADQPOS, mjWARN_BADQVEL}) {
    if (s.data->warning[k].number != s.warnings_seen[static_cast<std::size_t>(k)]) {
      s.warnings_seen[static_cast<std::size_t>(k)] = s.data->warning[k].number;
      reset = true;
    }
  }
  if (reset) {
    ++s.stats.instability_resets;
    for (const Impl::Hand& hd : s.hands) s.write_hand_state(hd, hd.target_wrist, hd.target_angles);
    mj_forward(s.model.get(), s.data.get());
  }
  s.update_fingertips();
  s.stats.last_contact_count = s.data->ncon;
}

TimeNs ContactSimulation::time_ns() const noexcept {
  return static_cast<TimeNs>(std::llround(impl_->data->time * 1e9));
}
std::size_t ContactSimulation::hand_count() const noexcept { return impl_->hands.size(); }
int ContactSimulation::hand_index(Handedness side) const noexcept {
  for (std::size_t h = 0; h < impl_->hands.size(); ++h) {
    if (impl_->hands[h].side == side) return static_cast<int>(h);
  }
  return -1;
}
// Out-of-range hand indices read hand 0: accessors never fail in the loop.
namespace {
std::size_t proxy_index_in_range(std::size_t h, std::size_t n) { return h < n ? h : 0; }
}  // namespace
Handedness ContactSimulation::hand(std::size_t h) const noexcept { return impl_->hands[proxy_index_in_range(h, hand_count())].side; }
const HandModel& ContactSimulation::hand_model(std::size_t h) const noexcept {
  return impl_->hands[proxy_index_in_range(h, hand_count())].model;
}

Pose ContactSimulation::proxy_wrist(std::size_t h) const noexcept {
  return impl_->proxy_wrist(impl_->hands[proxy_index_in_range(h, hand_count())]);
}

HandAngles ContactSimulation::proxy_angles(std::size_t h) const noexcept {
  const Impl::Hand& hd = impl_->hands[proxy_index_in_range(h, hand_count())];
  HandAngles a;
  for (std::size_t i = 0; i < kHandDofCount; ++i) a[i] = impl_->data->qpos[hd.dof_qpos[i]];
  return a;
}

HandPose ContactSimulation::proxy_pose(TimeNs time_ns, std::size_t h) const {
  const Impl::Hand& hd = impl_->hands[proxy_index_in_range(h, hand_count())];
  return hd.model.forward(hd.side, proxy_angles(h), impl_->proxy_wrist(hd), time_ns);
}

const std::array<FingertipContact, kFingerCount>& ContactSimulation::fingertips(std::size_t h) const noexcept {
  return impl_->hands[proxy_index_in_range(h, hand_count())].tips;
}
const FingertipContact& ContactSimulation::fingertip(Finger finger, std::size_t h) const noexcept {
  return fingertips(h)[static_cast<std::size_t>(finger)];
}

int ContactSimulation::collider_slot_count() const noexcept { return static_cast<int>(impl_->collider_geom.size()); }

bool ContactSimulation::set_collider(int slot, const ColliderShape& o, const Pose& T_world_collider) noexcept {
  Impl& s = *impl_;
  if (slot < 0 || slot >= collider_slot_count() || !finite_pose(T_world_collider)) return false;
  if (!o.half_extents_m.allFinite() || !std::isfinite(o.radius_m) || !std::isfinite(o.half_length_m) ||
      !std::isfinite(o.friction)) {
    return false;
  }
  mjModel* m = s.model.get();
  const int g = s.collider_geom[static_cast<std::size_t>(slot)];
  mjtNum* size = m->geom_size + 3 * g;
  switch (o.shape) {
    case ShapeKind::sphere:
      m->geom_type[g] = mjGEOM_SPHERE;
      size[0] = o.radius_m;
      m->geom_rbound[g] = o.radius_m;
      break;
    case ShapeKind::box:
      m->geom_type[g] = mjGEOM_BOX;
      for (int k = 0; k < 3; ++k) size[k] = o.half_extents_m[k];
      m->geom_rbound[g] = o.half_extents_m.norm();
      break;
    case ShapeKind::capsule:
      m->geom_type[g] = mjGEOM_CAPSULE;
      size[0] = o.radius_m;
      size[1] = o.half_length_m;
      m->geom_rbound[g] = o.radius_m + o.half_length_m;
      break;
    case ShapeKind::cylinder:
      m->geom_type[g] = mjGEOM_CYLINDER;
      size[0] = o.radius_m;
      size[1] = o.half_length_m;
      m->geom_rbound[g] = std::hypot(o.radius_m, o.half_length_m);
      break;
    default: return false;
  }
  m->geom_friction[3 * g] = o.friction;
  s.set_mocap(s.collider_mocap[static_cast<std::size_t>(slot)],
              {T_world_collider.q.normalized(), T_world_collider.p});
  return true;
}

bool ContactSimulation::move_collider(int slot, const Pose& T_world_collider) noexcept {
  Impl& s = *impl_;
  if (slot < 0 || slot >= collider_slot_count() || !finite_pose(T_world_collider)) return false;
  s.set_mocap(s.collider_mocap[static_cast<std::size_t>(slot)], {T_world_collider.q.normalized(), T_world_collider.p});
  return true;
}

void ContactSimulation::remove_collider(int slot) noexcept {
  Impl& s = *impl_;
  if (slot < 0 || slot >= collider_slot_count()) return;
  s.set_mocap(s.collider_mocap[static_cast<std::size_t>(slot)], {Quat::Identity(), Vec3(0.0, kParkedY, 0.0)});
}

Result<Pose> ContactSimulation::object_pose(std::string_view name) const {
  const Impl& s = *impl_;
  const int b = s.body_of(name);
  if (b <= 0 || s.is_hand_body(b)) {
    return make_error(Errc::not_found, "no scene object named '" + std::string(name) + "'");
  }
  return Pose{quat_from(s.data->xquat + 4 * b), vec_from(s.data->xpos + 3 * b)};
}

std::size_t ContactSimulation::free_object_count() const noexcept { return impl_->free_bodies.size(); }
const std::string& ContactSimulation::free_object_name(std::size_t i) const { return impl_->free_names.at(i); }
Pose ContactSimulation::free_object_pose(std::size_t i) const noexcept {
  const Impl& s = *impl_;
  if (i >= s.free_bodies.size()) return Pose{};
  const int b = s.free_bodies[i];
  return Pose{quat_from(s.data->xquat + 4 * b), vec_from(s.data->xpos + 3 * b)};
}

Status ContactSimulation::place_object(std::string_view name, const Pose& T_world_object) {
  Impl& s = *impl_;
  const int b = s.body_of(name);
  if (b <= 0) return make_error(Errc::not_found, "no scene object named '" + std::string(name) + "'");
  const mjModel* m = s.model.get();
  if (m->body_jntnum[b] != 1 || m->jnt_type[m->body_jntadr[b]] != mjJNT_FREE) {
    return make_error(Errc::invalid_argument, "scene object '" + std::string(name) + "' is fixed; only free objects move");
  }
  if (!finite_pose(T_world_object)) return make_error(Errc::invalid_argument, "object pose must be finite");
  const int j = m->body_jntadr[b];
  mjtNum* qpos = s.data->qpos + m->jnt_qposadr[j];
  const Quat q = T_world_object.q.normalized();
  for (int k = 0; k < 3; ++k) qpos[k] = T_world_object.p[k];
  qpos[3] = q.w();
  qpos[4] = q.x();
  qpos[5] = q.y();
  qpos[6] = q.z();
  for (int k = 0; k < 6; ++k) s.data->qvel[m->jnt_dofadr[j] + k] = 0.0;
  mj_forward(m, s.data.get());
  return {};
}

Status ContactSimulation::set_object_spring(std::string_view name, const Vec3& p_anchor_in_world,
                                            double stiffness_n_per_m, double damping_ns_per_m) {
  Impl& s = *impl_;
  const int b = s.body_of(name);
  if (b <= 0) return make_error(Errc::not_found, "no scene object named '" + std::string(name) + "'");
  const mjModel* m = s.model.get();
  if (m->body_jntnum[b] != 1 || m->jnt_type[m->body_jntadr[b]] != mjJNT_FREE) {
    return make_error(Errc::invalid_argument, "scene object '" + std::string(name) + "' is fixed; a spring needs a free object");
  }
  if (!p_anchor_in_world.allFinite() || !std::isfinite(stiffness_n_per_m) || !std::isfinite(damping_ns_per_m) ||
      stiffness_n_per_m < 0.0 || damping_ns_per_m < 0.0) {
    return make_error(Errc::invalid_argument, "spring anchor must be finite, stiffness and damping finite and >= 0");
  }
  std::erase_if(s.springs, [b](const Impl::Spring& sp) { return sp.body == b; });
  for (int k = 0; k < 6; ++k) s.data->xfrc_applied[6 * b + k] = 0.0;
  if (stiffness_n_per_m > 0.0 || damping_ns_per_m > 0.0) {
    s.springs.push_back({b, m->jnt_dofadr[m->body_jntadr[b]], p_anchor_in_world, stiffness_n_per_m, damping_ns_per_m});
  }
  return {};
}

Vec3 ContactSimulation::hand_force_on_object(std::string_view name) const {
  const Impl& s = *impl_;
  const int b = s.body_of(name);
  Vec3 total = Vec3::Zero();
  if (b <= 0) return total;
  for (int i = 0; i < s.data->ncon; ++i) {
    const mjContact& c = s.data->contact[i];
    const auto g1 = static_cast<std::size_t>(c.geom1), g2 = static_cast<std::size_t>(c.geom2);
    const bool obj1 = s.object_body_of_geom[g1] == b, obj2 = s.object_body_of_geom[g2] == b;
    if (!((obj1 && s.geom_hand[g2] >= 0) || (obj2 && s.geom_hand[g1] >= 0))) continue;
    mjtNum local[6];
    mj_contactForce(s.model.get(), s.data.get(), i, local);
    Vec3 f = Vec3::Zero();
    for (int r = 0; r < 3; ++r) f += local[r] * Vec3(c.frame[3 * r], c.frame[3 * r + 1], c.frame[3 * r + 2]);
    total += obj2 ? f : Vec3(-f);
  }
  return total;
}

ContactSimStats ContactSimulation::stats() const noexcept { return impl_->stats; }
const ContactSimOptions& ContactSimulation::options() const noexcept { return impl_->options; }

std::string ContactSimulation::describe_model() const {
  const mjModel* m = impl_->model.get();
  std::ostringstream s;
  s << impl_->hands.size() << (impl_->hands.size() == 1 ? " proxy hand, " : " proxy hands, ") << m->nbody << " bodies, " << m->ngeom << " geoms, " << m->nv << " DOFs, " << m->nu << " joint servos; "
    << impl_->options.describe();
  return s.str();
}

}  // namespace proprio::haptics
