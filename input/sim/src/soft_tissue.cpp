#include "proprio/sim/soft_tissue.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace proprio::sim {

SoftTissueOptions SoftTissueOptions::rigid() {
  SoftTissueOptions o;
  o.sliding = false;
  o.wobble = false;
  o.slip = false;
  return o;
}

Status SoftTissueOptions::validate() const {
  auto bad = [](const char* what, double v, const char* range) {
    char buf[192];
    std::snprintf(buf, sizeof buf, "soft tissue: %s is %g; it must be %s", what, v, range);
    return make_error(Errc::invalid_argument, buf);
  };
  auto in = [](double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; };
  if (!in(sliding_gain, 0.0, 1.0)) return bad("sliding_gain", sliding_gain, "in 0..1");
  if (!in(sliding_decay_m, 1e-4, 0.1)) return bad("sliding_decay_m", sliding_decay_m, "in 0.0001..0.1 m");
  if (!in(wobble_frequency_hz, 1.0, 200.0)) return bad("wobble_frequency_hz", wobble_frequency_hz, "in 1..200 Hz");
  if (!in(wobble_frequency_spread, 0.0, 0.5)) {
    return bad("wobble_frequency_spread", wobble_frequency_spread, "in 0..0.5");
  }
  if (!in(wobble_damping_ratio, 0.01, 2.0)) {
    return bad("wobble_damping_ratio", wobble_damping_ratio, "in 0.01..2");
  }
  // The grid must resolve the fastest spring: at least ~20 steps per period.
  const double fastest_hz = wobble_frequency_hz * (1.0 + wobble_frequency_spread);
  if (!in(wobble_step_s, 1e-5, 0.05) || wobble_step_s * fastest_hz > 0.05) {
    return bad("wobble_step_s", wobble_step_s, "in 1e-5..0.05 s and below 1/20 of the fastest wobble period");
  }
  if (!in(wobble_history_s, 0.1, 60.0)) return bad("wobble_history_s", wobble_history_s, "in 0.1..60 s");
  if (!in(slip_sigma_m, 0.0, 0.02)) return bad("slip_sigma_m", slip_sigma_m, "in 0..0.02 m");
  if (!in(slip_time_constant_s, 1.0, 1e5)) return bad("slip_time_constant_s", slip_time_constant_s, "in 1..1e5 s");
  if (!in(slip_knot_s, 0.01, 60.0)) return bad("slip_knot_s", slip_knot_s, "in 0.01..60 s");
  return {};
}

std::string SoftTissueOptions::describe() const {
  char buf[384];
  std::snprintf(buf, sizeof buf,
                "sliding=%s(gain=%.2f decay=%.1fmm) wobble=%s(%.1fHz+-%.0f%% zeta=%.2f step=%.2fms) "
                "slip=%s(sigma=%.1fmm tau=%.0fs)",
                sliding ? "on" : "off", sliding_gain, sliding_decay_m * 1e3, wobble ? "on" : "off",
                wobble_frequency_hz, wobble_frequency_spread * 100.0, wobble_damping_ratio, wobble_step_s * 1e3,
                slip ? "on" : "off", slip_sigma_m * 1e3, slip_time_constant_s);
  return buf;
}

namespace soft_tissue_detail {

// Where a joint sits in its finger's chain. The OpenXR joint set gives the
// thumb four joints (metacarpal, proximal, distal, tip) and each other finger
// five (metacarpal, proximal, intermediate, distal, tip).
struct ChainPlace {
  int finger = -1;  // -1: palm or wrist
  bool tip = false;
};
constexpr std::size_t kThumbFirst = index_of(HandJoint::thumb_metacarpal);
constexpr std::size_t kIndexFirst = index_of(HandJoint::index_metacarpal);

ChainPlace chain_place(HandJoint j) {
  const std::size_t i = index_of(j);
  if (i < kThumbFirst) return {};
  if (i < kIndexFirst) return {0, j == HandJoint::thumb_tip};
  const std::size_t f = (i - kIndexFirst) / 5;
  return {static_cast<int>(1 + f), (i - kIndexFirst) % 5 == 4};
}

std::size_t first_joint_of(int finger) {
  return finger == 0 ? kThumbFirst : kIndexFirst + 5 * static_cast<std::size_t>(finger - 1);
}

bool is_tip(HandJoint j) { return chain_place(j).tip; }

HandJoint joint_at(std::size_t i) { return static_cast<HandJoint>(i); }

// Flexion of `child` relative to `parent`: the child's bone direction (-Z) in
// the parent frame, as an angle about the parent's x axis, positive toward
// the palm (-Y). Zero for a straight finger (the model's frames are aligned
// along a finger at zero angles), insensitive to abduction about Y.
double flexion_rad(const HandPose& pose, HandJoint parent, HandJoint child) {
  const Vec3 d = pose.joint(parent).q.conjugate() * (pose.joint(child).q * Vec3(0.0, 0.0, -1.0));
  return std::atan2(-d.y(), -d.z());
}

Vec3 mirror_x(const Vec3& v) { return Vec3(-v.x(), v.y(), v.z()); }

// exp([[A, B], [0, 0]] dt) for the spring x'' = -w^2 x - 2 zeta w x' + u:
// the exact zero-order-hold step [x, v]_{k+1} = phi [x, v]_k + gamma u_k.
void spring_step(double omega, double zeta, double dt, Eigen::Matrix2d& phi, Eigen::Vector2d& gamma) {
  Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
  m(0, 1) = 1.0;
  m(1, 0) = -omega * omega;
  m(1, 1) = -2.0 * zeta * omega;
  m(1, 2) = 1.0;
  m *= dt;
  // ||m|| is about 0.1 on a grid that resolves the spring: a short Taylor
  // series after a few squarings is exact to double precision.
  constexpr int kSquarings = 4;
  m /= static_cast<double>(1 << kSquarings);
  Eigen::Matrix3d e = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d term = Eigen::Matrix3d::Identity();
  for (int n = 1; n <= 12; ++n) {
    term = term * m / static_cast<double>(n);
    e += term;
  }
  for (int s = 0; s < kSquarings; ++s) e = e * e;
  phi = e.topLeftCorner<2, 2>();
  gamma = e.topRightCorner<2, 1>();
}

}  // namespace soft_tissue_detail

using namespace soft_tissue_detail;

Result<SoftTissue> SoftTissue::create(SoftTissuePoseFunction poses, std::vector<SkinMount> mounts,
                                      SoftTissueOptions options, std::uint64_t seed) {
  if (auto st = options.validate(); !st) return st.error();
  if (options.wobble && !poses) {
    return make_error(Errc::invalid_argument, "soft tissue: wobble needs the hand's motion; no pose function was given");
  }
  for (const SkinMount& m : mounts) {
    if (is_tip(m.segment) || m.segment == HandJoint::palm) {
      return make_error(Errc::invalid_argument, "soft tissue: a mount is on joint '" +
                                                    std::string(to_string(m.segment)) +
                                                    "', which starts no segment (mounts go on the wrist or a bone)");
    }
    if (!m.p_in_segment.allFinite()) {
      return make_error(Errc::invalid_argument, "soft tissue: a mount's position is not finite");
    }
  }
  return SoftTissue(std::move(poses), std::move(mounts), options, seed);
}

SoftTissue::SoftTissue(SoftTissuePoseFunction poses, std::vector<SkinMount> mounts, SoftTissueOptions options,
                       std::uint64_t seed)
    : poses_(std::move(poses)), mounts_(std::move(mounts)), options_(options), seed_(seed) {
  step_ns_ = std::max<TimeNs>(1, seconds_to_ns(options_.wobble_step_s));
  step_s_ = ns_to_seconds(step_ns_);
  // The joints each mount's skin spans.
  spans_.resize(mounts_.size());
  for (std::size_t i = 0; i < mounts_.size(); ++i) {
    const HandJoint s = mounts_[i].segment;
    const ChainPlace place = chain_place(s);
    auto& spans = spans_[i];
    if (place.finger < 0) {
      // The dorsum: the four MCPs (the model's metacarpals are rigid with the wrist).
      for (int f = 1; f < static_cast<int>(kFingerCount); ++f) {
        const std::size_t meta = first_joint_of(f);
        spans.push_back({joint_at(meta), joint_at(meta + 1), false});
      }
      continue;
    }
    // Proximal joint: MCP, PIP, DIP, thumb MCP and IP (the CMCs are rigid or
    // too oblique at rest for the straight-finger flexion measure).
    const std::size_t first = first_joint_of(place.finger);
    if (index_of(s) > first) spans.push_back({joint_at(index_of(s) - 1), s, true});
    if (!chain_place(joint_at(index_of(s) + 1)).tip) spans.push_back({s, joint_at(index_of(s) + 1), false});
  }
  // One patch (wobble spring, slip walk) per segment with mounts, in order of first use.
  Rng wobble_rng(mix_seed(seed_, 1));
  for (const SkinMount& m : mounts_) {
    if (std::any_of(wobble_segments_.begin(), wobble_segments_.end(),
                    [&](const WobbleSegment& w) { return w.segment == m.segment; })) {
      continue;
    }
    WobbleSegment w;
    w.segment = m.segment;
    Vec3 sum = Vec3::Zero();
    int n = 0;
    for (const SkinMount& o : mounts_) {
      if (o.segment != m.segment) continue;
      sum += o.mirrored ? mirror_x(o.p_in_segment) : o.p_in_segment;
      ++n;
    }
    w.centre_in_segment = sum / n;
    const double f_hz =
        options_.wobble_frequency_hz * (1.0 + options_.wobble_frequency_spread * wobble_rng.uniform(-1.0, 1.0));
    w.omega_radps = 2.0 * M_PI * f_hz;
    spring_step(w.omega_radps, options_.wobble_damping_ratio, step_s_, w.phi, w.gamma);
    wobble_segments_.push_back(w);
  }
  slip_knots_.resize(wobble_segments_.size());
  for (std::size_t w = 0; w < wobble_segments_.size(); ++w) {
    slip_rngs_.emplace_back(mix_seed(mix_seed(seed_, 2), w));
    slip_knots_[w].push_back(Eigen::Vector2d::Zero());  // on at donning: the donning error is glove_as_built's
  }
}

std::size_t SoftTissue::wobble_index(HandJoint segment) const {
  for (std::size_t w = 0; w < wobble_segments_.size(); ++w) {
    if (wobble_segments_[w].segment == segment) return w;
  }
  return wobble_segments_.size();
}

double SoftTissue::wobble_frequency_hz(HandJoint segment) const {
  const std::size_t w = wobble_index(segment);
  return w < wobble_segments_.size() ? wobble_segments_[w].omega_radps / (2.0 * M_PI) : 0.0;
}

Vec3 SoftTissue::sliding(std::size_t mount, const HandPose& pose) const {
  if (!options_.sliding || mount >= mounts_.size()) return Vec3::Zero();
  const SkinMount& m = mounts_[mount];
  const Pose& T_world_seg = pose.joint(m.segment);
  const Vec3 p_world = T_world_seg * (m.mirrored ? mirror_x(m.p_in_segment) : m.p_in_segment);
  Vec3 moved_world = Vec3::Zero();
  for (const SpannedJoint& j : spans_[mount]) {
    const double theta = flexion_rad(pose, j.parent, j.child);
    const Pose& T_side = pose.joint(j.mount_on_child ? j.child : j.parent);
    const Vec3 joint_world = pose.joint(j.child).p;
    const Vec3 r = p_world - joint_world;
    const double height = (T_side.q.conjugate() * r).y();
    // Toward the joint along the bone: distally on the parent, proximally on the child.
    const Vec3 toward = T_side.q * Vec3(0.0, 0.0, j.mount_on_child ? 1.0 : -1.0);
    const double slide =
        options_.sliding_gain * height * theta * std::exp(-r.norm() / options_.sliding_decay_m);
    moved_world += slide * toward;
  }
  return T_world_seg.q.conjugate() * moved_world;
}

Vec3 SoftTissue::specific_force(std::size_t w, const HandPose& before, const HandPose& at,
                                const HandPose& after) const {
  const WobbleSegment& ws = wobble_segments_[w];
  const Vec3 a = (after.joint(ws.segment) * ws.centre_in_segment - 2.0 * (at.joint(ws.segment) * ws.centre_in_segment) +
                  before.joint(ws.segment) * ws.centre_in_segment) /
                 (step_s_ * step_s_);
  const Vec3 g_world(0.0, -9.80665, 0.0);
  return at.joint(ws.segment).q.conjugate() * (a - g_world);
}

void SoftTissue::wobble_restart() {
  history_.clear();
  k0_ = 0;
  pose_newest_ = poses_(0);
  pose_prev_ = poses_(-step_ns_);
  // Start at rest on the spring: sagged by the specific force, not moving.
  const HandPose next = poses_(step_ns_);
  WobbleState s;
  for (std::size_t w = 0; w < wobble_segments_.size(); ++w) {
    const Vec3 f = specific_force(w, pose_prev_, pose_newest_, next);
    const double w2 = wobble_segments_[w].omega_radps * wobble_segments_[w].omega_radps;
    s.x.push_back(-f / w2);
    s.v.push_back(Vec3::Zero());
  }
  history_.push_back(std::move(s));
}

void SoftTissue::wobble_advance() {
  const std::int64_t k = k0_ + static_cast<std::int64_t>(history_.size()) - 1;
  const HandPose next = poses_((k + 1) * step_ns_);
  const WobbleState& cur = history_.back();
  WobbleState s;
  s.x.resize(wobble_segments_.size());
  s.v.resize(wobble_segments_.size());
  for (std::size_t w = 0; w < wobble_segments_.size(); ++w) {
    const WobbleSegment& ws = wobble_segments_[w];
    const Vec3 u = -specific_force(w, pose_prev_, pose_newest_, next);
    for (int a = 0; a < 3; ++a) {
      const Eigen::Vector2d z = ws.phi * Eigen::Vector2d(cur.x[w][a], cur.v[w][a]) + ws.gamma * u[a];
      s.x[w][a] = z[0];
      s.v[w][a] = z[1];
    }
  }
  history_.push_back(std::move(s));
  pose_prev_ = std::move(pose_newest_);
  pose_newest_ = next;
  const auto keep = static_cast<std::size_t>(std::ceil(options_.wobble_history_s / step_s_)) + 2;
  while (history_.size() > keep) {
    history_.pop_front();
    ++k0_;
  }
}

Vec3 SoftTissue::wobble(HandJoint segment, TimeNs t) {
  const std::size_t w = wobble_index(segment);
  if (!options_.wobble || w >= wobble_segments_.size()) return Vec3::Zero();
  t = std::max<TimeNs>(t, 0);
  const std::int64_t k = t / step_ns_;
  if (history_.empty() || k < k0_) wobble_restart();
  while (k0_ + static_cast<std::int64_t>(history_.size()) - 1 < k + 1) wobble_advance();
  const WobbleState& a = history_[static_cast<std::size_t>(k - k0_)];
  const WobbleState& b = history_[static_cast<std::size_t>(k - k0_ + 1)];
  // Cubic Hermite on [x, v] at the two grid points.
  const double s = static_cast<double>(t - k * step_ns_) / static_cast<double>(step_ns_);
  const double h00 = (1.0 + 2.0 * s) * (1.0 - s) * (1.0 - s);
  const double h10 = s * (1.0 - s) * (1.0 - s);
  const double h01 = s * s * (3.0 - 2.0 * s);
  const double h11 = s * s * (s - 1.0);
  return h00 * a.x[w] + h10 * step_s_ * a.v[w] + h01 * b.x[w] + h11 * step_s_ * b.v[w];
}

void SoftTissue::slip_extend(std::size_t w, std::size_t knots) const {
  auto& k = slip_knots_[w];
  const double a = std::exp(-options_.slip_knot_s / options_.slip_time_constant_s);
  const double sd = options_.slip_sigma_m * std::sqrt(1.0 - a * a);
  while (k.size() < knots) {
    const double n0 = slip_rngs_[w].normal();
    const double n1 = slip_rngs_[w].normal();
    k.push_back(a * k.back() + sd * Eigen::Vector2d(n0, n1));
  }
}

Vec3 SoftTissue::slip(HandJoint segment, TimeNs t) const {
  const std::size_t w = wobble_index(segment);
  if (!options_.slip || w >= wobble_segments_.size()) return Vec3::Zero();
  const double u = std::max(0.0, ns_to_seconds(t)) / options_.slip_knot_s;
  const auto j = static_cast<std::size_t>(std::floor(u));
  slip_extend(w, j + 3);
  const auto& k = slip_knots_[w];
  const Eigen::Vector2d p0 = k[j == 0 ? 0 : j - 1], p1 = k[j], p2 = k[j + 1], p3 = k[j + 2];
  const double s = u - static_cast<double>(j);
  // Catmull-Rom: smooth, so an accelerometer on the mount feels no kinks.
  const Eigen::Vector2d c = 0.5 * ((2.0 * p1) + (-p0 + p2) * s + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * s * s +
                                   (-p0 + 3.0 * p1 - 3.0 * p2 + p3) * s * s * s);
  // Along the bone is -Z (toward the fingertips), sideways is X.
  return Vec3(c[1], 0.0, -c[0]);
}

Vec3 SoftTissue::offset(std::size_t mount, const HandPose& pose, TimeNs t) {
  if (mount >= mounts_.size()) return Vec3::Zero();
  const SkinMount& m = mounts_[mount];
  const Vec3 d = sliding(mount, pose) + wobble(m.segment, t) + slip(m.segment, t);
  return m.mirrored ? mirror_x(d) : d;
}

void SoftTissue::offsets(const HandPose& pose, TimeNs t, std::vector<Vec3>& out) {
  out.resize(mounts_.size());
  for (std::size_t i = 0; i < mounts_.size(); ++i) out[i] = offset(i, pose, t);
}

}  // namespace proprio::sim
