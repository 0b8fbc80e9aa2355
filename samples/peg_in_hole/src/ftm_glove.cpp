#include "proprio/peg_in_hole/ftm_glove.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <optional>
#include <vector>

#include "proprio/ftm/ftm_tracker.hpp"
#include "proprio/ftm_sim/ftm_wearer_sim.hpp"
#include "proprio/ftm_sim/wearer_calibration.hpp"

namespace proprio::peg_in_hole {

namespace {
// Truth (disturbance, tracking error) is sampled at the IMUs' 200 Hz.
constexpr std::int64_t kTruthEveryTicks = 5;
// A device current is passed on when it moved by more than this: the
// environment keeps every set_current() for the session, and 2 mA is 0.4 %
// of a stalled motor's current (far below what changes a field by 1 nT).
constexpr double kCurrentStepA = 0.002;
// The participant's commands carry per-tick motor noise; a glove's IMUs
// differentiate twice, and 0.1 mm of 1 kHz jitter reads as ~100 m/s² (and
// its rotational twin saturates the gyros), which no arm does. The wearer's
// true hand is the command through two cascaded first-order low-passes
// (ASSUMED 25 Hz each: above voluntary movement and tremor, 2 x 6.4 ms of
// delay), so its acceleration stays physical.
constexpr double kHandSmoothingHz = 25.0;
constexpr std::array<Finger, 3> kDeviceFingers = {Finger::thumb, Finger::index, Finger::middle};
// FtmGloveAblation::truth_delayed_30ms, in world ticks (1 ms).
constexpr std::size_t kAblationDelayTicks = 30;

constexpr std::array<std::pair<FtmGloveAblation, const char*>, 12> kAblationNames = {{
    {FtmGloveAblation::none, "none"},
    {FtmGloveAblation::truth, "truth"},
    {FtmGloveAblation::truth_angles, "truth_angles"},
    {FtmGloveAblation::truth_wrist, "truth_wrist"},
    {FtmGloveAblation::truth_wrist_position, "truth_wrist_position"},
    {FtmGloveAblation::truth_wrist_rotation, "truth_wrist_rotation"},
    {FtmGloveAblation::truth_thumb, "truth_thumb"},
    {FtmGloveAblation::truth_index_middle, "truth_index_middle"},
    {FtmGloveAblation::truth_ring_little, "truth_ring_little"},
    {FtmGloveAblation::truth_distal, "truth_distal"},
    {FtmGloveAblation::truth_delayed_30ms, "truth_delayed_30ms"},
    {FtmGloveAblation::true_mountings, "true_mountings"},
}};

void copy_finger_angles(HandAngles& to, const HandAngles& from, Finger f) {
  for (std::size_t i = first_dof_of(f); i < first_dof_of(f) + 4; ++i) to[i] = from[i];
}
}  // namespace

const char* to_string(FtmGloveAblation a) noexcept {
  for (const auto& [v, name] : kAblationNames) {
    if (v == a) return name;
  }
  return "?";
}

Result<FtmGloveAblation> parse_ftm_glove_ablation(std::string_view name) {
  std::string all;
  for (const auto& [v, n] : kAblationNames) {
    if (name == n) return v;
    all += all.empty() ? n : fmt::format(", {}", n);
  }
  return make_error(Errc::invalid_argument, fmt::format("FTM glove ablation '{}': use one of {}", name, all));
}

Status SimulatedFtmGloveOptions::validate() const {
  if (!std::isfinite(between_trials_s) || between_trials_s < 0.1 || between_trials_s > 10.0) {
    return make_error(Errc::invalid_argument,
                      fmt::format("SimulatedFtmGloveOptions.between_trials_s = {}: use 0.1-10 s", between_trials_s));
  }
  if (std::string_view(to_string(ablate)) == "?") {
    return make_error(Errc::invalid_argument, fmt::format("SimulatedFtmGloveOptions.ablate = {}: not a FtmGloveAblation",
                                                          static_cast<int>(ablate)));
  }
  return Status::success();
}

std::string SimulatedFtmGloveOptions::describe() const {
  return fmt::format("simulated FTM glove: seed {}, {:.1f} s back to rest between trials, device leads {}{}", seed,
                     between_trials_s, device_leads ? "on" : "off",
                     ablate == FtmGloveAblation::none
                         ? ""
                         : fmt::format(", DIAGNOSTIC ablation {} (not the FTM as simulated)", to_string(ablate)));
}

struct SimulatedFtmGlove::Impl {
  SimulatedFtmGloveOptions options;
  std::unique_ptr<ftm_sim::FtmWearerSimulator> wearer;
  std::string calibration_text;  // what the glove's calibration found (describe())
  // Both trackers see every sample, so switching "without AA" between
  // trials never starts a filter from scratch.
  std::optional<ftm::FtmTracker> with_aa, without_aa;
  bool track_abduction = true;
  TimeNs offset_ns = 0;     // wearer time of world time 0 in this trial
  TimeNs fed_until_ns = 0;  // wearer time the trackers have seen
  std::optional<HandCommand> last;
  std::vector<ftm::FtmEvent> events;
  HandPose estimate;
  std::array<double, 3> current_sent{};
  // The smoother's two stages (valid once started).
  bool smooth_started = false;
  std::array<HandCommand, 2> smooth{};
  HandCommand smoothed(const HandCommand& in) {
    if (!smooth_started) {
      smooth = {in, in};
      smooth_started = true;
      return in;
    }
    const double alpha = 1.0 - std::exp(-2.0 * 3.14159265358979323846 * kHandSmoothingHz * 1e-3);
    const HandCommand* src = &in;
    for (HandCommand& st : smooth) {
      st.T_world_wrist = interpolate(st.T_world_wrist, src->T_world_wrist, alpha);
      for (std::size_t i = 0; i < kHandDofCount; ++i) st.angles[i] += alpha * (src->angles[i] - st.angles[i]);
      src = &st;
    }
    return smooth[1];
  }
  // Trial accumulators.
  FtmTrialFigures figures;
  std::array<std::uint64_t, kFtmCompassCount> compass_samples{}, compass_flagged{}, truth_disturbed{};
  double angle_err_sum = 0.0, wrist_err_sum = 0.0, wrist_angle_err_sum = 0.0;
  Vec3 wrist_rotvec_sum = Vec3::Zero();
  std::uint64_t err_samples = 0;
  // The true hand's last kAblationDelayTicks + 1 ticks (truth_delayed_30ms only).
  std::deque<HandCommand> hand_history;

  // The diagnostic override (FtmGloveAblation) of the tracked hand `out`.
  HandCommand ablated(const HandCommand& out, const HandCommand& hand) {
    HandCommand a = out;
    switch (options.ablate) {
      case FtmGloveAblation::none:
      case FtmGloveAblation::true_mountings: break;  // applied to the calibration (create())
      case FtmGloveAblation::truth: a = hand; break;
      case FtmGloveAblation::truth_angles: a.angles = hand.angles; break;
      case FtmGloveAblation::truth_wrist: a.T_world_wrist = hand.T_world_wrist; break;
      case FtmGloveAblation::truth_wrist_position: a.T_world_wrist.p = hand.T_world_wrist.p; break;
      case FtmGloveAblation::truth_wrist_rotation: a.T_world_wrist.q = hand.T_world_wrist.q; break;
      case FtmGloveAblation::truth_thumb: copy_finger_angles(a.angles, hand.angles, Finger::thumb); break;
      case FtmGloveAblation::truth_index_middle:
        copy_finger_angles(a.angles, hand.angles, Finger::index);
        copy_finger_angles(a.angles, hand.angles, Finger::middle);
        break;
      case FtmGloveAblation::truth_ring_little:
        copy_finger_angles(a.angles, hand.angles, Finger::ring);
        copy_finger_angles(a.angles, hand.angles, Finger::little);
        break;
      case FtmGloveAblation::truth_distal:
        for (Finger f : {Finger::thumb, Finger::index, Finger::middle, Finger::ring, Finger::little}) {
          a.angles[first_dof_of(f) + 3] = hand.angles[first_dof_of(f) + 3];
        }
        break;
      case FtmGloveAblation::truth_delayed_30ms:
        hand_history.push_back(hand);
        while (hand_history.size() > kAblationDelayTicks + 1) hand_history.pop_front();
        a = hand_history.front();
        break;
    }
    return a;
  }

  void feed_until(TimeNs t) {
    events.clear();
    wearer->advance(t, events);
    for (const ftm::FtmEvent& e : events) {
      with_aa->push(e);
      without_aa->push(e);
      if (e.kind == ftm::FtmEvent::Kind::imu && e.imu.mag_fresh && e.index < kFtmCompassCount) {
        ++compass_samples[e.index];
        if (with_aa->mag_disturbed(static_cast<ftm::FtmImu>(e.index))) ++compass_flagged[e.index];
      }
    }
    fed_until_ns = std::max(fed_until_ns, t);
  }
  // Drive the wearer through [from, to] (wearer time) along pose(s), s in [0, 1], at 1 ms.
  template <class F>
  void drive_span(TimeNs from, TimeNs to, F&& pose) {
    for (TimeNs t = from; t <= to; t += kNsPerMillisecond) {
      const double s = to > from ? static_cast<double>(t - from) / static_cast<double>(to - from) : 1.0;
      const HandCommand c = smoothed(pose(s));
      wearer->drive(t, c.T_world_wrist, c.angles);
      feed_until(t - ftm_sim::FtmWearerSimulator::kDrivenLeadNs);
    }
  }
};

SimulatedFtmGlove::SimulatedFtmGlove(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SimulatedFtmGlove::~SimulatedFtmGlove() = default;

Result<std::unique_ptr<SimulatedFtmGlove>> SimulatedFtmGlove::create(const HandShape& participant_hand,
                                                                      const SimulatedFtmGloveOptions& options) {
  if (Status s = options.validate(); !s) return s.error();
  ftm_sim::FtmWearerOptions wo;
  wo.seed = options.seed;
  // The participant's size, without its thumb pronation: the FTM's 20-DOF
  // kinematics (and its calibration's known poses) have none, and a wearer
  // whose thumb metacarpal rests pronated 90° would have its CMC flexion and
  // abduction decoded swapped. The study's world keeps the pronated hand;
  // the angles are the same 20 numbers on both.
  wo.subject.hand_length_m = participant_hand.hand_length_m;
  wo.subject.hand_width_m = participant_hand.hand_width_m;
  wo.driven_task = true;
  wo.task_s = 86400.0;
  // The devices' currents come from the study's emulated devices only.
  wo.magnetic.enable_contact_current = false;
  wo.magnetic.enable_device_leads = options.device_leads;
  auto wearer = ftm_sim::FtmWearerSimulator::create(wo);
  if (!wearer) return wearer.error().with_context("simulated FTM wearer");
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  impl->wearer = std::move(*wearer);
  auto cal = ftm_sim::calibrate_from_wearer(*impl->wearer);
  if (!cal) return cal.error().with_context("calibrating the simulated FTM wearer");
  if (options.ablate == FtmGloveAblation::true_mountings) {
    const auto mounts = impl->wearer->imus().mountings();
    for (std::size_t i = 0; i < ftm::kFtmImuCount && i < mounts.size(); ++i) {
      cal->outcome.calibration.q_imu_segment[i] = mounts[i].T_segment_imu.q.conjugate();
    }
  }
  ftm::FtmTrackerOptions to;
  auto a = ftm::FtmTracker::create(to, cal->outcome.calibration);
  if (!a) return a.error();
  to.track_abduction = false;
  auto b = ftm::FtmTracker::create(to, cal->outcome.calibration);
  if (!b) return b.error();
  impl->calibration_text = cal->outcome.calibration.describe();
  // The calibration's mounting error per IMU against the simulator's true
  // mounting (q_imu_segment is the segment's frame in the IMU's): the
  // dorsum's error tilts the whole tracked hand.
  {
    const auto mounts = impl->wearer->imus().mountings();
    for (std::size_t i = 0; i < ftm::kFtmImuCount && i < mounts.size(); ++i) {
      const Quat q_true = mounts[i].T_segment_imu.q.conjugate();
      impl->calibration_text += fmt::format(
          "; IMU {} mount error {:.1f} deg (true misalignment {:.1f} deg)", i,
          rad_to_deg(cal->outcome.calibration.q_imu_segment[i].angularDistance(q_true)),
          rad_to_deg(mounts[i].misalignment_rad));
    }
  }
  impl->with_aa.emplace(std::move(*a));
  impl->without_aa.emplace(std::move(*b));
  for (const ftm::FtmEvent& e : cal->events) {
    impl->with_aa->push(e);
    impl->without_aa->push(e);
  }
  impl->fed_until_ns = impl->wearer->task_begin_ns() - 1;
  return std::unique_ptr<SimulatedFtmGlove>(new SimulatedFtmGlove(std::move(impl)));
}

Status SimulatedFtmGlove::begin_trial(const HandCommand& first, bool track_abduction) {
  Impl& m = *impl_;
  m.track_abduction = track_abduction;
  const TimeNs start = std::max(m.wearer->task_begin_ns(), m.wearer->driven_until_ns() + kNsPerMillisecond);
  TimeNs end = 0;
  if (!m.last) {
    // From the last calibration pose into the task: the simulator's own
    // minimum-jerk transition, then half a second at rest.
    const auto& cal = m.wearer->options().calibration;
    end = start + seconds_to_ns((cal.enabled ? cal.task_transition_s : 0.0) + 0.5);
    m.drive_span(start, end, [&first](double) { return first; });
  } else {
    const HandCommand from = *m.last;
    end = start + seconds_to_ns(m.options.between_trials_s);
    m.drive_span(start, end, [&](double s) {
      const double k = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);  // minimum jerk
      HandCommand c;
      c.T_world_wrist = interpolate(from.T_world_wrist, first.T_world_wrist, k);
      for (std::size_t i = 0; i < kHandDofCount; ++i) c.angles[i] = from.angles[i] + k * (first.angles[i] - from.angles[i]);
      return c;
    });
  }
  if (end >= m.wearer->end_ns()) {
    return make_error(Errc::out_of_range, "the simulated FTM wearer's session (a day of simulated time) is over");
  }
  m.offset_ns = end;
  m.last = first;
  m.hand_history.clear();
  m.figures = {};
  m.compass_samples = {};
  m.compass_flagged = {};
  m.truth_disturbed = {};
  m.angle_err_sum = m.wrist_err_sum = m.wrist_angle_err_sum = 0.0;
  m.wrist_rotvec_sum = Vec3::Zero();
  m.err_samples = 0;
  return Status::success();
}

HandCommand SimulatedFtmGlove::track(TimeNs world_t_ns, const HandCommand& truth) {
  Impl& m = *impl_;
  const TimeNs t = m.offset_ns + world_t_ns;
  // What the hand really does (smoothed command): the wearer's truth, and
  // what the tracked hand is judged against.
  const HandCommand hand = t > m.wearer->driven_until_ns() ? m.smoothed(truth) : m.smooth[1];
  if (t > m.wearer->driven_until_ns()) m.wearer->drive(t, hand.T_world_wrist, hand.angles);
  m.last = truth;
  m.feed_until(t - ftm_sim::FtmWearerSimulator::kDrivenLeadNs);
  const ftm::FtmTracker& tracker = m.track_abduction ? *m.with_aa : *m.without_aa;
  tracker.estimate(m.estimate);
  HandCommand out;
  out.angles = tracker.angles();
  out.T_world_wrist = m.estimate.active ? m.estimate.joint(HandJoint::wrist) : truth.T_world_wrist;

  if ((world_t_ns / kNsPerMillisecond) % kTruthEveryTicks == 0) {
    const auto tr = m.wearer->truth_at(t - ftm_sim::FtmWearerSimulator::kDrivenLeadNs);
    for (std::size_t i = 0; i < kFtmCompassCount; ++i) {
      m.figures.max_disturbance_uT[i] = std::max(m.figures.max_disturbance_uT[i], tr.mag_disturbance_uT[i]);
      m.truth_disturbed[i] += tr.mag_disturbed[i] ? 1U : 0U;
    }
    const auto tracked = tracker.dof_tracked();
    double sum = 0.0;
    int n = 0;
    for (std::size_t i = 0; i < kHandDofCount; ++i) {
      if (!tracked[i]) continue;
      sum += std::abs(out.angles[i] - hand.angles[i]);
      ++n;
    }
    if (n > 0) m.angle_err_sum += rad_to_deg(sum / n);
    m.wrist_err_sum += 1e3 * (out.T_world_wrist.p - hand.T_world_wrist.p).norm();
    m.wrist_angle_err_sum += rad_to_deg(out.T_world_wrist.q.angularDistance(hand.T_world_wrist.q));
    const Eigen::AngleAxisd e((hand.T_world_wrist.q.conjugate() * out.T_world_wrist.q).normalized());
    m.wrist_rotvec_sum += e.angle() * e.axis();
    ++m.err_samples;
  }
  return m.ablated(out, hand);
}

void SimulatedFtmGlove::set_device_currents(TimeNs world_t_ns, const std::array<double, kFingerCount>& current_a) {
  Impl& m = *impl_;
  for (std::size_t d = 0; d < kDeviceFingers.size(); ++d) {
    const double a = current_a[static_cast<std::size_t>(kDeviceFingers[d])];
    m.figures.max_current_a[d] = std::max(m.figures.max_current_a[d], a);
    if (std::abs(a - m.current_sent[d]) <= kCurrentStepA) continue;
    // From the next millisecond: the tick that measured it is over.
    m.wearer->set_fingertip_current(kDeviceFingers[d], m.offset_ns + world_t_ns, a);
    m.current_sent[d] = a;
  }
}

FtmTrialFigures SimulatedFtmGlove::end_trial() {
  Impl& m = *impl_;
  FtmTrialFigures f = m.figures;
  f.samples = m.err_samples;
  for (std::size_t i = 0; i < kFtmCompassCount; ++i) {
    f.flagged_fraction[i] =
        m.compass_samples[i] ? static_cast<double>(m.compass_flagged[i]) / static_cast<double>(m.compass_samples[i]) : 0.0;
    f.disturbed_fraction[i] =
        m.err_samples ? static_cast<double>(m.truth_disturbed[i]) / static_cast<double>(m.err_samples) : 0.0;
  }
  if (m.err_samples) {
    f.mean_angle_error_deg = m.angle_err_sum / static_cast<double>(m.err_samples);
    f.mean_wrist_error_mm = m.wrist_err_sum / static_cast<double>(m.err_samples);
    f.mean_wrist_angle_error_deg = m.wrist_angle_err_sum / static_cast<double>(m.err_samples);
    for (int k = 0; k < 3; ++k) {
      f.mean_wrist_rotation_error_in_wrist_deg[static_cast<std::size_t>(k)] =
          rad_to_deg(m.wrist_rotvec_sum[k]) / static_cast<double>(m.err_samples);
    }
  }
  return f;
}

std::string SimulatedFtmGlove::describe() const {
  return impl_->options.describe() + " | " + impl_->wearer->describe() + " | " + impl_->calibration_text;
}

}  // namespace proprio::peg_in_hole
