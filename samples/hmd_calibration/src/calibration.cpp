#include "proprio/hmd_calibration/calibration.hpp"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <fstream>

#include "proprio/core/config.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/core/random.hpp"

namespace proprio::hmd_calibration {

namespace {
constexpr double kPi = 3.14159265358979323846;
}

Status TargetOptions::validate() const {
  if (trials < 3) return make_error(Errc::invalid_argument, fmt::format("trials: at least 3, not {}", trials));
  if (!(r_min_m > 0 && r_max_m >= r_min_m)) {
    return make_error(Errc::invalid_argument, "target distances need 0 < r_min <= r_max");
  }
  if (!(angle_max_deg >= 0 && angle_max_deg < 90)) {
    return make_error(Errc::invalid_argument, "angle_max_deg must be in [0, 90)");
  }
  return {};
}

std::vector<Vec3> calibration_targets(const TargetOptions& o) {
  Rng rng(o.seed);
  std::vector<Vec3> targets;
  const double a = o.angle_max_deg * kPi / 180.0;
  for (int i = 0; i < o.trials; ++i) {
    const double r = rng.uniform(o.r_min_m, o.r_max_m);
    const double theta = rng.uniform(-a, a), phi = rng.uniform(-a, a);
    targets.emplace_back(r * std::cos(phi) * std::sin(theta), r * std::sin(phi), -r * std::cos(phi) * std::cos(theta));
  }
  return targets;
}

std::string RigidFit::describe() const {
  const Eigen::AngleAxisd aa(T_hmd_graphics.q);
  return fmt::format("graphics frame in the HMD frame: translation ({:.1f}, {:.1f}, {:.1f}) mm, rotation {:.2f} deg "
                     "about ({:.2f}, {:.2f}, {:.2f}); residuals over {} reaches: RMS {:.1f} mm, max {:.1f} mm",
                     T_hmd_graphics.p.x() * 1e3, T_hmd_graphics.p.y() * 1e3, T_hmd_graphics.p.z() * 1e3,
                     aa.angle() * 180.0 / kPi, aa.axis().x(), aa.axis().y(), aa.axis().z(), pairs, rms_m * 1e3,
                     max_m * 1e3);
}

Result<RigidFit> fit_hmd_graphics(const std::vector<Vec3>& cmd, const std::vector<Vec3>& finger) {
  if (cmd.size() != finger.size()) {
    return make_error(Errc::invalid_argument, fmt::format("{} targets but {} reaches", cmd.size(), finger.size()));
  }
  if (cmd.size() < 3) return make_error(Errc::invalid_argument, "at least 3 reaches are needed for a rigid fit");
  const auto n = static_cast<Eigen::Index>(cmd.size());
  Eigen::Matrix3Xd src(3, n), dst(3, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!cmd[static_cast<std::size_t>(i)].allFinite() || !finger[static_cast<std::size_t>(i)].allFinite()) {
      return make_error(Errc::invalid_argument, fmt::format("reach {} is not finite", i));
    }
    src.col(i) = cmd[static_cast<std::size_t>(i)];
    dst.col(i) = finger[static_cast<std::size_t>(i)];
  }
  // Collinear targets leave the rotation about their line undetermined.
  const Eigen::Matrix3Xd centred = src.colwise() - src.rowwise().mean();
  const Eigen::JacobiSVD<Eigen::Matrix3Xd> svd(centred);
  if (svd.singularValues()(1) < 1e-6 * std::max(1.0, svd.singularValues()(0))) {
    return make_error(Errc::invalid_argument, "the targets are collinear: the rotation is not determined");
  }
  const Eigen::Matrix4d T = Eigen::umeyama(src, dst, false);
  RigidFit fit;
  fit.T_hmd_graphics = {Quat(Eigen::Matrix3d(T.topLeftCorner<3, 3>())).normalized(), T.topRightCorner<3, 1>()};
  fit.pairs = static_cast<int>(n);
  double sum = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double r = (fit.T_hmd_graphics * Vec3(src.col(i)) - Vec3(dst.col(i))).norm();
    fit.residuals_m.push_back(r);
    sum += r * r;
    fit.max_m = std::max(fit.max_m, r);
  }
  fit.rms_m = std::sqrt(sum / static_cast<double>(n));
  return fit;
}

std::vector<Vec3> simulate_reaching(const Pose& T_true, const std::vector<Vec3>& cmd, double sd_m,
                                    std::uint64_t seed) {
  Rng rng(seed);
  std::vector<Vec3> out;
  for (const Vec3& p : cmd) out.push_back(T_true * p + sd_m * Vec3(rng.normal(), rng.normal(), rng.normal()));
  return out;
}

Status save_calibration(const std::filesystem::path& path, const RigidFit& fit) {
  const Pose& T = fit.T_hmd_graphics;
  std::string text = "# HMD calibration (proprio run hmd-calibration): p_hmd = R * p_graphics + t\n[hmd_calibration]\n";
  text += fmt::format("translation_m = [{:.6f}, {:.6f}, {:.6f}]\n", T.p.x(), T.p.y(), T.p.z());
  text += fmt::format("rotation_xyzw = [{:.8f}, {:.8f}, {:.8f}, {:.8f}]\n", T.q.x(), T.q.y(), T.q.z(), T.q.w());
  text += fmt::format("rms_m = {:.6f}\nmax_m = {:.6f}\npairs = {}\n", fit.rms_m, fit.max_m, fit.pairs);
  return write_file_atomic(path, text, "HMD calibration");
}

Result<Pose> load_calibration(const std::filesystem::path& path) {
  auto c = Config::load_file(path);
  if (!c) return c.error();
  if (auto k = c->check_keys("top level", {"hmd_calibration"}); !k) return k.error();
  auto table = c->table("hmd_calibration");
  if (!table) return table.error();
  if (auto k = table->check_keys("hmd_calibration", {"translation_m", "rotation_xyzw", "rms_m", "max_m", "pairs"}); !k) {
    return k.error();
  }
  auto t = c->get_doubles("hmd_calibration.translation_m");
  auto q = c->get_doubles("hmd_calibration.rotation_xyzw");
  if (!t) return t.error();
  if (!q) return q.error();
  if (t->size() != 3 || q->size() != 4) {
    return make_error(Errc::invalid_argument, path.string() + ": translation_m needs 3 numbers, rotation_xyzw 4");
  }
  const Quat rot((*q)[3], (*q)[0], (*q)[1], (*q)[2]);
  if (!(std::abs(rot.norm() - 1.0) < 1e-3)) {
    return make_error(Errc::invalid_argument, path.string() + ": rotation_xyzw is not a unit quaternion");
  }
  return Pose{rot.normalized(), Vec3((*t)[0], (*t)[1], (*t)[2])};
}

}  // namespace proprio::hmd_calibration
