#include "proprio/haptics/force_laws.hpp"

#include <cmath>
#include <sstream>

namespace proprio::haptics {

std::string ContactLawOptions::describe() const {
  std::ostringstream s;
  s << "contact law F = F0 + K d: F0 " << onset_force_n << " N, K " << stiffness_n_per_m << " N/m ("
    << stiffness_n_per_m / 100.0 << " N/cm), saturating at " << max_force_n << " N";
  return s.str();
}

Status ContactLawOptions::validate() const {
  if (!(std::isfinite(onset_force_n) && onset_force_n >= 0.0)) {
    return make_error(Errc::invalid_argument, "contact law onset_force_n must be >= 0 N");
  }
  if (!(std::isfinite(stiffness_n_per_m) && stiffness_n_per_m >= 0.0)) {
    return make_error(Errc::invalid_argument,
                      "contact law stiffness_n_per_m must be >= 0 N/m (the thesis's 0.042 N/cm is 4.2 N/m)");
  }
  if (!(std::isfinite(max_force_n) && max_force_n >= onset_force_n)) {
    return make_error(Errc::invalid_argument, "contact law max_force_n must be >= onset_force_n");
  }
  return {};
}

namespace {

AnalyticContact law_force(const ContactLawOptions& law, double penetration_m, const Vec3& n_in_world,
                          const Quat& q_world_tip) {
  AnalyticContact c;
  if (!(penetration_m > 0.0)) return c;  // also rejects NaN
  c.in_contact = true;
  c.penetration_m = penetration_m;
  c.n_in_world = n_in_world;
  const double magnitude = std::min(law.max_force_n, law.onset_force_n + law.stiffness_n_per_m * penetration_m);
  c.f_in_world = magnitude * n_in_world;
  c.force = FingertipForce::from_tip_frame(q_world_tip.conjugate() * c.f_in_world);
  c.on_pad = felt_on_pad(q_world_tip.conjugate() * c.f_in_world, q_world_tip.conjugate() * n_in_world);
  return c;
}

}  // namespace

AnalyticContact sphere_on_plane(const ContactLawOptions& law, const Vec3& p_plane_in_world, const Vec3& n_in_world,
                                const Vec3& p_sphere_in_world, double sphere_radius_m, const Quat& q_world_tip) noexcept {
  const Vec3 n = n_in_world.normalized();
  const double height = n.dot(p_sphere_in_world - p_plane_in_world);
  return law_force(law, sphere_radius_m - height, n, q_world_tip);
}

AnalyticContact sphere_on_half_cylinder(const ContactLawOptions& law, const HalfCylinderShape& cylinder,
                                        const Vec3& p_sphere_in_world, double sphere_radius_m,
                                        const Quat& q_world_tip) noexcept {
  const Vec3 c = cylinder.T_world_object.inverse() * p_sphere_in_world;
  if (std::abs(c.z()) > cylinder.half_length_m) return {};
  const double R = cylinder.radius_m;
  const double rho = std::hypot(c.x(), c.y());
  // Depth below the curved surface and below the flat face; the sphere is
  // pushed out through whichever it is nearer to.
  double depth = -1.0;
  Vec3 n_in_object = Vec3::Zero();
  if (c.y() >= 0.0) {
    if (rho > 1e-12) {
      depth = R + sphere_radius_m - rho;
      n_in_object = Vec3(c.x() / rho, c.y() / rho, 0.0);
    }
    if (rho < R && sphere_radius_m + c.y() < depth) {
      // Inside, closer to the flat face than to the curve.
      depth = sphere_radius_m + c.y();
      n_in_object = Vec3(0, -1, 0);
    }
  } else if (std::abs(c.x()) <= R) {
    // Below the flat face, within its width.
    depth = sphere_radius_m + c.y();  // c.y < 0: the sphere's top reaches above y = 0 when depth > 0
    n_in_object = Vec3(0, -1, 0);
  } else {
    // Beside the flat face: the nearest surface is its edge, at (+-R, 0).
    const Vec3 edge(c.x() > 0 ? R : -R, 0.0, c.z());
    const Vec3 d = c - edge;
    const double dist = d.norm();
    if (dist > 1e-12) {
      depth = sphere_radius_m - dist;
      n_in_object = d / dist;
    }
  }
  return law_force(law, depth, cylinder.T_world_object.q * n_in_object, q_world_tip);
}

}  // namespace proprio::haptics
