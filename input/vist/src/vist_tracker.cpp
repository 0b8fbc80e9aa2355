#include "proprio/vist/vist_tracker.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

#include "proprio/core/log.hpp"

namespace proprio::vist {
namespace {

constexpr TimeNs kNsPerS = 1'000'000'000;

TimeNs seconds_to_ns(double s) { return static_cast<TimeNs>(std::llround(s * 1e9)); }

// The rotation about world +Y (up) nearest to M, as an angle.
double nearest_heading(const Mat3& M) { return std::atan2(M(0, 2) - M(2, 0), M(0, 0) + M(2, 2)); }

Quat heading(double psi) { return Quat(Eigen::AngleAxisd(psi, Vec3::UnitY())); }

}  // namespace

Status VistTrackerOptions::validate() const {
  if (!(nominal_hand_length_m > 0.1 && nominal_hand_length_m < 0.3) ||
      !(nominal_hand_width_m > 0.05 && nominal_hand_width_m < 0.2)) {
    return make_error(Errc::invalid_argument, "VIST tracker: nominal hand length/width must be adult sizes in metres");
  }
  if (auto st = filter.validate(); !st) return st;
  if (auto st = stereo.validate(); !st) return st;
  if (auto st = correspondence.validate(); !st) return st;
  if (!(max_frame_latency_s > 0.0 && max_frame_latency_s <= 2.0)) {
    return make_error(Errc::invalid_argument, "VIST tracker: max_frame_latency_s must be in (0, 2] s");
  }
  if (!(max_imu_time_jump_s > 0.0 && max_imu_time_jump_s <= 1e6)) {
    return make_error(Errc::invalid_argument, "VIST tracker: max_imu_time_jump_s must be in (0, 1e6] s");
  }
  if (min_acquisition_points < 3 || min_acquisition_matches < 3) {
    return make_error(Errc::invalid_argument, "VIST tracker: acquisition needs at least 3 points and 3 matches");
  }
  if (acquisition_heading_steps < 1 || acquisition_heading_steps > 360) {
    return make_error(Errc::invalid_argument, "VIST tracker: acquisition_heading_steps must be in [1, 360]");
  }
  if (!(lost_after_s > 0.0)) return make_error(Errc::invalid_argument, "VIST tracker: lost_after_s must be > 0");
  if (!(vision_only_accel_density > 0.0) || !(vision_only_gyro_density > 0.0)) {
    return make_error(Errc::invalid_argument, "VIST tracker: vision-only motion-model densities must be > 0");
  }
  if (!use_imu && !use_vision) {
    return make_error(Errc::invalid_argument, "VIST tracker: use_imu and use_vision cannot both be off");
  }
  return {};
}

std::string VistTrackerOptions::describe() const {
  std::ostringstream s;
  s << "VIST tracker: " << to_string(hand) << " hand, nominal " << nominal_hand_length_m * 100 << " x "
    << nominal_hand_width_m * 100 << " cm; max frame latency " << max_frame_latency_s * 1e3 << " ms; imu "
    << (use_imu ? "on" : "OFF (vision only)") << ", vision " << (use_vision ? "on" : "OFF (IMU only)")
    << ", constraints " << (use_constraints ? "on" : "off") << "; acquisition " << min_acquisition_points
    << " points / " << min_acquisition_matches << " matches, " << acquisition_heading_steps
    << " headings; lost after " << lost_after_s << " s\n"
    << filter.describe() << stereo.describe() << "\n"
    << correspondence.describe() << "\n";
  return s.str();
}

std::string VistStats::describe() const {
  std::ostringstream s;
  s << "imu samples " << imu_samples << " (rejected: " << imu_rejected_non_finite << " non-finite, "
    << imu_rejected_saturated << " saturated, " << imu_rejected_out_of_order << " out of order, "
    << imu_rejected_unknown_sensor << " unknown sensor, " << imu_rejected_time_jump << " time jumps; "
    << imu_accel_clipped << " used with a clipped accelerometer); frames " << frames << " (fused " << frames_fused
    << ", late " << frames_late << ", duplicate " << frames_duplicate << ", before acquisition "
    << frames_before_init << "); acquisitions " << acquisitions << ", re-acquisitions " << reacquisitions
    << "; stereo points " << stereo_points << ", correspondences " << correspondences << ", markers fused "
    << markers_fused << ", gated " << markers_gated;
  return s.str();
}

Result<VistTracker> VistTracker::create(const ImuGloveDescription& glove, VistTrackerOptions options) {
  if (auto st = options.validate(); !st) return st.error();
  auto shape = HandShape::from_measurements(options.nominal_hand_length_m, options.nominal_hand_width_m);
  if (!shape) return shape.error();
  if (!options.use_imu) {
    // Vision only: the "IMU" is a constant-velocity model whose process noise
    // must cover real hand motion.
    options.filter.noise.accel_model_noise_density = options.vision_only_accel_density;
    options.filter.noise.gyro_model_noise_density = options.vision_only_gyro_density;
  }
  auto model = VistModel::build(glove, *shape, options.hand);
  if (!model) return model.error();
  if (model->segment_index(HandJoint::wrist) < 0) {
    return make_error(Errc::invalid_argument, "glove '" + glove.name + "': VIST needs an IMU on the dorsum (wrist segment)");
  }
  const std::size_t marker_count = model->markers.size();
  auto filter = VistFilter::create(std::move(*model), options.filter);
  if (!filter) return filter.error();
  auto matcher = StereoMatcher::create(glove.rig, options.stereo);
  if (!matcher) return matcher.error();
  auto search = CorrespondenceSearch::create(options.correspondence, marker_count, 256);
  if (!search) return search.error();
  // Acquisition starts from a coarse guess: no trust in the predicted position
  // (plain maximum likelihood for the translation) and a wider mixture.
  CorrespondenceOptions acq = options.correspondence;
  acq.translation_prior_sigma_m = 0.0;
  acq.sigma_c_m = std::max(acq.sigma_c_m, 0.015);
  acq.use_marker_covariance = false;
  auto acquisition = CorrespondenceSearch::create(acq, marker_count, 256);
  if (!acquisition) return acquisition.error();
  return VistTracker(glove, options, std::move(*filter), std::move(*matcher), std::move(*search),
                     std::move(*acquisition));
}

VistTracker::VistTracker(const ImuGloveDescription& glove, VistTrackerOptions options, VistFilter filter,
                         StereoMatcher matcher, CorrespondenceSearch search, CorrespondenceSearch acquisition_search)
    : glove_(glove),
      options_(std::move(options)),
      rig_(glove.rig),
      filter_(std::move(filter)),
      matcher_(std::move(matcher)),
      search_(std::move(search)),
      acquisition_search_(std::move(acquisition_search)),
      hand_model_(filter_.model().nominal_shape) {
  const auto& m = filter_.model();
  const std::size_t n = m.segments.size();
  dorsum_ = m.segment_index(HandJoint::wrist);
  std::uint16_t max_sensor = 0;
  for (const auto& s : m.segments) max_sensor = std::max(max_sensor, s.imu_sensor_id);
  segment_of_sensor_.assign(static_cast<std::size_t>(max_sensor) + 1, -1);
  for (std::size_t k = 0; k < n; ++k) segment_of_sensor_[m.segments[k].imu_sensor_id] = static_cast<int>(k);
  last_sample_ns_.assign(n, std::numeric_limits<TimeNs>::min());
  imu_time_guards_.assign(n, TimestampGuard(static_cast<DurationNs>(options_.max_imu_time_jump_s * 1e9)));
  imu_held_.assign(n, TimedImuSample{});
  last_gyro_.assign(n, Vec3::Zero());
  last_accel_.assign(n, Vec3::Zero());
  queue_.reserve(n * 200);
  frames_.reserve(8);
  placed_ = m.placed_nominal;
  marker_cov_.assign(m.markers.size(), Mat3::Zero());
  measurements_.reserve(m.markers.size());
  corr_.reserve(256);
  best_corr_.reserve(256);
  points_.reserve(128);
  observations_.reserve(128);
  work_states_.resize(n);
  work_rates_.resize(n);
  work_times_.resize(n);
  work_gyro_.resize(n);
  work_accel_.resize(n);
  output_.hand = options_.hand;
  output_.active = false;
}

// --- Input -------------------------------------------------------------------

bool VistTracker::add_imu(const TimedImuSample& s) {
  ++stats_.imu_samples;
  const int k = s.sample.sensor_id < segment_of_sensor_.size() ? segment_of_sensor_[s.sample.sensor_id] : -1;
  if (k < 0) {
    ++stats_.imu_rejected_unknown_sensor;
    return false;
  }
  const auto ks = static_cast<std::size_t>(k);
  const Vec3& a = s.sample.accel_mps2;
  const Vec3& w = s.sample.gyro_radps;
  if (!a.allFinite() || !w.allFinite()) {
    ++stats_.imu_rejected_non_finite;
    return false;
  }
  // Beyond the device's range is not a reading; a clipped gyro has lost the
  // attitude. A clipped accelerometer still leaves a good gyro (accel_clipped).
  if ((s.gyro_clipped && options_.reject_saturated) || a.cwiseAbs().maxCoeff() > options_.max_abs_accel_mps2 ||
      w.cwiseAbs().maxCoeff() > options_.max_abs_gyro_radps) {
    ++stats_.imu_rejected_saturated;
    return false;
  }
  if (s.accel_clipped) ++stats_.imu_accel_clipped;
  // Even an IMU's first sample waits for its second (one sample of latency at
  // start): a far-future first stamp would otherwise make every later sample
  // look out of order and stop the fusion for good.
  TimestampGuard& guard = imu_time_guards_[ks];
  const TimestampGuard::Step step = guard.check(s.time_ns);
  bool fresh = false;
  if (step.reject_held) ++stats_.imu_rejected_time_jump;
  if (step.release_held) fresh = accept_imu(ks, imu_held_[ks]);
  if (step.hold) {
    imu_held_[ks] = s;
    return fresh;
  }
  if (!step.accept) {
    ++stats_.imu_rejected_out_of_order;
    return fresh;
  }
  return accept_imu(ks, s) || fresh;
}

bool VistTracker::accept_imu(std::size_t ks, const TimedImuSample& s) {
  const Vec3& a = s.sample.accel_mps2;
  const Vec3& w = s.sample.gyro_radps;
  last_sample_ns_[ks] = s.time_ns;
  last_gyro_[ks] = w;
  last_accel_[ks] = a;
  queue_.push_back(s);
  newest_imu_ns_ = have_imu_ ? std::max(newest_imu_ns_, s.time_ns) : s.time_ns;
  have_imu_ = true;
  advance();
  if (!filter_.initialized()) return false;
  // A new output once every IMU has reported past the previous output (once per tick).
  const TimeNs half_period = 5'000'000;
  for (TimeNs t : last_sample_ns_) {
    if (t <= output_.time_ns + half_period) return false;
  }
  update_output();
  return true;
}

void VistTracker::add_stereo_frame(TimeNs capture_time_ns, const MarkerObservations& left,
                                   const MarkerObservations& right, const Pose& T_world_leftcam) {
  ++stats_.frames;
  if (filter_.initialized() && capture_time_ns <= core_time_ns_) {
    if (capture_time_ns == last_fused_ns_) {
      ++stats_.frames_duplicate;
    } else {
      ++stats_.frames_late;
    }
    return;
  }
  auto it = std::find_if(frames_.begin(), frames_.end(),
                         [&](const PendingFrame& f) { return f.capture_ns >= capture_time_ns; });
  if (it != frames_.end() && it->capture_ns == capture_time_ns) {
    ++stats_.frames_duplicate;
    return;
  }
  PendingFrame f;
  f.capture_ns = capture_time_ns;
  f.left = left;
  f.right = right;
  f.T_world_leftcam = T_world_leftcam;
  frames_.insert(it, std::move(f));
  advance();
  if (filter_.initialized()) update_output();
}

// --- Core --------------------------------------------------------------------

void VistTracker::integrate_queued_until(TimeNs t_ns) {
  std::size_t w = 0;
  for (std::size_t r = 0; r < queue_.size(); ++r) {
    const TimedImuSample& s = queue_[r];
    if (s.time_ns > t_ns) {
      queue_[w++] = s;
      continue;
    }
    const auto k = static_cast<std::size_t>(segment_of_sensor_[s.sample.sensor_id]);
    if (options_.use_imu) {
      filter_.propagate(k, s.time_ns, s.sample.gyro_radps, s.sample.accel_mps2, s.accel_clipped);
    } else {
      const SegmentState& st = filter_.state(k);
      const Vec3 f_rest = st.q_world_imu.conjugate() * Vec3(0.0, options_.filter.gravity_mps2, 0.0);
      filter_.propagate(k, s.time_ns, st.gyro_bias_radps, f_rest + st.accel_bias_mps2);
    }
  }
  queue_.resize(w);
}

Vec3 VistTracker::mean_accel(std::size_t segment, TimeNs around_ns) const {
  Vec3 sum = Vec3::Zero();
  int n = 0;
  const TimeNs window = 100'000'000;
  for (const auto& s : queue_) {
    if (segment_of_sensor_[s.sample.sensor_id] != static_cast<int>(segment)) continue;
    if (s.time_ns < around_ns - window || s.time_ns > around_ns + window / 2) continue;
    sum += s.sample.accel_mps2;
    ++n;
  }
  return n > 0 ? Vec3(sum / n) : last_accel_[segment];
}

void VistTracker::advance() {
  const TimeNs coverage_slack = 30'000'000;  // do not stall forever on one silent IMU
  while (!frames_.empty()) {
    PendingFrame& f = frames_.front();
    bool covered = have_imu_ && newest_imu_ns_ >= f.capture_ns;
    for (TimeNs t : last_sample_ns_) covered = covered && (t >= f.capture_ns || newest_imu_ns_ - f.capture_ns > coverage_slack);
    if (!covered) break;
    if (filter_.initialized()) {
      integrate_queued_until(f.capture_ns);
      filter_.propagate_all_to(f.capture_ns);
      core_time_ns_ = f.capture_ns;
    }
    process_frame(f);
    frames_.erase(frames_.begin());
  }
  if (!have_imu_) return;
  const TimeNs limit = newest_imu_ns_ - seconds_to_ns(options_.max_frame_latency_s);
  if (filter_.initialized()) {
    if (limit > core_time_ns_ && (frames_.empty() || frames_.front().capture_ns > limit)) {
      integrate_queued_until(limit);
      core_time_ns_ = limit;
    }
  } else {
    // Keep a second of samples for the gravity-based acquisition.
    const TimeNs keep_from = newest_imu_ns_ - kNsPerS;
    std::erase_if(queue_, [&](const TimedImuSample& s) { return s.time_ns < keep_from; });
    std::erase_if(frames_, [&](const PendingFrame& f) { return f.capture_ns < limit; });
  }
}

void VistTracker::process_frame(PendingFrame& f) {
  matcher_.match(f.left, f.right, points_);
  observations_.clear();
  for (const auto& p : points_) {
    observations_.push_back({static_cast<std::uint8_t>(p.hue), p.p_in_leftcam, p.cov_p_in_leftcam});
  }
  stats_.stereo_points += points_.size();
  last_frame_ = {};
  last_frame_.capture_time_ns = f.capture_ns;
  last_frame_.stereo_points = points_.size();

  if (!filter_.initialized()) {
    if (points_.size() >= options_.min_acquisition_points && acquire(f, false)) {
      ++stats_.acquisitions;
      last_frame_.acquired = true;
    } else {
      ++stats_.frames_before_init;
    }
    return;
  }
  if (!options_.use_vision) {
    if (options_.use_constraints) last_frame_.correction = filter_.correct({}, true);
    return;
  }
  if (f.capture_ns - last_seen_ns_ > seconds_to_ns(options_.lost_after_s) &&
      points_.size() >= options_.min_acquisition_points) {
    if (acquire(f, true)) {
      ++stats_.reacquisitions;
      last_frame_.acquired = true;
      return;
    }
  }
  const std::size_t n = fuse_frame(filter_, f.T_world_leftcam, last_frame_.correction);
  last_frame_.correspondences = n;
  stats_.correspondences += n;
  stats_.markers_fused += last_frame_.correction.markers_used;
  stats_.markers_gated += last_frame_.correction.markers_gated;
  const auto& c = last_frame_.correction;
  if (c.markers_used >= 3) last_seen_ns_ = f.capture_ns;
  if (c.markers_used + c.markers_gated > 0) {
    // A wrong lock shows as corresponded markers the filter keeps rejecting.
    const double gated = static_cast<double>(c.markers_gated) / static_cast<double>(c.markers_used + c.markers_gated);
    gated_fraction_ = 0.8 * gated_fraction_ + 0.2 * gated;
  }
  ++stats_.frames_fused;
  last_fused_ns_ = f.capture_ns;
  if (gated_fraction_ > options_.max_gated_fraction && f.capture_ns - acquired_ns_ > seconds_to_ns(0.5) &&
      points_.size() >= options_.min_acquisition_points) {
    // Keep the calibration only if the hand had been tracked well for a while before.
    const bool keep = f.capture_ns - acquired_ns_ > seconds_to_ns(5.0);
    logger().debug("VIST: {:.0f} % of corresponded markers rejected; re-acquiring", 100 * gated_fraction_);
    if (acquire(f, keep)) {
      ++stats_.reacquisitions;
      last_frame_.acquired = true;
    }
  }
}

std::size_t VistTracker::correspond(const Pose& T_world_leftcam, std::span<const SegmentState> states,
                                    CorrespondenceSearch& search, CorrespondenceResult& result) {
  update_placed_markers(states);
  reconstruct(states, {}, 0, work_pose_);
  const bool with_cov = &search == &search_;
  const Status st = search.search(work_pose_, T_world_leftcam, rig_, placed_,
                                  with_cov ? std::span<const Mat3>(marker_cov_) : std::span<const Mat3>{},
                                  observations_, result);
  if (!st) {
    result.clear();
    return 0;
  }
  return result.assignments.size();
}

void VistTracker::fuse_correspondences(VistFilter& filter, const Pose& T_world_leftcam,
                                       const CorrespondenceResult& result, CorrectionStats& st) {
  measurements_.clear();
  const Mat3 R = T_world_leftcam.q.toRotationMatrix();
  const auto& markers = filter.model().markers;
  for (const auto& a : result.assignments) {
    // Filter markers are in glove order (VistModel::build), so the glove index is the filter index.
    if (a.marker >= markers.size() || markers[a.marker].glove_index != a.marker) continue;
    const Observation3D& o = observations_[a.observation];
    measurements_.push_back({a.marker, T_world_leftcam * o.p_in_leftcam, R * o.covariance * R.transpose()});
  }
  st = filter.correct(measurements_, options_.use_constraints);
}

std::size_t VistTracker::fuse_frame(VistFilter& filter, const Pose& T_world_leftcam, CorrectionStats& st) {
  std::copy(filter.states().begin(), filter.states().end(), work_states_.begin());
  for (std::size_t j = 0; j < marker_cov_.size(); ++j) marker_cov_[j] = filter.marker_covariance_in_world(j);
  const std::size_t n = correspond(T_world_leftcam, work_states_, search_, corr_);
  fuse_correspondences(filter, T_world_leftcam, corr_, st);
  return n;
}

void VistTracker::update_placed_markers(std::span<const SegmentState> states) {
  const auto& m = filter_.model();
  for (std::size_t j = 0; j < m.markers.size(); ++j) {
    const auto& fm = m.markers[j];
    const auto& seg = m.segments[fm.segment];
    placed_[j].p_in_segment = seg.p_imu_in_segment + states[fm.segment].scale.cwiseProduct(fm.lever_in_segment);
  }
}

bool VistTracker::acquire(const PendingFrame& f, bool keep_calibration) {
  const auto& m = filter_.model();
  const std::size_t n = m.segments.size();
  // Gravity in each IMU frame, averaged around the capture time.
  std::vector<Quat> q_tilt(n);
  for (std::size_t k = 0; k < n; ++k) {
    const Vec3 a = mean_accel(k, f.capture_ns);
    if (!(a.norm() > 1.0)) return false;  // no usable IMU data yet
    q_tilt[k] = Quat::FromTwoVectors(a.normalized(), Vec3::UnitY());  // world up from the IMU's "up"
  }
  const auto T_wrist_rest = hand_model_.joint_poses_in_wrist(options_.hand, HandAngles{});
  const auto d = static_cast<std::size_t>(dorsum_);

  Vec3 obs_centroid = Vec3::Zero();
  for (const auto& o : observations_) obs_centroid += f.T_world_leftcam * o.p_in_leftcam;
  obs_centroid /= static_cast<double>(observations_.size());
  const Vec3 cam_in_world = f.T_world_leftcam.p;

  candidates_.clear();
  for (int h = 0; h < options_.acquisition_heading_steps; ++h) {
    const double psi = 2.0 * std::numbers::pi * h / options_.acquisition_heading_steps;
    for (std::size_t k = 0; k < n; ++k) {
      SegmentState& s = work_states_[k];
      const SegmentState& cur = filter_.state(k);
      s = SegmentState{};
      if (keep_calibration) {
        s.gyro_bias_radps = cur.gyro_bias_radps;
        s.accel_bias_mps2 = cur.accel_bias_mps2;
        s.scale = cur.scale;
        s.q_imu_segment = cur.q_imu_segment;
      } else {
        s.q_imu_segment = m.segments[k].q_segment_imu.conjugate();
      }
    }
    // Dorsum: its gravity tilt, then the candidate heading.
    work_states_[d].q_world_imu = (heading(psi) * q_tilt[d]).normalized();
    const Quat q_world_wrist = work_states_[d].q_world_segment();
    // Every other segment: its own tilt, at the heading nearest to the rest pose of the hand.
    for (std::size_t k = 0; k < n; ++k) {
      if (k == d) continue;
      const Quat q_guess = q_world_wrist * T_wrist_rest[index_of(m.segments[k].segment)].q *
                           work_states_[k].q_imu_segment.conjugate();
      const Mat3 M = q_guess.toRotationMatrix() * q_tilt[k].toRotationMatrix().transpose();
      work_states_[k].q_world_imu = (heading(nearest_heading(M)) * q_tilt[k]).normalized();
    }
    // Positions down the kinematic chain from the dorsum at the origin.
    std::vector<bool> placed(n, false);
    work_states_[d].p_imu_in_world = work_states_[d].q_world_segment() *
                                     work_states_[d].scale.cwiseProduct(m.segments[d].p_imu_in_segment);
    placed[d] = true;
    for (bool progress = true; progress;) {
      progress = false;
      for (const auto& c : m.position_constraints) {
        if (!placed[c.parent] || placed[c.child]) continue;
        const Vec3 joint = work_states_[c.parent].point_in_world(c.lever_in_parent);
        SegmentState& s = work_states_[c.child];
        s.p_imu_in_world = joint + s.q_world_segment() * s.scale.cwiseProduct(m.segments[c.child].p_imu_in_segment);
        placed[c.child] = progress = true;
      }
    }
    for (std::size_t k = 0; k < n; ++k) {
      if (!placed[k]) work_states_[k].p_imu_in_world = work_states_[d].p_imu_in_world;
    }
    // Move the hand so the markers facing the camera sit on the observations.
    Vec3 pred = Vec3::Zero();
    int count = 0;
    for (const auto& fm : m.markers) {
      const SegmentState& s = work_states_[fm.segment];
      const Vec3 p = s.point_in_world(fm.lever_in_segment);
      const Vec3 normal = s.q_world_segment() * m.placed_nominal[fm.glove_index].normal_in_segment;
      if (normal.dot(cam_in_world - p) <= 0.0) continue;
      pred += p;
      ++count;
    }
    if (count == 0) continue;
    const Vec3 shift = obs_centroid - pred / count;
    for (auto& s : work_states_) s.p_imu_in_world += shift;

    const std::size_t matches = correspond(f.T_world_leftcam, work_states_, acquisition_search_, corr_);
    Candidate cand;
    cand.matches = matches;
    cand.score = static_cast<double>(matches);
    for (const auto& a : corr_.assignments) cand.score += 0.01 * a.posterior;
    const Vec3 eta_in_world = f.T_world_leftcam.q * corr_.translation_in_leftcam[0];
    cand.states.assign(work_states_.begin(), work_states_.end());
    for (auto& s : cand.states) s.p_imu_in_world += eta_in_world;
    candidates_.push_back(std::move(cand));
  }
  if (candidates_.empty()) return false;
  // Verify the best guesses the way they will be used: initialise a filter on
  // each and iterate correspondence and correction on this frame (the first
  // guess of the fingers is coarse, each pass brings more markers within
  // reach). The winner explains most markers with fewest rejected.
  std::sort(candidates_.begin(), candidates_.end(),
            [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
  double best = -1e300;
  bool found = false;
  const std::size_t verify = std::min<std::size_t>(candidates_.size(), 3);
  for (std::size_t c = 0; c < verify; ++c) {
    if (candidates_[c].matches < options_.min_acquisition_matches) continue;
    VistFilter trial = filter_;
    const Status st = keep_calibration ? trial.reinitialize_pose(f.capture_ns, candidates_[c].states)
                                       : trial.initialize(f.capture_ns, candidates_[c].states);
    if (!st) continue;
    CorrectionStats cs;
    for (int pass = 0; pass < 3; ++pass) fuse_frame(trial, f.T_world_leftcam, cs);
    const double score = static_cast<double>(cs.markers_used) - 2.0 * static_cast<double>(cs.markers_gated) -
                         0.01 * (cs.markers_used > 0 ? cs.marker_nis_sum / cs.markers_used : 0.0);
    if (cs.markers_used >= options_.min_acquisition_matches && score > best) {
      best = score;
      acquisition_filter_ = std::move(trial);
      last_frame_.correction = cs;
      found = true;
    }
  }
  if (!found) return false;
  filter_ = std::move(*acquisition_filter_);
  acquisition_filter_.reset();
  // Samples before the acquisition cannot be integrated any more.
  std::erase_if(queue_, [&](const TimedImuSample& s) { return s.time_ns <= f.capture_ns; });
  core_time_ns_ = f.capture_ns;
  last_seen_ns_ = f.capture_ns;
  last_fused_ns_ = f.capture_ns;
  acquired_ns_ = f.capture_ns;
  gated_fraction_ = 0.0;
  ++stats_.frames_fused;
  return true;
}

// --- Output ------------------------------------------------------------------

void VistTracker::update_output() {
  const auto& m = filter_.model();
  const std::size_t n = m.segments.size();
  std::copy(filter_.states().begin(), filter_.states().end(), work_states_.begin());
  // Nominal-only propagation of a copy through the samples the core has not
  // integrated yet (same discretisation as the filter), then to the newest time.
  std::vector<TimeNs>& t = work_times_;
  for (std::size_t k = 0; k < n; ++k) {
    t[k] = filter_.time_ns(k);
    filter_.last_sample(k, work_gyro_[k], work_accel_[k]);
  }
  const Vec3 g_world(0.0, -options_.filter.gravity_mps2, 0.0);
  auto step = [&](std::size_t k, TimeNs to, const Vec3& gyro, const Vec3& accel) {
    if (to <= t[k]) return;
    const double dt = 1e-9 * static_cast<double>(to - t[k]);
    SegmentState& s = work_states_[k];
    if (options_.use_imu) {
      VistFilter::integrate_nominal(s, dt, 0.5 * (work_gyro_[k] + gyro), 0.5 * (work_accel_[k] + accel), g_world);
    } else {
      const Vec3 f_rest = s.q_world_imu.conjugate() * Vec3(0.0, options_.filter.gravity_mps2, 0.0);
      VistFilter::integrate_nominal(s, dt, s.gyro_bias_radps, f_rest + s.accel_bias_mps2, g_world);
    }
    work_gyro_[k] = gyro;
    work_accel_[k] = accel;
    t[k] = to;
  };
  for (const auto& s : queue_) {
    step(static_cast<std::size_t>(segment_of_sensor_[s.sample.sensor_id]), s.time_ns, s.sample.gyro_radps,
         s.sample.accel_mps2);
  }
  for (std::size_t k = 0; k < n; ++k) {
    const Vec3 g = work_gyro_[k], a = work_accel_[k];
    step(k, newest_imu_ns_, g, a);
    work_rates_[k] = options_.use_imu ? Vec3(work_gyro_[k] - work_states_[k].gyro_bias_radps) : Vec3::Zero();
  }
  reconstruct(work_states_, work_rates_, newest_imu_ns_, output_);
}

void VistTracker::ensure_shape(const SegmentState& dorsum) {
  // The hand model for the joints the glove does not instrument follows the
  // dorsum's calibrated size: +Z is along the hand, +X across it.
  const double length_scale = dorsum.scale.z(), width_scale = dorsum.scale.x();
  if (std::abs(length_scale - model_length_scale_) < 0.005 && std::abs(width_scale - model_width_scale_) < 0.005) {
    return;
  }
  const auto& nominal = filter_.model().nominal_shape;
  auto shape = HandShape::from_measurements(nominal.hand_length_m * length_scale, nominal.hand_width_m * width_scale);
  if (!shape) return;  // implausible intermediate estimate: keep the previous model
  hand_model_ = HandModel(*shape);
  model_length_scale_ = length_scale;
  model_width_scale_ = width_scale;
}

void VistTracker::reconstruct(std::span<const SegmentState> states, std::span<const Vec3> rates_in_imu, TimeNs t_ns,
                              HandPose& out) {
  const auto& m = filter_.model();
  const auto d = static_cast<std::size_t>(dorsum_);
  ensure_shape(states[d]);
  std::array<int, kHandJointCount> seg_of_joint;
  seg_of_joint.fill(-1);
  std::array<Pose, kHandJointCount> T_world_seg{};
  for (std::size_t k = 0; k < m.segments.size(); ++k) {
    const auto j = index_of(m.segments[k].segment);
    seg_of_joint[j] = static_cast<int>(k);
    T_world_seg[j] = states[k].T_world_segment(m.segments[k].p_imu_in_segment);
  }
  const Pose T_world_wrist = T_world_seg[index_of(HandJoint::wrist)];

  // Angles: the instrumented segments' orientations; an uninstrumented bone
  // keeps its parent's orientation (angle 0) and gets its angle from a synergy.
  HandPose& probe = work_pose_probe_;
  probe = hand_model_.forward(options_.hand, HandAngles{}, T_world_wrist, t_ns);
  for (std::size_t f = 0; f < kFingerCount; ++f) {
    const auto fj = finger_joints(static_cast<Finger>(f));
    Quat q;
    bool have = false;
    for (std::size_t i = 0; i < fj.count; ++i) {
      const auto j = index_of(fj.joints[i]);
      if (seg_of_joint[j] >= 0) {
        q = T_world_seg[j].q;
        have = true;
      }
      if (have) probe.T_world_joint[j].q = q;
    }
  }
  HandAngles a = hand_model_.inverse(probe).angles;
  const Synergies syn{};
  auto dof = [&](HandDof x) -> double& { return a[index_of(x)]; };
  auto instrumented = [&](HandJoint j) { return seg_of_joint[index_of(j)] >= 0; };
  if (!instrumented(HandJoint::thumb_distal)) dof(HandDof::thumb_ip_flexion) = syn.thumb_ip_from_mcp * dof(HandDof::thumb_mcp_flexion);
  if (!instrumented(HandJoint::index_distal)) dof(HandDof::index_dip_flexion) = syn.dip_from_pip * dof(HandDof::index_pip_flexion);
  if (!instrumented(HandJoint::middle_distal)) dof(HandDof::middle_dip_flexion) = syn.dip_from_pip * dof(HandDof::middle_pip_flexion);
  for (Finger f : {Finger::ring, Finger::little}) {
    const auto fj = finger_joints(f);
    bool any = false;
    for (std::size_t i = 0; i < fj.count; ++i) any = any || instrumented(fj.joints[i]);
    if (any) continue;
    for (std::size_t i = 0; i < 4; ++i) a[first_dof_of(f) + i] = a[first_dof_of(Finger::middle) + i];
  }
  out = hand_model_.forward(options_.hand, a, T_world_wrist, t_ns);

  // Each instrumented segment carries the rest of its finger rigidly: the
  // joints from it to the tip hang off where the filter has it.
  std::array<int, kHandJointCount> anchor;
  anchor.fill(static_cast<int>(d));
  for (std::size_t f = 0; f < kFingerCount; ++f) {
    const auto fj = finger_joints(static_cast<Finger>(f));
    Pose C = Pose::identity();
    int anchor_seg = static_cast<int>(d);
    for (std::size_t i = 0; i < fj.count; ++i) {
      const auto j = index_of(fj.joints[i]);
      if (seg_of_joint[j] >= 0) {
        C = T_world_seg[j] * out.T_world_joint[j].inverse();
        anchor_seg = seg_of_joint[j];
      }
      out.T_world_joint[j] = C * out.T_world_joint[j];
      anchor[j] = anchor_seg;
    }
  }
  // Tracked: what the glove measures (instrumented segments and what is rigid
  // with the dorsum); the rest is modelled: valid, not tracked.
  for (std::size_t j = 0; j < kHandJointCount; ++j) {
    const auto joint = joint_at(j);
    const bool rigid_with_dorsum = joint == HandJoint::wrist || joint == HandJoint::palm ||
                                   joint == HandJoint::index_metacarpal || joint == HandJoint::middle_metacarpal ||
                                   joint == HandJoint::ring_metacarpal || joint == HandJoint::little_metacarpal;
    out.flags[j] = (rigid_with_dorsum || seg_of_joint[j] >= 0) ? kJointFullyTracked : static_cast<std::uint8_t>(kOrientationValid | kPositionValid);
  }
  out.has_velocity = !rates_in_imu.empty();
  if (out.has_velocity) {
    for (std::size_t j = 0; j < kHandJointCount; ++j) {
      const SegmentState& s = states[static_cast<std::size_t>(anchor[j])];
      const Vec3 w_world = s.q_world_imu * rates_in_imu[static_cast<std::size_t>(anchor[j])];
      out.angular_velocity_in_world[j] = w_world;
      out.linear_velocity_in_world[j] = s.v_imu_in_world + w_world.cross(out.T_world_joint[j].p - s.p_imu_in_world);
    }
  }
}

}  // namespace proprio::vist
