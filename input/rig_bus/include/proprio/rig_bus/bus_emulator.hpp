#pragma once
// RigBusEmulator: the rig device's bus without the device. Any tree of
// components (a base on USB, joints, splitters) runs the protocol of thesis
// A.1 in simulated time: every component keeps bounded incoming and outgoing
// queues, polls each child every 5 ms on its own (skewed) clock, checks each
// message's CRC, fills an empty parent field with its own ID and the outlet
// the message came in on, and hands its queue up when its parent polls it.
// Joints create data messages at 50 Hz (angles from a callback: time,
// component -> JointAngles), every component a type message at 2 Hz, splitters
// and the base a child message per outlet at 2 Hz. The base packs its queue
// into HID reports, one per USB frame (1 ms).
//
// Faults, each configurable and seeded from options.seed:
//   - a link losing power for a while: the subtree below it goes dark, loses
//     its queues and reboots (IDs persist; boot counts advance);
//   - lost and corrupted messages on every hop (a corrupted one fails the
//     next receiver's CRC check and is dropped there);
//   - hot-plugging and unplugging subtrees, and re-parenting a subtree to
//     another free outlet (it is unpowered while it moves, so it reboots);
//   - per-component clock skew.
// The emulator knows the truth (truth_edges, events, creation_time_ns); the
// host side never sees it. Runs as fast as the CPU allows (advance_to); the
// real-time server on a hid::FakeHidLink is RigBusEmulatorServer below.
// Deterministic for a given tree, options and angles callback. Not thread-safe.
#include <array>
#include <cstdint>
#include <deque>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/hid/emulator_server.hpp"
#include "proprio/rig_bus/bus_host.hpp"
#include "proprio/rig_bus/bus_protocol.hpp"
#include "proprio/rig_device/joint_kinematics.hpp"

namespace proprio::rig_bus {

struct BusComponentSpec {
  std::uint32_t id = kNoComponent;
  ComponentKind kind = ComponentKind::joint;
  std::string kind_name = "joint";
  std::array<std::uint8_t, 3> colour_rgb{200, 200, 200};
  std::vector<Quat> q_inlet_outlet{Quat::Identity()};  // one per outlet
  // Index of the parent in BusTree::components; -1 for the base (index 0)
  // and for spares, which start unplugged (hot-plug faults plug them in).
  int parent = -1;
  std::uint8_t parent_outlet = 0;
};

struct BusTree {
  std::vector<BusComponentSpec> components;  // [0] is the base

  // One base, at index 0; unique non-zero IDs; outlet counts fit the kind
  // (base 1-8, joint 1, splitter 2-8); parents valid, without cycles, one
  // child per outlet. Messages name the component.
  Status validate() const;
  // Hops from the base (0 for it), or -1 for a component not connected to it.
  int depth_of(std::size_t index) const;
  int index_of(std::uint32_t id) const;  // -1 when absent
};

// A base with one outlet and a chain of joints below it.
BusTree make_bus_chain(std::size_t joints, std::uint64_t seed = 1);
// The benchmark's tree: a main branch `depth + 1` components deep (joints,
// with Y3 and Y2 splitters at depths 3 and 6) so a joint sits at exactly
// `depth`, side branches on the splitters, a second branch on the base, and
// a spare chain of two joints for hot-plugging. depth >= 7.
BusTree make_bench_bus_tree(int depth, std::uint64_t seed = 1);
// Smooth, distinct angles per component (the emulate command's default).
rig_device::JointAngles demo_bus_angles(TimeNs t_ns, std::uint32_t component_id);

struct BusPowerLoss {
  TimeNs at_ns = 0;
  std::uint32_t component_id = kNoComponent;  // the link into this component (its subtree goes dark)
  DurationNs duration_ns = 0;
};

enum class BusTopologyChangeKind : std::uint8_t { unplug, plug, reparent };
const char* to_string(BusTopologyChangeKind kind) noexcept;

struct BusTopologyChange {
  TimeNs at_ns = 0;
  BusTopologyChangeKind kind = BusTopologyChangeKind::unplug;
  std::uint32_t component_id = kNoComponent;  // the root of the subtree that moves
  std::uint32_t new_parent_id = kNoComponent; // plug, reparent
  std::uint8_t outlet = 0;                    // of the new parent
};

struct BusFaults {
  // Each message on each hop, from its own seeded stream.
  double loss_probability = 0.0;
  double corrupt_probability = 0.0;  // one bit flipped
  // Each component's crystal runs off by a uniform draw in +-this.
  double clock_skew_max_ppm = 0.0;
  // Random power losses: every interval (0: none) a random attached link
  // loses power for a uniform duration in [min, max].
  DurationNs power_loss_interval_ns = 0;
  DurationNs power_loss_min_ns = 50 * kNsPerMillisecond;
  DurationNs power_loss_max_ns = 500 * kNsPerMillisecond;
  // Random topology changes: every interval (0: none), starting at
  // topology_change_start_ns, in turn an unplug, a plug (of an unplugged
  // subtree into a free outlet) and a re-parent. The components named here
  // and their ancestors are never moved (a benchmark keeps its probe's depth).
  DurationNs topology_change_interval_ns = 0;
  TimeNs topology_change_start_ns = 5 * kNsPerSecond;
  std::vector<std::uint32_t> protected_ids;
  // A subtree being moved is unpowered this long (it reboots).
  DurationNs replug_power_gap_ns = 200 * kNsPerMillisecond;
  // Scripted faults (emulator time).
  std::vector<BusPowerLoss> power_losses;
  std::vector<BusTopologyChange> topology_changes;

  Status validate() const;
};

struct BusEmulatorOptions {
  DurationNs poll_period_ns = 5 * kNsPerMillisecond;     // component clock
  DurationNs data_period_ns = 20 * kNsPerMillisecond;    // 50 Hz
  DurationNs type_period_ns = 500 * kNsPerMillisecond;   // 2 Hz
  DurationNs child_period_ns = 500 * kNsPerMillisecond;  // 2 Hz
  DurationNs boot_time_ns = 30 * kNsPerMillisecond;      // power to first poll
  DurationNs usb_frame_ns = kNsPerMillisecond;           // one report per frame at most
  std::size_t queue_capacity = 64;         // messages, each of the two queues; the oldest goes when full
  std::size_t max_messages_per_poll = 16;  // one child's answer to one poll
  std::uint64_t seed = 1;
  BusFaults faults;

  Status validate() const;
  std::string describe() const;
};

using BusAnglesFn = std::function<rig_device::JointAngles(TimeNs t_ns, std::uint32_t component_id)>;

struct RigBusEmulatedReport {
  TimeNs send_ns = 0;  // emulator time
  std::array<std::uint8_t, kRigBusReportSize> bytes{};
};

struct BusEmulatorStats {
  std::array<std::uint64_t, 4> created{};  // by BusMessageType
  std::uint64_t hops = 0;                  // message transfers child -> parent attempted
  std::uint64_t lost = 0;
  std::uint64_t corrupted = 0;
  std::uint64_t crc_dropped = 0;           // corrupted ones the receiver caught
  std::uint64_t queue_overflows = 0;
  std::uint64_t lost_to_power = 0;         // in queues of components that went dark
  std::uint64_t power_losses = 0;
  std::uint64_t boots = 0;
  std::uint64_t unplugs = 0;
  std::uint64_t plugs = 0;
  std::uint64_t reparents = 0;
  std::uint64_t changes_skipped = 0;  // a random or scripted change that had no valid target
  std::uint64_t reports_sent = 0;
  std::uint64_t messages_to_host = 0;
};

enum class BusTruthEventKind : std::uint8_t { power_loss, unplug, plug, reparent };
struct BusTruthEvent {
  TimeNs at_ns = 0;
  BusTruthEventKind kind = BusTruthEventKind::power_loss;
  std::uint32_t component_id = kNoComponent;
  DurationNs duration_ns = 0;  // power losses
};

class RigBusEmulator {
 public:
  using Edge = BusTopologyTracker::Edge;

  // angles may be empty (all zero).
  static Result<RigBusEmulator> create(BusTree tree, BusEmulatorOptions options, BusAnglesFn angles = {});

  // Runs every event due up to t_ns and appends the reports the base sent.
  void advance_to(TimeNs t_ns, std::vector<RigBusEmulatedReport>& out);

  // Faults applied now (tests, the emulate command); errors name the reason.
  Status apply(BusTopologyChange change);
  Status cut_power(std::uint32_t component_id, DurationNs duration_ns);

  // Ground truth: the attached components' (id, parent, outlet), sorted; the
  // base with parent 0 and outlet 0xFF, as the host sees it.
  std::vector<Edge> truth_edges() const;
  const std::vector<BusTruthEvent>& events() const noexcept { return events_; }
  // When (emulator time) a message with this creator, boot and clock was
  // made, from the component's boot history (its last 8 boots).
  std::optional<TimeNs> creation_time_ns(std::uint32_t id, std::uint8_t boot, std::uint32_t clock_us) const;
  int depth_of(std::uint32_t id) const;  // -1 when unplugged or unknown
  bool powered(std::uint32_t id) const;
  std::uint32_t base_id() const;
  TimeNs now_ns() const noexcept { return now_ns_; }
  const BusTree& tree() const noexcept { return tree_; }
  const BusEmulatorOptions& options() const noexcept { return options_; }
  const BusEmulatorStats& stats() const noexcept { return stats_; }

 private:
  struct Wire {
    std::array<std::uint8_t, kBusMaxMessageSize> bytes{};
    std::uint8_t size = 0;
    std::uint8_t outlet = 0;  // incoming: the outlet it arrived on
  };
  struct Node {
    int parent = -1;
    std::uint8_t parent_outlet = 0;
    std::vector<int> children;  // per outlet, -1 free
    double skew_ppm = 0.0;
    TimeNs dark_until_ns = 0;  // the link into it is without power until then
    bool live = false;
    TimeNs boot_ns = 0;
    std::uint8_t boot_count = 0;
    std::array<std::pair<std::uint8_t, TimeNs>, 8> boots{};
    std::size_t boots_recorded = 0;
    TimeNs next_poll_ns = 0, next_data_ns = 0, next_type_ns = 0, next_child_ns = 0;
    std::deque<Wire> incoming, outgoing;
    std::array<std::uint32_t, kMaxOutlets> outlet_child{};  // as learned from messages
    std::array<TimeNs, kMaxOutlets> outlet_answer_ns{};
  };

  RigBusEmulator(BusTree tree, BusEmulatorOptions options, BusAnglesFn angles);
  DurationNs true_period(const Node& n, DurationNs device_period) const noexcept;
  std::uint32_t clock_us(const Node& n, TimeNs t) const noexcept;
  void refresh_power(TimeNs t);
  void boot(std::size_t i, TimeNs t);
  void go_dark(std::size_t i);
  TimeNs next_event_ns() const;
  void run_faults(TimeNs t);
  void random_power_loss(TimeNs t);
  void random_topology_change(TimeNs t);
  Status do_change(const BusTopologyChange& c, TimeNs t);
  void poll(std::size_t i, TimeNs t);
  void create_message(std::size_t i, BusMessage m);
  void push_bounded(std::deque<Wire>& q, const Wire& w);
  void usb_frame(TimeNs t, std::vector<RigBusEmulatedReport>& out);
  bool in_subtree(int node, int root) const;
  bool attached(int node) const;
  std::vector<std::pair<int, std::uint8_t>> free_outlets(int excluded_subtree) const;
  bool is_protected(int node) const;

  BusTree tree_;
  BusEmulatorOptions options_;
  BusAnglesFn angles_;
  std::vector<Node> nodes_;
  std::unordered_map<std::uint32_t, int> index_;
  Rng phase_rng_, loss_rng_, corrupt_rng_, fault_rng_;
  TimeNs now_ns_ = 0;
  TimeNs next_usb_ns_ = 0;
  TimeNs next_random_power_ns_ = 0;
  TimeNs next_random_change_ns_ = 0;
  std::uint64_t random_changes_ = 0;
  std::size_t next_scripted_power_ = 0;
  std::size_t next_scripted_change_ = 0;
  bool power_dirty_ = true;
  TimeNs next_power_restore_ns_ = 0;
  std::vector<BusTruthEvent> events_;
  BusEmulatorStats stats_;
};

// ---------------------------------------------------------------------------
// Serving the emulator over a fake cable, in real time (`proprio rig emulate`
// and the driver's tests).

struct RigBusServeOptions {
  DurationNs latency_min_ns = 200'000;
  DurationNs latency_jitter_ns = 300'000;
  DurationNs pump_interval_ns = 2 * kNsPerMillisecond;
  DurationNs lookahead_ns = 2 * kNsPerMillisecond;
  std::uint64_t seed = 1;  // latency draws
};

struct RigBusEmulatorServerTraits {
  using Emulator = RigBusEmulator;
  using Options = RigBusServeOptions;
  using Report = RigBusEmulatedReport;
  static void advance(RigBusEmulator& emulator, const RigBusServeOptions& options, TimeNs now_ns,
                      std::vector<RigBusEmulatedReport>& out);
  // The base takes no commands and has no feature reports (version 1).
  static void handle_command(RigBusEmulator&, std::span<const std::uint8_t>, TimeNs) {}
  static std::size_t feature(RigBusEmulator&, std::uint8_t, TimeNs, std::span<std::uint8_t>) { return 0; }
};
using RigBusEmulatorServer = hid::EmulatorServer<RigBusEmulatorServerTraits>;

}  // namespace proprio::rig_bus
