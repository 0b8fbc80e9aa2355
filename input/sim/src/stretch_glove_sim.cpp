#include "proprio/sim/stretch_glove_sim.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <utility>

namespace proprio::sim {

namespace {

// Sub-streams of the seeds: one per random effect, so that turning one off
// (or changing its size) does not shift another's draws.
enum Stream : std::uint64_t {
  kFabricationStream = 0,  // of glove_seed
  kDonningStream = 1,      // of seed, then of the donning index
  kNoiseStream = 2,
  kOutlierStream = 3,
  kDriftStream = 4,
  kExplorationStream = 5,
  kTaskMotionStream = 6,
  kWristStream = 7,
  kCreepStream = 8,
};

// The pose features the cell models are linear in, per DoF d:
//   kElong + d: flexion DoFs: skin elongation per unit skin offset, an angle
//               with the cam (theta (1 + cam theta)) and the fold under
//               hyperextension; abduction DoFs: |theta| (smoothed).
//   kVol + d:   flexion DoFs: theta+ (1 + theta+ / 2), the volume growth that
//               accelerates as a joint closes; abduction DoFs: theta, signed.
//   kWrist:     wrist flexion, as kElong (cam, fold);
//   kWrist + 1: wrist deviation, signed; kWrist + 2: |deviation| (smoothed).
//   kWeb + w:   strain of web w, from forward kinematics.
constexpr std::size_t kElong = 0;
constexpr std::size_t kVol = kHandDofCount;
constexpr std::size_t kWrist = 2 * kHandDofCount;
constexpr std::size_t kWeb = kWrist + 3;

double truncated_normal(Rng& rng, double bound) {
  for (;;) {
    const double z = rng.normal();
    if (std::abs(z) <= bound) return z;
  }
}

double laplace_cdf(double x, double scale) {
  return x < 0.0 ? 0.5 * std::exp(x / scale) : 1.0 - 0.5 * std::exp(-x / scale);
}

// Mean over [lo, hi] of a Laplace density of this scale centred at 0: the
// share of a joint's elongation, per metre, that lands on that stretch of glove.
double laplace_mean_density(double lo, double hi, double scale) {
  return (laplace_cdf(hi, scale) - laplace_cdf(lo, scale)) / (hi - lo);
}

// Silicone under compression buckles instead of shrinking: a stretch ratio
// below 1 reads as about 1, smoothly (softplus of width `softness`).
double soft_floor_at_one(double stretch, double softness) {
  const double x = (stretch - 1.0) / softness;
  if (x > 30.0) return stretch;  // exp(-30) is below double precision here
  return 1.0 + softness * std::log1p(std::exp(x));
}

// Index of a joint in its finger's chain (finger_joints order).
struct ChainPos {
  Finger finger = Finger::thumb;
  std::size_t bone = 0;
};

std::optional<ChainPos> chain_pos(HandJoint j) {
  for (std::size_t f = 0; f < kFingerCount; ++f) {
    const FingerJoints fj = finger_joints(static_cast<Finger>(f));
    for (std::size_t k = 0; k + 1 < fj.count; ++k) {
      if (fj.joints[k] == j) return ChainPos{static_cast<Finger>(f), k};
    }
  }
  return std::nullopt;
}

// A finger's dorsal skin line, arc length s in metres. Fingers: s = 0 at the
// MCP, the metacarpal is s < 0 (rigid with the dorsum). Thumb: s = 0 at the
// CMC, the base of its metacarpal.
struct Chain {
  std::array<double, 4> bone_start{};
  std::array<double, 4> bone_length{};
  std::array<double, 3> joint_s{};        // the three flexion joints, base to tip
  std::array<std::size_t, 3> flex_dof{};  // their DoFs
  std::array<double, 3> skin_offset{};    // h: skin distance from each joint's axis
  std::array<double, 3> volume_gain{};
  std::size_t abduction_dof = 0;
  double length = 0.0;       // s of the fingertip
  double bulge_end = 0.0;    // the muscle-bulge region is [0, bulge_end]
};

Chain make_chain(const HandShape& shape, Finger f, const StretchSkinModel& sk) {
  const auto& g = shape.fingers[static_cast<std::size_t>(f)];
  Chain c;
  const std::size_t d0 = first_dof_of(f);
  c.flex_dof = {d0, d0 + 2, d0 + 3};
  c.abduction_dof = d0 + 1;
  c.volume_gain = {sk.volume_mcp, sk.volume_pip, sk.volume_dip};
  for (std::size_t b = 0; b < 4; ++b) c.bone_length[b] = g.bone_length_m[b];
  if (f == Finger::thumb) {
    // Bones: metacarpal, proximal, distal; joints CMC, MCP, IP.
    c.bone_start = {0.0, g.bone_length_m[0], g.bone_length_m[0] + g.bone_length_m[1], 0.0};
    c.joint_s = {0.0, c.bone_start[1], c.bone_start[2]};
    c.skin_offset = {g.joint_radius_m[0], g.joint_radius_m[1], g.joint_radius_m[2]};
    c.length = c.bone_start[2] + g.bone_length_m[2];
    c.bulge_end = g.bone_length_m[0];  // the thenar eminence along the metacarpal
  } else {
    // Bones: metacarpal, proximal, intermediate, distal; joints MCP, PIP, DIP.
    const double p = g.bone_length_m[1], i = g.bone_length_m[2];
    c.bone_start = {-g.bone_length_m[0], 0.0, p, p + i};
    c.joint_s = {0.0, p, p + i};
    c.skin_offset = {g.joint_radius_m[1], g.joint_radius_m[2], g.joint_radius_m[3]};
    c.length = p + i + g.bone_length_m[3];
    c.bulge_end = p;  // intrinsic muscle tendons over the proximal phalanx
  }
  return c;
}

Error bad_option(const char* field, double value, const char* what) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "stretch-glove simulator option %s = %g is not usable: %s", field, value, what);
  return make_error(Errc::invalid_argument, buf);
}

HandAngles degrees(std::initializer_list<double> deg) {
  HandAngles a{};
  std::size_t i = 0;
  for (double d : deg) a[i++] = deg_to_rad(d);
  return a;
}

}  // namespace

// --- options -------------------------------------------------------------------

StretchGloveSimOptions StretchGloveSimOptions::ideal() {
  StretchGloveSimOptions o;
  o.enable_noise = false;
  o.enable_outliers = false;
  o.enable_drift = false;
  o.enable_fabrication_spread = false;
  o.enable_donning_variation = false;
  o.enable_saturation = false;
  return o;
}

Status StretchGloveSimOptions::validate() const {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  auto nonnegative = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (!positive(measurement_rate_hz) || measurement_rate_hz > 1e6) {
    return bad_option("measurement_rate_hz", measurement_rate_hz, "must be a rate above 0 and at most 1 MHz");
  }
  if (!positive(full_scale_pf)) return bad_option("full_scale_pf", full_scale_pf, "must be above 0 pF");
  if (!nonnegative(noise_pf)) return bad_option("noise_pf", noise_pf, "must be 0 or more pF");
  if (!nonnegative(noise_relative) || noise_relative > 0.5) {
    return bad_option("noise_relative", noise_relative, "must be a fraction 0-0.5");
  }
  if (!(outlier_probability >= 0.0 && outlier_probability <= 1.0)) {
    return bad_option("outlier_probability", outlier_probability, "must be a probability 0-1");
  }
  if (!nonnegative(outlier_min_pf) || !(outlier_max_pf >= outlier_min_pf) || !std::isfinite(outlier_max_pf)) {
    return bad_option("outlier_max_pf", outlier_max_pf, "must be at least outlier_min_pf, both 0 or more");
  }
  if (!nonnegative(drift_per_sqrt_s) || drift_per_sqrt_s > 0.1) {
    return bad_option("drift_per_sqrt_s", drift_per_sqrt_s, "must be 0-0.1 per sqrt(s)");
  }
  const std::pair<const char*, double> sigmas[] = {
      {"fabrication_sigma", fabrication_sigma},
      {"donning_gain_sigma", donning_gain_sigma},
      {"donning_prestretch_sigma", donning_prestretch_sigma},
  };
  for (const auto& [name, v] : sigmas) {
    // Truncated at 3 sigma, so 0.3 keeps every factor positive.
    if (!nonnegative(v) || v > 0.3) return bad_option(name, v, "must be a relative spread 0-0.3");
  }
  if (!nonnegative(donning_offset_sigma_pf)) {
    return bad_option("donning_offset_sigma_pf", donning_offset_sigma_pf, "must be 0 or more pF");
  }
  if (!nonnegative(slip_common_sigma_m) || slip_common_sigma_m > 0.02 || !nonnegative(slip_cell_sigma_m) ||
      slip_cell_sigma_m > 0.02 || !nonnegative(creep_per_sqrt_s_m) || creep_per_sqrt_s_m > 0.01) {
    return bad_option("slip_*_sigma_m/creep_per_sqrt_s_m",
                      std::max({slip_common_sigma_m, slip_cell_sigma_m, creep_per_sqrt_s_m}),
                      "must be 0-0.02 m (creep 0-0.01 m per sqrt(s)); metres, not millimetres");
  }
  const StretchSkinModel& s = skin;
  if (!positive(s.reference_hand_length_m) || !positive(s.reference_hand_width_m) || !positive(s.textile_prestretch)) {
    return bad_option("skin.reference_hand_*/textile_prestretch", s.textile_prestretch, "must be above 0");
  }
  for (double v : {s.finger_shear_lag_m, s.dorsum_shear_lag_m, s.volume_length_m, s.web_span_m, s.thumb_web_span_m,
                   s.dorsum_reach_m, s.slack_softness, s.wrist_shear_lag_m}) {
    if (!positive(v)) return bad_option("skin length scale", v, "lengths and widths must be above 0");
  }
  if (s.elements_per_cell < 1 || s.elements_per_cell > 64) {
    return bad_option("skin.elements_per_cell", s.elements_per_cell, "must be 1-64");
  }
  return {};
}

std::string StretchGloveSimOptions::describe() const {
  char buf[640];
  std::snprintf(
      buf, sizeof buf,
      "seed=%llu glove_seed=%llu rate=%.1fHz full_scale=%.0fpF noise=%s(%.3gpF + %.3g%%) outliers=%s(p=%.2g, "
      "%.0f-%.0fpF) drift=%s(%.2g/sqrt(s)) fabrication=%s(%.3g) donning=%s(gain %.3g, offset %.3gpF, prestretch "
      "%.3g, slip %.1f+%.1fmm) creep=%s(%.2gmm/sqrt(s)) saturation=%s; skin: reference hand %.1fx%.1fcm, textile "
      "prestretch %.3g, transfer %.2f, shear lag %.0f/%.0fmm, %d elements per cell",
      static_cast<unsigned long long>(seed), static_cast<unsigned long long>(glove_seed), measurement_rate_hz,
      full_scale_pf, enable_noise ? "on" : "off", noise_pf, noise_relative * 100.0, enable_outliers ? "on" : "off",
      outlier_probability, outlier_min_pf, outlier_max_pf, enable_drift ? "on" : "off", drift_per_sqrt_s,
      enable_fabrication_spread ? "on" : "off", fabrication_sigma, enable_donning_variation ? "on" : "off",
      donning_gain_sigma, donning_offset_sigma_pf, donning_prestretch_sigma, slip_common_sigma_m * 1e3,
      slip_cell_sigma_m * 1e3, enable_creep ? "on" : "off", creep_per_sqrt_s_m * 1e3, enable_saturation ? "on" : "off",
      skin.reference_hand_length_m * 100.0,
      skin.reference_hand_width_m * 100.0, skin.textile_prestretch, skin.transfer_efficiency,
      skin.finger_shear_lag_m * 1e3, skin.dorsum_shear_lag_m * 1e3, skin.elements_per_cell);
  return buf;
}

// --- simulator -----------------------------------------------------------------

Result<StretchGloveSimulator> StretchGloveSimulator::create(StretchGloveLayout layout, HandShape shape,
                                                            StretchGloveSimOptions options, int donning) {
  if (auto st = options.validate(); !st) return st.error();
  if (auto st = layout.validate(); !st) return st.error();
  for (const auto& f : shape.fingers) {
    if (f.bone_count < 3) {
      return make_error(Errc::invalid_argument,
                        "the hand shape has a finger without bones; build it with HandShape::from_measurements");
    }
  }
  StretchGloveSimulator s;
  s.layout_ = std::move(layout);
  s.shape_ = shape;
  s.options_ = options;
  s.model_ = HandModel(shape);

  Rng fab(mix_seed(options.glove_seed, kFabricationStream));
  for (const auto& c : s.layout_.cells) {
    const double z = truncated_normal(fab, 3.0);
    s.c0_pf_.push_back(c.rest_capacitance_pf *
                       (options.enable_fabrication_spread ? 1.0 + options.fabrication_sigma * z : 1.0));
  }

  const auto& L = s.layout_;
  s.combination_cells_.resize(L.measurement_count());
  for (int t = 0; t < L.top_strips; ++t) {
    for (int b = 0; b < L.bottom_strips; ++b) {
      auto& list = s.combination_cells_[static_cast<std::size_t>(t * L.bottom_strips + b)];
      for (std::size_t c = 0; c < L.cells.size(); ++c) {
        if ((L.cells[c].top_strip == t) != (L.cells[c].bottom_strip == b)) list.push_back(static_cast<std::uint16_t>(c));
      }
    }
  }
  s.noise_rng_ = Rng(mix_seed(options.seed, kNoiseStream));
  s.outlier_rng_ = Rng(mix_seed(options.seed, kOutlierStream));
  s.drift_rng_ = Rng(mix_seed(options.seed, kDriftStream));
  s.creep_rng_ = Rng(mix_seed(options.seed, kCreepStream));
  for (const auto& c : s.layout_.cells) {
    const auto pos = chain_pos(c.segment);
    s.region_.push_back(pos ? static_cast<std::size_t>(pos->finger) : kFingerCount);
  }
  s.don(donning);
  return s;
}

void StretchGloveSimulator::don(int index) {
  const std::size_t n = layout_.cells.size();
  donning_ = StretchDonning{};
  donning_.index = index;
  donning_.gain.assign(n, 1.0);
  donning_.offset_pf.assign(n, 0.0);
  donning_.prestretch.assign(n, 1.0);
  donning_.slip_m.assign(n, 0.0);
  creep_m_.fill(0.0);  // a fresh donning starts where it was put
  Rng rng(mix_seed(mix_seed(options_.seed, kDonningStream), static_cast<std::uint64_t>(index)));
  // The glove slides as a whole per finger (and on the dorsum), plus a little per cell.
  std::array<double, kFingerCount + 1> common{};
  for (auto& v : common) v = options_.slip_common_sigma_m * truncated_normal(rng, 3.0);
  for (std::size_t i = 0; i < n; ++i) {
    const double g = truncated_normal(rng, 3.0);
    const double o = truncated_normal(rng, 3.0);
    const double p = truncated_normal(rng, 3.0);
    const double s = truncated_normal(rng, 3.0);
    if (!options_.enable_donning_variation) continue;
    const std::size_t region = region_[i];
    donning_.gain[i] = 1.0 + options_.donning_gain_sigma * g;
    donning_.offset_pf[i] = options_.donning_offset_sigma_pf * o;
    donning_.prestretch[i] = 1.0 + options_.donning_prestretch_sigma * p;
    donning_.slip_m[i] = common[region] + options_.slip_cell_sigma_m * s;
  }
  build_cell_models();
}

void StretchGloveSimulator::build_cell_models() {
  const StretchSkinModel& sk = options_.skin;
  const double eta = sk.transfer_efficiency;
  const double L = shape_.hand_length_m;
  const double B = shape_.hand_width_m;
  // One size of glove: a hand bigger than the reference pre-stretches it.
  const double pre_along = sk.textile_prestretch * L / sk.reference_hand_length_m;
  const double pre_across = sk.textile_prestretch * B / sk.reference_hand_width_m;

  std::array<Chain, kFingerCount> chains;
  for (std::size_t f = 0; f < kFingerCount; ++f) chains[f] = make_chain(shape_, static_cast<Finger>(f), sk);

  // Joint positions on the flat hand, projected onto the back of the hand:
  // (across, toward the fingers) in metres, for the dorsum cells.
  HandAngles zero{};
  const auto T0 = model_.joint_poses_in_wrist(Handedness::right, zero);
  auto dorsal = [&](HandJoint j) { return Eigen::Vector2d(T0[index_of(j)].p.x(), -T0[index_of(j)].p.z()); };
  const Finger long_fingers[] = {Finger::index, Finger::middle, Finger::ring, Finger::little};

  cells_.assign(layout_.cells.size(), CellModel{});
  webs_.clear();
  const int K = sk.elements_per_cell;
  for (std::size_t i = 0; i < layout_.cells.size(); ++i) {
    const StretchCell& c = layout_.cells[i];
    CellModel& m = cells_[i];
    m.prestretch_along = pre_along * donning_.prestretch[i];
    m.prestretch_across = pre_across * donning_.prestretch[i];
    // The cell's extent along the bone, on the (pre-stretched) hand.
    const double extent = (c.direction == StretchDirection::along ? c.length_m : c.width_m) * pre_along;
    m.elements.resize(static_cast<std::size_t>(K));
    const double slip = donning_.slip_m[i] + creep_m_[region_[i]];
    const double h_wrist = sk.wrist_skin_offset * B;

    if (c.segment == HandJoint::wrist) {
      // Dorsum: position (across, toward the knuckles); slip moves it distally.
      const Eigen::Vector2d centre(c.across_fraction * B, c.along_fraction * L + slip);
      for (int k = 0; k < K; ++k) {
        Element& e = m.elements[static_cast<std::size_t>(k)];
        const Eigen::Vector2d p = centre + Eigen::Vector2d(0.0, extent * ((k + 0.5) / K - 0.5));
        auto decay = [&](const Eigen::Vector2d& q, double scale) { return std::exp(-(p - q).norm() / scale); };
        // A knuckle pulls the skin behind it, over its own metacarpal: the
        // pull fades across the hand twice as fast as along it.
        auto pull = [&](const Eigen::Vector2d& q, double scale) {
          const Eigen::Vector2d d = p - q;
          return std::exp(-std::hypot(2.0 * d.x(), d.y()) / scale) / (2.0 * scale);
        };
        const double ld = sk.dorsum_shear_lag_m;
        // Along: MCP flexion pulls the skin over the metacarpals toward the
        // knuckles; thumb CMC flexion pulls it toward the thumb's base.
        for (Finger f : long_fingers) {
          const Chain& ch = chains[static_cast<std::size_t>(f)];
          const double w = pull(dorsal(finger_joints(f).joints[1]), ld);
          e.along.push_back({static_cast<std::uint16_t>(kElong + ch.flex_dof[0]), eta * ch.skin_offset[0] * w});
        }
        {
          const Chain& th = chains[0];
          const double w = pull(dorsal(HandJoint::thumb_metacarpal), ld);
          e.along.push_back({static_cast<std::uint16_t>(kElong + th.flex_dof[0]), eta * th.skin_offset[0] * w});
        }
        // Across: spreading neighbouring fingers pulls the metacarpal heads
        // apart; the palm cups with ring/little MCP and thumb CMC flexion;
        // the interossei bulge with ab/adduction.
        const double reach = sk.dorsum_reach_m;
        for (std::size_t n = 0; n + 1 < 4; ++n) {
          const Finger a = long_fingers[n], b = long_fingers[n + 1];
          const Eigen::Vector2d mid = 0.5 * (dorsal(finger_joints(a).joints[1]) + dorsal(finger_joints(b).joints[1]));
          const double w = sk.dorsum_spread * decay(mid, reach);
          e.across.push_back({static_cast<std::uint16_t>(kVol + chains[static_cast<std::size_t>(a)].abduction_dof), w});
          e.across.push_back({static_cast<std::uint16_t>(kVol + chains[static_cast<std::size_t>(b)].abduction_dof), -w});
        }
        {
          const Eigen::Vector2d mid =
              0.5 * (dorsal(HandJoint::thumb_proximal) + dorsal(HandJoint::index_proximal));
          e.across.push_back(
              {static_cast<std::uint16_t>(kVol + chains[0].abduction_dof), sk.dorsum_spread * decay(mid, reach)});
        }
        for (Finger f : {Finger::ring, Finger::little}) {
          const double w = sk.dorsum_cupping * decay(dorsal(finger_joints(f).joints[1]), reach);
          e.across.push_back({static_cast<std::uint16_t>(kVol + chains[static_cast<std::size_t>(f)].flex_dof[0]), w});
        }
        e.across.push_back({static_cast<std::uint16_t>(kVol + chains[0].flex_dof[0]),
                            sk.dorsum_cupping * decay(dorsal(HandJoint::thumb_metacarpal), reach)});
        for (Finger f : long_fingers) {
          const double w = sk.dorsum_bulge * decay(dorsal(finger_joints(f).joints[1]), reach);
          e.across.push_back({static_cast<std::uint16_t>(kElong + chains[static_cast<std::size_t>(f)].abduction_dof), w});
        }
        // The wrist: flexion pulls the skin behind the strap toward the
        // forearm; radial deviation opens the ulnar side and closes the radial
        // one (and the reverse), fading toward the knuckles.
        const double lw = sk.wrist_shear_lag_m;
        const double from_wrist = std::max(0.0, p.y());
        e.along.push_back({static_cast<std::uint16_t>(kWrist),
                           eta * h_wrist * std::exp(-from_wrist / lw) / (2.0 * lw)});
        const double fade = std::exp(-from_wrist / (2.0 * lw));
        e.across.push_back({static_cast<std::uint16_t>(kWrist + 1), sk.wrist_deviation_gain * (p.x() / (0.5 * B)) * fade});
        e.across.push_back({static_cast<std::uint16_t>(kWrist + 2), 0.3 * sk.wrist_deviation_gain * fade});
      }
      continue;
    }

    const ChainPos pos = *chain_pos(c.segment);  // validate() guarantees a glove segment
    const Chain& ch = chains[static_cast<std::size_t>(pos.finger)];
    const double s_centre = ch.bone_start[pos.bone] + c.along_fraction * ch.bone_length[pos.bone] + slip;
    std::optional<std::size_t> web;
    if (c.category == StretchCellCategory::abduction) {
      Web w;
      w.cell = i;
      w.joint_a = c.segment;
      w.along_a_m = std::max(0.0, s_centre - ch.bone_start[pos.bone]);
      if (pos.finger == Finger::thumb) {
        // The first web space reaches from the thumb to the index MCP.
        w.joint_b = HandJoint::index_proximal;
        w.along_b_m = 0.0;
        w.span_m = sk.thumb_web_span_m;
      } else {
        const auto next = static_cast<Finger>(static_cast<int>(pos.finger) + 1);
        const Chain& nch = chains[static_cast<std::size_t>(next)];
        w.joint_b = finger_joints(next).joints[pos.bone];
        w.along_b_m = std::max(0.0, c.along_fraction * nch.bone_length[pos.bone] + slip);
        w.span_m = sk.web_span_m;
      }
      const Vec3 pa = T0[index_of(w.joint_a)] * Vec3(0.0, 0.0, -w.along_a_m);
      const Vec3 pb = T0[index_of(w.joint_b)] * Vec3(0.0, 0.0, -w.along_b_m);
      w.rest_distance_m = (pa - pb).norm();
      web = webs_.size();
      webs_.push_back(w);
    }
    const double lf = sk.finger_shear_lag_m;
    for (int k = 0; k < K; ++k) {
      Element& e = m.elements[static_cast<std::size_t>(k)];
      const double lo = s_centre + extent * (static_cast<double>(k) / K - 0.5);
      const double hi = lo + extent / K;
      const double s = 0.5 * (lo + hi);
      for (std::size_t j = 0; j < 3; ++j) {
        // Shear lag around the joint, plus the glove finger's even share.
        const double local = laplace_mean_density(lo - ch.joint_s[j], hi - ch.joint_s[j], lf);
        const double even = sk.finger_tension_fraction / ch.length;
        e.along.push_back({static_cast<std::uint16_t>(kElong + ch.flex_dof[j]), eta * ch.skin_offset[j] * (local + even)});
      }
      e.along.push_back({static_cast<std::uint16_t>(kElong + ch.abduction_dof),
                         eta * sk.abduction_skin * ch.skin_offset[0] *
                             laplace_mean_density(lo - ch.joint_s[0], hi - ch.joint_s[0], lf)});
      // A flexed wrist pulls the whole glove finger toward the strap.
      e.along.push_back({static_cast<std::uint16_t>(kWrist), eta * sk.wrist_tension_fraction * h_wrist / ch.length});
      if (web) {
        e.across.push_back({static_cast<std::uint16_t>(kWeb + *web), 1.0});
        continue;
      }
      for (std::size_t j = 0; j < 3; ++j) {
        const double w = ch.volume_gain[j] * std::exp(-std::abs(s - ch.joint_s[j]) / sk.volume_length_m);
        e.across.push_back({static_cast<std::uint16_t>(kVol + ch.flex_dof[j]), w});
      }
      if (s >= 0.0 && s <= ch.bulge_end) {
        e.across.push_back({static_cast<std::uint16_t>(kVol + ch.flex_dof[0]), sk.muscle_bulge});
      }
    }
  }
  features_.assign(kWeb + webs_.size(), 0.0);
}

void StretchGloveSimulator::features(const HandAngles& a, WristAngles wrist, bool with_webs,
                                     std::vector<double>& f) const {
  const StretchSkinModel& sk = options_.skin;
  f.resize(kWeb + webs_.size());
  const double wf = wrist.flexion_rad;
  f[kWrist] = wf >= 0.0 ? wf * (1.0 + sk.cam_dip * wf) : sk.hyperextension_fold * wf;
  f[kWrist + 1] = wrist.deviation_rad;
  f[kWrist + 2] = std::sqrt(wrist.deviation_rad * wrist.deviation_rad + 1e-4) - 1e-2;
  for (std::size_t d = 0; d < kHandDofCount; ++d) {
    const double th = a[d];
    if (is_abduction(static_cast<HandDof>(d))) {
      f[kElong + d] = std::sqrt(th * th + 1e-4) - 1e-2;
      f[kVol + d] = th;
      continue;
    }
    // DoF 0 of a finger is its base joint (MCP, thumb CMC), 2 the middle, 3 the distal one.
    const std::size_t k = d % 4;
    const double cam = k == 0 ? sk.cam_mcp : (k == 2 ? sk.cam_pip : sk.cam_dip);
    f[kElong + d] = th >= 0.0 ? th * (1.0 + cam * th) : sk.hyperextension_fold * th;
    const double closed = std::max(th, 0.0);
    f[kVol + d] = closed * (1.0 + 0.5 * closed);
  }
  if (!with_webs || webs_.empty()) return;
  const auto T = model_.joint_poses_in_wrist(Handedness::right, a);
  for (std::size_t w = 0; w < webs_.size(); ++w) {
    const Web& web = webs_[w];
    const Vec3 pa = T[index_of(web.joint_a)] * Vec3(0.0, 0.0, -web.along_a_m);
    const Vec3 pb = T[index_of(web.joint_b)] * Vec3(0.0, 0.0, -web.along_b_m);
    f[kWeb + w] = sk.web_transfer * ((pa - pb).norm() - web.rest_distance_m) / web.span_m;
  }
}

double StretchGloveSimulator::cell_ratio(std::size_t cell, const std::vector<double>& f, CellStretch* detail) const {
  const StretchSkinModel& sk = options_.skin;
  const CellModel& m = cells_[cell];
  const bool along = layout_.cells[cell].direction == StretchDirection::along;
  const double pre_par = along ? m.prestretch_along : m.prestretch_across;
  const double pre_perp = along ? m.prestretch_across : m.prestretch_along;
  double ratio = 0.0;
  double par_sum = 0.0, perp_sum = 0.0, area_sum = 0.0;
  if (detail) detail->element_area_stretch.clear();
  for (const Element& e : m.elements) {
    double strain_along = 0.0, strain_across = 0.0;
    for (const Term& t : e.along) strain_along += t.coefficient * f[t.feature];
    for (const Term& t : e.across) strain_across += t.coefficient * f[t.feature];
    const double strain_par = along ? strain_along : strain_across;
    const double strain_perp = along ? strain_across : strain_along;
    const double lambda_par = soft_floor_at_one(pre_par * (1.0 + strain_par), sk.slack_softness);
    const double lambda_perp_skin = pre_perp * (1.0 + strain_perp);
    const double lambda_perp =
        soft_floor_at_one(1.0 + sk.cross_direction_gain * (lambda_perp_skin - 1.0), sk.slack_softness);
    const double area = lambda_par * lambda_perp;
    ratio += area * area;  // eq. 4.3 per element
    if (detail) {
      par_sum += lambda_par;
      perp_sum += lambda_perp;
      area_sum += area;
      detail->element_area_stretch.push_back(area);
    }
  }
  const double n = static_cast<double>(m.elements.size());
  if (detail) {
    detail->stretch_parallel = par_sum / n;
    detail->stretch_perpendicular = perp_sum / n;
    detail->area_stretch = area_sum / n;
    detail->capacitance_ratio = ratio / n;
  }
  return ratio / n;  // eq. 4.8 with equal element areas
}

double StretchGloveSimulator::cell_pf(std::size_t cell, const std::vector<double>& f) const {
  return c0_pf_[cell] * cell_ratio(cell, f, nullptr) * donning_.gain[cell] + donning_.offset_pf[cell];
}

void StretchGloveSimulator::cell_capacitances(const HandAngles& angles, std::span<double> out_pf,
                                              WristAngles wrist) const {
  std::vector<double> f;
  features(angles, wrist, true, f);
  for (std::size_t i = 0; i < cells_.size() && i < out_pf.size(); ++i) out_pf[i] = cell_pf(i, f);
}

std::vector<CellStretch> StretchGloveSimulator::cell_stretch(const HandAngles& angles, WristAngles wrist) const {
  std::vector<double> f;
  features(angles, wrist, true, f);
  std::vector<CellStretch> out(cells_.size());
  for (std::size_t i = 0; i < cells_.size(); ++i) cell_ratio(i, f, &out[i]);
  return out;
}

TimeNs StretchGloveSimulator::measurement_time(std::uint64_t index) const noexcept {
  // index / rate, rounded once: the grid does not drift over long sessions.
  return seconds_to_ns(static_cast<double>(index) / options_.measurement_rate_hz);
}

std::span<const std::uint16_t> StretchGloveSimulator::cells_in(std::size_t combination) const {
  if (combination >= combination_cells_.size()) return {};
  return combination_cells_[combination];
}

void StretchGloveSimulator::set_faults(StretchFaults faults) {
  std::sort(faults.nan_measurements.begin(), faults.nan_measurements.end());
  std::sort(faults.saturated_measurements.begin(), faults.saturated_measurements.end());
  faults_ = std::move(faults);
}

StretchMeasurement StretchGloveSimulator::measure(const HandAngles& angles, StretchMeasurementTruth* truth,
                                                 WristAngles wrist) {
  StretchMeasurement m;
  m.index = next_index_++;
  // The glove creeps a little each second (drawn whether creep is on or not,
  // so the other streams never shift).
  const auto per_second = static_cast<std::uint64_t>(std::llround(options_.measurement_rate_hz));
  if (m.index > 0 && per_second > 0 && m.index % per_second == 0) {
    for (auto& c : creep_m_) {
      const double z = creep_rng_.normal();
      if (options_.enable_creep) c += options_.creep_per_sqrt_s_m * z;
    }
    if (options_.enable_creep) build_cell_models();
  }
  m.combination = static_cast<std::uint16_t>(m.index % combination_cells_.size());
  m.time_ns = measurement_time(m.index);
  const auto& cells = combination_cells_[m.combination];

  bool with_webs = false;
  for (const auto c : cells) with_webs = with_webs || layout_.cells[c].category == StretchCellCategory::abduction;
  features(angles, wrist, with_webs, features_);
  double sum = 0.0;
  for (const auto c : cells) {
    const bool dead = m.time_ns >= faults_.dead_from_ns &&
                      std::find(faults_.dead_cells.begin(), faults_.dead_cells.end(), c) != faults_.dead_cells.end();
    if (!dead) sum += cell_pf(c, features_);
  }

  // Each effect draws from its own stream exactly once per measurement, on or off.
  const double drift_step = drift_rng_.normal();
  const double noise_z = noise_rng_.normal();
  const double outlier_u = outlier_rng_.uniform01();
  const double outlier_size = outlier_rng_.uniform(options_.outlier_min_pf, options_.outlier_max_pf);
  if (options_.enable_drift) {
    drift_gain_ += options_.drift_per_sqrt_s * std::sqrt(1.0 / options_.measurement_rate_hz) * drift_step;
  }
  const double noise_free = sum * drift_gain_;
  const double sigma = std::hypot(options_.noise_pf, options_.noise_relative * noise_free);
  const double noise = options_.enable_noise ? sigma * noise_z : 0.0;
  const double outlier =
      options_.enable_outliers && outlier_u < options_.outlier_probability ? outlier_size : 0.0;
  double value = noise_free + noise + outlier;

  bool force_saturated = std::binary_search(faults_.saturated_measurements.begin(),
                                            faults_.saturated_measurements.end(), m.index);
  if (force_saturated || (options_.enable_saturation && value >= options_.full_scale_pf)) {
    value = options_.full_scale_pf;
    m.saturated = true;
  }
  if (std::binary_search(faults_.nan_measurements.begin(), faults_.nan_measurements.end(), m.index)) {
    value = std::numeric_limits<double>::quiet_NaN();
  }
  m.capacitance_pf = value;
  if (truth) {
    truth->noise_free_pf = noise_free;
    truth->noise_pf = noise;
    truth->outlier_pf = outlier;
    truth->drift_gain = drift_gain_;
  }
  return m;
}

// --- exploration motion ---------------------------------------------------------

namespace {

// Postures a person exploring "extreme poses" goes through; together they
// reach both ends of every DoF's default range. Degrees, HandDof order:
// thumb CMC flex, CMC abd, MCP, IP; then MCP flex, MCP abd, PIP, DIP for the
// index, middle, ring and little fingers.
const std::array<HandAngles, 15>& exploration_postures() {
  static const std::array<HandAngles, 15> postures = {
      degrees({45, 10, 55, 40, 90, 0, 110, 75, 90, 0, 110, 75, 90, 0, 110, 75, 90, 0, 110, 75}),  // fist
      degrees({-15, 20, -10, -15, -20, 0, 0, -5, -20, 0, 0, -5, -20, 0, 0, -5, -20, 0, 0, -5}),   // flat, bent back
      degrees({-10, 45, 0, 0, 0, 25, 0, 0, 0, 0, 0, 0, 0, -20, 0, 0, 0, -30, 0, 0}),              // spread wide
      degrees({0, 45, 0, 0, 10, 25, 10, 5, 10, 15, 10, 5, 10, 15, 10, 5, 10, 15, 10, 5}),         // sweep radially
      degrees({20, -15, 10, 10, 10, -15, 10, 5, 10, -15, 10, 5, 10, -20, 10, 5, 10, -30, 10, 5}),  // sweep ulnarly
      degrees({20, 0, 60, 85, 0, 0, 110, 80, 0, 0, 110, 80, 0, 0, 110, 80, 0, 0, 110, 80}),       // hook
      degrees({50, -15, 0, 0, 90, 0, 0, -5, 90, 0, 0, -5, 90, 0, 0, -5, 90, 0, 0, -5}),           // table-top
      degrees({50, -15, 60, 85, 10, 0, 15, 10, 10, 0, 15, 10, 10, 0, 15, 10, 10, 0, 15, 10}),     // thumb across
      degrees({-15, 45, -10, -15, 30, 5, 40, 25, 30, 0, 40, 25, 30, -3, 40, 25, 30, -8, 40, 25}),  // thumb out
      degrees({30, 25, 20, 15, 40, 0, 40, 27, 20, 0, 30, 20, 20, -3, 30, 20, 20, -8, 30, 20}),     // pinch, index
      degrees({50, 30, 40, 30, 20, 0, 20, 10, 30, 0, 40, 25, 45, 0, 60, 40, 60, 0, 70, 45}),       // pinch, little
      degrees({45, 10, 55, 40, 0, 0, 0, 0, 90, 0, 110, 75, 90, 0, 110, 75, 90, 0, 110, 75}),       // point
      degrees({45, 10, 55, 40, 0, 15, 0, 0, 0, -15, 0, 0, 90, 0, 110, 75, 90, 0, 110, 75}),        // victory
      degrees({45, 10, 55, 40, 90, 0, 110, 75, 90, 0, 110, 75, 90, 0, 110, 75, -20, -30, 0, -5}),  // little out
      degrees({0, 30, 0, 0, 45, 10, 60, 40, 45, 0, 60, 40, 45, -10, 60, 40, 45, -20, 60, 40}),     // claw, half
  };
  return postures;
}

}  // namespace

HandAngles ExplorationMotion::relaxed() {
  // The free-motion protocol's first keyframe (hand_motion.cpp), so the task
  // motion continues where the exploration ends.
  return degrees({10, 10, 10, 10, 15, 5, 20, 10, 15, 0, 20, 10, 15, -3, 20, 10, 15, -8, 20, 10});
}

ExplorationMotion::ExplorationMotion(JointLimits limits, ExplorationOptions options, std::uint64_t seed)
    : limits_(limits), options_(options), rng_(mix_seed(seed, kExplorationStream)) {}

const HandAngles& ExplorationMotion::keyframe(std::size_t k) {
  const auto& postures = exploration_postures();
  while (keyframes_.size() <= k) {
    const std::size_t n = keyframes_.size();
    if (n == 0) {
      keyframes_.push_back(relaxed());
      continue;
    }
    // Each round visits every posture once, in a fresh order.
    if (order_.empty()) {
      for (std::size_t i = 0; i < postures.size(); ++i) order_.push_back(i);
      rng_.shuffle(order_.begin(), order_.end());
    }
    HandAngles a = postures[order_.back()];
    order_.pop_back();
    for (std::size_t d = 0; d < kHandDofCount; ++d) {
      const double mid = 0.5 * (limits_.min_rad[d] + limits_.max_rad[d]);
      const double half = 0.5 * options_.reach * (limits_.max_rad[d] - limits_.min_rad[d]);
      a[d] = std::clamp(a[d] + options_.jitter_rad * rng_.normal(), mid - half, mid + half);
    }
    keyframes_.push_back(a);
  }
  return keyframes_[k];
}

HandAngles ExplorationMotion::sample(TimeNs t_ns) {
  const double t = std::max(0.0, ns_to_seconds(t_ns));
  const double period = options_.transition_s + options_.hold_s;
  const auto k = static_cast<std::size_t>(t / period);
  const double into = t - static_cast<double>(k) * period;
  HandAngles to = keyframe(k);
  if (k == 0 || into >= options_.transition_s) return to;
  const HandAngles from = keyframe(k - 1);
  const double s = minimum_jerk(into / options_.transition_s);
  for (std::size_t d = 0; d < kHandDofCount; ++d) to[d] = from[d] + s * (to[d] - from[d]);
  return to;
}

// --- wrist ---------------------------------------------------------------------------

WristMotion::WristMotion(WristMotionOptions options, std::uint64_t seed)
    : options_(options), rng_(mix_seed(seed, kWristStream)) {}

WristAngles WristMotion::sample(TimeNs t_ns) {
  const double t = std::max(0.0, ns_to_seconds(t_ns));
  const auto k = static_cast<std::size_t>(t / options_.interval_s);
  while (keyframes_.size() <= k) {
    WristAngles w;  // keyframe 0: straight
    if (!keyframes_.empty()) {
      w.flexion_rad = rng_.uniform(options_.flexion_min_rad, options_.flexion_max_rad);
      w.deviation_rad = rng_.uniform(options_.deviation_min_rad, options_.deviation_max_rad);
    }
    keyframes_.push_back(w);
  }
  const double into = t - static_cast<double>(k) * options_.interval_s;
  WristAngles to = keyframes_[k];
  const double transition = std::min(options_.transition_s, options_.interval_s);
  if (k == 0 || into >= transition) return to;
  const WristAngles& from = keyframes_[k - 1];
  const double s = minimum_jerk(into / transition);
  to.flexion_rad = from.flexion_rad + s * (to.flexion_rad - from.flexion_rad);
  to.deviation_rad = from.deviation_rad + s * (to.deviation_rad - from.deviation_rad);
  return to;
}

// --- session -------------------------------------------------------------------------

std::string StretchSessionOptions::describe() const {
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "exploration %.1f s (move %.2f s, hold %.2f s, reach %.2f), wrist motion %s (flexion %.0f..%.0f deg, "
                "deviation %.0f..%.0f deg), task %.1f s: ",
                exploration_s, exploration.transition_s, exploration.hold_s, exploration.reach,
                wrist_motion ? "on" : "off", rad_to_deg(wrist.flexion_min_rad), rad_to_deg(wrist.flexion_max_rad),
                rad_to_deg(wrist.deviation_min_rad), rad_to_deg(wrist.deviation_max_rad), task_s);
  return buf + task_motion.describe();
}

namespace {
HandMotionOptions task_options(HandMotionOptions o, std::uint64_t seed) {
  o.seed = mix_seed(seed, kTaskMotionStream);
  return o;
}
}  // namespace

StretchGloveSession::StretchGloveSession(StretchGloveSimulator simulator, StretchSessionOptions options)
    : sim_(std::move(simulator)),
      options_(options),
      exploration_(JointLimits::defaults(), options.exploration, sim_.options().seed),
      task_(HandModel(sim_.shape()), task_options(options.task_motion, sim_.options().seed)),
      wrist_(options.wrist, sim_.options().seed) {
  const double rate = sim_.options().measurement_rate_hz;
  const double total_s = std::max(0.0, options_.exploration_s) + std::max(0.0, options_.task_s);
  total_ = static_cast<std::uint64_t>(std::llround(total_s * rate));
  exploration_end_ns_ = seconds_to_ns(std::max(0.0, options_.exploration_s));
}

bool StretchGloveSession::next(StretchSample& out) {
  if (sim_.next_index() >= total_) return false;
  const TimeNs t = sim_.measurement_time(sim_.next_index());
  if (t < exploration_end_ns_) {
    out.phase = StretchPhase::exploration;
    // The last move of the exploration returns to the relaxed pose the task
    // motion starts from, so the two phases join without a jump.
    const TimeNs settle_ns = seconds_to_ns(options_.exploration.transition_s);
    const TimeNs blend_start = std::max<TimeNs>(0, exploration_end_ns_ - settle_ns);
    if (t >= blend_start && settle_ns > 0) {
      const HandAngles from = exploration_.sample(blend_start);
      const HandAngles to = ExplorationMotion::relaxed();
      const double s = minimum_jerk(static_cast<double>(t - blend_start) / static_cast<double>(settle_ns));
      for (std::size_t d = 0; d < kHandDofCount; ++d) out.angles[d] = from[d] + s * (to[d] - from[d]);
    } else {
      out.angles = exploration_.sample(t);
    }
  } else {
    out.phase = StretchPhase::task;
    out.angles = task_.sample(t - exploration_end_ns_).angles;
  }
  out.wrist = options_.wrist_motion ? wrist_.sample(t) : WristAngles{};
  out.measurement = sim_.measure(out.angles, &out.truth, out.wrist);
  return true;
}

}  // namespace proprio::sim
