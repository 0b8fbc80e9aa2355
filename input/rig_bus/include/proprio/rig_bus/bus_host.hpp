#pragma once
// The host's side of the rig bus, without threads: the topology tracker
// (thesis A.1: the parent -> child relations in a hash table rebuilt from the
// messages' parent fields, a last-seen time per component, a subtree detached
// after 2 s of silence) and RigBusHost, which decodes the base's HID reports
// into it. The live driver (bus_device.hpp) runs a RigBusHost on the HID
// kit's link thread; the benchmark and the tests run the same one in
// simulated time, so both measure the code the device uses.
//
// Whose parent a component has is taken from its newest message only (boot
// count, then clock: bus_newer), so a message still travelling the old path
// after a re-parent cannot move it back. A component counts as heard when a
// message it made arrives, and also when one its child made arrives with its
// ID in the parent field (it filled that in, so it was alive: a splitter
// speaks only at 2 Hz itself). A component is attached when it was
// heard within detach_after_ns and its parent chain up to the base is
// attached; detaching a component therefore detaches the subtree below it.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/rig_bus/bus_protocol.hpp"
#include "proprio/rig_device/joint_kinematics.hpp"

namespace proprio::rig_bus {

struct BusTrackerOptions {
  DurationNs detach_after_ns = 2 * kNsPerSecond;  // the thesis's silence
  // Components remembered at most (a bus with more is beyond any kit; a flood
  // of IDs cannot grow the table). When full, the longest-silent detached
  // component makes room; when none is detached the newcomer is ignored.
  std::size_t max_components = 512;

  Status validate() const;
  std::string describe() const;
};

struct BusOutletView {
  bool known = false;                    // a child message for this outlet arrived
  std::uint32_t child_id = kNoComponent; // as the splitter last reported it
  Quat q_inlet_outlet = Quat::Identity();
};

struct BusComponentView {
  std::uint32_t id = kNoComponent;
  bool type_known = false;  // a type message arrived (kind, name, colour, outlets)
  ComponentKind kind = ComponentKind::joint;
  std::string kind_name;
  std::array<std::uint8_t, 3> colour_rgb{};
  std::uint8_t outlet_count = 0;
  std::uint32_t parent_id = kNoComponent;  // 0: the base (or not known yet)
  std::uint8_t parent_outlet = kNoOutlet;
  bool attached = false;
  std::uint8_t boot = 0;          // the creator's boot count in its newest message
  std::uint64_t reboots_seen = 0; // boot count changes the host saw
  DurationNs silent_ns = 0;       // since its last message reached the host
  bool have_angles = false;
  rig_device::JointAngles angles;  // newest data message
  DurationNs angles_age_ns = 0;    // since that message reached the host
  std::vector<BusOutletView> outlets;  // splitters and the base: one per outlet
};

struct BusSnapshot {
  TimeNs time_ns = 0;
  std::uint32_t base_id = kNoComponent;  // 0 until the base is heard
  std::size_t attached = 0;
  std::vector<BusComponentView> components;  // sorted by ID; attached and detached
  // The component with this ID, or nullptr.
  const BusComponentView* find(std::uint32_t id) const;
};

struct BusTrackerStats {
  std::uint64_t messages = 0;
  std::array<std::uint64_t, 4> messages_by_type{};  // index = BusMessageType (0 unused)
  std::uint64_t stale_messages = 0;     // older than the creator's newest: counted as heard, fields ignored
  std::uint64_t parent_changes = 0;     // re-parents and first placements after a detach
  std::uint64_t detaches = 0;           // attached -> detached transitions seen by update()
  std::uint64_t attaches = 0;           // detached (or new) -> attached
  std::uint64_t table_full = 0;         // messages from a new ID dropped at a full table
  std::uint64_t evicted = 0;
};

class BusTopologyTracker {
 public:
  explicit BusTopologyTracker(BusTrackerOptions options = {});

  // One decoded message and the host time it arrived.
  void on_message(const BusMessage& message, TimeNs receive_ns);
  // Recomputes which components are attached at now (counts transitions).
  void update(TimeNs now_ns);
  BusSnapshot snapshot(TimeNs now_ns) const;
  // The (child, parent, outlet) edges of attached components, sorted by child;
  // the base appears with parent 0. Cheaper than a snapshot (benchmarks).
  struct Edge {
    std::uint32_t id = 0;
    std::uint32_t parent_id = 0;
    std::uint8_t parent_outlet = kNoOutlet;
    bool operator==(const Edge&) const = default;
    auto operator<=>(const Edge&) const = default;
  };
  std::vector<Edge> attached_edges(TimeNs now_ns) const;
  std::uint32_t base_id() const noexcept { return base_id_; }
  const BusTrackerStats& stats() const noexcept { return stats_; }
  const BusTrackerOptions& options() const noexcept { return options_; }

 private:
  struct Entry {
    TimeNs last_seen_ns = 0;
    bool any = false;  // a message fixed boot and clock
    std::uint8_t boot = 0;
    std::uint32_t clock_us = 0;
    std::uint64_t reboots = 0;
    std::uint32_t parent_id = kNoComponent;
    std::uint8_t parent_outlet = kNoOutlet;
    bool type_known = false;
    BusTypeBody type;
    bool have_angles = false;
    BusDataBody angles;
    TimeNs angles_ns = 0;
    std::uint8_t angles_boot = 0;
    std::uint32_t angles_clock_us = 0;
    std::array<BusOutletView, kMaxOutlets> outlets{};
    bool attached = false;  // as of the last update()
  };
  Entry* entry_for(std::uint32_t id, TimeNs now_ns);
  // attached flags at now for every entry (iterative; a parent cycle, which
  // only a firmware bug could make, counts as detached).
  std::unordered_map<std::uint32_t, bool> attached_at(TimeNs now_ns) const;

  BusTrackerOptions options_;
  std::unordered_map<std::uint32_t, Entry> table_;
  std::uint32_t base_id_ = kNoComponent;
  BusTrackerStats stats_;
};

struct RigBusHostStats {
  std::uint64_t reports = 0;
  std::uint64_t decode_errors = 0;
  std::array<std::uint64_t, kBusDecodeErrcCount> decode_errors_by_code{};
  std::uint64_t messages = 0;
  BusTrackerStats tracker;
};

// Decodes the base's reports into a tracker. Reports that do not decode are
// counted and dropped whole (the report's CRC covers its messages).
class RigBusHost {
 public:
  explicit RigBusHost(BusTrackerOptions options = {}) : tracker_(options) {}
  // One HID report and when it arrived. Returns its decode status.
  BusDecodeStatus on_report(std::span<const std::uint8_t> report, TimeNs receive_ns);
  void update(TimeNs now_ns) { tracker_.update(now_ns); }
  BusTopologyTracker& tracker() noexcept { return tracker_; }
  const BusTopologyTracker& tracker() const noexcept { return tracker_; }
  RigBusHostStats stats() const;

  // Calls f for each message of the last report, if it decoded (benchmarks
  // measure latency here).
  template <typename F>
  void for_each_message_of_last_report(F&& f) const {
    for (std::size_t i = 0; i < last_.count && i < last_.messages.size(); ++i) f(last_.messages[i]);
  }

 private:
  BusTopologyTracker tracker_;
  RigBusReport last_;
  RigBusHostStats stats_;
};

}  // namespace proprio::rig_bus
