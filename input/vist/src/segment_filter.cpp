#include "proprio/vist/segment_filter.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <sstream>

#include "proprio/core/log.hpp"

namespace proprio::vist {
namespace {

constexpr int D = kSegmentErrorDim;

// Which finger a joint belongs to and its position in the finger's chain.
bool finger_position(HandJoint j, Finger& finger, std::size_t& k) {
  for (std::size_t f = 0; f < kFingerCount; ++f) {
    const auto fj = finger_joints(static_cast<Finger>(f));
    for (std::size_t i = 0; i < fj.count; ++i) {
      if (fj.joints[i] == j) {
        finger = static_cast<Finger>(f);
        k = i;
        return true;
      }
    }
  }
  return false;
}

// The instrumented segment a segment hangs from: the previous bone of its
// finger, or the dorsum for a bone whose parent is a finger metacarpal (rigid
// with the dorsum) or for the thumb metacarpal.
HandJoint parent_segment(HandJoint child) {
  Finger f{};
  std::size_t k = 0;
  if (!finger_position(child, f, k) || k == 0) return HandJoint::wrist;
  if (f != Finger::thumb && k == 1) return HandJoint::wrist;
  return finger_joints(f).joints[k - 1];
}

bool state_finite(const SegmentState& s) {
  return s.p_imu_in_world.allFinite() && s.v_imu_in_world.allFinite() && s.q_world_imu.coeffs().allFinite() &&
         s.gyro_bias_radps.allFinite() && s.accel_bias_mps2.allFinite() && s.scale.allFinite() &&
         s.q_imu_segment.coeffs().allFinite();
}

}  // namespace

// --- Model -------------------------------------------------------------------

Result<VistModel> VistModel::build(const ImuGloveDescription& glove, const HandShape& nominal_shape, Handedness hand) {
  VistModel m;
  m.hand = hand;
  m.nominal_shape = nominal_shape;
  const auto imus = glove.place_imus(nominal_shape, hand);
  for (std::size_t i = 0; i < imus.size(); ++i) {
    if (m.segment_index(imus[i].segment) >= 0) {
      return make_error(Errc::invalid_argument, "glove '" + glove.name + "': two IMUs on segment " +
                                               std::string(to_string(imus[i].segment)) +
                                               "; the VIST filter needs exactly one IMU per tracked segment");
    }
    FilterSegment s;
    s.segment = imus[i].segment;
    s.imu_sensor_id = static_cast<std::uint16_t>(i);
    s.p_imu_in_segment = imus[i].T_segment_imu.p;
    s.q_segment_imu = imus[i].T_segment_imu.q;
    m.segments.push_back(s);
  }
  if (m.segments.empty()) return make_error(Errc::invalid_argument, "glove '" + glove.name + "' has no IMUs");

  m.placed_nominal = glove.place_markers(nominal_shape, hand);
  for (const auto& pm : m.placed_nominal) {
    const int k = m.segment_index(pm.segment);
    if (k < 0) {
      return make_error(Errc::invalid_argument, "glove '" + glove.name + "': marker " + std::to_string(pm.index) +
                                               " sits on " + std::string(to_string(pm.segment)) +
                                               ", which has no IMU; VIST tracks only segments that carry an IMU");
    }
    m.markers.push_back({pm.index, static_cast<std::size_t>(k),
                         pm.p_in_segment - m.segments[static_cast<std::size_t>(k)].p_imu_in_segment});
  }

  // Joint geometry from the nominal hand at zero angles: a joint rotates the
  // child about its own origin, so where the child's origin sits in the
  // parent's frame does not depend on the angles.
  const HandModel model(nominal_shape);
  HandAngles zero{};
  const auto T_wrist_joint = model.joint_poses_in_wrist(hand, zero);
  for (std::size_t c = 0; c < m.segments.size(); ++c) {
    const HandJoint child = m.segments[c].segment;
    if (child == HandJoint::wrist) continue;
    const int p = m.segment_index(parent_segment(child));
    if (p < 0) continue;
    const auto pi = static_cast<std::size_t>(p);
    const Pose T_parent_child =
        T_wrist_joint[index_of(m.segments[pi].segment)].inverse() * T_wrist_joint[index_of(child)];
    PositionConstraint pc;
    pc.joint = child;
    pc.parent = pi;
    pc.child = c;
    pc.lever_in_parent = T_parent_child.p - m.segments[pi].p_imu_in_segment;
    pc.lever_in_child = -m.segments[c].p_imu_in_segment;
    m.position_constraints.push_back(pc);

    Finger f{};
    std::size_t k = 0;
    finger_position(child, f, k);
    const bool mcp = (f == Finger::thumb) ? k == 1 : k == 1;
    const bool pip = f != Finger::thumb && k == 2;
    // Axes of the parent at the joint, in the parent frame (the joint's rest rotation).
    const Vec3 parent_y = T_parent_child.q * Vec3::UnitY();
    const Vec3 parent_z = T_parent_child.q * Vec3::UnitZ();
    if (mcp || pip) m.rotation_constraints.push_back({child, pi, c, parent_y, Vec3::UnitX(), "no twist"});
    if (m.segments[pi].segment != HandJoint::wrist) m.scale_couplings.push_back({pi, c});
    if (pip) m.rotation_constraints.push_back({child, pi, c, parent_z, Vec3::UnitX(), "no abduction"});
  }
  return m;
}

int VistModel::segment_index(HandJoint j) const noexcept {
  for (std::size_t i = 0; i < segments.size(); ++i) {
    if (segments[i].segment == j) return static_cast<int>(i);
  }
  return -1;
}

std::string VistModel::describe() const {
  std::ostringstream s;
  s << "VIST model (" << to_string(hand) << " hand, nominal " << nominal_shape.hand_length_m * 100 << " x "
    << nominal_shape.hand_width_m * 100 << " cm): " << segments.size() << " segments, " << markers.size()
    << " markers, " << position_constraints.size() << " joint and " << rotation_constraints.size()
    << " rotational constraints, " << scale_couplings.size() << " scale couplings\n";
  for (const auto& c : position_constraints) {
    s << "  joint " << to_string(c.joint) << ": " << to_string(segments[c.parent].segment) << " - "
      << to_string(segments[c.child].segment) << "\n";
  }
  for (const auto& c : rotation_constraints) s << "  " << to_string(c.joint) << ": " << c.what << "\n";
  return s.str();
}

// --- Options -----------------------------------------------------------------

Status FilterOptions::validate() const {
  auto positive = [](double v, const char* name) -> Status {
    if (!(v > 0.0) || !std::isfinite(v)) {
      return make_error(Errc::invalid_argument, std::string("VIST filter option ") + name + " must be > 0");
    }
    return {};
  };
  auto non_negative = [](double v, const char* name) -> Status {
    if (!(v >= 0.0) || !std::isfinite(v)) {
      return make_error(Errc::invalid_argument, std::string("VIST filter option ") + name + " must be >= 0");
    }
    return {};
  };
  for (auto st : {positive(noise.gyro_noise_density, "noise.gyro_noise_density"),
                  positive(noise.accel_noise_density, "noise.accel_noise_density"),
                  non_negative(noise.gyro_bias_random_walk, "noise.gyro_bias_random_walk"),
                  non_negative(noise.accel_bias_random_walk, "noise.accel_bias_random_walk"),
                  non_negative(noise.gyro_model_noise_density, "noise.gyro_model_noise_density"),
                  non_negative(noise.accel_model_noise_density, "noise.accel_model_noise_density"),
                  non_negative(noise.scale_random_walk, "noise.scale_random_walk"),
                  non_negative(noise.mounting_random_walk, "noise.mounting_random_walk"),
                  positive(initial.position_m, "initial.position_m"),
                  positive(initial.velocity_mps, "initial.velocity_mps"),
                  positive(initial.attitude_rad, "initial.attitude_rad"),
                  positive(initial.gyro_bias_radps, "initial.gyro_bias_radps"),
                  positive(initial.accel_bias_mps2, "initial.accel_bias_mps2"),
                  positive(initial.scale, "initial.scale"), positive(initial.mounting_rad, "initial.mounting_rad"),
                  positive(gravity_mps2, "gravity_mps2"), positive(joint_position_sigma_m, "joint_position_sigma_m"),
                  positive(joint_rotation_sigma, "joint_rotation_sigma"),
                  positive(scale_coupling_sigma, "scale_coupling_sigma"),
                  non_negative(marker_extra_sigma_m, "marker_extra_sigma_m"),
                  non_negative(clipped_accel_sigma_mps2, "clipped_accel_sigma_mps2"),
                  positive(marker_gate_chi2, "marker_gate_chi2"), positive(min_scale, "min_scale")}) {
    if (!st) return st;
  }
  if (!(max_scale > min_scale)) return make_error(Errc::invalid_argument, "VIST filter: max_scale must exceed min_scale");
  if (health_check_every < 1) return make_error(Errc::invalid_argument, "VIST filter: health_check_every must be >= 1");
  return {};
}

std::string FilterOptions::describe() const {
  std::ostringstream s;
  s << "VIST filter options:\n"
    << "  gyro noise " << noise.gyro_noise_density << " rad/s/√Hz (+ model " << noise.gyro_model_noise_density
    << "), accel noise " << noise.accel_noise_density << " m/s²/√Hz (+ model " << noise.accel_model_noise_density
    << ")\n"
    << "  bias walks " << noise.gyro_bias_random_walk << " rad/s²/√Hz, " << noise.accel_bias_random_walk
    << " m/s³/√Hz; scale walk " << noise.scale_random_walk << "/√s, mounting walk " << noise.mounting_random_walk
    << " rad/√s\n"
    << "  initial sigmas: position " << initial.position_m << " m, velocity " << initial.velocity_mps
    << " m/s, attitude " << initial.attitude_rad << " rad, gyro bias " << initial.gyro_bias_radps
    << " rad/s, accel bias " << initial.accel_bias_mps2 << " m/s², scale " << initial.scale << ", mounting "
    << initial.mounting_rad << " rad\n"
    << "  constraints: joint position sigma " << joint_position_sigma_m << " m, rotation sigma "
    << joint_rotation_sigma << ", scale coupling sigma " << scale_coupling_sigma << "\n"
    << "  markers: extra sigma " << marker_extra_sigma_m << " m, chi² gate " << marker_gate_chi2 << "\n"
    << "  clipped accelerometer: sigma " << clipped_accel_sigma_mps2 << " m/s²\n";
  return s.str();
}

// --- Filter ------------------------------------------------------------------

Result<VistFilter> VistFilter::create(VistModel model, FilterOptions options) {
  if (auto st = options.validate(); !st) return st.error();
  if (model.segments.empty()) return make_error(Errc::invalid_argument, "VIST filter: the model has no segments");
  return VistFilter(std::move(model), options);
}

VistFilter::VistFilter(VistModel model, FilterOptions options)
    : model_(std::move(model)), options_(options), g_world_(0.0, -options.gravity_mps2, 0.0) {
  const std::size_t n = model_.segments.size();
  const int N = static_cast<int>(n) * D;
  states_.resize(n);
  states_backup_.resize(n);
  times_.assign(n, 0);
  last_gyro_.assign(n, Vec3::Zero());
  last_accel_.assign(n, Vec3::Zero());
  last_accel_clipped_.assign(n, false);
  has_sample_.assign(n, false);
  phi_acc_.assign(n, Mat15::Identity());
  q_acc_.assign(n, Mat15::Zero());
  q_param_acc_.assign(n, Eigen::Matrix<double, 6, 1>::Zero());
  dirty_.assign(n, false);
  P_ = Eigen::MatrixXd::Zero(N, N);
  rows_tmp_.resize(9, N);
  cols_tmp_.resize(N, 9);
  const int max_blocks = static_cast<int>(model_.markers.size() + model_.position_constraints.size() +
                                          model_.rotation_constraints.size() + model_.scale_couplings.size());
  max_rows_ = 3 * static_cast<int>(model_.markers.size() + model_.position_constraints.size() +
                                   model_.scale_couplings.size()) +
              static_cast<int>(model_.rotation_constraints.size());
  PHt_.resize(N, max_rows_);
  S_.resize(max_rows_, max_rows_);
  W_.resize(max_rows_, N);
  r_.resize(max_rows_);
  Sinv_r_.resize(max_rows_);
  dx_.resize(N);
  blocks_.reserve(static_cast<std::size_t>(max_blocks));
}

Status VistFilter::initialize(TimeNs t_ns, std::span<const SegmentState> states) {
  if (states.size() != states_.size()) {
    return make_error(Errc::invalid_argument, "VIST filter: initialize needs " + std::to_string(states_.size()) +
                                             " segment states, got " + std::to_string(states.size()));
  }
  for (const auto& s : states) {
    if (!state_finite(s)) return make_error(Errc::invalid_argument, "VIST filter: initial state is not finite");
  }
  std::copy(states.begin(), states.end(), states_.begin());
  for (auto& s : states_) {
    s.q_world_imu.normalize();
    s.q_imu_segment.normalize();
  }
  times_.assign(states_.size(), t_ns);
  has_sample_.assign(states_.size(), false);
  P_.setZero();
  const auto& i = options_.initial;
  for (std::size_t k = 0; k < states_.size(); ++k) {
    const int o = static_cast<int>(k) * D;
    auto set = [&](int off, double sigma) { P_.block<3, 3>(o + off, o + off) = Mat3::Identity() * sigma * sigma; };
    set(kErrP, i.position_m);
    set(kErrV, i.velocity_mps);
    set(kErrTheta, i.attitude_rad);
    set(kErrBg, i.gyro_bias_radps);
    set(kErrBa, i.accel_bias_mps2);
    set(kErrScale, i.scale);
    set(kErrPhi, i.mounting_rad);
    phi_acc_[k].setIdentity();
    q_acc_[k].setZero();
    q_param_acc_[k].setZero();
    dirty_[k] = false;
  }
  initialized_ = true;
  return {};
}

Status VistFilter::reinitialize_pose(TimeNs t_ns, std::span<const SegmentState> states) {
  if (!initialized_) return initialize(t_ns, states);
  if (states.size() != states_.size()) {
    return make_error(Errc::invalid_argument, "VIST filter: reinitialize_pose needs one state per segment");
  }
  flush();
  const auto& i = options_.initial;
  for (std::size_t k = 0; k < states_.size(); ++k) {
    if (!state_finite(states[k])) return make_error(Errc::invalid_argument, "VIST filter: state is not finite");
    states_[k].p_imu_in_world = states[k].p_imu_in_world;
    states_[k].v_imu_in_world = states[k].v_imu_in_world;
    states_[k].q_world_imu = states[k].q_world_imu.normalized();
    times_[k] = t_ns;
    has_sample_[k] = false;
  }
  // Pose and velocity restart uncorrelated with everything; calibration keeps its covariance.
  const int N = static_cast<int>(P_.rows());
  for (std::size_t k = 0; k < states_.size(); ++k) {
    const int o = static_cast<int>(k) * D;
    P_.block(o, 0, 9, N).setZero();
    P_.block(0, o, N, 9).setZero();
    P_.block<3, 3>(o + kErrP, o + kErrP) = Mat3::Identity() * i.position_m * i.position_m;
    P_.block<3, 3>(o + kErrV, o + kErrV) = Mat3::Identity() * i.velocity_mps * i.velocity_mps;
    P_.block<3, 3>(o + kErrTheta, o + kErrTheta) = Mat3::Identity() * i.attitude_rad * i.attitude_rad;
  }
  return {};
}

void VistFilter::integrate_nominal(SegmentState& s, double dt_s, const Vec3& gyro_mean, const Vec3& accel_mean,
                                   const Vec3& g_world) noexcept {
  const Vec3 w = gyro_mean - s.gyro_bias_radps;
  const Vec3 a = accel_mean - s.accel_bias_mps2;
  // Specific force rotated with the attitude at mid-step: second-order accurate in dt.
  const Quat q_mid = s.q_world_imu * so3_exp(0.5 * dt_s * w);
  const Vec3 acc_world = q_mid * a + g_world;
  s.p_imu_in_world += s.v_imu_in_world * dt_s + 0.5 * dt_s * dt_s * acc_world;
  s.v_imu_in_world += dt_s * acc_world;
  s.q_world_imu = (s.q_world_imu * so3_exp(dt_s * w)).normalized();
}

bool VistFilter::propagate(std::size_t k, TimeNs t_ns, const Vec3& gyro_radps, const Vec3& accel_mps2,
                           bool accel_clipped) noexcept {
  if (k >= states_.size() || !gyro_radps.allFinite() || !accel_mps2.allFinite()) return false;
  if (t_ns < times_[k]) return false;
  const Vec3 gyro_prev = has_sample_[k] ? last_gyro_[k] : gyro_radps;
  const Vec3 accel_prev = has_sample_[k] ? last_accel_[k] : accel_mps2;
  // The step uses the mean of both samples: either one clipped spoils it.
  const bool clipped = accel_clipped || (has_sample_[k] && last_accel_clipped_[k]);
  const double dt = 1e-9 * static_cast<double>(t_ns - times_[k]);
  last_gyro_[k] = gyro_radps;
  last_accel_[k] = accel_mps2;
  last_accel_clipped_[k] = accel_clipped;
  has_sample_[k] = true;
  times_[k] = t_ns;
  if (dt <= 0.0 || !initialized_) return true;

  SegmentState& s = states_[k];
  const Vec3 gyro_mean = 0.5 * (gyro_prev + gyro_radps);
  const Vec3 accel_mean = 0.5 * (accel_prev + accel_mps2);
  const Mat15 phi = transition(s, dt, gyro_mean, accel_mean);

  // Noise (eq. 4.25 with densities): white accel and gyro noise enter velocity
  // and attitude; the biases walk.
  const auto& n = options_.noise;
  const double sa2 = n.accel_noise_density * n.accel_noise_density +
                     n.accel_model_noise_density * n.accel_model_noise_density;
  const double sg2 =
      n.gyro_noise_density * n.gyro_noise_density + n.gyro_model_noise_density * n.gyro_model_noise_density;
  Mat15 Q = Mat15::Zero();
  Q.block<3, 3>(0, 0) = Mat3::Identity() * sa2 * dt * dt * dt / 3.0;
  Q.block<3, 3>(0, 3) = Mat3::Identity() * sa2 * dt * dt / 2.0;
  Q.block<3, 3>(3, 0) = Q.block<3, 3>(0, 3);
  Q.block<3, 3>(3, 3) = Mat3::Identity() * sa2 * dt;
  Q.block<3, 3>(6, 6) = Mat3::Identity() * sg2 * dt;
  Q.block<3, 3>(9, 9) = Mat3::Identity() * n.gyro_bias_random_walk * n.gyro_bias_random_walk * dt;
  Q.block<3, 3>(12, 12) = Mat3::Identity() * n.accel_bias_random_walk * n.accel_bias_random_walk * dt;
  if (clipped) {
    // An unknown acceleration of this sigma held over the step.
    const double c2 = options_.clipped_accel_sigma_mps2 * options_.clipped_accel_sigma_mps2;
    Q.block<3, 3>(0, 0) += Mat3::Identity() * c2 * dt * dt * dt * dt / 4.0;
    Q.block<3, 3>(0, 3) += Mat3::Identity() * c2 * dt * dt * dt / 2.0;
    Q.block<3, 3>(3, 0) += Mat3::Identity() * c2 * dt * dt * dt / 2.0;
    Q.block<3, 3>(3, 3) += Mat3::Identity() * c2 * dt * dt;
  }

  phi_acc_[k] = phi * phi_acc_[k];
  q_acc_[k] = phi * q_acc_[k] * phi.transpose() + Q;
  q_param_acc_[k].head<3>().array() += n.scale_random_walk * n.scale_random_walk * dt;
  q_param_acc_[k].tail<3>().array() += n.mounting_random_walk * n.mounting_random_walk * dt;
  dirty_[k] = true;
  ++health_.imu_steps;

  integrate_nominal(s, dt, gyro_mean, accel_mean, g_world_);
  return true;
}

Eigen::Matrix<double, 15, 15> VistFilter::transition(const SegmentState& s, double dt, const Vec3& gyro_mean,
                                                     const Vec3& accel_mean) {
  const Vec3 w = gyro_mean - s.gyro_bias_radps;
  const Vec3 a = accel_mean - s.accel_bias_mps2;
  const Mat3 R = s.q_world_imu.toRotationMatrix();
  const Mat3 Ra = R * skew(a);
  // First order in dt, with the exact rotation block.
  Mat15 phi = Mat15::Identity();
  phi.block<3, 3>(0, 3) = Mat3::Identity() * dt;
  phi.block<3, 3>(0, 6) = -0.5 * dt * dt * Ra;
  phi.block<3, 3>(0, 12) = -0.5 * dt * dt * R;
  phi.block<3, 3>(3, 6) = -dt * Ra;
  phi.block<3, 3>(3, 9) = 0.5 * dt * dt * Ra;
  phi.block<3, 3>(3, 12) = -dt * R;
  phi.block<3, 3>(6, 6) = so3_exp(-dt * w).toRotationMatrix();
  phi.block<3, 3>(6, 9) = -dt * Mat3::Identity();
  return phi;
}

void VistFilter::propagate_all_to(TimeNs t_ns) noexcept {
  for (std::size_t k = 0; k < states_.size(); ++k) {
    if (t_ns > times_[k]) {
      if (has_sample_[k]) {
        // Hold the last sample: the mean of it with itself.
        const Vec3 g = last_gyro_[k], a = last_accel_[k];
        propagate(k, t_ns, g, a, last_accel_clipped_[k]);
      } else {
        times_[k] = t_ns;  // no IMU data yet: nothing to integrate
      }
    }
  }
}

void VistFilter::flush() noexcept {
  for (std::size_t k = 0; k < states_.size(); ++k) {
    if (!dirty_[k]) continue;
    const int o = static_cast<int>(k) * D;
    // The bias rows of the transition stay identity (biases only walk), so
    // only the position, velocity and attitude rows and columns change.
    const auto phi9 = phi_acc_[k].topRows<9>();
    rows_tmp_.noalias() = phi9 * P_.middleRows(o, 15);
    P_.middleRows(o, 9) = rows_tmp_;
    cols_tmp_.noalias() = P_.middleCols(o, 15) * phi9.transpose();
    P_.middleCols(o, 9) = cols_tmp_;
    P_.block<15, 15>(o, o) += q_acc_[k];
    for (int i = 0; i < 6; ++i) P_(o + 15 + i, o + 15 + i) += q_param_acc_[k](i);
    phi_acc_[k].setIdentity();
    q_acc_[k].setZero();
    q_param_acc_[k].setZero();
    dirty_[k] = false;
  }
}

const Eigen::MatrixXd& VistFilter::covariance() {
  flush();
  return P_;
}

Eigen::Matrix<double, kSegmentErrorDim, kSegmentErrorDim> VistFilter::segment_covariance(std::size_t k) {
  flush();
  const int o = static_cast<int>(k) * D;
  return P_.block<D, D>(o, o);
}

Vec3 VistFilter::marker_model(const SegmentState& s, const Vec3& lever, H3* H) {
  const Vec3 u = s.scale.cwiseProduct(lever);
  const Mat3 R_wi = s.q_world_imu.toRotationMatrix();
  const Mat3 R_ib = s.q_imu_segment.toRotationMatrix();
  const Vec3 w = R_ib * u;
  if (H) {
    H->setZero();
    H->block<3, 3>(0, kErrP) = Mat3::Identity();
    H->block<3, 3>(0, kErrTheta) = -R_wi * skew(w);
    H->block<3, 3>(0, kErrScale) = R_wi * R_ib * lever.asDiagonal();
    H->block<3, 3>(0, kErrPhi) = -R_wi * R_ib * skew(u);
  }
  return s.p_imu_in_world + R_wi * w;
}

Vec3 VistFilter::position_constraint_model(const SegmentState& parent, const SegmentState& child,
                                           const PositionConstraint& c, H3* H_parent, H3* H_child) {
  const Vec3 a = marker_model(parent, c.lever_in_parent, H_parent);
  const Vec3 b = marker_model(child, c.lever_in_child, H_child);
  if (H_child) *H_child = -*H_child;
  return a - b;
}

double VistFilter::rotation_constraint_model(const SegmentState& parent, const SegmentState& child,
                                             const RotationConstraint& c, H1* H_parent, H1* H_child) {
  const Mat3 R_wi_p = parent.q_world_imu.toRotationMatrix();
  const Mat3 R_ib_p = parent.q_imu_segment.toRotationMatrix();
  const Mat3 R_wi_c = child.q_world_imu.toRotationMatrix();
  const Mat3 R_ib_c = child.q_imu_segment.toRotationMatrix();
  const Mat3 R_wb_p = R_wi_p * R_ib_p;
  const Mat3 R_wb_c = R_wi_c * R_ib_c;
  const Vec3 A = R_wb_p * c.a_in_parent;
  const Vec3 B = R_wb_c * c.b_in_child;
  if (H_parent) {
    H_parent->setZero();
    H_parent->block<1, 3>(0, kErrTheta) = -B.transpose() * R_wi_p * skew(R_ib_p * c.a_in_parent);
    H_parent->block<1, 3>(0, kErrPhi) = -B.transpose() * R_wb_p * skew(c.a_in_parent);
  }
  if (H_child) {
    H_child->setZero();
    H_child->block<1, 3>(0, kErrTheta) = -A.transpose() * R_wi_c * skew(R_ib_c * c.b_in_child);
    H_child->block<1, 3>(0, kErrPhi) = -A.transpose() * R_wb_c * skew(c.b_in_child);
  }
  return A.dot(B);
}

void VistFilter::inject(SegmentState& s, const Eigen::Matrix<double, kSegmentErrorDim, 1>& dx) noexcept {
  s.p_imu_in_world += dx.segment<3>(kErrP);
  s.v_imu_in_world += dx.segment<3>(kErrV);
  s.q_world_imu = boxplus(s.q_world_imu, dx.segment<3>(kErrTheta)).normalized();
  s.gyro_bias_radps += dx.segment<3>(kErrBg);
  s.accel_bias_mps2 += dx.segment<3>(kErrBa);
  s.scale += dx.segment<3>(kErrScale);
  s.q_imu_segment = boxplus(s.q_imu_segment, dx.segment<3>(kErrPhi)).normalized();
}

Vec3 VistFilter::marker_in_world(std::size_t marker) const {
  const auto& m = model_.markers[marker];
  return states_[m.segment].point_in_world(m.lever_in_segment);
}

Mat3 VistFilter::marker_covariance_in_world(std::size_t marker) {
  flush();
  const auto& m = model_.markers[marker];
  H3 H;
  marker_model(states_[m.segment], m.lever_in_segment, &H);
  const int o = static_cast<int>(m.segment) * D;
  return H * P_.block<D, D>(o, o) * H.transpose();
}

CorrectionStats VistFilter::correct(std::span<const MarkerMeasurement> markers, bool use_constraints) noexcept {
  CorrectionStats st;
  if (!initialized_) return st;
  flush();
  blocks_.clear();
  int rows = 0;
  const double extra2 = options_.marker_extra_sigma_m * options_.marker_extra_sigma_m;

  // Markers, each gated on its own innovation.
  for (const auto& mm : markers) {
    if (mm.marker >= model_.markers.size() || rows + 3 > max_rows_) continue;
    if (!mm.p_in_world.allFinite() || !mm.covariance_in_world.allFinite()) {
      ++st.markers_gated;
      continue;
    }
    const auto& fm = model_.markers[mm.marker];
    RowBlock b;
    b.row = rows;
    b.dim = 3;
    b.seg_a = static_cast<int>(fm.segment);
    const Vec3 h = marker_model(states_[fm.segment], fm.lever_in_segment, &b.Ha);
    const Vec3 res = mm.p_in_world - h;
    const Mat3 Rm = mm.covariance_in_world + Mat3::Identity() * extra2;
    const int o = b.seg_a * D;
    const Mat3 Sb = b.Ha * P_.block<D, D>(o, o) * b.Ha.transpose() + Rm;
    const double nis = res.dot(Sb.ldlt().solve(res));
    if (!(nis <= options_.marker_gate_chi2)) {
      ++st.markers_gated;
      continue;
    }
    st.marker_nis_sum += nis;
    ++st.markers_used;
    r_.segment<3>(rows) = res;
    b.Hb.setZero();
    b.R = Rm;
    blocks_.push_back(b);
    rows += 3;
  }

  if (use_constraints) {
    // One row block per pseudo-measurement between two segments, noise sigma² I.
    auto add_block = [&](int dim, std::size_t a, std::size_t b, double sigma) -> RowBlock& {
      RowBlock& blk = blocks_.emplace_back();
      blk.row = rows;
      blk.dim = dim;
      blk.seg_a = static_cast<int>(a);
      blk.seg_b = static_cast<int>(b);
      blk.Ha.setZero();
      blk.Hb.setZero();
      blk.R = Mat3::Identity() * sigma * sigma;
      rows += dim;
      return blk;
    };
    for (const auto& c : model_.position_constraints) {
      RowBlock& b = add_block(3, c.parent, c.child, options_.joint_position_sigma_m);
      r_.segment<3>(b.row) = -position_constraint_model(states_[c.parent], states_[c.child], c, &b.Ha, &b.Hb);
    }
    for (const auto& c : model_.rotation_constraints) {
      RowBlock& b = add_block(1, c.parent, c.child, options_.joint_rotation_sigma);
      H1 Hp, Hc;
      r_(b.row) = -rotation_constraint_model(states_[c.parent], states_[c.child], c, &Hp, &Hc);
      b.Ha.row(0) = Hp;
      b.Hb.row(0) = Hc;
    }
    for (const auto& c : model_.scale_couplings) {
      RowBlock& b = add_block(3, c.a, c.b, options_.scale_coupling_sigma);
      b.Ha.block<3, 3>(0, kErrScale) = Mat3::Identity();
      b.Hb.block<3, 3>(0, kErrScale) = -Mat3::Identity();
      r_.segment<3>(b.row) = -(states_[c.a].scale - states_[c.b].scale);
    }
    st.constraint_rows = static_cast<std::size_t>(rows) - 3 * st.markers_used;
  }
  if (rows == 0) return st;

  // PHᵀ, exploiting that each row block touches one or two segments.
  auto PHt = PHt_.leftCols(rows);
  for (const auto& b : blocks_) {
    PHt.middleCols(b.row, b.dim).noalias() = P_.middleCols(b.seg_a * D, D) * b.Ha.topRows(b.dim).transpose();
    if (b.seg_b >= 0) {
      PHt.middleCols(b.row, b.dim).noalias() += P_.middleCols(b.seg_b * D, D) * b.Hb.topRows(b.dim).transpose();
    }
  }
  // S = H P Hᵀ + R (measurement noises are independent: R is block-diagonal).
  auto S = S_.topLeftCorner(rows, rows);
  S.setZero();
  for (const auto& b : blocks_) {
    S.block(b.row, b.row, b.dim, b.dim) = b.R.topLeftCorner(b.dim, b.dim);
    S.middleRows(b.row, b.dim).noalias() += b.Ha.topRows(b.dim) * PHt.middleRows(b.seg_a * D, D);
    if (b.seg_b >= 0) S.middleRows(b.row, b.dim).noalias() += b.Hb.topRows(b.dim) * PHt.middleRows(b.seg_b * D, D);
  }

  Eigen::LLT<Eigen::Ref<Eigen::MatrixXd>> llt(S);
  if (llt.info() != Eigen::Success) {
    ++health_.non_finite_rejected;
    return st;
  }
  Sinv_r_.head(rows) = llt.solve(r_.head(rows));
  dx_.noalias() = PHt * Sinv_r_.head(rows);
  // Undo nothing: refuse a correction that is not finite before touching anything.
  bool ok = dx_.allFinite();
  for (std::size_t k = 0; k < states_.size() && ok; ++k) {
    states_backup_[k] = states_[k];
    inject(states_backup_[k], dx_.segment<D>(static_cast<int>(k) * D));
    ok = state_finite(states_backup_[k]);
  }
  if (!ok) {
    ++health_.non_finite_rejected;
    logger().warn("VIST filter: a correction came out non-finite; skipped");
    return st;
  }
  for (std::size_t k = 0; k < states_.size(); ++k) {
    states_[k] = states_backup_[k];
    states_[k].scale = states_[k].scale.cwiseMax(options_.min_scale).cwiseMin(options_.max_scale);
  }
  auto W = W_.topRows(rows);
  W = PHt.transpose();
  llt.matrixL().solveInPlace(W);
  P_.selfadjointView<Eigen::Lower>().rankUpdate(W.transpose(), -1.0);
  P_.triangularView<Eigen::StrictlyUpper>() = P_.transpose();
  bool positive = P_.allFinite();
  for (int i = 0; i < P_.rows() && positive; ++i) positive = P_(i, i) > 0.0;
  if (!positive) {
    logger().warn("VIST filter: covariance lost positive-definiteness in a correction; repairing");
    check_health();
  }
  st.applied = true;
  ++health_.corrections;
  if (health_.corrections % static_cast<std::uint64_t>(options_.health_check_every) == 0) check_health();
  return st;
}

void VistFilter::check_health() noexcept {
  if (P_.allFinite()) {
    Eigen::LLT<Eigen::MatrixXd> llt(P_);
    if (llt.info() == Eigen::Success) return;
  } else {
    P_ = P_.unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; });
  }
  // Clamp the spectrum: keeps the directions, restores positive-definiteness.
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(P_);
  Eigen::VectorXd ev = es.eigenvalues().cwiseMax(1e-12);
  P_ = es.eigenvectors() * ev.asDiagonal() * es.eigenvectors().transpose();
  P_ = 0.5 * (P_ + P_.transpose()).eval();
  ++health_.covariance_repairs;
  logger().warn("VIST filter: covariance was not positive-definite; repaired (eigenvalues clamped)");
}

}  // namespace proprio::vist
