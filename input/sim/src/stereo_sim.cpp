#include "proprio/sim/stereo_sim.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <numeric>

namespace proprio::sim {

namespace {


// Markers on the palm move with the wrist: the model's non-thumb metacarpals
// are rigid with it, so the palm capsules are one body with the WRIST segment.
HandJoint body_of(HandJoint segment) noexcept {
  switch (segment) {
    case HandJoint::palm:
    case HandJoint::index_metacarpal:
    case HandJoint::middle_metacarpal:
    case HandJoint::ring_metacarpal:
    case HandJoint::little_metacarpal: return HandJoint::wrist;
    default: return segment;
  }
}

bool finite_nonneg(double x) { return std::isfinite(x) && x >= 0.0; }

}  // namespace

std::uint8_t marker_hue_code(MarkerHue hue) noexcept {
  // opencv_hue() is on OpenCV's 0-179 scale (2 degrees a step); HSV_FULL maps
  // degrees to 0-255 as round(deg * 256 / 360).
  const int deg = 2 * opencv_hue(hue);
  return static_cast<std::uint8_t>(((deg * 256 + 180) / 360) % 256);
}

MarkerHue marker_hue_from_code(std::uint8_t code) noexcept {
  MarkerHue best = MarkerHue::red;
  int best_d = 1000;
  for (auto h : {MarkerHue::red, MarkerHue::yellow, MarkerHue::green, MarkerHue::blue}) {
    int d = std::abs(static_cast<int>(code) - static_cast<int>(marker_hue_code(h)));
    d = std::min(d, 256 - d);  // hue is circular: 250 is nearer red than blue
    if (d < best_d) {
      best_d = d;
      best = h;
    }
  }
  return best;
}

std::string_view to_string(FacingModel m) noexcept {
  switch (m) {
    case FacingModel::cutoff: return "cutoff";
    case FacingModel::linear_ramp: return "linear-ramp";
  }
  return "?";
}

std::string_view to_string(MarkerVisibility v) noexcept {
  switch (v) {
    case MarkerVisibility::visible: return "visible";
    case MarkerVisibility::dropped: return "dropped";
    case MarkerVisibility::no_hand: return "no-hand";
    case MarkerVisibility::behind: return "behind";
    case MarkerVisibility::outside_fov: return "outside-fov";
    case MarkerVisibility::facing_away: return "facing-away";
    case MarkerVisibility::too_small: return "too-small";
    case MarkerVisibility::occluded: return "occluded";
    case MarkerVisibility::noise_outside: return "noise-outside";
  }
  return "?";
}

Status StereoSimOptions::validate() const {
  auto bad = [](const char* what) {
    return make_error(Errc::invalid_argument, std::string("stereo simulator options: ") + what);
  };
  if (!finite_nonneg(pixel_noise_px)) return bad("pixel_noise_px must be a finite value >= 0 (pixels)");
  if (!finite_nonneg(area_noise_fraction)) return bad("area_noise_fraction must be a finite value >= 0");
  if (!(drop_probability >= 0.0 && drop_probability <= 1.0)) return bad("drop_probability must be in [0, 1]");
  if (!(facing_max_deg > 0.0 && facing_max_deg <= 180.0)) return bad("facing_max_deg must be in (0, 180]");
  if (!(facing_alpha_min_deg >= 0.0 && facing_alpha_min_deg < facing_alpha_max_deg && facing_alpha_max_deg <= 180.0)) {
    return bad("facing angles need 0 <= facing_alpha_min_deg < facing_alpha_max_deg <= 180");
  }
  if (!finite_nonneg(occlusion_offset_m)) return bad("occlusion_offset_m must be a finite value >= 0 (metres)");
  if (!finite_nonneg(forearm_length_m)) return bad("forearm_length_m must be a finite value >= 0 (metres)");
  if (!finite_nonneg(min_area_px2)) return bad("min_area_px2 must be a finite value >= 0");
  if (!(std::isfinite(min_depth_m) && min_depth_m > 0.0)) return bad("min_depth_m must be > 0 (metres)");
  return Status::success();
}

std::string StereoSimOptions::describe() const {
  char facing_text[96];
  if (facing == FacingModel::cutoff) {
    std::snprintf(facing_text, sizeof facing_text, "cutoff(<%.1fdeg)", facing_max_deg);
  } else {
    std::snprintf(facing_text, sizeof facing_text, "linear-ramp(%.1f..%.1fdeg)", facing_alpha_min_deg,
                  facing_alpha_max_deg);
  }
  char buf[384];
  std::snprintf(buf, sizeof buf,
                "pixel_noise=%.3fpx area_noise=%.3f drop=%.4f facing=%s occlusion=%s(offset %.1fmm, forearm %.3fm) "
                "min_area=%.1fpx2 min_depth=%.3fm shuffle=%s seed=%llu",
                pixel_noise_px, area_noise_fraction, drop_probability, facing_text, occlusion ? "on" : "off",
                occlusion_offset_m * 1e3, forearm_length_m, min_area_px2, min_depth_m, shuffle ? "on" : "off",
                static_cast<unsigned long long>(seed));
  return buf;
}

std::size_t StereoGroundTruth::visible_count(std::size_t camera) const {
  return static_cast<std::size_t>(
      std::count(visibility[camera].begin(), visibility[camera].end(), MarkerVisibility::visible));
}

std::size_t StereoGroundTruth::stereo_count() const {
  std::size_t n = 0;
  for (std::size_t j = 0; j < visibility[0].size() && j < visibility[1].size(); ++j) {
    if (visibility[0][j] == MarkerVisibility::visible && visibility[1][j] == MarkerVisibility::visible) ++n;
  }
  return n;
}

double segment_segment_distance_sq(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1) noexcept {
  // Ericson, Real-Time Collision Detection (2005), §5.1.9: closest points of
  // two segments, parameters clamped to [0, 1], with the degenerate cases
  // (a segment that is a point, parallel segments) handled explicitly.
  constexpr double kEps = 1e-18;
  const Vec3 d1 = p1 - p0;
  const Vec3 d2 = q1 - q0;
  const Vec3 r = p0 - q0;
  const double a = d1.squaredNorm();
  const double e = d2.squaredNorm();
  const double f = d2.dot(r);
  double s = 0.0;
  double t = 0.0;
  if (a <= kEps && e <= kEps) return r.squaredNorm();
  if (a <= kEps) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= kEps) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2);
      const double denom = a * e - b * b;
      // Parallel (denom ~ 0): any s works; s = 0 and the clamping below find
      // the right pair of end points.
      s = denom > 1e-12 * a * e ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  return ((p0 + s * d1) - (q0 + t * d2)).squaredNorm();
}

bool segment_hits_capsule(const Vec3& p0, const Vec3& p1, const Capsule& c) noexcept {
  return segment_segment_distance_sq(p0, p1, c.a, c.b) < c.radius_m * c.radius_m;
}

HandCapsules hand_capsules(const HandPose& hand, double forearm_length_m) {
  HandCapsules out;
  auto add = [&](const Vec3& a, const Vec3& b, double radius, HandJoint owner) {
    if (out.count >= HandCapsules::kMax) return;
    out.capsules[out.count] = Capsule{a, b, radius};
    out.owner[out.count] = owner;
    ++out.count;
  };
  auto p = [&](HandJoint j) -> const Vec3& { return hand.joint(j).p; };
  auto r = [&](HandJoint j) { return hand.radius_m[index_of(j)]; };
  // One capsule per bone. The smaller end radius keeps a capsule inside the
  // skin at both ends (a finger tapers toward its tip), so it never hides
  // markers that sit on the next segment near the joint.
  for (std::size_t fi = 0; fi < kFingerCount; ++fi) {
    const FingerJoints fj = finger_joints(static_cast<Finger>(fi));
    for (std::size_t k = 0; k + 1 < fj.count; ++k) {
      const HandJoint a = fj.joints[k];
      const HandJoint b = fj.joints[k + 1];
      add(p(a), p(b), std::min(r(a), r(b)), a);
    }
  }
  // The palm: the four metacarpal capsules above already overlap side by side
  // (knuckle spacing < sum of radii for the model's hands), so a line of sight
  // cannot slip between them. The carpal row closes the gap at their bases.
  add(p(HandJoint::index_metacarpal), p(HandJoint::little_metacarpal),
      std::min(r(HandJoint::index_metacarpal), r(HandJoint::little_metacarpal)), HandJoint::wrist);
  if (forearm_length_m > 0.0) {
    const Pose& W = hand.joint(HandJoint::wrist);
    add(W.p, W * Vec3(0.0, 0.0, forearm_length_m), r(HandJoint::wrist), HandJoint::wrist);
  }
  return out;
}

StereoMarkerSimulator::StereoMarkerSimulator(StereoRig rig, std::vector<PlacedMarker> markers,
                                             StereoSimOptions options, Handedness markers_hand)
    : rig_(std::move(rig)), markers_(std::move(markers)), options_(options), markers_hand_(markers_hand) {
  for (auto& m : markers_) {
    const double n = m.normal_in_segment.norm();
    if (n > 1e-12) m.normal_in_segment /= n;
  }
}

Result<StereoMarkerSimulator> StereoMarkerSimulator::create(const ImuGloveDescription& glove, const HandShape& shape,
                                                            StereoSimOptions options) {
  if (auto st = options.validate(); !st) return st.error();
  const PinholeCamera& cam = glove.rig.camera;
  if (cam.width_px <= 0 || cam.height_px <= 0 || !(cam.fx_px > 0.0) || !(cam.fy_px > 0.0)) {
    return make_error(Errc::invalid_argument, "glove '" + glove.name + "' (" + glove.origin +
                                                  "): the stereo camera needs a positive image size and focal "
                                                  "lengths");
  }
  if (!(glove.rig.baseline_m > 0.0) || !(glove.rig.rate_hz > 0.0)) {
    return make_error(Errc::invalid_argument, "glove '" + glove.name + "' (" + glove.origin +
                                                  "): the stereo rig needs baseline_m > 0 and rate_hz > 0");
  }
  return StereoMarkerSimulator(glove.rig, glove.place_markers(shape, Handedness::right), options,
                               Handedness::right);
}

Eigen::Vector2d StereoMarkerSimulator::project(const Vec3& p_in_leftcam, std::size_t camera) const {
  const PinholeCamera& k = rig_.camera;
  // Rectified pair: the right camera differs only by +baseline along x.
  const double x = p_in_leftcam.x() - (camera == 1 ? rig_.baseline_m : 0.0);
  return {k.fx_px * x / p_in_leftcam.z() + k.cx_px, k.fy_px * p_in_leftcam.y() / p_in_leftcam.z() + k.cy_px};
}

StereoFrame StereoMarkerSimulator::simulate(const HandPose& hand, const Pose& T_world_head, TimeNs t_ns,
                                            StereoGroundTruth* truth, std::span<const Vec3> skin_offsets) const {
  const std::size_t n = markers_.size();
  const bool skin = skin_offsets.size() == n && n > 0;
  const StereoSimOptions& o = options_;
  const PinholeCamera& k = rig_.camera;

  StereoFrame frame;
  frame.time_ns = t_ns;
  frame.cameras[0].camera_id = 0;
  frame.cameras[1].camera_id = 1;
  const Pose T_world_lc = T_world_leftcam(T_world_head);
  const Pose T_lc_world = T_world_lc.inverse();
  if (truth) {
    truth->time_ns = t_ns;
    truth->T_world_leftcam = T_world_lc;
    for (std::size_t c = 0; c < 2; ++c) {
      truth->cameras[c].clear();
      truth->visibility[c].assign(n, MarkerVisibility::visible);
    }
  }
  auto mark_all = [&](MarkerVisibility v) {
    if (truth) {
      for (auto& vis : truth->visibility) vis.assign(n, v);
    }
  };

  // One engine per frame, seeded by time: a frame does not depend on which
  // frames came before. Every draw below happens unconditionally and in a
  // fixed order, so switching occlusion or facing changes which markers are
  // seen but not the noise of the others.
  Rng rng(mix_seed(o.seed, static_cast<std::uint64_t>(t_ns)));
  if (rng.uniform01() < o.drop_probability) {
    frame.dropped = true;
    mark_all(MarkerVisibility::dropped);
    return frame;
  }
  if (!hand.active) {
    mark_all(MarkerVisibility::no_hand);
    return frame;
  }

  HandCapsules caps;
  if (o.occlusion) caps = hand_capsules(hand, o.forearm_length_m);

  const std::array<Vec3, 2> c_world = {T_world_lc.p, T_world_lc * Vec3(rig_.baseline_m, 0.0, 0.0)};
  const bool mirror = hand.hand != markers_hand_;
  const double cos_facing_max = std::cos(o.facing_max_deg * std::numbers::pi / 180.0);
  const double area_per_z = std::numbers::pi * k.fx_px * k.fy_px;  // times (d/2)^2 cos(alpha) r / z^3
  const double u_lo = -0.5;
  const double u_hi = static_cast<double>(k.width_px) - 0.5;
  const double v_lo = -0.5;
  const double v_hi = static_cast<double>(k.height_px) - 0.5;

  std::array<std::vector<MarkerTruth>, 2> seen;
  for (auto& s : seen) s.reserve(n);

  for (std::size_t c = 0; c < 2; ++c) {
    const double x_shift = (c == 1) ? rig_.baseline_m : 0.0;
    for (std::size_t j = 0; j < n; ++j) {
      const double u_face = rng.uniform01();
      const double noise_u = rng.normal();
      const double noise_v = rng.normal();
      const double noise_area = rng.normal();

      const PlacedMarker& m = markers_[j];
      const Pose& T_world_seg = hand.joint(m.segment);
      // The other hand is the mirror image: x -> -x in every segment frame,
      // as in the hand model and ImuGloveDescription::place_markers.
      const Vec3 p_placed = skin ? Vec3(m.p_in_segment + skin_offsets[j]) : m.p_in_segment;
      const Vec3 p_seg = mirror ? Vec3(-p_placed.x(), p_placed.y(), p_placed.z()) : p_placed;
      const Vec3 n_seg =
          mirror ? Vec3(-m.normal_in_segment.x(), m.normal_in_segment.y(), m.normal_in_segment.z()) : m.normal_in_segment;
      const Vec3 p_world = T_world_seg * p_seg;
      const Vec3 n_world = T_world_seg.q * n_seg;
      const Vec3 p_lc = T_lc_world * p_world;

      auto reject = [&](MarkerVisibility why) {
        if (truth) truth->visibility[c][j] = why;
      };

      const double x = p_lc.x() - x_shift;
      const double y = p_lc.y();
      const double z = p_lc.z();
      if (!(z >= o.min_depth_m)) {
        reject(MarkerVisibility::behind);
        continue;
      }
      const double u = k.fx_px * x / z + k.cx_px;
      const double v = k.fy_px * y / z + k.cy_px;
      const double range = std::sqrt(x * x + y * y + z * z);
      // The whole blob must be inside the image: a blob cut by the border has a
      // biased centroid, and detectors usually reject it. Its extent is bounded
      // by the disc's radius seen face-on, stretched by r/z off axis.
      const double half = 0.5 * m.diameter_m;
      const double extent_px = half * std::max(k.fx_px, k.fy_px) * range / (z * z);
      if (u - extent_px < u_lo || u + extent_px > u_hi || v - extent_px < v_lo || v + extent_px > v_hi) {
        reject(MarkerVisibility::outside_fov);
        continue;
      }
      const Vec3 to_cam = c_world[c] - p_world;
      const double cos_alpha = n_world.dot(to_cam) / to_cam.norm();
      if (o.facing == FacingModel::cutoff) {
        if (!(cos_alpha > cos_facing_max)) {
          reject(MarkerVisibility::facing_away);
          continue;
        }
      } else {
        // Lee 2021 eq. (4.10), used as the probability of detection.
        const double alpha_deg = std::acos(std::clamp(cos_alpha, -1.0, 1.0)) * 180.0 / std::numbers::pi;
        const double p_seen =
            std::clamp((o.facing_alpha_max_deg - alpha_deg) / (o.facing_alpha_max_deg - o.facing_alpha_min_deg), 0.0, 1.0);
        if (!(u_face < p_seen)) {
          reject(MarkerVisibility::facing_away);
          continue;
        }
      }
      // |cos| so that a disabled facing test (180 deg) still gives a sane area.
      const double area = area_per_z * half * half * std::abs(cos_alpha) * range / (z * z * z);
      const double area_obs = std::max(0.0, area * (1.0 + o.area_noise_fraction * noise_area));
      if (area_obs < o.min_area_px2) {
        reject(MarkerVisibility::too_small);
        continue;
      }
      if (o.occlusion) {
        // From just off the marker's surface to the camera centre. A capsule of
        // the marker's own rigid body that contains the start point is
        // skipped: the glove's marker placement and our capsule radii are
        // separate approximations of the skin, and a marker must not hide
        // itself. Outside it, its own segment hides it like any other (a
        // dorsal marker seen through the finger from the palm side). Another
        // segment containing the start point does hide it: the marker is
        // pressed against that segment.
        const Vec3 start = p_world + o.occlusion_offset_m * n_world;
        const HandJoint own = body_of(m.segment);
        bool hidden = false;
        for (std::size_t i = 0; i < caps.count && !hidden; ++i) {
          const Capsule& cap = caps.capsules[i];
          if (body_of(caps.owner[i]) == own &&
              segment_segment_distance_sq(start, start, cap.a, cap.b) < cap.radius_m * cap.radius_m) {
            continue;
          }
          hidden = segment_hits_capsule(start, c_world[c], cap);
        }
        if (hidden) {
          reject(MarkerVisibility::occluded);
          continue;
        }
      }
      const double u_obs = u + o.pixel_noise_px * noise_u;
      const double v_obs = v + o.pixel_noise_px * noise_v;
      if (u_obs < u_lo || u_obs > u_hi || v_obs < v_lo || v_obs > v_hi) {
        reject(MarkerVisibility::noise_outside);
        continue;
      }
      MarkerTruth mt;
      mt.marker = j;
      mt.glove_index = m.index;
      mt.p_in_leftcam = p_lc;
      mt.u_px = u;
      mt.v_px = v;
      mt.area_px2 = area;
      mt.facing_deg = std::acos(std::clamp(cos_alpha, -1.0, 1.0)) * 180.0 / std::numbers::pi;
      seen[c].push_back(mt);
      frame.cameras[c].markers.push_back(Marker{marker_hue_code(m.hue), static_cast<float>(u_obs),
                                                static_cast<float>(v_obs), static_cast<float>(area_obs)});
    }
  }

  for (std::size_t c = 0; c < 2; ++c) {
    auto& obs = frame.cameras[c].markers;
    std::vector<std::size_t> order(obs.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    if (o.shuffle) rng.shuffle(order.begin(), order.end());
    std::vector<Marker> shuffled(obs.size());
    for (std::size_t i = 0; i < order.size(); ++i) shuffled[i] = obs[order[i]];
    obs = std::move(shuffled);
    if (truth) {
      truth->cameras[c].resize(order.size());
      for (std::size_t i = 0; i < order.size(); ++i) truth->cameras[c][i] = seen[c][order[i]];
    }
  }
  return frame;
}

void simulate_session(HandMotionGenerator& motion, const StereoMarkerSimulator& sim, double duration_s,
                      const StereoFrameCallback& on_frame) {
  const double rate = sim.rig().rate_hz;
  if (!(rate > 0.0) || !(duration_s > 0.0)) return;
  // Frame k at exactly k / rate (rounded to the nanosecond), so a session is
  // the same however long it runs.
  const auto frames = static_cast<std::int64_t>(std::floor(duration_s * rate + 1e-9));
  StereoGroundTruth truth;
  for (std::int64_t f = 0; f < frames; ++f) {
    const TimeNs t = seconds_to_ns(static_cast<double>(f) / rate);
    const HandMotionFrame mf = motion.sample(t);
    const StereoFrame frame = sim.simulate(mf.pose, mf.T_world_head, t, &truth);
    on_frame(mf, frame, truth);
  }
}

Result<StreamId> add_stereo_stream(RecordingWriter& writer, const StereoMarkerSimulator& sim,
                                   std::string_view rig_name) {
  const StereoRig& rig = sim.rig();
  const PinholeCamera& k = rig.camera;
  const Pose& T = rig.T_head_leftcam;
  char buf[1536];
  std::snprintf(buf, sizeof buf,
                "{\"source\": \"proprio::sim::StereoMarkerSimulator\", \"cameras\": {\"0\": \"left\", \"1\": \"right\"}, "
                "\"rectified\": true, \"width_px\": %d, \"height_px\": %d, \"fx_px\": %.17g, \"fy_px\": %.17g, "
                "\"cx_px\": %.17g, \"cy_px\": %.17g, \"baseline_m\": %.17g, \"rate_hz\": %.17g, "
                "\"T_head_leftcam\": {\"q_wxyz\": [%.17g, %.17g, %.17g, %.17g], \"p_m\": [%.17g, %.17g, %.17g]}, "
                "\"hue\": \"opencv_hsv_full_256\", \"hues\": {\"red\": %d, \"yellow\": %d, \"green\": %d, \"blue\": %d}, "
                "\"markers\": %zu, \"seed\": %llu, \"options\": \"%s\"}",
                k.width_px, k.height_px, k.fx_px, k.fy_px, k.cx_px, k.cy_px, rig.baseline_m, rig.rate_hz, T.q.w(),
                T.q.x(), T.q.y(), T.q.z(), T.p.x(), T.p.y(), T.p.z(), marker_hue_code(MarkerHue::red),
                marker_hue_code(MarkerHue::yellow), marker_hue_code(MarkerHue::green), marker_hue_code(MarkerHue::blue),
                sim.markers().size(), static_cast<unsigned long long>(sim.options().seed),
                sim.options().describe().c_str());
  return writer.add_stream(StreamKind::markers, "cam/" + std::string(rig_name) + "/markers", buf);
}

Status write_stereo_frame(RecordingWriter& writer, StreamId stream, const StereoFrame& frame) {
  if (frame.dropped) return Status::success();
  for (const auto& cam : frame.cameras) {
    if (auto st = writer.write(stream, cam, frame.time_ns); !st) return st;
  }
  return Status::success();
}

}  // namespace proprio::sim
