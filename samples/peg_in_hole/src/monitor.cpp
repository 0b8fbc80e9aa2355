#include "proprio/peg_in_hole/monitor.hpp"

#include <algorithm>
#include <cmath>

namespace proprio::peg_in_hole {

double grasp_force_n(const std::array<double, kFingerCount>& object_normal_n) noexcept {
  double f = 0.0;
  for (double n : object_normal_n) {
    if (std::isfinite(n)) f = std::max(f, n);
  }
  return f;
}

bool BreakMonitor::update(TimeNs time_ns, double force_n) noexcept {
  if (!std::isfinite(force_n)) {
    ++rejected_;
    return false;
  }
  if (!started_ || tau_s_ <= 0.0) {
    filtered_ = tau_s_ <= 0.0 ? force_n : 0.0;
    started_ = true;
    last_ns_ = time_ns;
    if (tau_s_ > 0.0) return false;
  } else {
    const double dt = std::max(0.0, 1e-9 * static_cast<double>(time_ns - last_ns_));
    last_ns_ = time_ns;
    // Exact discretisation of the first-order filter, so the result does not
    // depend on the sample rate (1 kHz servo, ~90 Hz frames).
    const double alpha = 1.0 - std::exp(-dt / tau_s_);
    filtered_ += alpha * (force_n - filtered_);
    // Settle exactly: a steady force equal to the threshold must reach it,
    // not creep towards it one rounding step short forever.
    if (std::abs(force_n - filtered_) < 1e-9) filtered_ = force_n;
  }
  if (!broken_ && filtered_ >= threshold_) {
    broken_ = true;
    return true;
  }
  return false;
}

void BreakMonitor::reset() noexcept {
  filtered_ = 0.0;
  started_ = false;
  broken_ = false;
}

std::array<float, 4> peg_colour(double force_n, double scale_max_n, bool broken) noexcept {
  if (broken) return {0.55f, 0.08f, 0.08f, 1.0f};
  double u = std::isfinite(force_n) ? force_n / scale_max_n : 0.0;
  u = std::clamp(u, 0.0, 1.0);
  const auto c = static_cast<float>(1.0 - u);
  return {c, c, 1.0f, 1.0f};  // white (1,1,1) -> blue (0,0,1)
}

double force_from_colour(const std::array<float, 4>& rgba, double scale_max_n) noexcept {
  return std::clamp(1.0 - static_cast<double>(rgba[0]), 0.0, 1.0) * scale_max_n;
}

HoleGeometry hole_geometry(const PegInHoleConfig& config, const Vec3& p_hole_in_world) {
  return {p_hole_in_world, Vec3::UnitX(), config.peg.radius_m + config.hole.clearance_m,
          config.hole.insertion_depth_m};
}

Vec3 peg_axis(const Pose& T_world_peg) noexcept { return T_world_peg.q * Vec3::UnitZ(); }

InsertionState insertion_state(const Pose& T_world_peg, double peg_half_length_m, const HoleGeometry& hole) noexcept {
  InsertionState s;
  const Vec3 axis = peg_axis(T_world_peg);
  const Vec3 ends[2] = {T_world_peg.p + peg_half_length_m * axis, T_world_peg.p - peg_half_length_m * axis};
  double best = -1e9;
  for (const Vec3& e : ends) {
    const Vec3 d = e - hole.p_entry_in_world;
    const double along = d.dot(hole.axis_in_world);
    if (along > best) {
      best = along;
      s.depth_m = along;
      s.radial_offset_m = (d - along * hole.axis_in_world).norm();
    }
  }
  s.axis_angle_rad = std::acos(std::clamp(std::abs(axis.dot(hole.axis_in_world)), 0.0, 1.0));
  s.inserted = s.depth_m >= hole.insertion_depth_m && s.radial_offset_m <= hole.radius_m;
  return s;
}

}  // namespace proprio::peg_in_hole
