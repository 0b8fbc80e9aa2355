#include "proprio/sim/magnetic_field.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iterator>

namespace proprio::sim {

namespace {

Error bad_earth(const char* field, double value, const char* what) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "Earth field option %s = %g is not usable: %s", field, value, what);
  return make_error(Errc::invalid_argument, buf);
}

const Vec3 kUpWorld(0.0, 1.0, 0.0);

// Minimum-jerk blend 0 -> 1 over s in [0, 1].
double min_jerk(double s) {
  s = std::clamp(s, 0.0, 1.0);
  return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
}

}  // namespace

Status EarthFieldOptions::validate() const {
  if (!std::isfinite(magnitude_T) || magnitude_T < 0.0 || magnitude_T > 1e-3) {
    return bad_earth("magnitude_T", magnitude_T, "use a field in [0, 1e-3] T (the Earth's is 25e-6 to 65e-6 T)");
  }
  if (!std::isfinite(inclination_rad) || std::abs(inclination_rad) > M_PI / 2.0) {
    return bad_earth("inclination_rad", inclination_rad, "use a dip in [-pi/2, pi/2] rad");
  }
  if (!std::isfinite(declination_rad) || std::abs(declination_rad) > M_PI) {
    return bad_earth("declination_rad", declination_rad, "use a declination in [-pi, pi] rad");
  }
  if (!north_world.allFinite() || std::abs(north_world.norm() - 1.0) > 1e-9 || std::abs(north_world.y()) > 1e-9) {
    return bad_earth("north_world.norm", north_world.norm(),
                     "north must be a horizontal unit vector (world +Y is up), e.g. (0, 0, -1)");
  }
  return Status::success();
}

std::string EarthFieldOptions::describe() const {
  char buf[256];
  std::snprintf(buf, sizeof buf, "earth: %.1f uT, dip %.1f deg, declination %.1f deg, north=(%.3g, %.3g, %.3g)",
                magnitude_T * 1e6, rad_to_deg(inclination_rad), rad_to_deg(declination_rad), north_world.x(),
                north_world.y(), north_world.z());
  return buf;
}

Vec3 earth_field_world_T(const EarthFieldOptions& o) {
  const Vec3 east = o.north_world.cross(kUpWorld);
  const Vec3 magnetic_north = std::cos(o.declination_rad) * o.north_world + std::sin(o.declination_rad) * east;
  return o.magnitude_T * (std::cos(o.inclination_rad) * magnetic_north - std::sin(o.inclination_rad) * kUpWorld);
}

double inclination_of(const Vec3& field_world) {
  const double horizontal = std::hypot(field_world.x(), field_world.z());
  return std::atan2(-field_world.y(), horizontal);
}

Vec3 dipole_field_T(const Vec3& m_world_Am2, const Vec3& r_m) {
  const double r = r_m.norm();
  if (!(r > 0.0)) return Vec3::Zero();
  const Vec3 u = r_m / r;
  return kMu0Over4Pi * (3.0 * m_world_Am2.dot(u) * u - m_world_Am2) / (r * r * r);
}

Pose ScriptedApproach::operator()(TimeNs t) const {
  const TimeNs t_near = t_start_ns + approach_ns;
  const TimeNs t_leave = t_near + hold_ns;
  const TimeNs t_gone = t_leave + retreat_ns;
  double s = 0.0;  // 0 = far, 1 = near
  if (t <= t_start_ns || t >= t_gone) {
    s = 0.0;
  } else if (t < t_near) {
    s = min_jerk(static_cast<double>(t - t_start_ns) / static_cast<double>(std::max<DurationNs>(approach_ns, 1)));
  } else if (t <= t_leave) {
    s = 1.0;
  } else {
    s = 1.0 - min_jerk(static_cast<double>(t - t_leave) / static_cast<double>(std::max<DurationNs>(retreat_ns, 1)));
  }
  return interpolate(T_world_far, T_world_near, s);
}

MagneticDipole haptic_device_dipole(HandJoint tip, const HapticDeviceDipoleOptions& o, CurrentFunction current) {
  MagneticDipole d;
  d.name = "haptic device on " + std::string(to_string(tip));
  d.moment_static_Am2 = Vec3(0.0, 0.0, o.moment_static_Am2);
  d.moment_per_current_Am2_per_A = Vec3(0.0, 0.0, o.moment_per_current_Am2_per_A);
  d.attached_to = tip;
  d.T_joint_dipole = o.T_tip_device;
  d.current_A = std::move(current);
  return d;
}

MagneticDipole drill_dipole(PoseFunction T_world_drill, CurrentFunction current) {
  MagneticDipole d;
  d.name = "hand drill";
  d.moment_static_Am2 = Vec3(0.0, 0.0, 1.0);
  d.moment_per_current_Am2_per_A = Vec3(0.0, 0.0, 0.05);
  d.T_world_dipole = std::move(T_world_drill);
  d.current_A = std::move(current);
  d.min_distance_m = 0.02;  // the motor sits inside a housing a few cm across
  return d;
}

MagneticDipole fan_dipole(PoseFunction T_world_fan, CurrentFunction current) {
  MagneticDipole d;
  d.name = "portable fan";
  d.moment_static_Am2 = Vec3(0.0, 0.0, 0.05);
  d.moment_per_current_Am2_per_A = Vec3(0.0, 0.0, 0.02);
  d.T_world_dipole = std::move(T_world_fan);
  d.current_A = std::move(current);
  d.min_distance_m = 0.015;
  return d;
}

MagneticDipole earphone_case_dipole(PoseFunction T_world_case) {
  MagneticDipole d;
  d.name = "earphone case";
  d.moment_static_Am2 = Vec3(0.0, 0.0, 0.1);
  d.T_world_dipole = std::move(T_world_case);
  d.min_distance_m = 0.01;
  return d;
}

PoseFunction fixed_pose(const Pose& T_world_object) {
  return [T_world_object](TimeNs) { return T_world_object; };
}

MagneticEnvironment::MagneticEnvironment(EarthFieldOptions earth)
    : earth_(std::move(earth)), earth_world_T_(sim::earth_field_world_T(earth_)) {}

Result<MagneticEnvironment> MagneticEnvironment::create(EarthFieldOptions earth) {
  if (Status s = earth.validate(); !s.ok()) return s.error();
  return MagneticEnvironment(std::move(earth));
}

Result<std::size_t> MagneticEnvironment::add_dipole(MagneticDipole dipole) {
  const std::string who = "magnetic dipole '" + dipole.name + "'";
  if (!dipole.attached_to && !dipole.T_world_dipole) {
    return make_error(Errc::invalid_argument,
                      who + " has no place: attach it to a hand joint or give it a T_world_dipole function");
  }
  if (!dipole.moment_static_Am2.allFinite() || !dipole.moment_per_current_Am2_per_A.allFinite()) {
    return make_error(Errc::invalid_argument, who + " has a moment that is not finite");
  }
  if (!std::isfinite(dipole.min_distance_m) || dipole.min_distance_m <= 0.0) {
    return make_error(Errc::invalid_argument, who + ": min_distance_m must be > 0 (the field diverges at r = 0)");
  }
  if (dipole.attached_to && (!dipole.T_joint_dipole.p.allFinite() || !dipole.T_joint_dipole.q.coeffs().allFinite())) {
    return make_error(Errc::invalid_argument, who + ": T_joint_dipole is not finite");
  }
  dipoles_.push_back(std::move(dipole));
  schedules_.emplace_back();
  return dipoles_.size() - 1;
}

Status MagneticEnvironment::set_current(std::size_t index, TimeNs from_ns, double amperes) {
  if (index >= dipoles_.size()) {
    return make_error(Errc::invalid_argument, "set_current: no dipole " + std::to_string(index) + " (there are " +
                                                  std::to_string(dipoles_.size()) + ")");
  }
  if (!std::isfinite(amperes)) {
    return make_error(Errc::invalid_argument,
                      "set_current: the current of '" + dipoles_[index].name + "' is not finite");
  }
  auto& s = schedules_[index];
  // Usually appended in time order; an earlier time is inserted in place,
  // and a repeated time replaces the value set for it.
  auto it = std::lower_bound(s.begin(), s.end(), from_ns,
                             [](const std::pair<TimeNs, double>& e, TimeNs t) { return e.first < t; });
  if (it != s.end() && it->first == from_ns) {
    it->second = amperes;
  } else {
    s.insert(it, {from_ns, amperes});
  }
  return Status::success();
}

double MagneticEnvironment::current_A(std::size_t index, TimeNs t) const {
  const auto& s = schedules_.at(index);
  auto it = std::upper_bound(s.begin(), s.end(), t,
                             [](TimeNs tt, const std::pair<TimeNs, double>& e) { return tt < e.first; });
  if (it != s.begin()) return std::prev(it)->second;
  const auto& f = dipoles_[index].current_A;
  return f ? f(t) : 0.0;
}

std::optional<Pose> MagneticEnvironment::dipole_pose_world(std::size_t index, TimeNs t, const HandPose* hand) const {
  const MagneticDipole& d = dipoles_.at(index);
  if (d.attached_to) {
    if (hand == nullptr || !hand->active) return std::nullopt;
    return hand->joint(*d.attached_to) * d.T_joint_dipole;
  }
  return d.T_world_dipole(t);
}

Vec3 MagneticEnvironment::dipole_field_world_T(std::size_t index, const Vec3& p_world, TimeNs t,
                                               const HandPose* hand) const {
  const std::optional<Pose> T_world_dipole = dipole_pose_world(index, t, hand);
  if (!T_world_dipole) return Vec3::Zero();
  const MagneticDipole& d = dipoles_[index];
  const double amperes = current_A(index, t);
  const Vec3 m_world = T_world_dipole->q * (d.moment_static_Am2 + amperes * d.moment_per_current_Am2_per_A);
  Vec3 r = p_world - T_world_dipole->p;
  const double dist = r.norm();
  if (dist > 0.0 && dist < d.min_distance_m) r *= d.min_distance_m / dist;
  return dipole_field_T(m_world, r);
}

Vec3 MagneticEnvironment::disturbance_world_T(const Vec3& p_world, TimeNs t, const HandPose* hand) const {
  Vec3 b = Vec3::Zero();
  for (std::size_t i = 0; i < dipoles_.size(); ++i) b += dipole_field_world_T(i, p_world, t, hand);
  for (std::size_t i = 0; i < leads_.size(); ++i) b += lead_field_world_T(i, p_world, t, hand);
  return b;
}

Vec3 segment_field_T(const Vec3& a, const Vec3& b, double amperes, const Vec3& p, double min_distance_m) {
  const Vec3 ab = b - a;
  const double len = ab.norm();
  if (len <= 0.0 || amperes == 0.0) return Vec3::Zero();
  const Vec3 u = ab / len;
  const Vec3 r1 = p - a, r2 = p - b;
  Vec3 d_perp = r1 - r1.dot(u) * u;
  double d = d_perp.norm();
  if (d <= 0.0) return Vec3::Zero();  // on the line: direction undefined
  const Vec3 d_hat = d_perp / d;
  d = std::max(d, min_distance_m);
  const double n1 = std::max(r1.norm(), min_distance_m), n2 = std::max(r2.norm(), min_distance_m);
  const double geometry = r1.dot(u) / n1 - r2.dot(u) / n2;  // cos θ1 − cos θ2
  return kMu0Over4Pi * amperes / d * geometry * u.cross(d_hat);
}

CurrentLeadPair fingertip_device_leads(HandJoint tip, std::optional<std::size_t> current_of_dipole) {
  CurrentLeadPair l;
  l.name = std::string(to_string(tip)) + " device leads";
  l.path.push_back(HandJoint::wrist);
  for (std::size_t fi = 0; fi < kFingerCount; ++fi) {
    const FingerJoints fj = finger_joints(static_cast<Finger>(fi));
    if (fj.joints[fj.count - 1] != tip) continue;
    for (std::size_t k = 0; k < fj.count; ++k) l.path.push_back(fj.joints[k]);
  }
  l.current_of_dipole = current_of_dipole;
  return l;
}

Result<std::size_t> MagneticEnvironment::add_lead_pair(CurrentLeadPair leads) {
  if (leads.path.size() < 2) return make_error(Errc::invalid_argument, "lead pair '" + leads.name + "': path needs >= 2 joints");
  if (!(leads.separation_m > 0.0) || !(leads.min_distance_m > 0.0) || !leads.p_joint_offset_m.allFinite()) {
    return make_error(Errc::invalid_argument,
                      "lead pair '" + leads.name + "': separation_m and min_distance_m must be > 0, the offset finite");
  }
  if (leads.current_of_dipole && *leads.current_of_dipole >= dipoles_.size()) {
    return make_error(Errc::invalid_argument, "lead pair '" + leads.name + "': current_of_dipole names no dipole");
  }
  leads_.push_back(std::move(leads));
  return leads_.size() - 1;
}

Vec3 MagneticEnvironment::lead_field_world_T(std::size_t index, const Vec3& p_world, TimeNs t,
                                             const HandPose* hand) const {
  const CurrentLeadPair& l = leads_.at(index);
  if (hand == nullptr || !hand->active) return Vec3::Zero();
  const double amperes =
      l.current_of_dipole ? current_A(*l.current_of_dipole, t) : (l.current_A ? l.current_A(t) : 0.0);
  if (amperes == 0.0) return Vec3::Zero();
  Vec3 b = Vec3::Zero();
  Pose j0 = hand->joint(l.path[0]);
  for (std::size_t k = 1; k < l.path.size(); ++k) {
    const Pose j1 = hand->joint(l.path[k]);
    const Vec3 a = j0 * l.p_joint_offset_m, e = j1 * l.p_joint_offset_m;
    const Vec3 a_ret = a + l.separation_m * (j0.q * Vec3::UnitX()), e_ret = e + l.separation_m * (j1.q * Vec3::UnitX());
    b += segment_field_T(a, e, amperes, p_world, l.min_distance_m);
    b += segment_field_T(e_ret, a_ret, amperes, p_world, l.min_distance_m);  // the return, the other way
    j0 = j1;
  }
  return b;
}

Vec3 MagneticEnvironment::field_world_T(const Vec3& p_world, TimeNs t, const HandPose* hand) const {
  return earth_world_T_ + disturbance_world_T(p_world, t, hand);
}

std::string MagneticEnvironment::describe() const {
  std::string out = "MagneticEnvironment: " + earth_.describe() + ", " + std::to_string(dipoles_.size()) + " dipoles" +
                    (leads_.empty() ? std::string() : ", " + std::to_string(leads_.size()) + " lead pairs");
  for (const auto& d : dipoles_) {
    char buf[256];
    std::snprintf(buf, sizeof buf, "\n  %s: |m| = %.3g A*m2 + %.3g A*m2/A, %s%s", d.name.c_str(),
                  d.moment_static_Am2.norm(), d.moment_per_current_Am2_per_A.norm(),
                  d.attached_to ? "on " : "in the world",
                  d.attached_to ? std::string(to_string(*d.attached_to)).c_str() : "");
    out += buf;
  }
  return out;
}

}  // namespace proprio::sim
