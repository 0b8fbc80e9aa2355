#include "proprio/rig_device/joint_accuracy.hpp"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

namespace proprio::rig_device {
namespace {

constexpr double kAccuracyDegPerRad = 180.0 / M_PI;
// The residual field in the jig's shield, dipping 60 deg (mid-latitude
// inclination) in the jig's frame.
const Vec3 kLabFieldDirection = Vec3(0.5, 0.0, -0.8660254037844386);

Quat random_rotation(Rng& rng) {
  // Uniform on SO(3): a normalised 4-D Gaussian (Shoemake's method's equivalent).
  Quat q(rng.normal(), rng.normal(), rng.normal(), rng.normal());
  if (q.norm() < 1e-12) return Quat::Identity();
  return q.normalized();
}

JointAngles random_angles(double bend_limit_rad, Rng& rng) {
  JointAngles a;
  a.twist_in_rad = rng.uniform(-M_PI, M_PI);
  // Uniform over the square of hinge angles, kept only inside the shaft-angle
  // stop (rejection: the stop cuts off the square's corners).
  do {
    a.bend_x_rad = rng.uniform(-bend_limit_rad, bend_limit_rad);
    a.bend_y_rad = rng.uniform(-bend_limit_rad, bend_limit_rad);
  } while (shaft_angle_rad(a.bend_x_rad, a.bend_y_rad) > bend_limit_rad);
  a.twist_out_rad = rng.uniform(-M_PI, M_PI);
  return a;
}

// The hand turns each ring the short way from where it is.
JointAngles short_way(const JointAngles& target, const JointAngles& from) {
  JointAngles cmd = target;
  cmd.twist_in_rad = from.twist_in_rad + wrap_angle_rad(target.twist_in_rad - from.twist_in_rad);
  cmd.twist_out_rad = from.twist_out_rad + wrap_angle_rad(target.twist_out_rad - from.twist_out_rad);
  return cmd;
}

}  // namespace

Result<EmulatedJoint> EmulatedJoint::create(const HallJointOptions& options, const JigOptions& jig,
                                            double jig_field_t) {
  auto joint = HallJoint::create(options);
  if (!joint) return joint.error();
  Rng rng(mix_seed(options.seed, 0x4a4947ull));  // "JIG"
  auto samples = run_calibration_jig(*joint, jig, jig_field_t * kLabFieldDirection, rng);
  if (!samples) return samples.error();
  auto cal = JointCalibration::fit(*samples, options.kind.bend_limit_rad, "joint-" + std::to_string(options.seed));
  if (!cal) return cal.error();
  return EmulatedJoint(std::move(*joint), std::move(*cal));
}

JointAngles EmulatedJoint::step(const JointAngles& commanded, const JointEnvironment& environment, Rng& rng) {
  joint_.move_to(commanded);
  const HallReadings readings = joint_.read(environment, rng);
  last_ = last_ ? calibration_.angles(readings, *last_) : calibration_.angles(readings);
  return *last_;
}

Status JointAccuracyOptions::validate() const {
  if (joints < 1 || joints > 1000) {
    return make_error(Errc::invalid_argument, "joints must be 1..1000; it is " + std::to_string(joints));
  }
  if (samples_per_joint < 1 || samples_per_joint > 100000) {
    return make_error(Errc::invalid_argument,
                      "samples_per_joint must be 1..100000; it is " + std::to_string(samples_per_joint));
  }
  if (auto st = jig.validate(); !st) return st;
  HallJointOptions h;
  h.kind = kind;
  return h.validate();
}

std::string JointAccuracyOptions::describe() const {
  std::ostringstream s;
  s << joints << " simulated joints x " << samples_per_joint << " held-out reports, seed " << seed
    << ", bends uniform within the stops (+-" << std::fixed << std::setprecision(1) << kind.bend_limit_rad * kAccuracyDegPerRad
    << " deg per hinge and between the shafts), twists over a full turn; " << jig.describe() << "; disturbances:"
    << (manufacturing_errors ? " manufacturing" : "") << (noise ? " noise" : "") << (backlash ? " play" : "")
    << (neighbours ? " neighbours" : "") << (ambient ? " ambient" : "") << (shielded_jig ? "" : " unshielded-jig")
    << (!manufacturing_errors && !noise && !backlash && !neighbours && !ambient ? " none" : "");
  return s.str();
}

AngleErrorStats summarise_errors_deg(std::vector<double> e) {
  AngleErrorStats s;
  s.count = e.size();
  if (e.empty()) return s;
  std::sort(e.begin(), e.end());
  double sum = 0.0;
  for (double v : e) sum += v;
  s.mean_deg = sum / static_cast<double>(e.size());
  const auto rank = [&](double p) {
    const auto k = static_cast<std::size_t>(std::ceil(p * static_cast<double>(e.size())));
    return e[std::min(e.size() - 1, k == 0 ? 0 : k - 1)];
  };
  s.p95_deg = rank(0.95);
  s.p99_deg = rank(0.99);
  s.max_deg = e.back();
  return s;
}

std::string JointAccuracyReport::describe() const {
  std::ostringstream s;
  s << std::fixed << std::setprecision(3);
  s << "joint angle error over " << joints << " joints, " << samples << " reports (deg: mean / p95 / p99 / max)\n";
  const auto line = [&](const char* name, const AngleErrorStats& a) {
    s << "  " << std::left << std::setw(8) << name << a.mean_deg << " / " << a.p95_deg << " / " << a.p99_deg << " / "
      << a.max_deg << "  (" << a.count << " angles)\n";
  };
  line("bend", bend);
  line("twist", twist);
  line("overall", overall);
  s << "  worst jig fit residual " << std::setprecision(2) << worst_fit_rms_counts << " counts rms\n";
  return s.str();
}

Result<JointAccuracyReport> evaluate_joint_accuracy(const JointAccuracyOptions& o) {
  if (auto st = o.validate(); !st) return st.error();
  std::vector<double> bend_err, twist_err;
  const auto total = static_cast<std::size_t>(o.joints) * static_cast<std::size_t>(o.samples_per_joint);
  bend_err.reserve(2 * total);
  twist_err.reserve(2 * total);
  JointAccuracyReport report;
  report.joints = o.joints;
  for (int j = 0; j < o.joints; ++j) {
    const std::uint64_t joint_seed = mix_seed(o.seed, static_cast<std::uint64_t>(j));
    HallJointOptions h;
    h.kind = o.kind;
    h.manufacturing_errors = o.manufacturing_errors;
    h.noise = o.noise;
    h.backlash = o.backlash;
    h.seed = joint_seed;
    auto joint = EmulatedJoint::create(h, o.jig, o.shielded_jig ? kShieldedJigFieldT : kEarthFieldT);
    if (!joint) return joint.error().with_context("joint " + std::to_string(j));
    for (double r : joint->calibration().fit_rms_counts()) {
      report.worst_fit_rms_counts = std::max(report.worst_fit_rms_counts, r);
    }
    // Neighbours: a parent joint whose outlet is this joint's inlet, a child
    // on this joint's outlet; their own seeds, their own random angles.
    HallJointOptions hp = h, hc = h;
    hp.seed = mix_seed(joint_seed, 2);
    hc.seed = mix_seed(joint_seed, 3);
    auto parent = HallJoint::create(hp);
    auto child = HallJoint::create(hc);
    if (!parent || !child) return (!parent ? parent.error() : child.error());
    Rng rng(mix_seed(joint_seed, 4));
    const Vec3 ambient_world = o.ambient ? Vec3(kEarthFieldT * random_rotation(rng).toRotationMatrix().col(2))
                                         : Vec3::Zero();
    for (int s = 0; s < o.samples_per_joint; ++s) {
      const JointAngles target = random_angles(o.kind.bend_limit_rad, rng);
      joint->joint().move_to(short_way(target, joint->joint().actual_angles()));
      JointEnvironment env;
      env.ambient_field_world_t = ambient_world;
      env.q_world_inlet = o.ambient ? random_rotation(rng) : Quat::Identity();
      if (o.neighbours) {
        parent->move_to(random_angles(o.kind.bend_limit_rad, rng));
        child->move_to(random_angles(o.kind.bend_limit_rad, rng));
        const Pose T_inlet_parent_inlet = parent->T_inlet_outlet().inverse();
        env.neighbour_magnets_inlet = transform_magnets(T_inlet_parent_inlet, parent->magnets_in_inlet());
        const auto c = transform_magnets(joint->joint().T_inlet_outlet(), child->magnets_in_inlet());
        env.neighbour_magnets_inlet.insert(env.neighbour_magnets_inlet.end(), c.begin(), c.end());
      }
      const JointAngles est = joint->calibration().angles(joint->joint().read(env, rng));
      const JointAngles& truth = joint->joint().actual_angles();
      bend_err.push_back(std::abs(est.bend_x_rad - truth.bend_x_rad) * kAccuracyDegPerRad);
      bend_err.push_back(std::abs(est.bend_y_rad - truth.bend_y_rad) * kAccuracyDegPerRad);
      twist_err.push_back(std::abs(wrap_angle_rad(est.twist_in_rad - truth.twist_in_rad)) * kAccuracyDegPerRad);
      twist_err.push_back(std::abs(wrap_angle_rad(est.twist_out_rad - truth.twist_out_rad)) * kAccuracyDegPerRad);
    }
  }
  report.samples = total;
  std::vector<double> all = bend_err;
  all.insert(all.end(), twist_err.begin(), twist_err.end());
  report.bend = summarise_errors_deg(std::move(bend_err));
  report.twist = summarise_errors_deg(std::move(twist_err));
  report.overall = summarise_errors_deg(std::move(all));
  return report;
}

}  // namespace proprio::rig_device
