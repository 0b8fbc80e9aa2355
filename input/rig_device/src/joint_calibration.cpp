#include "proprio/rig_device/joint_calibration.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

#include "proprio/core/config.hpp"
#include "proprio/core/file_io.hpp"

namespace proprio::rig_device {
namespace {

constexpr const char* kFormat = "proprio-rig-joint-calibration";
constexpr int kVersion = 1;
// Channel values are counts (0..4095); coefficients of a sane fit are of that
// order. A file with larger ones is corrupt, not a calibration.
constexpr double kMaxCoefficient = 1e6;
// The bends' starting point: F on this many points per hinge.
constexpr int kSearchTableN = 33;
constexpr int kTwistIterations = 6;
constexpr int kJointIterations = 12;
constexpr double kMaxStepRad = 0.2;
constexpr std::size_t kStarts = 4;
// The map keeps bends within the joint's stops (hall_joint.hpp: per hinge and
// between the shafts) plus a margin for play and noise, where the jig has
// been; short of 90 deg, where the 2-D sensor's reading flattens.
constexpr double kBendMarginRad = 0.05;
constexpr double kMaxBendRad = 1.55;

// {1, cos a, sin a, ..., cos Ha, sin Ha} of one angle and its derivative.
constexpr int kHarm = 2 * kBendHarmonics + 1;
struct HarmN {
  std::array<double, kHarm> f, d;
};
HarmN harm(double a) {
  HarmN h;
  h.f[0] = 1.0;
  h.d[0] = 0.0;
  for (int k = 1; k <= kBendHarmonics; ++k) {
    h.f[2 * k - 1] = std::cos(k * a);
    h.f[2 * k] = std::sin(k * a);
    h.d[2 * k - 1] = -k * std::sin(k * a);
    h.d[2 * k] = k * std::cos(k * a);
  }
  return h;
}

// F(bend_x, bend_y): the products, index kHarm i + j; with d/dbx and d/dby.
struct BendBasis {
  std::array<double, kBendBasisSize> f, dx, dy;
};
BendBasis bend_basis(double bx, double by) {
  const HarmN hx = harm(bx), hy = harm(by);
  BendBasis b;
  for (int i = 0; i < kHarm; ++i) {
    for (int j = 0; j < kHarm; ++j) {
      b.f[kHarm * i + j] = hx.f[i] * hy.f[j];
      b.dx[kHarm * i + j] = hx.d[i] * hy.f[j];
      b.dy[kHarm * i + j] = hx.f[i] * hy.d[j];
    }
  }
  return b;
}

// H(t): {1, cos t, sin t, cos 2t, sin 2t, cos 3t, sin 3t} and d/dt.
struct TwistBasis {
  std::array<double, kTwistBasisSize> f, d;
};
TwistBasis twist_basis(double t) {
  TwistBasis b;
  b.f[0] = 1.0;
  b.d[0] = 0.0;
  for (int k = 1; k <= 3; ++k) {
    b.f[2 * k - 1] = std::cos(k * t);
    b.f[2 * k] = std::sin(k * t);
    b.d[2 * k - 1] = -k * std::sin(k * t);
    b.d[2 * k] = k * std::cos(k * t);
  }
  return b;
}

// Rows of the three channel kinds' design matrices.
void bend_row(const BendBasis& bb, const TwistBasis& tout, double* row) {
  for (int k = 0; k < kBendBasisSize; ++k) row[k] = bb.f[k];
  for (int k = 0; k < kTwistCrossBasisSize; ++k) row[kBendBasisSize + k] = tout.f[1 + k];
}
void twist_out_row(const TwistBasis& tout, const BendBasis& bb, double* row) {
  for (int k = 0; k < kTwistBasisSize; ++k) row[k] = tout.f[k];
  for (int k = 1; k < kBendBasisSize; ++k) row[kTwistBasisSize + k - 1] = bb.f[k];
}

double dot(const std::vector<double>& c, const double* row, int n) {
  double s = 0.0;
  for (int k = 0; k < n; ++k) s += c[static_cast<std::size_t>(k)] * row[k];
  return s;
}

// Least squares with columns scaled to unit norm (the basis columns differ in
// scale little, but the rank check wants comparable columns).
Result<std::vector<double>> solve(const Eigen::MatrixXd& A, const Eigen::VectorXd& b, const std::string& channel,
                                  double* rms) {
  Eigen::VectorXd scale = A.colwise().norm().transpose();
  for (Eigen::Index k = 0; k < scale.size(); ++k) {
    if (scale[k] <= 0.0) scale[k] = 1.0;
  }
  const Eigen::MatrixXd As = A * scale.cwiseInverse().asDiagonal();
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(As);
  qr.setThreshold(1e-10);
  if (qr.rank() < A.cols()) {
    return make_error(Errc::invalid_argument,
                      "the jig data cannot pin the " + channel + " channel's model (rank " + std::to_string(qr.rank()) +
                          " of " + std::to_string(A.cols()) +
                          "); the jig must cover the bend range on a grid and turn both rings through full turns");
  }
  const Eigen::VectorXd x = qr.solve(b).cwiseQuotient(scale);
  *rms = std::sqrt((A * x - b).squaredNorm() / static_cast<double>(A.rows()));
  return std::vector<double>(x.data(), x.data() + x.size());
}

double twist_from_first_harmonic(const std::array<std::vector<double>, 2>& ch, const std::array<double, 2>& meas,
                                 double k_offset0, double k_offset1) {
  // meas_i - c0_i = a_i cos t + b_i sin t.
  Eigen::Matrix2d M;
  M << ch[0][1], ch[0][2], ch[1][1], ch[1][2];
  const Eigen::Vector2d rhs(meas[0] - ch[0][0] - k_offset0, meas[1] - ch[1][0] - k_offset1);
  const Eigen::Vector2d cs = M.colPivHouseholderQr().solve(rhs);
  return std::atan2(cs[1], cs[0]);
}

}  // namespace

Result<JointCalibration> JointCalibration::fit(const std::vector<JigSample>& samples, double bend_limit_rad,
                                               std::string joint_id) {
  if (!std::isfinite(bend_limit_rad) || bend_limit_rad <= 0.0 || bend_limit_rad > 1.5) {
    return make_error(Errc::invalid_argument, "calibration bend limit must be in (0, 1.5] rad");
  }
  if (joint_id.empty() || joint_id.size() > 64 ||
      std::any_of(joint_id.begin(), joint_id.end(), [](char ch) { return static_cast<unsigned char>(ch) < 0x20; })) {
    return make_error(Errc::invalid_argument, "the joint id must be 1..64 characters without control characters");
  }
  const auto n = static_cast<Eigen::Index>(samples.size());
  if (n < kTwistOutChannelCoeffs * 2) {
    return make_error(Errc::invalid_argument, "calibration needs at least " + std::to_string(kTwistOutChannelCoeffs * 2) +
                                                  " jig poses; it got " + std::to_string(samples.size()));
  }
  Eigen::MatrixXd A_bend(n, kBendChannelCoeffs), A_tin(n, kTwistInChannelCoeffs), A_tout(n, kTwistOutChannelCoeffs);
  std::array<Eigen::VectorXd, 6> y;
  for (auto& v : y) v.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const JigSample& s = samples[static_cast<std::size_t>(i)];
    const JointAngles& a = s.jig_angles;
    const HallReadings& r = s.readings;
    if (!std::isfinite(a.bend_x_rad + a.bend_y_rad + a.twist_in_rad + a.twist_out_rad) ||
        !std::isfinite(r.bend[0] + r.bend[1] + r.twist_in[0] + r.twist_in[1] + r.twist_out[0] + r.twist_out[1])) {
      return make_error(Errc::invalid_argument, "jig sample " + std::to_string(i) + " holds a non-finite value");
    }
    const BendBasis bb = bend_basis(a.bend_x_rad, a.bend_y_rad);
    const TwistBasis tin = twist_basis(a.twist_in_rad), tout = twist_basis(a.twist_out_rad);
    double row[kTwistOutChannelCoeffs];
    bend_row(bb, tout, row);
    for (int k = 0; k < kBendChannelCoeffs; ++k) A_bend(i, k) = row[k];
    for (int k = 0; k < kTwistInChannelCoeffs; ++k) A_tin(i, k) = tin.f[k];
    twist_out_row(tout, bb, row);
    for (int k = 0; k < kTwistOutChannelCoeffs; ++k) A_tout(i, k) = row[k];
    y[0][i] = r.bend[0];
    y[1][i] = r.bend[1];
    y[2][i] = r.twist_in[0];
    y[3][i] = r.twist_in[1];
    y[4][i] = r.twist_out[0];
    y[5][i] = r.twist_out[1];
  }
  JointCalibration cal;
  cal.joint_id_ = std::move(joint_id);
  cal.bend_limit_rad_ = bend_limit_rad;
  const char* names[6] = {"bend x", "bend y", "twist_in a", "twist_in b", "twist_out a", "twist_out b"};
  for (int c = 0; c < 6; ++c) {
    const Eigen::MatrixXd& A = c < 2 ? A_bend : (c < 4 ? A_tin : A_tout);
    auto x = solve(A, y[static_cast<std::size_t>(c)], names[c], &cal.fit_rms_counts_[static_cast<std::size_t>(c)]);
    if (!x) return x.error();
    (c < 2 ? cal.bend_ : (c < 4 ? cal.twist_in_ : cal.twist_out_))[static_cast<std::size_t>(c % 2)] = std::move(*x);
  }
  cal.build_search_table();
  return cal;
}

void JointCalibration::build_search_table() {
  table_n_ = kSearchTableN;
  table_.assign(static_cast<std::size_t>(table_n_ * table_n_), {0.0, 0.0});
  table_inside_.assign(table_.size(), false);
  const double range = std::min(bend_limit_rad_ + kBendMarginRad, kMaxBendRad);
  for (int i = 0; i < table_n_; ++i) {
    for (int j = 0; j < table_n_; ++j) {
      const double bx = -range + 2 * range * i / (table_n_ - 1), by = -range + 2 * range * j / (table_n_ - 1);
      // Outside the stops the fit is extrapolation and may mimic a reading.
      table_inside_[static_cast<std::size_t>(i * table_n_ + j)] = shaft_angle_rad(bx, by) <= range;
      const BendBasis bb = bend_basis(bx, by);
      for (int c = 0; c < 2; ++c) {
        table_[static_cast<std::size_t>(i * table_n_ + j)][static_cast<std::size_t>(c)] =
            dot(bend_[static_cast<std::size_t>(c)], bb.f.data(), kBendBasisSize);
      }
    }
  }
}

HallReadings JointCalibration::predict(const JointAngles& a) const {
  const BendBasis bb = bend_basis(a.bend_x_rad, a.bend_y_rad);
  const TwistBasis tin = twist_basis(a.twist_in_rad), tout = twist_basis(a.twist_out_rad);
  double brow[kBendChannelCoeffs], trow[kTwistOutChannelCoeffs];
  bend_row(bb, tout, brow);
  twist_out_row(tout, bb, trow);
  HallReadings r;
  for (std::size_t c = 0; c < 2; ++c) {
    r.bend[c] = dot(bend_[c], brow, kBendChannelCoeffs);
    r.twist_in[c] = dot(twist_in_[c], tin.f.data(), kTwistInChannelCoeffs);
    r.twist_out[c] = dot(twist_out_[c], trow, kTwistOutChannelCoeffs);
  }
  return r;
}

JointAngles JointCalibration::angles(const HallReadings& r) const { return solve_angles(r, nullptr); }

JointAngles JointCalibration::angles(const HallReadings& r, const JointAngles& previous) const {
  return solve_angles(r, &previous);
}

JointAngles JointCalibration::solve_angles(const HallReadings& r, const JointAngles* previous) const {
  JointAngles out;
  // Inlet twist: its channels depend on it alone.
  double t = twist_from_first_harmonic(twist_in_, r.twist_in, 0.0, 0.0);
  for (int it = 0; it < kTwistIterations; ++it) {
    const TwistBasis tb = twist_basis(t);
    double jr = 0.0, jj = 0.0;
    for (std::size_t c = 0; c < 2; ++c) {
      const double res = dot(twist_in_[c], tb.f.data(), kTwistBasisSize) - r.twist_in[c];
      const double d = dot(twist_in_[c], tb.d.data(), kTwistBasisSize);
      jr += d * res;
      jj += d * d;
    }
    if (jj <= 0.0) break;
    t -= jr / jj;
  }
  out.twist_in_rad = wrap_angle_rad(t);

  // Bends and outlet twist together. Start: the outlet twist from its first
  // harmonic with K at the straight joint, then the bends from the table with
  // G at that twist taken off.
  const BendBasis b0 = bend_basis(0.0, 0.0);
  double k0[2];
  for (std::size_t c = 0; c < 2; ++c) {
    k0[c] = 0.0;
    for (int k = 1; k < kBendBasisSize; ++k) k0[c] += twist_out_[c][static_cast<std::size_t>(kTwistBasisSize + k - 1)] * b0.f[k];
  }
  double tout = twist_from_first_harmonic(twist_out_, r.twist_out, k0[0], k0[1]);
  const TwistBasis tb0 = twist_basis(tout);
  double target[2];
  for (std::size_t c = 0; c < 2; ++c) {
    double g = 0.0;
    for (int k = 0; k < kTwistCrossBasisSize; ++k) g += bend_[c][static_cast<std::size_t>(kBendBasisSize + k)] * tb0.f[1 + k];
    target[c] = r.bend[c] - g;
  }
  const double range = std::min(bend_limit_rad_ + kBendMarginRad, kMaxBendRad);
  // Several starts: where the 2-D reading is compressed (near the stops) the
  // nearest table entry in counts can lie far off in angle, and a single
  // descent from it can stall on the stop. Keep the best fit of a few.
  std::array<std::size_t, kStarts> starts{};
  std::array<double, kStarts> start_d{};
  start_d.fill(1e300);
  for (std::size_t k = 0; k < table_.size(); ++k) {
    if (!table_inside_[k]) continue;
    const double d = std::pow(table_[k][0] - target[0], 2) + std::pow(table_[k][1] - target[1], 2);
    for (std::size_t s = 0; s < starts.size(); ++s) {
      if (d < start_d[s]) {
        for (std::size_t m = starts.size() - 1; m > s; --m) {
          starts[m] = starts[m - 1];
          start_d[m] = start_d[m - 1];
        }
        starts[s] = k;
        start_d[s] = d;
        break;
      }
    }
  }
  const auto tn = static_cast<std::size_t>(table_n_);
  const double tout0 = tout;
  double best_cost = 1e300, best_bx = 0.0, best_by = 0.0, best_tout = tout0;
  for (std::size_t s = 0; s <= starts.size(); ++s) {
    double bx = 0.0, by = 0.0;
    if (s < starts.size()) {
      if (start_d[s] >= 1e300) continue;
      bx = -range + 2 * range * static_cast<double>(starts[s] / tn) / (table_n_ - 1);
      by = -range + 2 * range * static_cast<double>(starts[s] % tn) / (table_n_ - 1);
      tout = tout0;
    } else {
      // The last report's angles: 20 ms ago the joint was close by.
      if (previous == nullptr || !std::isfinite(previous->bend_x_rad + previous->bend_y_rad + previous->twist_out_rad)) {
        continue;
      }
      bx = previous->bend_x_rad;
      by = previous->bend_y_rad;
      clamp_bends_to_stops(bx, by, range);
      tout = previous->twist_out_rad;
    }
    double cost = 1e300;
    for (int it = 0; it < kJointIterations; ++it) {
      const BendBasis bb = bend_basis(bx, by);
      const TwistBasis tb = twist_basis(tout);
      Eigen::Matrix<double, 4, 3> J;
      Eigen::Vector4d res;
      for (std::size_t c = 0; c < 2; ++c) {
        const auto& B = bend_[c];
        double v = 0, dx = 0, dy = 0, dt = 0;
        for (int k = 0; k < kBendBasisSize; ++k) {
          v += B[static_cast<std::size_t>(k)] * bb.f[k];
          dx += B[static_cast<std::size_t>(k)] * bb.dx[k];
          dy += B[static_cast<std::size_t>(k)] * bb.dy[k];
        }
        for (int k = 0; k < kTwistCrossBasisSize; ++k) {
          v += B[static_cast<std::size_t>(kBendBasisSize + k)] * tb.f[1 + k];
          dt += B[static_cast<std::size_t>(kBendBasisSize + k)] * tb.d[1 + k];
        }
        res[static_cast<Eigen::Index>(c)] = v - r.bend[c];
        J.row(static_cast<Eigen::Index>(c)) << dx, dy, dt;
        const auto& T = twist_out_[c];
        v = dx = dy = dt = 0;
        for (int k = 0; k < kTwistBasisSize; ++k) {
          v += T[static_cast<std::size_t>(k)] * tb.f[k];
          dt += T[static_cast<std::size_t>(k)] * tb.d[k];
        }
        for (int k = 1; k < kBendBasisSize; ++k) {
          v += T[static_cast<std::size_t>(kTwistBasisSize + k - 1)] * bb.f[k];
          dx += T[static_cast<std::size_t>(kTwistBasisSize + k - 1)] * bb.dx[k];
          dy += T[static_cast<std::size_t>(kTwistBasisSize + k - 1)] * bb.dy[k];
        }
        res[static_cast<Eigen::Index>(2 + c)] = v - r.twist_out[c];
        J.row(static_cast<Eigen::Index>(2 + c)) << dx, dy, dt;
      }
      cost = res.squaredNorm();
      const Eigen::Matrix3d JtJ = J.transpose() * J + 1e-9 * Eigen::Matrix3d::Identity();
      const Eigen::Vector3d step = JtJ.ldlt().solve(J.transpose() * res);
      if (!step.allFinite()) break;
      // A trust region keeps a step from leaping to a far basin where the fit
      // extrapolates; the clamp keeps the search where the jig has been.
      const double scale = std::min(1.0, kMaxStepRad / std::max(1e-300, step.cwiseAbs().maxCoeff()));
      bx -= scale * step[0];
      by -= scale * step[1];
      clamp_bends_to_stops(bx, by, range);
      tout -= scale * step[2];
      if (step.norm() < 1e-9) break;
    }
    if (cost < best_cost) {
      best_cost = cost;
      best_bx = bx;
      best_by = by;
      best_tout = tout;
    }
  }
  const double bx = best_bx, by = best_by;
  tout = best_tout;
  out.bend_x_rad = bx;
  out.bend_y_rad = by;
  out.twist_out_rad = wrap_angle_rad(tout);
  return out;
}

std::string JointCalibration::to_toml() const {
  std::ostringstream s;
  s << std::setprecision(17);
  s << "# A rig device joint's Hall-sensor calibration (docs/rig-device.md): the fitted\n"
       "# forward model, counts per basis term (input/rig_device/.../joint_calibration.hpp).\n";
  s << "format = \"" << kFormat << "\"\nversion = " << kVersion << "\njoint = \"";
  for (char ch : joint_id_) {
    if (ch == '"' || ch == '\\') s << '\\';
    s << ch;
  }
  s << "\"\nbend_limit_rad = " << bend_limit_rad_ << "\nfit_rms_counts = [";
  for (std::size_t i = 0; i < 6; ++i) s << (i ? ", " : "") << fit_rms_counts_[i];
  s << "]\n";
  const auto arr = [&](const char* key, const std::vector<double>& v) {
    s << key << " = [";
    for (std::size_t i = 0; i < v.size(); ++i) s << (i ? ", " : "") << v[i];
    s << "]\n";
  };
  s << "\n[bend]\n";
  arr("x", bend_[0]);
  arr("y", bend_[1]);
  s << "\n[twist_in]\n";
  arr("a", twist_in_[0]);
  arr("b", twist_in_[1]);
  s << "\n[twist_out]\n";
  arr("a", twist_out_[0]);
  arr("b", twist_out_[1]);
  return s.str();
}

Result<JointCalibration> JointCalibration::parse_toml(std::string_view text, const std::string& origin) {
  auto c = Config::parse(text, origin);
  if (!c) return c.error();
  constexpr std::string_view kHint = "docs/rig-device.md, 'Joint calibration files'";
  if (auto k = c->check_keys("top level", {"format", "version", "joint", "bend_limit_rad", "fit_rms_counts", "bend",
                                           "twist_in", "twist_out"},
                             kHint);
      !k) {
    return k.error();
  }
  auto format = c->get_string("format");
  if (!format) return format.error();
  if (*format != kFormat) {
    return make_error(Errc::parse_error, c->where("format") + ": format is '" + printable(*format, 60) + "', not '" +
                                             kFormat + "'");
  }
  auto version = c->get_int("version");
  if (!version) return version.error();
  if (*version != kVersion) {
    return make_error(Errc::unsupported, c->where("version") + ": calibration version " + std::to_string(*version) +
                                             " is not supported (this build reads " + std::to_string(kVersion) + ")");
  }
  JointCalibration cal;
  auto id = c->get_string_or("joint", "joint");
  if (!id) return id.error();
  if (id->empty() || id->size() > 64) {
    return make_error(Errc::invalid_argument, c->where("joint") + ": the joint id must be 1..64 characters");
  }
  cal.joint_id_ = *id;
  auto limit = c->get_double("bend_limit_rad");
  if (!limit) return limit.error();
  if (*limit <= 0.0 || *limit > 1.5) {
    return make_error(Errc::invalid_argument, c->where("bend_limit_rad") + ": bend_limit_rad must be in (0, 1.5] rad");
  }
  cal.bend_limit_rad_ = *limit;
  if (c->contains("fit_rms_counts")) {
    auto rms = c->get_doubles("fit_rms_counts");
    if (!rms) return rms.error();
    if (rms->size() != 6) {
      return make_error(Errc::invalid_argument, c->where("fit_rms_counts") + ": needs 6 values, one per channel");
    }
    for (std::size_t i = 0; i < 6; ++i) {
      if ((*rms)[i] < 0.0 || (*rms)[i] > kMaxCoefficient) {
        return make_error(Errc::invalid_argument, c->where("fit_rms_counts") + ": fit_rms_counts values must be in [0, 1e6]");
      }
      cal.fit_rms_counts_[i] = (*rms)[i];
    }
  }
  const auto table_pair = [&](const char* table, const char* k0, const char* k1, std::size_t size,
                              std::array<std::vector<double>, 2>& out) -> Status {
    auto t = c->table(table);
    if (!t) return t.error();
    if (auto k = t->check_keys(table, {k0, k1}, kHint); !k) return k.error();
    const char* keys[2] = {k0, k1};
    for (std::size_t i = 0; i < 2; ++i) {
      auto v = t->get_doubles(keys[i]);
      if (!v) return v.error();
      for (double x : *v) {
        if (std::abs(x) > kMaxCoefficient) {
          return make_error(Errc::invalid_argument, t->where(keys[i]) + ": a coefficient of " + table + "." + keys[i] +
                                                        " exceeds 1e6 counts; the file is not a calibration");
        }
      }
      if (v->size() != size) {
        return make_error(Errc::invalid_argument, t->where(keys[i]) + ": " + table + "." + keys[i] + " needs " +
                                                      std::to_string(size) + " coefficients; it has " +
                                                      std::to_string(v->size()));
      }
      out[i] = std::move(*v);
    }
    return Status::success();
  };
  if (auto st = table_pair("bend", "x", "y", kBendChannelCoeffs, cal.bend_); !st) return st.error();
  if (auto st = table_pair("twist_in", "a", "b", kTwistInChannelCoeffs, cal.twist_in_); !st) return st.error();
  if (auto st = table_pair("twist_out", "a", "b", kTwistOutChannelCoeffs, cal.twist_out_); !st) return st.error();
  cal.build_search_table();
  return cal;
}

Result<JointCalibration> JointCalibration::load(const std::filesystem::path& file) {
  auto text = read_input_file(file, "joint calibration", kMaxCalibrationFileBytes);
  if (!text) return text.error();
  return parse_toml(*text, file.string());
}

}  // namespace proprio::rig_device
