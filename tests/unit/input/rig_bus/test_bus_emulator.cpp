// The emulated bus in simulated time with the host's RigBusHost reading its
// reports: parent filling, the topology rebuilt under each fault (power loss
// and reboot, lost and corrupted messages, unplug, hot-plug, re-parent,
// clock skew), detaching after 2 s and not before, no ghosts after an unplug.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <set>

#include "proprio/rig_bus/bus_emulator.hpp"
#include "proprio/rig_bus/bus_host.hpp"

namespace {

using namespace proprio;
using namespace proprio::rig_bus;

constexpr TimeNs kMs = kNsPerMillisecond;
constexpr TimeNs kS = kNsPerSecond;
using Edge = BusTopologyTracker::Edge;

// The emulator and the host, reports arriving 1 ms after the base sends them.
struct Sim {
  explicit Sim(BusTree tree, BusEmulatorOptions o = {}, BusAnglesFn angles = demo_bus_angles)
      : emu(*RigBusEmulator::create(std::move(tree), o, std::move(angles))) {}
  void run_to(TimeNs t_end, TimeNs step = 5 * kMs) {
    for (TimeNs t = now + step; t <= t_end; t += step) {
      out.clear();
      emu.advance_to(t, out);
      for (const auto& r : out) {
        ASSERT_TRUE(host.on_report(r.bytes, r.send_ns + kMs).ok());
        host.for_each_message_of_last_report([&](const BusMessage& m) { messages.push_back(m); });
      }
      host.update(t);
      now = t;
      if (on_step) on_step(t);
    }
  }
  bool matches() const { return host.tracker().attached_edges(now) == emu.truth_edges(); }
  RigBusEmulator emu;
  RigBusHost host;
  std::vector<RigBusEmulatedReport> out;
  std::vector<BusMessage> messages;
  std::function<void(TimeNs)> on_step;
  TimeNs now = 0;
};

TEST(RigBusEmulator, TheFirstReceiverFillsTheParentAndTheOutlet) {
  BusTree tree = make_bench_bus_tree(8, 3);
  const BusTree copy = tree;
  Sim sim(std::move(tree));
  sim.run_to(1 * kS);
  ASSERT_FALSE(sim.messages.empty());
  for (const BusMessage& m : sim.messages) {
    const int i = copy.index_of(m.creator_id);
    ASSERT_GE(i, 0);
    const BusComponentSpec& c = copy.components[static_cast<std::size_t>(i)];
    if (c.kind == ComponentKind::base) {
      EXPECT_EQ(m.parent_id, kNoComponent);  // nobody above the base fills it
      EXPECT_EQ(m.parent_outlet, kNoOutlet);
    } else {
      EXPECT_EQ(m.parent_id, copy.components[static_cast<std::size_t>(c.parent)].id);
      EXPECT_EQ(m.parent_outlet, c.parent_outlet);
    }
  }
  EXPECT_TRUE(sim.matches());
  // The spare chain is not plugged in, so not on the host either.
  EXPECT_EQ(sim.host.tracker().attached_edges(sim.now).size(), copy.components.size() - 2);
}

TEST(RigBusEmulator, MessagesComeAtTheirRatesWithTheCallbacksAngles) {
  Sim sim(make_bus_chain(3, 5));
  sim.run_to(2 * kS);
  std::map<std::uint32_t, std::array<int, 4>> per;  // creator -> count by type
  for (const BusMessage& m : sim.messages) ++per[m.creator_id][static_cast<std::size_t>(m.type)];
  const BusTree& tree = sim.emu.tree();
  for (std::size_t i = 1; i < tree.components.size(); ++i) {
    const auto& n = per[tree.components[i].id];
    EXPECT_NEAR(n[1], 2 * 50, 3);  // data at 50 Hz
    EXPECT_NEAR(n[2], 2 * 2, 1);   // type at 2 Hz
    EXPECT_EQ(n[3], 0);            // joints have no child messages
  }
  EXPECT_NEAR(per[tree.components[0].id][3], 2 * 2, 1);  // the base's one outlet
  // Angles: what the callback said at the message's creation.
  for (const BusMessage& m : sim.messages) {
    if (m.type != BusMessageType::data) continue;
    const auto made = sim.emu.creation_time_ns(m.creator_id, m.boot, m.clock_us);
    ASSERT_TRUE(made.has_value());
    const rig_device::JointAngles want = demo_bus_angles(*made, m.creator_id);
    const rig_device::JointAngles got = angles_from_wire(m.data);
    EXPECT_NEAR(got.bend_x_rad, want.bend_x_rad, 2e-4);
    EXPECT_NEAR(got.twist_out_rad, want.twist_out_rad, 2e-4);
  }
}

TEST(RigBusEmulator, SameSeedSameBytes) {
  BusEmulatorOptions o;
  o.faults.loss_probability = 0.05;
  o.faults.corrupt_probability = 0.05;
  o.faults.clock_skew_max_ppm = 5000;
  o.faults.power_loss_interval_ns = 700 * kMs;
  o.faults.topology_change_interval_ns = 900 * kMs;
  o.faults.topology_change_start_ns = 100 * kMs;
  auto run = [&] {
    auto e = *RigBusEmulator::create(make_bench_bus_tree(8, 2), o, demo_bus_angles);
    std::vector<RigBusEmulatedReport> out;
    e.advance_to(3 * kS, out);
    std::vector<std::uint8_t> all;
    for (const auto& r : out) all.insert(all.end(), r.bytes.begin(), r.bytes.end());
    return all;
  };
  const auto a = run();
  EXPECT_FALSE(a.empty());
  EXPECT_EQ(a, run());
}

TEST(RigBusEmulator, APowerLossRebootsTheSubtreeWithItsIdsAndDetachesNothing) {
  BusTree tree = make_bus_chain(6, 7);
  const std::uint32_t cut = tree.components[3].id;
  BusEmulatorOptions o;
  o.faults.power_losses.push_back({500 * kMs, cut, 1200 * kMs});
  Sim sim(std::move(tree), o);
  std::uint64_t mismatched_steps = 0;
  sim.on_step = [&](TimeNs t) {
    if (t >= 300 * kMs) mismatched_steps += sim.matches() ? 0 : 1;  // after everyone was heard once
  };
  sim.run_to(4 * kS);
  EXPECT_EQ(mismatched_steps, 0u);  // 1.2 s dark is below the 2 s silence: the topology never changed
  EXPECT_EQ(sim.host.stats().tracker.detaches, 0u);
  const BusSnapshot s = sim.host.tracker().snapshot(sim.now);
  const BusTree& t = sim.emu.tree();
  for (std::size_t i = 1; i < t.components.size(); ++i) {
    const BusComponentView* v = s.find(t.components[i].id);
    ASSERT_NE(v, nullptr);
    EXPECT_EQ(v->reboots_seen, i >= 3 ? 1u : 0u) << i;  // the subtree below the cut link rebooted
    EXPECT_EQ(v->boot, i >= 3 ? 2 : 1);
  }
  EXPECT_GT(sim.emu.stats().lost_to_power + sim.emu.stats().boots, 0u);
}

TEST(RigBusEmulator, AnUnpluggedSubtreeDetachesAfterTwoSecondsNotBeforeAndLeavesNoGhost) {
  BusTree tree = make_bench_bus_tree(8, 4);
  const std::uint32_t root = tree.components[4].id;  // below the Y3 at depth 3
  std::set<std::uint32_t> subtree;
  for (std::size_t i = 0; i < tree.components.size(); ++i) {
    int j = static_cast<int>(i);
    while (j > 0 && tree.components[static_cast<std::size_t>(j)].id != root) j = tree.components[static_cast<std::size_t>(j)].parent;
    if (j > 0) subtree.insert(tree.components[i].id);
  }
  ASSERT_GE(subtree.size(), 5u);
  BusEmulatorOptions o;
  const TimeNs unplug_at = 1 * kS;
  o.faults.topology_changes.push_back({unplug_at, BusTopologyChangeKind::unplug, root, 0, 0});
  Sim sim(std::move(tree), o);
  TimeNs matched_at = -1;
  sim.on_step = [&](TimeNs t) {
    const auto seen = sim.host.tracker().attached_edges(t);
    std::size_t visible = 0;
    for (const auto& e : seen) visible += subtree.count(e.id);
    if (t > 300 * kMs && t < unplug_at + 2 * kS - 50 * kMs) {
      EXPECT_EQ(visible, subtree.size()) << "detached early at " << t;
    }
    if (t > unplug_at && matched_at < 0 && sim.matches()) matched_at = t;
  };
  sim.run_to(6 * kS);
  ASSERT_GT(matched_at, 0);
  const DurationNs recovery = matched_at - unplug_at;
  EXPECT_GE(recovery, 2 * kS - 50 * kMs);
  EXPECT_LT(recovery, 2 * kS + 100 * kMs);
  EXPECT_TRUE(sim.matches());  // still, at the end: no ghost
  const BusSnapshot s = sim.host.tracker().snapshot(sim.now);
  for (const std::uint32_t id : subtree) EXPECT_FALSE(s.find(id)->attached);
}

TEST(RigBusEmulator, HotPlugAndReparentAreSeenAtTheFirstMessage) {
  BusTree tree = make_bench_bus_tree(8, 5);
  const int spare = static_cast<int>(tree.components.size()) - 2;
  const std::uint32_t spare_id = tree.components[static_cast<std::size_t>(spare)].id;
  const std::uint32_t tail_id = tree.components[9].id;  // the main branch's last joint, outlet free
  const std::uint32_t side_id = tree.components[11].id;  // a side joint
  BusEmulatorOptions o;
  o.faults.topology_changes.push_back({1 * kS, BusTopologyChangeKind::plug, spare_id, tail_id, 0});
  // The side joint moves under the spare chain's last joint, plugged in by then.
  const std::uint32_t spare_tail_id = tree.components[static_cast<std::size_t>(spare) + 1].id;
  o.faults.topology_changes.push_back({3 * kS, BusTopologyChangeKind::reparent, side_id, spare_tail_id, 0});
  Sim sim(std::move(tree), o);
  std::vector<TimeNs> matched;
  bool was = true;
  sim.on_step = [&](TimeNs t) {
    if (t < 500 * kMs) return;  // the host is still hearing everyone for the first time
    const bool m = sim.matches();
    if (m && !was) matched.push_back(t);
    was = m;
  };
  sim.run_to(5 * kS);
  ASSERT_EQ(sim.emu.stats().plugs, 1u);
  ASSERT_EQ(sim.emu.stats().reparents, 1u);
  ASSERT_EQ(matched.size(), 2u);
  EXPECT_LT(matched[0] - 1 * kS, 500 * kMs);  // boot plus a few polls
  EXPECT_LT(matched[1] - 3 * kS, 800 * kMs);  // the power gap while moving, boot, polls
  EXPECT_TRUE(sim.matches());
  EXPECT_EQ(sim.host.stats().tracker.detaches, 0u);
}

TEST(RigBusEmulator, LostAndCorruptedMessagesAreAccountedForAndNeverReachTheHost) {
  BusEmulatorOptions o;
  o.faults.loss_probability = 0.05;
  o.faults.corrupt_probability = 0.05;
  Sim sim(make_bus_chain(8, 9), o);
  sim.run_to(3 * kS);
  const BusEmulatorStats& s = sim.emu.stats();
  EXPECT_GT(s.lost, 0u);
  EXPECT_GT(s.corrupted, 0u);
  EXPECT_EQ(s.crc_dropped, s.corrupted);  // a single flipped bit never passes CRC-16
  EXPECT_EQ(sim.host.stats().decode_errors, 0u);
  EXPECT_TRUE(sim.matches());
  const std::uint64_t created = s.created[1] + s.created[2] + s.created[3];
  EXPECT_LT(s.messages_to_host, created);
}

TEST(RigBusEmulator, ClockSkewShowsInTheComponentsClocks) {
  BusEmulatorOptions o;
  o.faults.clock_skew_max_ppm = 20'000;
  Sim sim(make_bus_chain(4, 11), o);
  sim.run_to(3 * kS);
  // Each joint times its data by its own clock: consecutive readings are 20 ms
  // apart on that clock (1 µs of counter truncation) ...
  std::map<std::uint32_t, std::uint32_t> last_clock;
  std::size_t pairs = 0;
  for (const BusMessage& m : sim.messages) {
    if (m.type != BusMessageType::data) continue;
    if (const auto it = last_clock.find(m.creator_id); it != last_clock.end()) {
      const std::uint32_t d = m.clock_us - it->second;
      if (d < 30'000) {  // not across a lost message
        EXPECT_NEAR(static_cast<double>(d), 20'000.0, 1.0);
        ++pairs;
      }
    }
    last_clock[m.creator_id] = m.clock_us;
  }
  EXPECT_GT(pairs, 400u);
  // ... while their clocks run at different rates against true time, each within the bound.
  std::map<std::uint32_t, std::pair<TimeNs, std::uint32_t>> first, last;
  for (const BusMessage& m : sim.messages) {
    const auto t = sim.emu.creation_time_ns(m.creator_id, m.boot, m.clock_us);
    ASSERT_TRUE(t);
    if (!first.count(m.creator_id)) first[m.creator_id] = {*t, m.clock_us};
    last[m.creator_id] = {*t, m.clock_us};
  }
  std::set<long> rates_kppm;
  for (const auto& [id, f] : first) {
    const auto& l = last[id];
    const double rate = static_cast<double>(l.second - f.second) * 1000.0 / static_cast<double>(l.first - f.first);
    rates_kppm.insert(std::lround((rate - 1.0) * 1e3));
    EXPECT_LE(std::abs(rate - 1.0), 0.0201);
  }
  EXPECT_GE(rates_kppm.size(), 2u);
  EXPECT_TRUE(sim.matches());  // the host orders by clock only within one component
}

TEST(RigBusEmulator, RandomFaultsKeepTheHostInStepWithTheTruth) {
  BusEmulatorOptions o;
  o.seed = 21;
  o.faults.loss_probability = 0.01;
  o.faults.corrupt_probability = 0.005;
  o.faults.clock_skew_max_ppm = 10'000;
  o.faults.power_loss_interval_ns = 2 * kS;
  o.faults.topology_change_interval_ns = 4 * kS;
  o.faults.topology_change_start_ns = 1 * kS;
  Sim sim(make_bench_bus_tree(8, 6), o);
  sim.run_to(20 * kS);
  const BusEmulatorStats& s = sim.emu.stats();
  EXPECT_GE(s.power_losses, 9u);
  EXPECT_GE(s.unplugs + s.plugs + s.reparents, 4u);
  // The last change was at 17 s; 3 s later everything is seen through.
  EXPECT_TRUE(sim.matches());
}

TEST(RigBusEmulator, QueuesStayBounded) {
  BusEmulatorOptions o;
  o.queue_capacity = 4;
  o.max_messages_per_poll = 1;  // a starved bus
  Sim sim(make_bench_bus_tree(8, 8), o);
  sim.run_to(1 * kS);
  EXPECT_GT(sim.emu.stats().queue_overflows, 0u);
}

TEST(RigBusEmulator, RefusesBadTreesAndOptionsWithUsableMessages) {
  auto message = [](const BusTree& t, BusEmulatorOptions o = {}) {
    auto e = RigBusEmulator::create(t, o);
    return e ? std::string() : e.error().message;
  };
  BusTree t = make_bus_chain(3);
  EXPECT_EQ(message(t), "");
  BusTree dup = t;
  dup.components[2].id = dup.components[1].id;
  EXPECT_NE(message(dup).find("same ID"), std::string::npos);
  BusTree zero = t;
  zero.components[1].id = 0;
  EXPECT_NE(message(zero).find("ID 0"), std::string::npos);
  BusTree shared = t;
  shared.components[3].parent = 1;
  shared.components[2].parent = 1;
  shared.components[2].parent_outlet = 0;
  shared.components[3].parent_outlet = 0;
  EXPECT_NE(message(shared).find("outlet"), std::string::npos);
  BusTree cycle = t;
  cycle.components[1].parent = 3;
  EXPECT_NE(message(cycle).find("ancestor"), std::string::npos);
  BusTree nobase = t;
  nobase.components[0].kind = ComponentKind::joint;
  EXPECT_NE(message(nobase).find("base"), std::string::npos);
  BusEmulatorOptions o;
  o.faults.loss_probability = 2.0;
  EXPECT_NE(message(t, o).find("loss_probability"), std::string::npos);
  o = {};
  o.max_messages_per_poll = 0;
  EXPECT_NE(message(t, o).find("max_messages_per_poll"), std::string::npos);
  EXPECT_FALSE(BusEmulatorOptions{}.describe().empty());
}

TEST(RigBusEmulator, RefusesImpossibleChanges) {
  auto e = *RigBusEmulator::create(make_bus_chain(3), {});
  const BusTree& t = e.tree();
  EXPECT_FALSE(e.apply({0, BusTopologyChangeKind::unplug, t.components[0].id, 0, 0}));  // the base
  EXPECT_FALSE(e.apply({0, BusTopologyChangeKind::plug, t.components[2].id, t.components[0].id, 0}));  // plugged
  // Into its own subtree.
  EXPECT_FALSE(e.apply({0, BusTopologyChangeKind::reparent, t.components[1].id, t.components[3].id, 0}));
  EXPECT_FALSE(e.cut_power(t.components[0].id, kS));
  EXPECT_TRUE(e.apply({0, BusTopologyChangeKind::unplug, t.components[2].id, 0, 0}));
  EXPECT_EQ(e.depth_of(t.components[3].id), -1);
  EXPECT_EQ(e.truth_edges().size(), 2u);
}

}  // namespace
