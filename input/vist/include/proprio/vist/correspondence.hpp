#pragma once
// VIST IMU-aided correspondence search (Lee 2021, §4.4, eqs. 4.7-4.13).
//
// Given the IMU-predicted glove markers M (positions, normals and position
// covariances from the predicted hand pose) and the stereo-matched 3D marker
// observations O (anonymous up to hue), find which observation is which glove
// marker:
//   1. marker priors p(m_j) (4.10-4.12): camera-facing factor x field-of-view
//      factor for both cameras, and 0 for markers hidden behind another
//      segment of the predicted hand;
//   2. coherent point drift (Myronenko & Song 2010) with a 3-DOF translation
//      eta: the predicted markers are the centroids of a Gaussian mixture
//      weighted by their priors, observations only explain markers of their
//      own hue (4.7-4.9); eta is found by EM;
//   3. the posterior p(m_j | o_i) (4.13), maximum-posterior assignment with
//      duplicate rejection (one observation per marker and vice versa) and
//      the threshold delta_3; the rest are outliers.
//
// Frames: everything the search works in is in the LEFT camera frame (OpenCV
// axes: x right, y down, z forward); the right camera sits at +baseline along
// the left camera's x. SI units throughout.
//
// Real-time use: CorrespondenceSearch preallocates for a maximum number of
// markers and observations; search()/match() do not allocate as long as the
// CorrespondenceResult passed in has been reserve()d (or was used before), and
// report Errc::out_of_range when the inputs exceed the capacity.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/hand_pose.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"

namespace proprio::vist {

// A stereo-matched, triangulated marker observation. `hue` is the MarkerHue
// value (0 red, 1 yellow, 2 green, 3 blue, as static_cast<std::uint8_t>(MarkerHue));
// an observation with any other value can match nothing and is an outlier.
struct Observation3D {
  std::uint8_t hue = 0;
  Vec3 p_in_leftcam = Vec3::Zero();
  Mat3 covariance = Mat3::Zero();  // of p_in_leftcam, m^2
};

// A glove marker where the IMU-predicted hand pose puts it.
struct PredictedMarker {
  std::size_t glove_index = 0;  // PlacedMarker::index
  HandJoint segment = HandJoint::wrist;
  MarkerHue hue = MarkerHue::red;
  Vec3 p_in_leftcam = Vec3::Zero();
  Vec3 normal_in_leftcam = Vec3::UnitZ();  // outward, unit
  Mat3 covariance = Mat3::Zero();          // of p_in_leftcam, m^2
};

struct CorrespondenceOptions {
  // Outlier weight w_c of the mixture (4.8), in [0, 1).
  double outlier_weight = 0.1;
  // Volume the outlier component is spread over (m^3): the uniform density in
  // (4.8) is outlier_weight / outlier_volume_m3 (see the .cpp for why not
  // w_c / N_O). Default: a 30 cm cube around the hand.
  double outlier_volume_m3 = 0.3 * 0.3 * 0.3;
  // Sigma_c (4.9): isotropic noise, m (standard deviation). Besides the
  // triangulation noise it absorbs what the translation eta cannot: rotation
  // and finger-angle errors of the prediction. 7 mm was best in the
  // simulated free-motion sessions (tests/unit/input/vist/test_vist_correspondence.cpp)
  // with 5 mm predicted marker covariances (4 mm: -3 points of accuracy at
  // 2.5x the nominal prediction errors, 10 mm: more distractors accepted).
  double sigma_c_m = 0.007;
  // Add each marker's predicted covariance and each observation's covariance
  // to Sigma_c in (4.9): Sigma_ij = Sigma_c + Sigma_j + Sigma_i.
  bool use_marker_covariance = true;
  bool use_observation_covariance = true;
  // Visible angular range of the marker (4.10), radians.
  double alpha_min_rad = 0.25 * 3.14159265358979323846;  // 45 deg
  double alpha_max_rad = 0.5 * 3.14159265358979323846;   // 90 deg
  // Markers nearer than this (left-camera depth, m) are behind / out of focus: prior 0.
  double min_depth_m = 0.05;
  // Eq. 4.12 occlusion by other segments of the predicted hand.
  bool occlusion = true;
  // false: every marker's prior is 1 (the vision-only baseline of Fig. 4.8-D);
  // occlusion and the factors are skipped.
  bool use_priors = true;
  // delta_3 (4.13): an assignment needs at least this posterior.
  double posterior_threshold = 0.5;
  // EM for eta (4.7-4.9).
  int max_iterations = 30;
  double tolerance_m = 1e-5;  // stop when eta moves less than this
  // Gaussian prior eta ~ N(0, sigma^2 I) (MAP-EM): the IMU prediction is
  // trusted to about this much, so one or two stray observations cannot drag
  // the whole marker set onto themselves. 0 disables it (plain ML as in CPD).
  double translation_prior_sigma_m = 0.03;
  // false: one eta shared by all hues, as the product over hues in (4.7)
  // reads; true: an independent eta per hue.
  bool per_hue_translation = false;
  enum class DuplicateRule : std::uint8_t {
    max_posterior,  // keep the pair with the higher posterior p(m_j|o_i)
    min_distance,   // keep the pair with the smaller Euclidean distance (the thesis text)
  };
  DuplicateRule duplicate_rule = DuplicateRule::max_posterior;

  Status validate() const;
  std::string describe() const;
};

// --- Priors (4.10-4.12) ---------------------------------------------------

// Camera-facing factor (4.10): 1 up to alpha_min, linear to 0 at alpha_max, 0 beyond.
double facing_factor(double alpha_rad, double alpha_min_rad, double alpha_max_rad) noexcept;
// Angle between a marker's outward normal and the ray from the marker to the
// camera centre (both in the same frame), radians in [0, pi].
double facing_angle(const Vec3& p_marker, const Vec3& normal, const Vec3& p_camera) noexcept;

// FOV factor (4.11): the probability mass, inside the image, of the 1-D
// Gaussian of the projected position along the direction of the nearest image
// edge: Phi(d / sigma*), d = signed distance (px) from the projected position
// to the nearest image edge (positive inside), sigma* = the standard
// deviation of the projected covariance along that edge's normal. The image
// covers [-0.5, W - 0.5] x [-0.5, H - 0.5] (pixel centres at integers).
double fov_factor(double u_px, double v_px, const Eigen::Matrix2d& covariance_px2,
                  const PinholeCamera& camera) noexcept;

// A hand segment as a capsule (in the left camera frame), the occluder of 4.12.
struct SegmentCapsule {
  Vec3 a_in_leftcam = Vec3::Zero();
  Vec3 b_in_leftcam = Vec3::Zero();
  double radius_m = 0.0;
  HandJoint segment = HandJoint::wrist;  // the glove segment (PlacedMarker::segment) it belongs to
};
struct SegmentCapsules {
  static constexpr std::size_t kMax = 24;
  std::array<SegmentCapsule, kMax> capsules{};
  std::size_t count = 0;
};
// One capsule per bone between consecutive XR joints of each finger (radius:
// the smaller of the two joint radii). The four finger metacarpals belong to
// the WRIST segment (the dorsum is rigid with them), the thumb's to
// THUMB_METACARPAL. No allocation.
SegmentCapsules segment_capsules(const HandPose& pose_in_world, const Pose& T_world_leftcam) noexcept;

// True when marker point p (left-camera frame), seen from `camera` (0 left,
// 1 right), projects inside a capsule of a segment other than `own_segment`
// and lies farther from that camera than the capsule's axis there.
bool occluded(const Vec3& p_in_leftcam, HandJoint own_segment, const SegmentCapsules& capsules,
              const StereoRig& rig, std::size_t camera) noexcept;

// Per-camera factors of one marker, for diagnostics and tests.
struct MarkerPrior {
  std::array<double, 2> facing{};  // p_n,c (4.10), [0] left, [1] right
  std::array<double, 2> fov{};     // p_f,c (4.11)
  bool occluded = false;           // 4.12 text
  double prior = 0.0;              // p(m_j) (4.12)
};

// p(m_j) for every marker (4.12). `details` may be empty or as long as `markers`.
// No allocation. Errors when `priors` (or a non-empty `details`) is shorter than `markers`.
Status marker_priors(std::span<const PredictedMarker> markers, const SegmentCapsules& capsules,
                     const StereoRig& rig, const CorrespondenceOptions& options, std::span<double> priors,
                     std::span<MarkerPrior> details = {});

// Markers where a hand pose puts them, in the left camera frame. The
// covariances are given in the world frame (the EKF's) and rotated into the
// camera frame; an empty span means zero covariance. No allocation.
Status predict_markers(const HandPose& pose_in_world, const Pose& T_world_leftcam,
                       std::span<const PlacedMarker> placed, std::span<const Mat3> covariance_in_world,
                       std::span<PredictedMarker> out);

// --- Search (4.7-4.9, 4.13) ------------------------------------------------

struct Assignment {
  std::size_t observation = 0;  // index into the observations
  std::size_t marker = 0;       // glove marker index (PlacedMarker::index)
  double posterior = 0.0;       // p(m_j | o_i), 4.13
};

struct CorrespondenceResult {
  std::vector<Assignment> assignments;  // ordered by observation index
  std::vector<std::size_t> outliers;    // observation indices left unassigned, ascending
  // eta (4.7-4.9): observed minus predicted, left-camera frame. Shared mode:
  // all four entries equal.
  std::array<Vec3, kMarkerHueCount> translation_in_leftcam{};
  int iterations = 0;
  bool converged = false;

  // Capacity so that search() does not allocate.
  void reserve(std::size_t max_observations);
  void clear() noexcept;
};

class CorrespondenceSearch {
 public:
  // Options must validate() (asserted); create() checks them.
  explicit CorrespondenceSearch(CorrespondenceOptions options = {}, std::size_t max_markers = 64,
                                std::size_t max_observations = 128);
  static Result<CorrespondenceSearch> create(CorrespondenceOptions options, std::size_t max_markers = 64,
                                             std::size_t max_observations = 128);

  // The whole stage: predict the markers from the IMU-predicted hand pose,
  // compute their priors, run EM and assign. `marker_covariance_in_world`:
  // one per placed marker, or empty (then only Sigma_c and the observation
  // covariances count).
  Status search(const HandPose& predicted_pose_in_world, const Pose& T_world_leftcam, const StereoRig& rig,
                std::span<const PlacedMarker> placed, std::span<const Mat3> marker_covariance_in_world,
                std::span<const Observation3D> observations, CorrespondenceResult& out);

  // EM and assignment on already predicted markers and their priors.
  Status match(std::span<const PredictedMarker> markers, std::span<const double> priors,
               std::span<const Observation3D> observations, CorrespondenceResult& out);

  // The priors of the last search() (as long as its markers).
  std::span<const double> last_priors() const noexcept { return {priors_.data(), last_marker_count_}; }
  std::span<const MarkerPrior> last_prior_details() const noexcept {
    return {prior_details_.data(), last_marker_count_};
  }

  const CorrespondenceOptions& options() const noexcept { return options_; }
  std::size_t max_markers() const noexcept { return max_markers_; }
  std::size_t max_observations() const noexcept { return max_observations_; }

 private:
  // One (observation, marker) pair of the same hue with a nonzero prior.
  struct Pair {
    std::uint32_t obs = 0;
    std::uint32_t marker = 0;  // index into the markers span
    Mat3 information = Mat3::Identity();  // Sigma_ij^-1
    double weight = 0.0;  // (1 - w_c) pi_j (2 pi)^-3/2 |Sigma_ij|^-1/2
    double posterior = 0.0;
  };

  CorrespondenceOptions options_;
  std::size_t max_markers_ = 0;
  std::size_t max_observations_ = 0;
  std::vector<PredictedMarker> predicted_;
  std::vector<double> priors_;
  std::vector<MarkerPrior> prior_details_;
  std::size_t last_marker_count_ = 0;
  std::vector<Pair> pairs_;                     // grouped by observation
  std::vector<std::uint32_t> obs_pair_begin_;   // pairs of obs i: [begin[i], begin[i+1])
  std::vector<double> obs_outlier_density_;     // w_c U, or 0 for an unmatched hue
  std::vector<std::int32_t> best_pair_;         // per observation
  std::vector<std::int32_t> marker_owner_;      // per marker: the observation holding it, -1
};

}  // namespace proprio::vist
