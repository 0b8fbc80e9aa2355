#include "proprio/ftm/ftm_calibration.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "proprio/core/config.hpp"
#include "proprio/core/file_io.hpp"

namespace proprio::ftm {
namespace {

constexpr std::array<FtmImu, kFtmImuCount> kImus = {FtmImu::dorsum, FtmImu::thumb_metacarpal,
                                                    FtmImu::index_proximal, FtmImu::middle_proximal};
constexpr std::array<FtmBend, kFtmBendCount> kBends = {FtmBend::thumb_mcp, FtmBend::index_pip,
                                                       FtmBend::middle_pip};

// Nominal bend sensor: 90° over 30 pF of change, zero at 0 pF.
constexpr double kNominalBeta1 = (M_PI / 2.0) / 30.0;

std::string fmt(const char* f, double a, double b = 0.0, double c = 0.0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, f, a, b, c);
  return buf;
}

bool unit_quat_ok(const Quat& q) { return q.coeffs().allFinite() && std::abs(q.norm() - 1.0) < 1e-6; }

// Closest rotation (Frobenius) to a sum of rotation matrices: the chordal L2 mean.
Quat project_to_so3(const Mat3& M) {
  Eigen::JacobiSVD<Mat3> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 D = Mat3::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  return Quat(svd.matrixU() * D * svd.matrixV().transpose()).normalized();
}

std::string toml_string(std::string_view s) {
  std::string out = "\"";
  for (char ch : s) {
    if (ch == '"' || ch == '\\') {
      out += '\\';
      out += ch;
    } else if (static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f) {
      out += '?';
    } else {
      out += ch;
    }
  }
  return out + "\"";
}

// `table` prefixes the key in messages ("imu.dorsum").
Result<std::vector<double>> doubles_n(const Config& c, const std::string& table, const std::string& key,
                                      std::size_t n) {
  auto v = c.get_doubles(key);
  if (!v) return v.error();
  if (v->size() != n) {
    return make_error(Errc::invalid_argument, c.where(key) + ": '" + table + "." + key + "' must have " + std::to_string(n) +
                                                  " numbers, but it has " + std::to_string(v->size()));
  }
  return v;
}

}  // namespace

// ---------------------------------------------------------------- FtmCalibration

Status FtmCalibration::validate() const {
  for (std::size_t i = 0; i < kFtmImuCount; ++i) {
    if (!accel_bias_mps2[i].allFinite() || !gyro_bias_radps[i].allFinite()) {
      return make_error(Errc::invalid_argument, "FtmCalibration.accel_bias_mps2/gyro_bias_radps[" +
                                                    std::to_string(i) + "] must be finite");
    }
  }
  if (auto s = HandShape::from_measurements(hand_length_m, hand_width_m); !s) {
    return s.error().with_context("FtmCalibration.hand_length_m/hand_width_m");
  }
  for (auto i : kImus) {
    const std::string name(to_string(i));
    if (!unit_quat_ok(q_imu_segment[index_of(i)]))
      return make_error(Errc::invalid_argument, "FtmCalibration.q_imu_segment[" + name + "] must be a unit quaternion");
    const MagCalibration& m = mag[index_of(i)];
    if (!m.hard_iron_uT.allFinite() || !m.soft_iron_inv.allFinite() || !(std::abs(m.soft_iron_inv.determinant()) > 1e-6))
      return make_error(Errc::invalid_argument,
                        "FtmCalibration.mag[" + name + "] must be finite with an invertible soft_iron_inv");
  }
  for (auto b : kBends) {
    const std::string name(to_string(b));
    if (!std::isfinite(beta0_rad[index_of(b)]) || !std::isfinite(beta1_rad_per_pF[index_of(b)]) ||
        beta1_rad_per_pF[index_of(b)] == 0.0)
      return make_error(Errc::invalid_argument,
                        "FtmCalibration.beta0_rad/beta1_rad_per_pF[" + name + "] must be finite, beta1 non-zero");
  }
  const double f = earth_field_world_uT.norm();
  if (!earth_field_world_uT.allFinite() || !(f > 1.0 && f < 1000.0))
    return make_error(Errc::invalid_argument, "FtmCalibration.earth_field_world_uT must be finite, 1-1000 uT");
  return {};
}

std::string FtmCalibration::describe() const {
  std::string s = "FTM calibration: " + std::string(to_string(hand)) + " hand" +
                  (subject.empty() ? std::string() : " of '" + printable(subject, 60) + "'") +
                  fmt(", %.1f x %.1f mm; field %.1f uT", hand_length_m * 1e3, hand_width_m * 1e3,
                      earth_field_world_uT.norm());
  for (auto i : kImus) {
    s += "; " + std::string(to_string(i)) +
         fmt(" mount %.1f deg, hard iron %.1f uT", rad_to_deg(2.0 * std::acos(std::min(1.0, std::abs(q_imu_segment[index_of(i)].w())))),
             mag[index_of(i)].hard_iron_uT.norm());
  }
  for (auto b : kBends) {
    s += "; " + std::string(to_string(b)) +
         fmt(" %.1f deg + %.2f deg/pF", rad_to_deg(beta0_rad[index_of(b)]), rad_to_deg(beta1_rad_per_pF[index_of(b)]));
  }
  return s;
}

FtmCalibration nominal_ftm_calibration(Handedness hand, double hand_length_m, double hand_width_m) {
  FtmCalibration c;
  c.hand = hand;
  c.hand_length_m = hand_length_m;
  c.hand_width_m = hand_width_m;
  c.beta0_rad.fill(0.0);
  c.beta1_rad_per_pF.fill(kNominalBeta1);
  return c;
}

// ---------------------------------------------------------------- TOML

std::string format_ftm_calibration(const FtmCalibration& c) {
  std::string s =
      "# FTM glove calibration (proprio calibrate ftm; docs/ftm.md).\n"
      "# q_imu_segment_wxyz: the hand segment's frame in the IMU's frame (unit quaternion w, x, y, z).\n"
      "# Compass: m_cal = soft_iron_inv (row-major 3x3) * (m_raw - hard_iron_uT). Bend: angle = beta0 + beta1 * pF.\n"
      "[ftm]\n";
  s += "hand = " + toml_string(to_string(c.hand)) + "\n";
  s += fmt("hand_length_m = %.6f\nhand_width_m = %.6f\n", c.hand_length_m, c.hand_width_m);
  s += "subject = " + toml_string(c.subject) + "\n";
  s += fmt("earth_field_world_uT = [%.6f, %.6f, %.6f]\n", c.earth_field_world_uT.x(), c.earth_field_world_uT.y(),
           c.earth_field_world_uT.z());
  char buf[512];
  for (auto i : kImus) {
    const Quat& q = c.q_imu_segment[index_of(i)];
    const MagCalibration& m = c.mag[index_of(i)];
    const Mat3& W = m.soft_iron_inv;
    std::snprintf(buf, sizeof buf,
                  "\n[imu.%s]\nq_imu_segment_wxyz = [%.12f, %.12f, %.12f, %.12f]\nhard_iron_uT = [%.6f, %.6f, %.6f]\n"
                  "soft_iron_inv = [%.9f, %.9f, %.9f, %.9f, %.9f, %.9f, %.9f, %.9f, %.9f]\n",
                  std::string(to_string(i)).c_str(), q.w(), q.x(), q.y(), q.z(), m.hard_iron_uT.x(),
                  m.hard_iron_uT.y(), m.hard_iron_uT.z(), W(0, 0), W(0, 1), W(0, 2), W(1, 0), W(1, 1), W(1, 2),
                  W(2, 0), W(2, 1), W(2, 2));
    s += buf;
  }
  for (auto b : kBends) {
    std::snprintf(buf, sizeof buf, "\n[bend.%s]\nbeta0_rad = %.12g\nbeta1_rad_per_pF = %.12g\n",
                  std::string(to_string(b)).c_str(), c.beta0_rad[index_of(b)], c.beta1_rad_per_pF[index_of(b)]);
    s += buf;
  }
  return s;
}

Result<FtmCalibration> parse_ftm_calibration(std::string_view text, const std::string& source) {
  auto parsed = Config::parse(text, source);
  if (!parsed) return parsed.error();
  const Config& root = *parsed;
  if (auto k = root.check_keys("top level", {"ftm", "imu", "bend"}, "see docs/ftm.md"); !k) return k.error();
  FtmCalibration c;
  {
    auto t = root.table("ftm");
    if (!t) return t.error();
    if (auto k = t->check_keys("ftm", {"hand", "hand_length_m", "hand_width_m", "subject", "earth_field_world_uT"});
        !k)
      return k.error();
    auto hand = t->get_string("hand");
    if (!hand) return hand.error();
    const auto h = parse_handedness(*hand);
    if (!h) return make_error(Errc::invalid_argument, t->where("hand") + ": 'ftm.hand' must be \"left\" or \"right\"");
    c.hand = *h;
    auto L = t->get_double("hand_length_m");
    if (!L) return L.error();
    auto B = t->get_double("hand_width_m");
    if (!B) return B.error();
    c.hand_length_m = *L;
    c.hand_width_m = *B;
    if (auto s = HandShape::from_measurements(c.hand_length_m, c.hand_width_m); !s)
      return s.error().with_context(t->where("hand_length_m") + ": 'ftm.hand_length_m'/'ftm.hand_width_m'");
    auto subj = t->get_string_or("subject", "");
    if (!subj) return subj.error();
    c.subject = *subj;
    auto f = doubles_n(*t, "ftm", "earth_field_world_uT", 3);
    if (!f) return f.error();
    c.earth_field_world_uT = Vec3((*f)[0], (*f)[1], (*f)[2]);
    const double n = c.earth_field_world_uT.norm();
    if (!(n > 1.0 && n < 1000.0))
      return make_error(Errc::out_of_range, t->where("earth_field_world_uT") +
                                                ": 'ftm.earth_field_world_uT' must have a magnitude of 1-1000 uT");
  }
  auto imus = root.table("imu");
  if (!imus) return imus.error();
  {
    std::set<std::string> names;
    for (auto i : kImus) names.insert(std::string(to_string(i)));
    if (auto k = imus->check_keys("imu", names); !k) return k.error();
  }
  for (auto i : kImus) {
    const std::string name(to_string(i));
    auto t = imus->table(name);
    if (!t) return t.error();
    if (auto k = t->check_keys("imu." + name, {"q_imu_segment_wxyz", "hard_iron_uT", "soft_iron_inv"}); !k)
      return k.error();
    auto q = doubles_n(*t, "imu." + name, "q_imu_segment_wxyz", 4);
    if (!q) return q.error();
    Quat qq((*q)[0], (*q)[1], (*q)[2], (*q)[3]);
    if (std::abs(qq.norm() - 1.0) > 1e-3)
      return make_error(Errc::invalid_argument, t->where("q_imu_segment_wxyz") + ": 'imu." + name +
                                                    ".q_imu_segment_wxyz' must be a unit quaternion (norm " +
                                                    fmt("%.4f)", qq.norm()));
    c.q_imu_segment[index_of(i)] = qq.normalized();
    auto h = doubles_n(*t, "imu." + name, "hard_iron_uT", 3);
    if (!h) return h.error();
    c.mag[index_of(i)].hard_iron_uT = Vec3((*h)[0], (*h)[1], (*h)[2]);
    auto w = doubles_n(*t, "imu." + name, "soft_iron_inv", 9);
    if (!w) return w.error();
    Mat3 W;
    W << (*w)[0], (*w)[1], (*w)[2], (*w)[3], (*w)[4], (*w)[5], (*w)[6], (*w)[7], (*w)[8];
    if (!(std::abs(W.determinant()) > 1e-6))
      return make_error(Errc::invalid_argument,
                        t->where("soft_iron_inv") + ": 'imu." + name + ".soft_iron_inv' is singular");
    c.mag[index_of(i)].soft_iron_inv = W;
  }
  auto bends = root.table("bend");
  if (!bends) return bends.error();
  {
    std::set<std::string> names;
    for (auto b : kBends) names.insert(std::string(to_string(b)));
    if (auto k = bends->check_keys("bend", names); !k) return k.error();
  }
  for (auto b : kBends) {
    const std::string name(to_string(b));
    auto t = bends->table(name);
    if (!t) return t.error();
    if (auto k = t->check_keys("bend." + name, {"beta0_rad", "beta1_rad_per_pF"}); !k) return k.error();
    auto b0 = t->get_double("beta0_rad");
    if (!b0) return b0.error();
    auto b1 = t->get_double("beta1_rad_per_pF");
    if (!b1) return b1.error();
    if (*b1 == 0.0)
      return make_error(Errc::invalid_argument,
                        t->where("beta1_rad_per_pF") + ": 'bend." + name + ".beta1_rad_per_pF' must not be 0");
    c.beta0_rad[index_of(b)] = *b0;
    c.beta1_rad_per_pF[index_of(b)] = *b1;
  }
  if (auto s = c.validate(); !s) return s.error().with_context(source);
  return c;
}

Result<FtmCalibration> load_ftm_calibration(const std::filesystem::path& path) {
  auto text = read_input_file(path, "FTM calibration", 1 * kMiB);
  if (!text) return text.error();
  return parse_ftm_calibration(*text, path.string());
}

Status save_ftm_calibration(const std::filesystem::path& path, const FtmCalibration& c) {
  if (auto s = c.validate(); !s) return s.error().with_context("not saving " + path.string());
  return write_file_atomic(path, format_ftm_calibration(c), "FTM calibration");
}

// ---------------------------------------------------------------- poses

std::string_view to_string(FtmCalibrationPose p) noexcept {
  switch (p) {
    case FtmCalibrationPose::flat: return "flat";
    case FtmCalibrationPose::thumb_parallel: return "thumb_parallel";
    case FtmCalibrationPose::bend_90: return "bend_90";
  }
  return "?";
}

std::string_view instruction(FtmCalibrationPose p) noexcept {
  switch (p) {
    case FtmCalibrationPose::flat:
      return "Lay the hand flat on the table, palm down, all fingers and the thumb straight and together. Hold "
             "still.";
    case FtmCalibrationPose::thumb_parallel:
      return "Keep the fingers flat and straight; move the thumb so that it lies straight and parallel to the "
             "index finger. Hold still.";
    case FtmCalibrationPose::bend_90:
      return "Keep the thumb parallel to the index finger and the knuckles straight; bend the middle joints of "
             "the four fingers 90 degrees and the thumb's middle joint as far as it goes (about 60 degrees). Hold "
             "still.";
  }
  return "";
}

HandAngles known_angles(FtmCalibrationPose p, const HandShape& shape) {
  // The same instructions, in the same arithmetic, as the simulated wearer
  // (input/ftm_sim: FtmWearerSimulator::instructed_angles), so a simulated
  // calibration is judged against exactly what the person was asked for.
  const JointLimits lim = JointLimits::defaults();
  HandAngles flat{};
  flat.fill(0.0);
  if (p == FtmCalibrationPose::flat) return flat;
  // Thumb parallel: the CMC angles (1° grid over the CMC range) that bring
  // the thumb metacarpal's long axis closest to the index proximal phalanx's.
  const HandModel model(shape);
  HandAngles parallel = flat;
  {
    const auto joints = model.joint_poses_in_wrist(Handedness::right, flat);
    const Vec3 finger_dir = joints[index_of(HandJoint::index_proximal)].q * Vec3(0, 0, -1);
    double best = 1e9;
    const std::size_t cf = index_of(HandDof::thumb_cmc_flexion), ca = index_of(HandDof::thumb_cmc_abduction);
    for (double f = lim.min_rad[cf]; f <= lim.max_rad[cf]; f += deg_to_rad(1.0)) {
      for (double a = lim.min_rad[ca]; a <= lim.max_rad[ca]; a += deg_to_rad(1.0)) {
        HandAngles x = flat;
        x[cf] = f;
        x[ca] = a;
        const auto j = model.joint_poses_in_wrist(Handedness::right, x);
        const Vec3 thumb_dir = j[index_of(HandJoint::thumb_metacarpal)].q * Vec3(0, 0, -1);
        const double err = std::acos(std::clamp(thumb_dir.dot(finger_dir), -1.0, 1.0));
        if (err < best) {
          best = err;
          parallel = x;
        }
      }
    }
  }
  if (p == FtmCalibrationPose::thumb_parallel) return parallel;
  // Bend 90: PIPs at 90° (DIPs at their synergy), the thumb MCP at 90° or its
  // limit (60°), the thumb IP at its synergy.
  HandAngles bend90 = parallel;
  for (Finger f : {Finger::index, Finger::middle, Finger::ring, Finger::little}) {
    bend90[first_dof_of(f) + 2] = deg_to_rad(90.0);
    bend90[first_dof_of(f) + 3] = deg_to_rad(60.0);
  }
  bend90[index_of(HandDof::thumb_mcp_flexion)] =
      std::min(deg_to_rad(90.0), lim.max_rad[index_of(HandDof::thumb_mcp_flexion)]);
  bend90[index_of(HandDof::thumb_ip_flexion)] = 0.5 * bend90[index_of(HandDof::thumb_mcp_flexion)];
  return bend90;
}

HandAngles known_angles(FtmCalibrationPose p) {
  return known_angles(p, HandShape::from_measurements(0.19, 0.10).value());
}

// ---------------------------------------------------------------- collector

FtmPoseCollector::FtmPoseCollector(FtmCalibrationPose pose, const FtmCalibration& mag_and_field,
                                   MahonyOptions options)
    : pose_(pose), cal_(mag_and_field) {
  options.mag_ref_in_world_uT = cal_.earth_field_world_uT;
  filters_.reserve(kFtmImuCount);
  for (std::size_t i = 0; i < kFtmImuCount; ++i) filters_.emplace_back(options);
}

void FtmPoseCollector::push(const FtmEvent& e) noexcept {
  const TimeNs t = e.time_ns();
  switch (e.kind) {
    case FtmEvent::Kind::imu: {
      if (e.index >= kFtmImuCount) return;
      const FtmImuSample& s = e.imu;
      if ((s.status & ~sample_status::mag_overflow) != 0 || !s.gyro_radps.allFinite() || !s.accel_mps2.allFinite())
        return;
      std::optional<Vec3> mag;
      if (s.mag_fresh && !(s.status & sample_status::mag_overflow) && s.mag_uT.allFinite())
        mag = cal_.mag[e.index].apply(s.mag_uT);
      filters_[e.index].update(t, s.gyro_radps, s.accel_mps2 - cal_.accel_bias_mps2[e.index], mag);
      if (gyro_n_[e.index] == 0) first_ns_[e.index] = t;
      gyro_[e.index][gyro_n_[e.index]++ % kRing] = {t, s.gyro_radps.norm()};
      gyro_vec_[e.index][(gyro_n_[e.index] - 1) % kRing] = s.gyro_radps;
      ++samples_;
      break;
    }
    case FtmEvent::Kind::bend:
      if (e.index >= kFtmBendCount || e.bend.status != 0 || !std::isfinite(e.bend.capacitance_pF)) return;
      bend_[e.index][bend_n_[e.index]++ % kRing] = {t, e.bend.capacitance_pF};
      break;
    case FtmEvent::Kind::wrist:
      if (!e.wrist.valid || !e.wrist.T_world_wrist.p.allFinite() || !e.wrist.T_world_wrist.q.coeffs().allFinite())
        return;
      wrist_ = e.wrist.T_world_wrist;
      wrist_valid_ = true;
      break;
  }
  newest_ns_ = std::max(newest_ns_, t);
}

bool FtmPoseCollector::still(DurationNs window) const {
  const TimeNs from = newest_ns_ - window;
  for (std::size_t i = 0; i < kFtmImuCount; ++i) {
    if (!filters_[i].initialised() || gyro_n_[i] == 0) return false;
    if (newest_ns_ - first_ns_[i] < std::max<DurationNs>(window, kSettleNs)) return false;
    const std::size_t n = std::min(gyro_n_[i], kRing);
    bool covers = false;
    for (std::size_t j = 0; j < n; ++j) {
      const TimedValue& v = gyro_[i][(gyro_n_[i] - 1 - j) % kRing];
      if (v.t < from) {
        covers = true;
        break;
      }
      if (!(v.v < kStillGyroRadps)) return false;
    }
    // The ring must reach back past the window (else part of it is unseen).
    if (!covers && gyro_n_[i] > kRing) return false;
  }
  for (std::size_t b = 0; b < kFtmBendCount; ++b) {
    if (bend_n_[b] == 0 || bend_[b][(bend_n_[b] - 1) % kRing].t < from) return false;
  }
  return true;
}

Result<FtmPoseCapture> FtmPoseCollector::finish() const {
  FtmPoseCapture c;
  c.pose = pose_;
  c.samples = samples_;
  c.T_world_wrist = wrist_;
  c.wrist_valid = wrist_valid_;
  constexpr DurationNs kWindow = 500'000'000;
  for (std::size_t i = 0; i < kFtmImuCount; ++i) {
    if (!filters_[i].initialised()) {
      return make_error(Errc::unavailable, "calibration pose '" + std::string(to_string(pose_)) + "': the " +
                                               std::string(to_string(static_cast<FtmImu>(i))) +
                                               " IMU gave no usable accelerometer + compass sample");
    }
    c.q_world_imu[i] = filters_[i].q_world_body();
    double ss = 0.0;
    std::size_t m = 0;
    Vec3 sum = Vec3::Zero();
    for (std::size_t j = 0; j < std::min(gyro_n_[i], kRing); ++j) {
      const std::size_t k = (gyro_n_[i] - 1 - j) % kRing;
      const TimedValue& v = gyro_[i][k];
      if (v.t < newest_ns_ - kWindow) break;
      ss += v.v * v.v;
      sum += gyro_vec_[i][k];
      ++m;
    }
    c.gyro_mean_radps[i] = m ? Vec3(sum / static_cast<double>(m)) : Vec3::Zero();
    c.gyro_rms_radps = std::max(c.gyro_rms_radps, m ? std::sqrt(ss / static_cast<double>(m)) : 0.0);
  }
  for (std::size_t b = 0; b < kFtmBendCount; ++b) {
    double sum = 0.0;
    std::size_t m = 0;
    for (std::size_t j = 0; j < std::min(bend_n_[b], kRing); ++j) {
      const TimedValue& v = bend_[b][(bend_n_[b] - 1 - j) % kRing];
      if (v.t < newest_ns_ - kWindow) break;
      sum += v.v;
      ++m;
    }
    if (m == 0) {
      return make_error(Errc::unavailable, "calibration pose '" + std::string(to_string(pose_)) + "': the " +
                                               std::string(to_string(static_cast<FtmBend>(b))) +
                                               " bend sensor gave no usable sample in the last 0.5 s");
    }
    c.capacitance_pF[b] = sum / static_cast<double>(m);
  }
  return c;
}

// ---------------------------------------------------------------- solvers

Result<FtmCalibration> solve_mag_and_field(std::span<const FtmEvent> events, FtmCalibration base,
                                           const MagFitOptions& options) {
  std::array<std::vector<Vec3>, kFtmImuCount> raw;
  struct Wrist {
    TimeNs t;
    Quat q;
  };
  std::vector<Wrist> wrist;
  for (const FtmEvent& e : events) {
    if (e.kind == FtmEvent::Kind::imu && e.index < kFtmImuCount && e.imu.mag_fresh &&
        (e.imu.status & ~sample_status::mag_overflow) == 0 && !(e.imu.status & sample_status::mag_overflow) &&
        e.imu.mag_uT.allFinite())
      raw[e.index].push_back(e.imu.mag_uT);
    if (e.kind == FtmEvent::Kind::wrist && e.wrist.valid && e.wrist.T_world_wrist.q.coeffs().allFinite())
      wrist.push_back({e.wrist.time_ns, e.wrist.T_world_wrist.q.normalized()});
  }
  for (auto i : kImus) {
    auto fit = fit_mag_ellipsoid(raw[index_of(i)], options);
    if (!fit) return fit.error().with_context(std::string(to_string(i)) + " IMU");
    base.mag[index_of(i)] = fit->first;
  }
  // The field in the world from the dorsum IMU.
  const std::size_t d = index_of(FtmImu::dorsum);
  const Quat q_seg_imu = base.q_imu_segment[d].conjugate();
  Vec3 sum = Vec3::Zero();
  std::size_t n = 0;
  if (!wrist.empty()) {
    for (const FtmEvent& e : events) {
      if (e.kind != FtmEvent::Kind::imu || e.index != d || !e.imu.mag_fresh || e.imu.status != 0 ||
          !e.imu.mag_uT.allFinite())
        continue;
      const TimeNs t = e.imu.time_ns;
      auto it = std::lower_bound(wrist.begin(), wrist.end(), t, [](const Wrist& w, TimeNs x) { return w.t < x; });
      const Wrist* best = nullptr;
      if (it != wrist.end()) best = &*it;
      if (it != wrist.begin() && (!best || std::llabs(std::prev(it)->t - t) < std::llabs(best->t - t)))
        best = &*std::prev(it);
      if (!best || std::llabs(best->t - t) > 50'000'000) continue;
      sum += best->q * q_seg_imu * base.mag[d].apply(e.imu.mag_uT);
      ++n;
    }
  }
  if (n >= 20) {
    base.earth_field_world_uT = sum / static_cast<double>(n);
    return base;
  }
  // Fallback: dip from the accelerometer, horizontal part along world -Z.
  const MahonyOptions defaults;
  const double g = defaults.gravity_ref_in_world_mps2.norm();
  const Vec3 up_world = defaults.gravity_ref_in_world_mps2 / g;
  double v = 0.0, h = 0.0;
  n = 0;
  for (const FtmEvent& e : events) {
    if (e.kind != FtmEvent::Kind::imu || e.index != d || !e.imu.mag_fresh || e.imu.status != 0 ||
        !e.imu.mag_uT.allFinite() || !e.imu.accel_mps2.allFinite())
      continue;
    const Vec3 accel = e.imu.accel_mps2 - base.accel_bias_mps2[d];
    const double an = accel.norm();
    if (std::abs(an - g) > 0.2 * g) continue;
    const Vec3 up = accel / an;
    const Vec3 m = base.mag[d].apply(e.imu.mag_uT);
    v += m.dot(up);
    h += (m - m.dot(up) * up).norm();
    ++n;
  }
  if (n < 20) {
    return make_error(Errc::unavailable,
                      "Earth field: fewer than 20 dorsum compass samples with the hand near rest or a valid wrist "
                      "pose; move more slowly through the figure-eight");
  }
  v /= static_cast<double>(n);
  h /= static_cast<double>(n);
  base.earth_field_world_uT = v * up_world + h * Vec3(0.0, 0.0, -1.0);
  return base;
}

Result<FtmCalibration> solve_three_pose(std::span<const FtmPoseCapture> captures, FtmCalibration base) {
  if (auto s = base.validate(); !s) return s.error().with_context("three-pose calibration: base calibration");
  if (captures.size() != kFtmCalibrationPoseCount) {
    return make_error(Errc::invalid_argument, "three-pose calibration needs exactly 3 captures, got " +
                                                  std::to_string(captures.size()));
  }
  std::array<int, kFtmCalibrationPoseCount> seen{};
  bool all_wrist = true;
  for (const FtmPoseCapture& c : captures) {
    const auto k = static_cast<std::size_t>(c.pose);
    if (k >= kFtmCalibrationPoseCount || seen[k]++)
      return make_error(Errc::invalid_argument, "three-pose calibration: pose '" + std::string(to_string(c.pose)) +
                                                    "' given twice (each pose once: flat, thumb_parallel, bend_90)");
    for (const Quat& q : c.q_world_imu)
      if (!unit_quat_ok(q.normalized()) || !q.coeffs().allFinite())
        return make_error(Errc::invalid_argument, "three-pose calibration: non-finite IMU orientation");
    for (double p : c.capacitance_pF)
      if (!std::isfinite(p)) return make_error(Errc::invalid_argument, "three-pose calibration: non-finite capacitance");
    all_wrist = all_wrist && c.wrist_valid;
  }
  auto shape = HandShape::from_measurements(base.hand_length_m, base.hand_width_m);
  if (!shape) return shape.error();
  const HandModel model(*shape);
  std::array<HandAngles, kFtmCalibrationPoseCount> known;
  for (std::size_t k = 0; k < kFtmCalibrationPoseCount; ++k)
    known[k] = known_angles(static_cast<FtmCalibrationPose>(k), *shape);
  const std::size_t d = index_of(FtmImu::dorsum);
  // The dorsum first: R_b_f = R_s_bᵀ R_s_wrist with the wrist tracker's
  // orientation. Without it the base's dorsum mounting is kept.
  if (all_wrist) {
    Mat3 acc = Mat3::Zero();
    for (const FtmPoseCapture& c : captures)
      acc += (c.q_world_imu[d].normalized().conjugate() * c.T_world_wrist.q.normalized()).toRotationMatrix();
    base.q_imu_segment[d] = project_to_so3(acc);
  }
  // The fingers relative to the dorsum IMU (R_s_h = R_s_bd R_b_f_d), not to
  // the wrist tracker: then the tracker's relative rotations reproduce the
  // known poses exactly whatever the dorsum mounting's error, and a heading
  // offset between the IMUs' world and the tracker's world cancels.
  std::array<Mat3, kFtmImuCount> acc;
  acc.fill(Mat3::Zero());
  for (const FtmPoseCapture& c : captures) {
    const auto T = model.joint_poses_in_wrist(base.hand, known[static_cast<std::size_t>(c.pose)]);
    const Quat q_world_hand = (c.q_world_imu[d].normalized() * base.q_imu_segment[d]).normalized();
    for (auto i : kImus) {
      if (i == FtmImu::dorsum) continue;
      const Quat q_world_seg = q_world_hand * T[index_of(segment_of(i))].q;
      acc[index_of(i)] += (c.q_world_imu[index_of(i)].normalized().conjugate() * q_world_seg).toRotationMatrix();
    }
  }
  for (auto i : kImus) {
    if (i != FtmImu::dorsum) base.q_imu_segment[index_of(i)] = project_to_so3(acc[index_of(i)]);
  }
  for (auto b : kBends) {
    double sr = 0, st = 0, srr = 0, srt = 0;
    double rmin = 1e300, rmax = -1e300;
    for (const FtmPoseCapture& c : captures) {
      const double r = c.capacitance_pF[index_of(b)];
      const double t = known[static_cast<std::size_t>(c.pose)][index_of(dof_of(b))];
      sr += r;
      st += t;
      srr += r * r;
      srt += r * t;
      rmin = std::min(rmin, r);
      rmax = std::max(rmax, r);
    }
    if (rmax - rmin < 0.05) {
      return make_error(Errc::invalid_argument,
                        "three-pose calibration: the " + std::string(to_string(b)) +
                            fmt(" bend sensor changed by only %.3f pF between the poses: is it connected, and was "
                                "the joint bent in the bend_90 pose?",
                                rmax - rmin));
    }
    const double n = static_cast<double>(captures.size());
    const double b1 = (n * srt - sr * st) / (n * srr - sr * sr);
    base.beta1_rad_per_pF[index_of(b)] = b1;
    base.beta0_rad[index_of(b)] = (st - b1 * sr) / n;
  }
  return base;
}

Status FtmTurnOnBiasOptions::validate() const {
  if (auto st = accel_fit.validate(); !st) return st.error().with_context("FtmTurnOnBiasOptions.accel_fit");
  if (!std::isfinite(max_pose_gyro_disagreement_radps) || !(max_pose_gyro_disagreement_radps > 0.0)) {
    return make_error(Errc::invalid_argument, "FtmTurnOnBiasOptions.max_pose_gyro_disagreement_radps must be > 0 (" +
                                                  describe() + ")");
  }
  return {};
}

std::string FtmTurnOnBiasOptions::describe() const {
  return std::string("accel offset from the figure-eight: ") + (fit_accel ? accel_fit.describe() : "off") +
         "; gyro offset from the poses: " + (gyro_from_poses ? "mean rate over the three still windows when they agree within " +
                                std::to_string(max_pose_gyro_disagreement_radps * 180.0 / M_PI) + " deg/s"
                          : std::string("off"));
}

Result<FtmCalibrationOutcome> calibrate_ftm(const FtmCalibrationRecording& recording, const FtmCalibration& base_in,
                                            const MahonyOptions& attitude, const MagFitOptions& mag,
                                            const FtmTurnOnBiasOptions& bias) {
  if (auto st = bias.validate(); !st) return st.error();
  FtmCalibration base = base_in;
  FtmCalibrationOutcome out;
  if (bias.fit_accel) {
    for (std::size_t i = 0; i < kFtmImuCount; ++i) {
      auto fit = fit_accel_bias(imu_samples_of(recording.figure_eight, i), bias.accel_fit);
      // A refused fit is not fatal: that IMU runs uncorrected, as before.
      if (fit) {
        base.accel_bias_mps2[i] = fit->bias_mps2;
        out.accel_bias_fitted[i] = true;
      } else {
        out.accel_bias_note[i] = fit.error().message;
      }
    }
  }
  auto field = solve_mag_and_field(recording.figure_eight, base, mag);
  if (!field) return make_error(field.error().code, "compass calibration (figure-eight): " + field.error().message);
  for (std::size_t k = 0; k < kFtmCalibrationPoseCount; ++k) {
    const auto pose = static_cast<FtmCalibrationPose>(k);
    FtmPoseCollector collector(pose, *field, attitude);
    // From the start of the session: the filters converge as a live run's have.
    for (const FtmEvent& e : recording.figure_eight) collector.push(e);
    for (std::size_t j = 0; j <= k; ++j) {
      for (const FtmEvent& e : recording.poses[j]) collector.push(e);
    }
    auto capture = collector.finish();
    if (!capture) {
      return make_error(capture.error().code,
                        "pose " + std::to_string(k + 1) + " (" + std::string(to_string(pose)) + "): " +
                            capture.error().message);
    }
    out.captures[k] = *capture;
  }
  auto solved = solve_three_pose(out.captures, *field);
  if (!solved) return solved.error();
  out.calibration = std::move(*solved);
  if (bias.gyro_from_poses) {
    // The poses are held still (FtmPoseCollector::still, a loose 8.6 °/s):
    // the mean rate over each window is the gyro's offset plus whatever the
    // hand still turned. Only when the three poses agree (a hand truly at
    // rest) is their mean taken as the offset; otherwise the filters learn it
    // online, as without this step.
    for (std::size_t i = 0; i < kFtmImuCount; ++i) {
      Vec3 sum = Vec3::Zero();
      for (const auto& c : out.captures) sum += c.gyro_mean_radps[i];
      const Vec3 mean = sum / static_cast<double>(kFtmCalibrationPoseCount);
      double worst = 0.0;
      for (const auto& c : out.captures) worst = std::max(worst, (c.gyro_mean_radps[i] - mean).norm());
      if (worst <= bias.max_pose_gyro_disagreement_radps) {
        out.calibration.gyro_bias_radps[i] = mean;
        out.gyro_bias_estimated[i] = true;
      } else {
        char buf[200];
        std::snprintf(buf, sizeof buf,
                      "gyro offset not taken from the poses: their mean rates differ by up to %.3g deg/s "
                      "(> %.3g): the hand was turning",
                      worst * 180.0 / M_PI, bias.max_pose_gyro_disagreement_radps * 180.0 / M_PI);
        out.gyro_bias_note[i] = buf;
      }
    }
  }
  return out;
}

}  // namespace proprio::ftm
