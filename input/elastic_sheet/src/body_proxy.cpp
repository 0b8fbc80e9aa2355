// The body proxies (see body_proxy.hpp). Sizes follow the thesis where it
// gives them (Sec. 4.5: a balloon up to ~120 mm across, a biceps of ~36 cm
// circumference) and adult anthropometry elsewhere.
#include "proprio/elastic_sheet/body_proxy.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include <Eigen/Geometry>
#include <Eigen/LU>

namespace proprio::elastic_sheet {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

// splitmix64: a portable, seeded stream (std distributions differ between
// standard libraries, and datasets must be reproducible).
struct BodyRng {
  std::uint64_t state;
  std::uint64_t next() {
    std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double uniform(double lo, double hi) { return lo + (hi - lo) * (static_cast<double>(next() >> 11) * 0x1.0p-53); }
};

double body_smoothstep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

MotionSignal body_signal(std::uint64_t seed, std::uint64_t channel) {
  MotionSignalOptions o;
  o.seed = seed * 0x100000001B3ull + channel * 0x9E3779B97F4A7C15ull + 17;
  return MotionSignal(o);
}

double wrap_angle(double a) { return std::remainder(a, 2.0 * kPi); }

// The ellipse angle at arc length u from +x (first order in the eccentricity
// e = (rx - ry) / (rx + ry): ds/dphi = rbar (1 - e cos 2 phi)), so u stays
// arc length on the elliptic limbs to O(e^2) (~1 % for e = 0.1) and the
// donned sheet is not stretched by the parameterisation itself.
double ellipse_angle(double u, double mean_radius, double rx, double ry) {
  const double sigma = u / mean_radius, e = (rx - ry) / (rx + ry);
  return sigma + 0.5 * e * std::sin(2.0 * sigma);
}

// A tube with an elliptic section, its centreline straight along z for
// v < -L, a circular arc of total angle `bend` towards direction `dir`
// (unit, in the xy plane) over v in [-L, L], straight again beyond. The
// section turns with the centreline, so the outer side of the bend stretches
// by (1 + kappa r) and the inner side shortens, as skin over a joint does.
Vec3 bent_tube_point(double phi, double v, double rx, double ry, double half_length, double bend, const Vec2& dir) {
  const Vec3 local(rx * std::cos(phi), ry * std::sin(phi), 0.0);
  if (v <= -half_length || std::abs(bend) < 1e-12) return local + Vec3(0, 0, v);
  const Vec3 d(dir.x(), dir.y(), 0.0);
  const double kappa = bend / (2.0 * half_length);
  const double s = std::min(v, half_length) + half_length;
  const double psi = kappa * s;
  const Vec3 axis = Vec3::UnitZ().cross(d);
  const Eigen::Matrix3d rot = Eigen::AngleAxisd(psi, axis).toRotationMatrix();
  Vec3 c = Vec3(0, 0, -half_length) + (std::sin(psi) / kappa) * Vec3::UnitZ() + ((1.0 - std::cos(psi)) / kappa) * d;
  if (v > half_length) c += (v - half_length) * (rot * Vec3::UnitZ());
  return c + rot * local;
}

// Each proxy evaluates its time-dependent state (the motion signals) once per
// call and then the map per point, so a batch costs one set of signals.
#define PROPRIO_ELASTIC_SHEET_BATCH_EVAL                                                        \
  Vec3 skin_point_m(const Vec2& uv, double t) const override { return eval(state_at(t), uv); } \
  void skin_points_m(const std::vector<Vec2>& uv, double t, std::vector<Vec3>& out) const override { \
    const State st = state_at(t);                                                               \
    out.resize(uv.size());                                                                      \
    for (std::size_t i = 0; i < uv.size(); ++i) out[i] = eval(st, uv[i]);                       \
  }

// --- balloon: a prolate spheroid (polar semi-axis twice the equatorial),
// equatorial diameter 90 mm at rest to 120 mm; the rubber stretches uniformly,
// so a skin point keeps its angles.
class BalloonProxy final : public BodyProxy {
 public:
  explicit BalloonProxy(std::uint64_t seed) : inflation_(body_signal(seed, 1)) {}
  BodyKind kind() const noexcept override { return BodyKind::balloon; }
  double radius(double t) const { return kA0 * (1.0 + (kMaxDiameter / kRestDiameter - 1.0) * inflation_.unipolar(t)); }
  struct State { double a; };
  State state_at(double t) const { return {radius(t)}; }
  Vec3 eval(const State& st, const Vec2& uv) const {
    const double a = st.a, c = kAspect * a;
    const double phi = uv.x() / kA0, theta = uv.y() / (kAspect * kA0);
    return {a * std::cos(theta) * std::cos(phi), a * std::cos(theta) * std::sin(phi), c * std::sin(theta)};
  }
  PROPRIO_ELASTIC_SHEET_BATCH_EVAL
  double rest_radius_m() const noexcept override { return kA0; }
  Vec2 default_site_uv_m() const noexcept override { return {0.0, 0.0}; }
  Vec2 uv_min_m() const noexcept override { return {-kPi * kA0, -0.45 * kPi * kAspect * kA0}; }
  Vec2 uv_max_m() const noexcept override { return {kPi * kA0, 0.45 * kPi * kAspect * kA0}; }
  double pose_value(double t) const override { return 2.0 * radius(t) * 1e3; }
  const char* pose_name() const noexcept override { return "balloon_diameter_mm"; }

 private:
  static constexpr double kRestDiameter = 0.090, kMaxDiameter = 0.120, kA0 = kRestDiameter / 2.0, kAspect = 2.0;
  MotionSignal inflation_;
};

// --- biceps: a cylinder of 36 cm circumference; flexing raises a Gaussian
// bulge on the front (+y) up to 15 mm that slides 30 mm towards the shoulder
// (-z) as it grows. Skin points keep their angle and height; the bulge
// stretches the skin over it.
class BicepsProxy final : public BodyProxy {
 public:
  explicit BicepsProxy(std::uint64_t seed) : flex_(body_signal(seed, 2)) {}
  BodyKind kind() const noexcept override { return BodyKind::biceps; }
  double bulge_m(double t) const { return kMaxBulge * flex_.unipolar(t); }
  double bulge_centre_m(double t) const { return 0.01 - 0.03 * flex_.unipolar(t); }
  struct State { double bulge, centre; };
  State state_at(double t) const { return {bulge_m(t), bulge_centre_m(t)}; }
  Vec3 eval(const State& st, const Vec2& uv) const {
    const double phi = uv.x() / kR0, v = uv.y();
    const double dv = v - st.centre, dphi = wrap_angle(phi - kPi / 2.0);
    const double r = kR0 + st.bulge * std::exp(-dv * dv / (2.0 * kSigmaV * kSigmaV)) *
                               std::exp(-dphi * dphi / (2.0 * kSigmaPhi * kSigmaPhi));
    return {r * std::cos(phi), r * std::sin(phi), v};
  }
  PROPRIO_ELASTIC_SHEET_BATCH_EVAL
  double rest_radius_m() const noexcept override { return kR0; }
  Vec2 default_site_uv_m() const noexcept override { return {kR0 * kPi / 2.0, 0.0}; }
  Vec2 uv_min_m() const noexcept override { return {-kPi * kR0, -0.2}; }
  Vec2 uv_max_m() const noexcept override { return {kPi * kR0, 0.2}; }
  double pose_value(double t) const override { return bulge_m(t) * 1e3; }
  const char* pose_name() const noexcept override { return "biceps_bulge_mm"; }
  std::vector<std::pair<std::string, double>> pose_values(double t) const override {
    return {{pose_name(), pose_value(t)}, {"biceps_bulge_centre_mm", bulge_centre_m(t) * 1e3}};
  }

 private:
  static constexpr double kR0 = 0.36 / (2.0 * kPi), kMaxBulge = 0.015, kSigmaV = 0.045, kSigmaPhi = 0.7;
  MotionSignal flex_;
};

// --- elbow: upper arm (z < 0) and forearm (z > 0), 40 mm radius tapering
// by 8 % either way along the limb, joined by a 180 mm long bend of 0-130 deg towards
// +y; the sheet sits on the back (-y), over the olecranon, where the skin
// stretches up to ~1.5x along the arm at full flexion.
class ElbowProxy final : public BodyProxy {
 public:
  explicit ElbowProxy(std::uint64_t seed) : flex_(body_signal(seed, 3)) {}
  BodyKind kind() const noexcept override { return BodyKind::elbow; }
  double angle_rad(double t) const { return kMaxAngle * flex_.unipolar(t); }
  struct State { double angle; };
  State state_at(double t) const { return {angle_rad(t)}; }
  Vec3 eval(const State& st, const Vec2& uv) const {
    const double r = kR0 * (1.0 - 0.08 * std::clamp(uv.y() / 0.15, -1.0, 1.0));
    return bent_tube_point(uv.x() / kR0, uv.y(), r, r, kHalfBend, st.angle, Vec2(0.0, 1.0));
  }
  PROPRIO_ELASTIC_SHEET_BATCH_EVAL
  double rest_radius_m() const noexcept override { return kR0; }
  Vec2 default_site_uv_m() const noexcept override { return {-kR0 * kPi / 2.0, 0.0}; }
  Vec2 uv_min_m() const noexcept override { return {-kPi * kR0, -0.22}; }
  Vec2 uv_max_m() const noexcept override { return {kPi * kR0, 0.22}; }
  double pose_value(double t) const override { return angle_rad(t) / kDeg; }
  const char* pose_name() const noexcept override { return "elbow_angle_deg"; }

 private:
  static constexpr double kR0 = 0.040, kHalfBend = 0.090, kMaxAngle = 130.0 * kDeg;
  MotionSignal flex_;
};

// --- wrist: forearm (elliptic, 60 x 40 mm at the wrist) and hand (80 x 28 mm
// palm, wider and thicker when the fingers splay: the palm's volume change),
// blended over the first 50 mm past the joint; a 50 mm bend of flexion /
// extension +-60 deg (towards +y = palmar) and deviation (20 deg radial,
// 30 deg ulnar, about the other axis). The sheet sits dorsally (-y).
class WristProxy final : public BodyProxy {
 public:
  explicit WristProxy(std::uint64_t seed)
      : flexion_(body_signal(seed, 4)), deviation_(body_signal(seed, 5)), splay_(body_signal(seed, 6)) {}
  BodyKind kind() const noexcept override { return BodyKind::wrist; }
  double flexion_rad(double t) const { return 60.0 * kDeg * flexion_.bipolar(t); }
  double deviation_rad(double t) const {
    const double b = deviation_.bipolar(t);
    return (b > 0.0 ? 30.0 : 20.0) * kDeg * b;
  }
  struct State { double splay, bend; Vec2 dir; };
  State state_at(double t) const {
    const double fe = flexion_rad(t), dev = deviation_rad(t);
    const double bend = std::hypot(fe, dev);
    return {splay_.unipolar(t), bend, bend > 1e-12 ? Vec2(dev / bend, fe / bend) : Vec2(0.0, 1.0)};
  }
  Vec3 eval(const State& st, const Vec2& uv) const {
    const double w = body_smoothstep(uv.y() / 0.05);
    const double rx = (1.0 - w) * 0.030 + w * 0.040 * (1.0 + 0.08 * st.splay);
    const double ry = (1.0 - w) * 0.020 + w * 0.014 * (1.0 + 0.15 * st.splay);
    return bent_tube_point(ellipse_angle(uv.x(), kR0, 0.030, 0.020), uv.y(), rx, ry, kHalfBend, st.bend, st.dir);
  }
  PROPRIO_ELASTIC_SHEET_BATCH_EVAL
  double rest_radius_m() const noexcept override { return kR0; }
  Vec2 default_site_uv_m() const noexcept override { return {-kR0 * kPi / 2.0, 0.0}; }
  Vec2 uv_min_m() const noexcept override { return {-kPi * kR0, -0.15}; }
  Vec2 uv_max_m() const noexcept override { return {kPi * kR0, 0.15}; }
  // alpha as the thesis's Table 4.2 uses it: the angle between the arm's and
  // the palm's axes (0 with the wrist straight).
  double pose_value(double t) const override { return std::hypot(flexion_rad(t), deviation_rad(t)) / kDeg; }
  const char* pose_name() const noexcept override { return "wrist_alpha_deg"; }
  std::vector<std::pair<std::string, double>> pose_values(double t) const override {
    return {{pose_name(), pose_value(t)},
            {"wrist_flexion_deg", flexion_rad(t) / kDeg},
            {"wrist_deviation_deg", deviation_rad(t) / kDeg},
            {"finger_splay", splay_.unipolar(t)}};
  }

 private:
  static constexpr double kR0 = 0.025, kHalfBend = 0.025;  // mean radius at the wrist
  MotionSignal flexion_, deviation_, splay_;
};

// --- forearm: elliptic (84 x 68 mm at the elbow end, tapering linearly by
// 25 % to the wrist end), pronation/supination of up to +-80 deg at the wrist end
// (z = +0.12 m), the twist falling linearly to 0 at the elbow end (z = -0.12),
// and the section flattening (pronation) or rounding (supination) by up to 8 %
// with it.
class ForearmProxy final : public BodyProxy {
 public:
  explicit ForearmProxy(std::uint64_t seed) : twist_(body_signal(seed, 7)) {}
  BodyKind kind() const noexcept override { return BodyKind::forearm; }
  double twist_rad(double t) const { return 80.0 * kDeg * twist_.bipolar(t); }
  struct State { double twist; };
  State state_at(double t) const { return {twist_rad(t)}; }
  Vec3 eval(const State& st, const Vec2& uv) const {
    const double v = uv.y(), phi = ellipse_angle(uv.x(), kR0, 0.042, 0.034);
    const double along = std::clamp((v + 0.12) / 0.24, 0.0, 1.0);
    const double taper = 1.0 - 0.25 * std::clamp((v + 0.12) / 0.24, -0.5, 1.5);
    const double omega = st.twist * along;
    // Pronation crosses the radius over the ulna and flattens the section
    // towards the wrist (and supination rounds it): without this a pure twist
    // would preserve every area and an area sensor could not see it.
    const double flatten = 0.08 * (st.twist / (80.0 * kDeg)) * along;
    const double lx = 0.042 * taper * (1.0 + flatten) * std::cos(phi);
    const double ly = 0.034 * taper * (1.0 - flatten) * std::sin(phi);
    const double c = std::cos(omega), s = std::sin(omega);
    return {c * lx - s * ly, s * lx + c * ly, v};
  }
  PROPRIO_ELASTIC_SHEET_BATCH_EVAL
  double rest_radius_m() const noexcept override { return kR0; }
  Vec2 default_site_uv_m() const noexcept override { return {-kR0 * kPi / 2.0, 0.0}; }
  Vec2 uv_min_m() const noexcept override { return {-kPi * kR0, -0.2}; }
  Vec2 uv_max_m() const noexcept override { return {kPi * kR0, 0.2}; }
  double pose_value(double t) const override { return twist_rad(t) / kDeg; }
  const char* pose_name() const noexcept override { return "forearm_twist_deg"; }

 private:
  static constexpr double kR0 = 0.0333;  // mean radius (rx + ry) / 2 at mid-forearm (taper 0.875)
  MotionSignal twist_;
};

}  // namespace

const char* to_string(BodyKind kind) noexcept {
  switch (kind) {
    case BodyKind::balloon: return "balloon";
    case BodyKind::biceps: return "biceps";
    case BodyKind::elbow: return "elbow";
    case BodyKind::wrist: return "wrist";
    case BodyKind::forearm: return "forearm";
  }
  return "?";
}

std::vector<BodyKind> all_body_kinds() {
  return {BodyKind::balloon, BodyKind::biceps, BodyKind::elbow, BodyKind::wrist, BodyKind::forearm};
}

Result<BodyKind> parse_body_kind(std::string_view name) {
  for (BodyKind k : all_body_kinds()) {
    if (name == to_string(k)) return k;
  }
  return make_error(Errc::invalid_argument,
                    "unknown body '" + std::string(name) + "'; use balloon, biceps, elbow, wrist or forearm");
}

Status MotionSignalOptions::validate() const {
  if (components < 1 || components > 16) {
    return make_error(Errc::invalid_argument, "motion signal components must be 1-16");
  }
  if (!(min_period_s > 0.0) || !(max_period_s >= min_period_s)) {
    return make_error(Errc::invalid_argument, "motion signal periods: need 0 < min_period_s <= max_period_s");
  }
  if (!(ramp_s >= 0.0) || !(gain > 0.0)) {
    return make_error(Errc::invalid_argument, "motion signal: ramp_s must be >= 0 and gain > 0");
  }
  return Status::success();
}

std::string MotionSignalOptions::describe() const {
  std::ostringstream s;
  s << "motion signal seed " << seed << ", " << components << " sines of " << min_period_s << "-" << max_period_s
    << " s, ramp " << ramp_s << " s, gain " << gain;
  return s.str();
}

MotionSignal::MotionSignal(const MotionSignalOptions& o) : ramp_s_(o.ramp_s), gain_(o.gain) {
  BodyRng rng{o.seed};
  double sum_sq = 0.0;
  const int n = std::clamp(o.components, 1, 16);
  for (int k = 0; k < n; ++k) {
    // Log-uniform periods: incommensurate with probability one, so the sum
    // never repeats.
    const double period = std::exp(rng.uniform(std::log(o.min_period_s), std::log(std::max(o.min_period_s, o.max_period_s))));
    Term t{rng.uniform(0.5, 1.0), 2.0 * kPi / period, rng.uniform(0.0, 2.0 * kPi)};
    sum_sq += t.amplitude * t.amplitude;
    terms_.push_back(t);
  }
  norm_ = std::sqrt(sum_sq / 2.0);  // unit RMS before squashing
}

double MotionSignal::bipolar(double t) const {
  double z = 0.0;
  for (const auto& term : terms_) z += term.amplitude * std::sin(term.omega * t + term.phase);
  const double ramp = ramp_s_ > 0.0 ? body_smoothstep(t / ramp_s_) : (t >= 0.0 ? 1.0 : 0.0);
  return ramp * std::tanh(gain_ * z / norm_);
}

double MotionSignal::unipolar(double t) const {
  double z = 0.0;
  for (const auto& term : terms_) z += term.amplitude * std::sin(term.omega * t + term.phase);
  const double ramp = ramp_s_ > 0.0 ? body_smoothstep(t / ramp_s_) : (t >= 0.0 ? 1.0 : 0.0);
  return ramp * 0.5 * (1.0 + std::tanh(gain_ * z / norm_));
}

Mat32 BodyProxy::skin_jacobian(const Vec2& uv, double t) const {
  constexpr double h = 1e-7;
  const Vec3 x = skin_point_m(uv, t);
  Mat32 j;
  j.col(0) = (skin_point_m(uv + Vec2(h, 0.0), t) - x) / h;
  j.col(1) = (skin_point_m(uv + Vec2(0.0, h), t) - x) / h;
  return j;
}

Vec3 BodyProxy::normal(const Vec2& uv, double t) const {
  const Mat32 j = skin_jacobian(uv, t);
  return j.col(0).cross(j.col(1)).normalized();
}

SurfaceSample BodyProxy::project(const Vec3& p, double t, const Vec2* hint) const {
  Vec2 uv;
  if (hint) {
    uv = *hint;
  } else {
    const Vec2 lo = uv_min_m(), hi = uv_max_m();
    double best = std::numeric_limits<double>::infinity();
    constexpr int kU = 64, kV = 48;
    for (int i = 0; i < kU; ++i) {
      for (int k = 0; k <= kV; ++k) {
        const Vec2 c(lo.x() + (hi.x() - lo.x()) * i / kU, lo.y() + (hi.y() - lo.y()) * k / kV);
        const double d = (skin_point_m(c, t) - p).squaredNorm();
        if (d < best) {
          best = d;
          uv = c;
        }
      }
    }
  }
  // Gauss-Newton on |X(uv) - p|^2, with a step cap for safety far from the
  // surface; converges quadratically near a foot point.
  for (int it = 0; it < 50; ++it) {
    const Mat32 j = skin_jacobian(uv, t);
    const Vec3 r = p - skin_point_m(uv, t);
    Vec2 step = (j.transpose() * j).ldlt().solve(j.transpose() * r);
    const double n = step.norm();
    if (n > 0.01) step *= 0.01 / n;
    uv += step;
    if (n < 1e-12) break;
  }
  SurfaceSample s;
  s.skin_uv_m = uv;
  s.point_m = skin_point_m(uv, t);
  s.normal = normal(uv, t);
  s.distance_m = (p - s.point_m).norm();
  return s;
}

void BodyProxy::skin_points_m(const std::vector<Vec2>& uv, double t, std::vector<Vec3>& out) const {
  out.resize(uv.size());
  for (std::size_t i = 0; i < uv.size(); ++i) out[i] = skin_point_m(uv[i], t);
}

std::vector<std::pair<std::string, double>> BodyProxy::pose_values(double t) const {
  return {{pose_name(), pose_value(t)}};
}

std::unique_ptr<BodyProxy> make_body(BodyKind kind, std::uint64_t seed) {
  switch (kind) {
    case BodyKind::balloon: return std::make_unique<BalloonProxy>(seed);
    case BodyKind::biceps: return std::make_unique<BicepsProxy>(seed);
    case BodyKind::elbow: return std::make_unique<ElbowProxy>(seed);
    case BodyKind::wrist: return std::make_unique<WristProxy>(seed);
    case BodyKind::forearm: return std::make_unique<ForearmProxy>(seed);
  }
  return nullptr;
}

}  // namespace proprio::elastic_sheet
