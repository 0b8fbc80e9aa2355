#include "proprio/vist_eval/evaluation.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <optional>

#include "proprio/core/random.hpp"
#include "proprio/sim/imu_sim.hpp"
#include "proprio/sim/stereo_image_sim.hpp"
#include "proprio/sim/stereo_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "proprio/vist/marker_detection.hpp"
#include "proprio/vist/vist_session.hpp"

namespace proprio::vist_eval {
namespace {

// The one glove of a bench run (the same for every subject): its own stream of the run's seed.
constexpr std::uint64_t kGloveBuildStream = 0x676c6f7665;

using WallClock = std::chrono::steady_clock;
double seconds_since(WallClock::time_point t0) { return std::chrono::duration<double>(WallClock::now() - t0).count(); }

constexpr std::array<HandJoint, 4> kKeypoints = {HandJoint::palm, HandJoint::thumb_tip, HandJoint::index_tip,
                                                  HandJoint::middle_tip};
// Two-sided 95 % interval of chi-square with 6 degrees of freedom.
constexpr double kChi2_6_lo = 1.2373, kChi2_6_hi = 14.4494;

// A static blob in the room behind the hand, seen by both cameras.
struct Distractor {
  Vec3 p_in_world;
  MarkerHue hue;
  double diameter_m;
};

std::vector<Distractor> make_distractors(int count, const Pose& T_world_head, std::uint64_t seed) {
  Rng rng(mix_seed(seed, 0xd157));
  std::vector<Distractor> out;
  for (int i = 0; i < count; ++i) {
    // In front of the head (-Z), 0.8-2.5 m away, spread over the view.
    const double z = -rng.uniform(0.8, 2.5);
    const Vec3 p_in_head(rng.uniform(-0.9, 0.9) * -z, rng.uniform(-0.6, 0.3) * -z, z);
    out.push_back({T_world_head * p_in_head, static_cast<MarkerHue>(rng.below(4)), rng.uniform(0.01, 0.04)});
  }
  return out;
}

void add_distractors(const std::vector<Distractor>& ds, const sim::StereoMarkerSimulator& sim,
                     const Pose& T_world_leftcam, sim::StereoFrame& frame) {
  const Pose T_leftcam_world = T_world_leftcam.inverse();
  const auto& cam = sim.rig().camera;
  for (const auto& d : ds) {
    const Vec3 p = T_leftcam_world * d.p_in_world;
    if (p.z() < 0.1) continue;
    for (std::size_t c = 0; c < 2; ++c) {
      const Eigen::Vector2d uv = sim.project(p, c);
      if (uv.x() < 0 || uv.y() < 0 || uv.x() > cam.width_px - 1 || uv.y() > cam.height_px - 1) continue;
      Marker m;
      m.hue = sim::marker_hue_code(d.hue);
      m.u_px = static_cast<float>(uv.x());
      m.v_px = static_cast<float>(uv.y());
      m.area_px2 = static_cast<float>(std::numbers::pi * 0.25 * d.diameter_m * d.diameter_m * cam.fx_px * cam.fy_px /
                                      (p.z() * p.z()));
      frame.cameras[c].markers.push_back(m);
    }
  }
}

// Per-axis least-squares scale taking the nominal glove's IMU-to-marker
// levers to the user's: the truth the filter's scale estimates are compared with.
struct ScaleTruth {
  Vec3 scale = Vec3::Ones();
  Vec3 leverage = Vec3::Zero();  // RMS nominal lever per axis (m): how well the markers span the axis
};
std::vector<ScaleTruth> true_scales(const vist::VistModel& model, const ImuGloveDescription& glove,
                                    const HandShape& shape, Handedness hand) {
  const auto imus = glove.place_imus(shape, hand);
  const auto markers = glove.place_markers(shape, hand);
  std::vector<ScaleTruth> out(model.segments.size());
  std::vector<Vec3> num(model.segments.size(), Vec3::Zero()), den(model.segments.size(), Vec3::Zero());
  std::vector<int> count(model.segments.size(), 0);
  for (const auto& fm : model.markers) {
    const auto& seg = model.segments[fm.segment];
    const Vec3 t = markers[fm.glove_index].p_in_segment - imus[seg.imu_sensor_id].T_segment_imu.p;
    const Vec3& n = fm.lever_in_segment;
    num[fm.segment] += t.cwiseProduct(n);
    den[fm.segment] += n.cwiseProduct(n);
    ++count[fm.segment];
  }
  for (std::size_t k = 0; k < out.size(); ++k) {
    for (int a = 0; a < 3; ++a) {
      out[k].scale[a] = den[k][a] > 0.0 ? num[k][a] / den[k][a] : 1.0;
      out[k].leverage[a] = count[k] > 0 ? std::sqrt(den[k][a] / count[k]) : 0.0;
    }
  }
  return out;
}

}  // namespace

std::string_view to_string(Challenge c) noexcept {
  switch (c) {
    case Challenge::none: return "none";
    case Challenge::occlude_half: return "occlude_half";
    case Challenge::out_of_view: return "out_of_view";
    case Challenge::distractors: return "distractors";
    case Challenge::dropped_frames: return "dropped_frames";
    case Challenge::imu_unplug: return "imu_unplug";
  }
  return "?";
}
std::string_view to_string(Ablation a) noexcept {
  switch (a) {
    case Ablation::full: return "full";
    case Ablation::imu_only: return "imu_only";
    case Ablation::vision_only: return "vision_only";
    case Ablation::no_imu_priors: return "no_imu_priors";
  }
  return "?";
}
std::string_view to_string(FrameMode m) noexcept { return m == FrameMode::images ? "images" : "detections"; }
std::optional<FrameMode> parse_frame_mode(std::string_view s) noexcept {
  if (s == "detections") return FrameMode::detections;
  if (s == "images") return FrameMode::images;
  return std::nullopt;
}

std::string_view to_string(RealismEffect e) noexcept {
  switch (e) {
    case RealismEffect::glove_build: return "glove_build";
    case RealismEffect::sliding: return "sliding";
    case RealismEffect::wobble: return "wobble";
    case RealismEffect::slip: return "slip";
    case RealismEffect::camera: return "camera";
    case RealismEffect::natural_motion: return "natural_motion";
    case RealismEffect::tremor: return "tremor";
    case RealismEffect::flicks: return "flicks";
  }
  return "?";
}

std::optional<RealismEffect> parse_realism_effect(std::string_view s) noexcept {
  for (RealismEffect e : kRealismEffects) {
    if (to_string(e) == s) return e;
  }
  return std::nullopt;
}

void SessionSpec::switch_off(RealismEffect e) {
  switch (e) {
    case RealismEffect::glove_build: glove_build = sim::GloveBuildErrors::as_drawn(); break;
    case RealismEffect::sliding: soft_tissue.sliding = false; break;
    case RealismEffect::wobble: soft_tissue.wobble = false; break;
    case RealismEffect::slip: soft_tissue.slip = false; break;
    case RealismEffect::camera: camera_realism = false; break;
    case RealismEffect::natural_motion: protocol = sim::MotionProtocol::free_motion; break;
    case RealismEffect::tremor: tremor = false; break;
    case RealismEffect::flicks: flicks = false; break;
  }
}

ErrorSummary summarize(std::vector<float>& e) {
  ErrorSummary s;
  s.samples = e.size();
  if (e.empty()) return s;
  std::sort(e.begin(), e.end());
  double sum = 0.0;
  for (float x : e) sum += x;
  s.mean_mm = sum / static_cast<double>(e.size());
  auto quantile = [&](double q) { return static_cast<double>(e[static_cast<std::size_t>(q * (e.size() - 1))]); };
  s.median_mm = quantile(0.5);
  s.p95_mm = quantile(0.95);
  auto pck = [&](double t) {
    return static_cast<double>(std::upper_bound(e.begin(), e.end(), static_cast<float>(t)) - e.begin()) /
           static_cast<double>(e.size());
  };
  s.pck20 = pck(20.0);
  s.pck35 = pck(35.0);
  // AUC of PCK over [0, 50] mm by the trapezoid rule on a 0.5 mm grid.
  double auc = 0.0;
  double prev = pck(0.0);
  for (int i = 1; i <= 100; ++i) {
    const double cur = pck(0.5 * i);
    auc += 0.5 * (prev + cur) * 0.5;
    prev = cur;
  }
  s.auc50 = auc / 50.0;
  return s;
}

Result<SessionResult> run_session(const ImuGloveDescription& glove, const SessionSpec& spec,
                                  const vist::VistTrackerOptions& base_options) {
  auto subject = sim::sim_subject(spec.subject);
  if (!subject) return subject.error();
  auto shape = subject->shape();
  if (!shape) return shape.error();

  SessionResult res;
  res.spec = spec;
  res.hand_length_m = subject->hand_length_m;
  res.hand_width_m = subject->hand_width_m;

  const std::uint64_t seed = mix_seed(spec.seed, static_cast<std::uint64_t>(spec.subject));
  // The simulators wear the glove as built and as it sits this session; the
  // tracker reads the drawn description.
  if (auto st = spec.glove_build.validate(); !st) return st.error();
  const ImuGloveDescription worn =
      sim::glove_as_built(glove, *shape, spec.glove_build, mix_seed(spec.seed, kGloveBuildStream), mix_seed(seed, 7));
  sim::HandMotionOptions mo;
  mo.protocol = spec.protocol;
  mo.hand = spec.hand;
  mo.seed = mix_seed(seed, 1);
  mo.tremor = spec.tremor;
  mo.flicks = spec.flicks;
  sim::HandMotionGenerator motion(HandModel(*shape), mo);
  sim::HandMotionGenerator truth_motion(HandModel(*shape), mo);  // same motion, sampled separately

  auto imu = sim::ImuSimulator::create(motion, worn.place_imus(*shape, spec.hand), sim::ImuNoiseOptions{},
                                       mix_seed(seed, 2));
  if (!imu) return imu.error();
  sim::StereoSimOptions so;
  so.seed = mix_seed(seed, 3);
  so.pixel_noise_px = spec.pixel_noise_px;
  so.drop_probability = spec.challenge == Challenge::dropped_frames ? 0.1 : 0.0;
  auto stereo = sim::StereoMarkerSimulator::create(worn, *shape, so);
  if (!stereo) return stereo.error();
  // Images mode: the same scene rendered (clutter, distractors, skin,
  // noise) and the blobs found by the OpenCV detector.
  std::optional<sim::StereoImageSimulator> renderer;
  std::optional<vist::MarkerDetector> detector;
  sim::StereoImageFrame images;
  if (spec.mode == FrameMode::images) {
    sim::StereoImageSimOptions io;
    io.visibility = sim::StereoImageSimOptions::default_visibility();
    io.visibility.drop_probability = so.drop_probability;
    io.visibility.seed = so.seed;
    io.seed = mix_seed(seed, 6);
    io.distractors = spec.challenge == Challenge::distractors ? spec.distractor_count : 0;
    if (!spec.camera_realism) io.switch_off_camera_realism();
    auto r = sim::StereoImageSimulator::create(worn, *shape, io);
    if (!r) return r.error();
    renderer.emplace(std::move(*r));
    auto d = vist::MarkerDetector::create(glove.rig.camera);
    if (!d) return d.error();
    detector.emplace(std::move(*d));
  }
  // The stereo simulator places markers for a right hand and mirrors them for a left pose.

  // Soft tissue moves every marker and IMU on its bone; it samples its own
  // copy of the motion (for the wobble's accelerations).
  sim::HandMotionGenerator tissue_motion(HandModel(*shape), mo);
  std::vector<sim::SkinMount> mounts;
  for (const PlacedMarker& m : stereo->markers()) {
    mounts.push_back({m.segment, m.p_in_segment, spec.hand == Handedness::left});
  }
  const std::size_t first_imu_mount = mounts.size();
  for (const sim::ImuMounting& m : imu->mountings()) mounts.push_back({m.segment, m.T_segment_imu_nominal.p, false});
  auto tissue = sim::SoftTissue::create([&tissue_motion](TimeNs t) { return tissue_motion.sample(t).pose; }, mounts,
                                        spec.soft_tissue, mix_seed(seed, 8));
  if (!tissue) return tissue.error();
  const bool soft = spec.soft_tissue.any();
  if (soft) {
    imu->set_mount_offsets([&tissue, first_imu_mount](std::size_t i, const HandPose& pose, TimeNs t) {
      return tissue->offset(first_imu_mount + i, pose, t);
    });
  }
  std::vector<Vec3> skin_offsets(first_imu_mount);
  auto marker_skin = [&](const HandPose& pose, TimeNs t) -> std::span<const Vec3> {
    if (!soft) return {};
    for (std::size_t i = 0; i < first_imu_mount; ++i) skin_offsets[i] = tissue->offset(i, pose, t);
    return skin_offsets;
  };

  vist::VistTrackerOptions to = base_options;
  to.hand = spec.hand;
  switch (spec.ablation) {
    case Ablation::full: break;
    case Ablation::imu_only: to.use_vision = false; break;
    case Ablation::vision_only: to.use_imu = false; break;
    case Ablation::no_imu_priors: to.correspondence.use_priors = false; break;
  }
  auto tracker = vist::VistTracker::create(glove, to);
  if (!tracker) return tracker.error();
  const vist::VistModel& model = tracker->model();
  std::optional<vist::VistSessionWriter> recorder;
  if (!spec.record_path.empty()) {
    vist::VistSessionInfo info;
    info.glove = glove;
    info.hand = spec.hand;
    info.nominal_hand_length_m = to.nominal_hand_length_m;
    info.nominal_hand_width_m = to.nominal_hand_width_m;
    auto w = vist::VistSessionWriter::create(spec.record_path, info, spec.overwrite_record);
    if (!w) return w.error();
    recorder.emplace(std::move(*w));
  }
  // The scales that best map the drawn levers onto the glove as it is worn: what a tracker could reach.
  const auto scale_truth = true_scales(model, worn, *shape, spec.hand);
  std::vector<Quat> q_imu_segment_truth;
  for (const auto& seg : model.segments) {
    q_imu_segment_truth.push_back(imu->mountings()[seg.imu_sensor_id].T_segment_imu.q.conjugate());
  }

  const auto distractors = spec.challenge == Challenge::distractors
                               ? make_distractors(spec.distractor_count, mo.T_world_head_rest, mix_seed(seed, 4))
                               : std::vector<Distractor>{};
  Rng occlusion_rng(mix_seed(seed, 5));
  std::vector<bool> occluded_half(stereo->markers().size(), false);
  {
    std::vector<std::size_t> idx(occluded_half.size());
    std::iota(idx.begin(), idx.end(), 0);
    occlusion_rng.shuffle(idx.begin(), idx.end());
    for (std::size_t i = 0; i < idx.size() / 2; ++i) occluded_half[idx[i]] = true;
  }
  auto hidden_window = [](double t_s) { return std::fmod(t_s, 10.0) >= 8.0; };  // occlude_half: 2 s of every 10
  auto out_of_view_window = [](double t_s) { return t_s >= 9.0 && std::fmod(t_s - 9.0, 12.0) < 3.0; };
  auto hidden = [&](double t_s, std::size_t marker) {
    switch (spec.challenge) {
      case Challenge::occlude_half: return hidden_window(t_s) && occluded_half[marker];
      case Challenge::out_of_view: return out_of_view_window(t_s);
      default: return false;
    }
  };
  // Out-of-view events: returns at 12, 24, 36, ... s.
  std::vector<double> returns_s;
  if (spec.challenge == Challenge::out_of_view) {
    for (double t = 12.0; t < spec.duration_s - 1.0; t += 12.0) returns_s.push_back(t);
  }
  if (spec.challenge == Challenge::imu_unplug) {
    for (double t = 11.0; t < spec.duration_s - 1.0; t += 15.0) returns_s.push_back(t);
  }
  std::vector<double> recovered(returns_s.size(), -1.0);

  const double rate = stereo->rig().rate_hz;
  const TimeNs latency_ns = static_cast<TimeNs>(spec.camera_latency_s * 1e9);
  struct Arrival {
    TimeNs arrival, capture;
    sim::StereoFrame frame;
    Pose T_world_leftcam;
  };
  std::vector<Arrival> in_flight;
  std::int64_t next_frame = 0;
  const TimeNs end_ns = static_cast<TimeNs>(spec.duration_s * 1e9);
  const TimeNs warmup_ns = static_cast<TimeNs>(spec.warmup_s * 1e9);
  const TimeNs calib_ns = static_cast<TimeNs>(spec.calibration_check_s * 1e9);
  bool calibration_done = false;
  double tracker_s = 0.0;
  double nees_sum = 0.0;
  std::size_t nees_in = 0;
  std::vector<float> kp_err, joint_err;
  std::array<double, 4> kp_sum{};
  std::size_t kp_n = 0;
  vist::TimedImuSample ts;
  sim::StereoGroundTruth gt;
  const auto t0 = WallClock::now();

  while (imu->next_nominal_time_ns() <= end_ns) {
    const TimeNs tick_ns = imu->next_nominal_time_ns();
    // Frames captured up to this tick: simulate now, deliver after the latency.
    while (static_cast<TimeNs>(static_cast<double>(next_frame) / rate * 1e9) <= tick_ns) {
      const TimeNs cap = static_cast<TimeNs>(std::llround(static_cast<double>(next_frame) / rate * 1e9));
      ++next_frame;
      const auto mf = truth_motion.sample(cap);
      Arrival a;
      a.capture = cap;
      a.arrival = cap + latency_ns;
      a.T_world_leftcam = stereo->T_world_leftcam(mf.T_world_head);
      if (renderer) {
        // The challenges, rendered: the occluded half is not drawn (skin shows
        // where those markers were); out of view, no hand is in the picture.
        const double t_s = 1e-9 * static_cast<double>(cap);
        HandPose shown = mf.pose;
        if (spec.challenge == Challenge::out_of_view && out_of_view_window(t_s)) shown.active = false;
        const bool occluding = spec.challenge == Challenge::occlude_half && hidden_window(t_s);
        renderer->render(shown, mf.T_world_head, cap, images, nullptr, occluding ? &occluded_half : nullptr,
                         marker_skin(mf.pose, cap));
        if (images.dropped) continue;
        a.frame.time_ns = cap;
        if (auto st = detector->detect_stereo(images.images[0], images.images[1], a.frame.cameras[0],
                                              a.frame.cameras[1]);
            !st) {
          return st.error();
        }
        in_flight.push_back(std::move(a));
        continue;
      }
      a.frame = stereo->simulate(mf.pose, mf.T_world_head, cap, &gt, marker_skin(mf.pose, cap));
      if (a.frame.dropped) continue;  // nothing arrives
      const double t_s = 1e-9 * static_cast<double>(cap);
      for (std::size_t c = 0; c < 2; ++c) {
        auto& obs = a.frame.cameras[c].markers;
        std::size_t w = 0;
        for (std::size_t i = 0; i < obs.size(); ++i) {
          if (!hidden(t_s, gt.cameras[c][i].marker)) obs[w++] = obs[i];
        }
        obs.resize(w);
      }
      if (!distractors.empty()) add_distractors(distractors, *stereo, a.T_world_leftcam, a.frame);
      in_flight.push_back(std::move(a));
    }
    // Deliver what has arrived by now, then the IMU tick.
    for (auto it = in_flight.begin(); it != in_flight.end();) {
      if (it->arrival > tick_ns) break;
      const auto c0 = WallClock::now();
      tracker->add_stereo_frame(it->capture, it->frame.cameras[0], it->frame.cameras[1], it->T_world_leftcam);
      tracker_s += seconds_since(c0);
      if (recorder) {
        if (auto st = recorder->write_stereo_frame(it->capture, it->frame.cameras[0], it->frame.cameras[1],
                                                   it->T_world_leftcam);
            !st) {
          return st.error();
        }
      }
      // Consistency at the frame's capture time, while the core is there.
      const auto& lf = tracker->last_frame();
      if (tracker->initialized() && lf.capture_time_ns == it->capture && lf.correction.applied &&
          tracker->filter().time_ns(0) == it->capture && it->capture >= warmup_ns) {
        const auto truth = truth_motion.sample(it->capture);
        auto& filter = tracker->filter();
        for (std::size_t k = 0; k < model.segments.size(); ++k) {
          const auto& seg = model.segments[k];
          const Vec3 skin = soft ? tissue->offset(first_imu_mount + seg.imu_sensor_id, truth.pose, it->capture)
                                 : Vec3(Vec3::Zero());
          const Pose T_world_imu_true = truth.pose.joint(seg.segment) * Pose{Quat::Identity(), skin} *
                                        imu->mountings()[seg.imu_sensor_id].T_segment_imu;
          const auto& s = filter.state(k);
          Eigen::Matrix<double, 6, 1> e;
          e.head<3>() = T_world_imu_true.p - s.p_imu_in_world;
          e.tail<3>() = boxminus(T_world_imu_true.q, s.q_world_imu);
          const auto P = filter.segment_covariance(k);
          Eigen::Matrix<double, 6, 6> P6;
          P6.topLeftCorner<3, 3>() = P.block<3, 3>(vist::kErrP, vist::kErrP);
          P6.topRightCorner<3, 3>() = P.block<3, 3>(vist::kErrP, vist::kErrTheta);
          P6.bottomLeftCorner<3, 3>() = P.block<3, 3>(vist::kErrTheta, vist::kErrP);
          P6.bottomRightCorner<3, 3>() = P.block<3, 3>(vist::kErrTheta, vist::kErrTheta);
          const double nees = e.dot(P6.ldlt().solve(e));
          if (std::isfinite(nees)) {
            nees_sum += nees;
            nees_in += (nees >= kChi2_6_lo && nees <= kChi2_6_hi) ? 1 : 0;
            ++res.nees_samples;
          }
        }
      }
      it = in_flight.erase(it);
    }
    const auto readings = imu->next();
    bool new_pose = false;
    const double tick_s = 1e-9 * static_cast<double>(tick_ns);
    const bool unplugged = spec.challenge == Challenge::imu_unplug && tick_s >= 10.0 && std::fmod(tick_s - 10.0, 15.0) < 1.0;
    const auto c1 = WallClock::now();
    for (const auto& r : readings) {
      if (unplugged) break;
      ts.time_ns = r.time_ns;
      ts.sample = r.sample;
      ts.accel_clipped = r.accel_saturated;
      ts.gyro_clipped = r.gyro_saturated;
      new_pose = tracker->add_imu(ts) || new_pose;
      if (recorder) {
        if (auto st = recorder->write_imu(ts); !st) return st.error();
      }
    }
    tracker_s += seconds_since(c1);
    if (!tracker->initialized()) continue;
    if (!res.acquired) {
      res.acquired = true;
      res.acquisition_time_s = 1e-9 * static_cast<double>(tick_ns);
    }
    if (!calibration_done && tick_ns >= calib_ns) {
      calibration_done = true;
      double smax = 0.0, ssum = 0.0, mmax = 0.0, msum = 0.0;
      int sn = 0;
      for (std::size_t k = 0; k < model.segments.size(); ++k) {
        const auto& s = tracker->filter().state(k);
        for (int a = 0; a < 3; ++a) {
          if (scale_truth[k].leverage[a] < 0.005) continue;  // the markers do not span this axis
          const double e = std::abs(s.scale[a] - scale_truth[k].scale[a]) / scale_truth[k].scale[a];
          smax = std::max(smax, e);
          ssum += e;
          ++sn;
        }
        const double m = rad_to_deg(angle_between(s.q_imu_segment, q_imu_segment_truth[k]));
        mmax = std::max(mmax, m);
        msum += m;
      }
      res.scale_error_max = smax;
      res.scale_error_mean = sn > 0 ? ssum / sn : 0.0;
      res.mounting_error_max_deg = mmax;
      res.mounting_error_mean_deg = msum / static_cast<double>(model.segments.size());
    }
    if (!new_pose) continue;
    const HandPose& out = tracker->pose();
    const auto truth = truth_motion.sample(out.time_ns);
    if (recorder) {
      if (auto st = recorder->write_ground_truth(truth.pose); !st) return st.error();
      if (auto st = recorder->write_output(out); !st) return st.error();
    }
    std::array<double, 4> e{};
    for (std::size_t i = 0; i < 4; ++i) {
      e[i] = 1e3 * (out.joint(kKeypoints[i]).p - truth.pose.joint(kKeypoints[i]).p).norm();
    }
    const double t_s = 1e-9 * static_cast<double>(out.time_ns);
    for (std::size_t i = 0; i < returns_s.size(); ++i) {
      if (recovered[i] < 0.0 && t_s >= returns_s[i] && t_s < returns_s[i] + 9.0 &&
          (e[0] + e[1] + e[2] + e[3]) / 4.0 < 10.0) {
        recovered[i] = t_s - returns_s[i];
      }
    }
    if (out.time_ns < warmup_ns) continue;
    for (std::size_t i = 0; i < 4; ++i) {
      kp_err.push_back(static_cast<float>(e[i]));
      kp_sum[i] += e[i];
    }
    ++kp_n;
    for (double je : joint_position_errors(out, truth.pose)) joint_err.push_back(static_cast<float>(1e3 * je));
  }
  if (recorder) {
    if (auto st = recorder->close(); !st) return st.error();
  }
  res.wall_seconds = seconds_since(t0);
  res.tracker_seconds = tracker_s;
  res.sim_seconds = spec.duration_s;
  res.recovery_s = recovered;
  for (std::size_t i = 0; i < 4; ++i) res.keypoint_mean_mm[i] = kp_n ? kp_sum[i] / static_cast<double>(kp_n) : 0.0;
  res.keypoint_errors_mm = kp_err;
  res.joint_errors_mm = joint_err;
  res.keypoints = summarize(kp_err);
  res.all_joints = summarize(joint_err);
  res.nees_mean = res.nees_samples ? nees_sum / static_cast<double>(res.nees_samples) : 0.0;
  res.nees_in_95 = res.nees_samples ? static_cast<double>(nees_in) / static_cast<double>(res.nees_samples) : 0.0;
  res.stats = tracker->stats();
  return res;
}

Aggregate aggregate(std::string name, const std::vector<SessionResult>& sessions) {
  Aggregate a;
  a.name = std::move(name);
  a.sessions = sessions.size();
  std::vector<float> kp, joints;
  double sim_s = 0.0, wall_s = 0.0, trk_s = 0.0, nees_w = 0.0, nees_in = 0.0;
  std::size_t nees_n = 0, kp_n = 0;
  for (const auto& s : sessions) {
    kp.insert(kp.end(), s.keypoint_errors_mm.begin(), s.keypoint_errors_mm.end());
    joints.insert(joints.end(), s.joint_errors_mm.begin(), s.joint_errors_mm.end());
    const std::size_t n = s.keypoint_errors_mm.size() / 4;
    for (std::size_t i = 0; i < 4; ++i) a.keypoint_mean_mm[i] += s.keypoint_mean_mm[i] * static_cast<double>(n);
    kp_n += n;
    a.scale_error_max = std::max(a.scale_error_max, s.scale_error_max);
    a.mounting_error_max_deg = std::max(a.mounting_error_max_deg, s.mounting_error_max_deg);
    nees_w += s.nees_mean * static_cast<double>(s.nees_samples);
    nees_in += s.nees_in_95 * static_cast<double>(s.nees_samples);
    nees_n += s.nees_samples;
    a.recovery_s.insert(a.recovery_s.end(), s.recovery_s.begin(), s.recovery_s.end());
    sim_s += s.sim_seconds;
    wall_s += s.wall_seconds;
    trk_s += s.tracker_seconds;
    if (!s.acquired) ++a.acquisitions_failed;
  }
  for (auto& m : a.keypoint_mean_mm) m = kp_n ? m / static_cast<double>(kp_n) : 0.0;
  a.keypoints = summarize(kp);
  a.all_joints = summarize(joints);
  a.nees_mean = nees_n ? nees_w / static_cast<double>(nees_n) : 0.0;
  a.nees_in_95 = nees_n ? nees_in / static_cast<double>(nees_n) : 0.0;
  a.realtime_factor = wall_s > 0.0 ? sim_s / wall_s : 0.0;
  a.tracker_realtime_factor = trk_s > 0.0 ? sim_s / trk_s : 0.0;
  return a;
}


Result<TrackSessionResult> track_session(const std::filesystem::path& session, const TrackSessionOptions& options) {
  auto reader = vist::VistSessionReader::open(session);
  if (!reader) return reader.error();
  TrackSessionResult res;
  res.info = reader->info();
  vist::VistTrackerOptions to = options.tracker;
  to.hand = res.info.hand;
  to.nominal_hand_length_m = res.info.nominal_hand_length_m;
  to.nominal_hand_width_m = res.info.nominal_hand_width_m;
  auto tracker = vist::VistTracker::create(res.info.glove, to);
  if (!tracker) return tracker.error().with_context(session.string());

  std::optional<vist::VistSessionWriter> out;
  if (!options.output_path.empty()) {
    auto w = vist::VistSessionWriter::create(options.output_path, res.info, options.overwrite_output);
    if (!w) return w.error();
    out.emplace(std::move(*w));
  }
  struct Output {
    TimeNs t;
    std::array<Vec3, kHandJointCount> p;
  };
  std::vector<Output> outputs;
  std::vector<Output> truths;
  std::optional<TimeNs> first_imu, last_imu;
  for (;;) {
    auto item = reader->next();
    if (!item) return item.error().with_context(session.string());
    if (!*item) break;
    if (auto* imu = std::get_if<vist::TimedImuSample>(&**item)) {
      ++res.imu_samples;
      if (!first_imu) first_imu = imu->time_ns;
      last_imu = imu->time_ns;
      const auto c0 = WallClock::now();
      const bool fresh = tracker->add_imu(*imu);
      res.tracker_seconds += seconds_since(c0);
      if (!fresh) continue;
      const HandPose& pose = tracker->pose();
      ++res.poses;
      if (pose.active) {
        Output o{pose.time_ns, {}};
        for (std::size_t j = 0; j < kHandJointCount; ++j) o.p[j] = pose.T_world_joint[j].p;
        outputs.push_back(o);
      }
      if (out) {
        if (auto st = out->write_output(pose); !st) return st.error();
      }
    } else if (auto* f = std::get_if<vist::VistStereoFrame>(&**item)) {
      ++res.stereo_frames;
      const auto c0 = WallClock::now();
      tracker->add_stereo_frame(f->capture_time_ns, f->left, f->right, f->T_world_leftcam);
      res.tracker_seconds += seconds_since(c0);
    } else if (auto* gt = std::get_if<vist::VistGroundTruth>(&**item)) {
      ++res.ground_truth_poses;
      Output o{gt->pose.time_ns, {}};
      for (std::size_t j = 0; j < kHandJointCount; ++j) o.p[j] = gt->pose.T_world_joint[j].p;
      truths.push_back(o);
      if (out) {
        if (auto st = out->write_ground_truth(gt->pose); !st) return st.error();
      }
    }
  }
  if (out) {
    if (auto st = out->close(); !st) return st.error();
  }
  res.skipped_records = reader->skipped_records();
  res.recording = reader->summary();
  res.stats = tracker->stats();
  if (first_imu) res.session_seconds = 1e-9 * static_cast<double>(*last_imu - *first_imu);

  // Score against the truth, linearly interpolated between samples up to 50 ms apart.
  std::sort(truths.begin(), truths.end(), [](const Output& a, const Output& b) { return a.t < b.t; });
  const TimeNs warmup_end = first_imu ? *first_imu + static_cast<TimeNs>(options.warmup_s * 1e9) : 0;
  std::vector<float> kp_err, joint_err;
  std::array<double, 4> kp_sum{};
  for (const Output& o : outputs) {
    if (o.t < warmup_end) continue;
    auto it = std::lower_bound(truths.begin(), truths.end(), o.t, [](const Output& a, TimeNs t) { return a.t < t; });
    std::array<Vec3, kHandJointCount> truth;
    if (it != truths.end() && it->t == o.t) {
      truth = it->p;
    } else if (it != truths.end() && it != truths.begin() && it->t - std::prev(it)->t <= 50 * kNsPerMillisecond) {
      const Output& a = *std::prev(it);
      const double w = static_cast<double>(o.t - a.t) / static_cast<double>(it->t - a.t);
      for (std::size_t j = 0; j < kHandJointCount; ++j) truth[j] = (1.0 - w) * a.p[j] + w * it->p[j];
    } else {
      continue;
    }
    for (std::size_t i = 0; i < 4; ++i) {
      const double e = 1e3 * (o.p[index_of(kKeypoints[i])] - truth[index_of(kKeypoints[i])]).norm();
      kp_err.push_back(static_cast<float>(e));
      kp_sum[i] += e;
    }
    for (std::size_t j = 0; j < kHandJointCount; ++j) {
      joint_err.push_back(static_cast<float>(1e3 * (o.p[j] - truth[j]).norm()));
    }
  }
  const std::size_t n = kp_err.size() / 4;
  if (n > 0) {
    res.scored = true;
    for (std::size_t i = 0; i < 4; ++i) res.keypoint_mean_mm[i] = kp_sum[i] / static_cast<double>(n);
    res.keypoints = summarize(kp_err);
    res.all_joints = summarize(joint_err);
  }
  return res;
}

}  // namespace proprio::vist_eval
