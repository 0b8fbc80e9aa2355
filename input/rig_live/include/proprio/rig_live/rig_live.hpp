#pragma once
// The rig device live: a device's base on USB (or a plan's device emulated
// behind the bus emulator on the HID kit's fake cable, with the bus faults it
// was designed for), read by the real driver (rig_bus::RigBusDevice), its
// topology bound to the plan (rig_plan::bind_device) and its joints' readings
// retargeted onto the character (rig_plan::Retargeter, pose-space
// interpolation included). update() is called from the app's frame loop: it
// never blocks (the driver publishes snapshots from its own thread).
//
// With the emulated device, each frame also carries the truth: the scripted
// animator's pose at this instant through the same retargeting, so the
// difference is what the sensors, the bus (loss, latency, detaches) and the
// binding cost. The host side never reads it.
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/core/skeleton.hpp"
#include "proprio/core/time.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/rig_bus/bus_device.hpp"
#include "proprio/rig_bus/bus_emulator.hpp"
#include "proprio/rig_live/plan_device.hpp"
#include "proprio/rig_plan/binding.hpp"
#include "proprio/rig_plan/retarget.hpp"

namespace proprio::rig_live {

// An emulated bus on the fake cable with the real driver reading it: what
// `rig emulate` shows and what the live source reads in emulation.
class EmulatedBusLink {
 public:
  static Result<std::unique_ptr<EmulatedBusLink>> create(rig_bus::BusTree tree, rig_bus::BusEmulatorOptions options,
                                                         rig_bus::BusAnglesFn angles,
                                                         rig_bus::RigBusServeOptions serve = {},
                                                         rig_bus::RigBusDeviceOptions device = {});
  ~EmulatedBusLink();
  Status start();  // emulator time 0 is now
  void stop();
  rig_bus::RigBusDevice& device() { return *device_; }
  // Emulator time now (ns since start), for the truth.
  TimeNs emulator_now_ns() const;
  rig_bus::BusEmulatorStats emulator_stats() const { return server_->emulator_stats(); }
  std::vector<rig_bus::BusTruthEvent> truth_events() const;
  std::vector<rig_bus::BusTopologyTracker::Edge> truth_edges() const;
  std::shared_ptr<hid::FakeHidLink> link() { return link_; }

 private:
  EmulatedBusLink() = default;
  std::shared_ptr<hid::FakeHidLink> link_;
  std::unique_ptr<rig_bus::RigBusEmulatorServer> server_;
  std::unique_ptr<rig_bus::RigBusDevice> device_;
};

struct RigLiveOptions {
  std::string device = "emulate";  // emulate: the plan's device on the fake cable; usb: a base on USB
  std::string hid_path;            // usb: the base's hidraw node (default: the first rig base)
  EmulatedDeviceOptions emulated;
  rig_bus::BusFaults faults;       // emulate: the bus's faults
  std::uint64_t bus_seed = 1;
  rig_plan::RetargetOptions retarget;
  // A joint whose newest reading is older than this counts as missing (its
  // node falls back to the pose space) even before the bus detaches it.
  double stale_after_s = 0.25;
  Status validate() const;
  std::string describe() const;
};

struct RigLiveFrame {
  TimeNs time_ns = 0;
  double t_s = 0.0;  // since start()
  SkeletonPose pose;
  std::optional<SkeletonPose> truth;  // emulated device only
  std::vector<std::optional<Quat>> q_in_out;  // per plan module, as used
  int joints_planned = 0;
  int joints_live = 0;           // bound, attached, with a fresh reading
  int components_attached = 0;   // on the bus, base included
  std::string binding_problems;  // empty when the device matches the plan
  double newest_reading_age_ms = 0.0;
  std::size_t target_sample = 0;  // emulated: the sample pose the animator is at or heading to
};

// From a bus snapshot to a rig pose: the observed topology bound to the plan,
// each bound, attached joint's fresh reading through the retargeter. The live
// source and the simulated-time benchmark (live_bench.hpp) both pose with it.
// One per thread; allocates only while the device grows.
class SnapshotPoser {
 public:
  static Result<SnapshotPoser> create(const rig_plan::RigInput& input, const rig_plan::Plan& plan,
                                      const rig_plan::RetargetOptions& options, double stale_after_s);
  // Fills frame's pose, q_in_out, joint and component counts, binding
  // problems and newest reading age at now_ns (not its times, truth or
  // target sample). A reading older than the stale limit at now_ns is missing.
  Status pose(const rig_bus::BusSnapshot& snapshot, TimeNs now_ns, RigLiveFrame& frame);
  const rig_plan::Plan& plan() const { return plan_; }

 private:
  SnapshotPoser(rig_plan::Plan plan, rig_plan::Retargeter retargeter, double stale_after_s)
      : plan_(std::move(plan)), retargeter_(std::move(retargeter)), stale_after_s_(stale_after_s) {}
  rig_plan::Plan plan_;
  rig_plan::Retargeter retargeter_;
  double stale_after_s_;
  std::vector<rig_plan::ObservedModule> observed_;
};

class RigLiveSource {
 public:
  static Result<std::unique_ptr<RigLiveSource>> create(const rig_plan::RigInput& input, const rig_plan::Plan& plan,
                                                       const RigLiveOptions& options);
  ~RigLiveSource();
  Status start();
  void stop();
  // The device's newest state as a rig pose (engine thread; never blocks).
  Status update(RigLiveFrame& frame);
  rig_bus::RigBusDeviceStats device_stats();
  std::optional<rig_bus::BusEmulatorStats> emulator_stats() const;
  rig_bus::BusSnapshot snapshot();
  const RigLiveOptions& options() const { return options_; }

 private:
  RigLiveSource() = default;
  RigLiveOptions options_;
  std::optional<SnapshotPoser> poser_;
  std::optional<rig_plan::Retargeter> truth_retargeter_;
  std::unique_ptr<EmulatedBusLink> emulated_;
  std::shared_ptr<EmulatedPlanDevice> emulated_device_;
  std::unique_ptr<rig_bus::RigBusDevice> usb_;
  rig_bus::RigBusDevice* device_ = nullptr;
  TimeNs start_ns_ = 0;
  std::vector<Quat> truth_q_;
  std::vector<std::optional<Quat>> truth_opt_;
};

}  // namespace proprio::rig_live
