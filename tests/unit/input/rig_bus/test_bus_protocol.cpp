// The rig bus's message format and the base's HID report: round trips, every
// corrupted bit caught, every field check reachable behind a valid CRC, and
// a decoder that reads nothing beyond what it is given.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <set>
#include <vector>

#include "proprio/hid/crc16.hpp"
#include "proprio/rig_bus/bus_emulator.hpp"
#include "proprio/rig_bus/bus_host.hpp"
#include "proprio/rig_bus/bus_protocol.hpp"
#include "support/devices.hpp"
#include "support/seed_corpus.hpp"

namespace {

using namespace proprio;
using namespace proprio::rig_bus;

constexpr double kPiT = 3.14159265358979323846;

BusMessage data_message() {
  BusMessage m;
  m.type = BusMessageType::data;
  m.boot = 3;
  m.creator_id = 0x12345678;
  m.clock_us = 0xFFFF0000u;
  rig_device::JointAngles a;
  a.twist_in_rad = 0.5;
  a.bend_x_rad = -1.2;
  a.bend_y_rad = 0.25;
  a.twist_out_rad = 3.0;
  m.data = quantise_angles(a);
  return m;
}

BusMessage type_message() {
  BusMessage m;
  m.type = BusMessageType::type;
  m.creator_id = 0xCAFE0001;
  m.parent_id = 0xBEEF0002;
  m.parent_outlet = 2;
  m.type_info.kind = ComponentKind::splitter;
  m.type_info.outlet_count = 3;
  m.type_info.colour_rgb = {1, 2, 3};
  set_kind_name(m.type_info, "Y3");
  return m;
}

BusMessage child_message() {
  BusMessage m;
  m.type = BusMessageType::child;
  m.creator_id = 0xCAFE0001;
  m.child.outlet = 1;
  m.child.outlet_count = 3;
  m.child.child_id = 0x0BADF00D;
  m.child.q_wxyz = quantise_rotation(Quat(Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized())));
  return m;
}

std::vector<std::uint8_t> reseal(std::vector<std::uint8_t> b) {
  hid::seal_crc(b, b.size() - 2);
  return b;
}

TEST(RigBusProtocol, EveryMessageTypeRoundTrips) {
  for (const BusMessage& m : {data_message(), type_message(), child_message()}) {
    const auto bytes = encode_bus_message(m);
    ASSERT_EQ(bytes.size(), bus_message_size(bytes[0]));
    BusMessage back;
    ASSERT_TRUE(decode_bus_message(bytes, back).ok()) << describe(decode_bus_message(bytes, back));
    EXPECT_EQ(back, m);
  }
  EXPECT_EQ(encode_bus_message(data_message()).size(), kBusDataMessageSize);
  EXPECT_EQ(encode_bus_message(type_message()).size(), kBusTypeMessageSize);
  EXPECT_EQ(encode_bus_message(child_message()).size(), kBusChildMessageSize);
}

TEST(RigBusProtocol, ReportsCarryUpToTwoMessagesAndRoundTrip) {
  RigBusReport r;
  r.count = 2;
  r.messages[0] = data_message();
  r.messages[1] = data_message();
  r.messages[1].creator_id = 77;
  const auto bytes = encode_rig_bus_report(r);
  RigBusReport back;
  ASSERT_TRUE(decode_rig_bus_report(bytes, back).ok());
  EXPECT_EQ(back, r);
  // A type message and a data message fill the 59-byte payload exactly.
  r.messages[0] = type_message();
  ASSERT_TRUE(decode_rig_bus_report(encode_rig_bus_report(r), back).ok());
  EXPECT_EQ(back, r);
  // Two type messages do not fit: the encoder sends what fits and says so.
  r.messages[1] = type_message();
  ASSERT_TRUE(decode_rig_bus_report(encode_rig_bus_report(r), back).ok());
  EXPECT_EQ(back.count, 1);
  RigBusReport empty;
  ASSERT_TRUE(decode_rig_bus_report(encode_rig_bus_report(empty), back).ok());
  EXPECT_EQ(back.count, 0);
}

TEST(RigBusProtocol, EverySingleBitFlipIsCaught) {
  for (const BusMessage& m : {data_message(), type_message(), child_message()}) {
    const auto bytes = encode_bus_message(m);
    for (std::size_t i = 0; i < bytes.size() * 8; ++i) {
      auto b = bytes;
      b[i / 8] ^= static_cast<std::uint8_t>(1u << (i % 8));
      BusMessage out;
      EXPECT_FALSE(decode_bus_message(b, out).ok()) << "bit " << i;
    }
  }
  RigBusReport r;
  r.count = 2;
  r.messages[0] = data_message();
  r.messages[1] = child_message();
  const auto report = encode_rig_bus_report(r);
  for (std::size_t i = 0; i < report.size() * 8; ++i) {
    auto b = report;
    b[i / 8] ^= static_cast<std::uint8_t>(1u << (i % 8));
    RigBusReport out;
    EXPECT_FALSE(decode_rig_bus_report(b, out).ok()) << "bit " << i;
  }
}

TEST(RigBusProtocol, TruncatedAndOverlongInputIsRefusedWithoutReadingPastIt) {
  const auto bytes = encode_bus_message(type_message());
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    // A copy of exactly n bytes: ASan would catch a read past it.
    const std::vector<std::uint8_t> cut(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(n));
    BusMessage out;
    const BusDecodeStatus s = decode_bus_message(cut, out);
    EXPECT_FALSE(s.ok());
    EXPECT_EQ(s.code, n == 0 ? BusDecodeErrc::empty : BusDecodeErrc::bad_length);
    EXPECT_EQ(out, BusMessage{});
  }
  auto longer = bytes;
  longer.push_back(0);
  BusMessage out;
  EXPECT_EQ(decode_bus_message(longer, out).code, BusDecodeErrc::bad_length);
  const auto report = encode_rig_bus_report(RigBusReport{});
  const std::vector<std::uint8_t> short_report(report.begin(), report.begin() + 40);
  RigBusReport r;
  EXPECT_EQ(decode_rig_bus_report(short_report, r).code, BusDecodeErrc::bad_length);
}

TEST(RigBusProtocol, FieldChecksBehindAValidCrcSayWhatIsWrong) {
  auto expect_code = [](std::vector<std::uint8_t> b, BusDecodeErrc code) {
    b = reseal(std::move(b));
    BusMessage out;
    const BusDecodeStatus s = decode_bus_message(b, out);
    EXPECT_EQ(s.code, code) << to_string(s.code);
    EXPECT_FALSE(describe(s).empty());
    EXPECT_NE(to_error(s).message.find("rig bus"), std::string::npos);
  };
  auto d = encode_bus_message(data_message());
  {
    auto b = d;
    b[2] = b[3] = b[4] = b[5] = 0;  // creator 0
    expect_code(b, BusDecodeErrc::bad_id);
  }
  {
    auto b = d;
    b[10] = 0;  // outlet without a parent
    expect_code(b, BusDecodeErrc::bad_outlet);
  }
  {
    auto b = d;
    b[6] = 1;  // a parent, outlet still 0xFF
    expect_code(b, BusDecodeErrc::bad_outlet);
  }
  {
    auto b = d;
    hid::put_i16(&b[15], 18001);
    expect_code(b, BusDecodeErrc::bad_angle);
    hid::put_i16(&b[15], -18000);  // that is +18000, the one code for 180°
    expect_code(b, BusDecodeErrc::bad_angle);
  }
  {
    auto b = d;
    b[0] = 0x15;  // type 5
    expect_code(b, BusDecodeErrc::unknown_message_type);
    b[0] = 0x21;  // major 2
    BusMessage out;
    EXPECT_EQ(decode_bus_message(b, out).code, BusDecodeErrc::unsupported_version);
    EXPECT_EQ(to_error(decode_bus_message(b, out)).code, Errc::unsupported);
  }
  auto t = encode_bus_message(type_message());
  {
    auto b = t;
    b[16] = 1;  // a splitter with one outlet
    expect_code(b, BusDecodeErrc::bad_kind);
    b = t;
    b[15] = 9;
    expect_code(b, BusDecodeErrc::bad_kind);
  }
  {
    auto b = t;
    b[20] = 0x07;  // unprintable name byte
    expect_code(b, BusDecodeErrc::bad_name);
    b = t;
    b[25] = 'x';  // a byte after the name's NUL
    expect_code(b, BusDecodeErrc::bad_name);
  }
  auto c = encode_bus_message(child_message());
  {
    auto b = c;
    b[15] = 3;  // outlet 3 of 3
    expect_code(b, BusDecodeErrc::bad_outlet);
    b = c;
    for (std::size_t i = 21; i < 29; ++i) b[i] = 0;  // zero quaternion
    expect_code(b, BusDecodeErrc::bad_rotation);
  }
  // Reports: the count, an inner message, and the padding.
  RigBusReport r;
  r.count = 1;
  r.messages[0] = data_message();
  const auto rb = encode_rig_bus_report(r);
  auto report_code = [](std::array<std::uint8_t, kRigBusReportSize> b) {
    hid::seal_crc(b, kRigBusReportCrcAt);
    RigBusReport out;
    const BusDecodeStatus s = decode_rig_bus_report(b, out);
    EXPECT_FALSE(describe(s).empty());
    return s;
  };
  {
    auto b = rb;
    b[2] = 3;
    EXPECT_EQ(report_code(b).code, BusDecodeErrc::bad_count);
    b = rb;
    b[3 + 20] ^= 1;  // inside the message: its own CRC fails
    const BusDecodeStatus s = report_code(b);
    EXPECT_EQ(s.code, BusDecodeErrc::bad_message);
    EXPECT_EQ(s.expected, 0u);
    EXPECT_EQ(static_cast<BusDecodeErrc>(s.actual), BusDecodeErrc::crc_mismatch);
    b = rb;
    b[60] = 1;
    EXPECT_EQ(report_code(b).code, BusDecodeErrc::bad_padding);
    b = rb;
    b[2] = 2;  // a second message that is all zero bytes
    EXPECT_EQ(report_code(b).code, BusDecodeErrc::bad_message);
    b = rb;
    b[0] = 0x51;
    EXPECT_EQ(report_code(b).code, BusDecodeErrc::unknown_report_id);
    EXPECT_NE(describe(report_code(b)).find("FTM"), std::string::npos);
  }
}

TEST(RigBusProtocol, AnglesQuantiseToCentidegreesAndWrap) {
  rig_device::JointAngles a;
  a.twist_in_rad = 0.123456;
  a.bend_x_rad = -1.3;
  a.bend_y_rad = 2.0 * kPiT + 0.1;  // wraps to 0.1
  a.twist_out_rad = std::nan("");
  const rig_device::JointAngles back = angles_from_wire(quantise_angles(a));
  const double half_lsb = 0.005 * kPiT / 180.0 + 1e-12;
  EXPECT_NEAR(back.twist_in_rad, a.twist_in_rad, half_lsb);
  EXPECT_NEAR(back.bend_x_rad, a.bend_x_rad, half_lsb);
  EXPECT_NEAR(back.bend_y_rad, 0.1, half_lsb);
  EXPECT_EQ(back.twist_out_rad, 0.0);
  rig_device::JointAngles edge;
  edge.twist_in_rad = kPiT;
  EXPECT_EQ(quantise_angles(edge).angles_cdeg[0], 18000);
}

TEST(RigBusProtocol, RotationsSurviveTheWire) {
  const Quat q(Eigen::AngleAxisd(2.5, Vec3(0.3, -1, 0.2).normalized()));
  const Quat back = rotation_from_wire(quantise_rotation(q));
  EXPECT_LT(back.angularDistance(q), 1e-4);
  const Quat flipped(-q.w(), -q.x(), -q.y(), -q.z());
  EXPECT_EQ(quantise_rotation(flipped), quantise_rotation(q));
}

TEST(RigBusProtocol, IdsFromProgrammingTimesAreNonZeroAndSpread) {
  std::set<std::uint32_t> ids;
  for (std::uint64_t t = 0; t < 10000; ++t) {
    const std::uint32_t id = component_id_for(1'700'000'000'000'000ull + t * 1'000'000ull);
    EXPECT_NE(id, kNoComponent);
    ids.insert(id);
  }
  EXPECT_EQ(ids.size(), 10000u);  // a second apart never collides in this range
}

TEST(RigBusProtocol, NewerOrdersAcrossWrapsAndReboots) {
  EXPECT_TRUE(bus_newer(1, 100, 1, 50));
  EXPECT_FALSE(bus_newer(1, 50, 1, 100));
  EXPECT_FALSE(bus_newer(1, 100, 1, 100));
  EXPECT_TRUE(bus_newer(1, 5, 1, 0xFFFFFFF0u));  // the µs counter wrapped
  EXPECT_TRUE(bus_newer(2, 0, 1, 4'000'000'000u));  // a reboot restarts the clock
  EXPECT_TRUE(bus_newer(0, 0, 255, 0));             // the boot count wrapped
  EXPECT_FALSE(bus_newer(1, 999, 2, 0));
}

TEST(RigBusProtocol, KindNamesArePrintableAndBounded) {
  BusTypeBody b;
  set_kind_name(b, "a-very-long-kind-name\x01");
  EXPECT_EQ(kind_name_of(b), "a-very-long-");
  set_kind_name(b, std::string("Y\x02", 2));
  EXPECT_EQ(kind_name_of(b), "Y?");
}

// ---------------------------------------------------------------------------
// Seed corpus for fuzz_rig_bus_protocol.

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

fs::path rig_bus_corpus_dir() { return fs::path(PROPRIO_TESTS_DIR) / "fuzz" / "corpus" / "rig_bus_protocol"; }

Bytes emulated_stream(BusEmulatorOptions o, TimeNs until) {
  auto e = *RigBusEmulator::create(make_bench_bus_tree(8, 1), o, demo_bus_angles);
  std::vector<RigBusEmulatedReport> out;
  e.advance_to(until, out);
  Bytes all;
  for (const auto& r : out) all.insert(all.end(), r.bytes.begin(), r.bytes.end());
  return all;
}

// PROPRIO_REGEN_CORPUS=1 ./rig_bus_tests --gtest_filter='RigBusSeedCorpus.*'
// rewrites the seeds after a protocol change; commit the result.
TEST(RigBusSeedCorpus, Regenerate) {
  if (!testing_support::regenerate_corpus_requested()) GTEST_SKIP() << "set PROPRIO_REGEN_CORPUS=1 to rewrite the seeds";
  const fs::path dir = rig_bus_corpus_dir();
  fs::create_directories(dir);
  testing_support::write_bytes(dir / "message_data.bin", encode_bus_message(data_message()));
  testing_support::write_bytes(dir / "message_type.bin", encode_bus_message(type_message()));
  testing_support::write_bytes(dir / "message_child.bin", encode_bus_message(child_message()));
  RigBusReport r;
  r.count = 2;
  r.messages[0] = type_message();
  r.messages[0].type_info.kind = ComponentKind::joint;
  r.messages[0].type_info.outlet_count = 1;
  r.messages[1] = data_message();
  const auto report = encode_rig_bus_report(r);
  testing_support::write_bytes(dir / "report_type_data.bin", Bytes(report.begin(), report.end()));
  // 250 ms: type and child messages of every component (sent right after boot), then data. Short, so
  // that the replay's mutations of it stay quick.
  testing_support::write_bytes(dir / "stream_250ms.bin", emulated_stream({}, 250 * kNsPerMillisecond));
  BusEmulatorOptions faulty;
  faulty.seed = 2;
  faulty.faults.loss_probability = 0.1;
  faulty.faults.power_losses.push_back({100 * kNsPerMillisecond, make_bench_bus_tree(8, 1).components[2].id,
                                        50 * kNsPerMillisecond});
  Bytes damaged = emulated_stream(faulty, 250 * kNsPerMillisecond);
  for (std::size_t i = 17; i < damaged.size(); i += 997) damaged[i] ^= 0x10;  // report-level corruption
  testing_support::write_bytes(dir / "stream_faults.bin", damaged);
}

TEST(RigBusSeedCorpus, EverySeedStillDecodes) {
  const fs::path dir = rig_bus_corpus_dir();
  ASSERT_TRUE(fs::is_directory(dir)) << dir << " is missing; run with PROPRIO_REGEN_CORPUS=1";
  std::size_t seeds = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    const Bytes b = testing_support::read_bytes(entry.path());
    ++seeds;
    if (name.rfind("message_", 0) == 0) {
      EXPECT_TRUE(decode_bus_message(b).ok()) << name;
    } else if (name.rfind("report_", 0) == 0) {
      EXPECT_TRUE(decode_rig_bus_report(b).ok()) << name;
    } else {
      ASSERT_EQ(b.size() % kRigBusReportSize, 0u) << name;
      RigBusHost host;
      for (std::size_t at = 0; at < b.size(); at += kRigBusReportSize) {
        (void)host.on_report(std::span<const std::uint8_t>(b).subspan(at, kRigBusReportSize), static_cast<TimeNs>(at));
      }
      EXPECT_GT(host.stats().messages, 0u) << name;
      EXPECT_EQ(host.stats().decode_errors > 0, name.find("faults") != std::string::npos) << name;
    }
  }
  EXPECT_EQ(seeds, 6u);
}

}  // namespace
