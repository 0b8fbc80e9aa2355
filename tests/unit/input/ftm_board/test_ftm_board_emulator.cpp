// FtmBoardEmulator against FtmStreamDecoder (offline, bit-exact), and
// FtmBoardDevice end to end over the kit's fake HID link with the emulator
// served in real time. Also writes and checks the fuzz seed corpus.
//
// Threads: every wait is for a condition with a generous deadline (20 s);
// nothing asserts how long anything took.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

#include "proprio/ftm_board/ftm_device.hpp"
#include "proprio/ftm_board/ftm_emulator.hpp"
#include "proprio/ftm_board/ftm_protocol.hpp"
#include "proprio/ftm_board/ftm_stream.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "support/board_rig.hpp"
#include "support/devices.hpp"
#include "support/seed_corpus.hpp"

namespace proprio::devices::ftm_board_emulator_test {
namespace {

namespace fs = std::filesystem;
namespace st = ftm::sample_status;
using namespace std::chrono_literals;
using Bytes = std::vector<std::uint8_t>;
constexpr double kTwoPi = 6.283185307179586;

// The synthetic wearer: every sensor its own slow signal, at the board's
// nominal rates (IMUs at n x 5 ms, compass fresh on even ticks, bend sensors
// at n x 1 ms), so a board without crystal error samples each exactly.
Vec3 ftme_accel(std::size_t i, double t) {
  const double p = static_cast<double>(i);
  return Vec3(2.0 * std::sin(kTwoPi * 0.5 * t + p), 9.0 + 0.5 * std::cos(kTwoPi * 0.3 * t), -1.0 + 0.2 * p);
}
Vec3 ftme_gyro(std::size_t i, double t) {
  const double p = static_cast<double>(i);
  return Vec3(1.5 * std::sin(kTwoPi * 0.8 * t + p), -0.3 * p, 0.7 * std::cos(kTwoPi * 0.4 * t));
}
Vec3 ftme_mag(std::size_t i, double t) {
  return Vec3(20.0 + static_cast<double>(i), -5.0 + 3.0 * std::sin(kTwoPi * 0.3 * t), -40.0);
}
double ftme_bend(std::size_t k, double t) {
  return 100.0 + 20.0 * static_cast<double>(k) + 10.0 * std::sin(kTwoPi * 0.7 * t + static_cast<double>(k));
}
// Largest rates of change, per second (for tolerances on mapped times).
constexpr double kAccelSlope = 2.0 * kTwoPi * 0.5;
constexpr double kBendSlope = 10.0 * kTwoPi * 0.7;

class FtmeFeed final : public ftm::FtmSampleFeed {
 public:
  // Lets a test spoil a sample (saturate, NaN) before it is delivered.
  std::function<void(ftm::FtmEvent&)> spoil;

  void advance(TimeNs t_ns, std::vector<ftm::FtmEvent>& out) override {
    for (;;) {
      const TimeNs ti = static_cast<TimeNs>(next_imu_) * 5 * kNsPerMillisecond;
      const TimeNs tb = static_cast<TimeNs>(next_bend_) * kNsPerMillisecond;
      if (std::min(ti, tb) > t_ns) return;
      if (ti <= tb) {
        const double t = ns_to_seconds(ti);
        for (std::size_t i = 0; i < ftm::kFtmImuCount; ++i) {
          ftm::FtmEvent e;
          e.kind = ftm::FtmEvent::Kind::imu;
          e.index = static_cast<std::uint8_t>(i);
          e.imu.time_ns = ti;
          e.imu.accel_mps2 = ftme_accel(i, t);
          e.imu.gyro_radps = ftme_gyro(i, t);
          e.imu.mag_fresh = next_imu_ % 2 == 0;
          e.imu.mag_uT = ftme_mag(i, ns_to_seconds(ti - (next_imu_ % 2) * 5 * kNsPerMillisecond));
          if (spoil) spoil(e);
          out.push_back(e);
        }
        ++next_imu_;
      } else {
        for (std::size_t k = 0; k < ftm::kFtmBendCount; ++k) {
          ftm::FtmEvent e;
          e.kind = ftm::FtmEvent::Kind::bend;
          e.index = static_cast<std::uint8_t>(k);
          e.bend.time_ns = tb;
          e.bend.capacitance_pF = ftme_bend(k, ns_to_seconds(tb));
          if (spoil) spoil(e);
          out.push_back(e);
        }
        ++next_bend_;
      }
    }
  }

 private:
  std::uint64_t next_imu_ = 0;
  std::uint64_t next_bend_ = 0;
};

FtmBoardEmulator ftme_make(FtmEmulatorOptions o = {}, std::function<void(ftm::FtmEvent&)> spoil = {}) {
  auto feed = std::make_unique<FtmeFeed>();
  feed->spoil = std::move(spoil);
  auto e = FtmBoardEmulator::create(std::move(o), std::move(feed));
  EXPECT_TRUE(e.ok()) << (e.ok() ? "" : e.error().message);
  return std::move(*e);
}

std::vector<FtmEmulatedReport> ftme_run(FtmBoardEmulator& e, TimeNs end_ns) {
  std::vector<FtmEmulatedReport> out;
  for (TimeNs t = 0; t <= end_ns; t += 5 * kNsPerMillisecond) e.advance_to(t, out);
  e.flush(out);
  return out;
}

struct FtmeDecoded {
  FtmStreamDecoder decoder;
  std::vector<FtmBoardSample> samples;
  std::vector<FtmPushResult> results;
  void push_all(const std::vector<FtmEmulatedReport>& reports) {
    std::array<FtmBoardSample, kFtmMaxSamplesPerReport> buf;
    for (const auto& r : reports) {
      results.push_back(decoder.push(r.bytes, buf, r.send_ns));
      for (std::size_t i = 0; i < results.back().sample_count; ++i) samples.push_back(buf[i]);
    }
  }
};

// Value of a decoded sample against the feed at the instant the board sampled it.
void ftme_expect_value(const FtmBoardSample& s, TimeNs sampled_ns, double time_slack_s = 0.0) {
  const double t = ns_to_seconds(sampled_ns);
  if (s.event.kind == ftm::FtmEvent::Kind::imu) {
    const double a = accel_mps2_per_count(kFtmDefaultAccelRange), g = gyro_radps_per_count(kFtmDefaultGyroRange);
    const Vec3 accel = ftme_accel(s.event.index, t), gyro = ftme_gyro(s.event.index, t);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(s.event.imu.accel_mps2[k], accel[k], 0.5 * a + kAccelSlope * time_slack_s + 1e-9);
      EXPECT_NEAR(s.event.imu.gyro_radps[k], gyro[k], 0.5 * g + 1.5 * kTwoPi * time_slack_s + 1e-9);
    }
    EXPECT_EQ(s.event.imu.status, 0);
  } else {
    EXPECT_NEAR(s.event.bend.capacitance_pF, ftme_bend(s.event.index, t), 0.005 + kBendSlope * time_slack_s + 1e-9);
    EXPECT_EQ(s.event.bend.status, 0);
  }
}

// ---------------------------------------------------------------------------
// Emulator and decoder, offline

TEST(FtmBoardEmulator, SamplesInAreSamplesOutWithinQuantisation) {
  FtmBoardEmulator emu = ftme_make();
  const auto reports = ftme_run(emu, 500 * kNsPerMillisecond);
  FtmeDecoded d;
  d.push_all(reports);
  const FtmStreamStats& s = d.decoder.stats();
  EXPECT_EQ(s.decode_errors, 0u);
  EXPECT_EQ(s.lost_imu_samples + s.lost_bend_samples, 0u);
  EXPECT_EQ(s.imu_samples, 4u * 101);  // ticks 0..500 ms
  EXPECT_EQ(s.bend_samples, 3u * 500);  // the last report (ticks 500-504) is not complete at 500 ms
  EXPECT_EQ(s.imu_period_us, 5000);
  EXPECT_EQ(s.bend_period_us, 1000);
  EXPECT_EQ(emu.stats().imu_stale, 0u);
  EXPECT_EQ(emu.stats().bend_stale, 0u);
  std::size_t fresh = 0;
  for (const FtmBoardSample& x : d.samples) {
    const TimeNs sampled = x.event.kind == ftm::FtmEvent::Kind::imu
                               ? emu.imu_tick_time_ns(static_cast<std::uint64_t>(x.sequence))
                               : emu.bend_tick_time_ns(static_cast<std::uint64_t>(x.sequence));
    EXPECT_EQ(x.device_time_us * 1000, sampled);  // no crystal error, counter from 0
    ftme_expect_value(x, sampled);
    if (x.event.kind == ftm::FtmEvent::Kind::imu) {
      // The compass is fresh on even ticks; on odd ones it repeats the even tick's reading.
      EXPECT_EQ(x.event.imu.mag_fresh, x.sequence % 2 == 0);
      const Vec3 m = ftme_mag(x.event.index, ns_to_seconds(sampled - (x.sequence % 2) * 5 * kNsPerMillisecond));
      EXPECT_LE((x.event.imu.mag_uT - m).cwiseAbs().maxCoeff(), 0.5 * kFtmMagUtPerCount + 1e-9);
      fresh += x.event.imu.mag_fresh;
    }
  }
  EXPECT_EQ(fresh, 4u * 51);
  EXPECT_EQ(s.mag_fresh, fresh);
}

TEST(FtmBoardEmulator, TimestampsFollowTheDriftingCrystalAndWrap) {
  FtmEmulatorOptions o;
  o.clock_error_ppm = 80.0;
  o.boot_timestamp_us = 0xFFFFFFFFu - 100'000;  // wraps 0.1 s in
  FtmBoardEmulator emu = ftme_make(o);
  FtmeDecoded d;
  d.push_all(ftme_run(emu, 400 * kNsPerMillisecond));
  EXPECT_EQ(d.decoder.stats().timestamp_wraps, 3u);  // once per channel (IMUs 0-1, IMUs 2-3, bend)
  EXPECT_EQ(d.decoder.stats().device_resets, 0u);
  std::int64_t prev = std::numeric_limits<std::int64_t>::min();
  std::size_t stale = 0;
  for (const FtmBoardSample& x : d.samples) {
    if (x.event.kind != ftm::FtmEvent::Kind::imu || x.event.index != 0) continue;
    EXPECT_GT(x.device_time_us, prev);
    prev = x.device_time_us;
    // The device µs at the tick: the crystal runs 80 ppm fast against true time.
    const TimeNs sampled = emu.imu_tick_time_ns(static_cast<std::uint64_t>(x.sequence));
    EXPECT_EQ(static_cast<std::uint32_t>(x.device_time_us), emu.device_timestamp_us(sampled));
    // The fast board's ticks run ahead of the sensor's samples: tick 1 comes
    // 0.4 µs before the feed's second sample, finds nothing new and says stale.
    if (x.event.imu.status == st::stale) {
      ++stale;
      continue;
    }
    ftme_expect_value(x, sampled, 0.005);  // sample-and-hold: up to one feed period old
  }
  EXPECT_EQ(stale, 1u);
}

TEST(FtmBoardEmulator, LimitsReachTheHostAsStatusBits) {
  // IMU 1 whirls past ±2000 °/s, IMU 2 sits next to a magnet, IMU 3's bus read fails, bend 0 reads NaN.
  auto spoil = [](ftm::FtmEvent& e) {
    if (e.kind == ftm::FtmEvent::Kind::imu && e.index == 1) e.imu.gyro_radps.z() = 50.0;
    if (e.kind == ftm::FtmEvent::Kind::imu && e.index == 2) e.imu.mag_uT.x() = 6000.0;
    if (e.kind == ftm::FtmEvent::Kind::imu && e.index == 3) e.imu.accel_mps2.y() = std::nan("");
    if (e.kind == ftm::FtmEvent::Kind::bend && e.index == 0) e.bend.capacitance_pF = std::nan("");
    if (e.kind == ftm::FtmEvent::Kind::bend && e.index == 2) e.bend.capacitance_pF = 900.0;
  };
  FtmBoardEmulator emu = ftme_make({}, spoil);
  FtmeDecoded d;
  d.push_all(ftme_run(emu, 100 * kNsPerMillisecond));
  ASSERT_FALSE(d.samples.empty());
  for (const FtmBoardSample& x : d.samples) {
    if (x.event.kind == ftm::FtmEvent::Kind::imu) {
      const ftm::FtmImuSample& s = x.event.imu;
      EXPECT_TRUE(s.accel_mps2.allFinite() && s.gyro_radps.allFinite() && s.mag_uT.allFinite());
      switch (x.event.index) {
        case 0: EXPECT_EQ(s.status, 0); break;
        case 1: EXPECT_EQ(s.status, st::gyro_saturated); break;
        case 2: EXPECT_EQ(s.status, st::mag_overflow); break;
        case 3:
          EXPECT_EQ(s.status, st::sensor_error);
          EXPECT_EQ(s.accel_mps2, Vec3::Zero());
          break;
      }
    } else {
      const std::uint8_t want = x.event.index == 1 ? 0 : st::sensor_error;
      EXPECT_EQ(x.event.bend.status, want) << int(x.event.index);
      EXPECT_TRUE(std::isfinite(x.event.bend.capacitance_pF));
    }
  }
  EXPECT_GT(d.decoder.stats().imu_unusable, 0u);
  EXPECT_GT(d.decoder.stats().mag_overflows, 0u);
  EXPECT_GT(emu.stats().imu_flagged, 0u);
}

TEST(FtmBoardEmulator, AFeedThatStopsReadsStale) {
  // The feed's IMU 0 stops delivering 50 ms in: the board repeats its last sample, flagged stale.
  auto feed = std::make_unique<FtmeFeed>();
  struct Stopper final : ftm::FtmSampleFeed {
    std::unique_ptr<FtmeFeed> inner;
    void advance(TimeNs t, std::vector<ftm::FtmEvent>& out) override {
      std::vector<ftm::FtmEvent> all;
      inner->advance(t, all);
      for (const auto& e : all) {
        if (e.kind == ftm::FtmEvent::Kind::imu && e.index == 0 && e.imu.time_ns >= 50 * kNsPerMillisecond) continue;
        out.push_back(e);
      }
    }
  };
  auto stopper = std::make_unique<Stopper>();
  stopper->inner = std::move(feed);
  auto emu = FtmBoardEmulator::create({}, std::move(stopper));
  ASSERT_TRUE(emu.ok());
  FtmeDecoded d;
  d.push_all(ftme_run(*emu, 100 * kNsPerMillisecond));
  std::size_t stale = 0;
  for (const FtmBoardSample& x : d.samples) {
    if (x.event.kind != ftm::FtmEvent::Kind::imu) continue;
    const bool should = x.event.index == 0 && x.sequence >= 10;
    EXPECT_EQ((x.event.imu.status & st::stale) != 0, should) << x.sequence;
    stale += should;
  }
  EXPECT_EQ(stale, 11u);
  EXPECT_EQ(emu->stats().imu_stale, 11u);
}

TEST(FtmBoardEmulator, UnpluggingRebootsTheBoard) {
  FtmEmulatorOptions o;
  o.faults.unplugs.push_back({100 * kNsPerMillisecond, 50 * kNsPerMillisecond});
  FtmBoardEmulator emu = ftme_make(o);
  FtmeDecoded d;
  d.push_all(ftme_run(emu, 300 * kNsPerMillisecond));
  const FtmStreamStats& s = d.decoder.stats();
  EXPECT_EQ(emu.stats().boots, 2u);
  EXPECT_EQ(s.device_resets, 1u);
  EXPECT_EQ(s.lost_imu_samples + s.lost_bend_samples, 0u);  // the board made nothing while off
  bool saw_epoch1 = false;
  for (const FtmBoardSample& x : d.samples) {
    if (x.epoch == 1) {
      saw_epoch1 = true;
      if (x.event.kind == ftm::FtmEvent::Kind::imu) {
        // The rebooted board's run starts at 150 ms, its counter at 0.
        ftme_expect_value(x, 150 * kNsPerMillisecond + emu.imu_tick_time_ns(static_cast<std::uint64_t>(x.sequence)) -
                                 emu.imu_tick_time_ns(0), 0.005);
      }
    } else {
      EXPECT_EQ(x.epoch, 0u);
    }
  }
  EXPECT_TRUE(saw_epoch1);
}

TEST(FtmBoardEmulator, FaultsAreAllAccountedFor) {
  FtmEmulatorOptions o;
  o.seed = 3;
  o.faults.drop_probability = 0.05;
  o.faults.duplicate_probability = 0.05;
  o.faults.corrupt_probability = 0.05;
  o.faults.reorder_probability = 0.05;
  o.faults.device_overrun_probability = 0.03;
  FtmBoardEmulator emu = ftme_make(o);
  FtmeDecoded d;
  d.push_all(ftme_run(emu, 2 * kNsPerSecond));
  const FtmStreamStats& s = d.decoder.stats();
  const FtmEmulatorStats& e = emu.stats();
  EXPECT_GT(e.dropped, 0u);
  EXPECT_GT(e.duplicated, 0u);
  EXPECT_GT(e.corrupted, 0u);
  EXPECT_GT(e.reordered, 0u);
  EXPECT_GT(e.device_overruns, 0u);
  // Every flipped bit is caught by the CRC; a corrupted report that was also
  // duplicated is two decode errors and no duplicate.
  EXPECT_GE(s.decode_errors, e.corrupted);
  EXPECT_EQ(s.decode_errors + s.duplicates, e.corrupted + e.duplicated);
  EXPECT_EQ(s.device_resets, 0u);
  // Every sample the board made is delivered or counted lost, except at the
  // stream's ends (a loss before the first or after the last report of a
  // channel leaves no gap to see).
  const std::uint64_t made_imu = 4 * e.imu_ticks;
  EXPECT_LE(s.imu_samples + s.lost_imu_samples, made_imu);
  EXPECT_GE(s.imu_samples + s.lost_imu_samples, made_imu - 4 * 4);
  EXPECT_GT(s.lost_imu_samples, 0u);
  const std::uint64_t made_bend = 3 * e.bend_ticks;
  EXPECT_LE(s.bend_samples + s.lost_bend_samples, made_bend);
  EXPECT_GE(s.bend_samples + s.lost_bend_samples, made_bend - 3 * 5 * 4);
  EXPECT_GT(s.device_overruns, 0u);
  // Whatever the faults, every delivered sample has the right value for its tick.
  for (const FtmBoardSample& x : d.samples) {
    const TimeNs sampled = x.event.kind == ftm::FtmEvent::Kind::imu
                               ? emu.imu_tick_time_ns(static_cast<std::uint64_t>(x.sequence))
                               : emu.bend_tick_time_ns(static_cast<std::uint64_t>(x.sequence));
    ftme_expect_value(x, sampled);
  }
  // Reproducible from the seed.
  FtmBoardEmulator again = ftme_make(o);
  const auto a = ftme_run(again, 2 * kNsPerSecond);
  FtmBoardEmulator third = ftme_make(o);
  const auto b = ftme_run(third, 2 * kNsPerSecond);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i].bytes, b[i].bytes);
}

TEST(FtmBoardEmulator, AnswersCommandsAsTheFirmwareDoes) {
  FtmBoardEmulator emu = ftme_make();
  std::vector<FtmEmulatedReport> out;
  emu.advance_to(50 * kNsPerMillisecond, out);
  FtmCommand c;
  c.op = FtmCommandOp::set_rates;
  c.token = 7;
  c.imu_rate_hz = 100;
  c.bend_rate_hz = 500;
  EXPECT_EQ(emu.handle_command(encode_ftm_command(c), 50 * kNsPerMillisecond), FtmCommandResult::ok);
  auto info = decode_ftm_info_report(emu.info_report(60 * kNsPerMillisecond));
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->imu_rate_hz, 100);
  EXPECT_EQ(info->bend_rate_hz, 500);
  EXPECT_EQ(info->last_command_token, 7);
  EXPECT_EQ(info->last_command_result, FtmCommandResult::ok);
  c.imu_rate_hz = 5000;
  EXPECT_EQ(emu.handle_command(encode_ftm_command(c), 60 * kNsPerMillisecond), FtmCommandResult::bad_argument);
  c.imu_rate_hz = 450;  // each rate allowed, together 1100 reports/s: more than the endpoint carries
  c.bend_rate_hz = 1000;
  EXPECT_EQ(emu.handle_command(encode_ftm_command(c), 60 * kNsPerMillisecond), FtmCommandResult::bad_argument);
  c.op = FtmCommandOp::set_ranges;
  c.accel_range = FtmAccelRange::g16;
  EXPECT_EQ(emu.handle_command(encode_ftm_command(c), 60 * kNsPerMillisecond), FtmCommandResult::ok);
  auto bad = encode_ftm_command(c);
  bad[5] ^= 0x40;
  EXPECT_EQ(emu.handle_command(bad, 60 * kNsPerMillisecond), FtmCommandResult::bad_report);
  EXPECT_EQ(emu.handle_command(Bytes{0x58, 0x10}, 60 * kNsPerMillisecond), FtmCommandResult::bad_report);
  out.clear();
  emu.advance_to(200 * kNsPerMillisecond, out);
  FtmeDecoded d;
  d.push_all(out);
  EXPECT_EQ(d.decoder.stats().imu_period_us, 10000);
  EXPECT_EQ(d.decoder.stats().bend_period_us, 2000);
  EXPECT_EQ(d.decoder.stats().accel_range, FtmAccelRange::g16);
  c.op = FtmCommandOp::stop_streaming;
  EXPECT_EQ(emu.handle_command(encode_ftm_command(c), 200 * kNsPerMillisecond), FtmCommandResult::ok);
  out.clear();
  emu.advance_to(300 * kNsPerMillisecond, out);
  EXPECT_TRUE(out.empty());
  EXPECT_FALSE(decode_ftm_info_report(emu.info_report(300 * kNsPerMillisecond))->streaming);
}

TEST(FtmBoardEmulator, RefusesBadOptionsWithUsableMessages) {
  auto message = [](FtmEmulatorOptions o, bool with_feed = true) {
    auto e = FtmBoardEmulator::create(o, with_feed ? std::make_unique<FtmeFeed>() : nullptr);
    return e.ok() ? std::string() : e.error().message;
  };
  FtmEmulatorOptions o;
  o.imu_rate_hz = 5;
  EXPECT_NE(message(o).find("imu_rate_hz = 5"), std::string::npos);
  o = {};
  o.imu_rate_hz = 500;
  o.bend_rate_hz = 1000;
  EXPECT_NE(message(o).find("1000 reports/s"), std::string::npos);
  o = {};
  o.bend_samples_per_report = 6;
  EXPECT_NE(message(o).find("bend_samples_per_report"), std::string::npos);
  o = {};
  o.faults.drop_probability = 1.5;
  EXPECT_NE(message(o).find("faults.drop_probability"), std::string::npos);
  o = {};
  o.faults.unplugs.push_back({0, 0});
  EXPECT_NE(message(o).find("unplugs[0]"), std::string::npos);
  EXPECT_NE(message({}, false).find("feed"), std::string::npos);
  EXPECT_EQ(message({}), "");
}

// ---------------------------------------------------------------------------
// FtmBoardDevice over the fake link, the emulator served in real time.

using proprio::testing_support::wait_until;

FtmDeviceOptions ftme_device_options() { return testing_support::quick_link<FtmDeviceOptions>(); }

using FtmeRigBase = testing_support::BoardRig<FtmBoardEmulatorServer, FtmBoardDevice, FtmBoardSample>;
struct FtmeRig : FtmeRigBase {
  explicit FtmeRig(FtmEmulatorOptions eo = {}, hid::FakeHidFaults faults = {})
      : FtmeRigBase(ftme_make(eo), ftme_device_options(), faults) {}
};

// Each sample's host time against the instant the board sampled it, and its
// value against the feed at that instant; times strictly increase per sensor.
std::vector<double> ftme_check_device_samples(FtmeRig& rig) {
  std::vector<double> errors_ms;
  std::array<TimeNs, 7> last{};
  const TimeNs t0 = rig.server.time_zero_ns();
  rig.server.with_emulator([&](const FtmBoardEmulator& emu) {
    for (const FtmBoardSample& x : rig.samples) {
      const bool imu = x.event.kind == ftm::FtmEvent::Kind::imu;
      const TimeNs t = x.event.time_ns();
      const std::size_t slot = imu ? x.event.index : 4u + x.event.index;
      EXPECT_GT(t, last[slot]);
      EXPECT_LE(t, x.receive_ns);
      last[slot] = t;
      if (x.epoch != 0) continue;  // the rebooted board's run started elsewhere; checked by value below
      const auto n = static_cast<std::uint64_t>(x.sequence);
      const TimeNs truth = t0 + (imu ? emu.imu_tick_time_ns(n) : emu.bend_tick_time_ns(n));
      errors_ms.push_back(static_cast<double>(t - truth) * 1e-6);
      ftme_expect_value(x, truth - t0);
    }
    return 0;
  });
  return errors_ms;
}

TEST(FtmBoardDevice, StreamsTimestampedSamplesInTheContractsUnits) {
  FtmeRig rig;
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  ASSERT_TRUE(rig.drain_until([&] { return rig.samples.size() >= 3000; })) << rig.samples.size();
  ASSERT_TRUE(rig.quiesce());
  rig.device.stop();
  const FtmDeviceStats st = rig.device.stats();
  ASSERT_EQ(rig.samples.size(), st.samples_delivered);
  std::vector<double> errors_ms = ftme_check_device_samples(rig);
  ASSERT_FALSE(errors_ms.empty());
  // Mapped times sit on the board's instants plus the link's latency floor
  // (0.2 ms) and the reader's wake-up; not a report's length late.
  std::sort(errors_ms.begin(), errors_ms.end());
  EXPECT_GT(errors_ms.front(), -1.0);
  EXPECT_LT(errors_ms.back(), 10.0);
  EXPECT_LT(errors_ms[errors_ms.size() / 2], 3.0);
  std::size_t imu = 0, bend = 0;
  for (const auto& x : rig.samples) (x.event.kind == ftm::FtmEvent::Kind::imu ? imu : bend)++;
  EXPECT_GT(imu, 0u);
  EXPECT_GT(bend, imu);  // 3 kHz of bend samples against 800 Hz of IMU samples
  EXPECT_EQ(st.stream.lost_imu_samples + st.stream.lost_bend_samples, 0u);
  EXPECT_EQ(st.stream.decode_errors, 0u);
  EXPECT_EQ(st.connects, 1u);
  EXPECT_TRUE(st.clock_locked);
  EXPECT_TRUE(st.have_info);
  EXPECT_EQ(st.info.imu_rate_hz, 200);
  EXPECT_EQ(st.info.bend_rate_hz, 1000);
  EXPECT_EQ(rig.state_log(),
            (std::vector<FtmLinkState>{FtmLinkState::connecting, FtmLinkState::streaming, FtmLinkState::stopped}));
  EXPECT_TRUE(rig.link->writes().empty());  // a streaming board is left alone
}

TEST(FtmBoardDevice, ResumesAfterUnplugAndReplug) {
  FtmEmulatorOptions eo;
  eo.faults.unplugs.push_back({200 * kNsPerMillisecond, 150 * kNsPerMillisecond});
  eo.boot_timestamp_us = 4'000'000'000u;
  FtmeRig rig(eo);
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  rig.link->schedule_unplug(rig.server.time_zero_ns() + 200 * kNsPerMillisecond, 150 * kNsPerMillisecond);
  ASSERT_TRUE(rig.drain_until([&] {
    return !rig.samples.empty() && rig.samples.back().epoch == 1 && rig.samples.back().sequence >= 100;
  })) << rig.samples.size();
  ASSERT_TRUE(rig.quiesce());
  rig.device.stop();
  const FtmDeviceStats st = rig.device.stats();
  const TimeNs t0 = rig.server.time_zero_ns();
  std::size_t before = 0, after = 0;
  std::array<TimeNs, 7> last{};
  for (const FtmBoardSample& x : rig.samples) {
    const TimeNs t = x.event.time_ns() - t0;
    EXPECT_FALSE(t > 210 * kNsPerMillisecond && t < 340 * kNsPerMillisecond) << ns_to_seconds(t);
    (x.epoch == 0 ? before : after)++;
    // Values against the feed at the mapped time: the clock re-locked on the rebooted board.
    ftme_expect_value(x, t, 0.010);
    const std::size_t slot = x.event.kind == ftm::FtmEvent::Kind::imu ? x.event.index : 4u + x.event.index;
    EXPECT_GT(x.event.time_ns(), last[slot]);
    last[slot] = x.event.time_ns();
  }
  EXPECT_GT(before, 0u);
  EXPECT_GT(after, 0u);
  EXPECT_GE(st.disconnects, 1u);
  EXPECT_GE(st.connects, 2u);
  EXPECT_EQ(st.stream.device_resets, 1u);
  EXPECT_GE(st.clock_relocks, 1u);
  const auto log = rig.state_log();
  const auto pos = std::find(log.begin(), log.end(), FtmLinkState::disconnected);
  ASSERT_NE(pos, log.end());
  EXPECT_NE(std::find(pos, log.end(), FtmLinkState::streaming), log.end());
}

TEST(FtmBoardDevice, EmulatorAndLinkFaultsAreSkippedAndAccountedFor) {
  FtmEmulatorOptions eo;
  eo.seed = 5;
  eo.faults.duplicate_probability = 0.05;
  eo.faults.reorder_probability = 0.05;
  eo.faults.device_overrun_probability = 0.03;
  hid::FakeHidFaults faults;
  faults.corrupt_probability = 0.05;
  faults.drop_probability = 0.05;
  faults.seed = 4;
  FtmeRig rig(eo, faults);
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  ASSERT_TRUE(rig.drain_until([&] { return rig.device.stats().reports_read >= 600; }));
  ASSERT_TRUE(rig.quiesce());
  rig.device.stop();
  const FtmDeviceStats st = rig.device.stats();
  EXPECT_GT(st.stream.decode_errors, 0u);
  EXPECT_GT(st.stream.lost_imu_samples + st.stream.lost_bend_samples, 0u);
  EXPECT_GT(st.stream.duplicates, 0u);
  EXPECT_GT(st.stream.device_overruns, 0u);
  EXPECT_EQ(st.stream.device_resets, 0u);
  EXPECT_EQ(st.connects, 1u);
  EXPECT_EQ(rig.samples.size(), st.samples_delivered);
  const std::vector<double> errors_ms = ftme_check_device_samples(rig);
  ASSERT_FALSE(errors_ms.empty());
}

TEST(FtmBoardDevice, QueuedCommandsReachTheBoard) {
  FtmeRig rig;
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  ASSERT_TRUE(rig.drain_until([&] { return rig.device.stats().stream.imu_reports >= 10; }));
  FtmCommand c;
  c.op = FtmCommandOp::set_rates;
  c.token = 3;
  c.imu_rate_hz = 100;
  c.bend_rate_hz = 500;
  rig.device.send_command(c);
  ASSERT_TRUE(rig.drain_until([&] {
    const FtmDeviceStats s = rig.device.stats();
    return s.stream.imu_period_us == 10000 && s.stream.bend_period_us == 2000 && s.stream.imu_reports >= 30;
  }));
  ASSERT_EQ(rig.link->writes().size(), 1u);
  EXPECT_EQ(decode_ftm_command(rig.link->writes()[0]).value(), c);
  // The rate change restarted the stream: a new epoch, and no loss counted across it.
  const FtmDeviceStats s = rig.device.stats();
  EXPECT_EQ(s.stream.device_resets, 1u);
  EXPECT_GE(s.clock_relocks, 1u);
}

TEST(FtmBoardDevice, ALiveBoardIsAFeedInTimeOrder) {
  FtmeRig rig;
  FtmBoardFeed feed(rig.device);
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  std::vector<ftm::FtmEvent> events;
  // The consumer polls 100 ms behind now: a bend report's 5 ms and the link's
  // latency, with room for a loaded machine's scheduling.
  ASSERT_TRUE(wait_until([&] {
    feed.advance(MonotonicClock::instance().now_ns() - 100 * kNsPerMillisecond, events);
    return events.size() >= 2000;
  }));
  rig.device.stop();
  TimeNs prev = 0;
  std::size_t imu = 0;
  for (std::size_t i = 0; i < events.size(); ++i) {
    const ftm::FtmEvent& e = events[i];
    EXPECT_GE(e.time_ns(), prev) << i;
    if (i > 0 && e.time_ns() == prev) {
      EXPECT_GE(e.kind, events[i - 1].kind) << i;
    }
    prev = e.time_ns();
    imu += e.kind == ftm::FtmEvent::Kind::imu;
  }
  EXPECT_GT(imu, 0u);
  EXPECT_LT(imu, events.size());
  EXPECT_EQ(feed.delivered(), events.size());
  // Only a reader stalled for longer than the lag delivers out of order.
  EXPECT_LE(feed.dropped_out_of_order(), feed.delivered() / 10);
}

// ---------------------------------------------------------------------------
// Fuzz seed corpus (tests/fuzz/corpus/ftm_protocol)

fs::path ftme_corpus_dir() { return testing_support::fuzz_corpus_dir("ftm_protocol"); }
using proprio::testing_support::read_bytes;
using proprio::testing_support::write_bytes;
Bytes ftme_concat(const std::vector<FtmEmulatedReport>& reports) { return testing_support::concat_reports(reports); }

// PROPRIO_REGEN_CORPUS=1 ctest -R FtmSeedCorpus rewrites the seeds after a
// protocol change; commit the result.
TEST(FtmSeedCorpus, Regenerate) {
  if (!testing_support::regenerate_corpus_requested())
    GTEST_SKIP() << "set PROPRIO_REGEN_CORPUS=1 to rewrite the seeds";
  const fs::path dir = ftme_corpus_dir();
  fs::create_directories(dir);
  FtmBoardEmulator plain = ftme_make();
  const auto plain_reports = ftme_run(plain, 40 * kNsPerMillisecond);
  write_bytes(dir / "imu_report.bin", Bytes(plain_reports[0].bytes.begin(), plain_reports[0].bytes.end()));
  for (const auto& r : plain_reports) {
    if (r.bytes[0] == static_cast<std::uint8_t>(FtmReportId::bend)) {
      write_bytes(dir / "bend_report.bin", Bytes(r.bytes.begin(), r.bytes.end()));
      break;
    }
  }
  write_bytes(dir / "stream_40ms.bin", ftme_concat(plain_reports));

  FtmEmulatorOptions wrap;
  wrap.boot_timestamp_us = 0xFFFFFFFFu - 15'000u;
  wrap.clock_error_ppm = -90;
  wrap.faults.unplugs.push_back({30 * kNsPerMillisecond, 10 * kNsPerMillisecond});
  FtmBoardEmulator wrapping = ftme_make(wrap);
  write_bytes(dir / "stream_wrap_restart.bin", ftme_concat(ftme_run(wrapping, 60 * kNsPerMillisecond)));

  FtmEmulatorOptions faulty;
  faulty.seed = 2;
  faulty.faults.corrupt_probability = 0.2;
  faulty.faults.duplicate_probability = 0.2;
  faulty.faults.reorder_probability = 0.2;
  faulty.faults.device_overrun_probability = 0.2;
  auto spoil = [](ftm::FtmEvent& e) {
    if (e.kind == ftm::FtmEvent::Kind::imu && e.index == 1) e.imu.gyro_radps.z() = 50.0;
    if (e.kind == ftm::FtmEvent::Kind::bend && e.index == 0) e.bend.capacitance_pF = 900.0;
  };
  FtmBoardEmulator faults = ftme_make(faulty, spoil);
  write_bytes(dir / "stream_faults.bin", ftme_concat(ftme_run(faults, 60 * kNsPerMillisecond)));

  const auto info = ftme_make().info_report(123'456'000);
  write_bytes(dir / "info_report.bin", Bytes(info.begin(), info.end()));
  FtmCommand c;
  c.op = FtmCommandOp::set_rates;
  c.imu_rate_hz = 100;
  c.bend_rate_hz = 500;
  c.token = 5;
  const auto cb = encode_ftm_command(c);
  write_bytes(dir / "command_set_rates.bin", Bytes(cb.begin(), cb.end()));
}

TEST(FtmSeedCorpus, EverySeedStillDecodes) {
  const fs::path dir = ftme_corpus_dir();
  ASSERT_TRUE(fs::is_directory(dir)) << dir << " is missing; run with PROPRIO_REGEN_CORPUS=1";
  const std::size_t seeds = testing_support::check_seed_corpus(
      dir, [](const Bytes& b) { return decode_ftm_info_report(b); },
      [](const Bytes& b) { return decode_ftm_command(b); },
      [](const Bytes& b, bool faulty) {
        ASSERT_EQ(b.size() % kFtmDataReportSize, 0u);
        ASSERT_GT(b.size(), 0u);
        FtmStreamDecoder d;
        std::array<FtmBoardSample, kFtmMaxSamplesPerReport> out;
        for (std::size_t at = 0; at < b.size(); at += kFtmDataReportSize) {
          d.push(std::span(b).subspan(at, kFtmDataReportSize), out);
        }
        if (faulty) {
          EXPECT_GT(d.stats().decode_errors, 0u);
        } else {
          EXPECT_EQ(d.stats().decode_errors, 0u);
          EXPECT_GT(d.stats().accepted, 0u);
        }
      });
  EXPECT_GE(seeds, 7u);
}

}  // namespace
}  // namespace proprio::devices::ftm_board_emulator_test
