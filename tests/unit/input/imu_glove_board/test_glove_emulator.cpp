// ImuGloveEmulator: driven by proprio::sim's ImuSimulator (the wiring lives
// here, since proprio::devices may not depend on proprio::sim), decoded by
// ImuGloveStreamDecoder. Also writes and checks the fuzz seed corpus.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/imu_glove_board/imu_glove_emulator.hpp"
#include "proprio/imu_glove_board/imu_glove_protocol.hpp"
#include "proprio/imu_glove_board/imu_glove_stream.hpp"
#include "proprio/sim/hand_motion.hpp"
#include "proprio/sim/imu_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "support/devices.hpp"
#include "support/seed_corpus.hpp"

namespace proprio::devices {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;
using proprio::testing_support::kG;

std::vector<ImuSample> samples_of(std::span<const sim::ImuReading> readings) {
  std::vector<ImuSample> out;
  out.reserve(readings.size());
  for (const auto& r : readings) out.push_back(r.sample);
  return out;
}

// Still samples for n IMUs (for tests that do not need motion).
std::vector<ImuSample> still(std::size_t n = 7, double ax = 0.0) {
  std::vector<ImuSample> out(n);
  for (std::size_t i = 0; i < n; ++i) {
    out[i].sensor_id = static_cast<std::uint16_t>(i);
    out[i].accel_mps2 = Vec3(ax, kG, 0.01 * static_cast<double>(i));
    out[i].gyro_radps = Vec3(0.001 * static_cast<double>(i), 0, 0);
  }
  return out;
}

ImuGloveEmulator make(ImuGloveEmulatorOptions o = {}) {
  auto e = ImuGloveEmulator::create(std::move(o));
  EXPECT_TRUE(e.ok()) << (e.ok() ? "" : e.error().message);
  return *e;
}

// Runs n ticks at the emulator's rate; returns every report's bytes in send order.
std::vector<ImuGloveEmulatedReport> run(ImuGloveEmulator& e, std::int64_t n, std::int64_t first_tick = 0) {
  std::vector<ImuGloveEmulatedReport> out;
  const DurationNs period = kNsPerSecond / e.rate_hz();
  for (std::int64_t k = first_tick; k < first_tick + n; ++k) {
    EXPECT_TRUE(e.tick(k * period, still(e.options().imu_count, 0.001 * static_cast<double>(k)), out).ok());
  }
  e.flush(out);
  return out;
}

struct Decoded {
  ImuGloveStreamDecoder decoder;
  std::vector<ImuGloveSample> samples;
  std::vector<ImuGlovePushResult> results;
  void push_all(const std::vector<ImuGloveEmulatedReport>& reports) {
    std::array<ImuGloveSample, 4> buf;
    for (const auto& r : reports) {
      results.push_back(decoder.push(r.bytes, buf, r.send_ns));
      for (std::size_t i = 0; i < results.back().sample_count; ++i) samples.push_back(buf[i]);
    }
  }
};

// ---------------------------------------------------------------------------
// Against the IMU simulator

TEST(GloveEmulator, EmulatorAndDecoderReproduceImuSimulatorReadingsWithinQuantisation) {
  const HandShape shape = *sim::sim_subject(2)->shape();
  sim::HandMotionGenerator motion(HandModel(shape), sim::HandMotionOptions{});
  auto imu_sim = sim::ImuSimulator::create(motion, ImuGloveDescription::vist_default().place_imus(shape),
                                           sim::ImuNoiseOptions{}, 5);
  ASSERT_TRUE(imu_sim.ok()) << imu_sim.error().message;
  ASSERT_EQ(imu_sim->imu_count(), 7u);
  ImuGloveEmulatorOptions eo;
  eo.imu_count = 7;
  eo.clock_error_ppm = 37.0;
  ImuGloveEmulator emu = make(eo);

  ImuGloveStreamDecoder decoder;
  std::array<ImuGloveSample, 4> buf;
  std::vector<ImuGloveEmulatedReport> out;
  const double qa = 0.5 / accel_counts_per_mps2(AccelRange::g16) * (1 + 1e-9);
  const double qg = 0.5 / gyro_counts_per_radps(GyroRange::dps2000) * (1 + 1e-9);
  double worst_a = 0, worst_g = 0;
  std::size_t compared = 0;
  for (int k = 0; k < 1000; ++k) {
    const TimeNs tick = imu_sim->next_nominal_time_ns();
    const auto readings = imu_sim->next();
    out.clear();
    ASSERT_TRUE(emu.tick(tick, samples_of(readings), out).ok());
    ASSERT_EQ(out.size(), 2u);
    for (const auto& r : out) {
      const auto res = decoder.push(r.bytes, buf);
      ASSERT_EQ(res.verdict, ImuGloveReportVerdict::accepted);
      EXPECT_EQ(res.timestamp_us, emu.device_timestamp_us(tick));
      for (std::size_t i = 0; i < res.sample_count; ++i) {
        const ImuGloveSample& s = buf[i];
        const sim::ImuReading& truth = readings[s.imu.sensor_id];
        ASSERT_EQ(truth.sample.sensor_id, s.imu.sensor_id);
        const bool saturated = truth.accel_saturated || truth.gyro_saturated;
        EXPECT_EQ(s.status != 0, saturated);
        if (saturated) continue;
        worst_a = std::max(worst_a, (s.imu.accel_mps2 - truth.sample.accel_mps2).cwiseAbs().maxCoeff());
        worst_g = std::max(worst_g, (s.imu.gyro_radps - truth.sample.gyro_radps).cwiseAbs().maxCoeff());
        ++compared;
      }
    }
  }
  EXPECT_EQ(compared, 7000u);
  EXPECT_LE(worst_a, qa);
  EXPECT_LE(worst_g, qg);
  EXPECT_EQ(decoder.stats().lost, 0u);
  EXPECT_EQ(decoder.stats().samples_good(), 7000u);
  // The period the host measures is the device's: 10 ms on a crystal 37 ppm fast.
  EXPECT_NEAR(decoder.stats().tick_period_us, 10000.37, 0.05);
}

TEST(GloveEmulator, SaturatedAndNonFiniteReadingsAreFlaggedAndCounted) {
  ImuGloveEmulator emu = make();
  Decoded d;
  std::vector<ImuGloveEmulatedReport> out;
  for (int k = 0; k < 10; ++k) {
    auto s = still();
    if (k % 2 == 0) s[1].accel_mps2.y() = 20 * kG;  // beyond ±16 g
    if (k % 5 == 0) s[6].gyro_radps.x() = -0.0175 * 2500;  // beyond -2000 °/s
    if (k == 3) s[3].gyro_radps.z() = std::nan("");
    ASSERT_TRUE(emu.tick(k * 10 * kNsPerMillisecond, s, out).ok());
  }
  d.push_all(out);
  const auto& st = d.decoder.stats();
  EXPECT_EQ(st.imus[1].accel_saturated, 5u);
  EXPECT_EQ(st.imus[6].gyro_saturated, 2u);
  EXPECT_EQ(st.imus[3].sensor_error, 1u);
  EXPECT_EQ(st.samples_rejected(), 8u);
  EXPECT_EQ(emu.stats().saturated_samples, 7u);
  EXPECT_EQ(emu.stats().error_samples, 1u);
  for (const ImuGloveSample& s : d.samples) {
    if (s.imu.sensor_id == 1 && (s.status & imu_status::accel_saturated)) {
      EXPECT_NEAR(s.imu.accel_mps2.y(), 32767 / 2048.0 * kG, 1e-9);  // pinned at the rail
    }
    if (s.status & imu_status::sensor_error) {
      EXPECT_EQ(s.imu.gyro_radps, Vec3::Zero());
    }
  }
}

// ---------------------------------------------------------------------------
// The device clock

TEST(GloveEmulator, TimestampsFollowTheDriftingCrystalAndWrap) {
  ImuGloveEmulatorOptions o;
  o.clock_error_ppm = 80.0;
  o.boot_timestamp_us = 0xFFFFFFFFu - 200'000u;  // wraps 0.2 s in
  ImuGloveEmulator emu = make(o);
  Decoded d;
  d.push_all(run(emu, 100));
  ASSERT_EQ(d.samples.size(), 700u);
  for (const ImuGloveSample& s : d.samples) {
    const std::int64_t k = s.sequence;
    // 10 ms of a crystal 80 ppm fast is 10000.8 counts; the counter truncates.
    EXPECT_NEAR(static_cast<double>(s.device_time_us - static_cast<std::int64_t>(o.boot_timestamp_us)),
                static_cast<double>(k) * 10000.8, 1.0)
        << k;
    EXPECT_EQ(s.timestamp_us, emu.device_timestamp_us(k * 10 * kNsPerMillisecond));
  }
  EXPECT_EQ(d.decoder.stats().timestamp_wraps, 1u);
  EXPECT_EQ(d.decoder.stats().device_resets, 0u);
}

// ---------------------------------------------------------------------------
// Faults: each accounted for by the decoder, all reproducible from the seed.

struct FaultRun {
  ImuGloveEmulatorStats emulated;
  ImuGloveStreamStats decoded;
  std::vector<ImuGloveEmulatedReport> reports;
  std::vector<ImuGloveSample> samples;
};
FaultRun run_faults(ImuGloveEmulatorFaults f, std::uint64_t seed = 3, std::int64_t ticks = 2000) {
  ImuGloveEmulatorOptions o;
  o.faults = std::move(f);
  o.seed = seed;
  ImuGloveEmulator emu = make(o);
  Decoded d;
  FaultRun r;
  r.reports = run(emu, ticks);
  d.push_all(r.reports);
  r.emulated = emu.stats();
  r.decoded = d.decoder.stats();
  r.samples = d.samples;
  return r;
}

TEST(GloveEmulatorFaults, CorruptedReportsAreAllCaught) {
  ImuGloveEmulatorFaults f;
  f.corrupt_probability = 0.05;
  const FaultRun r = run_faults(f);
  ASSERT_GT(r.emulated.corrupted, 100u);
  EXPECT_EQ(r.decoded.decode_errors, r.emulated.corrupted);
  EXPECT_EQ(r.decoded.accepted, 4000u - r.emulated.corrupted);
}

TEST(GloveEmulatorFaults, DroppedReportsAreCountedLost) {
  ImuGloveEmulatorFaults f;
  f.drop_probability = 0.05;
  const FaultRun r = run_faults(f);
  ASSERT_GT(r.emulated.dropped, 100u);
  EXPECT_LE(r.decoded.lost, r.emulated.dropped);
  EXPECT_GE(r.decoded.lost + 2, r.emulated.dropped);  // the last report of each part may be the lost one
  EXPECT_EQ(r.decoded.accepted, r.emulated.reports_sent);
}

TEST(GloveEmulatorFaults, DuplicatesAreCounted) {
  ImuGloveEmulatorFaults f;
  f.duplicate_probability = 0.05;
  const FaultRun r = run_faults(f);
  ASSERT_GT(r.emulated.duplicated, 100u);
  EXPECT_EQ(r.decoded.duplicates, r.emulated.duplicated);
  EXPECT_EQ(r.decoded.accepted, 4000u);
  EXPECT_EQ(r.decoded.lost, 0u);
}

TEST(GloveEmulatorFaults, ReorderedReportsLoseNothing) {
  ImuGloveEmulatorFaults f;
  f.reorder_probability = 0.05;
  const FaultRun r = run_faults(f);
  ASSERT_GT(r.emulated.reordered, 100u);
  EXPECT_EQ(r.decoded.accepted + r.decoded.late, 4000u);
  EXPECT_EQ(r.decoded.lost, 0u);
  EXPECT_EQ(r.decoded.duplicates, 0u);
}

TEST(GloveEmulatorFaults, StaleSamplesRepeatTheLastValuesAndAreCounted) {
  ImuGloveEmulatorFaults f;
  f.stale_probability = 0.1;
  const FaultRun r = run_faults(f, 3, 500);
  ASSERT_GT(r.emulated.stale_samples, 100u);
  std::uint64_t stale = 0;
  for (const auto& imu : r.decoded.imus) stale += imu.stale;
  EXPECT_EQ(stale, r.emulated.stale_samples);
  std::array<const ImuGloveSample*, 7> last{};
  for (const ImuGloveSample& s : r.samples) {
    if ((s.status & imu_status::stale) && last[s.imu.sensor_id]) {
      EXPECT_EQ(s.imu.accel_mps2, last[s.imu.sensor_id]->imu.accel_mps2);
    }
    last[s.imu.sensor_id] = &s;
  }
}

TEST(GloveEmulatorFaults, EverythingAtOnceIsReproducibleFromTheSeed) {
  ImuGloveEmulatorFaults f;
  f.drop_probability = 0.02;
  f.duplicate_probability = 0.02;
  f.corrupt_probability = 0.02;
  f.reorder_probability = 0.02;
  f.stale_probability = 0.02;
  f.unplugs.push_back({3 * kNsPerSecond, kNsPerSecond});
  const FaultRun a = run_faults(f, 11, 1000);
  const FaultRun b = run_faults(f, 11, 1000);
  const FaultRun c = run_faults(f, 12, 1000);
  ASSERT_EQ(a.reports.size(), b.reports.size());
  for (std::size_t i = 0; i < a.reports.size(); ++i) {
    ASSERT_EQ(a.reports[i].bytes, b.reports[i].bytes) << i;
    ASSERT_EQ(a.reports[i].send_ns, b.reports[i].send_ns) << i;
  }
  bool differs = a.reports.size() != c.reports.size();
  for (std::size_t i = 0; !differs && i < a.reports.size(); ++i) differs = a.reports[i].bytes != c.reports[i].bytes;
  EXPECT_TRUE(differs);
  EXPECT_EQ(a.decoded.device_resets, 1u);
  // Switching one fault off leaves the others' draws alone.
  ImuGloveEmulatorFaults no_stale = f;
  no_stale.stale_probability = 0.0;
  const FaultRun d = run_faults(no_stale, 11, 1000);
  EXPECT_EQ(d.emulated.dropped, a.emulated.dropped);
  EXPECT_EQ(d.emulated.corrupted, a.emulated.corrupted);
}

TEST(GloveEmulator, UnpluggingRebootsTheGlove) {
  ImuGloveEmulatorOptions o;
  o.boot_timestamp_us = 1000;
  o.faults.unplugs.push_back({kNsPerSecond, kNsPerSecond / 2});
  ImuGloveEmulator emu = make(o);
  const auto reports = run(emu, 300);
  EXPECT_EQ(emu.stats().boots, 2u);
  EXPECT_EQ(emu.stats().ticks_unpowered, 50u);
  EXPECT_EQ(reports.size(), 2u * 250u);
  for (const auto& r : reports) {
    EXPECT_FALSE(r.send_ns >= kNsPerSecond && r.send_ns < 3 * kNsPerSecond / 2) << r.send_ns;
  }
  // The first report after the outage: a freshly booted glove.
  const auto first_after = std::find_if(reports.begin(), reports.end(),
                                        [](const auto& r) { return r.send_ns >= 3 * kNsPerSecond / 2; });
  ASSERT_NE(first_after, reports.end());
  auto rep = decode_data_report(first_after->bytes);
  ASSERT_TRUE(rep.ok());
  EXPECT_EQ(rep->sequence, 0);
  EXPECT_EQ(rep->timestamp_us, 1000u);
  EXPECT_TRUE(rep->flags & data_flags::stream_start);
  Decoded d;
  d.push_all(reports);
  EXPECT_EQ(d.decoder.stats().device_resets, 1u);
  EXPECT_EQ(d.decoder.stats().lost, 0u);
  EXPECT_EQ(d.samples.back().epoch, 1u);
}

TEST(GloveEmulator, SkippedTicksAreOverruns) {
  ImuGloveEmulator emu = make();
  std::vector<ImuGloveEmulatedReport> out;
  for (TimeNs t : {0, 10, 40, 50}) ASSERT_TRUE(emu.tick(t * kNsPerMillisecond, still(), out).ok());
  auto third = decode_data_report(out[4].bytes);
  ASSERT_TRUE(third.ok());
  EXPECT_EQ(third->sequence, 4);
  EXPECT_TRUE(third->flags & data_flags::overrun);
  EXPECT_FALSE(decode_data_report(out[6].bytes)->flags & data_flags::overrun);
  Decoded d;
  d.push_all(out);
  EXPECT_EQ(d.decoder.stats().lost, 4u);
  EXPECT_EQ(d.decoder.stats().device_overruns, 1u);
}

// ---------------------------------------------------------------------------
// Host commands and device info

TEST(GloveEmulator, AnswersCommandsAsTheFirmwareDoes) {
  ImuGloveEmulator emu = make();
  std::vector<ImuGloveEmulatedReport> out;
  auto info = [&](TimeNs t) { return *decode_info_report(emu.info_report(t)); };
  EXPECT_EQ(info(0).last_command_result, ImuGloveCommandResult::none);
  EXPECT_TRUE(info(0).streaming);
  EXPECT_EQ(info(0).imu_count, 7);
  EXPECT_EQ(info(0).rate_hz, 100);

  ImuGloveCommand c;
  c.op = ImuGloveCommandOp::stop_streaming;
  c.token = 1;
  EXPECT_EQ(emu.handle_command(encode_command(c)), ImuGloveCommandResult::ok);
  ASSERT_TRUE(emu.tick(0, still(), out).ok());
  EXPECT_TRUE(out.empty());
  EXPECT_FALSE(info(0).streaming);
  EXPECT_EQ(info(0).last_command_token, 1);

  c.op = ImuGloveCommandOp::set_rate;
  c.rate_hz = 0;
  c.token = 2;
  EXPECT_EQ(emu.handle_command(encode_command(c)), ImuGloveCommandResult::bad_argument);
  EXPECT_EQ(info(0).last_command_result, ImuGloveCommandResult::bad_argument);
  c.rate_hz = 200;
  EXPECT_EQ(emu.handle_command(encode_command(c)), ImuGloveCommandResult::ok);
  EXPECT_EQ(info(0).rate_hz, 200);

  c.op = ImuGloveCommandOp::set_ranges;
  c.accel_range = AccelRange::g4;
  c.gyro_range = GyroRange::dps500;
  EXPECT_EQ(emu.handle_command(encode_command(c)), ImuGloveCommandResult::ok);

  c.op = ImuGloveCommandOp::start_streaming;
  c.token = 3;
  EXPECT_EQ(emu.handle_command(encode_command(c)), ImuGloveCommandResult::ok);
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(emu.tick(k * 5 * kNsPerMillisecond, still(7, 0.25), out).ok());
  ASSERT_EQ(out.size(), 6u);
  auto first = *decode_data_report(out[0].bytes);
  EXPECT_EQ(first.sequence, 0);
  EXPECT_TRUE(first.flags & data_flags::stream_start);
  EXPECT_EQ(first.accel_range, AccelRange::g4);
  EXPECT_EQ(first.gyro_range, GyroRange::dps500);
  EXPECT_EQ(decode_data_report(out[5].bytes)->sequence, 2);  // 5 ms apart at 200 Hz: no overrun
  EXPECT_EQ(first.imus[0].accel[0], std::lround(0.25 * 8192 / kG));
  EXPECT_EQ(info(0).last_command_token, 3);

  // Bytes that are not a command are answered, not thrown at.
  EXPECT_EQ(emu.handle_command(Bytes{0x10, 0x10, 1}), ImuGloveCommandResult::bad_report);
  const auto start_bytes = encode_command(c);
  Bytes unknown(start_bytes.begin(), start_bytes.end());
  unknown[2] = 0x77;
  const std::uint16_t crc = hid::crc16_ccitt(std::span(unknown).first(14));
  unknown[14] = static_cast<std::uint8_t>(crc);
  unknown[15] = static_cast<std::uint8_t>(crc >> 8);
  EXPECT_EQ(emu.handle_command(unknown), ImuGloveCommandResult::unknown_command);
  EXPECT_EQ(info(0).last_command_result, ImuGloveCommandResult::unknown_command);
}

TEST(GloveEmulator, RefusesBadOptionsAndInputsWithUsableMessages) {
  auto message = [](ImuGloveEmulatorOptions o) {
    auto e = ImuGloveEmulator::create(std::move(o));
    return e.ok() ? std::string() : e.error().message;
  };
  ImuGloveEmulatorOptions o;
  o.imu_count = 17;
  EXPECT_NE(message(o).find("imu_count"), std::string::npos);
  o = {};
  o.rate_hz = 501;
  EXPECT_NE(message(o).find("rate_hz"), std::string::npos);
  o = {};
  o.clock_error_ppm = 5000;
  EXPECT_NE(message(o).find("clock_error_ppm"), std::string::npos);
  o = {};
  o.faults.corrupt_probability = 1.5;
  EXPECT_NE(message(o).find("corrupt_probability"), std::string::npos);
  o = {};
  o.faults.unplugs.push_back({0, 0});
  EXPECT_NE(message(o).find("unplugs[0]"), std::string::npos);

  ImuGloveEmulator emu = make();
  std::vector<ImuGloveEmulatedReport> out;
  auto s = emu.tick(0, still(6), out);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::invalid_argument);
  auto wrong_ids = still();
  std::swap(wrong_ids[0], wrong_ids[1]);
  EXPECT_FALSE(emu.tick(0, wrong_ids, out).ok());
  EXPECT_TRUE(out.empty());
}

// ---------------------------------------------------------------------------
// Served over the fake link (ImuGloveEmulatorServer), on a manual clock

TEST(GloveEmulatorServer, TicksAtTheEmulatorsRateWithTheProvidersReadingsAndAnswersTheHost) {
  ManualClock clock(5 * kNsPerSecond);
  auto link = std::make_shared<hid::FakeHidLink>(clock);
  std::vector<std::pair<std::int64_t, TimeNs>> calls;  // the server's thread and this one, under its lock
  ImuGloveEmulatorServer server(ImuGloveTicker(make(),
                                               [&](std::int64_t k, TimeNs t, std::span<ImuSample> out) {
                                                 calls.emplace_back(k, t);
                                                 for (auto& s : out)
                                                   s.accel_mps2 = Vec3(0.0, kG, 0.001 * static_cast<double>(k));
                                               }),
                                link, ImuGloveServeOptions{}, clock);
  server.start();
  clock.advance(35 * kNsPerMillisecond);
  server.pump();
  auto ticks = [&] { return server.with_emulator([&](const ImuGloveTicker&) { return calls; }); };
  auto seen = ticks();
  ASSERT_EQ(seen.size(), 4u);  // 0, 10, 20 and 30 ms at 100 Hz
  for (std::size_t k = 0; k < seen.size(); ++k) {
    EXPECT_EQ(seen[k].first, static_cast<std::int64_t>(k));
    EXPECT_EQ(seen[k].second, static_cast<TimeNs>(k) * 10 * kNsPerMillisecond);
  }
  EXPECT_EQ(server.emulator_stats().reports_sent, 8u);  // two reports per tick of 7 IMUs

  // The host sets 200 Hz: the next ticks come 5 ms apart.
  hid::FakeHidTransport host(link);
  ASSERT_TRUE(host.open());
  ImuGloveCommand c;
  c.op = ImuGloveCommandOp::set_rate;
  c.rate_hz = 200;
  c.token = 9;
  ASSERT_TRUE(host.write(encode_command(c)));
  clock.advance(20 * kNsPerMillisecond);
  server.pump();
  seen = ticks();
  ASSERT_GE(seen.size(), 6u);
  EXPECT_EQ(seen.back().second - seen[seen.size() - 2].second, 5 * kNsPerMillisecond);
  std::array<std::uint8_t, kImuGloveInfoReportSize> info{};
  auto n = host.get_feature(static_cast<std::uint8_t>(ImuGloveReportId::device_info), info);
  ASSERT_TRUE(n) << n.error().message;
  auto decoded = decode_info_report(info);
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ(decoded->rate_hz, 200);
  EXPECT_EQ(decoded->last_command_token, 9);
  EXPECT_EQ(server.with_emulator([](const ImuGloveTicker& g) { return g.refused_ticks; }), 0u);
  server.stop();
}

TEST(GloveEmulatorServer, TicksWithBadReadingsAreRefusedAndCounted) {
  ManualClock clock;
  auto link = std::make_shared<hid::FakeHidLink>(clock);
  ImuGloveEmulatorServer server(
      ImuGloveTicker(make(), [](std::int64_t, TimeNs, std::span<ImuSample> out) { out[0].sensor_id = 3; }), link,
      ImuGloveServeOptions{}, clock);
  server.start();
  clock.advance(25 * kNsPerMillisecond);
  server.pump();
  server.stop();
  EXPECT_EQ(server.with_emulator([](const ImuGloveTicker& g) { return g.refused_ticks; }), 3u);
  EXPECT_EQ(server.emulator_stats().reports_sent, 0u);
}

// ---------------------------------------------------------------------------
// Fuzz seed corpus (tests/fuzz/corpus/glove_protocol)

fs::path corpus_dir() { return testing_support::fuzz_corpus_dir("glove_protocol"); }

using proprio::testing_support::read_bytes;
using proprio::testing_support::write_bytes;
Bytes concat(const std::vector<ImuGloveEmulatedReport>& reports) { return testing_support::concat_reports(reports); }

// PROPRIO_REGEN_CORPUS=1 ctest -R GloveSeedCorpus rewrites the seeds after a
// protocol change; commit the result.
TEST(GloveSeedCorpus, Regenerate) {
  if (!testing_support::regenerate_corpus_requested())
    GTEST_SKIP() << "set PROPRIO_REGEN_CORPUS=1 to rewrite the seeds";
  const fs::path dir = corpus_dir();
  fs::create_directories(dir);
  fs::remove(dir / "empty_seed");

  ImuGloveEmulator plain = make();
  const auto ten = run(plain, 10);
  write_bytes(dir / "data_report_part0.bin", Bytes(ten[0].bytes.begin(), ten[0].bytes.end()));
  write_bytes(dir / "data_report_part1.bin", Bytes(ten[1].bytes.begin(), ten[1].bytes.end()));
  write_bytes(dir / "stream_7imu_10ticks.bin", concat(ten));

  ImuGloveEmulatorOptions wrap;
  wrap.boot_timestamp_us = 0xFFFFFFFFu - 25'000u;
  wrap.clock_error_ppm = -90;
  wrap.faults.unplugs.push_back({60 * kNsPerMillisecond, 20 * kNsPerMillisecond});
  ImuGloveEmulator wrapping = make(wrap);
  write_bytes(dir / "stream_wrap_restart.bin", concat(run(wrapping, 12)));

  ImuGloveEmulatorOptions small;
  small.imu_count = 3;
  small.accel_range = AccelRange::g2;
  small.gyro_range = GyroRange::dps250;
  ImuGloveEmulator three = make(small);
  write_bytes(dir / "stream_3imu_ranges.bin", concat(run(three, 4)));

  ImuGloveEmulatorOptions faulty;
  faulty.seed = 2;
  faulty.faults.corrupt_probability = 0.2;
  faulty.faults.duplicate_probability = 0.2;
  faulty.faults.reorder_probability = 0.2;
  faulty.faults.stale_probability = 0.2;
  ImuGloveEmulator faults = make(faulty);
  write_bytes(dir / "stream_faults.bin", concat(run(faults, 8)));

  ImuGloveDeviceInfo info;
  info.imu_count = 7;
  info.rate_hz = 100;
  info.streaming = true;
  info.timestamp_us = 123456;
  const auto ib = encode_info_report(info);
  write_bytes(dir / "info_report.bin", Bytes(ib.begin(), ib.end()));
  ImuGloveCommand c;
  c.op = ImuGloveCommandOp::set_rate;
  c.rate_hz = 200;
  c.token = 5;
  const auto cb = encode_command(c);
  write_bytes(dir / "command_set_rate.bin", Bytes(cb.begin(), cb.end()));
}

TEST(GloveSeedCorpus, EverySeedStillDecodes) {
  const fs::path dir = corpus_dir();
  ASSERT_TRUE(fs::is_directory(dir)) << dir << " is missing; run with PROPRIO_REGEN_CORPUS=1";
  const std::size_t seeds = testing_support::check_seed_corpus(
      dir, [](const Bytes& b) { return decode_info_report(b); }, [](const Bytes& b) { return decode_command(b); },
      [](const Bytes& b, bool faulty) {
        ASSERT_EQ(b.size() % kImuGloveDataReportSize, 0u);
        const std::size_t bad = testing_support::count_refused(
            b, kImuGloveDataReportSize, [](std::span<const std::uint8_t> r) { return decode_data_report(r); });
        if (faulty) {
          EXPECT_GT(bad, 0u);
        } else {
          EXPECT_EQ(bad, 0u);
        }
      });
  EXPECT_GE(seeds, 8u);
}

}  // namespace
}  // namespace proprio::devices
