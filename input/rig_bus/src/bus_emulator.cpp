#include "proprio/rig_bus/bus_emulator.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "proprio/hid/emulator_faults.hpp"

namespace proprio::rig_bus {

namespace {

constexpr double kTreePi = 3.14159265358979323846;
constexpr TimeNs kNever = std::numeric_limits<TimeNs>::max();

std::string name_of(const BusTree& t, std::size_t i) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "component %zu (ID 0x%08x)", i, t.components[i].id);
  return buf;
}

Status bad(const std::string& what) { return make_error(Errc::invalid_argument, "rig bus tree: " + what); }

// Programming times a second apart from a seeded start, as a flashing
// session would stamp them.
std::uint32_t next_id(Rng& rng, std::uint64_t& programmed_us) {
  programmed_us += 1'000'000 + rng.below(60'000'000);
  return component_id_for(programmed_us);
}

BusComponentSpec joint_spec(std::uint32_t id, int parent, std::uint8_t outlet) {
  BusComponentSpec s;
  s.id = id;
  s.kind = ComponentKind::joint;
  s.kind_name = "joint";
  s.colour_rgb = {230, 230, 230};
  s.parent = parent;
  s.parent_outlet = outlet;
  return s;
}

BusComponentSpec splitter_spec(std::uint32_t id, int parent, std::uint8_t outlet, int valence) {
  BusComponentSpec s;
  s.id = id;
  s.kind = ComponentKind::splitter;
  s.kind_name = valence == 2 ? "Y2" : "Y3";
  s.colour_rgb = valence == 2 ? std::array<std::uint8_t, 3>{40, 120, 220} : std::array<std::uint8_t, 3>{220, 80, 40};
  s.q_inlet_outlet.clear();
  for (int k = 0; k < valence; ++k) {
    // Outlets spread evenly around the shaft, each tilted 40° off it.
    const double around = 2.0 * kTreePi * k / valence;
    s.q_inlet_outlet.push_back(Quat(Eigen::AngleAxisd(around, Vec3::UnitZ())) *
                               Quat(Eigen::AngleAxisd(40.0 * kTreePi / 180.0, Vec3::UnitX())));
  }
  s.parent = parent;
  s.parent_outlet = outlet;
  return s;
}

BusComponentSpec base_spec(std::uint32_t id, int outlets) {
  BusComponentSpec s;
  s.id = id;
  s.kind = ComponentKind::base;
  s.kind_name = "base";
  s.colour_rgb = {30, 30, 30};
  s.q_inlet_outlet.assign(static_cast<std::size_t>(outlets), Quat::Identity());
  return s;
}

}  // namespace

// ---------------------------------------------------------------------------
// Trees

int BusTree::index_of(std::uint32_t id) const {
  for (std::size_t i = 0; i < components.size(); ++i) {
    if (components[i].id == id) return static_cast<int>(i);
  }
  return -1;
}

int BusTree::depth_of(std::size_t index) const {
  int depth = 0;
  std::size_t i = index;
  while (i != 0) {
    const int p = components[i].parent;
    if (p < 0 || depth > static_cast<int>(components.size())) return -1;
    i = static_cast<std::size_t>(p);
    ++depth;
  }
  return depth;
}

Status BusTree::validate() const {
  if (components.empty() || components[0].kind != ComponentKind::base) {
    return bad("the first component must be the base (kind base)");
  }
  if (components.size() > 256) return bad(std::to_string(components.size()) + " components; at most 256");
  std::unordered_map<std::uint32_t, std::size_t> seen;
  std::vector<std::vector<int>> taken(components.size());
  for (std::size_t i = 0; i < components.size(); ++i) {
    const BusComponentSpec& c = components[i];
    if (c.id == kNoComponent) return bad(name_of(*this, i) + " has ID 0, which means 'empty' on the bus");
    if (!seen.emplace(c.id, i).second) return bad(name_of(*this, i) + " has the same ID as another component");
    if (i > 0 && c.kind == ComponentKind::base) return bad(name_of(*this, i) + " is a second base");
    const std::size_t n = c.q_inlet_outlet.size();
    const bool fits = c.kind == ComponentKind::joint ? n == 1 : c.kind == ComponentKind::splitter ? (n >= 2 && n <= kMaxOutlets)
                                                                                                   : (n >= 1 && n <= kMaxOutlets);
    if (!fits) return bad(name_of(*this, i) + " has " + std::to_string(n) + " outlets; a joint has 1, a splitter 2-8, the base 1-8");
    taken[i].assign(n, -1);
    if (i == 0 && c.parent != -1) return bad("the base has no parent");
    if (c.parent >= static_cast<int>(components.size()) || c.parent < -1 || (i > 0 && c.parent == static_cast<int>(i))) {
      return bad(name_of(*this, i) + " names a parent that does not exist");
    }
  }
  for (std::size_t i = 1; i < components.size(); ++i) {
    const BusComponentSpec& c = components[i];
    if (c.parent < 0) continue;
    auto& slots = taken[static_cast<std::size_t>(c.parent)];
    if (c.parent_outlet >= slots.size()) {
      return bad(name_of(*this, i) + " sits on outlet " + std::to_string(c.parent_outlet) + " of a parent with " +
                 std::to_string(slots.size()));
    }
    if (slots[c.parent_outlet] >= 0) return bad(name_of(*this, i) + " shares its parent's outlet with another component");
    slots[c.parent_outlet] = static_cast<int>(i);
    // A cycle never reaches the base or a spare root.
    std::size_t j = i, steps = 0;
    while (j != 0 && components[j].parent >= 0) {
      j = static_cast<std::size_t>(components[j].parent);
      if (++steps > components.size()) return bad(name_of(*this, i) + " is its own ancestor");
    }
  }
  return {};
}

BusTree make_bus_chain(std::size_t joints, std::uint64_t seed) {
  Rng rng(mix_seed(seed, 11));
  std::uint64_t programmed = 1'700'000'000'000'000ull + rng.below(1'000'000'000'000ull);
  BusTree t;
  t.components.push_back(base_spec(next_id(rng, programmed), 1));
  for (std::size_t i = 0; i < joints; ++i) {
    t.components.push_back(joint_spec(next_id(rng, programmed), static_cast<int>(i), 0));
  }
  return t;
}

BusTree make_bench_bus_tree(int depth, std::uint64_t seed) {
  depth = std::max(depth, 7);
  Rng rng(mix_seed(seed, 12));
  std::uint64_t programmed = 1'700'000'000'000'000ull + rng.below(1'000'000'000'000ull);
  BusTree t;
  auto add = [&](BusComponentSpec s) {
    t.components.push_back(std::move(s));
    return static_cast<int>(t.components.size() - 1);
  };
  add(base_spec(next_id(rng, programmed), 2));
  // Main branch: depths 1 .. depth + 1, splitters at 3 (Y3) and 6 (Y2).
  int parent = 0;
  std::uint8_t outlet = 0;
  int y3 = -1, y2 = -1;
  for (int d = 1; d <= depth + 1; ++d) {
    int idx;
    if (d == 3) {
      idx = y3 = add(splitter_spec(next_id(rng, programmed), parent, outlet, 3));
    } else if (d == 6) {
      idx = y2 = add(splitter_spec(next_id(rng, programmed), parent, outlet, 2));
    } else {
      idx = add(joint_spec(next_id(rng, programmed), parent, outlet));
    }
    parent = idx;
    outlet = 0;
  }
  // Side branches.
  int a = add(joint_spec(next_id(rng, programmed), y3, 1));
  add(joint_spec(next_id(rng, programmed), a, 0));
  add(joint_spec(next_id(rng, programmed), y3, 2));
  a = add(joint_spec(next_id(rng, programmed), y2, 1));
  add(joint_spec(next_id(rng, programmed), a, 0));
  // Second branch on the base: a joint, a Y2 and a joint on each outlet.
  a = add(joint_spec(next_id(rng, programmed), 0, 1));
  const int s = add(splitter_spec(next_id(rng, programmed), a, 0, 2));
  add(joint_spec(next_id(rng, programmed), s, 0));
  add(joint_spec(next_id(rng, programmed), s, 1));
  // A spare chain, unplugged at the start.
  a = add(joint_spec(next_id(rng, programmed), -1, 0));
  add(joint_spec(next_id(rng, programmed), a, 0));
  return t;
}

rig_device::JointAngles demo_bus_angles(TimeNs t_ns, std::uint32_t id) {
  const double t = static_cast<double>(t_ns) * 1e-9;
  const double phase = static_cast<double>(id % 1000) * 0.0137;
  rig_device::JointAngles a;
  a.twist_in_rad = 0.6 * std::sin(0.31 * t + phase);
  a.bend_x_rad = 0.8 * std::sin(0.53 * t + 2.0 * phase);
  a.bend_y_rad = 0.5 * std::sin(0.71 * t + 3.0 * phase);
  a.twist_out_rad = 0.4 * std::sin(0.43 * t + 5.0 * phase);
  return a;
}

const char* to_string(BusTopologyChangeKind kind) noexcept {
  switch (kind) {
    case BusTopologyChangeKind::unplug: return "unplug";
    case BusTopologyChangeKind::plug: return "plug";
    case BusTopologyChangeKind::reparent: return "reparent";
  }
  return "unknown";
}

// ---------------------------------------------------------------------------
// Options

Status BusFaults::validate() const {
  const char* who = "rig bus emulator";
  if (auto s = hid::check_fault_probability(who, "loss_probability", loss_probability); !s) return s;
  if (auto s = hid::check_fault_probability(who, "corrupt_probability", corrupt_probability); !s) return s;
  auto err = [](const std::string& m) { return make_error(Errc::invalid_argument, "rig bus emulator: faults." + m); };
  if (!(clock_skew_max_ppm >= 0.0 && clock_skew_max_ppm <= 100'000.0)) {
    return err("clock_skew_max_ppm must be 0 to 100000 (10 %)");
  }
  if (power_loss_interval_ns < 0 || topology_change_interval_ns < 0) {
    return err("power_loss_interval_ns and topology_change_interval_ns must be 0 (off) or positive");
  }
  if (power_loss_min_ns <= 0 || power_loss_max_ns < power_loss_min_ns) {
    return err("power_loss_min_ns must be positive and at most power_loss_max_ns");
  }
  if (replug_power_gap_ns < 0) return err("replug_power_gap_ns must not be negative");
  if (topology_change_start_ns < 0) return err("topology_change_start_ns must not be negative");
  for (std::size_t i = 0; i < power_losses.size(); ++i) {
    if (power_losses[i].duration_ns <= 0) return err("power_losses[" + std::to_string(i) + "] must last longer than 0");
  }
  return {};
}

Status BusEmulatorOptions::validate() const {
  auto err = [](const std::string& m) { return make_error(Errc::invalid_argument, "BusEmulatorOptions." + m); };
  if (poll_period_ns < 100'000) return err("poll_period_ns must be at least 0.1 ms");
  if (data_period_ns < poll_period_ns || type_period_ns < poll_period_ns || child_period_ns < poll_period_ns) {
    return err("data, type and child periods must be at least the poll period");
  }
  if (boot_time_ns < 0) return err("boot_time_ns must not be negative");
  if (usb_frame_ns < 125'000) return err("usb_frame_ns must be at least 125 us (a high-speed microframe)");
  if (queue_capacity < 2 || queue_capacity > 4096) return err("queue_capacity must be 2 to 4096");
  if (max_messages_per_poll < 1 || max_messages_per_poll > queue_capacity) {
    return err("max_messages_per_poll must be 1 to queue_capacity");
  }
  return faults.validate();
}

std::string BusEmulatorOptions::describe() const {
  char text[400];
  std::snprintf(text, sizeof text,
                "poll %.1f ms, data %.0f Hz, type %.1f Hz, child %.1f Hz, boot %.0f ms, queues %zu, %zu per poll; "
                "loss %.2f %%, corruption %.2f %%, skew +-%.0f ppm, power loss every %.1f s (%.0f-%.0f ms), "
                "topology change every %.1f s, seed %llu",
                poll_period_ns * 1e-6, 1e9 / static_cast<double>(data_period_ns),
                1e9 / static_cast<double>(type_period_ns), 1e9 / static_cast<double>(child_period_ns),
                boot_time_ns * 1e-6, queue_capacity, max_messages_per_poll, faults.loss_probability * 100.0,
                faults.corrupt_probability * 100.0, faults.clock_skew_max_ppm, faults.power_loss_interval_ns * 1e-9,
                faults.power_loss_min_ns * 1e-6, faults.power_loss_max_ns * 1e-6,
                faults.topology_change_interval_ns * 1e-9, static_cast<unsigned long long>(seed));
  return text;
}

// ---------------------------------------------------------------------------
// Emulator

Result<RigBusEmulator> RigBusEmulator::create(BusTree tree, BusEmulatorOptions options, BusAnglesFn angles) {
  if (auto s = tree.validate(); !s) return s.error();
  if (auto s = options.validate(); !s) return s.error();
  return RigBusEmulator(std::move(tree), std::move(options), std::move(angles));
}

RigBusEmulator::RigBusEmulator(BusTree tree, BusEmulatorOptions options, BusAnglesFn angles)
    : tree_(std::move(tree)),
      options_(std::move(options)),
      angles_(std::move(angles)),
      phase_rng_(mix_seed(options_.seed, hid::kFirstDeviceFaultStream)),
      loss_rng_(mix_seed(options_.seed, hid::kFirstDeviceFaultStream + 1)),
      corrupt_rng_(mix_seed(options_.seed, hid::kFirstDeviceFaultStream + 2)),
      fault_rng_(mix_seed(options_.seed, hid::kFirstDeviceFaultStream + 3)) {
  Rng skew_rng(mix_seed(options_.seed, hid::kFirstDeviceFaultStream + 4));
  nodes_.resize(tree_.components.size());
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const BusComponentSpec& c = tree_.components[i];
    Node& n = nodes_[i];
    n.parent = c.parent;
    n.parent_outlet = c.parent_outlet;
    n.children.assign(c.q_inlet_outlet.size(), -1);
    n.skew_ppm = skew_rng.uniform(-1.0, 1.0) * options_.faults.clock_skew_max_ppm;
    index_[c.id] = static_cast<int>(i);
  }
  for (std::size_t i = 1; i < nodes_.size(); ++i) {
    if (nodes_[i].parent >= 0) nodes_[static_cast<std::size_t>(nodes_[i].parent)].children[nodes_[i].parent_outlet] = static_cast<int>(i);
  }
  auto by_time = [](const auto& a, const auto& b) { return a.at_ns < b.at_ns; };
  std::stable_sort(options_.faults.power_losses.begin(), options_.faults.power_losses.end(), by_time);
  std::stable_sort(options_.faults.topology_changes.begin(), options_.faults.topology_changes.end(), by_time);
  next_random_power_ns_ = options_.faults.power_loss_interval_ns > 0 ? options_.faults.power_loss_interval_ns : kNever;
  next_random_change_ns_ =
      options_.faults.topology_change_interval_ns > 0 ? options_.faults.topology_change_start_ns : kNever;
  refresh_power(0);
}

DurationNs RigBusEmulator::true_period(const Node& n, DurationNs device_period) const noexcept {
  return std::max<DurationNs>(1, static_cast<DurationNs>(static_cast<double>(device_period) / (1.0 + n.skew_ppm * 1e-6)));
}

std::uint32_t RigBusEmulator::clock_us(const Node& n, TimeNs t) const noexcept {
  return hid::emulated_counter_us(n.boot_ns, t, 0, n.skew_ppm);
}

bool RigBusEmulator::attached(int i) const {
  std::size_t steps = 0;
  while (i > 0) {
    i = nodes_[static_cast<std::size_t>(i)].parent;
    if (++steps > nodes_.size()) return false;
  }
  return i == 0;
}

bool RigBusEmulator::in_subtree(int node, int root) const {
  std::size_t steps = 0;
  while (node >= 0) {
    if (node == root) return true;
    node = nodes_[static_cast<std::size_t>(node)].parent;
    if (++steps > nodes_.size()) return false;
  }
  return false;
}

void RigBusEmulator::refresh_power(TimeNs t) {
  // Parents come before their subtrees only in a fresh tree; walk up instead.
  next_power_restore_ns_ = kNever;
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    bool live = true;
    int j = static_cast<int>(i);
    std::size_t steps = 0;
    while (j > 0) {
      const Node& n = nodes_[static_cast<std::size_t>(j)];
      if (n.dark_until_ns > t) {
        live = false;
        next_power_restore_ns_ = std::min(next_power_restore_ns_, n.dark_until_ns);
      }
      j = n.parent;
      if (++steps > nodes_.size()) j = -1;
    }
    if (j != 0) live = false;
    if (live && !nodes_[i].live) boot(i, t);
    if (!live && nodes_[i].live) go_dark(i);
  }
  power_dirty_ = false;
}

void RigBusEmulator::boot(std::size_t i, TimeNs t) {
  Node& n = nodes_[i];
  n.live = true;
  ++n.boot_count;
  n.boot_ns = t;
  n.boots[n.boots_recorded % n.boots.size()] = {n.boot_count, t};
  ++n.boots_recorded;
  n.incoming.clear();
  n.outgoing.clear();
  n.outlet_child.fill(kNoComponent);
  n.outlet_answer_ns.fill(t);
  ++stats_.boots;
  const TimeNs ready = t + options_.boot_time_ns;
  auto phase = [&](DurationNs period) {
    return ready + static_cast<TimeNs>(phase_rng_.below(static_cast<std::uint64_t>(true_period(n, period))));
  };
  n.next_poll_ns = phase(options_.poll_period_ns);
  n.next_data_ns = phase(options_.data_period_ns);
  // Firmware announces itself right after boot, then at 2 Hz.
  n.next_type_ns = phase(options_.poll_period_ns);
  n.next_child_ns = phase(options_.poll_period_ns);
}

void RigBusEmulator::go_dark(std::size_t i) {
  Node& n = nodes_[i];
  n.live = false;
  stats_.lost_to_power += n.incoming.size() + n.outgoing.size();
  n.incoming.clear();
  n.outgoing.clear();
}

TimeNs RigBusEmulator::next_event_ns() const {
  TimeNs next = std::min({next_random_power_ns_, next_random_change_ns_, next_power_restore_ns_});
  if (next_scripted_power_ < options_.faults.power_losses.size()) {
    next = std::min(next, options_.faults.power_losses[next_scripted_power_].at_ns);
  }
  if (next_scripted_change_ < options_.faults.topology_changes.size()) {
    next = std::min(next, options_.faults.topology_changes[next_scripted_change_].at_ns);
  }
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const Node& n = nodes_[i];
    if (!n.live) continue;
    const ComponentKind kind = tree_.components[i].kind;
    next = std::min({next, n.next_poll_ns, n.next_type_ns});
    if (kind == ComponentKind::joint) next = std::min(next, n.next_data_ns);
    if (kind != ComponentKind::joint) next = std::min(next, n.next_child_ns);
  }
  if (!nodes_[0].outgoing.empty()) next = std::min(next, next_usb_ns_);
  return next;
}

void RigBusEmulator::advance_to(TimeNs t_ns, std::vector<RigBusEmulatedReport>& out) {
  for (;;) {
    const TimeNs t = std::max(now_ns_, next_event_ns());
    if (t > t_ns) break;
    now_ns_ = t;
    run_faults(t);
    if (power_dirty_ || t >= next_power_restore_ns_) refresh_power(t);
    for (std::size_t i = 0; i < nodes_.size(); ++i) {
      Node& n = nodes_[i];
      if (!n.live) continue;
      const BusComponentSpec& spec = tree_.components[i];
      if (spec.kind == ComponentKind::joint && n.next_data_ns <= t) {
        BusMessage m;
        m.type = BusMessageType::data;
        m.data = quantise_angles(angles_ ? angles_(t, spec.id) : rig_device::JointAngles{});
        create_message(i, m);
        n.next_data_ns += true_period(n, options_.data_period_ns);
      }
      if (n.next_type_ns <= t) {
        BusMessage m;
        m.type = BusMessageType::type;
        m.type_info.kind = spec.kind;
        m.type_info.outlet_count = static_cast<std::uint8_t>(spec.q_inlet_outlet.size());
        m.type_info.colour_rgb = spec.colour_rgb;
        set_kind_name(m.type_info, spec.kind_name);
        create_message(i, m);
        n.next_type_ns += true_period(n, options_.type_period_ns);
      }
      if (spec.kind != ComponentKind::joint && n.next_child_ns <= t) {
        for (std::size_t k = 0; k < spec.q_inlet_outlet.size(); ++k) {
          BusMessage m;
          m.type = BusMessageType::child;
          m.child.outlet = static_cast<std::uint8_t>(k);
          m.child.outlet_count = static_cast<std::uint8_t>(spec.q_inlet_outlet.size());
          m.child.child_id = n.outlet_child[k];
          m.child.q_wxyz = quantise_rotation(spec.q_inlet_outlet[k]);
          create_message(i, m);
        }
        n.next_child_ns += true_period(n, options_.child_period_ns);
      }
      if (n.next_poll_ns <= t) {
        poll(i, t);
        n.next_poll_ns += true_period(n, options_.poll_period_ns);
      }
    }
    if (next_usb_ns_ <= t) usb_frame(t, out);
  }
  now_ns_ = std::max(now_ns_, t_ns);
}

void RigBusEmulator::push_bounded(std::deque<Wire>& q, const Wire& w) {
  if (q.size() >= options_.queue_capacity) {
    q.pop_front();  // the oldest reading is the least useful
    ++stats_.queue_overflows;
  }
  q.push_back(w);
}

void RigBusEmulator::create_message(std::size_t i, BusMessage m) {
  Node& n = nodes_[i];
  m.boot = n.boot_count;
  m.creator_id = tree_.components[i].id;
  m.parent_id = kNoComponent;
  m.parent_outlet = kNoOutlet;
  m.clock_us = clock_us(n, now_ns_);
  Wire w;
  w.size = static_cast<std::uint8_t>(encode_bus_message(m, w.bytes));
  ++stats_.created[static_cast<std::size_t>(m.type) & 3];
  push_bounded(n.outgoing, w);
}

void RigBusEmulator::poll(std::size_t i, TimeNs t) {
  Node& p = nodes_[i];
  const std::uint32_t own_id = tree_.components[i].id;
  const DurationNs forget_after = 10 * true_period(p, options_.poll_period_ns);
  for (std::size_t k = 0; k < p.children.size(); ++k) {
    const int c = p.children[k];
    const bool answers = c >= 0 && nodes_[static_cast<std::size_t>(c)].live &&
                         t >= nodes_[static_cast<std::size_t>(c)].boot_ns + options_.boot_time_ns;
    if (!answers) {
      if (t - p.outlet_answer_ns[k] > forget_after) p.outlet_child[k] = kNoComponent;
      continue;
    }
    p.outlet_answer_ns[k] = t;
    Node& child = nodes_[static_cast<std::size_t>(c)];
    for (std::size_t m = 0; m < options_.max_messages_per_poll && !child.outgoing.empty(); ++m) {
      Wire w = child.outgoing.front();
      child.outgoing.pop_front();
      ++stats_.hops;
      // One draw per stream per hop, whatever the outcome.
      const bool lost = loss_rng_.uniform01() < options_.faults.loss_probability;
      const bool corrupt = corrupt_rng_.uniform01() < options_.faults.corrupt_probability;
      const std::uint64_t byte = corrupt_rng_.below(w.size);
      const std::uint64_t bit = corrupt_rng_.below(8);
      if (lost) {
        ++stats_.lost;
        continue;
      }
      if (corrupt) {
        w.bytes[byte] ^= static_cast<std::uint8_t>(1u << bit);
        ++stats_.corrupted;
      }
      w.outlet = static_cast<std::uint8_t>(k);
      push_bounded(p.incoming, w);
    }
  }
  // The firmware's main loop: check, fill the parent, queue for our parent.
  while (!p.incoming.empty()) {
    Wire w = p.incoming.front();
    p.incoming.pop_front();
    BusMessage m;
    if (!decode_bus_message(std::span<const std::uint8_t>(w.bytes.data(), w.size), m)) {
      ++stats_.crc_dropped;
      continue;
    }
    if (m.parent_id == kNoComponent) {
      m.parent_id = own_id;
      m.parent_outlet = w.outlet;
      p.outlet_child[w.outlet] = m.creator_id;
      w.size = static_cast<std::uint8_t>(encode_bus_message(m, w.bytes));
    }
    push_bounded(p.outgoing, w);
  }
}

void RigBusEmulator::usb_frame(TimeNs t, std::vector<RigBusEmulatedReport>& out) {
  Node& base = nodes_[0];
  next_usb_ns_ = t + options_.usb_frame_ns;
  if (base.outgoing.empty()) return;
  RigBusReport r;
  std::size_t used = 0;
  while (!base.outgoing.empty() && r.count < r.messages.size()) {
    const Wire& w = base.outgoing.front();
    if (used + w.size > kRigBusReportPayloadBytes) break;
    BusMessage m;
    if (decode_bus_message(std::span<const std::uint8_t>(w.bytes.data(), w.size), m)) {
      r.messages[r.count++] = m;
      used += w.size;
    }
    base.outgoing.pop_front();
  }
  if (r.count == 0) return;
  RigBusEmulatedReport rep;
  rep.send_ns = t;
  rep.bytes = encode_rig_bus_report(r);
  out.push_back(rep);
  ++stats_.reports_sent;
  stats_.messages_to_host += r.count;
}

bool RigBusEmulator::is_protected(int node) const {
  for (const std::uint32_t id : options_.faults.protected_ids) {
    const auto it = index_.find(id);
    if (it != index_.end() && in_subtree(it->second, node)) return true;  // node is it or an ancestor of it
  }
  return false;
}

std::vector<std::pair<int, std::uint8_t>> RigBusEmulator::free_outlets(int excluded_subtree) const {
  std::vector<std::pair<int, std::uint8_t>> out;
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    if (!attached(static_cast<int>(i))) continue;
    if (excluded_subtree >= 0 && in_subtree(static_cast<int>(i), excluded_subtree)) continue;
    for (std::size_t k = 0; k < nodes_[i].children.size(); ++k) {
      if (nodes_[i].children[k] < 0) out.emplace_back(static_cast<int>(i), static_cast<std::uint8_t>(k));
    }
  }
  return out;
}

void RigBusEmulator::run_faults(TimeNs t) {
  const auto& script_power = options_.faults.power_losses;
  while (next_scripted_power_ < script_power.size() && script_power[next_scripted_power_].at_ns <= t) {
    const BusPowerLoss& p = script_power[next_scripted_power_++];
    if (!cut_power(p.component_id, p.duration_ns)) ++stats_.changes_skipped;
  }
  const auto& script_changes = options_.faults.topology_changes;
  while (next_scripted_change_ < script_changes.size() && script_changes[next_scripted_change_].at_ns <= t) {
    if (!do_change(script_changes[next_scripted_change_++], t)) ++stats_.changes_skipped;
  }
  while (next_random_power_ns_ <= t) {
    random_power_loss(t);
    next_random_power_ns_ += options_.faults.power_loss_interval_ns;
  }
  while (next_random_change_ns_ <= t) {
    random_topology_change(t);
    next_random_change_ns_ += options_.faults.topology_change_interval_ns;
  }
}

void RigBusEmulator::random_power_loss(TimeNs t) {
  std::vector<int> candidates;
  for (std::size_t i = 1; i < nodes_.size(); ++i) {
    if (nodes_[i].live) candidates.push_back(static_cast<int>(i));
  }
  const double u = fault_rng_.uniform01();
  const DurationNs d = options_.faults.power_loss_min_ns +
                       static_cast<DurationNs>(u * static_cast<double>(options_.faults.power_loss_max_ns -
                                                                        options_.faults.power_loss_min_ns));
  if (candidates.empty()) {
    ++stats_.changes_skipped;
    return;
  }
  const int pick = candidates[fault_rng_.below(candidates.size())];
  (void)cut_power(tree_.components[static_cast<std::size_t>(pick)].id, d);
  (void)t;
}

void RigBusEmulator::random_topology_change(TimeNs t) {
  const auto kind = static_cast<BusTopologyChangeKind>(random_changes_++ % 3);
  BusTopologyChange c;
  c.at_ns = t;
  c.kind = kind;
  std::vector<int> movable;
  for (std::size_t i = 1; i < nodes_.size(); ++i) {
    const int ii = static_cast<int>(i);
    const bool connected = attached(ii);
    if (kind == BusTopologyChangeKind::plug) {
      if (!connected && nodes_[i].parent < 0) movable.push_back(ii);  // a spare subtree's root
    } else if (connected && !is_protected(ii)) {
      movable.push_back(ii);
    }
  }
  if (movable.empty()) {
    ++stats_.changes_skipped;
    return;
  }
  const int pick = movable[fault_rng_.below(movable.size())];
  c.component_id = tree_.components[static_cast<std::size_t>(pick)].id;
  if (kind != BusTopologyChangeKind::unplug) {
    const auto slots = free_outlets(pick);
    if (slots.empty()) {
      ++stats_.changes_skipped;
      return;
    }
    const auto& slot = slots[fault_rng_.below(slots.size())];
    c.new_parent_id = tree_.components[static_cast<std::size_t>(slot.first)].id;
    c.outlet = slot.second;
  }
  if (!do_change(c, t)) ++stats_.changes_skipped;
}

Status RigBusEmulator::apply(BusTopologyChange change) { return do_change(change, now_ns_); }

Status RigBusEmulator::do_change(const BusTopologyChange& c, TimeNs t) {
  auto err = [&](const char* why) {
    char buf[200];
    std::snprintf(buf, sizeof buf, "rig bus emulator: cannot %s component 0x%08x: %s", to_string(c.kind),
                  c.component_id, why);
    return make_error(Errc::invalid_argument, buf);
  };
  const auto it = index_.find(c.component_id);
  if (it == index_.end()) return err("no such component");
  const int i = it->second;
  if (i == 0) return err("the base stays on USB");
  Node& n = nodes_[static_cast<std::size_t>(i)];
  const bool connected = n.parent >= 0;
  if (c.kind == BusTopologyChangeKind::unplug && !connected) return err("it is not plugged in");
  if (c.kind == BusTopologyChangeKind::plug && connected) return err("it is plugged in already");
  if (c.kind == BusTopologyChangeKind::reparent && !connected) return err("it is not plugged in");
  int target = -1;
  if (c.kind != BusTopologyChangeKind::unplug) {
    const auto pt = index_.find(c.new_parent_id);
    if (pt == index_.end()) return err("the new parent does not exist");
    target = pt->second;
    if (in_subtree(target, i)) return err("the new parent is inside the subtree that moves");
    if (c.outlet >= nodes_[static_cast<std::size_t>(target)].children.size()) return err("the outlet does not exist");
    if (nodes_[static_cast<std::size_t>(target)].children[c.outlet] >= 0) return err("the outlet is taken");
  }
  if (connected) {
    nodes_[static_cast<std::size_t>(n.parent)].children[n.parent_outlet] = -1;
    n.parent = -1;
  }
  if (target >= 0) {
    n.parent = target;
    n.parent_outlet = c.outlet;
    nodes_[static_cast<std::size_t>(target)].children[c.outlet] = i;
    // Pulling the plug and pushing it in elsewhere cuts the subtree's power.
    if (c.kind == BusTopologyChangeKind::reparent) n.dark_until_ns = std::max(n.dark_until_ns, t + options_.faults.replug_power_gap_ns);
  }
  BusTruthEvent e;
  e.at_ns = t;
  e.component_id = c.component_id;
  switch (c.kind) {
    case BusTopologyChangeKind::unplug: e.kind = BusTruthEventKind::unplug; ++stats_.unplugs; break;
    case BusTopologyChangeKind::plug: e.kind = BusTruthEventKind::plug; ++stats_.plugs; break;
    case BusTopologyChangeKind::reparent: e.kind = BusTruthEventKind::reparent; ++stats_.reparents; break;
  }
  events_.push_back(e);
  power_dirty_ = true;
  refresh_power(t);
  return {};
}

Status RigBusEmulator::cut_power(std::uint32_t component_id, DurationNs duration_ns) {
  const auto it = index_.find(component_id);
  if (it == index_.end() || it->second == 0) {
    return make_error(Errc::invalid_argument, "rig bus emulator: no link into component " + std::to_string(component_id) +
                                                  " to cut (the base's power is the USB cable)");
  }
  if (duration_ns <= 0) return make_error(Errc::invalid_argument, "rig bus emulator: a power loss must last longer than 0");
  Node& n = nodes_[static_cast<std::size_t>(it->second)];
  n.dark_until_ns = std::max(n.dark_until_ns, now_ns_ + duration_ns);
  ++stats_.power_losses;
  events_.push_back({now_ns_, BusTruthEventKind::power_loss, component_id, duration_ns});
  refresh_power(now_ns_);
  return {};
}

std::vector<RigBusEmulator::Edge> RigBusEmulator::truth_edges() const {
  std::vector<Edge> out;
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    if (!attached(static_cast<int>(i))) continue;
    if (i == 0) {
      out.push_back({tree_.components[0].id, kNoComponent, kNoOutlet});
    } else {
      const Node& n = nodes_[i];
      out.push_back({tree_.components[i].id, tree_.components[static_cast<std::size_t>(n.parent)].id, n.parent_outlet});
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::optional<TimeNs> RigBusEmulator::creation_time_ns(std::uint32_t id, std::uint8_t boot,
                                                        std::uint32_t clock_us_value) const {
  const auto it = index_.find(id);
  if (it == index_.end()) return std::nullopt;
  const Node& n = nodes_[static_cast<std::size_t>(it->second)];
  const std::size_t kept = std::min(n.boots_recorded, n.boots.size());
  for (std::size_t j = 0; j < kept; ++j) {
    if (n.boots[j].first != boot) continue;
    const double true_us = static_cast<double>(clock_us_value) / (1.0 + n.skew_ppm * 1e-6);
    return n.boots[j].second + static_cast<TimeNs>(true_us * 1000.0);
  }
  return std::nullopt;
}

int RigBusEmulator::depth_of(std::uint32_t id) const {
  const auto it = index_.find(id);
  if (it == index_.end()) return -1;
  int depth = 0;
  int i = it->second;
  while (i > 0) {
    i = nodes_[static_cast<std::size_t>(i)].parent;
    if (++depth > static_cast<int>(nodes_.size())) return -1;
  }
  return i == 0 ? depth : -1;
}

bool RigBusEmulator::powered(std::uint32_t id) const {
  const auto it = index_.find(id);
  return it != index_.end() && nodes_[static_cast<std::size_t>(it->second)].live;
}

std::uint32_t RigBusEmulator::base_id() const { return tree_.components[0].id; }

void RigBusEmulatorServerTraits::advance(RigBusEmulator& emulator, const RigBusServeOptions& options, TimeNs now_ns,
                                         std::vector<RigBusEmulatedReport>& out) {
  emulator.advance_to(now_ns + options.lookahead_ns, out);
}

}  // namespace proprio::rig_bus
