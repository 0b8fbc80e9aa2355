#pragma once
// VIST sensor fusion (Lee 2021, §4.5, eqs. 4.14-4.39): one error-state EKF
// over all instrumented hand segments, each a free rigid body carried by its
// IMU, corrected by the corresponded glove markers and by anatomical
// constraints between adjacent segments, with online calibration of each
// segment's scale and of each IMU's mounting.
//
// State of segment k (nominal 16 + 7, error 15 + 6, eqs. 4.14, 4.15, 4.20):
//   p_imu_in_world, v_imu_in_world, q_world_imu, gyro bias, accel bias | scale, q_imu_segment
//   error: [dp dv dtheta dbg dba | dscale dphi], 21 per segment, in that order.
//
// Quaternions are Hamilton (Eigen). The thesis follows Trawny & Roumeliotis
// (JPL, q_true = dq (x) q_hat with the error in the IMU frame). Its error
// dynamics (4.21, 4.24) are exactly those of the Hamilton right (local)
// perturbation used here,
//   R_world_imu = R_hat_world_imu Exp(dtheta),   R_imu_segment = R_hat_imu_segment Exp(dphi),
// so F and G carry over unchanged; the measurement Jacobians are derived
// afresh for this convention (the signs of 4.31 and 4.37 differ with the
// residual convention) and checked against finite differences in
// tests/unit/input/vist/test_vist_filter.cpp.
//
// Geometry (eq. 4.28, Fig. 4.5): a point designed at x_in_segment on the
// nominal glove sits, on the user's hand, at
//   p_world = p_imu_in_world + R_world_imu R_imu_segment diag(scale) (x_in_segment - p_imu_in_segment)
// i.e. the glove stretches with the segment about its IMU.
//
// Rotational constraints. The thesis writes them as a zero component of the
// relative quaternion (4.35). For a 2-DOF (flexion + abduction) joint that
// component is not zero (it is sin(abd/2) sin(flex/2)), so we use the exact
// form for the hand model's joints (universal and hinge joints): an axis of the
// parent stays orthogonal to an axis of the child,
//   c = a_in_parentᵀ R_world_parentᵀ R_world_child b_in_child = 0,
// e.g. no twist at the MCP: the child's flexion axis (+X) stays orthogonal to
// the parent's abduction axis (+Y). Same count and meaning as the thesis: no
// twist at the thumb, index and middle MCP; no twist and no abduction at the
// index and middle PIP.
//
// Covariance propagation is deferred: each segment's transition and noise
// over the IMU steps since the last correction are accumulated (15 x 15,
// block-diagonal across segments) and applied to the joint covariance only
// when a correction or a covariance query needs it. This is exact and moves
// the 147 x 147 work from the IMU rate to the camera rate.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"

namespace proprio::vist {

inline constexpr int kSegmentErrorDim = 21;
// Offsets into a segment's 21 error-state entries.
inline constexpr int kErrP = 0, kErrV = 3, kErrTheta = 6, kErrBg = 9, kErrBa = 12, kErrScale = 15, kErrPhi = 18;

// One instrumented segment: which IMU rides on it and where (nominal glove).
struct FilterSegment {
  HandJoint segment = HandJoint::wrist;
  std::uint16_t imu_sensor_id = 0;  // ImuSample::sensor_id feeding this segment
  Vec3 p_imu_in_segment = Vec3::Zero();
  Quat q_segment_imu = Quat::Identity();  // nominal IMU axes in the segment frame
};

struct FilterMarker {
  std::size_t glove_index = 0;  // PlacedMarker::index
  std::size_t segment = 0;      // index into VistModel::segments
  Vec3 lever_in_segment = Vec3::Zero();  // L of eq. 4.28: x_marker - p_imu, nominal, segment frame
};

// Adjacent segments meet at a joint (eq. 4.32).
struct PositionConstraint {
  HandJoint joint = HandJoint::wrist;
  std::size_t parent = 0, child = 0;  // indices into VistModel::segments
  Vec3 lever_in_parent = Vec3::Zero();  // joint - p_imu, nominal, parent frame
  Vec3 lever_in_child = Vec3::Zero();
};

// a_in_parent ⟂ b_in_child (see the top of this file).
struct RotationConstraint {
  HandJoint joint = HandJoint::wrist;
  std::size_t parent = 0, child = 0;
  Vec3 a_in_parent = Vec3::UnitY();
  Vec3 b_in_child = Vec3::UnitX();
  std::string_view what;  // "no twist", "no abduction"
};

// Adjacent bones of one finger grow together: their scales agree up to
// scale_coupling_sigma. Without it a segment whose markers rarely face the
// camera (the intermediate phalanges of a curled finger) cannot calibrate.
struct ScaleCoupling {
  std::size_t a = 0, b = 0;  // indices into VistModel::segments
};

// The glove and the nominal hand, as the filter sees them.
struct VistModel {
  Handedness hand = Handedness::right;
  HandShape nominal_shape;
  std::vector<FilterSegment> segments;
  std::vector<FilterMarker> markers;      // one per glove marker, in glove order
  std::vector<PlacedMarker> placed_nominal;  // the glove's markers placed on the nominal hand
  std::vector<PositionConstraint> position_constraints;
  std::vector<RotationConstraint> rotation_constraints;
  std::vector<ScaleCoupling> scale_couplings;

  // Segments: the glove's IMU mounts (one IMU per segment). Constraints: the
  // thesis's six joints and seven rotational constraints, wherever both
  // segments are instrumented. Errors when a segment has two IMUs, a marker
  // sits on a segment without an IMU, or the shape is not usable.
  static Result<VistModel> build(const ImuGloveDescription& glove, const HandShape& nominal_shape, Handedness hand);
  // Index of the segment riding on this joint, or -1.
  int segment_index(HandJoint j) const noexcept;
  std::string describe() const;
};

struct SegmentState {
  Vec3 p_imu_in_world = Vec3::Zero();
  Vec3 v_imu_in_world = Vec3::Zero();
  Quat q_world_imu = Quat::Identity();
  Vec3 gyro_bias_radps = Vec3::Zero();
  Vec3 accel_bias_mps2 = Vec3::Zero();
  Vec3 scale = Vec3::Ones();  // lambda_B, per segment axis
  Quat q_imu_segment = Quat::Identity();

  Quat q_world_segment() const { return (q_world_imu * q_imu_segment).normalized(); }
  // Where a nominal segment point is on the user's hand (eq. 4.28).
  Vec3 point_in_world(const Vec3& lever_in_segment) const {
    return p_imu_in_world + q_world_imu * (q_imu_segment * scale.cwiseProduct(lever_in_segment));
  }
  // The segment frame (its joint) in the world: origin where the nominal origin maps.
  Pose T_world_segment(const Vec3& p_imu_in_segment) const {
    return Pose{q_world_segment(), point_in_world(-p_imu_in_segment)};
  }
};

struct FilterNoise {
  // IMU: continuous-time densities (same convention as the simulator; the
  // defaults are the MPU-9250 datasheet values and its assumed bias walks).
  double gyro_noise_density = 0.01 * 0.017453292519943295;  // rad/s/√Hz
  double accel_noise_density = 300e-6 * 9.80665;            // m/s²/√Hz
  double gyro_bias_random_walk = 5e-5;                       // rad/s²/√Hz
  double accel_bias_random_walk = 2e-3;                      // m/s³/√Hz
  // Extra white noise on top (model error: IMU not exactly rigid with the
  // bone, skin and glove sliding, integration error). Densities.
  double gyro_model_noise_density = 0.001;   // rad/s/√Hz
  double accel_model_noise_density = 0.01;   // m/s²/√Hz
  // Calibration parameters drift slowly (eq. 4.22): random walks.
  double scale_random_walk = 1e-4;      // 1/√s
  double mounting_random_walk = 1e-4;   // rad/√s
};

struct FilterInitialSigma {
  double position_m = 0.03;
  double velocity_mps = 0.3;
  double attitude_rad = 0.25;
  double gyro_bias_radps = 0.03;   // MPU-9250 turn-on ZRO ±5 °/s read as ±3σ
  double accel_bias_mps2 = 0.25;   // ±60-80 mg as ±3σ
  double scale = 0.08;             // hand sizes ±8 % around the nominal
  double mounting_rad = 0.1;       // misalignment up to ~10°
};

struct FilterOptions {
  FilterNoise noise;
  FilterInitialSigma initial;
  double gravity_mps2 = 9.80665;
  double joint_position_sigma_m = 0.002;   // pseudo-measurement noise, positional constraints
  double joint_rotation_sigma = 0.02;      // of the axis dot product (≈ rad)
  // Phalanx length ratios vary between people by a few per cent (Buchholz
  // et al. 1992 report their ratios with such spreads): an assumption.
  double scale_coupling_sigma = 0.03;
  // Marker measurements: added to the triangulation covariance. It stands
  // for how far a marker may sit from its place in the glove's file: 2.5 mm
  // for a hand-sewn glove (1.5 mm of making and 2 mm of donning, the
  // simulator's sim::GloveBuildErrors). A glove measured against its file
  // can set it lower; trusting the file more than it deserves makes the
  // filter overconfident and less accurate (docs/benchmarks.md).
  double marker_extra_sigma_m = 0.0025;
  // A sample whose accelerometer clipped (a quick flick swings a fingertip
  // IMU past 16 g) still has a good gyro: it is integrated, and the unknown
  // part of its acceleration enters the velocity as white noise of this
  // sigma (about half the MPU-9250's 16 g range again beyond the clip).
  double clipped_accel_sigma_mps2 = 80.0;
  // Chi-square gate per marker (3 DOF): 16.27 is the 99.9 % quantile.
  double marker_gate_chi2 = 16.27;
  // Scales are kept in this range whatever a correction says.
  double min_scale = 0.6, max_scale = 1.6;
  // Every this many corrections the covariance is checked (Cholesky) and
  // repaired if it is not positive-definite.
  int health_check_every = 30;

  Status validate() const;
  std::string describe() const;
};

struct MarkerMeasurement {
  std::size_t marker = 0;  // index into VistModel::markers
  Vec3 p_in_world = Vec3::Zero();
  Mat3 covariance_in_world = Mat3::Zero();
};

struct CorrectionStats {
  std::size_t markers_used = 0;
  std::size_t markers_gated = 0;  // failed the chi-square gate
  std::size_t constraint_rows = 0;
  double marker_nis_sum = 0.0;    // sum of the used markers' normalised innovations squared
  bool applied = false;
};

struct FilterHealth {
  std::uint64_t corrections = 0;
  std::uint64_t covariance_repairs = 0;   // not positive-definite: eigenvalues clamped
  std::uint64_t non_finite_rejected = 0;  // a correction that would produce NaN/inf was skipped
  std::uint64_t imu_steps = 0;
};

class VistFilter {
 public:
  static Result<VistFilter> create(VistModel model, FilterOptions options = {});

  // Sets every segment's state at time t and the initial covariance from
  // options().initial (no cross-correlation). `states` has one entry per segment.
  Status initialize(TimeNs t_ns, std::span<const SegmentState> states);
  // Keeps calibration (biases, scales, mountings) and their covariance;
  // resets pose and velocity to `states` with the initial pose uncertainty
  // (re-acquisition after the hand was lost).
  Status reinitialize_pose(TimeNs t_ns, std::span<const SegmentState> states);
  bool initialized() const noexcept { return initialized_; }

  // One IMU sample of segment k, measured at t (after the segment's time).
  // Integrates from the segment's time to t with the mean of the previous and
  // this sample. Rejects non-finite samples (returns false; the caller counts).
  // accel_clipped: the device flagged its accelerometer as clipped
  // (FilterOptions::clipped_accel_sigma_mps2).
  bool propagate(std::size_t k, TimeNs t_ns, const Vec3& gyro_radps, const Vec3& accel_mps2,
                 bool accel_clipped = false) noexcept;
  // Brings every segment to time t by holding its last sample (t >= each segment's time).
  void propagate_all_to(TimeNs t_ns) noexcept;

  // Marker and constraint corrections in one update at the segments' common
  // time (call propagate_all_to first). `use_constraints=false` gives the
  // markers alone. No allocation.
  CorrectionStats correct(std::span<const MarkerMeasurement> markers, bool use_constraints = true) noexcept;

  // Predicted marker position on the user's hand and its covariance (world).
  Vec3 marker_in_world(std::size_t marker) const;
  Mat3 marker_covariance_in_world(std::size_t marker);  // flushes deferred propagation
  // Marginal covariance of segment k's 21 error states.
  Eigen::Matrix<double, kSegmentErrorDim, kSegmentErrorDim> segment_covariance(std::size_t k);

  std::span<const SegmentState> states() const noexcept { return states_; }
  const SegmentState& state(std::size_t k) const { return states_[k]; }
  TimeNs time_ns(std::size_t k) const { return times_[k]; }
  // Latest bias-corrected angular rate of segment k (IMU frame).
  Vec3 angular_rate_in_imu(std::size_t k) const { return last_gyro_[k] - states_[k].gyro_bias_radps; }
  // The last raw sample of segment k (held when propagating past it); false before the first.
  bool last_sample(std::size_t k, Vec3& gyro_radps, Vec3& accel_mps2) const {
    gyro_radps = last_gyro_[k];
    accel_mps2 = last_accel_[k];
    return has_sample_[k];
  }
  Pose T_world_segment(std::size_t k) const { return states_[k].T_world_segment(model_.segments[k].p_imu_in_segment); }

  const VistModel& model() const noexcept { return model_; }
  const FilterOptions& options() const noexcept { return options_; }
  const FilterHealth& health() const noexcept { return health_; }
  std::size_t segment_count() const noexcept { return states_.size(); }
  // The full joint covariance (after flushing).
  const Eigen::MatrixXd& covariance();

  // Nominal-state-only integration of one sample, used for output prediction
  // on a copy of the states (no covariance). Same discretisation as propagate().
  static void integrate_nominal(SegmentState& s, double dt_s, const Vec3& gyro_mean, const Vec3& accel_mean,
                                const Vec3& g_world) noexcept;

  // Error-state transition of one IMU step (eq. 4.24 discretised), for mean
  // raw samples over dt; what propagate() applies. Exposed for tests.
  static Eigen::Matrix<double, 15, 15> transition(const SegmentState& s, double dt_s, const Vec3& gyro_mean,
                                                   const Vec3& accel_mean);

  // Residual and Jacobians of the measurement models (exposed for the
  // finite-difference tests). H blocks are 3 x 21 / 1 x 21 per segment.
  using H3 = Eigen::Matrix<double, 3, kSegmentErrorDim>;
  using H1 = Eigen::Matrix<double, 1, kSegmentErrorDim>;
  static Vec3 marker_model(const SegmentState& s, const Vec3& lever, H3* H);
  static Vec3 position_constraint_model(const SegmentState& parent, const SegmentState& child,
                                        const PositionConstraint& c, H3* H_parent, H3* H_child);
  static double rotation_constraint_model(const SegmentState& parent, const SegmentState& child,
                                          const RotationConstraint& c, H1* H_parent, H1* H_child);
  // Applies an error-state correction to a state (the boxplus of eq. 4.20).
  static void inject(SegmentState& s, const Eigen::Matrix<double, kSegmentErrorDim, 1>& dx) noexcept;

 private:
  VistFilter(VistModel model, FilterOptions options);
  void flush() noexcept;
  void check_health() noexcept;

  using Mat15 = Eigen::Matrix<double, 15, 15>;
  VistModel model_;
  FilterOptions options_;
  Vec3 g_world_;
  bool initialized_ = false;
  std::vector<SegmentState> states_;
  std::vector<SegmentState> states_backup_;  // corrected states, checked before they replace states_
  std::vector<TimeNs> times_;
  std::vector<Vec3> last_gyro_, last_accel_;
  std::vector<bool> last_accel_clipped_;
  std::vector<bool> has_sample_;
  // Deferred propagation: accumulated transition and noise since the last flush.
  std::vector<Mat15> phi_acc_, q_acc_;
  std::vector<Eigen::Matrix<double, 6, 1>> q_param_acc_;
  std::vector<bool> dirty_;
  Eigen::MatrixXd P_;
  // Work buffers sized once (no allocation in correct()).
  Eigen::Matrix<double, 9, Eigen::Dynamic> rows_tmp_;
  Eigen::Matrix<double, Eigen::Dynamic, 9> cols_tmp_;
  Eigen::MatrixXd PHt_, S_, W_;
  Eigen::VectorXd r_, Sinv_r_, dx_;
  struct RowBlock {
    int row = 0, dim = 0;
    int seg_a = -1, seg_b = -1;
    Eigen::Matrix<double, 3, kSegmentErrorDim> Ha, Hb;
    Mat3 R = Mat3::Zero();  // measurement noise of this block
  };
  std::vector<RowBlock> blocks_;
  int max_rows_ = 0;
  FilterHealth health_;
};

}  // namespace proprio::vist
