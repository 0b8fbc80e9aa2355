// The host's topology tracker on hand-made messages: the parent table,
// detaching after 2 s of silence and not before, subtrees going with their
// root, stale messages unable to undo a re-parent, and a bounded table.
#include <gtest/gtest.h>

#include "proprio/rig_bus/bus_host.hpp"

namespace {

using namespace proprio;
using namespace proprio::rig_bus;

constexpr std::uint32_t kBase = 100, kA = 200, kB = 300, kC = 400;
constexpr TimeNs kTrkMs = kNsPerMillisecond;

BusMessage msg(std::uint32_t creator, std::uint32_t parent, std::uint8_t outlet, std::uint32_t clock_us,
               std::uint8_t boot = 1) {
  BusMessage m;
  m.type = BusMessageType::data;
  m.creator_id = creator;
  m.parent_id = parent;
  m.parent_outlet = parent == kNoComponent ? kNoOutlet : outlet;
  m.clock_us = clock_us;
  m.boot = boot;
  return m;
}

// base <- A (outlet 0) <- B (outlet 0); C on the base's outlet 1.
void hear_all(BusTopologyTracker& t, TimeNs now, std::uint32_t clock_us) {
  t.on_message(msg(kBase, 0, 0, clock_us), now);
  t.on_message(msg(kA, kBase, 0, clock_us), now);
  t.on_message(msg(kB, kA, 0, clock_us), now);
  t.on_message(msg(kC, kBase, 1, clock_us), now);
}

TEST(RigBusTracker, RebuildsTheParentTableFromParentFields) {
  BusTopologyTracker t;
  hear_all(t, 10 * kTrkMs, 1000);
  const auto edges = t.attached_edges(10 * kTrkMs);
  using E = BusTopologyTracker::Edge;
  const std::vector<E> want{{kBase, 0, kNoOutlet}, {kA, kBase, 0}, {kB, kA, 0}, {kC, kBase, 1}};
  EXPECT_EQ(edges, want);
  EXPECT_EQ(t.base_id(), kBase);
  const BusSnapshot s = t.snapshot(10 * kTrkMs);
  EXPECT_EQ(s.attached, 4u);
  ASSERT_NE(s.find(kB), nullptr);
  EXPECT_EQ(s.find(kB)->parent_id, kA);
  EXPECT_TRUE(s.find(kB)->have_angles);
}

TEST(RigBusTracker, DetachesAfterTwoSecondsOfSilenceAndNotBefore) {
  BusTopologyTracker t;
  hear_all(t, 0, 0);
  // Everyone but B keeps talking.
  for (TimeNs now = 20 * kTrkMs; now <= 3 * kNsPerSecond; now += 20 * kTrkMs) {
    const auto clock = static_cast<std::uint32_t>(now / 1000);
    t.on_message(msg(kBase, 0, 0, clock), now);
    t.on_message(msg(kA, kBase, 0, clock), now);
    t.on_message(msg(kC, kBase, 1, clock), now);
    t.update(now);
    const BusSnapshot s = t.snapshot(now);
    EXPECT_EQ(s.find(kB)->attached, now < 2 * kNsPerSecond) << now;
    EXPECT_TRUE(s.find(kA)->attached);
  }
  EXPECT_EQ(t.stats().detaches, 1u);
}

TEST(RigBusTracker, ASilentComponentTakesItsSubtreeWithIt) {
  BusTopologyTracker t;
  hear_all(t, 0, 0);
  // B keeps talking but names a parent the host never heard of (X, say, whose
  // messages are all lost): B's chain does not reach the base.
  constexpr std::uint32_t kX = 999;
  for (TimeNs now = 20 * kTrkMs; now <= 2500 * kTrkMs; now += 20 * kTrkMs) {
    const auto clock = static_cast<std::uint32_t>(now / 1000);
    t.on_message(msg(kBase, 0, 0, clock), now);
    t.on_message(msg(kB, kX, 0, clock), now);
    t.on_message(msg(kC, kBase, 1, clock), now);
  }
  const BusSnapshot s = t.snapshot(2500 * kTrkMs);
  EXPECT_FALSE(s.find(kA)->attached);  // silent for 2.5 s
  EXPECT_FALSE(s.find(kB)->attached);
  EXPECT_LT(s.find(kB)->silent_ns, 100 * kTrkMs);
  EXPECT_TRUE(s.find(kC)->attached);
  EXPECT_TRUE(s.find(kBase)->attached);
  // Once X is heard, with the base as its parent, B is attached through it.
  t.on_message(msg(kX, kBase, 2, 5'000'000), 2510 * kTrkMs);
  EXPECT_TRUE(t.snapshot(2510 * kTrkMs).find(kB)->attached);
}

TEST(RigBusTracker, AParentThatRelaysItsChildrenIsHeardThroughThem) {
  BusTopologyTracker t;
  hear_all(t, 0, 0);
  // A (a quiet splitter, say) makes nothing itself; B's messages name it as parent.
  for (TimeNs now = 20 * kTrkMs; now <= 3 * kNsPerSecond; now += 20 * kTrkMs) {
    const auto clock = static_cast<std::uint32_t>(now / 1000);
    t.on_message(msg(kBase, 0, 0, clock), now);
    t.on_message(msg(kB, kA, 0, clock), now);
  }
  const BusSnapshot s = t.snapshot(3 * kNsPerSecond);
  EXPECT_TRUE(s.find(kA)->attached);
  EXPECT_TRUE(s.find(kB)->attached);
  EXPECT_FALSE(s.find(kC)->attached);
}

TEST(RigBusTracker, AReparentStandsAgainstOlderMessagesFromTheOldPath) {
  BusTopologyTracker t;
  hear_all(t, 0, 1000);
  // B moves to C's outlet 0: a newer message says so...
  t.on_message(msg(kB, kC, 0, 2000), 10 * kTrkMs);
  // ... then one made before the move arrives late through A.
  t.on_message(msg(kB, kA, 0, 1500), 12 * kTrkMs);
  const BusSnapshot s = t.snapshot(12 * kTrkMs);
  EXPECT_EQ(s.find(kB)->parent_id, kC);
  EXPECT_EQ(t.stats().stale_messages, 1u);
  // After a reboot (a later boot count) the clock restarts, and it still counts as newer.
  t.on_message(msg(kB, kA, 0, 5, 2), 300 * kTrkMs);
  EXPECT_EQ(t.snapshot(300 * kTrkMs).find(kB)->parent_id, kA);
  EXPECT_EQ(t.snapshot(300 * kTrkMs).find(kB)->reboots_seen, 1u);
}

TEST(RigBusTracker, TypeAndChildMessagesFillTheView) {
  BusTopologyTracker t;
  hear_all(t, 0, 10);
  BusMessage type;
  type.type = BusMessageType::type;
  type.creator_id = kA;
  type.parent_id = kBase;
  type.parent_outlet = 0;
  type.clock_us = 20;
  type.boot = 1;  // hear_all's boot: a lower one would be older
  type.type_info.kind = ComponentKind::splitter;
  type.type_info.outlet_count = 2;
  type.type_info.colour_rgb = {9, 8, 7};
  set_kind_name(type.type_info, "Y2");
  t.on_message(type, 5 * kTrkMs);
  BusMessage child = type;
  child.type = BusMessageType::child;
  child.clock_us = 30;
  child.child.outlet = 1;
  child.child.outlet_count = 2;
  child.child.child_id = kB;
  child.child.q_wxyz = quantise_rotation(Quat(Eigen::AngleAxisd(0.5, Vec3::UnitX())));
  t.on_message(child, 6 * kTrkMs);
  const BusSnapshot s = t.snapshot(6 * kTrkMs);
  const BusComponentView* a = s.find(kA);
  ASSERT_NE(a, nullptr);
  EXPECT_TRUE(a->type_known);
  EXPECT_EQ(a->kind, ComponentKind::splitter);
  EXPECT_EQ(a->kind_name, "Y2");
  EXPECT_EQ(a->colour_rgb, (std::array<std::uint8_t, 3>{9, 8, 7}));
  ASSERT_EQ(a->outlets.size(), 2u);
  EXPECT_FALSE(a->outlets[0].known);
  EXPECT_TRUE(a->outlets[1].known);
  EXPECT_EQ(a->outlets[1].child_id, kB);
  EXPECT_LT(a->outlets[1].q_inlet_outlet.angularDistance(Quat(Eigen::AngleAxisd(0.5, Vec3::UnitX()))), 1e-3);
}

TEST(RigBusTracker, TheTableStaysBounded) {
  BusTrackerOptions o;
  o.max_components = 8;
  BusTopologyTracker t(o);
  t.on_message(msg(kBase, 0, 0, 1), 0);
  for (std::uint32_t id = 1000; id < 1100; ++id) t.on_message(msg(id, kBase, 0, 1), kTrkMs);
  EXPECT_LE(t.snapshot(kTrkMs).components.size(), 8u);
  EXPECT_GT(t.stats().table_full, 0u);
  // Once they are all silent, newcomers evict them.
  t.on_message(msg(kBase, 0, 0, 5'000'000), 5 * kNsPerSecond);
  t.on_message(msg(5000, kBase, 0, 1), 5 * kNsPerSecond);
  EXPECT_NE(t.snapshot(5 * kNsPerSecond).find(5000), nullptr);
  EXPECT_GT(t.stats().evicted, 0u);
}

TEST(RigBusTracker, AParentCycleIsDetachedNotLooped) {
  BusTopologyTracker t;
  t.on_message(msg(kBase, 0, 0, 1), 0);
  t.on_message(msg(kA, kB, 0, 1), 0);
  t.on_message(msg(kB, kA, 0, 1), 0);
  const BusSnapshot s = t.snapshot(kTrkMs);
  EXPECT_FALSE(s.find(kA)->attached);
  EXPECT_FALSE(s.find(kB)->attached);
  EXPECT_EQ(s.attached, 1u);
}

TEST(RigBusHost, CountsReportsItCannotReadAndKeepsTheRest) {
  RigBusHost host;
  RigBusReport r;
  r.count = 1;
  r.messages[0] = msg(kBase, 0, 0, 1);
  auto good = encode_rig_bus_report(r);
  auto bad = good;
  bad[10] ^= 0x40;
  EXPECT_TRUE(host.on_report(good, kTrkMs).ok());
  EXPECT_FALSE(host.on_report(bad, 2 * kTrkMs).ok());
  const RigBusHostStats s = host.stats();
  EXPECT_EQ(s.reports, 2u);
  EXPECT_EQ(s.decode_errors, 1u);
  EXPECT_EQ(s.decode_errors_by_code[static_cast<std::size_t>(BusDecodeErrc::crc_mismatch)], 1u);
  EXPECT_EQ(s.messages, 1u);
  EXPECT_EQ(host.tracker().base_id(), kBase);
}

TEST(RigBusTrackerOptions, RefusesBadValuesWithUsableMessages) {
  BusTrackerOptions o;
  EXPECT_TRUE(o.validate().ok());
  EXPECT_FALSE(o.describe().empty());
  o.detach_after_ns = 0;
  EXPECT_NE(o.validate().error().message.find("detach_after_ns"), std::string::npos);
  o = {};
  o.max_components = 1;
  EXPECT_NE(o.validate().error().message.find("max_components"), std::string::npos);
}

}  // namespace
