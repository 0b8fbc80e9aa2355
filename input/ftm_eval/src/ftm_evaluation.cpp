#include "proprio/ftm_eval/ftm_evaluation.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/hand_pose.hpp"
#include "proprio/ftm/ftm_calibration.hpp"
#include "proprio/ftm/ftm_tracker.hpp"
#include "proprio/ftm/imu_bias.hpp"
#include "proprio/ftm/mahony_filter.hpp"
#include "proprio/ftm_sim/ftm_wearer_sim.hpp"
#include "proprio/ftm_sim/wearer_calibration.hpp"
#include "proprio/sim/imu_sim.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::ftm_eval {
namespace {

constexpr std::array<HandDof, 3> kSynergyDofs = {HandDof::thumb_ip_flexion, HandDof::index_dip_flexion,
                                                 HandDof::middle_dip_flexion};
constexpr std::array<HandJoint, 3> kTips = {HandJoint::thumb_tip, HandJoint::index_tip, HandJoint::middle_tip};
// Scored every 20 ms (50 Hz): consecutive 200 Hz frames are strongly
// correlated, more of them would not change the means.
constexpr DurationNs kScorePeriodNs = 20 * kNsPerMillisecond;
// The first second of the task is left out: the transition from the last
// calibration pose into the task's first posture.
constexpr DurationNs kTaskSettleNs = kNsPerSecond;

double wrap_pi(double a) { return std::remainder(a, 2.0 * M_PI); }

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto k = static_cast<std::size_t>(std::clamp(p, 0.0, 1.0) * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

double mean_of(const std::vector<double>& v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  double s = 0.0;
  for (double x : v) s += x;
  return s / static_cast<double>(v.size());
}

// Heading part of the rotation between two world orientations: the twist of
// q_est q_trueᵀ about world up (+Y).
double heading_error_rad(const Quat& q_est, const Quat& q_true) {
  const Quat e = (q_est * q_true.conjugate()).normalized();
  return wrap_pi(2.0 * std::atan2(e.y(), e.w()));
}

FtmCaseResult not_run(FtmCase which, std::string reason) {
  FtmCaseResult r;
  r.which = which;
  r.ran = false;
  r.reason = std::move(reason);
  return r;
}

ftm_sim::FtmWearerOptions wearer_options(const FtmBenchOptions& bench, int subject, std::uint64_t seed,
                                         sim::MotionProtocol protocol, double task_s) {
  ftm_sim::FtmWearerOptions o;
  o.seed = seed;
  o.subject.subject_index = subject;
  o.protocol = protocol;
  o.task_s = task_s;
  o.soft_tissue = bench.soft_tissue;
  return o;
}

// One calibrated wearer and the tracker(s) that follow it.
struct Session {
  std::unique_ptr<ftm_sim::FtmWearerSimulator> sim;
  std::vector<ftm::FtmTracker> trackers;
};

Result<Session> start_session(ftm_sim::FtmWearerOptions o, const std::vector<bool>& gate_mag,
                              const ftm::MagDisturbanceOptions& detector = {}) {
  auto sim = ftm_sim::FtmWearerSimulator::create(std::move(o));
  if (!sim) return sim.error();
  auto cal = ftm_sim::calibrate_from_wearer(**sim);
  if (!cal) return cal.error();
  Session s;
  s.sim = std::move(*sim);
  for (bool gate : gate_mag) {
    ftm::FtmTrackerOptions to;
    to.hand = s.sim->options().hand;
    to.attitude.gate_mag = gate;
    to.attitude.disturbance = detector;
    auto tracker = ftm::FtmTracker::create(to, cal->outcome.calibration);
    if (!tracker) return tracker.error();
    for (const auto& e : cal->events) tracker->push(e);
    s.trackers.push_back(std::move(*tracker));
  }
  return s;
}

// Errors of one scored frame.
struct PoseErrors {
  std::array<double, ftm::kFtmTrackedDofs.size()> dof_rad{};
  std::array<double, kSynergyDofs.size()> synergy_rad{};
  std::array<double, kTips.size()> tip_m{};
  double heading_rad = 0.0;
  bool ok = false;
};

PoseErrors score(const ftm::FtmTracker& tracker, const ftm_sim::FtmWearerSimulator::Truth& truth) {
  PoseErrors e;
  HandPose est;
  tracker.estimate(est);
  if (!est.active || !truth.pose.active) return e;
  const auto& a = tracker.angles();
  for (std::size_t i = 0; i < ftm::kFtmTrackedDofs.size(); ++i) {
    const auto d = index_of(ftm::kFtmTrackedDofs[i]);
    e.dof_rad[i] = std::abs(wrap_pi(a[d] - truth.angles[d]));
  }
  for (std::size_t i = 0; i < kSynergyDofs.size(); ++i) {
    const auto d = index_of(kSynergyDofs[i]);
    e.synergy_rad[i] = std::abs(wrap_pi(a[d] - truth.angles[d]));
  }
  const Pose est_wrist_inv = est.T_world_joint[index_of(HandJoint::wrist)].inverse();
  const Pose true_wrist_inv = truth.pose.T_world_joint[index_of(HandJoint::wrist)].inverse();
  for (std::size_t i = 0; i < kTips.size(); ++i) {
    const Vec3 p_est = est_wrist_inv * est.T_world_joint[index_of(kTips[i])].p;
    const Vec3 p_true = true_wrist_inv * truth.pose.T_world_joint[index_of(kTips[i])].p;
    e.tip_m[i] = (p_est - p_true).norm();
  }
  e.heading_rad = std::abs(heading_error_rad(est.T_world_joint[index_of(HandJoint::wrist)].q,
                                             truth.pose.T_world_joint[index_of(HandJoint::wrist)].q));
  bool finite = std::isfinite(e.heading_rad);
  for (double x : e.dof_rad) finite = finite && std::isfinite(x);
  for (double x : e.tip_m) finite = finite && std::isfinite(x);
  e.ok = finite;
  return e;
}

struct Accumulator {
  std::vector<double> tracked_deg;  // every DOF of every frame
  std::array<std::vector<double>, ftm::kFtmTrackedDofs.size()> per_dof_deg;
  std::array<std::vector<double>, kSynergyDofs.size()> synergy_deg;
  std::vector<double> tip_mm;
  std::vector<double> heading_deg;
  std::uint64_t frames = 0;
  std::uint64_t non_finite = 0;

  void add(const PoseErrors& e) {
    if (!e.ok) {
      ++non_finite;
      return;
    }
    ++frames;
    for (std::size_t i = 0; i < e.dof_rad.size(); ++i) {
      tracked_deg.push_back(rad_to_deg(e.dof_rad[i]));
      per_dof_deg[i].push_back(rad_to_deg(e.dof_rad[i]));
    }
    for (std::size_t i = 0; i < e.synergy_rad.size(); ++i) synergy_deg[i].push_back(rad_to_deg(e.synergy_rad[i]));
    for (double t : e.tip_m) tip_mm.push_back(1e3 * t);
    heading_deg.push_back(rad_to_deg(e.heading_rad));
  }
};

void report_progress(FtmProgress progress, void* user, int done, int total) {
  if (progress != nullptr) progress(user, done, total);
}

FtmCaseResult run_on_hand(FtmCase which, const FtmBenchOptions& options, FtmProgress progress, void* user) {
  const auto protocol =
      which == FtmCase::pinch_grasp ? sim::MotionProtocol::pinch_grasp : sim::MotionProtocol::free_motion;
  Accumulator acc;
  std::vector<double> session_means;
  for (int i = 0; i < options.subjects; ++i) {
    const int subject = options.first_subject + i;
    auto session = start_session(
        wearer_options(options, subject, options.seed + static_cast<std::uint64_t>(i), protocol, options.task_s), {true});
    if (!session) {
      return not_run(which, "subject " + std::to_string(subject) + ": " + session.error().message);
    }
    auto& sim = *session->sim;
    auto& tracker = session->trackers.front();
    std::vector<ftm::FtmEvent> events;
    sim.advance(sim.end_ns(), events);
    const std::size_t before = acc.tracked_deg.size();
    TimeNs next = sim.task_begin_ns() + kTaskSettleNs;
    for (const auto& e : events) {
      tracker.push(e);
      const bool frame = e.kind == ftm::FtmEvent::Kind::imu && e.index == index_of(ftm::FtmImu::dorsum);
      if (!frame || e.time_ns() < next) continue;
      next += kScorePeriodNs;
      acc.add(score(tracker, sim.truth_at(e.time_ns())));
    }
    if (acc.tracked_deg.size() > before) {
      const std::vector<double> mine(acc.tracked_deg.begin() + static_cast<std::ptrdiff_t>(before),
                                     acc.tracked_deg.end());
      session_means.push_back(mean_of(mine));
    }
    report_progress(progress, user, i + 1, options.subjects);
  }
  if (acc.frames == 0) return not_run(which, "no frame could be scored (the tracker never produced a pose)");
  if (acc.non_finite > 0) {
    return not_run(which, std::to_string(acc.non_finite) + " scored frames had non-finite errors");
  }
  FtmCaseResult r;
  r.which = which;
  r.ran = true;
  r.sessions = options.subjects;
  r.metrics.emplace_back("tracked_mean_deg", mean_of(acc.tracked_deg));
  r.metrics.emplace_back("tracked_p95_deg", percentile(acc.tracked_deg, 0.95));
  r.metrics.emplace_back("tracked_worst_session_mean_deg",
                         *std::max_element(session_means.begin(), session_means.end()));
  for (std::size_t i = 0; i < ftm::kFtmTrackedDofs.size(); ++i) {
    r.metrics.emplace_back(std::string(to_string(ftm::kFtmTrackedDofs[i])) + "_mean_deg", mean_of(acc.per_dof_deg[i]));
  }
  std::vector<double> syn_all;
  for (std::size_t i = 0; i < kSynergyDofs.size(); ++i) {
    r.metrics.emplace_back("synergy_" + std::string(to_string(kSynergyDofs[i])) + "_mean_deg",
                           mean_of(acc.synergy_deg[i]));
    syn_all.insert(syn_all.end(), acc.synergy_deg[i].begin(), acc.synergy_deg[i].end());
  }
  r.metrics.emplace_back("synergy_mean_deg", mean_of(syn_all));
  r.metrics.emplace_back("fingertip_rel_wrist_mean_mm", mean_of(acc.tip_mm));
  r.metrics.emplace_back("fingertip_rel_wrist_p95_mm", percentile(acc.tip_mm, 0.95));
  r.metrics.emplace_back("wrist_heading_mean_deg", mean_of(acc.heading_deg));
  r.counts.emplace_back("frames", acc.frames);
  r.counts.emplace_back("dof_samples", acc.tracked_deg.size());
  return r;
}

// Drill, fan and earphone case, each approaching over 2 s, held near the
// back of the hand for hold_s and taken away over 2 s, 4 s apart.
std::vector<ftm_sim::FtmMagneticObject> disturbance_objects(TimeNs first_ns, double hold_s) {
  std::vector<ftm_sim::FtmMagneticObject> objects;
  const DurationNs hold_ns = static_cast<DurationNs>(hold_s * 1e9);
  TimeNs t = first_ns;
  for (auto kind : {ftm_sim::FtmMagneticObject::Kind::drill, ftm_sim::FtmMagneticObject::Kind::fan,
                    ftm_sim::FtmMagneticObject::Kind::earphone_case}) {
    ftm_sim::FtmMagneticObject o;
    o.kind = kind;
    o.t_start_ns = t;
    o.hold_ns = hold_ns;
    objects.push_back(o);
    t += o.approach_ns + o.hold_ns + o.retreat_ns + 4 * kNsPerSecond;
  }
  return objects;
}

FtmCaseResult run_disturbance(const FtmBenchOptions& options, FtmProgress progress, void* user) {
  constexpr FtmCase which = FtmCase::disturbance;
  // Hit/false-alarm counts over every fresh compass sample of every IMU.
  // Truth (FtmBenchOptions::disturbance_truth_heading_deg): a compass sample
  // is disturbed when the dipoles turn the field's horizontal part at that
  // IMU by more than the threshold, i.e. when trusting it would pull heading.
  std::uint64_t disturbed = 0, hits = 0, undisturbed = 0, false_alarms = 0;
  std::uint64_t undisturbed_settled = 0, false_alarms_settled = 0;
  std::uint64_t release = 0, release_flagged = 0, heading_relevant = 0, heading_relevant_hits = 0;
  // The simulator's field definition (2° of direction or 3 % of magnitude),
  // kept for comparison with the previous figures.
  std::uint64_t f_disturbed = 0, f_hits = 0, f_undisturbed = 0, f_false = 0;
  const double truth_rad = deg_to_rad(options.disturbance_truth_heading_deg);
  // The detector keeps trusting the compass off for hold_s after the field is
  // back in tolerance, by design (a magnet leaving passes through the
  // tolerance band); with its low-pass (3 τ to settle) that is its release
  // window. Flags inside it are counted apart (release), not as false alarms.
  const auto release_ns = static_cast<DurationNs>(
      (options.detector.hold_s + 3.0 * options.detector.lowpass_tau_s) * 1e9);
  Accumulator gated_in, plain_in, gated_out, plain_out;
  for (int i = 0; i < options.subjects; ++i) {
    const int subject = options.first_subject + i;
    const TimeNs lead = 2 * kNsPerSecond;
    auto o =
        wearer_options(options, subject, options.seed + static_cast<std::uint64_t>(i), sim::MotionProtocol::pinch_grasp, 1.0);
    // The objects' times are in simulation time: the task starts after the
    // calibration phases, whose length a probe wearer tells.
    auto probe = ftm_sim::FtmWearerSimulator::create(o);
    if (!probe) return not_run(which, "subject " + std::to_string(subject) + ": " + probe.error().message);
    const TimeNs task_begin = (*probe)->task_begin_ns();
    o.magnetic.objects = disturbance_objects(task_begin + lead, options.disturbance_hold_s);
    const auto& last = o.magnetic.objects.back();
    o.task_s = 1e-9 * static_cast<double>(last.t_start_ns + last.approach_ns + last.hold_ns + last.retreat_ns + lead -
                                          task_begin);
    auto session = start_session(o, {true, false}, options.detector);
    if (!session) return not_run(which, "subject " + std::to_string(subject) + ": " + session.error().message);
    auto& sim = *session->sim;
    auto& gated = session->trackers[0];
    auto& plain = session->trackers[1];
    const auto& objects = sim.options().magnetic.objects;
    auto in_window = [&](TimeNs t) {
      for (const auto& ob : objects) {
        if (t >= ob.t_start_ns && t <= ob.t_start_ns + ob.approach_ns + ob.hold_ns + ob.retreat_ns) return true;
      }
      return false;
    };
    std::vector<ftm::FtmEvent> events;
    sim.advance(sim.end_ns(), events);
    TimeNs next = sim.task_begin_ns() + kTaskSettleNs;
    // The detector's hold time (0.5 s) and low-pass keep the flag a little
    // past the end of a disturbance: false alarms are also counted with the
    // second after each disturbed sample left out ("settled").
    std::array<TimeNs, ftm::kFtmImuCount> last_disturbed_ns{};
    last_disturbed_ns.fill(std::numeric_limits<TimeNs>::min() / 2);
    for (const auto& e : events) {
      gated.push(e);
      plain.push(e);
      const TimeNs t = e.time_ns();
      if (t < sim.task_begin_ns() + kTaskSettleNs) continue;
      if (e.kind == ftm::FtmEvent::Kind::imu && e.imu.mag_fresh) {
        const auto truth = sim.truth_at(t);
        const bool flagged = gated.mag_disturbed(static_cast<ftm::FtmImu>(e.index));
        const bool is = truth.mag_heading_deviation_rad[e.index] > truth_rad ||
                        truth.mag_norm_deviation[e.index] > options.detector.norm_tolerance ||
                        truth.mag_dip_deviation_rad[e.index] > options.detector.dip_tolerance_rad;
        heading_relevant += truth.mag_heading_deviation_rad[e.index] > truth_rad ? 1 : 0;
        heading_relevant_hits += truth.mag_heading_deviation_rad[e.index] > truth_rad && flagged ? 1 : 0;
        if (truth.mag_disturbed[e.index]) {
          ++f_disturbed;
          f_hits += flagged ? 1 : 0;
        } else {
          ++f_undisturbed;
          f_false += flagged ? 1 : 0;
        }
        if (is) {
          ++disturbed;
          hits += flagged ? 1 : 0;
          last_disturbed_ns[e.index] = t;
        } else if (t - last_disturbed_ns[e.index] <= release_ns) {
          ++release;
          release_flagged += flagged ? 1 : 0;
        } else {
          ++undisturbed;
          false_alarms += flagged ? 1 : 0;
          if (t - last_disturbed_ns[e.index] > kNsPerSecond) {
            ++undisturbed_settled;
            false_alarms_settled += flagged ? 1 : 0;
          }
        }
      }
      const bool frame = e.kind == ftm::FtmEvent::Kind::imu && e.index == index_of(ftm::FtmImu::dorsum);
      if (!frame || t < next) continue;
      next += kScorePeriodNs;
      const auto truth = sim.truth_at(t);
      if (in_window(t)) {
        gated_in.add(score(gated, truth));
        plain_in.add(score(plain, truth));
      } else {
        gated_out.add(score(gated, truth));
        plain_out.add(score(plain, truth));
      }
    }
    report_progress(progress, user, i + 1, options.subjects);
  }
  if (disturbed == 0) return not_run(which, "no compass sample was disturbed: nothing to detect");
  if (undisturbed == 0 || gated_in.frames == 0 || gated_out.frames == 0) {
    return not_run(which, "no frame could be scored inside or outside the disturbances");
  }
  if (gated_in.non_finite + plain_in.non_finite + gated_out.non_finite + plain_out.non_finite > 0) {
    return not_run(which, "scored frames had non-finite errors");
  }
  FtmCaseResult r;
  r.which = which;
  r.ran = true;
  r.sessions = options.subjects;
  auto rate = [](std::uint64_t k, std::uint64_t n) {
    return n == 0 ? std::numeric_limits<double>::quiet_NaN() : static_cast<double>(k) / static_cast<double>(n);
  };
  r.metrics.emplace_back("detector_hit_rate", rate(hits, disturbed));
  r.metrics.emplace_back("detector_false_alarm_rate", rate(false_alarms, undisturbed));
  r.metrics.emplace_back("detector_false_alarm_rate_settled", rate(false_alarms_settled, undisturbed_settled));
  r.metrics.emplace_back("detector_release_window_flag_rate", rate(release_flagged, release));
  r.metrics.emplace_back("detector_hit_rate_heading_only", rate(heading_relevant_hits, heading_relevant));
  r.metrics.emplace_back("detector_hit_rate_field_2deg_3pct", rate(f_hits, f_disturbed));
  r.metrics.emplace_back("detector_false_alarm_rate_field_2deg_3pct", rate(f_false, f_undisturbed));
  r.metrics.emplace_back("heading_during_gated_mean_deg", mean_of(gated_in.heading_deg));
  r.metrics.emplace_back("heading_during_plain_mean_deg", mean_of(plain_in.heading_deg));
  r.metrics.emplace_back("heading_during_gated_p95_deg", percentile(gated_in.heading_deg, 0.95));
  r.metrics.emplace_back("heading_during_plain_p95_deg", percentile(plain_in.heading_deg, 0.95));
  r.metrics.emplace_back("heading_outside_gated_mean_deg", mean_of(gated_out.heading_deg));
  r.metrics.emplace_back("heading_outside_plain_mean_deg", mean_of(plain_out.heading_deg));
  r.metrics.emplace_back("tracked_during_gated_mean_deg", mean_of(gated_in.tracked_deg));
  r.metrics.emplace_back("tracked_during_plain_mean_deg", mean_of(plain_in.tracked_deg));
  r.metrics.emplace_back("tracked_outside_gated_mean_deg", mean_of(gated_out.tracked_deg));
  r.counts.emplace_back("disturbed_compass_samples", disturbed);
  r.counts.emplace_back("undisturbed_compass_samples", undisturbed);
  r.counts.emplace_back("undisturbed_settled_compass_samples", undisturbed_settled);
  r.counts.emplace_back("release_window_compass_samples", release);
  r.counts.emplace_back("field_disturbed_compass_samples", f_disturbed);
  r.counts.emplace_back("frames_during", gated_in.frames);
  r.counts.emplace_back("frames_outside", gated_out.frames);
  return r;
}

// ---- imu_bench ---------------------------------------------------------

// The bench IMU lies still on the table for this long at turn-on: its gyro
// offset is the mean rate over it (estimate_still_bias), as a user would do.
constexpr double kBenchStillS = 2.0;
constexpr double kBenchFigureEightS = 20.0;
constexpr double kBenchRestS = 3.0;
constexpr double kBenchMoveS = 2.0;

double min_jerk(double s) {
  s = std::clamp(s, 0.0, 1.0);
  return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
}

struct BenchTurn {
  Vec3 axis;
  double angle_rad;
  double begin_s;  // the move out starts
};

// The bench's turns. About Y only 85°: the ZYX Euler angles are singular at
// 90° about their middle axis, where yaw and roll are not defined.
std::array<BenchTurn, 3> bench_turns(double hold_s) {
  std::array<BenchTurn, 3> turns{{{Vec3::UnitX(), deg_to_rad(90.0), 0.0},
                                  {Vec3::UnitY(), deg_to_rad(85.0), 0.0},
                                  {Vec3::UnitZ(), deg_to_rad(90.0), 0.0}}};
  double t = kBenchStillS + kBenchFigureEightS + kBenchRestS;
  for (auto& turn : turns) {
    turn.begin_s = t;
    t += kBenchMoveS + hold_s + kBenchMoveS + kBenchRestS;
  }
  return turns;
}

Quat bench_orientation(double t_s, const std::array<BenchTurn, 3>& turns, double hold_s) {
  if (t_s < kBenchStillS) return Quat::Identity();
  if (const double t = t_s - kBenchStillS; t < kBenchFigureEightS) {
    // Figure-eight: yaw, pitch and roll at incommensurate rates under a
    // sin² envelope, so it starts and ends at rest in the start pose.
    const double env = std::pow(std::sin(M_PI * t / kBenchFigureEightS), 2);
    const double yaw = deg_to_rad(170.0) * env * std::sin(2.0 * M_PI * 0.23 * t);
    const double pitch = deg_to_rad(70.0) * env * std::sin(2.0 * M_PI * 0.37 * t);
    const double roll = deg_to_rad(85.0) * env * std::sin(2.0 * M_PI * 0.29 * t + 1.0);
    return (Quat(Eigen::AngleAxisd(yaw, Vec3::UnitY())) * Quat(Eigen::AngleAxisd(pitch, Vec3::UnitX())) *
            Quat(Eigen::AngleAxisd(roll, Vec3::UnitZ())))
        .normalized();
  }
  for (const auto& turn : turns) {
    const double u = t_s - turn.begin_s;
    if (u < 0.0 || u > 2.0 * kBenchMoveS + hold_s) continue;
    double s = 1.0;
    if (u < kBenchMoveS)
      s = min_jerk(u / kBenchMoveS);
    else if (u > kBenchMoveS + hold_s)
      s = 1.0 - min_jerk((u - kBenchMoveS - hold_s) / kBenchMoveS);
    return Quat(Eigen::AngleAxisd(s * turn.angle_rad, turn.axis));
  }
  return Quat::Identity();
}

FtmCaseResult run_imu_bench(const FtmBenchOptions& options, FtmProgress progress, void* user) {
  constexpr FtmCase which = FtmCase::imu_bench;
  const auto turns = bench_turns(options.bench_hold_s);
  const double end_s = turns.back().begin_s + 2.0 * kBenchMoveS + options.bench_hold_s + kBenchRestS;
  const double hold_s = options.bench_hold_s;
  // The IMU's board lies on the table: the body frame starts level.
  sim::HandPoseFunction poses = [turns, hold_s](TimeNs t_ns) {
    HandPose p;
    p.time_ns = t_ns;
    p.active = true;
    const Pose T{bench_orientation(1e-9 * static_cast<double>(t_ns), turns, hold_s), Vec3(0.0, 1.0, 0.0)};
    p.T_world_joint.fill(T);
    return p;
  };
  std::vector<double> euler_err_deg, angle_err_deg;
  std::array<std::vector<double>, 3> per_turn_deg;
  const int runs = std::max(1, options.subjects);
  auto imu_options = ftm_sim::FtmWearerOptions::default_imu();
  if (options.bench_ideal_compass) {
    imu_options.magnetometer.enable_hard_iron = false;
    imu_options.magnetometer.enable_soft_iron = false;
  }
  for (int run = 0; run < runs; ++run) {
    // Four IMUs on the same rigid plate, each with its own noise, biases and
    // iron (drawn per IMU): four bench IMUs per run, and the glove's
    // four-IMU compass calibration (solve_mag_and_field) applies unchanged.
    std::vector<PlacedImu> placed;
    for (std::size_t k = 0; k < ftm::kFtmImuCount; ++k)
      placed.push_back(PlacedImu{k, HandJoint::wrist, Pose::identity()});
    auto imu_sim = sim::ImuSimulator::create(poses, placed, imu_options,
                                             mix_seed(options.seed + static_cast<std::uint64_t>(run), 0xbe7c));
    if (!imu_sim) return not_run(which, imu_sim.error().message);
    struct Step {
      std::uint8_t imu = 0;
      ftm::FtmImuSample sample;
      Quat q_true;
    };
    std::vector<Step> steps;
    const auto end_ns = static_cast<TimeNs>(end_s * 1e9);
    while (imu_sim->next_nominal_time_ns() < end_ns) {
      const auto readings = imu_sim->next();
      for (std::size_t k = 0; k < readings.size(); ++k) {
        const auto& r = readings[k];
        Step s;
        s.imu = static_cast<std::uint8_t>(k);
        s.sample.time_ns = r.time_ns;
        s.sample.accel_mps2 = r.sample.accel_mps2;
        s.sample.gyro_radps = r.sample.gyro_radps;
        s.sample.mag_uT = r.sample.mag_T ? Vec3(*r.sample.mag_T * 1e6) : Vec3::Zero();
        s.sample.mag_fresh = r.mag_fresh;
        s.sample.status = static_cast<std::uint8_t>((r.accel_saturated ? ftm::sample_status::accel_saturated : 0) |
                                                    (r.gyro_saturated ? ftm::sample_status::gyro_saturated : 0) |
                                                    (r.mag_overflow ? ftm::sample_status::mag_overflow : 0));
        s.q_true = imu_sim->ground_truth()[k].T_world_imu.q;
        steps.push_back(s);
      }
    }
    // Compass calibration from the figure-eight, as the glove's own (no
    // wrist tracker on the bench: the field's dip comes from the accelerometer).
    // Turn-on biases, what a user of the glove does (imu_bias.hpp): the gyro
    // offset from the still start, the accelerometer offset from a sphere fit
    // over the figure-eight's quasi-static samples. From the readings only.
    std::vector<ftm::FtmEvent> still, figure_eight;
    for (const auto& s : steps) {
      if (s.sample.time_ns > static_cast<TimeNs>((kBenchStillS + kBenchFigureEightS) * 1e9)) break;
      ftm::FtmEvent e;
      e.kind = ftm::FtmEvent::Kind::imu;
      e.index = s.imu;
      e.imu = s.sample;
      (s.sample.time_ns < static_cast<TimeNs>(kBenchStillS * 1e9) ? still : figure_eight).push_back(e);
    }
    auto base = ftm::nominal_ftm_calibration(Handedness::right, 0.19, 0.10);
    std::array<Vec3, ftm::kFtmImuCount> gyro_bias{};
    gyro_bias.fill(Vec3::Zero());
    if (options.bench_turn_on_bias) {
      for (std::uint8_t imu = 0; imu < ftm::kFtmImuCount; ++imu) {
        auto g = ftm::estimate_still_bias(ftm::imu_samples_of(still, imu));
        if (!g) return not_run(which, "IMU " + std::to_string(imu) + ": " + g.error().message);
        gyro_bias[imu] = g->gyro_bias_radps;
        auto a = ftm::fit_accel_bias(ftm::imu_samples_of(figure_eight, imu));
        if (!a) return not_run(which, "IMU " + std::to_string(imu) + ": " + a.error().message);
        base.accel_bias_mps2[imu] = a->bias_mps2;
      }
    }
    auto cal = ftm::solve_mag_and_field(figure_eight, base);
    if (!cal) return not_run(which, "compass calibration: " + cal.error().message);
    ftm::MahonyOptions mo;
    mo.mag_ref_in_world_uT = cal->earth_field_world_uT;
    for (std::uint8_t imu = 0; imu < ftm::kFtmImuCount; ++imu) {
      auto filter = ftm::MahonyFilter::create(mo);
      if (filter) filter->set_gyro_bias(gyro_bias[imu]);
      const Vec3 accel_bias = cal->accel_bias_mps2[imu];
      if (!filter) return not_run(which, filter.error().message);
      const auto& mag_cal = cal->mag[imu];
      std::optional<Quat> q_est0, q_true0;
      for (const auto& s : steps) {
        if (s.imu != imu) continue;
        const bool mag_ok = s.sample.mag_fresh && (s.sample.status & ftm::sample_status::mag_overflow) == 0;
        filter->update(s.sample.time_ns, s.sample.gyro_radps, s.sample.accel_mps2 - accel_bias,
                       mag_ok ? std::optional<Vec3>(mag_cal.apply(s.sample.mag_uT)) : std::nullopt);
        const double t = 1e-9 * static_cast<double>(s.sample.time_ns);
        // The reference: the end of the rest before the first turn.
        if (!q_est0 && t >= turns.front().begin_s - 0.1 && filter->initialised()) {
          q_est0 = filter->q_world_body();
          q_true0 = s.q_true;
        }
        if (!q_est0) continue;
        for (std::size_t k = 0; k < turns.size(); ++k) {
          // The hold, its first half second left out (the filter settling).
          const double u = t - turns[k].begin_s - kBenchMoveS;
          if (u < 0.5 || u > options.bench_hold_s) continue;
          const Quat r_est = (q_est0->conjugate() * filter->q_world_body()).normalized();
          const Quat r_true = (q_true0->conjugate() * s.q_true).normalized();
          const Vec3 e_est = ftm::euler_zyx_rad(r_est);
          const Vec3 e_true = ftm::euler_zyx_rad(r_true);
          double sum = 0.0;
          for (int a = 0; a < 3; ++a) sum += std::abs(wrap_pi(e_est[a] - e_true[a]));
          const double err = rad_to_deg(sum / 3.0);
          if (!std::isfinite(err)) return not_run(which, "non-finite Euler error");
          euler_err_deg.push_back(err);
          per_turn_deg[k].push_back(err);
          angle_err_deg.push_back(rad_to_deg(r_est.angularDistance(r_true)));
        }
      }
    }
    report_progress(progress, user, run + 1, runs);
  }
  if (euler_err_deg.empty()) return not_run(which, "the filter never initialised: nothing scored");
  FtmCaseResult r;
  r.which = which;
  r.ran = true;
  r.sessions = runs;
  r.metrics.emplace_back("euler_mean_deg", mean_of(euler_err_deg));
  r.metrics.emplace_back("euler_p95_deg", percentile(euler_err_deg, 0.95));
  r.metrics.emplace_back("turn_x_euler_mean_deg", mean_of(per_turn_deg[0]));
  r.metrics.emplace_back("turn_y_euler_mean_deg", mean_of(per_turn_deg[1]));
  r.metrics.emplace_back("turn_z_euler_mean_deg", mean_of(per_turn_deg[2]));
  r.metrics.emplace_back("rotation_angle_mean_deg", mean_of(angle_err_deg));
  r.counts.emplace_back("imus", static_cast<std::uint64_t>(runs) * ftm::kFtmImuCount);
  r.counts.emplace_back("samples", euler_err_deg.size());
  return r;
}

}  // namespace

std::string_view to_string(FtmCase c) noexcept {
  switch (c) {
    case FtmCase::imu_bench: return "imu_bench";
    case FtmCase::free_motion: return "free_motion";
    case FtmCase::pinch_grasp: return "pinch_grasp";
    case FtmCase::disturbance: return "disturbance";
  }
  return "?";
}

Result<FtmCase> parse_ftm_case(std::string_view name) {
  for (auto c : all_ftm_cases()) {
    if (to_string(c) == name) return c;
  }
  return make_error(Errc::invalid_argument, "unknown FTM bench case '" + std::string(name) +
                                                "' (imu_bench, free_motion, pinch_grasp, disturbance)");
}

std::vector<FtmCase> all_ftm_cases() {
  return {FtmCase::imu_bench, FtmCase::free_motion, FtmCase::pinch_grasp, FtmCase::disturbance};
}

Status FtmBenchOptions::validate() const {
  auto fail = [this](const std::string& field, const std::string& why) {
    return make_error(Errc::invalid_argument, "FtmBenchOptions." + field + " " + why + " (" + describe() + ")");
  };
  if (first_subject < 0 || first_subject >= sim::kSimSubjectCount) {
    return fail("first_subject", "must be 0.." + std::to_string(sim::kSimSubjectCount - 1));
  }
  const int max_subjects = sim::kSimSubjectCount - first_subject;
  if (subjects < 1 || subjects > max_subjects) {
    return fail("subjects", "must be 1.." + std::to_string(max_subjects) + " (from first_subject)");
  }
  if (!std::isfinite(disturbance_truth_heading_deg) || disturbance_truth_heading_deg <= 0.0 ||
      disturbance_truth_heading_deg > 90.0) {
    return fail("disturbance_truth_heading_deg", "must be in (0, 90] deg");
  }
  if (auto st = detector.validate(); !st) return fail("detector", st.error().message);
  if (!std::isfinite(task_s) || task_s < 2.0 || task_s > 3600.0) return fail("task_s", "must be in [2, 3600] s");
  if (!std::isfinite(disturbance_hold_s) || disturbance_hold_s < 1.0 || disturbance_hold_s > 120.0) {
    return fail("disturbance_hold_s", "must be in [1, 120] s");
  }
  if (!std::isfinite(bench_hold_s) || bench_hold_s < 1.0 || bench_hold_s > 120.0) {
    return fail("bench_hold_s", "must be in [1, 120] s");
  }
  if (auto st = soft_tissue.validate(); !st) return st.error().with_context("FtmBenchOptions");
  return {};
}

std::string FtmBenchOptions::describe() const {
  std::ostringstream s;
  s << "first_subject=" << first_subject << " subjects=" << subjects << " task_s=" << task_s << " seed=" << seed
    << " disturbance_hold_s=" << disturbance_hold_s << " bench_hold_s=" << bench_hold_s
    << " bench_turn_on_bias=" << (bench_turn_on_bias ? "on" : "off")
    << " disturbance_truth_heading_deg=" << disturbance_truth_heading_deg << " detector: " << detector.describe()
    << " soft tissue: " << soft_tissue.describe();
  return s.str();
}

double FtmCaseResult::metric(std::string_view name) const {
  for (const auto& [k, v] : metrics) {
    if (k == name) return v;
  }
  return std::numeric_limits<double>::quiet_NaN();
}

FtmCaseResult run_ftm_case(FtmCase which, const FtmBenchOptions& options, FtmProgress progress, void* user) {
  if (auto st = options.validate(); !st) return not_run(which, st.error().message);
  switch (which) {
    case FtmCase::imu_bench: return run_imu_bench(options, progress, user);
    case FtmCase::free_motion:
    case FtmCase::pinch_grasp: return run_on_hand(which, options, progress, user);
    case FtmCase::disturbance: return run_disturbance(options, progress, user);
  }
  return not_run(which, "unknown case");
}

}  // namespace proprio::ftm_eval
