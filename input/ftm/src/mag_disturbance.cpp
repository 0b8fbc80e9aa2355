#include "proprio/ftm/mag_disturbance.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace proprio::ftm {

double dip_angle_rad(const Vec3& field, const Vec3& up) noexcept {
  const double n = field.norm() * up.norm();
  if (!(n > 0.0)) return 0.0;
  return std::asin(std::clamp(-field.dot(up) / n, -1.0, 1.0));
}

Status MagDisturbanceOptions::validate() const {
  const bool ok = norm_tolerance > 0.0 && std::isfinite(norm_tolerance) && dip_tolerance_rad > 0.0 &&
                  dip_tolerance_rad < M_PI && hold_s >= 0.0 && std::isfinite(hold_s) && lowpass_tau_s >= 0.0 &&
                  std::isfinite(lowpass_tau_s) && std::isfinite(max_rejection_s) &&
                  (max_rejection_s <= 0.0 || max_rejection_s > hold_s);
  if (!ok) {
    return make_error(Errc::invalid_argument,
                      "magnetic disturbance detector: need norm_tolerance > 0, 0 < dip_tolerance < 180°, "
                      "hold_s >= 0, lowpass_tau_s >= 0, and max_rejection_s <= 0 (off) or > hold_s (got " +
                          describe() + ")");
  }
  return {};
}

std::string MagDisturbanceOptions::describe() const {
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "flag when |norm - ref| > %.3g %% of ref or |dip - ref| > %.3g deg (low-pass %.3g s), "
                "trust again after %.3g s in tolerance, give up rejecting after %.3g s",
                100.0 * norm_tolerance, dip_tolerance_rad * 180.0 / M_PI, lowpass_tau_s, hold_s, max_rejection_s);
  return buf;
}

MagDisturbanceDetector::MagDisturbanceDetector(const MagDisturbanceOptions& options, const Vec3& mag_ref_in_world,
                                               const Vec3& up_in_world)
    : options_(options), ref_norm_(mag_ref_in_world.norm()), ref_dip_(dip_angle_rad(mag_ref_in_world, up_in_world)) {}

void MagDisturbanceDetector::reset() noexcept {
  primed_ = disturbed_ = expired_ = false;
  norm_lp_ = dip_lp_ = 0.0;
}

bool MagDisturbanceDetector::update(TimeNs t_ns, const Vec3& mag_body, const Vec3& up_in_body) noexcept {
  if (!mag_body.allFinite() || !up_in_body.allFinite()) return disturbed_;
  const double norm = mag_body.norm();
  const double dip = dip_angle_rad(mag_body, up_in_body);
  if (!primed_ || t_ns <= last_ns_) {
    norm_lp_ = norm;
    dip_lp_ = dip;
    primed_ = true;
  } else {
    const double dt = ns_to_seconds(t_ns - last_ns_);
    const double a = options_.lowpass_tau_s > 0.0 ? dt / (options_.lowpass_tau_s + dt) : 1.0;
    norm_lp_ += a * (norm - norm_lp_);
    dip_lp_ += a * (dip - dip_lp_);
  }
  last_ns_ = t_ns;

  const bool out = std::abs(norm_lp_ - ref_norm_) > options_.norm_tolerance * ref_norm_ ||
                   std::abs(dip_lp_ - ref_dip_) > options_.dip_tolerance_rad;
  if (out) {
    if (!disturbed_) disturbed_since_ns_ = t_ns;
    disturbed_ = true;
    last_bad_ns_ = t_ns;
  } else if (disturbed_ && ns_to_seconds(t_ns - last_bad_ns_) >= options_.hold_s) {
    disturbed_ = false;
  }
  expired_ = disturbed_ && options_.max_rejection_s > 0.0 &&
             ns_to_seconds(t_ns - disturbed_since_ns_) >= options_.max_rejection_s;
  return disturbed_;
}

}  // namespace proprio::ftm
