#pragma once
// The simulated posing task of thesis §3.3 "Hardware comparison" / App. A.3:
// simulated participants pose a device to on-screen target poses with our
// joints (Cardan + twist rings) and with Jacobson et al.'s twist-bend-twist
// joints (simulated_user.hpp), and the task reports the thesis's metrics:
//   time      elapsed until the minimal pose error of the trial is reached
//   error     that minimal pose error, in % of the initial pose error
//   work      integral of the pose error [%] over the whole trial, in %·s (the
//             thesis gives no unit for its 89.65 vs 474.1; divide by 60 for %·min)
//   angular   mean over joints of |rotation angle| between device and target, at the end
// plus the ratio of mean times (theirs / ours) and the thesis's "matched
// accuracy" ratio (per trial: the time each device needs to first reach the
// less accurate device's minimum, theirs / ours).
//
// Statistics follow a participant design: each participant's trials are
// averaged per device, and means and SDs are over participants. Every
// participant poses the same target poses with both devices; there is no
// learning in the model, so the order of devices does not matter.
//
// The numbers come out of the model as measured; nothing in it is fitted to
// the thesis's 130 s vs 257 s.
#include <cstdint>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/rig_eval/posing_device.hpp"
#include "proprio/rig_eval/simulated_user.hpp"

namespace proprio::rig_eval {

struct PosingTaskOptions {
  int participants = 10;  // the thesis's study had 10
  int poses = 3;          // target poses per participant and device (the thesis: three timed blocks)
  std::uint64_t seed = 1;
  double time_limit_s = 600.0;  // per trial; a participant who is never satisfied stops here
  double trace_dt_s = 1.0;      // spacing of the downsampled error traces
  PosingDeviceKind device = PosingDeviceKind::humanoid6;
  int chain_joints = 5;  // device = chain only
  UserModelOptions user;

  Status validate() const;
  std::string describe() const;
};

struct MeanSd {
  double mean = 0.0;
  double sd = 0.0;  // sample SD (n - 1); 0 for one value
};

struct PosingTrialSummary {
  int participant = 0;
  int pose = 0;
  JointDesign design = JointDesign::cardan_twist;
  double initial_error_m = 0.0;
  double time_to_min_s = 0.0;
  double stop_time_s = 0.0;
  double min_error_percent = 0.0;
  double final_error_percent = 0.0;
  double work_percent_s = 0.0;
  double angular_error_deg = 0.0;  // at the end of the trial, mean over joints
  std::vector<double> joint_angular_error_deg;  // at the end of the trial, per joint
  bool timed_out = false;
  int looks = 0;
  int movements = 0;
  int regrasps = 0;
  // Pose error in % of the initial error at k * trace_dt_s, k = 0 .. until
  // the trial stopped (the first value is 100).
  std::vector<double> error_percent_trace;
};

struct DeviceSummary {
  JointDesign design = JointDesign::cardan_twist;
  int trials = 0;
  int timed_out = 0;
  MeanSd time_to_min_s;
  MeanSd stop_time_s;
  MeanSd min_error_percent;
  MeanSd final_error_percent;
  MeanSd work_percent_s;
  MeanSd angular_error_deg;
  // Per pose, the error trace [%] averaged over participants at trace_dt_s
  // (a trial that stopped holds its last value), as Fig. 3.10 plots it.
  std::vector<std::vector<double>> mean_trace_percent;
};

struct PosingTaskReport {
  PosingTaskOptions options;
  DeviceSummary ours;    // cardan_twist
  DeviceSummary theirs;  // twist_bend_twist
  double time_ratio = 0.0;  // theirs.time_to_min_s.mean / ours.time_to_min_s.mean
  MeanSd matched_accuracy_time_ratio;  // over trials, theirs / ours
  // Paired t statistic over participants (theirs - ours), df = participants - 1.
  double time_t = 0.0;
  double min_error_t = 0.0;
  double work_t = 0.0;
  std::vector<PosingTrialSummary> trials;

  std::string describe() const;
};

Result<PosingTaskReport> run_posing_task(const PosingTaskOptions& options);

// The report as JSON (options, both devices' summaries, ratios, t statistics,
// and per trial its metrics and, with include_traces, its error trace).
std::string posing_report_json(const PosingTaskReport& report, bool include_traces = true);
// Every trial's downsampled trace in long form for plotting:
// "participant,pose,design,t_s,error_percent" and one row per sample.
std::string posing_traces_csv(const PosingTaskReport& report);

// Metrics of one trial's error record (exposed for tests and tools).
PosingTrialSummary summarize_trial(const TrialResult& trial, const JointRotations& target, double trace_dt_s);

}  // namespace proprio::rig_eval
