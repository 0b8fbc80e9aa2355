// StretchEmulator against StretchStreamDecoder (offline, bit-exact), and
// StretchDevice end to end over the fake HID link with the emulator served in
// real time. Also writes and checks the fuzz seed corpus.
//
// Threads: every wait is for a condition with a generous deadline (20 s);
// nothing asserts how long anything took.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "proprio/hid/hid_transport.hpp"
#include "proprio/stretch_board/stretch_device.hpp"
#include "proprio/stretch_board/stretch_emulator.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"
#include "proprio/stretch_board/stretch_stream.hpp"
#include "support/board_rig.hpp"
#include "support/devices.hpp"
#include "support/seed_corpus.hpp"

// A namespace of this file's own: its helpers share names with the glove
// emulator tests' (make, Decoded, FaultRun, corpus_dir, ...) in the unity build.
namespace proprio::devices::stretch_emulator_test {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using Bytes = std::vector<std::uint8_t>;
constexpr double kTwoPi = 6.283185307179586;

// Every combination its own level, all drifting slowly (max slope 8.8 pF/s).
double synthetic_pf(std::size_t combination, TimeNs t_ns) {
  const double c = static_cast<double>(combination);
  return 20.0 + 0.5 * c + 2.0 * std::sin(kTwoPi * 0.7 * ns_to_seconds(t_ns) + 0.1 * c);
}
constexpr double kSyntheticMaxSlopePfPerS = 2.0 * kTwoPi * 0.7;

StretchEmulator make(StretchEmulatorOptions o = {}, StretchCapacitanceProvider p = synthetic_pf) {
  auto e = StretchEmulator::create(std::move(o), std::move(p));
  EXPECT_TRUE(e.ok()) << (e.ok() ? "" : e.error().message);
  return std::move(*e);
}

// Runs the emulator to end_ns in 5 ms steps; returns every report in send order.
std::vector<StretchEmulatedReport> run(StretchEmulator& e, TimeNs end_ns) {
  std::vector<StretchEmulatedReport> out;
  for (TimeNs t = 0; t <= end_ns; t += 5 * kNsPerMillisecond) e.advance_to(t, out);
  e.flush(out);
  return out;
}

struct Decoded {
  explicit Decoded(StretchStreamOptions o = {}) : decoder(o) {}
  StretchStreamDecoder decoder;
  std::vector<StretchSample> samples;
  std::vector<StretchPushResult> results;
  void push_all(const std::vector<StretchEmulatedReport>& reports) {
    std::array<StretchSample, kStretchMeasurementsPerReport> buf;
    for (const auto& r : reports) {
      results.push_back(decoder.push(r.bytes, buf, r.send_ns));
      for (std::size_t i = 0; i < results.back().sample_count; ++i) samples.push_back(buf[i]);
    }
  }
};

// ---------------------------------------------------------------------------
// Emulator and decoder, offline

TEST(StretchEmulator, EmulatorAndDecoderReproduceTheProviderWithinQuantisation) {
  StretchEmulatorOptions o;
  o.clock_error_ppm = 37.0;
  StretchEmulator emu = make(o);
  Decoded d;
  d.push_all(run(emu, 2 * kNsPerSecond));
  // 2 s at 960/s, less the last report still filling.
  ASSERT_GE(d.samples.size(), 1920u - 12u);
  ASSERT_LE(d.samples.size(), 1921u);
  std::set<std::uint16_t> combinations;
  double worst = 0.0;
  for (std::size_t i = 0; i < d.samples.size(); ++i) {
    const StretchSample& s = d.samples[i];
    ASSERT_EQ(s.sequence, static_cast<std::int64_t>(i));
    ASSERT_EQ(s.combination, i % 182);
    ASSERT_EQ(s.status, StretchMeasurementStatus::ok);
    EXPECT_EQ(s.combination, s.top_strip * 14 + s.bottom_strip);
    const TimeNs t = emu.measurement_time_ns(static_cast<std::uint64_t>(s.sequence));
    worst = std::max(worst, std::fabs(s.capacitance_pf - synthetic_pf(s.combination, t)));
    // Each measurement's device time, measurement 0 of a report from the wire and the others from the period.
    EXPECT_NEAR(static_cast<double>(s.device_time_us), static_cast<double>(emu.device_timestamp_us(t)), 1.0) << i;
    combinations.insert(s.combination);
  }
  EXPECT_LE(worst, 0.0005 + 1e-9);
  EXPECT_EQ(combinations.size(), 182u);
  const auto& st = d.decoder.stats();
  EXPECT_EQ(st.lost, 0u);
  EXPECT_EQ(st.measurements_good(), d.samples.size());
  // The board paces measurements with its own crystal, so in device µs the period is exact whatever its error.
  EXPECT_NEAR(st.measurement_period_us, 1e6 / 960.0, 0.05);
  EXPECT_EQ(emu.stats().discarded_partial, 0u);
  EXPECT_LT(emu.stats().measurements - d.samples.size(), 12u);  // the report still filling
  // True time between measurements: the crystal runs 37 ppm fast, so its period is that much short.
  EXPECT_NEAR(static_cast<double>(emu.measurement_time_ns(960000) - emu.measurement_time_ns(0)),
              1e9 * 1000.0 / (1.0 + 37e-6), 2.0);
}

TEST(StretchEmulator, TimestampsFollowTheDriftingCrystalAndWrap) {
  StretchEmulatorOptions o;
  o.clock_error_ppm = -80.0;
  o.boot_timestamp_us = 0xFFFFFFFFu - 200'000u;  // wraps 0.2 s in
  StretchEmulator emu = make(o);
  Decoded d;
  d.push_all(run(emu, kNsPerSecond / 2));
  ASSERT_GT(d.samples.size(), 400u);
  for (const StretchPushResult& r : d.results) {
    // Measurement 0 of each report carries the counter as the board latched it.
    const TimeNs t = emu.measurement_time_ns(static_cast<std::uint64_t>(r.sequence));
    EXPECT_EQ(r.timestamp_us, emu.device_timestamp_us(t));
    EXPECT_NEAR(static_cast<double>(r.device_time_us - static_cast<std::int64_t>(o.boot_timestamp_us)),
                static_cast<double>(r.sequence) * 1e6 / 960.0, 1.0);
  }
  EXPECT_EQ(d.decoder.stats().timestamp_wraps, 1u);
  EXPECT_EQ(d.decoder.stats().device_resets, 0u);
}

TEST(StretchEmulator, SlowRatesSendShortReportsRightAfterTheirLastMeasurement) {
  StretchEmulatorOptions o;
  o.rate_hz = 100;  // 12 measurements would span 110 ms; the 20 ms age limit cuts reports at 3
  StretchEmulator emu = make(o);
  const auto reports = run(emu, kNsPerSecond);
  ASSERT_GE(reports.size(), 30u);
  for (const auto& r : reports) {
    auto rep = decode_stretch_data_report(r.bytes);
    ASSERT_TRUE(rep.ok()) << rep.error().message;
    EXPECT_EQ(rep->count, 3);
    EXPECT_EQ(r.send_ns, emu.measurement_time_ns(rep->sequence + 2u));
  }
  Decoded d;
  d.push_all(reports);
  EXPECT_EQ(d.decoder.stats().lost, 0u);
  EXPECT_NEAR(d.decoder.stats().measurement_period_us, 10000.0, 0.5);
}

TEST(StretchEmulator, OutOfRangeReadingsAreFlaggedLikeTheBoardDoes) {
  StretchEmulatorOptions o;
  o.full_scale_pf = 400.0;
  auto provider = [](std::size_t c, TimeNs) {
    switch (c) {
      case 3: return 500.0;          // beyond full scale
      case 4: return -1.0;           // below the parasitic baseline
      case 5: return std::nan("");   // no oscillation
      default: return 10.0;
    }
  };
  StretchEmulator emu = make(o, provider);
  Decoded d;
  d.push_all(run(emu, 400 * kNsPerMillisecond));  // two full cycles and more
  const auto& st = d.decoder.stats();
  ASSERT_GE(st.measurements, 364u);
  std::map<std::uint16_t, StretchMeasurementStatus> status;
  for (const StretchSample& s : d.samples) {
    status[s.combination] = s.status;
    if (s.combination == 3) {
      EXPECT_DOUBLE_EQ(s.capacitance_pf, 400.0);
    }
    if (s.combination == 4 || s.combination == 5) {
      EXPECT_EQ(s.capacitance_pf, 0.0);
    }
  }
  EXPECT_EQ(status[3], StretchMeasurementStatus::saturated);
  EXPECT_EQ(status[4], StretchMeasurementStatus::below_zero);
  EXPECT_EQ(status[5], StretchMeasurementStatus::no_signal);
  EXPECT_EQ(status[6], StretchMeasurementStatus::ok);
  EXPECT_EQ(st.by_status[1], emu.stats().saturated);
  EXPECT_EQ(st.by_status[2], emu.stats().below_zero);
  EXPECT_EQ(st.by_status[3], emu.stats().no_signal);
  EXPECT_EQ(st.flagged_by_combination[3], st.by_status[1]);
  EXPECT_EQ(st.measurements_flagged(), st.flagged_by_combination[3] + st.flagged_by_combination[4] +
                                           st.flagged_by_combination[5]);
}

// ---------------------------------------------------------------------------
// Faults: each accounted for by the decoder, all reproducible from the seed.

struct FaultRun {
  StretchEmulatorStats emulated;
  StretchStreamStats decoded;
  std::vector<StretchEmulatedReport> reports;
};
FaultRun run_faults(StretchEmulatorFaults f, std::uint64_t seed = 3, TimeNs end = 2 * kNsPerSecond) {
  StretchEmulatorOptions o;
  o.faults = std::move(f);
  o.seed = seed;
  StretchEmulator emu = make(o);
  Decoded d;
  FaultRun r;
  r.reports = run(emu, end);
  d.push_all(r.reports);
  r.emulated = emu.stats();
  r.decoded = d.decoder.stats();
  return r;
}
constexpr std::uint64_t kReportsIn2s = 160;  // 1920 measurements, 12 per report

TEST(StretchEmulatorFaults, CorruptedReportsAreAllCaught) {
  StretchEmulatorFaults f;
  f.corrupt_probability = 0.1;
  const FaultRun r = run_faults(f);
  ASSERT_GT(r.emulated.corrupted, 5u);
  EXPECT_EQ(r.decoded.decode_errors, r.emulated.corrupted);
  EXPECT_EQ(r.decoded.accepted, kReportsIn2s - r.emulated.corrupted);
}

TEST(StretchEmulatorFaults, DroppedReportsAreCountedLostToTheMeasurement) {
  StretchEmulatorFaults f;
  f.drop_probability = 0.1;
  const FaultRun r = run_faults(f);
  ASSERT_GT(r.emulated.dropped, 5u);
  // The last report may be the lost one, which nothing after it reveals.
  EXPECT_LE(r.decoded.lost, 12u * r.emulated.dropped);
  EXPECT_GE(r.decoded.lost + 12u, 12u * r.emulated.dropped);
  EXPECT_EQ(r.decoded.accepted, r.emulated.reports_sent);
}

TEST(StretchEmulatorFaults, DuplicatesAndReorderingAreAccountedFor) {
  StretchEmulatorFaults f;
  f.duplicate_probability = 0.1;
  f.reorder_probability = 0.1;
  const FaultRun r = run_faults(f);
  ASSERT_GT(r.emulated.duplicated, 5u);
  ASSERT_GT(r.emulated.reordered, 5u);
  EXPECT_EQ(r.decoded.duplicates, r.emulated.duplicated);
  EXPECT_EQ(r.decoded.late, r.emulated.reordered);  // each held-back report arrives after its successor
  EXPECT_EQ(r.decoded.accepted + r.decoded.late, kReportsIn2s);
  EXPECT_EQ(r.decoded.lost, 0u);
}

TEST(StretchEmulatorFaults, SaturationAndBoardOverrunsAreCounted) {
  StretchEmulatorFaults f;
  f.saturate_probability = 0.02;
  f.device_overrun_probability = 0.05;
  const FaultRun r = run_faults(f);
  ASSERT_GT(r.emulated.injected_saturations, 10u);
  ASSERT_GT(r.emulated.device_overruns, 3u);
  // Saturated readings in the reports that were sent: every one the decoder saw, flagged.
  std::uint64_t sent_saturated = 0;
  std::uint64_t flagged_overrun = 0;
  for (const auto& rep : r.reports) {
    auto d = decode_stretch_data_report(rep.bytes);
    ASSERT_TRUE(d.ok());
    for (std::size_t i = 0; i < d->count; ++i) sent_saturated += d->measurements[i].status == StretchMeasurementStatus::saturated;
    flagged_overrun += (d->flags & stretch_flags::overrun) != 0;
  }
  EXPECT_EQ(r.decoded.by_status[static_cast<std::size_t>(StretchMeasurementStatus::saturated)], sent_saturated);
  EXPECT_GT(sent_saturated, 0u);
  EXPECT_EQ(r.decoded.device_overruns, flagged_overrun);
  EXPECT_LE(flagged_overrun, r.emulated.device_overruns);  // back-to-back discards flag one report
  EXPECT_LE(r.decoded.lost, 12u * r.emulated.device_overruns);
  EXPECT_GE(r.decoded.lost + 12u, 12u * r.emulated.device_overruns);
}

TEST(StretchEmulatorFaults, EverythingAtOnceIsReproducibleFromTheSeed) {
  StretchEmulatorFaults f;
  f.drop_probability = 0.03;
  f.duplicate_probability = 0.03;
  f.corrupt_probability = 0.03;
  f.reorder_probability = 0.03;
  f.device_overrun_probability = 0.03;
  f.saturate_probability = 0.03;
  f.unplugs.push_back({kNsPerSecond, kNsPerSecond / 4});
  const FaultRun a = run_faults(f, 11);
  const FaultRun b = run_faults(f, 11);
  const FaultRun c = run_faults(f, 12);
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
  StretchEmulatorFaults no_saturation = f;
  no_saturation.saturate_probability = 0.0;
  const FaultRun d = run_faults(no_saturation, 11);
  EXPECT_EQ(d.emulated.dropped, a.emulated.dropped);
  EXPECT_EQ(d.emulated.corrupted, a.emulated.corrupted);
  EXPECT_EQ(d.emulated.device_overruns, a.emulated.device_overruns);
  EXPECT_EQ(d.emulated.injected_saturations, 0u);
}

TEST(StretchEmulator, UnpluggingRebootsTheBoard) {
  StretchEmulatorOptions o;
  o.boot_timestamp_us = 1000;
  o.faults.unplugs.push_back({kNsPerSecond / 2, kNsPerSecond / 4});
  StretchEmulator emu = make(o);
  const auto reports = run(emu, kNsPerSecond);
  EXPECT_EQ(emu.stats().boots, 2u);
  for (const auto& r : reports) {
    EXPECT_FALSE(r.send_ns >= kNsPerSecond / 2 && r.send_ns < 3 * kNsPerSecond / 4) << r.send_ns;
  }
  const auto first_after = std::find_if(reports.begin(), reports.end(),
                                        [](const auto& r) { return r.send_ns >= 3 * kNsPerSecond / 4; });
  ASSERT_NE(first_after, reports.end());
  auto rep = decode_stretch_data_report(first_after->bytes);
  ASSERT_TRUE(rep.ok());
  EXPECT_EQ(rep->sequence, 0u);
  EXPECT_EQ(rep->timestamp_us, 1000u);  // the counter restarted at boot
  EXPECT_TRUE(rep->flags & stretch_flags::stream_start);
  EXPECT_EQ(rep->measurements[0].combination, 0);  // and so did the scan
  Decoded d;
  d.push_all(reports);
  EXPECT_EQ(d.decoder.stats().device_resets, 1u);
  EXPECT_EQ(d.decoder.stats().lost, 0u);
  EXPECT_EQ(d.samples.back().epoch, 1u);
  // 0.75 s of measuring at 960/s: sent, cut short by the power loss, or in the report still filling.
  EXPECT_LT(emu.stats().measurements - d.samples.size() - emu.stats().discarded_partial, 12u);
  EXPECT_NEAR(static_cast<double>(emu.stats().measurements), 0.75 * 960, 2.0);
}

// ---------------------------------------------------------------------------
// Host commands and device info

TEST(StretchEmulator, AnswersCommandsAsTheFirmwareDoes) {
  StretchEmulatorOptions o;
  o.full_scale_pf = 800.0;
  o.parasitic_pf = 12.345;
  o.firmware = {3, 1, 4};
  StretchEmulator emu = make(o);
  std::vector<StretchEmulatedReport> out;
  auto info = [&](TimeNs t) { return *decode_stretch_info_report(emu.info_report(t)); };
  EXPECT_EQ(info(0).last_command_result, StretchCommandResult::none);
  EXPECT_TRUE(info(0).streaming);
  EXPECT_EQ(info(0).top_strips, 13);
  EXPECT_EQ(info(0).bottom_strips, 14);
  EXPECT_EQ(info(0).rate_hz, 960);
  EXPECT_EQ(info(0).full_scale_ff, 800000u);
  EXPECT_EQ(info(0).parasitic_ff, 12345u);
  EXPECT_EQ(info(0).firmware, (std::array<std::uint8_t, 3>{3, 1, 4}));

  StretchCommand c;
  c.op = StretchCommandOp::stop_streaming;
  c.token = 1;
  EXPECT_EQ(emu.handle_command(encode_stretch_command(c), 0), StretchCommandResult::ok);
  emu.advance_to(100 * kNsPerMillisecond, out);
  EXPECT_TRUE(out.empty());
  EXPECT_FALSE(info(0).streaming);
  EXPECT_EQ(info(0).last_command_token, 1);

  c.op = StretchCommandOp::set_rate;
  c.rate_hz = 0;
  c.token = 2;
  EXPECT_EQ(emu.handle_command(encode_stretch_command(c), 0), StretchCommandResult::bad_argument);
  EXPECT_EQ(info(0).last_command_result, StretchCommandResult::bad_argument);
  c.rate_hz = 480;
  EXPECT_EQ(emu.handle_command(encode_stretch_command(c), 0), StretchCommandResult::ok);
  EXPECT_EQ(info(0).rate_hz, 480);

  c.op = StretchCommandOp::start_streaming;
  c.token = 3;
  EXPECT_EQ(emu.handle_command(encode_stretch_command(c), 150 * kNsPerMillisecond), StretchCommandResult::ok);
  emu.advance_to(300 * kNsPerMillisecond, out);
  ASSERT_GE(out.size(), 5u);
  auto first = *decode_stretch_data_report(out[0].bytes);
  EXPECT_EQ(first.sequence, 0u);
  EXPECT_TRUE(first.flags & stretch_flags::stream_start);
  EXPECT_EQ(emu.measurement_time_ns(0), 150 * kNsPerMillisecond);  // the run starts at the command
  EXPECT_EQ(emu.measurement_time_ns(480) - emu.measurement_time_ns(0), kNsPerSecond);  // at the new rate
  EXPECT_FALSE(decode_stretch_data_report(out[1].bytes)->flags & stretch_flags::stream_start);
  // At 480/s, 12 measurements would span 23 ms: the 20 ms age limit cuts reports at 10.
  EXPECT_EQ(decode_stretch_data_report(out[1].bytes)->sequence, 10u);
  EXPECT_EQ(info(0).last_command_token, 3);

  // Bytes that are not a command are answered, not thrown at.
  EXPECT_EQ(emu.handle_command(Bytes{0x30, 0x10, 1}, 0), StretchCommandResult::bad_report);
  const auto start_bytes = encode_stretch_command(c);
  Bytes unknown(start_bytes.begin(), start_bytes.end());
  unknown[2] = 0x77;
  const std::uint16_t crc = hid::crc16_ccitt(std::span(unknown).first(14));
  unknown[14] = static_cast<std::uint8_t>(crc);
  unknown[15] = static_cast<std::uint8_t>(crc >> 8);
  EXPECT_EQ(emu.handle_command(unknown, 0), StretchCommandResult::unknown_command);
  EXPECT_EQ(info(0).last_command_result, StretchCommandResult::unknown_command);
  EXPECT_EQ(emu.handle_command(encode_stretch_data_report({}), 0), StretchCommandResult::bad_report);
}

TEST(StretchEmulator, RefusesBadOptionsWithUsableMessages) {
  auto message = [](StretchEmulatorOptions o, StretchCapacitanceProvider p = synthetic_pf) {
    auto e = StretchEmulator::create(std::move(o), std::move(p));
    return e.ok() ? std::string() : e.error().message;
  };
  StretchEmulatorOptions o;
  o.top_strips = 33;
  EXPECT_NE(message(o).find("top_strips = 33"), std::string::npos) << message(o);
  o = {};
  o.bottom_strips = 0;
  EXPECT_NE(message(o).find("bottom_strips"), std::string::npos);
  o = {};
  o.rate_hz = 4001;
  EXPECT_NE(message(o).find("rate_hz"), std::string::npos);
  o = {};
  o.full_scale_pf = 2000;
  EXPECT_NE(message(o).find("full_scale_pf"), std::string::npos);
  o = {};
  o.clock_error_ppm = 5000;
  EXPECT_NE(message(o).find("clock_error_ppm"), std::string::npos);
  o = {};
  o.measurements_per_report = 13;
  EXPECT_NE(message(o).find("measurements_per_report"), std::string::npos);
  o = {};
  o.faults.saturate_probability = 1.5;
  EXPECT_NE(message(o).find("saturate_probability"), std::string::npos);
  o = {};
  o.faults.unplugs.push_back({0, 0});
  EXPECT_NE(message(o).find("unplugs[0]"), std::string::npos);
  EXPECT_NE(message({}, nullptr).find("provider"), std::string::npos);
  EXPECT_EQ(message({}), "");
}

// ---------------------------------------------------------------------------
// StretchDevice over the fake link, the emulator served in real time.

using proprio::testing_support::wait_until;

StretchDeviceOptions test_options() { return testing_support::quick_link<StretchDeviceOptions>(); }

using BoardRigBase = testing_support::BoardRig<StretchEmulatorServer, StretchDevice, StretchSample>;
struct BoardRig : BoardRigBase {
  explicit BoardRig(StretchEmulatorOptions eo = {}, hid::FakeHidFaults faults = {},
                    StretchDeviceOptions dopts = test_options(), StretchCapacitanceProvider p = synthetic_pf)
      : BoardRigBase(make(eo, std::move(p)), dopts, faults) {}
};

// Value and time of every sample against the provider: the time mapping must
// put each measurement where the board took it (within the link's latency
// floor and scheduling), so the provider at the mapped time gives the value.
void expect_values_and_times(const std::vector<StretchSample>& samples, TimeNs t0) {
  std::vector<double> errors_ms;
  TimeNs previous = 0;
  for (const StretchSample& s : samples) {
    EXPECT_LE(s.time_ns, s.receive_ns);
    EXPECT_GT(s.time_ns, previous);
    previous = s.time_ns;
    // 10 ms of timing error moves the synthetic value by at most 0.09 pF.
    const double truth = synthetic_pf(s.combination, s.time_ns - t0);
    EXPECT_NEAR(s.capacitance_pf, truth, kSyntheticMaxSlopePfPerS * 0.010 + 0.0005) << "combination " << s.combination;
  }
}

TEST(StretchDevice, StreamsDecodedTimestampedMeasurements) {
  BoardRig rig;
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  ASSERT_TRUE(rig.drain_until([&] { return rig.samples.size() >= 400; })) << rig.samples.size();
  ASSERT_TRUE(rig.quiesce());
  rig.device.stop();
  const StretchDeviceStats st = rig.device.stats();
  const TimeNs t0 = rig.server.time_zero_ns();
  ASSERT_EQ(rig.samples.size(), st.samples_delivered);
  // Measurement n is combination n mod 182, taken when the emulator says it was.
  std::vector<double> errors_ms;
  rig.server.with_emulator([&](const StretchEmulator& emu) {
    for (const StretchSample& s : rig.samples) {
      EXPECT_EQ(s.combination, s.sequence % 182);
      EXPECT_EQ(s.epoch, 0u);
      const TimeNs truth_ns = t0 + emu.measurement_time_ns(static_cast<std::uint64_t>(s.sequence));
      EXPECT_NEAR(s.capacitance_pf, synthetic_pf(s.combination, truth_ns - t0), 0.0005 + 1e-9);
      errors_ms.push_back(static_cast<double>(s.time_ns - truth_ns) * 1e-6);
    }
    return 0;
  });
  // Mapped times sit on the board's instants plus the link's latency floor
  // (0.2 ms here) and the reader's wake-up: never before the measurement by
  // more than the early skew estimate allows, and not a report's length (11.5 ms) late.
  std::sort(errors_ms.begin(), errors_ms.end());
  EXPECT_GT(errors_ms.front(), -1.0);
  EXPECT_LT(errors_ms.back(), 10.0);
  EXPECT_LT(errors_ms[errors_ms.size() / 2], 3.0);
  expect_values_and_times(rig.samples, t0);
  EXPECT_EQ(st.state, StretchLinkState::stopped);
  EXPECT_EQ(st.stream.lost, 0u);
  EXPECT_EQ(st.stream.decode_errors, 0u);
  EXPECT_EQ(st.samples_rejected, 0u);
  EXPECT_EQ(st.connects, 1u);
  EXPECT_TRUE(st.clock_locked);
  EXPECT_TRUE(st.have_info);
  EXPECT_EQ(st.info.combination_count(), 182u);
  EXPECT_EQ(st.info.rate_hz, 960);
  EXPECT_EQ(rig.state_log(), (std::vector<StretchLinkState>{StretchLinkState::connecting, StretchLinkState::streaming,
                                                            StretchLinkState::stopped}));
  EXPECT_TRUE(rig.link->writes().empty());  // a streaming board is left alone
}

TEST(StretchDevice, ResumesAfterUnplugAndReplug) {
  StretchEmulatorOptions eo;
  // The board loses power 0.2 s in for 0.15 s and boots again: counter and sequence restart.
  eo.faults.unplugs.push_back({200 * kNsPerMillisecond, 150 * kNsPerMillisecond});
  eo.boot_timestamp_us = 4'000'000'000u;
  BoardRig rig(eo);
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  rig.link->schedule_unplug(rig.server.time_zero_ns() + 200 * kNsPerMillisecond, 150 * kNsPerMillisecond);
  const bool done = rig.drain_until([&] { return !rig.samples.empty() && rig.samples.back().epoch == 1 &&
                                                 rig.samples.back().sequence >= 200; });
  ASSERT_TRUE(done) << rig.samples.size() << " samples";
  ASSERT_TRUE(rig.quiesce());
  rig.device.stop();
  const StretchDeviceStats st = rig.device.stats();
  std::size_t before = 0, after = 0;
  const TimeNs t0 = rig.server.time_zero_ns();
  for (const StretchSample& s : rig.samples) {
    const TimeNs t = s.time_ns - t0;
    EXPECT_FALSE(t > 210 * kNsPerMillisecond && t < 340 * kNsPerMillisecond) << ns_to_seconds(t);
    (s.epoch == 0 ? before : after)++;
    EXPECT_EQ(s.combination, s.sequence % 182);  // the rebooted board scans from combination 0 again
  }
  EXPECT_NEAR(static_cast<double>(before), 0.2 * 960, 15.0);
  EXPECT_GE(after, 200u);
  expect_values_and_times(rig.samples, t0);
  EXPECT_GE(st.disconnects, 1u);
  EXPECT_GE(st.connects, 2u);
  EXPECT_GE(st.open_failures, 1u);
  EXPECT_EQ(st.stream.device_resets, 1u);
  EXPECT_EQ(st.stream.lost, 0u);
  EXPECT_GE(st.clock_relocks, 1u);
  const auto log = rig.state_log();
  const auto pos = std::find(log.begin(), log.end(), StretchLinkState::disconnected);
  ASSERT_NE(pos, log.end());
  EXPECT_NE(std::find(pos, log.end(), StretchLinkState::streaming), log.end());
}

TEST(StretchDevice, CorruptedAndLostReportsAreSkippedAndAccountedFor) {
  hid::FakeHidFaults faults;
  faults.corrupt_probability = 0.08;
  faults.drop_probability = 0.08;
  faults.seed = 4;
  BoardRig rig({}, faults);
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  ASSERT_TRUE(rig.drain_until([&] { return rig.device.stats().reports_read >= 60; }));
  ASSERT_TRUE(rig.quiesce());
  const StretchDeviceStats st = rig.device.stats();
  rig.device.stop();
  const auto link = rig.link->stats();
  ASSERT_GT(link.corrupted, 0u);
  ASSERT_GT(link.dropped, 0u);
  EXPECT_EQ(st.stream.decode_errors, link.corrupted);  // one flipped bit never gets past the CRC
  // Every report the board sent was either read or lost on the way.
  EXPECT_EQ(st.stream.accepted + st.stream.decode_errors, link.pushed - link.dropped);
  // Their measurements are lost, but for the last report, which nothing after it reveals.
  EXPECT_LE(st.stream.lost, 12u * (link.dropped + link.corrupted));
  EXPECT_GE(st.stream.lost + 12u, 12u * (link.dropped + link.corrupted));
  EXPECT_EQ(st.stream.lost % 12, 0u);
  expect_values_and_times(rig.samples, rig.server.time_zero_ns());
  EXPECT_EQ(st.samples_delivered, rig.samples.size());
}

TEST(StretchDevice, SendsStartWhenTheBoardStaysSilentAndQueuedCommandsReachIt) {
  StretchEmulatorOptions eo;
  eo.stream_on_boot = false;  // e.g. another program stopped it
  StretchDeviceOptions o = test_options();
  o.restart_after_silence_ns = 100 * kNsPerMillisecond;
  BoardRig rig(eo, {}, o);
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  ASSERT_TRUE(rig.drain_until([&] { return rig.samples.size() >= 100; }));
  auto writes = rig.link->writes();
  ASSERT_FALSE(writes.empty());
  auto cmd = decode_stretch_command(writes.front());
  ASSERT_TRUE(cmd.ok()) << cmd.error().message;
  EXPECT_EQ(cmd->op, StretchCommandOp::start_streaming);
  EXPECT_GE(rig.device.stats().restart_commands, 1u);

  StretchCommand c;
  c.op = StretchCommandOp::set_rate;
  c.rate_hz = 480;
  c.token = 9;
  rig.device.send_command(c);
  ASSERT_TRUE(rig.drain_until([&] {
    return std::count_if(rig.samples.begin(), rig.samples.end(), [](const StretchSample& s) { return s.epoch == 1; }) >=
           48;
  }));
  rig.device.stop();
  writes = rig.link->writes();
  auto back = decode_stretch_command(writes.back());
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(*back, c);
  EXPECT_EQ(rig.server.with_emulator([](const StretchEmulator& e) { return e.rate_hz(); }), 480);
  // SET_RATE restarted the stream, and the host measured the new period.
  EXPECT_NEAR(rig.device.stats().stream.measurement_period_us, 1e6 / 480.0, 1.0);
}

TEST(StretchDevice, FlaggedMeasurementsAreRejectedAndCountedUnlessAsked) {
  // Combination 5 never oscillates; combination 7 reads beyond full scale.
  auto provider = [](std::size_t c, TimeNs t) {
    if (c == 5) return std::nan("");
    if (c == 7) return 5000.0;
    return synthetic_pf(c, t);
  };
  for (bool deliver_flagged : {false, true}) {
    SCOPED_TRACE(deliver_flagged ? "deliver_flagged" : "default");
    StretchDeviceOptions o = test_options();
    o.deliver_flagged = deliver_flagged;
    BoardRig rig({}, {}, o, provider);
    ASSERT_TRUE(rig.device.start().ok());
    rig.server.start();
    ASSERT_TRUE(rig.drain_until([&] { return rig.device.stats().stream.measurements >= 400; }));
    ASSERT_TRUE(rig.quiesce());
    const StretchDeviceStats st = rig.device.stats();
    rig.device.stop();
    const std::uint64_t flagged = st.stream.flagged_by_combination[5] + st.stream.flagged_by_combination[7];
    EXPECT_GE(flagged, 4u);
    EXPECT_EQ(st.stream.measurements_flagged(), flagged);
    EXPECT_EQ(st.stream.by_status[static_cast<std::size_t>(StretchMeasurementStatus::no_signal)],
              st.stream.flagged_by_combination[5]);
    std::size_t delivered_flagged = 0;
    for (const StretchSample& s : rig.samples) {
      delivered_flagged += s.status != StretchMeasurementStatus::ok;
      EXPECT_EQ(s.status != StretchMeasurementStatus::ok, s.combination == 5 || s.combination == 7);
    }
    EXPECT_EQ(rig.samples.size(), st.stream.measurements - (deliver_flagged ? 0 : flagged));
    EXPECT_EQ(delivered_flagged, deliver_flagged ? flagged : 0u);
    EXPECT_EQ(st.samples_rejected, deliver_flagged ? 0u : flagged);
  }
}

TEST(StretchDevice, ABoardThatIsNotTheLayoutsIsRefusedWithAReason) {
  StretchDeviceOptions o = test_options();
  o.stream.expected_top_strips = 12;
  o.stream.expected_bottom_strips = 12;
  BoardRig rig({}, {}, o);  // the board has 13 x 14
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  ASSERT_TRUE(wait_until([&] { return rig.device.stats().stream.wrong_layout >= 5; }));
  rig.device.stop();
  const StretchDeviceStats st = rig.device.stats();
  EXPECT_EQ(st.stream.accepted, 0u);
  EXPECT_EQ(st.samples_delivered, 0u);
  StretchSample s;
  EXPECT_FALSE(rig.device.pop(s));
  std::lock_guard lock(rig.states_mutex);
  ASSERT_GE(rig.details.size(), 2u);
  EXPECT_NE(rig.details[1].find("WRONG LAYOUT"), std::string::npos) << rig.details[1];
  EXPECT_NE(rig.details[1].find("13 x 14 strips"), std::string::npos) << rig.details[1];
}

TEST(StretchDevice, ASlowConsumerLosesMeasurementsAtTheRingNotTheReader) {
  StretchDeviceOptions o = test_options();
  o.queue_capacity = 16;
  BoardRig rig({}, {}, o);
  ASSERT_TRUE(rig.device.start().ok());
  rig.server.start();
  ASSERT_TRUE(wait_until([&] { return rig.device.stats().stream.accepted >= 10; }));  // nobody pops meanwhile
  rig.server.stop();
  rig.link->flush();
  ASSERT_TRUE(wait_until([&] { return rig.link->pending() == 0 && rig.device.stats().reports_read == rig.link->stats().delivered; }));
  const StretchDeviceStats st = rig.device.stats();
  EXPECT_EQ(st.samples_delivered, 16u);
  EXPECT_EQ(st.queue_overruns, st.stream.measurements - 16u);
  StretchSample s;
  std::int64_t popped = 0;
  while (rig.device.pop(s)) EXPECT_EQ(s.sequence, popped++);  // the oldest are kept, in order
  EXPECT_EQ(popped, 16);
  rig.device.stop();
}

// ---------------------------------------------------------------------------
// Fuzz seed corpus (tests/fuzz/corpus/stretch_protocol)

fs::path corpus_dir() { return testing_support::fuzz_corpus_dir("stretch_protocol"); }
using proprio::testing_support::read_bytes;
using proprio::testing_support::write_bytes;
Bytes concat(const std::vector<StretchEmulatedReport>& reports) { return testing_support::concat_reports(reports); }

// PROPRIO_REGEN_CORPUS=1 ctest -R StretchSeedCorpus rewrites the seeds after a
// protocol change; commit the result.
TEST(StretchSeedCorpus, Regenerate) {
  if (!testing_support::regenerate_corpus_requested())
    GTEST_SKIP() << "set PROPRIO_REGEN_CORPUS=1 to rewrite the seeds";
  const fs::path dir = corpus_dir();
  fs::create_directories(dir);
  fs::remove(dir / "placeholder");

  StretchEmulator plain = make();
  const auto plain_reports = run(plain, 120 * kNsPerMillisecond);
  write_bytes(dir / "data_report.bin", Bytes(plain_reports[0].bytes.begin(), plain_reports[0].bytes.end()));
  write_bytes(dir / "stream_13x14_120ms.bin", concat(plain_reports));

  StretchEmulatorOptions wrap;
  wrap.boot_timestamp_us = 0xFFFFFFFFu - 25'000u;
  wrap.clock_error_ppm = -90;
  wrap.faults.unplugs.push_back({60 * kNsPerMillisecond, 20 * kNsPerMillisecond});
  StretchEmulator wrapping = make(wrap);
  write_bytes(dir / "stream_wrap_restart.bin", concat(run(wrapping, 110 * kNsPerMillisecond)));

  StretchEmulatorOptions slow;
  slow.top_strips = 3;
  slow.bottom_strips = 2;
  slow.rate_hz = 200;
  slow.full_scale_pf = 30.0;  // some readings saturate
  StretchEmulator small = make(slow);
  write_bytes(dir / "stream_3x2_short_reports.bin", concat(run(small, 150 * kNsPerMillisecond)));

  StretchEmulatorOptions faulty;
  faulty.seed = 2;
  faulty.faults.corrupt_probability = 0.2;
  faulty.faults.duplicate_probability = 0.2;
  faulty.faults.reorder_probability = 0.2;
  faulty.faults.device_overrun_probability = 0.2;
  faulty.faults.saturate_probability = 0.1;
  StretchEmulator faults = make(faulty);
  write_bytes(dir / "stream_faults.bin", concat(run(faults, 120 * kNsPerMillisecond)));

  const auto info = make().info_report(123'456'000);
  write_bytes(dir / "info_report.bin", Bytes(info.begin(), info.end()));

  // Protocol 1.1: an array board that measures the single strips too (5 x 4:
  // 20 pairs and 9 single strips), and its info report.
  StretchEmulatorOptions array;
  array.top_strips = 5;
  array.bottom_strips = 4;
  array.single_strips = true;
  StretchEmulator array_board = make(array);
  const auto array_reports = run(array_board, 120 * kNsPerMillisecond);
  write_bytes(dir / "stream_5x4_single_strips.bin", concat(array_reports));
  const auto array_info = array_board.info_report(50'000'000);
  write_bytes(dir / "info_report_single_strips.bin", Bytes(array_info.begin(), array_info.end()));
  // A 1.0 report with the bit 1.1 calls single_strips set: reserved then, so it means nothing.
  Bytes v10(plain_reports[1].bytes.begin(), plain_reports[1].bytes.end());
  v10[1] = 0x10;
  v10[10] |= stretch_flags::single_strips;
  const std::uint16_t crc = hid::crc16_ccitt(std::span(v10).first(v10.size() - 2));
  v10[v10.size() - 2] = static_cast<std::uint8_t>(crc);
  v10[v10.size() - 1] = static_cast<std::uint8_t>(crc >> 8);
  write_bytes(dir / "data_report_v10_reserved_bit.bin", v10);
  StretchCommand c;
  c.op = StretchCommandOp::set_rate;
  c.rate_hz = 480;
  c.token = 5;
  const auto cb = encode_stretch_command(c);
  write_bytes(dir / "command_set_rate.bin", Bytes(cb.begin(), cb.end()));
}

TEST(StretchSeedCorpus, EverySeedStillDecodes) {
  const fs::path dir = corpus_dir();
  ASSERT_TRUE(fs::is_directory(dir)) << dir << " is missing; run with PROPRIO_REGEN_CORPUS=1";
  const std::size_t seeds = testing_support::check_seed_corpus(
      dir, [](const Bytes& b) { return decode_stretch_info_report(b); },
      [](const Bytes& b) { return decode_stretch_command(b); },
      [](const Bytes& b, bool faulty) {
        ASSERT_EQ(b.size() % kStretchDataReportSize, 0u);
        ASSERT_GT(b.size(), 0u);
        const std::size_t bad = testing_support::count_refused(
            b, kStretchDataReportSize, [](std::span<const std::uint8_t> r) { return decode_stretch_data_report(r); });
        if (faulty) {
          EXPECT_GT(bad, 0u);
        } else {
          EXPECT_EQ(bad, 0u);
        }
      });
  EXPECT_GE(seeds, 10u);
}

}  // namespace
}  // namespace proprio::devices::stretch_emulator_test
