#include "proprio/vist/correspondence.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <sstream>

namespace proprio::vist {

namespace {

constexpr double kPi = 3.14159265358979323846;
// (2 pi)^(-3/2), the normaliser of a 3-D Gaussian (4.9).
const double kGaussNorm3 = 1.0 / std::pow(2.0 * kPi, 1.5);

// Camera centres in the left camera frame: the right camera is at +baseline
// along the left camera's x (rectified rig, same orientation).
Vec3 camera_centre(const StereoRig& rig, std::size_t camera) {
  return camera == 0 ? Vec3::Zero() : Vec3(rig.baseline_m, 0.0, 0.0);
}

}  // namespace

// --- Options ---------------------------------------------------------------

Status CorrespondenceOptions::validate() const {
  auto bad = [](const std::string& what) {
    return Status(make_error(Errc::invalid_argument, "CorrespondenceOptions: " + what));
  };
  if (!(outlier_weight >= 0.0 && outlier_weight < 1.0)) return bad("outlier_weight must be in [0, 1)");
  if (!(outlier_volume_m3 > 0.0)) return bad("outlier_volume_m3 must be > 0 (m^3)");
  if (!(sigma_c_m >= 0.0)) return bad("sigma_c_m must be >= 0 (m)");
  if (sigma_c_m == 0.0 && !use_marker_covariance && !use_observation_covariance) {
    return bad("sigma_c_m is 0 and no covariance is used: the mixture (4.9) would be degenerate");
  }
  if (!(alpha_min_rad >= 0.0 && alpha_min_rad < alpha_max_rad && alpha_max_rad <= kPi)) {
    return bad("need 0 <= alpha_min_rad < alpha_max_rad <= pi");
  }
  if (!(min_depth_m >= 0.0)) return bad("min_depth_m must be >= 0 (m)");
  if (!(posterior_threshold >= 0.0 && posterior_threshold <= 1.0)) {
    return bad("posterior_threshold (delta_3) must be in [0, 1]");
  }
  if (max_iterations < 0) return bad("max_iterations must be >= 0");
  if (!(tolerance_m >= 0.0)) return bad("tolerance_m must be >= 0 (m)");
  if (!(translation_prior_sigma_m >= 0.0)) return bad("translation_prior_sigma_m must be >= 0 (m; 0 = off)");
  return Status::success();
}

std::string CorrespondenceOptions::describe() const {
  std::ostringstream s;
  s << "correspondence: w_c " << outlier_weight << ", outlier volume " << outlier_volume_m3 << " m^3, sigma_c "
    << sigma_c_m * 1000.0 << " mm" << (use_marker_covariance ? " + marker cov" : "")
    << (use_observation_covariance ? " + observation cov" : "") << ", alpha " << alpha_min_rad * 180.0 / kPi << "-"
    << alpha_max_rad * 180.0 / kPi << " deg, min depth " << min_depth_m << " m, priors "
    << (use_priors ? "on" : "off") << ", occlusion " << (occlusion ? "on" : "off") << ", delta_3 "
    << posterior_threshold << ", EM " << max_iterations << " it / " << tolerance_m * 1000.0 << " mm, eta prior "
    << translation_prior_sigma_m * 1000.0 << " mm, " << (per_hue_translation ? "eta per hue" : "shared eta")
    << ", duplicates by "
    << (duplicate_rule == DuplicateRule::max_posterior ? "max posterior" : "min distance");
  return s.str();
}

// --- Priors ----------------------------------------------------------------

double facing_factor(double alpha_rad, double alpha_min_rad, double alpha_max_rad) noexcept {
  // Eq. 4.10.
  if (alpha_rad <= alpha_min_rad) return 1.0;
  if (alpha_rad <= alpha_max_rad) return (alpha_max_rad - alpha_rad) / (alpha_max_rad - alpha_min_rad);
  return 0.0;
}

double facing_angle(const Vec3& p_marker, const Vec3& normal, const Vec3& p_camera) noexcept {
  // Fig. 4.4-A: the angle between the normal and p_camera - m_j (marker to
  // camera), so a marker looking straight at the camera has alpha = 0.
  const Vec3 ray = p_camera - p_marker;
  const double rn = ray.norm() * normal.norm();
  if (rn <= 0.0) return kPi;
  return std::acos(std::clamp(ray.dot(normal) / rn, -1.0, 1.0));
}

double fov_factor(double u_px, double v_px, const Eigen::Matrix2d& covariance_px2,
                  const PinholeCamera& camera) noexcept {
  // Eq. 4.11. d_j is signed (positive inside the image) so that the integral
  // from -inf to d_j gives 1/2 on the edge, -> 1 deep inside and -> 0 far
  // outside; a marker outside the image gets a small but nonzero prior when
  // its predicted position is uncertain enough to reach inside.
  const double d_left = u_px + 0.5;
  const double d_right = (static_cast<double>(camera.width_px) - 0.5) - u_px;
  const double d_top = v_px + 0.5;
  const double d_bottom = (static_cast<double>(camera.height_px) - 0.5) - v_px;
  double d = d_left;
  double var = covariance_px2(0, 0);
  if (d_right < d) { d = d_right; var = covariance_px2(0, 0); }
  if (d_top < d) { d = d_top; var = covariance_px2(1, 1); }
  if (d_bottom < d) { d = d_bottom; var = covariance_px2(1, 1); }
  if (!(var > 0.0)) return d > 0.0 ? 1.0 : (d == 0.0 ? 0.5 : 0.0);
  // Integral of N(0, sigma*^2) from -inf to d = Phi(d / sigma*).
  return 0.5 * std::erfc(-d / std::sqrt(2.0 * var));
}

SegmentCapsules segment_capsules(const HandPose& pose_in_world, const Pose& T_world_leftcam) noexcept {
  SegmentCapsules out;
  const Pose T_leftcam_world = T_world_leftcam.inverse();
  for (std::size_t f = 0; f < kFingerCount; ++f) {
    const auto finger = static_cast<Finger>(f);
    const FingerJoints fj = finger_joints(finger);
    for (std::size_t k = 0; k + 1 < fj.count && out.count < SegmentCapsules::kMax; ++k) {
      const HandJoint j0 = fj.joints[k];
      const HandJoint j1 = fj.joints[k + 1];
      SegmentCapsule& c = out.capsules[out.count++];
      c.a_in_leftcam = T_leftcam_world * pose_in_world.joint(j0).p;
      c.b_in_leftcam = T_leftcam_world * pose_in_world.joint(j1).p;
      c.radius_m = std::min(pose_in_world.radius_m[index_of(j0)], pose_in_world.radius_m[index_of(j1)]);
      // The finger metacarpals are rigid with the dorsum, which glove
      // descriptions call the WRIST segment: a dorsum marker sits on top of
      // them and must not be "occluded" by its own bones.
      c.segment = (k == 0 && finger != Finger::thumb) ? HandJoint::wrist : j0;
    }
  }
  return out;
}

bool occluded(const Vec3& p_in_leftcam, HandJoint own_segment, const SegmentCapsules& capsules,
              const StereoRig& rig, std::size_t camera) noexcept {
  // Eq. 4.12 text: occluded when the projection falls inside another
  // segment's projected shape and the marker is farther than that segment.
  // Segments are capsules; projected, a capsule is approximated by the 2-D
  // segment between its projected end points with a radius interpolated
  // between the projected end radii (f r / z). Depth along the 2-D segment is
  // interpolated in 1/z, which is linear in the image under perspective.
  const Vec3 centre = camera_centre(rig, camera);
  const PinholeCamera& cam = rig.camera;
  constexpr double kMinZ = 1e-3;
  const Vec3 p = p_in_leftcam - centre;
  if (p.z() <= kMinZ) return false;
  const Eigen::Vector2d q(cam.fx_px * p.x() / p.z(), cam.fy_px * p.y() / p.z());  // without cx, cy: cancels
  const double f_mean = 0.5 * (cam.fx_px + cam.fy_px);
  for (std::size_t k = 0; k < capsules.count; ++k) {
    const SegmentCapsule& c = capsules.capsules[k];
    if (c.segment == own_segment) continue;
    const Vec3 a = c.a_in_leftcam - centre;
    const Vec3 b = c.b_in_leftcam - centre;
    if (a.z() <= kMinZ || b.z() <= kMinZ) continue;
    const Eigen::Vector2d qa(cam.fx_px * a.x() / a.z(), cam.fy_px * a.y() / a.z());
    const Eigen::Vector2d qb(cam.fx_px * b.x() / b.z(), cam.fy_px * b.y() / b.z());
    const Eigen::Vector2d ab = qb - qa;
    const double len2 = ab.squaredNorm();
    const double t = len2 > 0.0 ? std::clamp((q - qa).dot(ab) / len2, 0.0, 1.0) : 0.0;
    const double inv_z = (1.0 - t) / a.z() + t / b.z();
    const double r_px = f_mean * c.radius_m * inv_z;  // radius interpolated like 1/z (r/z is linear in t)
    if ((q - (qa + t * ab)).squaredNorm() >= r_px * r_px) continue;
    if (p.z() * inv_z > 1.0) return true;  // marker depth > capsule axis depth
  }
  return false;
}

Status marker_priors(std::span<const PredictedMarker> markers, const SegmentCapsules& capsules,
                     const StereoRig& rig, const CorrespondenceOptions& options, std::span<double> priors,
                     std::span<MarkerPrior> details) {
  if (priors.size() < markers.size() || (!details.empty() && details.size() < markers.size())) {
    return make_error(Errc::invalid_argument, "marker_priors: output spans are shorter than the marker list");
  }
  const PinholeCamera& cam = rig.camera;
  for (std::size_t j = 0; j < markers.size(); ++j) {
    const PredictedMarker& m = markers[j];
    MarkerPrior d;
    if (!options.use_priors) {
      d.facing = {1.0, 1.0};
      d.fov = {1.0, 1.0};
      d.prior = 1.0;
    } else {
      double prior = 1.0;
      for (std::size_t c = 0; c < 2; ++c) {
        const Vec3 centre = camera_centre(rig, c);
        d.facing[c] = facing_factor(facing_angle(m.p_in_leftcam, m.normal_in_leftcam, centre), options.alpha_min_rad,
                                    options.alpha_max_rad);
        const Vec3 p = m.p_in_leftcam - centre;
        if (p.z() < std::max(options.min_depth_m, 1e-6)) {
          d.fov[c] = 0.0;  // behind the camera or too close to be seen: nothing to integrate
        } else {
          // Sigma* = J Sigma J^T, J the Jacobian of the pinhole projection.
          const double iz = 1.0 / p.z();
          Eigen::Matrix<double, 2, 3> J;
          J << cam.fx_px * iz, 0.0, -cam.fx_px * p.x() * iz * iz, 0.0, cam.fy_px * iz, -cam.fy_px * p.y() * iz * iz;
          const Eigen::Matrix2d cov_px = J * m.covariance * J.transpose();
          d.fov[c] = fov_factor(cam.fx_px * p.x() * iz + cam.cx_px, cam.fy_px * p.y() * iz + cam.cy_px, cov_px, cam);
        }
        prior *= d.facing[c] * d.fov[c];  // eq. 4.12
      }
      if (options.occlusion && prior > 0.0) {
        // A stereo observation needs both cameras, so hidden in either is unobservable.
        d.occluded = occluded(m.p_in_leftcam, m.segment, capsules, rig, 0) ||
                     occluded(m.p_in_leftcam, m.segment, capsules, rig, 1);
        if (d.occluded) prior = 0.0;
      }
      d.prior = prior;
    }
    priors[j] = d.prior;
    if (!details.empty()) details[j] = d;
  }
  return Status::success();
}

Status predict_markers(const HandPose& pose_in_world, const Pose& T_world_leftcam,
                       std::span<const PlacedMarker> placed, std::span<const Mat3> covariance_in_world,
                       std::span<PredictedMarker> out) {
  if (out.size() < placed.size()) {
    return make_error(Errc::invalid_argument, "predict_markers: output span is shorter than the marker list");
  }
  if (!covariance_in_world.empty() && covariance_in_world.size() < placed.size()) {
    return make_error(Errc::invalid_argument,
                      "predict_markers: give one covariance per placed marker, or none");
  }
  const Pose T_leftcam_world = T_world_leftcam.inverse();
  const Mat3 R = T_leftcam_world.q.toRotationMatrix();
  for (std::size_t j = 0; j < placed.size(); ++j) {
    const PlacedMarker& pm = placed[j];
    const Pose T_leftcam_segment = T_leftcam_world * pose_in_world.joint(pm.segment);
    PredictedMarker& m = out[j];
    m.glove_index = pm.index;
    m.segment = pm.segment;
    m.hue = pm.hue;
    m.p_in_leftcam = T_leftcam_segment * pm.p_in_segment;
    m.normal_in_leftcam = (T_leftcam_segment.q * pm.normal_in_segment).normalized();
    m.covariance = covariance_in_world.empty() ? Mat3::Zero() : Mat3(R * covariance_in_world[j] * R.transpose());
  }
  return Status::success();
}

// --- Result ----------------------------------------------------------------

void CorrespondenceResult::reserve(std::size_t max_observations) {
  assignments.reserve(max_observations);
  outliers.reserve(max_observations);
}

void CorrespondenceResult::clear() noexcept {
  assignments.clear();
  outliers.clear();
  translation_in_leftcam.fill(Vec3::Zero());
  iterations = 0;
  converged = false;
}

// --- Search ----------------------------------------------------------------

CorrespondenceSearch::CorrespondenceSearch(CorrespondenceOptions options, std::size_t max_markers,
                                           std::size_t max_observations)
    : options_(options), max_markers_(max_markers), max_observations_(max_observations) {
  assert(options_.validate().ok());
  predicted_.resize(max_markers_);
  priors_.resize(max_markers_);
  prior_details_.resize(max_markers_);
  pairs_.resize(max_markers_ * max_observations_);
  obs_pair_begin_.resize(max_observations_ + 1);
  obs_outlier_density_.resize(max_observations_);
  best_pair_.resize(max_observations_);
  marker_owner_.resize(max_markers_);
}

Result<CorrespondenceSearch> CorrespondenceSearch::create(CorrespondenceOptions options, std::size_t max_markers,
                                                          std::size_t max_observations) {
  if (Status s = options.validate(); !s.ok()) return s.error();
  if (max_markers == 0 || max_observations == 0 || max_markers > (1u << 20) || max_observations > (1u << 20)) {
    return make_error(Errc::invalid_argument, "CorrespondenceSearch: capacities must be in 1..2^20");
  }
  return CorrespondenceSearch(options, max_markers, max_observations);
}

Status CorrespondenceSearch::search(const HandPose& predicted_pose_in_world, const Pose& T_world_leftcam,
                                    const StereoRig& rig, std::span<const PlacedMarker> placed,
                                    std::span<const Mat3> marker_covariance_in_world,
                                    std::span<const Observation3D> observations, CorrespondenceResult& out) {
  if (placed.size() > max_markers_) {
    return make_error(Errc::out_of_range, "CorrespondenceSearch::search: more markers than the capacity given at construction");
  }
  const std::size_t n = placed.size();
  if (Status s = predict_markers(predicted_pose_in_world, T_world_leftcam, placed, marker_covariance_in_world,
                                 std::span<PredictedMarker>(predicted_.data(), n));
      !s.ok()) {
    return s;
  }
  const SegmentCapsules capsules =
      options_.occlusion && options_.use_priors ? segment_capsules(predicted_pose_in_world, T_world_leftcam)
                                                : SegmentCapsules{};
  if (Status s = marker_priors(std::span<const PredictedMarker>(predicted_.data(), n), capsules, rig, options_,
                               std::span<double>(priors_.data(), n), std::span<MarkerPrior>(prior_details_.data(), n));
      !s.ok()) {
    return s;
  }
  last_marker_count_ = n;
  return match(std::span<const PredictedMarker>(predicted_.data(), n), std::span<const double>(priors_.data(), n),
               observations, out);
}

Status CorrespondenceSearch::match(std::span<const PredictedMarker> markers, std::span<const double> priors,
                                   std::span<const Observation3D> observations, CorrespondenceResult& out) {
  out.clear();
  if (markers.size() > max_markers_ || observations.size() > max_observations_) {
    return make_error(Errc::out_of_range,
                      "CorrespondenceSearch::match: more markers or observations than the capacity given at construction");
  }
  if (priors.size() < markers.size()) {
    return make_error(Errc::invalid_argument, "CorrespondenceSearch::match: need one prior per marker");
  }
  const CorrespondenceOptions& o = options_;

  // Mixture weights. (4.8) weights each centroid by p(m_j); we normalise the
  // priors over the markers of the hue (pi_j = p(m_j) / sum_h p), as CPD's
  // 1/M does, so that the Gaussian part integrates to 1 - w_c whatever the
  // number of visible markers.
  std::array<double, kMarkerHueCount> hue_prior_sum{};
  for (std::size_t j = 0; j < markers.size(); ++j) {
    const double p = std::max(priors[j], 0.0);
    hue_prior_sum[static_cast<std::size_t>(markers[j].hue)] += p;
  }
  // The outlier term. (4.8) writes it w_c / N_O,h, CPD's uniform over the
  // data with the point sets normalised to unit scale. In metres a Gaussian
  // density of a few-mm sigma is ~1e5 m^-3, so w_c / N_O (~0.03) would never
  // win and nothing would ever be an outlier; we use a proper uniform
  // density w_c / V over the working volume instead.
  const double outlier_density = o.outlier_weight / o.outlier_volume_m3;
  const Mat3 sigma_c = (o.sigma_c_m * o.sigma_c_m) * Mat3::Identity();

  // Pairs (i, j) of the same hue with p(m_j) > 0: the only nonzero terms of
  // (4.8). Sigma_ij does not depend on eta, so its inverse and normaliser are
  // computed once here.
  std::size_t n_pairs = 0;
  for (std::size_t i = 0; i < observations.size(); ++i) {
    obs_pair_begin_[i] = static_cast<std::uint32_t>(n_pairs);
    const Observation3D& ob = observations[i];
    obs_outlier_density_[i] = outlier_density;
    if (ob.hue >= kMarkerHueCount) continue;
    const double sum = hue_prior_sum[ob.hue];
    if (!(sum > 0.0)) continue;
    for (std::size_t j = 0; j < markers.size(); ++j) {
      const PredictedMarker& m = markers[j];
      if (static_cast<std::uint8_t>(m.hue) != ob.hue || !(priors[j] > 0.0)) continue;
      Mat3 S = sigma_c;
      if (o.use_marker_covariance) S += m.covariance;
      if (o.use_observation_covariance) S += ob.covariance;
      const double det = S.determinant();
      if (!(det > 0.0) || !std::isfinite(det)) continue;  // degenerate: cannot be a mixture component
      Pair& pr = pairs_[n_pairs++];
      pr.obs = static_cast<std::uint32_t>(i);
      pr.marker = static_cast<std::uint32_t>(j);
      pr.information = S.inverse();  // closed form for fixed 3x3
      pr.weight = (1.0 - o.outlier_weight) * (priors[j] / sum) * kGaussNorm3 / std::sqrt(det);
      pr.posterior = 0.0;
    }
  }
  obs_pair_begin_[observations.size()] = static_cast<std::uint32_t>(n_pairs);

  // E-step: posteriors P(m_j | o_i) of CPD with the uniform component in the
  // denominator (the same expression 4.13 evaluates at the final eta).
  std::array<Vec3, kMarkerHueCount> eta{};
  eta.fill(Vec3::Zero());
  auto e_step = [&]() {
    for (std::size_t i = 0; i < observations.size(); ++i) {
      const Observation3D& ob = observations[i];
      const std::uint32_t b = obs_pair_begin_[i];
      const std::uint32_t e = obs_pair_begin_[i + 1];
      if (b == e) continue;
      const Vec3& et = eta[ob.hue];
      double den = obs_outlier_density_[i];
      for (std::uint32_t k = b; k < e; ++k) {
        Pair& pr = pairs_[k];
        const Vec3 r = ob.p_in_leftcam - markers[pr.marker].p_in_leftcam - et;
        pr.posterior = pr.weight * std::exp(-0.5 * r.dot(pr.information * r));
        den += pr.posterior;
      }
      const double inv = den > 0.0 ? 1.0 / den : 0.0;
      for (std::uint32_t k = b; k < e; ++k) pairs_[k].posterior *= inv;
    }
  };

  // M-step (4.7-4.9 with T(m, eta) = m + eta): maximising the expected
  // complete-data log-likelihood sum_ij P_ij log N(o_i; m_j + eta, Sigma_ij)
  // is weighted least squares, eta = (sum P Sigma^-1)^-1 sum P Sigma^-1 (o - m),
  // plus the Gaussian prior on eta when it is on (MAP-EM).
  const double prior_info =
      o.translation_prior_sigma_m > 0.0 ? 1.0 / (o.translation_prior_sigma_m * o.translation_prior_sigma_m) : 0.0;
  bool converged = false;
  int iterations = 0;
  for (;;) {
    e_step();
    if (converged || iterations >= o.max_iterations || n_pairs == 0) break;
    std::array<Mat3, kMarkerHueCount> A;
    std::array<Vec3, kMarkerHueCount> bvec;
    A.fill(Mat3::Zero());
    bvec.fill(Vec3::Zero());
    for (std::size_t k = 0; k < n_pairs; ++k) {
      const Pair& pr = pairs_[k];
      const std::size_t h = o.per_hue_translation ? observations[pr.obs].hue : 0;
      const Mat3 W = pr.posterior * pr.information;
      A[h] += W;
      bvec[h] += W * (observations[pr.obs].p_in_leftcam - markers[pr.marker].p_in_leftcam);
    }
    double moved = 0.0;
    const std::size_t n_eta = o.per_hue_translation ? kMarkerHueCount : 1;
    for (std::size_t h = 0; h < n_eta; ++h) {
      A[h].diagonal().array() += prior_info;
      // Without a prior and with no responsibility, A is zero: keep eta.
      if (!(A[h].trace() > 0.0)) continue;
      const Vec3 next = A[h].ldlt().solve(bvec[h]);
      if (!next.allFinite()) continue;
      moved = std::max(moved, (next - eta[h]).norm());
      eta[h] = next;
    }
    if (!o.per_hue_translation) eta.fill(eta[0]);
    ++iterations;
    converged = moved < o.tolerance_m;
  }

  // Maximum posterior per observation (4.13), then delta_3.
  for (std::size_t j = 0; j < markers.size(); ++j) marker_owner_[j] = -1;
  for (std::size_t i = 0; i < observations.size(); ++i) {
    best_pair_[i] = -1;
    double best = -1.0;
    for (std::uint32_t k = obs_pair_begin_[i]; k < obs_pair_begin_[i + 1]; ++k) {
      if (pairs_[k].posterior > best) {  // strict: ties keep the lower marker index
        best = pairs_[k].posterior;
        best_pair_[i] = static_cast<std::int32_t>(k);
      }
    }
    if (best_pair_[i] >= 0 && best < o.posterior_threshold) best_pair_[i] = -1;
  }
  // Duplicate rejection: a marker keeps one observation (the thesis keeps the
  // nearest pair; max_posterior keeps the more certain one); the other
  // observations become outliers. Observations are visited in index order
  // and only strict improvements win, so the result is deterministic.
  auto distance2 = [&](std::int32_t k) {
    const Pair& pr = pairs_[static_cast<std::size_t>(k)];
    const Observation3D& ob = observations[pr.obs];
    return (ob.p_in_leftcam - markers[pr.marker].p_in_leftcam - eta[ob.hue]).squaredNorm();
  };
  for (std::size_t i = 0; i < observations.size(); ++i) {
    const std::int32_t k = best_pair_[i];
    if (k < 0) continue;
    const std::uint32_t j = pairs_[static_cast<std::size_t>(k)].marker;
    const std::int32_t other = marker_owner_[j];
    if (other < 0) {
      marker_owner_[j] = static_cast<std::int32_t>(i);
      continue;
    }
    const std::int32_t ko = best_pair_[static_cast<std::size_t>(other)];
    const bool wins = o.duplicate_rule == CorrespondenceOptions::DuplicateRule::max_posterior
                          ? pairs_[static_cast<std::size_t>(k)].posterior > pairs_[static_cast<std::size_t>(ko)].posterior
                          : distance2(k) < distance2(ko);
    if (wins) {
      best_pair_[static_cast<std::size_t>(other)] = -1;
      marker_owner_[j] = static_cast<std::int32_t>(i);
    } else {
      best_pair_[i] = -1;
    }
  }

  if (out.assignments.capacity() < observations.size() || out.outliers.capacity() < observations.size()) {
    out.reserve(observations.size());  // allocates only on a result that was not reserve()d
  }
  for (std::size_t i = 0; i < observations.size(); ++i) {
    const std::int32_t k = best_pair_[i];
    if (k < 0) {
      out.outliers.push_back(i);
      continue;
    }
    const Pair& pr = pairs_[static_cast<std::size_t>(k)];
    out.assignments.push_back(Assignment{i, markers[pr.marker].glove_index, pr.posterior});
  }
  out.translation_in_leftcam = eta;
  out.iterations = iterations;
  out.converged = converged;
  return Status::success();
}

}  // namespace proprio::vist
