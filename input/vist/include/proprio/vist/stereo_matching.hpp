#pragma once
// VIST left-right stereo matching (Lee 2021, §4.3.3, eqs. 4.4-4.6): pairs the
// colour blobs of a rectified stereo camera per hue with a 1-DOF coherent
// point drift (Myronenko & Song 2010) and triangulates each pair into a 3D
// point in the left camera frame, with its covariance from pixel noise.
//
// Reading of the thesis (documented because the text leaves choices open):
// - Eq. 4.4 factorises over the four hues: each hue is registered on its own.
// - Eq. 4.5/4.6: the right blobs R_h are GMM centroids with the even prior
//   1/N_R,h; a left blob l is drawn from N(T(r_j, zeta), Sigma_s) or, with
//   weight w_s, from a uniform outlier density. On rectified images
//   T(r, zeta) = r + (zeta, 0): zeta is the horizontal parallax (disparity
//   u_left - u_right, pixels) common to the hue group. Rows carry no unknown.
// - A hand spans several centimetres of depth, so one zeta cannot put every
//   left blob on its right partner within pixel noise. We therefore let EM fit
//   the horizontal variance as CPD fits sigma^2 (Sigma_s = diag(sigma_u^2,
//   2 sigma_px^2)): sigma_u absorbs the spread of disparities within the hue,
//   the row variance stays the pixel noise of two centroids. Each pair then
//   gets its own disparity for triangulation.
// - The uniform outlier term "w_s / N_L,h" of eq. 4.5 is, as in CPD, a density;
//   in pixel units we take it uniform over the image (1 / (W H)), which keeps
//   the posterior independent of how pixels are scaled.
// - Outlier tests after EM ("distance and ratio tests" of §4.3.3), with the
//   fitted Sigma_s as metric (squared Mahalanobis distance m):
//   distance: m(l_i, T(r_j,min)) <= k^2 (thesis: ||l - T(r_min)||^2 < delta_1);
//   ratio:    m_min / m_min2 < delta_2 (thesis: squared distance ratio of the
//             closest to the second closest right point < delta_2), applied
//             from the left and, optionally, from the right side.
//   Pairs must also be mutual nearest neighbours, so matching is one-to-one.
// - Physical gates, applied before EM as a hard prior (a pair outside them has
//   prior 0): |v_l - v_r| <= max_row_difference_px, depth within
//   [min_depth_m, max_depth_m], blob areas within max_area_ratio.
//
// Hot path: StereoMatcher keeps every buffer between calls; after the first
// frames (or from the start, up to reserve_markers blobs per camera) match()
// allocates nothing. Deterministic: same input, same output, bit for bit.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/core/result.hpp"

namespace proprio::vist {

struct StereoMatchOptions {
  // Sigma of one blob centroid, per axis, pixels (Sigma_s of eq. 4.6 and the
  // triangulation covariance). Thesis: tuned by pilot tests.
  double pixel_noise_px = 1.0;
  double outlier_weight = 0.1;  // w_s of eq. 4.5, in [0, 1)
  int max_em_iterations = 50;
  double em_tolerance_px = 1e-3;  // stop when zeta and sigma_u move less than this
  // Floor of the fitted horizontal sigma (besides sqrt(2) pixel_noise_px): a
  // hue group's disparities spread by at least this much without failing the
  // distance test.
  double min_disparity_sigma_px = 3.0;
  double max_row_difference_px = 3.0;  // rectified: |v_left - v_right| gate
  double distance_test_sigmas = 3.0;   // k: reject a pair with m > k^2
  double ratio_test_max = 0.25;        // delta_2: reject if m_best >= ratio * m_second
  bool ratio_test_both_sides = true;   // also test the right blob's two nearest left blobs
  double min_depth_m = 0.1;
  double max_depth_m = 1.5;
  double max_area_ratio = 3.0;  // larger/smaller blob area; <= 0 disables; areas <= 0 are not tested
  // Blobs whose hue is farther than this (HSV_FULL steps, circular) from every
  // glove hue are rejected.
  double max_hue_distance = 21.0;
  std::size_t reserve_markers = 64;  // per camera; buffers sized for this up front

  Status validate() const;
  std::string describe() const;
};

// One triangulated marker observation (an element of O in §4.3).
struct StereoPoint {
  MarkerHue hue = MarkerHue::red;
  std::uint32_t left_index = 0;   // into the left MarkerObservations::markers
  std::uint32_t right_index = 0;  // into the right MarkerObservations::markers
  double u_left_px = 0.0;
  double v_left_px = 0.0;
  double u_right_px = 0.0;
  double v_right_px = 0.0;
  double disparity_px = 0.0;  // u_left - u_right of this pair
  double posterior = 0.0;     // P(r_j | l_i) of eq. 4.5 at the fitted zeta
  double mahalanobis_sq = 0.0;  // m of the pair under the fitted Sigma_s
  Vec3 p_in_leftcam = Vec3::Zero();
  // Pixel noise (pixel_noise_px on u_l, u_r, v_l, v_r, independent) through
  // the triangulation Jacobian, m^2.
  Mat3 cov_p_in_leftcam = Mat3::Zero();
};

// What happened to the blobs of the last match() call.
struct StereoMatchStats {
  std::size_t left_markers = 0;
  std::size_t right_markers = 0;
  std::size_t rejected_non_finite = 0;  // NaN/inf pixel, either camera
  std::size_t rejected_hue = 0;         // no glove hue near, either camera
  std::size_t left_without_candidate = 0;  // no right blob passes the gates
  std::size_t rejected_distance = 0;
  std::size_t rejected_ratio = 0;
  std::size_t rejected_not_mutual = 0;  // the right blob prefers another left blob
  std::size_t matched = 0;
  int em_iterations = 0;  // summed over hues
  std::array<double, kMarkerHueCount> zeta_px{};     // fitted disparity per hue (0: no pairs)
  std::array<double, kMarkerHueCount> sigma_u_px{};  // fitted horizontal sigma per hue
};

class StereoMatcher {
 public:
  // Validates the rig (positive focal lengths, baseline and image size) and options.
  static Result<StereoMatcher> create(const StereoRig& rig, StereoMatchOptions options = {});

  // Matches one rectified stereo frame. `out` is cleared and filled (its
  // capacity is kept, so a reused vector stops allocating). Output order: by
  // hue (red, yellow, green, blue), then by left index. Never throws on bad
  // data: non-finite blobs are skipped and counted.
  const StereoMatchStats& match(const MarkerObservations& left, const MarkerObservations& right,
                                std::vector<StereoPoint>& out);

  const StereoMatchStats& last_stats() const noexcept { return stats_; }
  const StereoMatchOptions& options() const noexcept { return options_; }
  const StereoRig& rig() const noexcept { return rig_; }

  // Triangulation of one rectified pair (left camera frame, metres), and its
  // covariance for independent pixel noise sigma_px on all four coordinates.
  static Vec3 triangulate(const StereoRig& rig, double u_left, double v_left, double u_right, double v_right);
  static Mat3 triangulation_covariance(const StereoRig& rig, double u_left, double v_left, double u_right,
                                       double v_right, double sigma_px);

 private:
  StereoMatcher(const StereoRig& rig, const StereoMatchOptions& options);

  struct Pair {
    std::uint32_t i = 0;  // local index in the hue's left group
    std::uint32_t j = 0;  // local index in the hue's right group
    double du = 0.0;      // u_left - u_right (the pair's own disparity)
    double row_term = 0.0;  // (v_left - v_right)^2 / sigma_v^2
    double m = 0.0;         // squared Mahalanobis distance at the fitted zeta
    double posterior = 0.0;
  };
  void match_hue(std::size_t h, const MarkerObservations& left, const MarkerObservations& right,
                 std::vector<StereoPoint>& out);
  void group(const MarkerObservations& obs, std::array<std::vector<std::uint32_t>, kMarkerHueCount>& groups);

  StereoRig rig_;
  StereoMatchOptions options_;
  std::array<std::uint8_t, kMarkerHueCount> hue_codes_{};
  double min_disparity_px_ = 0.0;
  double max_disparity_px_ = 0.0;
  std::array<std::vector<std::uint32_t>, kMarkerHueCount> left_groups_;
  std::array<std::vector<std::uint32_t>, kMarkerHueCount> right_groups_;
  std::vector<Pair> pairs_;                 // feasible pairs of one hue, sorted by i then j
  std::vector<std::uint32_t> left_begin_;   // pairs_ range of each left blob: [begin[i], begin[i+1])
  std::vector<std::int32_t> right_best_;    // per right blob: pair index of its nearest left blob
  std::vector<double> right_best_m_;
  std::vector<double> right_second_m_;
  StereoMatchStats stats_;
};

}  // namespace proprio::vist
