#pragma once
// The benchmark of the bus targets, in simulated time: a tree of
// depth >= 8 (make_bench_bus_tree) runs on the emulator with message loss,
// random link power losses and random topology changes (unplug, plug,
// re-parent, in turn), and its base's reports go through RigBusHost, the
// decoder and tracker the live driver runs. Every check_interval the host's
// attached (component, parent, outlet) set is compared with the truth.
//
// Measured:
//  - recovery: from each topology change to the first check at which the
//    host matches the truth again (target <= 2 s). An unplug can only be seen
//    as 2 s of silence, so its recovery is the silence rule plus the time the
//    subtree's last messages spent on the way (reported separately);
//  - false detaches: components the host detached while truly attached
//    (powered or not; target 0);
//  - ghosts: components the host still shows attached longer than the
//    silence plus ghost_grace after they truly left (target 0);
//  - latency: from a data message's creation (a reading) at the probe joint,
//    which sits at `depth` and is never moved, to its arrival at the host
//    (target p99 <= 50 ms).
#include <cstdint>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/rig_bus/bus_emulator.hpp"

namespace proprio::rig_bus {

struct BusBenchOptions {
  int depth = 8;                               // of the probe joint; the tree is one deeper
  DurationNs duration_ns = 300 * kNsPerSecond; // simulated
  double loss_probability = 0.01;              // each message, each hop
  double corrupt_probability = 0.001;          // each message, each hop
  DurationNs power_loss_interval_ns = 10 * kNsPerSecond;
  DurationNs power_loss_min_ns = 50 * kNsPerMillisecond;
  DurationNs power_loss_max_ns = 500 * kNsPerMillisecond;
  DurationNs topology_change_interval_ns = 10 * kNsPerSecond;  // offset 5 s from the power losses
  double clock_skew_max_ppm = 10'000.0;        // RC oscillators of small MCUs: +-1 %
  DurationNs usb_latency_ns = kNsPerMillisecond;
  DurationNs check_interval_ns = 5 * kNsPerMillisecond;
  DurationNs detach_after_ns = 2 * kNsPerSecond;
  DurationNs ghost_grace_ns = kNsPerSecond;
  std::uint64_t seed = 1;

  Status validate() const;
  std::string describe() const;
};

struct BusChangeRecovery {
  TimeNs at_ns = 0;
  BusTruthEventKind kind = BusTruthEventKind::unplug;
  std::uint32_t component_id = kNoComponent;
  // -1: the host never matched the truth before the next change or the end.
  DurationNs recovery_ns = -1;
};

struct BusRecoveryStats {
  std::size_t changes = 0;
  std::size_t recovered = 0;
  double p50_ms = 0.0, p95_ms = 0.0, max_ms = 0.0;
};

struct BusBenchReport {
  std::string error;  // empty when the run happened; else why not (bad options)
  std::string options;
  std::size_t components = 0;
  int probe_depth = 0;
  std::uint32_t probe_id = kNoComponent;
  double simulated_s = 0.0;
  double wall_s = 0.0;

  std::vector<BusChangeRecovery> changes;
  BusRecoveryStats recovery_all, recovery_unplug, recovery_plug, recovery_reparent;
  std::size_t power_losses = 0;
  std::size_t false_detaches = 0;     // components
  std::size_t ghost_components = 0;   // episodes
  std::size_t latency_samples = 0;
  double latency_p50_ms = 0.0, latency_p99_ms = 0.0, latency_max_ms = 0.0;

  BusEmulatorStats emulator;
  RigBusHostStats host;

  // The targets: every change recovered within 2 s (unplugs within
  // 2 s of silence plus transit: recovery_limit_unplug_ms), no false
  // detaches, no ghosts, p99 latency <= 50 ms.
  bool targets_met() const;
  std::string summary() const;  // a few lines for people
  std::string to_json() const;  // one object, for `proprio bench rig --json`
};

BusBenchReport run_bus_bench(const BusBenchOptions& options);

}  // namespace proprio::rig_bus
