// Transports (the fake link, hidapi's failure paths), the SPSC ring and
// ImuGloveDevice end to end over the fake link: streaming, corrupted and lost
// reports, unplug and replug, silence, flagged samples, a slow consumer.
//
// Threads: every wait is for a condition with a generous deadline (20 s);
// nothing asserts how long anything took.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/imu_glove_board/imu_glove_device.hpp"
#include "proprio/imu_glove_board/imu_glove_emulator.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/hid/spsc_ring.hpp"
#include "support/board_rig.hpp"
#include "support/devices.hpp"

namespace proprio::devices {
namespace {

using namespace std::chrono_literals;
using Bytes = std::vector<std::uint8_t>;

using proprio::testing_support::wait_until;

// ---------------------------------------------------------------------------
// hid::SpscRing

TEST(SpscRing, KeepsOrderAndRefusesWhenFull) {
  hid::SpscRing<int> ring(5);
  EXPECT_EQ(ring.capacity(), 8u);
  for (int i = 0; i < 8; ++i) EXPECT_TRUE(ring.try_push(i));
  EXPECT_FALSE(ring.try_push(99));
  int v = -1;
  for (int i = 0; i < 8; ++i) {
    ASSERT_TRUE(ring.try_pop(v));
    EXPECT_EQ(v, i);
  }
  EXPECT_FALSE(ring.try_pop(v));
  EXPECT_EQ(ring.size(), 0u);
}

TEST(SpscRing, TwoThreadsPassEveryValueInOrder) {
  hid::SpscRing<std::uint64_t> ring(64);  // small, so that it runs full and empty often
  constexpr std::uint64_t kCount = 200000;
  std::atomic<bool> producer_done{false};
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < kCount;) {
      if (ring.try_push(i)) {
        ++i;
      } else {
        std::this_thread::yield();
      }
    }
    producer_done.store(true);
  });
  std::uint64_t expected = 0, v = 0;
  bool in_order = true;
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  while (in_order && expected < kCount && std::chrono::steady_clock::now() < deadline) {
    if (!ring.try_pop(v)) {
      std::this_thread::yield();
      continue;
    }
    in_order = v == expected;
    ++expected;
  }
  // Drain until the producer is done, so it cannot block on a full ring if the consumer stopped early.
  while (!producer_done.load()) ring.try_pop(v);
  producer.join();
  EXPECT_TRUE(in_order);
  EXPECT_EQ(expected, kCount);
}

// ---------------------------------------------------------------------------
// hid::FakeHidLink / hid::FakeHidTransport

TEST(FakeHid, DeliversReportsAtTheirReleaseTimeInOrder) {
  ManualClock clock(1000);
  auto link = std::make_shared<hid::FakeHidLink>(clock);
  hid::FakeHidTransport t(link);
  ASSERT_TRUE(t.open().ok());
  link->push(Bytes{1, 2, 3}, 2000);
  link->push(Bytes{4, 5}, 1500);  // released earlier: read first
  std::array<std::uint8_t, 64> buf{};
  auto n = t.read(buf, 0);
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, 0u);  // nothing due yet
  clock.set(1600);
  n = t.read(buf, 0);
  ASSERT_TRUE(n.ok());
  ASSERT_EQ(*n, 2u);
  EXPECT_EQ(buf[0], 4);
  clock.set(2000);
  n = t.read(buf, 1'000'000);
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, 3u);
  EXPECT_EQ(link->stats().delivered, 2u);
}

TEST(FakeHid, UnplugKillsTheHandleAndOpenWaitsForTheCable) {
  ManualClock clock(0);
  auto link = std::make_shared<hid::FakeHidLink>(clock);
  hid::FakeHidTransport t(link);
  ASSERT_TRUE(t.open().ok());
  link->push(Bytes{1}, 50);
  link->schedule_unplug(100, 1000);
  link->push(Bytes{2}, 500);   // due while the cable is out: lost
  link->push(Bytes{3}, 1200);  // after replug
  std::array<std::uint8_t, 8> buf{};
  clock.set(60);
  EXPECT_EQ(*t.read(buf, 0), 1u);
  clock.set(150);
  auto n = t.read(buf, 0);
  ASSERT_FALSE(n.ok());
  EXPECT_EQ(n.error().code, Errc::unavailable);
  EXPECT_FALSE(t.is_open());
  EXPECT_FALSE(link->plugged());
  auto s = t.open();
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::not_found);
  clock.set(1100);
  EXPECT_TRUE(link->plugged());
  ASSERT_TRUE(t.open().ok());
  clock.set(1300);
  n = t.read(buf, 0);
  ASSERT_TRUE(n.ok());
  ASSERT_EQ(*n, 1u);
  EXPECT_EQ(buf[0], 3);
  const auto st = link->stats();
  EXPECT_EQ(st.lost_unplugged, 1u);
  EXPECT_EQ(st.failed_opens, 1u);
  EXPECT_EQ(st.opens, 2u);
  EXPECT_EQ(st.read_errors, 1u);
}

TEST(FakeHid, AHandleOpenedBeforeAnOutageDiesEvenIfNobodyReadDuringIt) {
  ManualClock clock(0);
  auto link = std::make_shared<hid::FakeHidLink>(clock);
  hid::FakeHidTransport t(link);
  ASSERT_TRUE(t.open().ok());
  link->schedule_unplug(10, 10);
  clock.set(100);  // the cable went out and back in meanwhile: the device re-enumerated
  std::array<std::uint8_t, 8> buf{};
  EXPECT_FALSE(t.read(buf, 0).ok());
  EXPECT_TRUE(t.open().ok());
}

TEST(FakeHid, WritesAndFeatureReportsReachTheDeviceSide) {
  ManualClock clock(0);
  auto link = std::make_shared<hid::FakeHidLink>(clock);
  std::vector<Bytes> seen;
  link->set_write_handler([&](std::span<const std::uint8_t> b) { seen.emplace_back(b.begin(), b.end()); });
  link->set_feature_handler([](std::uint8_t id, std::span<std::uint8_t> out) -> std::size_t {
    if (id != 2 || out.size() < 3) return 0;
    out[0] = 2;
    out[1] = 42;
    out[2] = 43;
    return 3;
  });
  hid::FakeHidTransport t(link);
  EXPECT_FALSE(t.write(Bytes{1}).ok());  // not open
  ASSERT_TRUE(t.open().ok());
  ASSERT_TRUE(t.write(Bytes{0x10, 1, 2}).ok());
  ASSERT_EQ(seen.size(), 1u);
  EXPECT_EQ(link->writes(), seen);
  std::array<std::uint8_t, 32> buf{};
  auto n = t.get_feature(2, buf);
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, 3u);
  EXPECT_EQ(buf[1], 42);
  EXPECT_FALSE(t.get_feature(9, buf).ok());
}

TEST(FakeHid, FaultsAreSeededAndCounted) {
  auto run = [](std::uint64_t seed) {
    ManualClock clock(0);
    hid::FakeHidFaults f;
    f.drop_probability = 0.1;
    f.duplicate_probability = 0.1;
    f.corrupt_probability = 0.1;
    f.reorder_probability = 0.1;
    f.seed = seed;
    auto link = std::make_shared<hid::FakeHidLink>(clock, f);
    hid::FakeHidTransport t(link);
    EXPECT_TRUE(t.open().ok());
    for (std::uint8_t i = 0; i < 200; ++i) link->push(Bytes(8, i));
    std::vector<Bytes> got;
    std::array<std::uint8_t, 8> buf{};
    for (auto n = t.read(buf, 0); n.ok() && *n > 0; n = t.read(buf, 0)) got.emplace_back(buf.begin(), buf.end());
    return std::make_pair(got, link->stats());
  };
  const auto [a, sa] = run(9);
  const auto [b, sb] = run(9);
  const auto [c, sc] = run(10);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
  EXPECT_GT(sa.dropped, 0u);
  EXPECT_GT(sa.duplicated, 0u);
  EXPECT_GT(sa.corrupted, 0u);
  EXPECT_GT(sa.reordered, 0u);
  EXPECT_EQ(a.size(), 200u - sa.dropped + sa.duplicated);
}

// ---------------------------------------------------------------------------
// hidapi: what can be checked without a glove attached.

TEST(HidapiTransport, AbsentDeviceGivesAnActionableError) {
  auto list = hid::enumerate_hid_devices();
  ASSERT_TRUE(list.ok()) << list.error().message;  // possibly empty in a container
  hid::HidDeviceSelector sel;
  sel.vendor_id = 0xFFFF;
  sel.product_id = 0xFFFE;
  sel.serial = "NOPE";
  hid::HidapiTransport t(sel);
  auto s = t.open();
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::not_found);
  EXPECT_NE(s.error().message.find("ffff:fffe"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("NOPE"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("proprio glove list"), std::string::npos) << s.error().message;
  std::array<std::uint8_t, 64> buf{};
  auto n = t.read(buf, 0);
  ASSERT_FALSE(n.ok());
  EXPECT_EQ(n.error().code, Errc::unavailable);
  EXPECT_FALSE(t.write(buf).ok());
  EXPECT_FALSE(t.get_feature(2, buf).ok());
  EXPECT_FALSE(hid::hidapi_version().empty());
}

TEST(HidapiTransport, UnopenablePathSaysWhichAndWhatToDo) {
  hid::HidDeviceSelector sel;
  sel.path = "/nonexistent/hidraw99";
  hid::HidapiTransport t(sel);
  auto s = t.open();
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::not_found);
  EXPECT_NE(s.error().message.find("/nonexistent/hidraw99"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("plugged in"), std::string::npos) << s.error().message;
  EXPECT_FALSE(t.is_open());
}

TEST(HidapiTransport, APathThatIsNoHidrawNodeIsRefusedBeforeHidapiSeesIt) {
  // hidapi's hidraw backend crashed on these (exit 139).
  for (const char* path : {"/dev/null", "/dev/zero", "/etc/hostname", "/tmp"}) {
    hid::HidDeviceSelector sel;
    sel.path = path;
    hid::HidapiTransport t(sel);
    auto s = t.open();
    ASSERT_FALSE(s.ok()) << path;
    EXPECT_EQ(s.error().code, Errc::invalid_argument) << path;
    EXPECT_NE(s.error().message.find("hidraw"), std::string::npos) << s.error().message;
    EXPECT_FALSE(t.is_open());
  }
}

// ---------------------------------------------------------------------------
// ImuGloveDevice over the fake link, fed by the emulator in real time.

// IMU i at tick k: values that identify both, well inside the ranges.
std::vector<ImuSample> synthetic_tick(std::int64_t k, std::size_t imus = 7) {
  std::vector<ImuSample> out(imus);
  for (std::size_t i = 0; i < imus; ++i) {
    out[i].sensor_id = static_cast<std::uint16_t>(i);
    out[i].accel_mps2 = Vec3(0.5 * static_cast<double>(i) - 1.0, 0.05 * static_cast<double>(k), 9.8);
    out[i].gyro_radps = Vec3(0.1 * static_cast<double>(i), -0.2, std::sin(0.1 * static_cast<double>(k)));
  }
  return out;
}

struct Rig {
  explicit Rig(ImuGloveEmulatorOptions eo = {}, hid::FakeHidFaults faults = {}, ImuGloveDeviceOptions dopts = test_options())
      : link(std::make_shared<hid::FakeHidLink>(MonotonicClock::instance(), faults)),
        emulator(*ImuGloveEmulator::create(eo)),
        device(std::make_unique<hid::FakeHidTransport>(link), dopts) {
    link->set_write_handler([this](std::span<const std::uint8_t> b) {
      std::lock_guard lock(emulator_mutex);
      emulator.handle_command(b);
    });
    link->set_feature_handler([this](std::uint8_t id, std::span<std::uint8_t> out) -> std::size_t {
      if (id != static_cast<std::uint8_t>(ImuGloveReportId::device_info) || out.size() < kImuGloveInfoReportSize) return 0;
      std::lock_guard lock(emulator_mutex);
      const auto info = emulator.info_report(MonotonicClock::instance().now_ns() - t0);
      std::copy(info.begin(), info.end(), out.begin());
      return info.size();
    });
    device.set_state_callback([this](hid::LinkState s, std::string_view) {
      std::lock_guard lock(states_mutex);
      states.push_back(s);
    });
  }
  // The reader thread calls back into members declared after the device: stop it first.
  ~Rig() { device.stop(); }
  Rig(const Rig&) = delete;
  Rig& operator=(const Rig&) = delete;

  static ImuGloveDeviceOptions test_options() { return testing_support::quick_link<ImuGloveDeviceOptions>(); }

  // Schedules ticks [0, ticks) of synthetic data for release in real time,
  // starting 30 ms from now, each report after 0.2-1 ms of "USB latency".
  void schedule(std::int64_t ticks) {
    t0 = MonotonicClock::instance().now_ns() + 30 * kNsPerMillisecond;
    Rng rng(77);
    std::vector<ImuGloveEmulatedReport> out;
    for (std::int64_t k = 0; k < ticks; ++k) {
      out.clear();
      {
        std::lock_guard lock(emulator_mutex);
        EXPECT_TRUE(emulator.tick(k * 10 * kNsPerMillisecond, synthetic_tick(k), out).ok());
      }
      for (const auto& r : out) {
        link->push(r.bytes, t0 + r.send_ns + 200'000 + static_cast<TimeNs>(rng.below(800'000)));
      }
    }
    std::lock_guard lock(emulator_mutex);
    out.clear();
    emulator.flush(out);
    for (const auto& r : out) link->push(r.bytes, t0 + r.send_ns + 1'000'000);
    link->flush();
    last_release = t0 + ticks * 10 * kNsPerMillisecond + 5 * kNsPerMillisecond;
  }

  // Pops everything available into samples; true once pred holds.
  bool drain_until(const std::function<bool()>& pred, std::chrono::seconds timeout = 20s) {
    return wait_until(
        [&] {
          ImuGloveSample s;
          while (device.pop(s)) samples.push_back(s);
          return pred();
        },
        timeout);
  }
  // Everything scheduled has been released and read.
  bool all_read() {
    return MonotonicClock::instance().now_ns() > last_release && link->pending() == 0 &&
           device.stats().reports_read == link->stats().delivered;
  }
  std::vector<hid::LinkState> state_log() {
    std::lock_guard lock(states_mutex);
    return states;
  }

  std::shared_ptr<hid::FakeHidLink> link;
  std::mutex emulator_mutex;
  ImuGloveEmulator emulator;
  ImuGloveDevice device;
  std::atomic<TimeNs> t0{0};  // the emulator's time zero; read by the feature handler on the reader thread
  TimeNs last_release = 0;
  std::vector<ImuGloveSample> samples;
  std::mutex states_mutex;
  std::vector<hid::LinkState> states;
};

// For failure messages: what the device and the link saw.
std::string describe(const ImuGloveDeviceStats& st, const hid::FakeHidLink& link) {
  const auto l = link.stats();
  return "device: reports read " + std::to_string(st.reports_read) + ", accepted " +
         std::to_string(st.stream.accepted) + ", lost " + std::to_string(st.stream.lost) + ", duplicates " +
         std::to_string(st.stream.duplicates) + ", late " + std::to_string(st.stream.late) + ", decode errors " +
         std::to_string(st.stream.decode_errors) + ", resets " + std::to_string(st.stream.device_resets) +
         ", delivered " + std::to_string(st.samples_delivered) + ", rejected " + std::to_string(st.samples_rejected) +
         ", connects " + std::to_string(st.connects) + ", disconnects " + std::to_string(st.disconnects) +
         ", open failures " + std::to_string(st.open_failures) + "; link: pushed " + std::to_string(l.pushed) +
         ", delivered " + std::to_string(l.delivered) + ", lost unplugged " + std::to_string(l.lost_unplugged) +
         ", pending " + std::to_string(link.pending());
}

// The tick a sample belongs to, from the value synthetic_tick put in it.
std::int64_t tick_of(const ImuGloveSample& s) { return std::llround(s.imu.accel_mps2.y() / 0.05); }

void expect_matches_synthetic(const ImuGloveSample& s) {
  const auto k = tick_of(s);
  const ImuSample truth = synthetic_tick(k)[s.imu.sensor_id];
  const double qa = 0.5 / accel_counts_per_mps2(AccelRange::g16) + 1e-12;
  const double qg = 0.5 / gyro_counts_per_radps(GyroRange::dps2000) + 1e-12;
  EXPECT_LE((s.imu.accel_mps2 - truth.accel_mps2).cwiseAbs().maxCoeff(), qa) << "IMU " << s.imu.sensor_id << " tick " << k;
  EXPECT_LE((s.imu.gyro_radps - truth.gyro_radps).cwiseAbs().maxCoeff(), qg) << "IMU " << s.imu.sensor_id << " tick " << k;
}

// Every IMU's sample times strictly increase; every time is at or before the
// report's arrival (the envelope runs below every receive time).
void expect_sane_times(const std::vector<ImuGloveSample>& samples) {
  std::map<std::uint16_t, TimeNs> last;
  for (const ImuGloveSample& s : samples) {
    EXPECT_LE(s.time_ns, s.receive_ns);
    EXPECT_LT(s.receive_ns - s.time_ns, kNsPerSecond);
    auto it = last.find(s.imu.sensor_id);
    if (it != last.end()) {
      EXPECT_GT(s.time_ns, it->second) << "IMU " << s.imu.sensor_id;
    }
    last[s.imu.sensor_id] = s.time_ns;
  }
}

TEST(GloveDevice, StreamsDecodedTimestampedSamples) {
  Rig rig;
  ASSERT_TRUE(rig.device.start().ok());
  rig.schedule(100);
  ASSERT_TRUE(rig.drain_until([&] { return rig.samples.size() >= 700 && rig.all_read(); }))
      << rig.samples.size() << " samples";
  rig.device.stop();
  EXPECT_EQ(rig.samples.size(), 700u);
  std::map<std::uint16_t, int> per_imu;
  for (const ImuGloveSample& s : rig.samples) {
    ++per_imu[s.imu.sensor_id];
    expect_matches_synthetic(s);
    EXPECT_EQ(s.status, 0);
    EXPECT_EQ(s.epoch, 0u);
  }
  for (std::uint16_t i = 0; i < 7; ++i) EXPECT_EQ(per_imu[i], 100) << i;
  expect_sane_times(rig.samples);
  const ImuGloveDeviceStats st = rig.device.stats();
  EXPECT_EQ(st.state, hid::LinkState::stopped);
  EXPECT_EQ(st.stream.accepted, 200u);
  EXPECT_EQ(st.stream.lost, 0u);
  EXPECT_EQ(st.samples_delivered, 700u);
  EXPECT_EQ(st.connects, 1u);
  EXPECT_TRUE(st.clock_locked);
  EXPECT_TRUE(st.have_info);
  EXPECT_EQ(st.info.imu_count, 7);
  EXPECT_EQ(st.info.rate_hz, 100);
  EXPECT_EQ(rig.state_log(), (std::vector<hid::LinkState>{hid::LinkState::connecting, hid::LinkState::streaming,
                                                          hid::LinkState::stopped}));
  EXPECT_TRUE(rig.link->writes().empty());  // a streaming glove is left alone
}

TEST(GloveDevice, ResumesAfterUnplugAndReplug) {
  ImuGloveEmulatorOptions eo;
  // The glove loses power 0.5 s in for 0.3 s and boots again: counter and sequence restart.
  eo.faults.unplugs.push_back({500 * kNsPerMillisecond, 300 * kNsPerMillisecond});
  eo.boot_timestamp_us = 4'000'000'000u;
  Rig rig(eo);
  ASSERT_TRUE(rig.device.start().ok());
  rig.schedule(150);
  rig.link->schedule_unplug(rig.t0 + 500 * kNsPerMillisecond, 300 * kNsPerMillisecond);
  // Ticks 0-49 and 80-149 were powered.
  const bool done = rig.drain_until([&] { return rig.samples.size() >= 7 * 120 && rig.all_read(); });
  const ImuGloveDeviceStats st = rig.device.stats();
  ASSERT_TRUE(done) << rig.samples.size() << " samples; " << describe(st, *rig.link);
  rig.device.stop();
  EXPECT_EQ(rig.samples.size(), 7u * 120u);
  std::size_t after = 0;
  for (const ImuGloveSample& s : rig.samples) {
    expect_matches_synthetic(s);
    const auto k = tick_of(s);
    EXPECT_TRUE(k < 50 || k >= 80) << k;
    EXPECT_EQ(s.epoch, k < 50 ? 0u : 1u) << k;
    if (k >= 80) {
      ++after;
      EXPECT_EQ(static_cast<std::int64_t>(s.sequence), k - 80);  // the rebooted glove counts from 0
    }
  }
  EXPECT_EQ(after, 7u * 70u);
  expect_sane_times(rig.samples);
  EXPECT_GE(st.disconnects, 1u);
  EXPECT_GE(st.connects, 2u);
  EXPECT_GE(st.open_failures, 1u);
  EXPECT_EQ(st.stream.device_resets, 1u);
  EXPECT_EQ(st.stream.lost, 0u);
  EXPECT_GE(st.clock_relocks, 1u);
  const auto log = rig.state_log();
  const auto pos = std::find(log.begin(), log.end(), hid::LinkState::disconnected);
  ASSERT_NE(pos, log.end());
  EXPECT_NE(std::find(pos, log.end(), hid::LinkState::streaming), log.end());
}

TEST(GloveDevice, CorruptedReportsAreSkippedAndCounted) {
  hid::FakeHidFaults faults;
  faults.corrupt_probability = 0.1;
  faults.seed = 4;
  Rig rig({}, faults);
  ASSERT_TRUE(rig.device.start().ok());
  rig.schedule(150);
  ASSERT_TRUE(rig.drain_until([&] { return rig.all_read(); }));
  const ImuGloveDeviceStats st = rig.device.stats();
  rig.device.stop();
  const auto link = rig.link->stats();
  ASSERT_GT(link.corrupted, 5u);
  EXPECT_EQ(st.stream.decode_errors, link.corrupted);  // one flipped bit never gets past the CRC
  EXPECT_EQ(st.stream.decode_errors_by_code[static_cast<std::size_t>(ImuGloveDecodeErrc::crc_mismatch)] +
                st.stream.decode_errors_by_code[static_cast<std::size_t>(ImuGloveDecodeErrc::unknown_report_id)] +
                st.stream.decode_errors_by_code[static_cast<std::size_t>(ImuGloveDecodeErrc::unsupported_version)],
            link.corrupted);
  EXPECT_EQ(st.stream.accepted, 300u - link.corrupted);
  EXPECT_LE(st.stream.lost, link.corrupted);  // a corrupted last report is not known lost yet
  EXPECT_GE(st.stream.lost + 2, link.corrupted);
  for (const ImuGloveSample& s : rig.samples) expect_matches_synthetic(s);
  expect_sane_times(rig.samples);
  EXPECT_EQ(st.samples_delivered, rig.samples.size());
}

TEST(GloveDevice, LostDuplicatedAndReorderedReportsAreAccountedFor) {
  hid::FakeHidFaults faults;
  faults.drop_probability = 0.05;
  faults.duplicate_probability = 0.05;
  faults.reorder_probability = 0.05;
  faults.seed = 8;
  Rig rig({}, faults);
  ASSERT_TRUE(rig.device.start().ok());
  rig.schedule(150);
  ASSERT_TRUE(rig.drain_until([&] { return rig.all_read(); }));
  const ImuGloveDeviceStats st = rig.device.stats();
  rig.device.stop();
  const auto link = rig.link->stats();
  ASSERT_GT(link.dropped, 0u);
  ASSERT_GT(link.duplicated, 0u);
  ASSERT_GT(link.reordered, 0u);
  EXPECT_EQ(st.stream.duplicates, link.duplicated);
  // A held-back report usually swaps with the next, which belongs to the
  // other part, so both are still in order within their part; only when the
  // next was dropped does it arrive after its own part's next report (late).
  EXPECT_LE(st.stream.late, link.reordered);
  EXPECT_EQ(st.stream.accepted + st.stream.late, 300u - link.dropped);
  EXPECT_LE(st.stream.lost, link.dropped);
  EXPECT_GE(st.stream.lost + 2, link.dropped);
  EXPECT_EQ(st.samples_delivered, rig.samples.size());
  for (const ImuGloveSample& s : rig.samples) expect_matches_synthetic(s);
  expect_sane_times(rig.samples);
}

TEST(GloveDevice, WaitsForAGloveThatIsNotThereYet) {
  Rig rig;
  rig.link->unplug_for(150 * kNsPerMillisecond);
  ASSERT_TRUE(rig.device.start().ok());
  ASSERT_TRUE(wait_until([&] { return rig.device.stats().open_failures >= 1; }));
  ASSERT_TRUE(wait_until([&] { return rig.device.state() == hid::LinkState::streaming; }));
  rig.schedule(20);
  ASSERT_TRUE(rig.drain_until([&] { return rig.samples.size() >= 140 && rig.all_read(); }));
  rig.device.stop();
  EXPECT_EQ(rig.samples.size(), 140u);
  const auto log = rig.state_log();
  ASSERT_GE(log.size(), 3u);
  EXPECT_EQ(log[0], hid::LinkState::connecting);
  EXPECT_EQ(log[1], hid::LinkState::disconnected);
  EXPECT_EQ(log[2], hid::LinkState::streaming);
}

TEST(GloveDevice, SendsStartWhenTheGloveStaysSilent) {
  ImuGloveEmulatorOptions eo;
  eo.stream_on_boot = false;  // e.g. another program stopped it
  ImuGloveDeviceOptions o = Rig::test_options();
  o.restart_after_silence_ns = 100 * kNsPerMillisecond;
  Rig rig(eo, {}, o);
  ASSERT_TRUE(rig.device.start().ok());
  rig.schedule(5);  // the emulator is stopped: nothing comes
  ASSERT_TRUE(wait_until([&] { return !rig.link->writes().empty(); }));
  rig.device.stop();
  const auto writes = rig.link->writes();
  auto cmd = decode_command(writes.front());
  ASSERT_TRUE(cmd.ok()) << cmd.error().message;
  EXPECT_EQ(cmd->op, ImuGloveCommandOp::start_streaming);
  EXPECT_GE(rig.device.stats().restart_commands, 1u);
  std::lock_guard lock(rig.emulator_mutex);
  EXPECT_TRUE(rig.emulator.streaming());
}

TEST(GloveDevice, QueuedCommandsAreSent) {
  Rig rig;
  ASSERT_TRUE(rig.device.start().ok());
  ImuGloveCommand c;
  c.op = ImuGloveCommandOp::set_rate;
  c.rate_hz = 250;
  c.token = 9;
  rig.device.send_command(c);
  ASSERT_TRUE(wait_until([&] { return !rig.link->writes().empty(); }));
  rig.device.stop();
  auto back = decode_command(rig.link->writes().front());
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(*back, c);
  std::lock_guard lock(rig.emulator_mutex);
  EXPECT_EQ(rig.emulator.rate_hz(), 250);
}

TEST(GloveDevice, FlaggedSamplesAreRejectedAndCountedUnlessAsked) {
  for (bool deliver_flagged : {false, true}) {
    SCOPED_TRACE(deliver_flagged ? "deliver_flagged" : "default");
    ImuGloveDeviceOptions o = Rig::test_options();
    o.deliver_flagged = deliver_flagged;
    Rig rig({}, {}, o);
    ASSERT_TRUE(rig.device.start().ok());
    // Schedule by hand: IMU 2 reads NaN on even ticks, IMU 5's gyro is far past full scale on every third.
    rig.t0 = MonotonicClock::instance().now_ns() + 30 * kNsPerMillisecond;
    std::vector<ImuGloveEmulatedReport> out;
    for (std::int64_t k = 0; k < 30; ++k) {
      auto tick = synthetic_tick(k);
      if (k % 2 == 0) tick[2].accel_mps2.x() = std::nan("");
      if (k % 3 == 0) tick[5].gyro_radps.z() = 100.0;
      out.clear();
      std::lock_guard lock(rig.emulator_mutex);  // the reader thread may be asking for device info
      ASSERT_TRUE(rig.emulator.tick(k * 10 * kNsPerMillisecond, tick, out).ok());
      for (const auto& r : out) rig.link->push(r.bytes, rig.t0 + r.send_ns + 300'000);
    }
    rig.last_release = rig.t0 + 300 * kNsPerMillisecond;
    ASSERT_TRUE(rig.drain_until([&] { return rig.all_read() && rig.samples.size() >= (deliver_flagged ? 210u : 185u); }));
    const ImuGloveDeviceStats st = rig.device.stats();
    rig.device.stop();
    EXPECT_EQ(st.stream.imus[2].sensor_error, 15u);
    EXPECT_EQ(st.stream.imus[5].gyro_saturated, 10u);
    EXPECT_EQ(st.stream.samples_rejected(), 25u);
    if (deliver_flagged) {
      EXPECT_EQ(rig.samples.size(), 210u);
      EXPECT_EQ(st.samples_rejected, 0u);
      std::size_t flagged = 0;
      for (const ImuGloveSample& s : rig.samples) flagged += s.status != 0;
      EXPECT_EQ(flagged, 25u);
    } else {
      EXPECT_EQ(rig.samples.size(), 185u);
      EXPECT_EQ(st.samples_rejected, 25u);
      for (const ImuGloveSample& s : rig.samples) {
        EXPECT_EQ(s.status, 0);
        expect_matches_synthetic(s);
      }
    }
  }
}

TEST(GloveDevice, ASlowConsumerLosesSamplesAtTheRingNotTheReader) {
  ImuGloveDeviceOptions o = Rig::test_options();
  o.queue_capacity = 16;
  Rig rig({}, {}, o);
  ASSERT_TRUE(rig.device.start().ok());
  rig.schedule(20);
  ASSERT_TRUE(wait_until([&] { return rig.all_read(); }));  // nobody pops meanwhile
  const ImuGloveDeviceStats st = rig.device.stats();
  EXPECT_EQ(st.samples_delivered, 16u);
  EXPECT_EQ(st.queue_overruns, 140u - 16u);
  EXPECT_EQ(st.stream.accepted, 40u);
  ImuGloveSample s;
  int popped = 0;
  while (rig.device.pop(s)) ++popped;
  EXPECT_EQ(popped, 16);
  rig.device.stop();
}

TEST(GloveDevice, SampleCallbackReplacesTheRing) {
  Rig rig;
  std::mutex m;
  std::vector<ImuGloveSample> got;
  rig.device.set_sample_callback([&](const ImuGloveSample& s) {
    std::lock_guard lock(m);
    got.push_back(s);
  });
  ASSERT_TRUE(rig.device.start().ok());
  EXPECT_FALSE(rig.device.start().ok());  // already running
  rig.schedule(10);
  ASSERT_TRUE(wait_until([&] {
    std::lock_guard lock(m);
    return got.size() >= 70;
  }));
  rig.device.stop();
  ImuGloveSample s;
  EXPECT_FALSE(rig.device.pop(s));
  std::lock_guard lock(m);
  EXPECT_EQ(got.size(), 70u);
}

TEST(GloveDevice, StopsPromptlyWhileRetryingAndCanRestart) {
  Rig rig;
  rig.link->unplug_for(3600 * kNsPerSecond);
  ASSERT_TRUE(rig.device.start().ok());
  ASSERT_TRUE(wait_until([&] { return rig.device.stats().open_failures >= 3; }));
  rig.device.stop();
  EXPECT_FALSE(rig.device.running());
  EXPECT_EQ(rig.device.state(), hid::LinkState::stopped);
  ASSERT_TRUE(rig.device.start().ok());
  EXPECT_TRUE(rig.device.running());
  rig.device.stop();
}

}  // namespace
}  // namespace proprio::devices
