#pragma once
// The rig device end to end in simulated time, for `proprio bench rig`: a
// plan's device posed by the scripted animator, its joints read through their
// Hall sensors and calibration, its messages through the bus emulator with
// faults, the base's reports through the host's decoder and topology tracker
// (the code the live driver runs), then binding and retargeting
// (SnapshotPoser, the live source's own). Each host frame is compared with
// the animator's pose at that instant, so the error includes the bus's
// latency as a user would see it. The pipeline never reads the truth.
#include <cstdint>
#include <string>

#include "proprio/core/result.hpp"
#include "proprio/rig_bus/bus_emulator.hpp"
#include "proprio/rig_live/plan_device.hpp"
#include "proprio/rig_plan/plan.hpp"

namespace proprio::rig_live {

struct LiveBenchOptions {
  double seconds = 60.0;        // simulated
  double warmup_s = 1.0;        // the bus comes up; not scored
  double frame_rate_hz = 60.0;  // host poses per second
  double usb_latency_s = 0.001;
  bool hall_sensors = true;
  bool pose_space = true;
  AnimatorOptions animator;
  rig_bus::BusFaults faults = default_faults();
  std::uint64_t seed = 1;
  static rig_bus::BusFaults default_faults();  // 1 % loss, 0.1 % corruption, a power loss every 10 s, 50 ppm skew
  Status validate() const;
  std::string describe() const;
};

struct ErrorStats {
  std::size_t count = 0;
  double mean = 0.0, p95 = 0.0, max = 0.0;
};

struct LiveBenchReport {
  std::string character;
  int joints = 0;
  std::size_t frames = 0;               // scored host frames
  double joints_live_fraction = 0.0;    // mean over frames of live joints / planned joints
  double frames_all_live_fraction = 0.0;
  double character_size_m = 0.0;        // the largest extent of its nodes at rest
  ErrorStats node_error_m;              // per frame: mean over nodes of |live - truth|
  ErrorStats node_error_percent;        // the same, in % of character_size_m
  ErrorStats joint_error_deg;           // per live joint and frame: angle between its reading and the animator's
  std::uint64_t host_detaches = 0;
  std::uint64_t power_losses = 0;
  double wall_s = 0.0;
  std::string describe() const;
};

Result<LiveBenchReport> run_live_bench(const rig_plan::RigInput& input, const rig_plan::Plan& plan,
                                       const LiveBenchOptions& options);

}  // namespace proprio::rig_live
