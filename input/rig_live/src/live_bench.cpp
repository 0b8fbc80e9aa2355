#include "proprio/rig_live/live_bench.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

#include "proprio/rig_bus/bus_host.hpp"
#include "proprio/rig_device/joint_kinematics.hpp"
#include "proprio/rig_live/rig_live.hpp"
#include "proprio/rig_plan/retarget.hpp"

namespace proprio::rig_live {
namespace {

ErrorStats stats_of(std::vector<double> v) {
  ErrorStats s;
  s.count = v.size();
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  double sum = 0.0;
  for (double x : v) sum += x;
  s.mean = sum / static_cast<double>(v.size());
  s.p95 = v[std::min(v.size() - 1, v.size() * 95 / 100)];
  s.max = v.back();
  return s;
}

}  // namespace

rig_bus::BusFaults LiveBenchOptions::default_faults() {
  rig_bus::BusFaults f;
  f.loss_probability = 0.01;
  f.corrupt_probability = 0.001;
  f.power_loss_interval_ns = 10 * kNsPerSecond;
  f.clock_skew_max_ppm = 50.0;
  return f;
}

Status LiveBenchOptions::validate() const {
  if (!(seconds > 0.0 && seconds <= 86400.0)) return make_error(Errc::invalid_argument, "seconds must be in (0, 86400]");
  if (!(warmup_s >= 0.0 && warmup_s < seconds))
    return make_error(Errc::invalid_argument, "the warm-up must be >= 0 and shorter than the run");
  if (!(frame_rate_hz >= 1.0 && frame_rate_hz <= 1000.0))
    return make_error(Errc::invalid_argument, "the frame rate must be in [1, 1000] Hz");
  if (!(usb_latency_s >= 0.0 && usb_latency_s <= 1.0))
    return make_error(Errc::invalid_argument, "the USB latency must be in [0, 1] s");
  if (auto st = animator.validate(); !st) return st;
  return faults.validate();
}

std::string LiveBenchOptions::describe() const {
  std::ostringstream s;
  s << seconds << " s simulated (first " << warmup_s << " s not scored), host frames at " << frame_rate_hz << " Hz; "
    << (hall_sensors ? "joints through simulated Hall sensors and calibration" : "exact joint angles") << "; bus loss "
    << faults.loss_probability * 100.0 << " %, corruption " << faults.corrupt_probability * 100.0 << " %, ";
  if (faults.power_loss_interval_ns > 0)
    s << "a link power loss every " << ns_to_seconds(faults.power_loss_interval_ns) << " s, ";
  s << "skew " << faults.clock_skew_max_ppm << " ppm; pose space " << (pose_space ? "on" : "off") << "; "
    << animator.describe() << "; seed " << seed;
  return s.str();
}

std::string LiveBenchReport::describe() const {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(2);
  s << character << ": " << frames << " host frames, " << joints << " joints; live " << 100.0 * joints_live_fraction
    << " % of joint-frames, every joint live in " << 100.0 * frames_all_live_fraction << " % of frames\n"
    << "  node error against the animator: mean " << 1e3 * node_error_m.mean << " mm, p95 " << 1e3 * node_error_m.p95
    << ", max " << 1e3 * node_error_m.max << " (" << node_error_percent.mean << " % / " << node_error_percent.p95
    << " % of the character's " << character_size_m << " m)\n"
    << "  joint error (reading vs animator, latency included): mean " << joint_error_deg.mean << " deg, p95 "
    << joint_error_deg.p95 << ", max " << joint_error_deg.max << "; " << host_detaches << " detaches, " << power_losses
    << " power losses; " << wall_s << " s wall";
  return s.str();
}

Result<LiveBenchReport> run_live_bench(const rig_plan::RigInput& input, const rig_plan::Plan& plan,
                                       const LiveBenchOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  const auto wall0 = std::chrono::steady_clock::now();
  auto tree = bus_tree_for_plan(plan, options.seed);
  if (!tree) return tree.error();
  EmulatedDeviceOptions eo;
  eo.hall_sensors = options.hall_sensors;
  eo.animator = options.animator;
  eo.seed = options.seed;
  auto device = EmulatedPlanDevice::create(plan, *tree, eo);
  if (!device) return device.error();
  rig_bus::BusEmulatorOptions bo;
  bo.seed = options.seed;
  bo.faults = options.faults;
  auto emulator = rig_bus::RigBusEmulator::create(tree->tree, bo, angles_callback(*device));
  if (!emulator) return emulator.error();
  rig_plan::RetargetOptions ro;
  ro.pose_space = options.pose_space;
  auto poser = SnapshotPoser::create(input, plan, ro, 0.25);
  if (!poser) return poser.error();
  auto truth_retargeter = rig_plan::Retargeter::create(input, plan, ro);
  if (!truth_retargeter) return truth_retargeter.error();
  rig_bus::RigBusHost host;

  LiveBenchReport r;
  r.character = input.name;
  for (const auto& m : plan.modules) r.joints += m.type == rig_plan::DeviceModule::Type::joint ? 1 : 0;
  {
    std::vector<Pose> T;
    forward_kinematics(input.skeleton, rest_pose(input.skeleton), T);
    Vec3 lo = Vec3::Constant(1e30), hi = Vec3::Constant(-1e30);
    for (const auto& t : T) {
      lo = lo.cwiseMin(t.p);
      hi = hi.cwiseMax(t.p);
    }
    r.character_size_m = std::max(1e-6, (hi - lo).maxCoeff());
  }
  const auto dt_ns = static_cast<DurationNs>(1e9 / options.frame_rate_hz);
  const TimeNs end_ns = seconds_to_ns(options.seconds);
  const TimeNs warm_ns = seconds_to_ns(options.warmup_s);
  const DurationNs usb_ns = seconds_to_ns(options.usb_latency_s);
  std::vector<rig_bus::RigBusEmulatedReport> reports;
  RigLiveFrame frame;
  std::vector<Quat> truth_q;
  std::vector<std::optional<Quat>> truth_opt;
  SkeletonPose truth_pose;
  std::vector<Pose> T_live, T_true;
  std::vector<double> node_err, joint_err;
  double live_sum = 0.0;
  std::size_t all_live = 0;
  for (TimeNs t = dt_ns; t <= end_ns; t += dt_ns) {
    reports.clear();
    emulator->advance_to(t - usb_ns, reports);
    for (const auto& rep : reports) host.on_report(rep.bytes, rep.send_ns + usb_ns);
    host.update(t);
    const auto snap = host.tracker().snapshot(t);
    if (auto st = poser->pose(snap, t, frame); !st) return st.error();
    if (t < warm_ns) continue;
    const double t_s = ns_to_seconds(t);
    (*device)->animator().q_in_out(t_s, truth_q);
    truth_opt.assign(truth_q.begin(), truth_q.end());
    if (auto st = truth_retargeter->retarget(truth_opt, truth_pose); !st) return st.error();
    forward_kinematics(input.skeleton, frame.pose, T_live);
    forward_kinematics(input.skeleton, truth_pose, T_true);
    double sum = 0.0;
    for (std::size_t n = 0; n < T_live.size(); ++n) sum += (T_live[n].p - T_true[n].p).norm();
    node_err.push_back(sum / static_cast<double>(T_live.size()));
    for (std::size_t m = 0; m < frame.q_in_out.size(); ++m) {
      if (!frame.q_in_out[m]) continue;
      joint_err.push_back(so3_log(frame.q_in_out[m]->conjugate() * truth_q[m]).norm() * 180.0 / M_PI);
    }
    const double live = r.joints > 0 ? static_cast<double>(frame.joints_live) / r.joints : 0.0;
    live_sum += live;
    all_live += frame.joints_live == r.joints ? 1 : 0;
  }
  r.frames = node_err.size();
  if (r.frames == 0) return make_error(Errc::invalid_argument, "no host frame was scored: run longer than the warm-up");
  r.joints_live_fraction = live_sum / static_cast<double>(r.frames);
  r.frames_all_live_fraction = static_cast<double>(all_live) / static_cast<double>(r.frames);
  std::vector<double> pct(node_err.size());
  for (std::size_t i = 0; i < node_err.size(); ++i) pct[i] = 100.0 * node_err[i] / r.character_size_m;
  r.node_error_m = stats_of(node_err);
  r.node_error_percent = stats_of(pct);
  r.joint_error_deg = stats_of(joint_err);
  r.host_detaches = host.stats().tracker.detaches;
  r.power_losses = emulator->stats().power_losses;
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  return r;
}

}  // namespace proprio::rig_live
