#include "proprio/rig_eval/posing_task.hpp"

#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>

namespace proprio::rig_eval {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

// Streams of the task's seed (mix_seed): poses, participants, trials.
constexpr std::uint64_t kPoseStream = 1;
constexpr std::uint64_t kParticipantStream = 2;
constexpr std::uint64_t kTrialStream = 3;

MeanSd mean_sd(const std::vector<double>& v) {
  MeanSd out;
  if (v.empty()) return out;
  double sum = 0.0;
  for (const double x : v) sum += x;
  out.mean = sum / static_cast<double>(v.size());
  if (v.size() > 1) {
    double ss = 0.0;
    for (const double x : v) ss += (x - out.mean) * (x - out.mean);
    out.sd = std::sqrt(ss / static_cast<double>(v.size() - 1));
  }
  return out;
}

// Error [m] of a piecewise-linear record at time t (held after its end).
double error_at(const std::vector<ErrorSample>& e, double t) {
  if (t <= e.front().t_s) return e.front().error_m;
  if (t >= e.back().t_s) return e.back().error_m;
  const auto it = std::upper_bound(e.begin(), e.end(), t, [](double x, const ErrorSample& s) { return x < s.t_s; });
  const ErrorSample& b = *it;
  const ErrorSample& a = *(it - 1);
  const double span = b.t_s - a.t_s;
  return span > 0.0 ? a.error_m + (t - a.t_s) / span * (b.error_m - a.error_m) : b.error_m;
}

// First time the record reaches `level` [m] (linear between samples); +inf if never.
double first_time_at_or_below(const std::vector<ErrorSample>& e, double level) {
  if (e.front().error_m <= level) return e.front().t_s;
  for (std::size_t i = 1; i < e.size(); ++i) {
    if (e[i].error_m <= level) {
      const double drop = e[i - 1].error_m - e[i].error_m;
      const double f = drop > 0.0 ? (e[i - 1].error_m - level) / drop : 1.0;
      return e[i - 1].t_s + std::clamp(f, 0.0, 1.0) * (e[i].t_s - e[i - 1].t_s);
    }
  }
  return INFINITY;
}

double min_error(const std::vector<ErrorSample>& e) {
  double m = e.front().error_m;
  for (const auto& s : e) m = std::min(m, s.error_m);
  return m;
}

double paired_t(const std::vector<double>& ours, const std::vector<double>& theirs) {
  std::vector<double> diff(ours.size());
  for (std::size_t i = 0; i < ours.size(); ++i) diff[i] = theirs[i] - ours[i];
  const MeanSd d = mean_sd(diff);
  if (diff.size() < 2 || d.sd <= 0.0) return 0.0;
  return d.mean / (d.sd / std::sqrt(static_cast<double>(diff.size())));
}

PosingDevice device_for(const PosingTaskOptions& o) {
  return o.device == PosingDeviceKind::chain ? make_chain_device(o.chain_joints) : make_humanoid_device();
}

std::string format_summary(const DeviceSummary& s) {
  return fmt::format(
      "{}: time to min {:.1f} s (SD {:.1f}), stopped at {:.1f} s (SD {:.1f}), min error {:.1f} % (SD {:.1f}), "
      "final {:.1f} %, work {:.0f} %·s (SD {:.0f}), angular error {:.1f} deg (SD {:.1f}), {} of {} trials timed out",
      to_string(s.design), s.time_to_min_s.mean, s.time_to_min_s.sd, s.stop_time_s.mean, s.stop_time_s.sd,
      s.min_error_percent.mean, s.min_error_percent.sd, s.final_error_percent.mean, s.work_percent_s.mean,
      s.work_percent_s.sd, s.angular_error_deg.mean, s.angular_error_deg.sd, s.timed_out, s.trials);
}

nlohmann::json mean_sd_json(const MeanSd& m) { return {{"mean", m.mean}, {"sd", m.sd}}; }

nlohmann::json summary_json(const DeviceSummary& s) {
  return {{"design", to_string(s.design)},
          {"trials", s.trials},
          {"timed_out", s.timed_out},
          {"time_to_min_s", mean_sd_json(s.time_to_min_s)},
          {"stop_time_s", mean_sd_json(s.stop_time_s)},
          {"min_error_percent", mean_sd_json(s.min_error_percent)},
          {"final_error_percent", mean_sd_json(s.final_error_percent)},
          {"work_percent_s", mean_sd_json(s.work_percent_s)},
          {"angular_error_deg", mean_sd_json(s.angular_error_deg)},
          {"mean_trace_percent", s.mean_trace_percent}};
}

}  // namespace

Status PosingTaskOptions::validate() const {
  if (participants < 1 || participants > 1000) {
    return make_error(Errc::invalid_argument, "posing task: participants must be 1-1000");
  }
  if (poses < 1 || poses > 100) return make_error(Errc::invalid_argument, "posing task: poses must be 1-100");
  if (!std::isfinite(time_limit_s) || time_limit_s <= 0.0 || time_limit_s > 3600.0) {
    return make_error(Errc::invalid_argument, "posing task: time_limit_s must be in (0, 3600]");
  }
  if (!std::isfinite(trace_dt_s) || trace_dt_s < 0.01 || trace_dt_s > 60.0) {
    return make_error(Errc::invalid_argument, "posing task: trace_dt_s must be in [0.01, 60]");
  }
  if (device == PosingDeviceKind::chain && (chain_joints < 1 || chain_joints > 32)) {
    return make_error(Errc::invalid_argument, "posing task: chain_joints must be 1-32");
  }
  if (auto s = user.validate(); !s) return s.error().with_context("posing task");
  return {};
}

std::string PosingTaskOptions::describe() const {
  return fmt::format("posing task: {} participants x {} poses x 2 joint designs on the {} device{}, seed {}, "
                     "time limit {:g} s, traces every {:g} s; {}",
                     participants, poses, to_string(device),
                     device == PosingDeviceKind::chain ? fmt::format(" ({} joints)", chain_joints) : std::string(),
                     seed, time_limit_s, trace_dt_s, user.describe());
}

std::string PosingTaskReport::describe() const {
  return fmt::format(
      "{}\n  ours   {}\n  theirs {}\n  time ratio theirs/ours {:.2f}; matched-accuracy time ratio {:.2f} (SD {:.2f}); "
      "paired t (df {}): time {:.2f}, min error {:.2f}, work {:.2f}",
      options.describe(), format_summary(ours), format_summary(theirs), time_ratio, matched_accuracy_time_ratio.mean,
      matched_accuracy_time_ratio.sd, options.participants - 1, time_t, min_error_t, work_t);
}

std::string posing_report_json(const PosingTaskReport& r, bool include_traces) {
  nlohmann::json trials = nlohmann::json::array();
  for (const auto& t : r.trials) {
    nlohmann::json j = {{"participant", t.participant},
                        {"pose", t.pose},
                        {"design", to_string(t.design)},
                        {"initial_error_m", t.initial_error_m},
                        {"time_to_min_s", t.time_to_min_s},
                        {"stop_time_s", t.stop_time_s},
                        {"min_error_percent", t.min_error_percent},
                        {"final_error_percent", t.final_error_percent},
                        {"work_percent_s", t.work_percent_s},
                        {"angular_error_deg", t.angular_error_deg},
                        {"joint_angular_error_deg", t.joint_angular_error_deg},
                        {"timed_out", t.timed_out},
                        {"looks", t.looks},
                        {"movements", t.movements},
                        {"regrasps", t.regrasps}};
    if (include_traces) j["error_percent_trace"] = t.error_percent_trace;
    trials.push_back(std::move(j));
  }
  const PosingTaskOptions& o = r.options;
  nlohmann::json out = {
      {"options",
       {{"participants", o.participants},
        {"poses", o.poses},
        {"seed", o.seed},
        {"time_limit_s", o.time_limit_s},
        {"trace_dt_s", o.trace_dt_s},
        {"device", to_string(o.device)},
        {"description", o.describe()}}},
      {"ours", summary_json(r.ours)},
      {"theirs", summary_json(r.theirs)},
      {"time_ratio", r.time_ratio},
      {"matched_accuracy_time_ratio", mean_sd_json(r.matched_accuracy_time_ratio)},
      {"paired_t", {{"df", o.participants - 1}, {"time", r.time_t}, {"min_error", r.min_error_t}, {"work", r.work_t}}},
      {"trials", std::move(trials)}};
  // Non-finite numbers (none are expected) would become null rather than invalid JSON.
  return out.dump(2);
}

std::string posing_traces_csv(const PosingTaskReport& r) {
  std::string out = "participant,pose,design,t_s,error_percent\n";
  for (const auto& t : r.trials) {
    for (std::size_t k = 0; k < t.error_percent_trace.size(); ++k) {
      out += fmt::format("{},{},{},{:g},{:.4f}\n", t.participant, t.pose, to_string(t.design),
                         static_cast<double>(k) * r.options.trace_dt_s, t.error_percent_trace[k]);
    }
  }
  return out;
}

PosingTrialSummary summarize_trial(const TrialResult& trial, const JointRotations& target, double trace_dt_s) {
  PosingTrialSummary s;
  s.design = trial.design;
  s.initial_error_m = trial.initial_error_m;
  s.stop_time_s = trial.stop_time_s;
  s.timed_out = trial.timed_out;
  s.looks = trial.looks;
  s.movements = trial.movements;
  s.regrasps = trial.regrasps;
  const auto& e = trial.error;
  // A trial that starts on the target has nothing to measure against: call it 0 %.
  const double scale = trial.initial_error_m > 0.0 ? 100.0 / trial.initial_error_m : 0.0;
  const double m = min_error(e);
  s.min_error_percent = m * scale;
  s.final_error_percent = e.back().error_m * scale;
  s.time_to_min_s = first_time_at_or_below(e, m);
  for (std::size_t i = 1; i < e.size(); ++i) {
    s.work_percent_s += 0.5 * (e[i].error_m + e[i - 1].error_m) * scale * (e[i].t_s - e[i - 1].t_s);
  }
  s.angular_error_deg = mean_joint_angle_error_rad(trial.final_pose, target) * kRadToDeg;
  for (std::size_t j = 0; j < target.size(); ++j) {
    s.joint_angular_error_deg.push_back(angle_between(trial.final_pose[j], target[j]) * kRadToDeg);
  }
  const auto samples = static_cast<std::size_t>(std::floor(trial.stop_time_s / trace_dt_s)) + 1;
  s.error_percent_trace.reserve(samples);
  for (std::size_t k = 0; k < samples; ++k) {
    s.error_percent_trace.push_back(error_at(e, static_cast<double>(k) * trace_dt_s) * scale);
  }
  return s;
}

Result<PosingTaskReport> run_posing_task(const PosingTaskOptions& options) {
  if (auto s = options.validate(); !s) return s.error();
  PosingTaskReport report;
  report.options = options;
  const PosingDevice device = device_for(options);

  std::vector<JointRotations> targets;
  {
    Rng rng(mix_seed(options.seed, kPoseStream));
    for (int p = 0; p < options.poses; ++p) targets.push_back(sample_target_pose(device, rng));
  }
  TrialOptions trial_options;
  trial_options.time_limit_s = options.time_limit_s;

  const auto P = static_cast<std::size_t>(options.participants);
  // Per participant, per device (0 ours, 1 theirs): means over poses.
  struct Means {
    std::vector<double> time, stop, min_err, final_err, work, angle;
  };
  Means per[2];
  std::vector<double> matched_ratios;
  std::vector<std::vector<std::vector<double>>> pose_traces[2];  // [device][pose][participant]
  for (auto& d : pose_traces) d.resize(static_cast<std::size_t>(options.poses));

  for (std::size_t participant = 0; participant < P; ++participant) {
    Rng participant_rng(mix_seed(mix_seed(options.seed, kParticipantStream), participant));
    const SimulatedUser user = draw_participant(options.user, participant_rng);
    double sums[2][6] = {};
    for (int pose = 0; pose < options.poses; ++pose) {
      PosingTrialSummary pair[2];
      std::vector<ErrorSample> ours_record;
      for (int d = 0; d < 2; ++d) {
        const JointDesign design = d == 0 ? JointDesign::cardan_twist : JointDesign::twist_bend_twist;
        Rng trial_rng(mix_seed(mix_seed(mix_seed(options.seed, kTrialStream), participant),
                               static_cast<std::uint64_t>(pose * 2 + d)));
        const TrialResult trial =
            simulate_trial(device, design, targets[static_cast<std::size_t>(pose)], user, trial_options, trial_rng);
        PosingTrialSummary s = summarize_trial(trial, targets[static_cast<std::size_t>(pose)], options.trace_dt_s);
        s.participant = static_cast<int>(participant);
        s.pose = pose;
        const double values[6] = {s.time_to_min_s, s.stop_time_s, s.min_error_percent,
                                  s.final_error_percent, s.work_percent_s, s.angular_error_deg};
        for (int k = 0; k < 6; ++k) sums[d][k] += values[k];
        pose_traces[d][static_cast<std::size_t>(pose)].push_back(s.error_percent_trace);
        // The matched-accuracy ratio needs both records of this pose.
        if (d == 0) {
          pair[0] = s;
          report.trials.push_back(std::move(s));
          ours_record = trial.error;
        } else {
          const double level_pct = std::max(pair[0].min_error_percent, s.min_error_percent);
          const double t_theirs = first_time_at_or_below(trial.error, level_pct * trial.initial_error_m / 100.0);
          const double t_ours = first_time_at_or_below(ours_record, level_pct * trial.initial_error_m / 100.0);
          if (std::isfinite(t_theirs) && std::isfinite(t_ours) && t_ours > 0.0) matched_ratios.push_back(t_theirs / t_ours);
          report.trials.push_back(std::move(s));
        }
      }
    }
    for (int d = 0; d < 2; ++d) {
      Means& m = per[d];
      const double n = options.poses;
      m.time.push_back(sums[d][0] / n);
      m.stop.push_back(sums[d][1] / n);
      m.min_err.push_back(sums[d][2] / n);
      m.final_err.push_back(sums[d][3] / n);
      m.work.push_back(sums[d][4] / n);
      m.angle.push_back(sums[d][5] / n);
    }
  }

  for (int d = 0; d < 2; ++d) {
    DeviceSummary& s = d == 0 ? report.ours : report.theirs;
    s.design = d == 0 ? JointDesign::cardan_twist : JointDesign::twist_bend_twist;
    s.time_to_min_s = mean_sd(per[d].time);
    s.stop_time_s = mean_sd(per[d].stop);
    s.min_error_percent = mean_sd(per[d].min_err);
    s.final_error_percent = mean_sd(per[d].final_err);
    s.work_percent_s = mean_sd(per[d].work);
    s.angular_error_deg = mean_sd(per[d].angle);
    for (const auto& t : report.trials) {
      if (t.design != s.design) continue;
      ++s.trials;
      s.timed_out += t.timed_out ? 1 : 0;
    }
    for (const auto& traces : pose_traces[d]) {
      std::size_t longest = 0;
      for (const auto& tr : traces) longest = std::max(longest, tr.size());
      std::vector<double> mean(longest, 0.0);
      for (const auto& tr : traces) {
        for (std::size_t k = 0; k < longest; ++k) mean[k] += (k < tr.size() ? tr[k] : tr.back());
      }
      for (double& v : mean) v /= static_cast<double>(traces.size());
      s.mean_trace_percent.push_back(std::move(mean));
    }
  }
  report.time_ratio = report.ours.time_to_min_s.mean > 0.0
                          ? report.theirs.time_to_min_s.mean / report.ours.time_to_min_s.mean
                          : 0.0;
  report.matched_accuracy_time_ratio = mean_sd(matched_ratios);
  report.time_t = paired_t(per[0].time, per[1].time);
  report.min_error_t = paired_t(per[0].min_err, per[1].min_err);
  report.work_t = paired_t(per[0].work, per[1].work);
  return report;
}

}  // namespace proprio::rig_eval
