#pragma once
// Body proxies for the elastic-sheet simulator (issue 30): the time-varying
// body surfaces the thesis's datasets were captured on (Glauser 2019, Sec.
// 4.5: a balloon, a flexing biceps, an elbow, a wrist, a twisting forearm).
//
// Frames and coordinates. The body frame is metric, z along the limb axis.
// The skin is parameterised by its rest surface coordinates uv (metres): u is
// arc length around the axis at the rest radius (u = rest_radius * angle,
// angle 0 on +x, counter-clockwise seen from +z), v is along the axis. A skin
// material point keeps its uv for ever; skin_point_m(uv, t) says where it is
// at time t, so the map carries the skin's own motion (bulge, bend, twist,
// inflation) and friction can drag the sheet with it. X_u x X_v points out of
// the body.
//
// Motion. Each body is driven by seeded, smooth, aperiodic signals (sums of
// sines at incommensurate periods of 4-15 s, squashed into range, ramped in
// over the first second so t = 0 is the rest pose, where the sheet is
// donned). pose_value() is the scalar the datasets split on (Table 4.2 uses
// the wrist's angle alpha).
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "proprio/core/result.hpp"

namespace proprio::elastic_sheet {

using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;
using Mat32 = Eigen::Matrix<double, 3, 2>;

enum class BodyKind { balloon, biceps, elbow, wrist, forearm };
const char* to_string(BodyKind kind) noexcept;
Result<BodyKind> parse_body_kind(std::string_view name);
std::vector<BodyKind> all_body_kinds();

struct MotionSignalOptions {
  std::uint64_t seed = 1;
  int components = 4;          // sines summed
  double min_period_s = 4.0;   // human-plausible: elbow peaks at ~200 deg/s, a full swing >= ~1 s
  double max_period_s = 15.0;
  double ramp_s = 1.0;         // from rest at t = 0
  double gain = 1.3;           // squash gain: larger visits the extremes more often
  Status validate() const;
  std::string describe() const;
};

// A smooth aperiodic signal; same seed, same signal.
class MotionSignal {
 public:
  explicit MotionSignal(const MotionSignalOptions& options = {});
  double bipolar(double t_s) const;   // in (-1, 1), 0 at t = 0
  double unipolar(double t_s) const;  // in [0, 1), 0 at t = 0

 private:
  struct Term { double amplitude, omega, phase; };
  std::vector<Term> terms_;
  double norm_ = 1.0, ramp_s_ = 1.0, gain_ = 1.0;
};

struct SurfaceSample {
  Vec3 point_m = Vec3::Zero();
  Vec3 normal = Vec3::UnitZ();  // outward, unit
  Vec2 skin_uv_m = Vec2::Zero();
  double distance_m = 0.0;      // from the queried point
};

class BodyProxy {
 public:
  virtual ~BodyProxy() = default;
  virtual BodyKind kind() const noexcept = 0;

  // Where the skin material point uv is at time t (body frame, metres).
  virtual Vec3 skin_point_m(const Vec2& skin_uv_m, double t_s) const = 0;
  // The same for many points at once (the motion signals evaluated once).
  virtual void skin_points_m(const std::vector<Vec2>& skin_uv_m, double t_s, std::vector<Vec3>& out) const;
  // d skin_point / d uv (forward differences of 1e-7 m: the maps are smooth
  // and a few evaluations per vertex and step are cheap enough).
  Mat32 skin_jacobian(const Vec2& skin_uv_m, double t_s) const;
  Vec3 normal(const Vec2& skin_uv_m, double t_s) const;
  // The closest surface point to p at time t: Gauss-Newton over uv from the
  // hint, or from a coarse search of the body's uv range when none is given.
  SurfaceSample project(const Vec3& p_m, double t_s, const Vec2* hint_uv_m = nullptr) const;

  virtual double rest_radius_m() const noexcept = 0;  // turns an angle around the axis into u
  virtual Vec2 default_site_uv_m() const noexcept = 0;  // where the sheet centre goes by default
  virtual Vec2 uv_min_m() const noexcept = 0;  // the parameterised skin region
  virtual Vec2 uv_max_m() const noexcept = 0;

  // The split value: balloon diameter (mm), biceps bulge height (mm), elbow
  // flexion (deg), wrist alpha = angle between forearm and palm axes (deg,
  // 0 straight), forearm twist at the wrist end (deg).
  virtual double pose_value(double t_s) const = 0;
  virtual const char* pose_name() const noexcept = 0;
  // pose_value and the body's other degrees of freedom, named.
  virtual std::vector<std::pair<std::string, double>> pose_values(double t_s) const;
};

// The proxies, with the thesis's sizes (documented in body_proxy.cpp).
// Each motion signal's seed is derived from `seed`.
std::unique_ptr<BodyProxy> make_body(BodyKind kind, std::uint64_t seed);

}  // namespace proprio::elastic_sheet
