#include "proprio/rig_device/hall_joint.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace proprio::rig_device {
namespace {

Quat hall_about(const Vec3& axis, double angle_rad) { return Quat(Eigen::AngleAxisd(angle_rad, axis)); }

// Smallest shaft lengths that leave room for the rings and sensors placed by
// the constants in the header (a ring 2 mm short of the next face at least).
constexpr double kMinLengthInM = kTwistInRingFromInletM + 2e-3;
constexpr double kMinLengthOutM = kTwistOutRingFromCardanM + 2e-3;

Vec3 tilted(const Vec3& v, double sigma_rad, Rng& rng) {
  const Vec3 w(rng.normal(0.0, sigma_rad), rng.normal(0.0, sigma_rad), rng.normal(0.0, sigma_rad));
  return (so3_exp(w) * v).normalized();
}

Vec3 jitter(const Vec3& p, double sigma_m, Rng& rng) {
  return p + Vec3(rng.normal(0.0, sigma_m), rng.normal(0.0, sigma_m), rng.normal(0.0, sigma_m));
}

double play(double actual, double commanded, double width) {
  return std::clamp(actual, commanded - 0.5 * width, commanded + 0.5 * width);
}

}  // namespace

double shaft_angle_rad(double bx, double by) {
  return std::acos(std::clamp(std::cos(bx) * std::cos(by), -1.0, 1.0));
}

void clamp_bends_to_stops(double& bx, double& by, double limit) {
  bx = std::clamp(bx, -limit, limit);
  by = std::clamp(by, -limit, limit);
  if (shaft_angle_rad(bx, by) <= limit) return;
  // The shaft angle grows monotonically with a common scale of both bends.
  double lo = 0.0, hi = 1.0;
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (shaft_angle_rad(mid * bx, mid * by) <= limit ? lo : hi) = mid;
  }
  bx *= lo;
  by *= lo;
}

Vec3 dipole_field_t(const Vec3& m, const Vec3& r) {
  const double r2 = r.squaredNorm();
  if (r2 <= 0.0) return Vec3::Zero();
  const double r1 = std::sqrt(r2);
  const double r3 = r2 * r1;
  const double r5 = r3 * r2;
  return kMu0Over4Pi * (3.0 * r * m.dot(r) / r5 - m / r3);
}

double magnet_moment_am2(double remanence_t, double volume_m3) {
  return remanence_t * volume_m3 / (4.0 * M_PI * kMu0Over4Pi);
}

int adc_counts(double field_t, double sensitivity_v_per_t, double offset_v, double noise_t, Rng& rng) {
  const double noisy_t = noise_t > 0.0 ? field_t + rng.normal(0.0, noise_t) : field_t;
  const double volts = 0.5 * kSupplyV + offset_v + sensitivity_v_per_t * noisy_t;
  const double code = std::round(volts / kSupplyV * static_cast<double>(kAdcMaxCount + 1));
  return static_cast<int>(std::clamp(code, 0.0, static_cast<double>(kAdcMaxCount)));
}

std::vector<Magnet> transform_magnets(const Pose& T_a_b, const std::vector<Magnet>& in_b) {
  std::vector<Magnet> out;
  out.reserve(in_b.size());
  for (const Magnet& m : in_b) out.push_back({T_a_b * m.p_m, T_a_b.q * m.moment_am2});
  return out;
}

std::vector<Magnet> neighbour_magnets_in_inlet(const Pose& T_device_inlet, const std::vector<Magnet>& magnets_device,
                                               double radius_m) {
  const Pose T_inlet_device = T_device_inlet.inverse();
  std::vector<Magnet> out;
  for (const Magnet& m : magnets_device) {
    const Vec3 p = T_inlet_device * m.p_m;
    if (p.norm() <= radius_m) out.push_back({p, T_inlet_device.q * m.moment_am2});
  }
  return out;
}

Status HallJointOptions::validate() const {
  if (!std::isfinite(kind.length_in_m) || kind.length_in_m < kMinLengthInM || kind.length_in_m > 1.0) {
    return make_error(Errc::invalid_argument, "the Hall joint needs length_in_m in [" + std::to_string(kMinLengthInM) +
                                                  ", 1] m for its inlet ring; it is " + std::to_string(kind.length_in_m));
  }
  if (!std::isfinite(kind.length_out_m) || kind.length_out_m < kMinLengthOutM || kind.length_out_m > 1.0) {
    return make_error(Errc::invalid_argument, "the Hall joint needs length_out_m in [" +
                                                  std::to_string(kMinLengthOutM) + ", 1] m for its outlet ring; it is " +
                                                  std::to_string(kind.length_out_m));
  }
  if (!std::isfinite(kind.bend_limit_rad) || kind.bend_limit_rad <= 0.0 || kind.bend_limit_rad > 1.5) {
    return make_error(Errc::invalid_argument,
                      "the Hall joint's bend limit must be in (0, 1.5] rad (the 2-D sensor reads sin(bend), "
                      "which flattens at 90 deg); it is " +
                          std::to_string(kind.bend_limit_rad));
  }
  return Status::success();
}

std::string HallJointOptions::describe() const {
  std::ostringstream s;
  s << "Hall joint '" << kind.name << "' seed " << seed << ": shafts " << kind.length_in_m * 1e3 << " + "
    << kind.length_out_m * 1e3 << " mm, bend limit " << kind.bend_limit_rad * 180.0 / M_PI << " deg; "
    << (manufacturing_errors ? "manufacturing errors" : "as designed") << ", " << (noise ? "noise" : "no noise")
    << ", " << (backlash ? "play and friction" : "no play");
  return s.str();
}

Result<HallJoint> HallJoint::create(const HallJointOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  HallJoint j;
  j.options_ = options;
  Rng rng(mix_seed(options.seed, 0x4a4f494e54ull));  // "JOINT"
  const bool err = options.manufacturing_errors;
  const double tilt_sigma = err ? kMagnetTiltSigmaRad : 0.0;
  const double offset_sigma = err ? kMagnetOffsetSigmaM : 0.0;
  const double strength_sigma = err ? kMagnetStrengthSigma : 0.0;
  const double place_sigma = err ? kSensorPlacementSigmaM : 0.0;
  const double axis_sigma = err ? kSensorAxisTiltSigmaRad : 0.0;
  const double sens_sigma = err ? kSensitivitySigma : 0.0;
  const double voff_sigma = err ? kSensorOffsetSigmaV : 0.0;

  const double bend_m = magnet_moment_am2(
      kNdFeBRemanenceT, M_PI * 0.25 * kBendMagnetDiameterM * kBendMagnetDiameterM * kBendMagnetLengthM);
  const double twist_m = magnet_moment_am2(
      kNdFeBRemanenceT, M_PI * 0.25 * kTwistMagnetDiameterM * kTwistMagnetDiameterM * kTwistMagnetThicknessM);
  const auto magnet = [&](const Vec3& p, const Vec3& dir, double moment) {
    const double strength = moment * (1.0 + rng.normal(0.0, strength_sigma));
    return Magnet{jitter(p, offset_sigma, rng), strength * tilted(dir, tilt_sigma, rng)};
  };
  const double L_in = options.kind.length_in_m;
  const double L_out = options.kind.length_out_m;
  j.twist_in_magnet_ = magnet(Vec3(0, 0, kTwistInRingFromInletM), Vec3::UnitX(), twist_m);
  j.bend_magnet_ = magnet(Vec3(0, 0, L_in), Vec3::UnitZ(), bend_m);
  j.twist_out_magnet_ = magnet(Vec3(0, 0, kTwistOutRingFromCardanM - L_out), Vec3::UnitX(), twist_m);

  const auto element = [&](const Vec3& p, const Vec3& axis, double sensitivity) {
    return Element{p, tilted(axis, axis_sigma, rng), sensitivity * (1.0 + rng.normal(0.0, sens_sigma)),
                   rng.normal(0.0, voff_sigma)};
  };
  // The 2-D sensor is one package: one placement error for both axes.
  const Vec3 bend_p = jitter(Vec3(0, 0, kBendSensorDistanceM), place_sigma, rng);
  j.bend_elements_ = {element(bend_p, Vec3::UnitX(), kBendSensitivityVPerT),
                      element(bend_p, Vec3::UnitY(), kBendSensitivityVPerT)};
  const double rho = kTwistSensorRadiusM;
  j.twist_in_elements_ = {
      element(jitter(Vec3(rho, 0, kTwistInRingFromInletM), place_sigma, rng), Vec3::UnitX(), kTwistSensitivityVPerT),
      element(jitter(Vec3(0, rho, kTwistInRingFromInletM), place_sigma, rng), Vec3::UnitY(), kTwistSensitivityVPerT)};
  j.twist_out_elements_ = {
      element(jitter(Vec3(rho, 0, kTwistOutRingFromCardanM), place_sigma, rng), Vec3::UnitX(), kTwistSensitivityVPerT),
      element(jitter(Vec3(0, rho, kTwistOutRingFromCardanM), place_sigma, rng), Vec3::UnitY(), kTwistSensitivityVPerT)};
  for (double& w : j.play_width_rad_) {
    w = options.backlash ? rng.uniform(kBacklashMinRad, kBacklashMaxRad) + kFrictionBandRad : 0.0;
  }
  return j;
}

void HallJoint::move_to(const JointAngles& commanded) {
  const double limit = options_.kind.bend_limit_rad;
  double bx = commanded.bend_x_rad, by = commanded.bend_y_rad;
  clamp_bends_to_stops(bx, by, limit);
  actual_.twist_in_rad = play(actual_.twist_in_rad, commanded.twist_in_rad, play_width_rad_[0]);
  actual_.bend_x_rad = play(actual_.bend_x_rad, bx, play_width_rad_[1]);
  actual_.bend_y_rad = play(actual_.bend_y_rad, by, play_width_rad_[2]);
  clamp_bends_to_stops(actual_.bend_x_rad, actual_.bend_y_rad, limit);
  actual_.twist_out_rad = play(actual_.twist_out_rad, commanded.twist_out_rad, play_width_rad_[3]);
}

namespace {

struct Frames {
  Pose T_I_Y1, T_I_Y2, T_I_O;
};

Frames frames_for(const JointAngles& a, const JointKind& kind) {
  Frames f;
  f.T_I_Y1 = Pose{hall_about(Vec3::UnitZ(), a.twist_in_rad), Vec3::Zero()};
  f.T_I_Y2 = f.T_I_Y1 * Pose{(hall_about(Vec3::UnitX(), a.bend_x_rad) * hall_about(Vec3::UnitY(), a.bend_y_rad)).normalized(),
                             Vec3(0, 0, kind.length_in_m)};
  f.T_I_O = f.T_I_Y2 * Pose{hall_about(Vec3::UnitZ(), a.twist_out_rad), Vec3(0, 0, kind.length_out_m)};
  return f;
}

}  // namespace

std::vector<Magnet> HallJoint::magnets_in_inlet() const {
  const Frames f = frames_for(actual_, options_.kind);
  std::vector<Magnet> out = transform_magnets(f.T_I_Y1, {twist_in_magnet_, bend_magnet_});
  const auto o = transform_magnets(f.T_I_O, {twist_out_magnet_});
  out.insert(out.end(), o.begin(), o.end());
  return out;
}

Pose HallJoint::T_inlet_outlet() const { return frames_for(actual_, options_.kind).T_I_O; }

HallReadings HallJoint::read(const JointEnvironment& env, Rng& rng) const {
  const Frames f = frames_for(actual_, options_.kind);
  std::vector<Magnet> magnets = magnets_in_inlet();
  magnets.insert(magnets.end(), env.neighbour_magnets_inlet.begin(), env.neighbour_magnets_inlet.end());
  const Vec3 ambient_inlet_t = env.q_world_inlet.conjugate() * env.ambient_field_world_t;
  const double noise_t = options_.noise ? kHallNoiseT : 0.0;
  const auto channel = [&](const Element& e, const Pose& T_I_mount) {
    const Vec3 p = T_I_mount * e.p_m;
    const Vec3 axis = T_I_mount.q * e.axis;
    Vec3 field = ambient_inlet_t;
    for (const Magnet& m : magnets) field += dipole_field_t(m.moment_am2, p - m.p_m);
    const double along = field.dot(axis);
    int sum = 0;
    for (int k = 0; k < kOversampling; ++k) sum += adc_counts(along, e.sensitivity_v_per_t, e.offset_v, noise_t, rng);
    return static_cast<double>(sum) / kOversampling;
  };
  HallReadings r;
  for (int i = 0; i < 2; ++i) {
    r.bend[i] = channel(bend_elements_[i], f.T_I_Y2);
    r.twist_in[i] = channel(twist_in_elements_[i], Pose::identity());
    r.twist_out[i] = channel(twist_out_elements_[i], f.T_I_Y2);
  }
  return r;
}

Status JigOptions::validate() const {
  if (bend_grid < 3 || bend_grid > 41) {
    return make_error(Errc::invalid_argument, "jig bend_grid must be 3..41 points per hinge; it is " +
                                                  std::to_string(bend_grid));
  }
  if (reports_per_pose < 1 || reports_per_pose > 64) {
    return make_error(Errc::invalid_argument, "jig reports_per_pose must be 1..64; it is " +
                                                  std::to_string(reports_per_pose));
  }
  return Status::success();
}

std::string JigOptions::describe() const {
  std::ostringstream s;
  s << "calibration jig: " << bend_grid << " x " << bend_grid << " bend grid, visited both ways ("
    << 2 * bend_grid * bend_grid << " poses), " << reports_per_pose << " report(s) averaged per pose";
  return s.str();
}

Result<std::vector<JigSample>> run_calibration_jig(HallJoint& joint, const JigOptions& options,
                                                   const Vec3& ambient_field_world_t, Rng& rng) {
  if (auto st = options.validate(); !st) return st.error();
  if (!ambient_field_world_t.allFinite()) {
    return make_error(Errc::invalid_argument, "the jig's ambient field must be finite");
  }
  const int n = options.bend_grid;
  const double limit = joint.options().kind.bend_limit_rad;
  std::vector<std::pair<double, double>> path;
  for (int i = 0; i < n; ++i) {
    const double bx = -limit + 2.0 * limit * i / (n - 1);
    for (int k = 0; k < n; ++k) {
      const int jj = (i % 2 == 0) ? k : n - 1 - k;  // serpentine
      path.emplace_back(bx, -limit + 2.0 * limit * jj / (n - 1));
    }
  }
  const std::size_t half = path.size();
  for (std::size_t i = 0; i < half; ++i) path.push_back(path[half - 1 - i]);

  JointEnvironment env;
  env.ambient_field_world_t = ambient_field_world_t;
  std::vector<JigSample> out;
  out.reserve(path.size());
  // R2 low-discrepancy steps for the twist pair (Roberts 2018: 1/g, 1/g^2,
  // g the plastic number), so twist pairs cover the torus evenly.
  constexpr double kR2a = 0.7548776662466927, kR2b = 0.5698402909980532;
  JointAngles last_cmd = joint.actual_angles();
  for (std::size_t k = 0; k < path.size(); ++k) {
    JointAngles target;
    target.bend_x_rad = path[k].first;
    target.bend_y_rad = path[k].second;
    clamp_bends_to_stops(target.bend_x_rad, target.bend_y_rad, limit);
    target.twist_in_rad = wrap_angle_rad(2.0 * M_PI * std::fmod(0.5 + kR2a * static_cast<double>(k + 1), 1.0));
    target.twist_out_rad = wrap_angle_rad(2.0 * M_PI * std::fmod(0.5 + kR2b * static_cast<double>(k + 1), 1.0));
    // The jig turns each ring the short way round.
    JointAngles cmd = target;
    cmd.twist_in_rad = last_cmd.twist_in_rad + wrap_angle_rad(target.twist_in_rad - last_cmd.twist_in_rad);
    cmd.twist_out_rad = last_cmd.twist_out_rad + wrap_angle_rad(target.twist_out_rad - last_cmd.twist_out_rad);
    joint.move_to(cmd);
    last_cmd = cmd;
    HallReadings mean;
    for (int r = 0; r < options.reports_per_pose; ++r) {
      const HallReadings h = joint.read(env, rng);
      for (int c = 0; c < 2; ++c) {
        mean.bend[c] += h.bend[c] / options.reports_per_pose;
        mean.twist_in[c] += h.twist_in[c] / options.reports_per_pose;
        mean.twist_out[c] += h.twist_out[c] / options.reports_per_pose;
      }
    }
    out.push_back({target, mean});
  }
  return out;
}

}  // namespace proprio::rig_device
