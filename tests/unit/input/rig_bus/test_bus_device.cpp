// RigBusDevice on the kit's fake HID link with the emulated bus served in
// real time at the other end (hid::EmulatorServer), as `proprio rig emulate`
// runs it. Threads: every wait is for a condition with a generous deadline
// (20 s); nothing here asserts how long anything took.
#include <gtest/gtest.h>

#include <memory>

#include "proprio/hid/hid_transport.hpp"
#include "proprio/rig_bus/bus_device.hpp"
#include "proprio/rig_bus/bus_emulator.hpp"
#include "support/board_rig.hpp"
#include "support/devices.hpp"

namespace {

using namespace proprio;
using namespace proprio::rig_bus;
using testing_support::wait_until;

struct BusRig {
  explicit BusRig(BusTree tree, BusEmulatorOptions eo = {}, hid::FakeHidFaults faults = {})
      : truth(tree),
        link(std::make_shared<hid::FakeHidLink>(MonotonicClock::instance(), faults)),
        server(*RigBusEmulator::create(std::move(tree), eo, demo_bus_angles), link),
        device(std::make_unique<hid::FakeHidTransport>(link), testing_support::quick_link<RigBusDeviceOptions>()) {}
  ~BusRig() {
    device.stop();
    server.stop();
  }
  // Every plugged-in component attached, with the parent the tree gives it.
  bool all_attached() {
    const BusSnapshot s = device.snapshot();
    for (std::size_t i = 0; i < truth.components.size(); ++i) {
      const BusComponentSpec& c = truth.components[i];
      if (truth.depth_of(i) < 0) continue;  // a spare, not plugged in
      const BusComponentView* v = s.find(c.id);
      if (!v || !v->attached) {
        last_problem = "component " + std::to_string(c.id) + (v ? " detached" : " not seen");
        return false;
      }
      const std::uint32_t parent = c.parent < 0 ? kNoComponent : truth.components[static_cast<std::size_t>(c.parent)].id;
      if (v->parent_id != parent) {
        last_problem = "component " + std::to_string(c.id) + " under " + std::to_string(v->parent_id);
        return false;
      }
    }
    return true;
  }
  std::string last_problem;  // why all_attached() last said no
  BusTree truth;
  std::shared_ptr<hid::FakeHidLink> link;
  RigBusEmulatorServer server;
  RigBusDevice device;
};

TEST(RigBusDevice, TheHostSeesTheWholeTreeWithKindsAndAngles) {
  BusRig rig(make_bench_bus_tree(8, 1));
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  ASSERT_TRUE(wait_until([&] { return rig.all_attached(); })) << rig.last_problem;
  // Wait for every kind to be known and every joint's first reading.
  ASSERT_TRUE(wait_until([&] {
    const BusSnapshot s = rig.device.snapshot();
    for (const auto& v : s.components) {
      if (!v.type_known || (v.kind == ComponentKind::joint && !v.have_angles)) return false;
    }
    return !s.components.empty();
  }));
  const BusSnapshot s = rig.device.snapshot();
  EXPECT_EQ(s.base_id, rig.truth.components[0].id);
  for (std::size_t i = 0; i < rig.truth.components.size(); ++i) {
    const BusComponentSpec& c = rig.truth.components[i];
    if (rig.truth.depth_of(i) < 0) continue;
    const BusComponentView* v = s.find(c.id);
    ASSERT_NE(v, nullptr);
    EXPECT_EQ(v->kind, c.kind);
    EXPECT_EQ(v->kind_name, c.kind_name);
    EXPECT_EQ(v->colour_rgb, c.colour_rgb);
    EXPECT_EQ(v->have_angles, c.kind == ComponentKind::joint);
    if (c.parent >= 0) {
      EXPECT_EQ(v->parent_outlet, c.parent_outlet);
    }
  }
  const RigBusDeviceStats st = rig.device.stats();
  EXPECT_GT(st.host.reports, 0u);
  EXPECT_EQ(st.host.decode_errors, 0u);
  EXPECT_EQ(st.connects, 1u);
}

TEST(RigBusDevice, ComesBackAfterTheUsbCableIsPulledAndDetachesASilentBus) {
  BusRig rig(make_bus_chain(4, 2));
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  ASSERT_TRUE(wait_until([&] { return rig.all_attached(); }));
  rig.link->unplug_for(300 * kNsPerMillisecond);
  ASSERT_TRUE(wait_until([&] { return rig.device.stats().disconnects >= 1; }));
  ASSERT_TRUE(wait_until([&] { return rig.device.stats().connects >= 2 && rig.all_attached(); }));
  // The bus stops talking: after the silence everything is detached.
  rig.server.stop();
  ASSERT_TRUE(wait_until([&] {
    const BusSnapshot s = rig.device.snapshot();
    return !s.components.empty() && s.attached == 0;
  }));
}

TEST(RigBusDevice, LinkFaultsCostReportsNotTheTopology) {
  hid::FakeHidFaults f;
  f.corrupt_probability = 0.05;
  f.drop_probability = 0.05;
  f.duplicate_probability = 0.05;
  f.reorder_probability = 0.05;
  BusEmulatorOptions eo;
  eo.faults.loss_probability = 0.01;
  BusRig rig(make_bench_bus_tree(8, 3), eo, f);
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  ASSERT_TRUE(wait_until([&] { return rig.all_attached() && rig.device.stats().host.decode_errors > 0; }))
      << rig.last_problem;
  EXPECT_EQ(rig.device.stats().host.tracker.detaches, 0u);
}

TEST(RigBusDeviceOptions, RefusesBadValues) {
  RigBusDeviceOptions o;
  EXPECT_TRUE(o.validate().ok());
  EXPECT_FALSE(o.describe().empty());
  o.read_timeout_ns = 3 * kNsPerSecond;
  EXPECT_NE(o.validate().error().message.find("read_timeout_ns"), std::string::npos);
  RigBusDevice no_transport(nullptr);
  EXPECT_FALSE(no_transport.start().ok());
  EXPECT_TRUE(no_transport.snapshot().components.empty());
}

}  // namespace
