// platform_3dof: a plate under the fingertip pad hung from three wires at
// 120 deg, in the manner of Prattichizzo, Chinello, Pacchierotti & Malvezzi
// (IEEE ToH 2013, "Towards wearability in fingertip haptics: a 3-DoF wearable
// device for cutaneous force feedback"). Equations in device_model.hpp and
// docs/haptic-devices.md.
#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "proprio/haptics/device_model.hpp"

namespace proprio::haptics {

namespace {

std::string num4(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

// Geometry and stiffness, shared by the model and by PlatformParams::validate.
// Positions are in the plate frame: fingertip-frame axes, origin at the
// plate's rest centre, so the plate centre p is also its displacement.
class Platform {
 public:
  explicit Platform(const PlatformParams& p) : p_(p) {
    for (std::size_t i = 0; i < 3; ++i) {
      const double a = p.leg_angles_rad[i];
      const double reach = p.anchor_radius_m - p.plate_radius_m;
      // A wire from plate attachment B_i to exit A_i: the plate centre p sits
      // at distance l_i from C_i = A_i - B_i.
      c_[i] = Vec3(reach * std::cos(a), p.anchor_height_m, reach * std::sin(a));
      rest_len_[i] = c_[i].norm();
    }
    // Subtracting sphere 0 from spheres 1 and 2 leaves two linear equations in
    // the plate's (x, z), because every C_i lies at the same height.
    Eigen::Matrix2d a;
    a << 2.0 * (c_[1].x() - c_[0].x()), 2.0 * (c_[1].z() - c_[0].z()), 2.0 * (c_[2].x() - c_[0].x()),
        2.0 * (c_[2].z() - c_[0].z());
    det_ = a.determinant();
    a_inv_ = std::abs(det_) > 0.0 ? Eigen::Matrix2d(a.inverse()) : Eigen::Matrix2d::Zero();
  }

  // The horizontal offsets of the wire exits must not be collinear, or the
  // wires cannot hold the plate sideways. det_ is in m^2; compare with the
  // square of the offset so the test does not depend on scale.
  bool well_posed() const noexcept {
    const double reach = std::abs(p_.anchor_radius_m - p_.plate_radius_m);
    return reach > 0.0 && std::abs(det_) > 1e-3 * reach * reach;
  }

  double rest_length(std::size_t i) const noexcept { return rest_len_[i]; }
  double length(std::size_t i, const Vec3& p) const noexcept { return (c_[i] - p).norm(); }

  // Forward kinematics: plate position from the three wire lengths, closed
  // form (trilateration); the plate hangs below the wire exits.
  Vec3 plate(const std::array<double, 3>& len) const noexcept {
    const auto h2 = [](const Vec3& v) { return v.x() * v.x() + v.z() * v.z(); };
    const Eigen::Vector2d rhs(h2(c_[1]) - h2(c_[0]) - len[1] * len[1] + len[0] * len[0],
                              h2(c_[2]) - h2(c_[0]) - len[2] * len[2] + len[0] * len[0]);
    const Eigen::Vector2d xz = a_inv_ * rhs;
    const double dx = c_[0].x() - xz.x();
    const double dz = c_[0].z() - xz.y();
    // Lengths too short to reach the plate's plane put it at the exits' height.
    const double below = std::sqrt(std::max(0.0, len[0] * len[0] - dx * dx - dz * dz));
    return Vec3(xz.x(), p_.anchor_height_m - below, xz.y());
  }

  // Wire tensions t (N, positive = pulling) that hold the plate at p while it
  // presses force f_in_tip on the fingertip: sum_i t_i u_i = f, u_i the unit
  // vector from the plate toward exit i. False if the wires are degenerate.
  bool tensions(const Vec3& p, const Vec3& f_in_tip, Vec3& t) const noexcept {
    Mat3 u;
    for (std::size_t i = 0; i < 3; ++i) {
      const Vec3 d = c_[i] - p;
      const double n = d.norm();
      if (!(n > 0.0)) return false;
      u.col(static_cast<Eigen::Index>(i)) = d / n;
    }
    const double det = u.determinant();
    if (!(std::abs(det) > 1e-9)) return false;
    t = u.inverse() * f_in_tip;
    return true;
  }

  double normal_force(double indent_m) const noexcept {
    if (!(indent_m > 0.0)) return 0.0;
    if (p_.normal_model == PlatformParams::NormalModel::linear) return p_.normal_stiffness_n_per_m * indent_m;
    const double b = p_.exp_initial_stiffness_n_per_m;
    const double m = p_.exp_rate_per_m;
    return b / m * std::expm1(m * indent_m);
  }
  double indentation(double normal_n) const noexcept {
    if (!(normal_n > 0.0)) return 0.0;
    if (p_.normal_model == PlatformParams::NormalModel::linear) return normal_n / p_.normal_stiffness_n_per_m;
    const double b = p_.exp_initial_stiffness_n_per_m;
    const double m = p_.exp_rate_per_m;
    return std::log1p(m * normal_n / b) / m;
  }

  // Plate displacement that presses f on the pad.
  Vec3 displacement(const FingertipForce& f) const noexcept {
    return Vec3(f.shear_x_n / p_.shear_stiffness_x_n_per_m, indentation(f.normal_n),
                f.shear_z_n / p_.shear_stiffness_z_n_per_m);
  }
  // Force the plate at p presses on the pad: none when it does not touch.
  FingertipForce force(const Vec3& p) const noexcept {
    if (!p.allFinite()) {
      const double nan = std::nan("");
      return FingertipForce{nan, nan, nan};
    }
    if (!(p.y() > 0.0)) return {};
    return FingertipForce{normal_force(p.y()), p_.shear_stiffness_x_n_per_m * p.x(),
                          p_.shear_stiffness_z_n_per_m * p.z()};
  }

  std::array<double, 3> lengths(const MotorAngles& q) const noexcept {
    std::array<double, 3> len{};
    for (std::size_t i = 0; i < 3; ++i) {
      len[i] = rest_len_[i] - p_.pulley_radius_m * (q.rad[i] - p_.rest_angles_rad[i]);
    }
    return len;
  }

 private:
  const PlatformParams& p_;
  std::array<Vec3, 3> c_;
  std::array<double, 3> rest_len_{};
  Eigen::Matrix2d a_inv_ = Eigen::Matrix2d::Zero();
  double det_ = 0.0;
};

class PlatformDevice final : public FingertipDeviceModel {
 public:
  PlatformDevice(PlatformParams p, DeviceLimits limits) : p_(std::move(p)), limits_(limits), k_(p_) {}
  PlatformDevice(const PlatformDevice&) = delete;  // k_ refers to p_
  PlatformDevice& operator=(const PlatformDevice&) = delete;

  std::string_view kind() const noexcept override { return "platform_3dof"; }
  std::size_t motor_count() const noexcept override { return 3; }
  const DeviceLimits& limits() const noexcept override { return limits_; }
  ForceAxes axes() const noexcept override { return ForceAxes{true, true}; }
  MotorSpec motor_spec() const noexcept override { return p_.motor; }

  FingertipForce renderable(const FingertipForce& desired) const noexcept override {
    return clamp_to_limits(desired, limits_, axes());
  }

  MotorAngles inverse(const FingertipForce& force) const noexcept override {
    const Vec3 d = k_.displacement(renderable(force));
    MotorAngles q;
    for (std::size_t i = 0; i < 3; ++i) {
      // Winding in (positive angle) shortens the wire.
      q.rad[i] = p_.rest_angles_rad[i] + (k_.rest_length(i) - k_.length(i, d)) / p_.pulley_radius_m;
    }
    return q;
  }

  FingertipForce forward(const MotorAngles& q) const noexcept override { return k_.force(k_.plate(k_.lengths(q))); }

  std::array<double, kMaxDeviceMotors> load_torques(const MotorAngles& q) const noexcept override {
    return plant(q).load_torques_nm;
  }

  // A taut wire pulls its pulley toward unwinding; a wire that would have to
  // push is slack and loads nothing.
  Plant plant(const MotorAngles& q) const noexcept override {
    Plant out;
    const Vec3 p = k_.plate(k_.lengths(q));
    out.force = k_.force(p);
    Vec3 t;
    if (!out.force.is_finite() || !k_.tensions(p, out.force.in_tip_frame(), t)) return out;
    for (std::size_t i = 0; i < 3; ++i) {
      out.load_torques_nm[i] = -p_.pulley_radius_m * std::max(0.0, t[static_cast<Eigen::Index>(i)]);
    }
    return out;
  }

  MotorAngles rest() const noexcept override {
    MotorAngles q;
    for (std::size_t i = 0; i < 3; ++i) q.rad[i] = p_.rest_angles_rad[i];
    return q;
  }

  std::string describe() const override {
    return "platform_3dof" + (p_.name.empty() ? std::string() : " '" + p_.name + "'") + ": " + p_.describe() +
           "; limits " + limits_.describe();
  }

 private:
  PlatformParams p_;
  DeviceLimits limits_;
  Platform k_;  // refers to p_, so declared after it
};

}  // namespace

Status PlatformParams::validate(const DeviceLimits& limits) const {
  auto bad = [](const std::string& what) { return make_error(Errc::invalid_argument, what); };
  auto positive = [](double v) { return v > 0.0 && std::isfinite(v); };
  if (!positive(pulley_radius_m)) return bad("'motors.pulley_radius_m' must be a positive number of metres");
  if (!positive(plate_radius_m) || !positive(anchor_radius_m) || !positive(anchor_height_m)) {
    return bad("'platform.plate_radius_m', 'platform.anchor_radius_m' and 'platform.anchor_height_m' must be "
               "positive numbers of metres");
  }
  if (!(motor.gear_ratio > 0.0) || motor.encoder_counts_per_motor_rev < 0) {
    return bad("'motors.gear_ratio' must be > 0 and 'motors.encoder_counts_per_motor_rev' >= 0");
  }
  for (std::size_t i = 0; i < 3; ++i) {
    if (!std::isfinite(rest_angles_rad[i]) || !std::isfinite(leg_angles_rad[i])) {
      return bad("'motors.rest_angles_rad' and 'platform.leg_angles_deg' must be finite");
    }
  }
  const bool linear = normal_model == NormalModel::linear;
  if (linear ? !positive(normal_stiffness_n_per_m)
             : !(positive(exp_initial_stiffness_n_per_m) && positive(exp_rate_per_m))) {
    return bad(linear ? "'fingertip.normal_stiffness_n_per_m' must be positive"
                      : "'fingertip.exp_initial_stiffness_n_per_m' and 'fingertip.exp_rate_per_m' must be positive");
  }
  if (!positive(shear_stiffness_x_n_per_m) || !positive(shear_stiffness_z_n_per_m)) {
    return bad("'fingertip.shear_stiffness_x_n_per_m' and 'fingertip.shear_stiffness_z_n_per_m' must be positive");
  }
  const Platform k(*this);
  if (!k.well_posed()) {
    return bad("'platform.anchor_radius_m' must differ from 'platform.plate_radius_m' and 'platform.leg_angles_deg' "
               "must spread the wires around the plate: wires that hang straight down, or all in one plane, "
               "cannot hold the plate sideways");
  }
  // Every force the limits allow must be reachable with the plate below the
  // wire exits and all three wires pulling. The extremes of the allowed set
  // are where this fails first: sample its rim at 16 normal levels in 72
  // directions (a sample, so keep some margin in the geometry).
  const double mu = limits.friction_coefficient;
  for (int level = 1; level <= 16; ++level) {
    const double fn = limits.max_normal_n * level / 16.0;
    const double shear = std::min(limits.max_shear_n, mu * fn);
    const int directions = shear > 0.0 ? 72 : 1;
    for (int j = 0; j < directions; ++j) {
      const double az = 2.0 * M_PI * j / directions;
      const FingertipForce f{fn, shear * std::cos(az), shear * std::sin(az)};
      const Vec3 d = k.displacement(f);
      const std::string where = "normal " + num4(fn) + " N with shear " + num4(shear) + " N toward " +
                                num4(az * 180.0 / M_PI) + " deg (from +X toward +Z)";
      if (!(d.y() < anchor_height_m)) {
        return bad("the plate would have to rise " + num4(d.y() * 1e3) + " mm, past the wire exits at 'platform."
                   "anchor_height_m' = " + num4(anchor_height_m * 1e3) + " mm, to press " + where +
                   "; raise the exits, stiffen the fingertip model or lower 'limits.max_normal_n'");
      }
      Vec3 t;
      if (!k.tensions(d, f.in_tip_frame(), t)) {
        return bad("the wires are degenerate (parallel) at " + where + "; change the 'platform' geometry");
      }
      for (Eigen::Index i = 0; i < 3; ++i) {
        if (t[i] < -1e-9) {
          return bad("wire " + std::to_string(i) + " would have to push (tension " + num4(t[i]) + " N) to render " +
                     where + "; widen 'platform.anchor_radius_m', lower 'platform.anchor_height_m', or reduce "
                     "'limits.friction_coefficient' / 'limits.max_shear_n'");
        }
      }
    }
  }
  return {};
}

std::string PlatformParams::describe() const {
  char buf[640];
  const double res = motor.output_resolution_rad();
  const bool linear = normal_model == NormalModel::linear;
  char normal[128];
  if (linear) {
    std::snprintf(normal, sizeof normal, "linear normal stiffness %.4g N/m", normal_stiffness_n_per_m);
  } else {
    std::snprintf(normal, sizeof normal, "exponential normal f = (b/m)(exp(m d)-1), b %.4g N/m, m %.4g 1/m",
                  exp_initial_stiffness_n_per_m, exp_rate_per_m);
  }
  std::snprintf(buf, sizeof buf,
                "3 wires at [%.4g, %.4g, %.4g] deg, plate radius %.4g mm, exits at radius %.4g mm and %.4g mm above "
                "the plate; pulley r %.4g mm, rest [%.4g, %.4g, %.4g] rad, gear %.4g:1, %lld counts/motor rev "
                "(%.3g mrad/count); fingertip: %s, shear stiffness x %.4g N/m, z %.4g N/m",
                leg_angles_rad[0] * 180.0 / M_PI, leg_angles_rad[1] * 180.0 / M_PI, leg_angles_rad[2] * 180.0 / M_PI,
                plate_radius_m * 1e3, anchor_radius_m * 1e3, anchor_height_m * 1e3, pulley_radius_m * 1e3,
                rest_angles_rad[0], rest_angles_rad[1], rest_angles_rad[2], motor.gear_ratio,
                static_cast<long long>(motor.encoder_counts_per_motor_rev), res * 1e3, normal,
                shear_stiffness_x_n_per_m, shear_stiffness_z_n_per_m);
  return buf;
}

Result<std::unique_ptr<FingertipDeviceModel>> make_platform_device(PlatformParams params, DeviceLimits limits) {
  if (auto st = limits.validate(); !st) return st.error();
  if (auto st = params.validate(limits); !st) return st.error().with_context("platform_3dof");
  return std::unique_ptr<FingertipDeviceModel>(std::make_unique<PlatformDevice>(std::move(params), limits));
}

}  // namespace proprio::haptics
