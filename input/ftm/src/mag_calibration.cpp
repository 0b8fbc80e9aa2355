#include "proprio/ftm/mag_calibration.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <vector>

namespace proprio::ftm {
namespace {

Error mag_error(Errc code, const char* fmt, double a = 0.0, double b = 0.0) {
  char buf[320];
  std::snprintf(buf, sizeof buf, fmt, a, b);
  return make_error(code, buf);
}

constexpr int kAzimuthBins = 8, kBands = 4;

}  // namespace

Status MagFitOptions::validate() const {
  if (min_samples < 10) return make_error(Errc::invalid_argument, "MagFitOptions.min_samples must be >= 10");
  if (!(min_coverage >= 0.0 && min_coverage <= 1.0))
    return make_error(Errc::invalid_argument, "MagFitOptions.min_coverage must be in [0, 1]");
  if (!(min_field_uT > 0.0 && max_field_uT > min_field_uT && std::isfinite(max_field_uT)))
    return make_error(Errc::invalid_argument, "MagFitOptions.min_field_uT/max_field_uT must satisfy 0 < min < max");
  if (!(max_axis_ratio >= 1.0 && std::isfinite(max_axis_ratio)))
    return make_error(Errc::invalid_argument, "MagFitOptions.max_axis_ratio must be >= 1");
  return {};
}

std::string MagFitOptions::describe() const {
  char buf[200];
  std::snprintf(buf, sizeof buf, "min_samples %zu, min_coverage %.2f, field %.0f-%.0f uT, max_axis_ratio %.1f",
                min_samples, min_coverage, min_field_uT, max_field_uT, max_axis_ratio);
  return buf;
}

double direction_coverage(std::span<const Vec3> v) noexcept {
  // Equal-area bins: 4 bands of equal height in z (Archimedes), 8 azimuths.
  std::array<bool, kAzimuthBins * kBands> hit{};
  for (const Vec3& x : v) {
    const double n = x.norm();
    if (!(n > 0.0) || !std::isfinite(n)) continue;
    const Vec3 u = x / n;
    const int band = std::clamp(static_cast<int>((u.z() + 1.0) * 0.5 * kBands), 0, kBands - 1);
    const double az = std::atan2(u.y(), u.x()) + M_PI;
    const int a = std::clamp(static_cast<int>(az / (2.0 * M_PI) * kAzimuthBins), 0, kAzimuthBins - 1);
    hit[static_cast<std::size_t>(band * kAzimuthBins + a)] = true;
  }
  return static_cast<double>(std::count(hit.begin(), hit.end(), true)) / static_cast<double>(hit.size());
}

Result<std::pair<MagCalibration, MagFitReport>> fit_mag_ellipsoid(std::span<const Vec3> raw_uT,
                                                                  const MagFitOptions& options) {
  if (auto s = options.validate(); !s) return s.error();
  if (raw_uT.size() < options.min_samples) {
    return mag_error(Errc::invalid_argument,
                     "compass fit: %.0f samples, at least %.0f needed: record a longer figure-eight motion",
                     static_cast<double>(raw_uT.size()), static_cast<double>(options.min_samples));
  }
  Vec3 mean = Vec3::Zero();
  for (std::size_t i = 0; i < raw_uT.size(); ++i) {
    if (!raw_uT[i].allFinite()) {
      return mag_error(Errc::invalid_argument, "compass fit: sample %.0f is not finite (NaN or Inf)",
                       static_cast<double>(i));
    }
    mean += raw_uT[i];
  }
  mean /= static_cast<double>(raw_uT.size());
  // Centre and scale the data so the normal equations are well conditioned.
  double scale = 0.0;
  for (const Vec3& x : raw_uT) scale += (x - mean).norm();
  scale /= static_cast<double>(raw_uT.size());
  if (!(scale > 1e-6)) {
    return mag_error(Errc::invalid_argument,
                     "compass fit: the samples do not move (spread %.3g uT): move the hand through a figure-eight "
                     "in all directions",
                     scale);
  }
  const auto n = static_cast<Eigen::Index>(raw_uT.size());
  Eigen::MatrixXd D(n, 9);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Vec3 x = (raw_uT[static_cast<std::size_t>(i)] - mean) / scale;
    D.row(i) << x.x() * x.x(), x.y() * x.y(), x.z() * x.z(), 2 * x.x() * x.y(), 2 * x.x() * x.z(),
        2 * x.y() * x.z(), 2 * x.x(), 2 * x.y(), 2 * x.z();
  }
  const Eigen::VectorXd ones = Eigen::VectorXd::Ones(n);
  const Eigen::VectorXd v = D.colPivHouseholderQr().solve(ones);
  if (!v.allFinite()) return mag_error(Errc::invalid_argument, "compass fit: singular system (degenerate motion)");
  Mat3 Q;
  Q << v(0), v(3), v(4), v(3), v(1), v(5), v(4), v(5), v(2);
  const Vec3 b(v(6), v(7), v(8));
  Eigen::SelfAdjointEigenSolver<Mat3> eq(Q);
  if (eq.info() != Eigen::Success || !(eq.eigenvalues().minCoeff() > 0.0)) {
    return mag_error(Errc::invalid_argument,
                     "compass fit: the samples do not lie on an ellipsoid (smallest axis term %.3g): move the hand "
                     "through a figure-eight in all directions, away from metal",
                     eq.eigenvalues().minCoeff());
  }
  const Vec3 c = -Q.ldlt().solve(b);
  const double k = 1.0 + c.dot(Q * c);
  if (!(k > 0.0)) return mag_error(Errc::invalid_argument, "compass fit: imaginary ellipsoid (k = %.3g)", k);
  const Vec3 ev = eq.eigenvalues() / k;  // semi-axes a_i = 1/sqrt(ev_i)
  const double axis_ratio = std::sqrt(ev.maxCoeff() / ev.minCoeff());
  if (axis_ratio > options.max_axis_ratio) {
    return mag_error(Errc::invalid_argument,
                     "compass fit: ellipsoid axes differ by %.2fx (limit %.2f): degenerate motion or strong iron "
                     "nearby; move the hand through a figure-eight in all directions",
                     axis_ratio, options.max_axis_ratio);
  }
  // sqrt(Q/k) in the eigenbasis; r makes its determinant 1 after scaling back.
  const Vec3 sq = ev.cwiseSqrt();
  const double r = std::cbrt(1.0 / (sq.x() * sq.y() * sq.z()));  // geometric-mean radius, scaled units
  const Mat3 W = eq.eigenvectors() * (r * sq).asDiagonal() * eq.eigenvectors().transpose();
  MagCalibration cal;
  cal.hard_iron_uT = mean + scale * c;
  cal.soft_iron_inv = W;  // the map is linear: the scale cancels (W(x-c)/scale*scale)
  MagFitReport rep;
  rep.samples = raw_uT.size();
  rep.field_uT = r * scale;
  std::vector<Vec3> corrected;
  corrected.reserve(raw_uT.size());
  double ss = 0.0;
  for (const Vec3& x : raw_uT) {
    corrected.push_back(cal.apply(x));
    const double e = corrected.back().norm() - rep.field_uT;
    ss += e * e;
  }
  rep.residual_rms_uT = std::sqrt(ss / static_cast<double>(raw_uT.size()));
  rep.coverage = direction_coverage(corrected);
  if (rep.coverage < options.min_coverage) {
    return mag_error(Errc::invalid_argument,
                     "compass fit: the motion covered %.0f%% of directions (at least %.0f%% needed): move the hand "
                     "through a figure-eight, turning it over and around so the glove points every way",
                     100.0 * rep.coverage, 100.0 * options.min_coverage);
  }
  if (rep.field_uT < options.min_field_uT || rep.field_uT > options.max_field_uT) {
    return mag_error(Errc::invalid_argument,
                     "compass fit: field %.1f uT is implausible (Earth 25-65 uT): wrong unit, or a magnet nearby",
                     rep.field_uT);
  }
  return std::pair{cal, rep};
}

}  // namespace proprio::ftm
