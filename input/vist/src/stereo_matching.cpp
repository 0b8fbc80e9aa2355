// VIST left-right stereo matching: 1-DOF CPD per hue (Lee 2021, eqs. 4.4-4.6),
// outlier tests and triangulation. See the header for the reading of the thesis.
#include "proprio/vist/stereo_matching.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>

namespace proprio::vist {

namespace {

bool finite_pos(double x) { return std::isfinite(x) && x > 0.0; }

// Circular distance on the 256-step HSV_FULL hue circle.
double hue_distance(double a, double b) {
  const double d = std::fabs(a - b);
  return std::min(d, 256.0 - d);
}

}  // namespace

Status StereoMatchOptions::validate() const {
  auto bad = [](const char* what) {
    return Status(make_error(Errc::invalid_argument, std::string("StereoMatchOptions: ") + what));
  };
  if (!finite_pos(pixel_noise_px)) return bad("pixel_noise_px must be > 0");
  if (!(outlier_weight >= 0.0 && outlier_weight < 1.0)) return bad("outlier_weight must be in [0, 1)");
  if (max_em_iterations < 1) return bad("max_em_iterations must be >= 1");
  if (!finite_pos(em_tolerance_px)) return bad("em_tolerance_px must be > 0");
  if (!(std::isfinite(min_disparity_sigma_px) && min_disparity_sigma_px >= 0.0))
    return bad("min_disparity_sigma_px must be >= 0");
  if (!finite_pos(max_row_difference_px)) return bad("max_row_difference_px must be > 0");
  if (!finite_pos(distance_test_sigmas)) return bad("distance_test_sigmas must be > 0");
  if (!(ratio_test_max > 0.0 && ratio_test_max <= 1.0)) return bad("ratio_test_max must be in (0, 1]");
  if (!finite_pos(min_depth_m) || !(max_depth_m > min_depth_m) || std::isnan(max_depth_m))
    return bad("need 0 < min_depth_m < max_depth_m");
  if (std::isnan(max_area_ratio) || (max_area_ratio > 0.0 && max_area_ratio < 1.0))
    return bad("max_area_ratio must be >= 1 (or <= 0 to disable)");
  if (!(max_hue_distance >= 0.0 && max_hue_distance <= 128.0)) return bad("max_hue_distance must be in [0, 128]");
  if (reserve_markers > 4096) return bad("reserve_markers must be <= 4096");
  return Status::success();
}

std::string StereoMatchOptions::describe() const {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "pixel_noise=%.3fpx w_s=%.3f em=%d iters/%.1epx min_disparity_sigma=%.2fpx row_gate=%.2fpx "
                "distance_test=%.2fsigma ratio_test=%.3f(%s) depth=%.3f..%.3fm area_ratio=%.2f hue_gate=%.1f "
                "reserve=%zu",
                pixel_noise_px, outlier_weight, max_em_iterations, em_tolerance_px, min_disparity_sigma_px,
                max_row_difference_px, distance_test_sigmas, ratio_test_max,
                ratio_test_both_sides ? "both sides" : "left side", min_depth_m, max_depth_m, max_area_ratio,
                max_hue_distance, reserve_markers);
  return buf;
}

Result<StereoMatcher> StereoMatcher::create(const StereoRig& rig, StereoMatchOptions options) {
  if (Status s = options.validate(); !s.ok()) return s.error();
  const PinholeCamera& c = rig.camera;
  if (!finite_pos(c.fx_px) || !finite_pos(c.fy_px) || !finite_pos(rig.baseline_m) || c.width_px <= 0 ||
      c.height_px <= 0 || !std::isfinite(c.cx_px) || !std::isfinite(c.cy_px)) {
    return make_error(Errc::invalid_argument,
                      "StereoMatcher: the rig needs positive focal lengths, baseline and image size, and a finite "
                      "principal point");
  }
  return StereoMatcher(rig, options);
}

StereoMatcher::StereoMatcher(const StereoRig& rig, const StereoMatchOptions& options)
    : rig_(rig), options_(options) {
  for (std::size_t h = 0; h < kMarkerHueCount; ++h) {
    // OpenCV's 0-179 hue -> HSV_FULL's 0-255, rounded as cvtColor does.
    const double full = opencv_hue(static_cast<MarkerHue>(h)) * 256.0 / 180.0;
    hue_codes_[h] = static_cast<std::uint8_t>(static_cast<int>(std::lround(full)) & 0xff);
  }
  // Depth gate in disparity: z = fx b / d (rectified).
  const double fb = rig_.camera.fx_px * rig_.baseline_m;
  min_disparity_px_ = fb / options_.max_depth_m;
  max_disparity_px_ = fb / options_.min_depth_m;
  const std::size_t n = options_.reserve_markers;
  for (std::size_t h = 0; h < kMarkerHueCount; ++h) {
    left_groups_[h].reserve(n);
    right_groups_[h].reserve(n);
  }
  // A hue group has at most n x n pairs; in practice the row gate leaves a few
  // per left blob, but reserving the worst case keeps match() allocation-free.
  pairs_.reserve(n * n);
  left_begin_.reserve(n + 1);
  right_best_.reserve(n);
  right_best_m_.reserve(n);
  right_second_m_.reserve(n);
}

Vec3 StereoMatcher::triangulate(const StereoRig& rig, double u_left, double v_left, double u_right,
                                double v_right) {
  const PinholeCamera& c = rig.camera;
  const double d = u_left - u_right;
  const double z = c.fx_px * rig.baseline_m / d;
  // Rows agree up to noise on rectified images: average them.
  const double v = 0.5 * (v_left + v_right);
  return {(u_left - c.cx_px) * z / c.fx_px, (v - c.cy_px) * z / c.fy_px, z};
}

Mat3 StereoMatcher::triangulation_covariance(const StereoRig& rig, double u_left, double v_left,
                                             double u_right, double v_right, double sigma_px) {
  const PinholeCamera& c = rig.camera;
  const Vec3 p = triangulate(rig, u_left, v_left, u_right, v_right);
  const double d = u_left - u_right;
  // Jacobian of (x, y, z) w.r.t. (u_l, u_r, v_l, v_r): z = fx b / d gives
  // dz/du_l = -z/d, dz/du_r = z/d; x = (u_l - cx) z / fx, y = (v - cy) z / fy.
  Eigen::Matrix<double, 3, 4> J;
  J << p.z() / c.fx_px - p.x() / d, p.x() / d, 0.0, 0.0,  //
      -p.y() / d, p.y() / d, 0.5 * p.z() / c.fy_px, 0.5 * p.z() / c.fy_px,  //
      -p.z() / d, p.z() / d, 0.0, 0.0;
  return sigma_px * sigma_px * (J * J.transpose());
}

void StereoMatcher::group(const MarkerObservations& obs,
                          std::array<std::vector<std::uint32_t>, kMarkerHueCount>& groups) {
  for (auto& g : groups) g.clear();
  const auto& markers = obs.markers;
  for (std::size_t k = 0; k < markers.size(); ++k) {
    const Marker& m = markers[k];
    if (!std::isfinite(m.u_px) || !std::isfinite(m.v_px)) {
      ++stats_.rejected_non_finite;
      continue;
    }
    std::size_t best = 0;
    double best_d = std::numeric_limits<double>::infinity();
    for (std::size_t h = 0; h < kMarkerHueCount; ++h) {
      const double dh = hue_distance(m.hue, hue_codes_[h]);
      if (dh < best_d) {
        best_d = dh;
        best = h;
      }
    }
    if (best_d > options_.max_hue_distance) {
      ++stats_.rejected_hue;
      continue;
    }
    groups[best].push_back(static_cast<std::uint32_t>(k));
  }
}

const StereoMatchStats& StereoMatcher::match(const MarkerObservations& left, const MarkerObservations& right,
                                             std::vector<StereoPoint>& out) {
  stats_ = StereoMatchStats{};
  stats_.left_markers = left.markers.size();
  stats_.right_markers = right.markers.size();
  out.clear();
  if (out.capacity() < options_.reserve_markers) out.reserve(options_.reserve_markers);
  group(left, left_groups_);
  group(right, right_groups_);
  // Eq. 4.4: the likelihood factorises over hues, so each hue is registered alone.
  for (std::size_t h = 0; h < kMarkerHueCount; ++h) match_hue(h, left, right, out);
  stats_.matched = out.size();
  return stats_;
}

void StereoMatcher::match_hue(std::size_t h, const MarkerObservations& left, const MarkerObservations& right,
                              std::vector<StereoPoint>& out) {
  const auto& L = left_groups_[h];
  const auto& R = right_groups_[h];
  if (L.empty()) return;
  if (R.empty()) {
    stats_.left_without_candidate += L.size();
    return;
  }
  const double sp2 = options_.pixel_noise_px * options_.pixel_noise_px;
  // Rows: difference of two centroids, each with pixel noise.
  const double sv2 = 2.0 * sp2;
  const double su2_floor = std::max(2.0 * sp2, options_.min_disparity_sigma_px * options_.min_disparity_sigma_px);

  // Feasible pairs (the hard prior): same row, depth in range, similar area.
  pairs_.clear();
  left_begin_.clear();
  for (std::uint32_t i = 0; i < L.size(); ++i) {
    left_begin_.push_back(static_cast<std::uint32_t>(pairs_.size()));
    const Marker& l = left.markers[L[i]];
    for (std::uint32_t j = 0; j < R.size(); ++j) {
      const Marker& r = right.markers[R[j]];
      const double dv = static_cast<double>(l.v_px) - r.v_px;
      if (std::fabs(dv) > options_.max_row_difference_px) continue;
      const double du = static_cast<double>(l.u_px) - r.u_px;
      if (du < min_disparity_px_ || du > max_disparity_px_) continue;
      if (options_.max_area_ratio > 0.0 && l.area_px2 > 0.0f && r.area_px2 > 0.0f) {
        const double a = std::max(l.area_px2, r.area_px2);
        const double b = std::min(l.area_px2, r.area_px2);
        if (a > options_.max_area_ratio * b) continue;
      }
      pairs_.push_back(Pair{i, j, du, dv * dv / sv2, 0.0, 0.0});
    }
  }
  left_begin_.push_back(static_cast<std::uint32_t>(pairs_.size()));
  if (pairs_.empty()) {
    stats_.left_without_candidate += L.size();
    return;
  }

  // EM for zeta (Myronenko & Song 2010, rigid CPD reduced to a horizontal
  // shift). Start from every feasible pair weighted alike: zeta the mean
  // disparity, sigma_u their spread.
  double zeta = 0.0;
  for (const Pair& p : pairs_) zeta += p.du;
  zeta /= static_cast<double>(pairs_.size());
  double su2 = 0.0;
  for (const Pair& p : pairs_) su2 += (p.du - zeta) * (p.du - zeta);
  su2 = std::max(su2 / static_cast<double>(pairs_.size()), su2_floor);

  const double M = static_cast<double>(R.size());
  const double w = options_.outlier_weight;
  const double image_area = static_cast<double>(rig_.camera.width_px) * rig_.camera.height_px;
  // E-step (eq. 4.5 with 4.6): P(j | i) = e_ij / (sum_k e_ik + c), e = exp(-m/2),
  // after multiplying numerator and denominator by 2 pi sigma_u sigma_v M / (1 - w):
  // c = w / (1 - w) * M * 2 pi sigma_u sigma_v / (W H), the uniform outlier density
  // 1 / (W H) being eq. 4.5's w_s / N term in pixel units.
  auto e_step = [&](double z, double s2) {
    const double c = (w / (1.0 - w)) * M * 2.0 * std::numbers::pi * std::sqrt(s2 * sv2) / image_area;
    for (std::size_t i = 0; i + 1 < left_begin_.size(); ++i) {
      double sum = c;
      for (std::uint32_t k = left_begin_[i]; k < left_begin_[i + 1]; ++k) {
        Pair& p = pairs_[k];
        const double r = p.du - z;
        p.m = r * r / s2 + p.row_term;
        p.posterior = std::exp(-0.5 * p.m);
        sum += p.posterior;
      }
      const double inv = 1.0 / sum;
      for (std::uint32_t k = left_begin_[i]; k < left_begin_[i + 1]; ++k) pairs_[k].posterior *= inv;
    }
  };

  int it = 0;
  for (; it < options_.max_em_iterations; ++it) {
    e_step(zeta, su2);
    // M-step: the weighted mean disparity maximises the expected complete-data
    // log-likelihood in zeta; sigma_u^2 is its weighted residual variance (1-D).
    double np = 0.0, sd = 0.0;
    for (const Pair& p : pairs_) {
      np += p.posterior;
      sd += p.posterior * p.du;
    }
    if (!(np > 1e-12)) break;  // everything is an outlier: keep the last estimate
    const double zeta_new = sd / np;
    double sr = 0.0;
    for (const Pair& p : pairs_) sr += p.posterior * (p.du - zeta_new) * (p.du - zeta_new);
    const double su2_new = std::max(sr / np, su2_floor);
    const bool converged = std::fabs(zeta_new - zeta) < options_.em_tolerance_px &&
                           std::fabs(std::sqrt(su2_new) - std::sqrt(su2)) < options_.em_tolerance_px;
    zeta = zeta_new;
    su2 = su2_new;
    if (converged) {
      ++it;
      break;
    }
  }
  e_step(zeta, su2);  // posteriors and distances at the final parameters
  stats_.em_iterations += it;
  stats_.zeta_px[h] = zeta;
  stats_.sigma_u_px[h] = std::sqrt(su2);

  // Each right blob's nearest and second-nearest left blob (for the one-to-one
  // and right-side ratio tests).
  right_best_.assign(R.size(), -1);
  right_best_m_.assign(R.size(), std::numeric_limits<double>::infinity());
  right_second_m_.assign(R.size(), std::numeric_limits<double>::infinity());
  for (std::size_t k = 0; k < pairs_.size(); ++k) {
    const Pair& p = pairs_[k];
    if (p.m < right_best_m_[p.j]) {
      right_second_m_[p.j] = right_best_m_[p.j];
      right_best_m_[p.j] = p.m;
      right_best_[p.j] = static_cast<std::int32_t>(k);
    } else if (p.m < right_second_m_[p.j]) {
      right_second_m_[p.j] = p.m;
    }
  }

  const double k2 = options_.distance_test_sigmas * options_.distance_test_sigmas;
  const double ratio = options_.ratio_test_max;
  for (std::size_t i = 0; i + 1 < left_begin_.size(); ++i) {
    const std::uint32_t b = left_begin_[i], e = left_begin_[i + 1];
    if (b == e) {
      ++stats_.left_without_candidate;
      continue;
    }
    // Within one left blob the posterior is monotone in m, so the closest
    // transformed right blob (thesis) is also the maximum-posterior one.
    std::uint32_t best = b;
    double second_m = std::numeric_limits<double>::infinity();
    for (std::uint32_t k = b + 1; k < e; ++k) {
      if (pairs_[k].m < pairs_[best].m) {
        second_m = pairs_[best].m;
        best = k;
      } else if (pairs_[k].m < second_m) {
        second_m = pairs_[k].m;
      }
    }
    const Pair& p = pairs_[best];
    // Distance test: ||l - T(r_min)||^2 < delta_1, in the fitted metric.
    if (p.m > k2) {
      ++stats_.rejected_distance;
      continue;
    }
    // Ratio test: ||l - T(r_min)||^2 / ||l - T(r_min2)||^2 < delta_2 (written
    // as a product so an exact duplicate, 0 / 0, is ambiguous, not a match).
    if (!(p.m < ratio * second_m) ||
        (options_.ratio_test_both_sides && !(right_best_m_[p.j] < ratio * right_second_m_[p.j]))) {
      ++stats_.rejected_ratio;
      continue;
    }
    if (right_best_[p.j] != static_cast<std::int32_t>(best)) {
      ++stats_.rejected_not_mutual;
      continue;
    }
    const Marker& l = left.markers[L[p.i]];
    const Marker& r = right.markers[R[p.j]];
    StereoPoint s;
    s.hue = static_cast<MarkerHue>(h);
    s.left_index = L[p.i];
    s.right_index = R[p.j];
    s.u_left_px = l.u_px;
    s.v_left_px = l.v_px;
    s.u_right_px = r.u_px;
    s.v_right_px = r.v_px;
    // Each pair keeps its own disparity: zeta only aligned the group.
    s.disparity_px = p.du;
    s.posterior = p.posterior;
    s.mahalanobis_sq = p.m;
    s.p_in_leftcam = triangulate(rig_, s.u_left_px, s.v_left_px, s.u_right_px, s.v_right_px);
    s.cov_p_in_leftcam = triangulation_covariance(rig_, s.u_left_px, s.v_left_px, s.u_right_px, s.v_right_px,
                                                  options_.pixel_noise_px);
    out.push_back(s);
  }
}

}  // namespace proprio::vist
