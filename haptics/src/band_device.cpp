// band_2dof: a belt over the fingertip pad wound by two pulleys (Minamizawa et
// al. 2007, "gravity grabber"; the device of Lee 2021 ch. 2.2). Equations in
// device_model.hpp and docs/haptic-devices.md.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "proprio/haptics/device_model.hpp"

namespace proprio::haptics {

namespace {

std::string g(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

std::string row_text(std::size_t i, const BandParams::Row& r) {
  char buf[160];
  std::snprintf(buf, sizeof buf, "band.force_table[%zu] (takeup_mm = %g, normal_n = %g)", i, r.takeup_m * 1e3,
                r.normal_n);
  return buf;
}

class BandDevice final : public FingertipDeviceModel {
 public:
  BandDevice(BandParams p, DeviceLimits limits) : p_(std::move(p)), limits_(limits) {
    pretension_n_ = p_.force_table.front().normal_n;
  }

  std::string_view kind() const noexcept override { return "band_2dof"; }
  std::size_t motor_count() const noexcept override { return 2; }
  const DeviceLimits& limits() const noexcept override { return limits_; }
  // The belt runs along the finger: it cannot push the skin sideways.
  ForceAxes axes() const noexcept override { return ForceAxes{false, true}; }
  MotorSpec motor_spec() const noexcept override { return p_.motor; }

  FingertipForce renderable(const FingertipForce& desired) const noexcept override {
    return clamp_to_limits(desired, limits_, axes());
  }

  MotorAngles inverse(const FingertipForce& force) const noexcept override {
    const FingertipForce f = renderable(force);
    const double total = takeup_for(pretension_n_ + f.normal_n);
    const double slip = f.shear_z_n / p_.shear_stiffness_n_per_m;  // (s0 - s1) / 2
    const double s[2] = {0.5 * total + slip, 0.5 * total - slip};
    MotorAngles q;
    for (std::size_t i = 0; i < 2; ++i) {
      q.rad[i] = p_.rest_angles_rad[i] + p_.winding_direction[i] * s[i] / p_.pulley_radius_m;
    }
    return q;
  }

  FingertipForce forward(const MotorAngles& q) const noexcept override {
    double s[2];
    takeups(q, s);
    FingertipForce f;
    f.normal_n = belt_force(s[0] + s[1]) - pretension_n_;
    f.shear_z_n = p_.shear_stiffness_n_per_m * 0.5 * (s[0] - s[1]);
    return f;
  }

  // Under the pad the belt runs along Z and turns up toward each pulley, so
  // the pad carries the sum of the two belt tensions as normal force and their
  // difference as shear: N = T0 + T1, shear_z = T0 - T1 (pulley 0 proximal).
  // Tension unwinds its pulley.
  std::array<double, kMaxDeviceMotors> load_torques(const MotorAngles& q) const noexcept override {
    double s[2];
    takeups(q, s);
    const double n = belt_force(s[0] + s[1]);
    const double shear = p_.shear_stiffness_n_per_m * 0.5 * (s[0] - s[1]);
    const double tension[2] = {std::max(0.0, 0.5 * (n + shear)), std::max(0.0, 0.5 * (n - shear))};
    std::array<double, kMaxDeviceMotors> tau{};
    for (std::size_t i = 0; i < 2; ++i) tau[i] = -p_.winding_direction[i] * p_.pulley_radius_m * tension[i];
    return tau;
  }

  MotorAngles rest() const noexcept override {
    MotorAngles q;
    q.rad[0] = p_.rest_angles_rad[0];
    q.rad[1] = p_.rest_angles_rad[1];
    return q;
  }

  std::string describe() const override {
    return "band_2dof" + (p_.name.empty() ? std::string() : " '" + p_.name + "'") + ": " + p_.describe() +
           "; limits " + limits_.describe();
  }

 private:
  void takeups(const MotorAngles& q, double (&s)[2]) const noexcept {
    for (std::size_t i = 0; i < 2; ++i) {
      s[i] = p_.pulley_radius_m * p_.winding_direction[i] * (q.rad[i] - p_.rest_angles_rad[i]);
    }
  }

  // The calibrated N(total take-up), piecewise linear, extended linearly past
  // both ends (forward() must answer for any angle), and never below zero: a
  // slack belt does not pull the pad away.
  double belt_force(double total) const noexcept {
    const auto& t = p_.force_table;
    std::size_t k = 0;  // segment [k, k+1]
    if (total >= t.back().takeup_m) {
      k = t.size() - 2;
    } else if (total > t.front().takeup_m) {
      const auto it = std::upper_bound(t.begin(), t.end(), total,
                                       [](double v, const BandParams::Row& r) { return v < r.takeup_m; });
      k = static_cast<std::size_t>(it - t.begin()) - 1;
    }
    const double u = (total - t[k].takeup_m) / (t[k + 1].takeup_m - t[k].takeup_m);
    return std::max(0.0, t[k].normal_n + u * (t[k + 1].normal_n - t[k].normal_n));
  }

  // Inverse of belt_force on the table's range; validation guarantees that
  // every renderable normal lies inside it.
  double takeup_for(double force) const noexcept {
    const auto& t = p_.force_table;
    if (!(force > t.front().normal_n)) return t.front().takeup_m;
    if (force >= t.back().normal_n) return t.back().takeup_m;
    const auto it = std::upper_bound(t.begin(), t.end(), force,
                                     [](double v, const BandParams::Row& r) { return v < r.normal_n; });
    const std::size_t k = static_cast<std::size_t>(it - t.begin()) - 1;
    const double u = (force - t[k].normal_n) / (t[k + 1].normal_n - t[k].normal_n);
    return t[k].takeup_m + u * (t[k + 1].takeup_m - t[k].takeup_m);
  }

  BandParams p_;
  DeviceLimits limits_;
  double pretension_n_ = 0.0;
};

}  // namespace

Status BandParams::validate(const DeviceLimits& limits) const {
  auto bad = [](const std::string& what) { return make_error(Errc::invalid_argument, what); };
  if (!(pulley_radius_m > 0.0) || !std::isfinite(pulley_radius_m)) {
    return bad("'motors.pulley_radius_m' must be a positive number of metres");
  }
  if (!(shear_stiffness_n_per_m > 0.0) || !std::isfinite(shear_stiffness_n_per_m)) {
    return bad("'band.shear_stiffness_n_per_m' must be a positive number of N/m");
  }
  for (std::size_t i = 0; i < 2; ++i) {
    if (winding_direction[i] != 1 && winding_direction[i] != -1) {
      return bad("'motors.winding_direction' element " + std::to_string(i) + " must be +1 or -1");
    }
    if (!std::isfinite(rest_angles_rad[i])) return bad("'motors.rest_angles_rad' must be finite");
  }
  if (!(motor.gear_ratio > 0.0) || motor.encoder_counts_per_motor_rev < 0) {
    return bad("'motors.gear_ratio' must be > 0 and 'motors.encoder_counts_per_motor_rev' >= 0");
  }

  const auto& t = force_table;
  if (t.size() < 2) {
    return bad("'band.force_table' has " + std::to_string(t.size()) +
               " rows; the calibration needs at least 2 ({ takeup_mm = 0, normal_n = <pretension> } and one more)");
  }
  for (std::size_t i = 0; i < t.size(); ++i) {
    if (!std::isfinite(t[i].takeup_m) || !std::isfinite(t[i].normal_n) || t[i].normal_n < 0.0) {
      return bad(row_text(i, t[i]) + ": take-up and force must be finite and the force >= 0");
    }
  }
  if (t[0].takeup_m != 0.0) {
    return bad(row_text(0, t[0]) + ": the first row must be the rest position, takeup_mm = 0, with the "
                                   "belt's pretension as normal_n");
  }
  // Strictly monotonic in both columns, or the inverse is not a function.
  for (std::size_t i = 1; i < t.size(); ++i) {
    if (!(t[i].takeup_m > t[i - 1].takeup_m)) {
      return bad(row_text(i, t[i]) + ": takeup_mm must increase from row to row (the row before has " +
                 g(t[i - 1].takeup_m * 1e3) + " mm); sort the table or remove the duplicate");
    }
    if (!(t[i].normal_n > t[i - 1].normal_n)) {
      return bad(row_text(i, t[i]) + ": normal_n must increase with take-up (the row before has " +
                 g(t[i - 1].normal_n) +
                 " N); a calibration that is not monotonic cannot be inverted, re-measure it or drop the row");
    }
  }
  const double reach = t.back().normal_n - t.front().normal_n;
  if (limits.max_normal_n > reach) {
    return bad("'limits.max_normal_n' = " + g(limits.max_normal_n) +
               " N is more than the force table reaches above the pretension (" + g(reach) +
               " N); lower the limit or extend 'band.force_table'");
  }
  // Both belt ends must stay taut: |shear| <= T0 + T1 = pretension + normal
  // wherever the limits allow shear. That bound minus the allowed shear is
  // piecewise linear in the normal force, so checking its corners suffices.
  const double mu = limits.friction_coefficient;
  const double kink = mu > 0.0 ? limits.max_shear_n / mu : 0.0;
  for (const double fn : {0.0, std::min(kink, limits.max_normal_n), limits.max_normal_n}) {
    const double shear = std::min(limits.max_shear_n, mu * fn);
    if (shear > t.front().normal_n + fn + 1e-12) {
      return bad("'limits.friction_coefficient' = " + g(mu) + " allows " + g(shear) +
                 " N of shear at " + g(fn) + " N normal, more than the belt can carry with both ends "
                 "taut (pretension + normal); lower the friction coefficient or 'limits.max_shear_n'");
    }
  }
  return {};
}

std::string BandParams::describe() const {
  char buf[512];
  const double res = motor.output_resolution_rad();
  std::snprintf(buf, sizeof buf,
                "2 motors, pulley r %.4g mm, winding [%+d, %+d], rest [%.4g, %.4g] rad, gear %.4g:1, %lld "
                "counts/motor rev (%.3g mrad/count); force table %zu rows, take-up 0..%.4g mm -> %.4g..%.4g N "
                "(pretension %.4g N); shear stiffness %.4g N/m; renders normal and shear_z only (no shear_x: the "
                "belt moves along the finger)",
                pulley_radius_m * 1e3, winding_direction[0], winding_direction[1], rest_angles_rad[0],
                rest_angles_rad[1], motor.gear_ratio, static_cast<long long>(motor.encoder_counts_per_motor_rev),
                res * 1e3, force_table.size(), force_table.empty() ? 0.0 : force_table.back().takeup_m * 1e3,
                force_table.empty() ? 0.0 : force_table.front().normal_n,
                force_table.empty() ? 0.0 : force_table.back().normal_n,
                force_table.empty() ? 0.0 : force_table.front().normal_n, shear_stiffness_n_per_m);
  return buf;
}

Result<std::unique_ptr<FingertipDeviceModel>> make_band_device(BandParams params, DeviceLimits limits) {
  if (auto st = limits.validate(); !st) return st.error();
  if (auto st = params.validate(limits); !st) return st.error().with_context("band_2dof");
  return std::unique_ptr<FingertipDeviceModel>(std::make_unique<BandDevice>(std::move(params), limits));
}

}  // namespace proprio::haptics
