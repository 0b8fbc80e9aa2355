// The glove's HID wire protocol (codec) and the stream decoder that tracks
// sequence numbers, timestamps and flagged samples.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/imu_glove_board/imu_glove_protocol.hpp"
#include "proprio/imu_glove_board/imu_glove_stream.hpp"
#include "support/devices.hpp"

namespace proprio::devices {
namespace {

using Bytes = std::vector<std::uint8_t>;
using proprio::testing_support::kG;
constexpr double kDeg = 0.017453292519943295;

using proprio::testing_support::bytes_of;

ImuGloveDataReport random_report(Rng& rng) {
  ImuGloveDataReport r;
  r.imu_total = static_cast<std::uint8_t>(1 + rng.below(kImuGloveMaxImus));
  r.first_imu = static_cast<std::uint8_t>(kImuGloveImusPerReport * rng.below((r.imu_total + 3) / 4));
  r.sequence = static_cast<std::uint16_t>(rng.next_u64());
  r.timestamp_us = static_cast<std::uint32_t>(rng.next_u64());
  r.flags = static_cast<std::uint8_t>(rng.below(4));
  r.accel_range = static_cast<AccelRange>(rng.below(4));
  r.gyro_range = static_cast<GyroRange>(rng.below(4));
  for (std::size_t i = 0; i < r.block_count(); ++i) {
    auto& imu = r.imus[i];
    imu.status = static_cast<std::uint8_t>(rng.below(16));
    for (std::size_t a = 0; a < 3; ++a) {
      imu.accel[a] = static_cast<std::int16_t>(static_cast<std::uint16_t>(rng.next_u64()));
      imu.gyro[a] = static_cast<std::int16_t>(static_cast<std::uint16_t>(rng.next_u64()));
    }
  }
  return r;
}

// ---------------------------------------------------------------------------
// CRC and layout

TEST(GloveCrc, MatchesTheCcittFalseCheckValue) {
  const char* text = "123456789";
  const auto* p = reinterpret_cast<const std::uint8_t*>(text);
  EXPECT_EQ(hid::crc16_ccitt({p, 9}), 0x29B1);
  // Chaining gives the same as one call.
  EXPECT_EQ(hid::crc16_ccitt({p + 4, 5}, hid::crc16_ccitt({p, 4})), 0x29B1);
  EXPECT_EQ(hid::crc16_ccitt({}), 0xFFFF);
}

TEST(GloveProtocol, DataReportBytesFollowTheDocumentedLayout) {
  ImuGloveDataReport r;
  r.first_imu = 4;
  r.imu_total = 7;
  r.sequence = 0x1234;
  r.timestamp_us = 0xDEADBEEF;
  r.flags = data_flags::stream_start;
  r.accel_range = AccelRange::g8;     // code 2
  r.gyro_range = GyroRange::dps1000;  // code 2
  r.imus[0] = {imu_status::gyro_saturated, {-2, 1, 0x7FFF}, {-32768, 256, 3}};
  r.imus[2] = {imu_status::stale | imu_status::sensor_error, {5, 6, 7}, {8, 9, 10}};
  const auto b = encode_data_report(r);
  ASSERT_EQ(b.size(), 64u);
  EXPECT_EQ(b[0], 0x01);
  EXPECT_EQ(b[1], 0x10);  // version 1.0
  EXPECT_EQ(b[2], 4);
  EXPECT_EQ(b[3], 7);
  EXPECT_EQ(b[4], 0x34);  // little-endian sequence
  EXPECT_EQ(b[5], 0x12);
  EXPECT_EQ(b[6], 0xEF);  // little-endian timestamp
  EXPECT_EQ(b[7], 0xBE);
  EXPECT_EQ(b[8], 0xAD);
  EXPECT_EQ(b[9], 0xDE);
  EXPECT_EQ(b[10], 0x01);
  EXPECT_EQ(b[11], 2 | 2 << 2);
  // Status nibbles: block 0 in bits 0-3, block 2 in bits 8-11.
  EXPECT_EQ(b[12], 0x04);
  EXPECT_EQ(b[13], 0x09);
  // Block 0: ax = -2, ay = 1, az = 32767, gx = -32768, gy = 256, gz = 3.
  const std::uint8_t block0[12] = {0xFE, 0xFF, 0x01, 0x00, 0xFF, 0x7F, 0x00, 0x80, 0x00, 0x01, 0x03, 0x00};
  EXPECT_EQ(0, std::memcmp(&b[14], block0, 12));
  // Block 3 does not exist (IMUs 4-6 only): zero.
  for (std::size_t i = 50; i < 62; ++i) EXPECT_EQ(b[i], 0) << i;
  const std::uint16_t crc = hid::crc16_ccitt(std::span(b).first(62));
  EXPECT_EQ(b[62], crc & 0xFF);
  EXPECT_EQ(b[63], crc >> 8);
}

TEST(GloveProtocol, DataReportRoundTripsBitExact) {
  Rng rng(42);
  for (int n = 0; n < 2000; ++n) {
    const ImuGloveDataReport r = random_report(rng);
    const auto bytes = encode_data_report(r);
    ImuGloveDataReport back;
    ASSERT_TRUE(decode_data_report(bytes, back).ok()) << describe(decode_data_report(bytes, back));
    ASSERT_EQ(back, r);
    ASSERT_EQ(encode_data_report(back), bytes);
  }
}

TEST(GloveProtocol, InfoAndCommandReportsRoundTrip) {
  ImuGloveDeviceInfo info;
  info.firmware = {2, 7, 13};
  info.imu_count = 7;
  info.rate_hz = 250;
  info.accel_range = AccelRange::g4;
  info.gyro_range = GyroRange::dps500;
  info.streaming = true;
  info.last_command_token = 0xA5;
  info.last_command_result = ImuGloveCommandResult::bad_argument;
  info.timestamp_us = 0xFFFFFFF0u;
  const auto ib = encode_info_report(info);
  ASSERT_EQ(ib.size(), 32u);
  EXPECT_EQ(ib[0], 0x02);
  auto info_back = decode_info_report(ib);
  ASSERT_TRUE(info_back.ok()) << info_back.error().message;
  EXPECT_EQ(*info_back, info);

  for (auto op : {ImuGloveCommandOp::start_streaming, ImuGloveCommandOp::stop_streaming, ImuGloveCommandOp::set_rate,
                  ImuGloveCommandOp::set_ranges}) {
    ImuGloveCommand c;
    c.op = op;
    c.token = 77;
    c.rate_hz = 200;
    c.accel_range = AccelRange::g2;
    c.gyro_range = GyroRange::dps250;
    const auto cb = encode_command(c);
    ASSERT_EQ(cb.size(), 16u);
    EXPECT_EQ(cb[0], 0x10);
    auto back = decode_command(cb);
    ASSERT_TRUE(back.ok()) << back.error().message;
    EXPECT_EQ(*back, c);
  }
}

// ---------------------------------------------------------------------------
// Every error path, with the numbers in the status and a message that says what.

ImuGloveDataReport valid_report() {
  ImuGloveDataReport r;
  r.imu_total = 7;
  r.sequence = 9;
  r.timestamp_us = 1000;
  return r;
}

TEST(GloveProtocolErrors, EmptyAndWrongLengths) {
  ImuGloveDataReport out;
  auto s = decode_data_report({}, out);
  EXPECT_EQ(s.code, ImuGloveDecodeErrc::empty);
  const auto good = encode_data_report(valid_report());
  for (std::size_t len : {1u, 63u}) {
    s = decode_data_report(std::span(good).first(len), out);
    EXPECT_EQ(s.code, ImuGloveDecodeErrc::bad_length) << len;
    EXPECT_EQ(s.expected, 64u);
    EXPECT_EQ(s.actual, len);
  }
  Bytes longer = bytes_of(good);
  longer.push_back(0);
  s = decode_data_report(longer, out);
  EXPECT_EQ(s.code, ImuGloveDecodeErrc::bad_length);
  EXPECT_EQ(s.actual, 65u);
  EXPECT_NE(describe(s).find("65 bytes"), std::string::npos) << describe(s);
}

TEST(GloveProtocolErrors, UnknownReportIdAndVersion) {
  ImuGloveDataReport out;
  Bytes b = bytes_of(encode_data_report(valid_report()));
  b[0] = 0x7E;
  auto s = decode_data_report(b, out);
  EXPECT_EQ(s.code, ImuGloveDecodeErrc::unknown_report_id);
  EXPECT_EQ(s.actual, 0x7Eu);

  ImuGloveDataReport v2 = valid_report();
  v2.version = 0x20;  // protocol 2.0, with a valid CRC
  s = decode_data_report(encode_data_report(v2), out);
  EXPECT_EQ(s.code, ImuGloveDecodeErrc::unsupported_version);
  EXPECT_EQ(s.expected, 1u);
  EXPECT_EQ(s.actual, 0x20u);
  auto result = decode_data_report(encode_data_report(v2));
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, Errc::unsupported);
  EXPECT_NE(result.error().message.find("version 2.0"), std::string::npos) << result.error().message;

  // A newer minor of the same major decodes.
  ImuGloveDataReport v13 = valid_report();
  v13.version = 0x13;
  EXPECT_TRUE(decode_data_report(encode_data_report(v13), out).ok());
  EXPECT_EQ(out.version, 0x13);
}

TEST(GloveProtocolErrors, CrcMismatchCarriesBothValues) {
  const auto good = encode_data_report(valid_report());
  Bytes b = bytes_of(good);
  b[20] ^= 0x10;
  ImuGloveDataReport out;
  const auto s = decode_data_report(b, out);
  ASSERT_EQ(s.code, ImuGloveDecodeErrc::crc_mismatch);
  const std::uint16_t carried = static_cast<std::uint16_t>(b[62] | b[63] << 8);
  EXPECT_EQ(s.expected, carried);
  EXPECT_EQ(s.actual, hid::crc16_ccitt(std::span(b).first(62)));
  EXPECT_NE(s.expected, s.actual);
  auto result = decode_data_report(b);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, Errc::parse_error);
  char carried_hex[8], computed_hex[8];
  std::snprintf(carried_hex, sizeof carried_hex, "0x%04x", s.expected);
  std::snprintf(computed_hex, sizeof computed_hex, "0x%04x", s.actual);
  EXPECT_NE(result.error().message.find(carried_hex), std::string::npos) << result.error().message;
  EXPECT_NE(result.error().message.find(computed_hex), std::string::npos) << result.error().message;
}

TEST(GloveProtocolErrors, EverySingleBitFlipIsDetected) {
  const auto good = encode_data_report(valid_report());
  ImuGloveDataReport out;
  for (std::size_t byte = 0; byte < good.size(); ++byte) {
    for (int bit = 0; bit < 8; ++bit) {
      Bytes b = bytes_of(good);
      b[byte] ^= static_cast<std::uint8_t>(1u << bit);
      EXPECT_FALSE(decode_data_report(b, out).ok()) << "byte " << byte << " bit " << bit;
    }
  }
}

TEST(GloveProtocolErrors, BadImuCountAndFirstImu) {
  ImuGloveDataReport out;
  for (int total : {0, 17, 255}) {
    ImuGloveDataReport r = valid_report();
    r.imu_total = static_cast<std::uint8_t>(total);
    const auto s = decode_data_report(encode_data_report(r), out);
    EXPECT_EQ(s.code, ImuGloveDecodeErrc::bad_imu_count) << total;
    EXPECT_EQ(s.actual, static_cast<std::uint32_t>(total));
  }
  for (int first : {1, 3, 8, 12}) {
    ImuGloveDataReport r = valid_report();  // 7 IMUs: first must be 0 or 4
    r.first_imu = static_cast<std::uint8_t>(first);
    const auto s = decode_data_report(encode_data_report(r), out);
    EXPECT_EQ(s.code, ImuGloveDecodeErrc::bad_first_imu) << first;
    EXPECT_EQ(s.expected, 7u);
    EXPECT_EQ(s.actual, static_cast<std::uint32_t>(first));
  }
}

TEST(GloveProtocolErrors, InfoAndCommandChecks) {
  ImuGloveDeviceInfo info;
  info.imu_count = 7;
  info.rate_hz = 0;
  auto r = decode_info_report(encode_info_report(info));
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("bad rate 0 Hz"), std::string::npos) << r.error().message;
  info.rate_hz = kImuGloveMaxRateHz + 1;
  EXPECT_FALSE(decode_info_report(encode_info_report(info)).ok());
  info.rate_hz = 100;
  info.imu_count = 0;
  ImuGloveDeviceInfo out;
  EXPECT_EQ(decode_info_report(encode_info_report(info), out).code, ImuGloveDecodeErrc::bad_imu_count);

  Bytes cmd = bytes_of(encode_command({}));
  cmd[2] = 0x55;  // unknown opcode, CRC fixed up
  const std::uint16_t crc = hid::crc16_ccitt(std::span(cmd).first(14));
  cmd[14] = static_cast<std::uint8_t>(crc);
  cmd[15] = static_cast<std::uint8_t>(crc >> 8);
  ImuGloveCommand c;
  const auto s = decode_command(cmd, c);
  EXPECT_EQ(s.code, ImuGloveDecodeErrc::unknown_command);
  EXPECT_EQ(s.actual, 0x55u);
  // A data report handed to the command decoder is the wrong report, not garbage.
  EXPECT_EQ(decode_command(encode_data_report(valid_report()), c).code, ImuGloveDecodeErrc::unknown_report_id);
}

TEST(GloveProtocolErrors, EveryCodeHasANameAndAMessage) {
  for (std::size_t i = 0; i < kImuGloveDecodeErrcCount; ++i) {
    const ImuGloveDecodeStatus s{static_cast<ImuGloveDecodeErrc>(i), 1, 2};
    EXPECT_STRNE(to_string(s.code), "unknown") << i;
    EXPECT_FALSE(describe(s).empty());
  }
}

// ---------------------------------------------------------------------------
// Scales and quantisation

TEST(GloveScales, MatchTheDatasheetSensitivities) {
  ImuGloveImuRaw raw;
  raw.accel = {2048, -2048, 0};
  raw.gyro = {164, -164, 0};
  const ImuSample s = to_imu_sample(raw, 5, AccelRange::g16, GyroRange::dps2000);
  EXPECT_EQ(s.sensor_id, 5);
  EXPECT_DOUBLE_EQ(s.accel_mps2.x(), kG);       // 2048 LSB/g at ±16 g
  EXPECT_DOUBLE_EQ(s.accel_mps2.y(), -kG);
  EXPECT_NEAR(s.gyro_radps.x(), 10.0 * kDeg, 1e-15);  // 16.4 LSB/(°/s) at ±2000 °/s
  EXPECT_FALSE(s.mag_T.has_value());

  const double accel_per_g[4] = {16384, 8192, 4096, 2048};
  const double gyro_per_dps[4] = {131, 65.5, 32.8, 16.4};
  for (int code = 0; code < 4; ++code) {
    EXPECT_DOUBLE_EQ(accel_counts_per_mps2(static_cast<AccelRange>(code)), accel_per_g[code] / kG);
    EXPECT_DOUBLE_EQ(gyro_counts_per_radps(static_cast<GyroRange>(code)), gyro_per_dps[code] / kDeg);
    EXPECT_DOUBLE_EQ(accel_full_scale_mps2(static_cast<AccelRange>(code)), (2 << code) * kG);
  }
  EXPECT_DOUBLE_EQ(gyro_full_scale_radps(GyroRange::dps2000), 2000 * kDeg);
}

TEST(GloveScales, QuantisationErrorIsAtMostHalfACount) {
  Rng rng(7);
  for (int code = 0; code < 4; ++code) {
    const auto ar = static_cast<AccelRange>(code);
    const auto gr = static_cast<GyroRange>(code);
    const double half_a = 0.5 / accel_counts_per_mps2(ar);
    const double half_g = 0.5 / gyro_counts_per_radps(gr);
    double worst_a = 0, worst_g = 0;
    for (int n = 0; n < 5000; ++n) {
      ImuSample in;
      // Inside the representable range (the gyro's 32767 counts are a little below its nominal full scale).
      const double amax = 32767.0 / accel_counts_per_mps2(ar), gmax = 32767.0 / gyro_counts_per_radps(gr);
      in.accel_mps2 = Vec3(rng.uniform(-amax, amax), rng.uniform(-amax, amax), rng.uniform(-amax, amax)) * 0.999;
      in.gyro_radps = Vec3(rng.uniform(-gmax, gmax), rng.uniform(-gmax, gmax), rng.uniform(-gmax, gmax)) * 0.999;
      const ImuGloveImuRaw raw = quantise_imu(in, ar, gr);
      ASSERT_EQ(raw.status, 0);
      const ImuSample out = to_imu_sample(raw, 0, ar, gr);
      worst_a = std::max(worst_a, (out.accel_mps2 - in.accel_mps2).cwiseAbs().maxCoeff());
      worst_g = std::max(worst_g, (out.gyro_radps - in.gyro_radps).cwiseAbs().maxCoeff());
    }
    EXPECT_LE(worst_a, half_a * (1 + 1e-9)) << code;
    EXPECT_LE(worst_g, half_g * (1 + 1e-9)) << code;
    // ... and the bound is tight (the test would notice a coarser scale).
    EXPECT_GT(worst_a, 0.9 * half_a) << code;
    EXPECT_GT(worst_g, 0.9 * half_g) << code;
  }
  // At ±16 g / ±2000 °/s that is 2.4 mm/s² and 0.53 mrad/s.
  EXPECT_NEAR(0.5 / accel_counts_per_mps2(AccelRange::g16), 2.394e-3, 1e-6);
  EXPECT_NEAR(0.5 / gyro_counts_per_radps(GyroRange::dps2000), 5.32e-4, 1e-6);
}

TEST(GloveScales, SaturationAndNonFiniteInputsAreFlagged) {
  ImuSample in;
  in.accel_mps2 = Vec3(16 * kG, 0, 0);  // exactly full scale: 32768 counts do not fit
  in.gyro_radps = Vec3(0, -2500 * kDeg, 0);
  ImuGloveImuRaw raw = quantise_imu(in, AccelRange::g16, GyroRange::dps2000);
  EXPECT_EQ(raw.accel[0], 32767);
  EXPECT_EQ(raw.gyro[1], -32768);
  EXPECT_EQ(raw.status, imu_status::accel_saturated | imu_status::gyro_saturated);

  in.accel_mps2 = Vec3(1e300, 0, 0);  // far beyond int16: clamped, not undefined
  in.gyro_radps = Vec3::Zero();
  raw = quantise_imu(in, AccelRange::g2, GyroRange::dps250);
  EXPECT_EQ(raw.accel[0], 32767);
  EXPECT_EQ(raw.status, imu_status::accel_saturated);

  for (double bad : {std::nan(""), double{INFINITY}, -double{INFINITY}}) {
    in.accel_mps2 = Vec3(0, 0, 0);
    in.gyro_radps = Vec3(0, bad, 0);
    raw = quantise_imu(in, AccelRange::g16, GyroRange::dps2000);
    EXPECT_EQ(raw.status, imu_status::sensor_error);
    EXPECT_EQ(raw.accel, (std::array<std::int16_t, 3>{0, 0, 0}));
    EXPECT_EQ(raw.gyro, (std::array<std::int16_t, 3>{0, 0, 0}));
  }

  // The host flags a rail value even when the firmware did not.
  ImuGloveImuRaw quiet;
  quiet.gyro = {0, 0, -32768};
  EXPECT_EQ(host_status(quiet), imu_status::gyro_saturated);
  quiet.gyro = {0, 0, -32767};
  EXPECT_EQ(host_status(quiet), 0);
  quiet.accel = {32767, 0, 0};
  quiet.status = imu_status::stale;
  EXPECT_EQ(host_status(quiet), imu_status::stale | imu_status::accel_saturated);
}

// ---------------------------------------------------------------------------
// Stream decoder

struct Tick {
  std::uint16_t seq;
  std::uint32_t ts;
  std::uint8_t flags = 0;
};

// The reports of one tick of a 7-IMU glove: IMU i reads accel (i, seq, 0) counts.
std::vector<Bytes> tick_reports(Tick t, std::uint8_t imu_total = 7) {
  std::vector<Bytes> out;
  for (std::uint8_t first = 0; first < imu_total; first = static_cast<std::uint8_t>(first + 4)) {
    ImuGloveDataReport r;
    r.first_imu = first;
    r.imu_total = imu_total;
    r.sequence = t.seq;
    r.timestamp_us = t.ts;
    r.flags = t.flags;
    for (std::size_t b = 0; b < r.block_count(); ++b) {
      r.imus[b].accel = {static_cast<std::int16_t>(first + b), static_cast<std::int16_t>(t.seq & 0x3FFF), 0};
    }
    out.push_back(bytes_of(encode_data_report(r)));
  }
  return out;
}

struct Feed {
  ImuGloveStreamDecoder decoder;
  std::array<ImuGloveSample, 4> samples{};
  std::vector<ImuGlovePushResult> results;
  ImuGlovePushResult push(const Bytes& b, TimeNs rx = 0) {
    results.push_back(decoder.push(b, samples, rx));
    return results.back();
  }
  void tick(Tick t, std::uint8_t imu_total = 7) {
    for (const Bytes& b : tick_reports(t, imu_total)) push(b);
  }
  const ImuGloveStreamStats& stats() const { return decoder.stats(); }
};

constexpr std::uint32_t kPeriodUs = 10000;

TEST(GloveStream, InOrderStreamIsAllAccepted) {
  Feed f;
  for (std::uint16_t k = 0; k < 1000; ++k) f.tick({k, 5000u + k * kPeriodUs, k == 0 ? data_flags::stream_start : std::uint8_t{0}});
  const auto& s = f.stats();
  EXPECT_EQ(s.reports, 2000u);
  EXPECT_EQ(s.accepted, 2000u);
  EXPECT_EQ(s.lost, 0u);
  EXPECT_EQ(s.duplicates, 0u);
  EXPECT_EQ(s.late, 0u);
  EXPECT_EQ(s.device_resets, 0u);
  EXPECT_EQ(s.imu_total, 7);
  EXPECT_DOUBLE_EQ(s.tick_period_us, kPeriodUs);
  EXPECT_EQ(s.samples_good(), 7000u);
  for (std::size_t i = 0; i < 7; ++i) EXPECT_EQ(s.imus[i].good, 1000u);
  EXPECT_EQ(s.imus[7].good, 0u);
}

TEST(GloveStream, SamplesCarryIdsValuesAndTimes) {
  Feed f;
  const auto r0 = f.push(tick_reports({3, 123456})[1], 777);
  ASSERT_EQ(r0.verdict, ImuGloveReportVerdict::accepted);
  ASSERT_EQ(r0.sample_count, 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    const ImuGloveSample& s = f.samples[i];
    EXPECT_EQ(s.imu.sensor_id, 4 + i);
    EXPECT_DOUBLE_EQ(s.imu.accel_mps2.x(), static_cast<double>(4 + i) / accel_counts_per_mps2(AccelRange::g16));
    EXPECT_EQ(s.sequence, 3);
    EXPECT_EQ(s.timestamp_us, 123456u);
    EXPECT_EQ(s.device_time_us, 123456);
    EXPECT_EQ(s.receive_ns, 777);
    EXPECT_EQ(s.status, 0);
  }
}

TEST(GloveStream, GapsAreCountedPerPart) {
  Feed f;
  for (std::uint16_t k = 0; k < 100; ++k) {
    const auto reports = tick_reports({k, k * kPeriodUs});
    if (k >= 10 && k <= 12) continue;                // whole ticks lost: 6 reports
    if (k == 20) {
      f.push(reports[0]);                            // part 1 lost: 1 report
      continue;
    }
    for (const auto& b : reports) f.push(b);
  }
  EXPECT_EQ(f.stats().lost, 7u);
  EXPECT_EQ(f.stats().accepted, 200u - 7u);
  EXPECT_EQ(f.stats().device_resets, 0u);
}

TEST(GloveStream, DuplicatesAndReorderedReportsAreDroppedAndCounted) {
  Feed f;
  for (std::uint16_t k = 0; k < 30; ++k) f.tick({k, k * kPeriodUs});
  const auto t30 = tick_reports({30, 30 * kPeriodUs});
  const auto t31 = tick_reports({31, 31 * kPeriodUs});
  // Tick 31 overtakes tick 30; part 0 of 29 comes again.
  EXPECT_EQ(f.push(t31[0]).verdict, ImuGloveReportVerdict::accepted);
  EXPECT_EQ(f.stats().lost, 1u);  // 30/part 0 looks lost for now
  EXPECT_EQ(f.push(t30[0]).verdict, ImuGloveReportVerdict::late);
  EXPECT_EQ(f.stats().lost, 0u);  // ... until it turns up
  EXPECT_EQ(f.push(t30[1]).verdict, ImuGloveReportVerdict::accepted);
  EXPECT_EQ(f.push(t31[1]).verdict, ImuGloveReportVerdict::accepted);
  EXPECT_EQ(f.push(t31[1]).verdict, ImuGloveReportVerdict::duplicate);
  EXPECT_EQ(f.push(tick_reports({29, 29 * kPeriodUs})[0]).verdict, ImuGloveReportVerdict::duplicate);
  EXPECT_EQ(f.push(t30[0]).verdict, ImuGloveReportVerdict::duplicate);  // the late one, again
  const auto& s = f.stats();
  EXPECT_EQ(s.duplicates, 3u);
  EXPECT_EQ(s.late, 1u);
  EXPECT_EQ(s.lost, 0u);
  EXPECT_EQ(s.device_resets, 0u);
  // No samples from dropped reports: one per accepted tick, and the late
  // report of tick 30 gave none (IMUs 0-3 would have gone back in time).
  for (std::size_t i = 0; i < 4; ++i) EXPECT_EQ(s.imus[i].good, 31u) << i;
  for (std::size_t i = 4; i < 7; ++i) EXPECT_EQ(s.imus[i].good, 32u) << i;
}

// A reference model of what the decoder must count, run against random
// drops, duplicates and reorders (within the 64-report window).
TEST(GloveStream, CountsMatchAReferenceModelUnderRandomFaults) {
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    Rng rng(seed);
    struct Item {
      std::uint16_t tick;
      std::size_t part;
      Bytes bytes;
    };
    std::vector<Item> wire;
    const int ticks = 3000;  // wraps nothing, but crosses the 64-report window many times
    for (int k = 0; k < ticks; ++k) {
      const auto reports = tick_reports({static_cast<std::uint16_t>(k), static_cast<std::uint32_t>(k) * kPeriodUs});
      for (std::size_t p = 0; p < reports.size(); ++p) {
        if (k > 0 && rng.uniform01() < 0.05) continue;  // lost (never the very first)
        wire.push_back({static_cast<std::uint16_t>(k), p, reports[p]});
        if (rng.uniform01() < 0.03) wire.push_back(wire.back());
      }
    }
    // Not among the first ticks: a part whose first report is late is a case
    // the decoder cannot tell from attaching mid-stream.
    for (std::size_t i = 8; i + 4 < wire.size(); ++i) {
      if (rng.uniform01() < 0.03) std::swap(wire[i], wire[i + 1 + rng.below(4)]);
    }
    // Reference: per part, the newest tick seen and the set seen.
    std::uint64_t dup = 0, late = 0, acc = 0;
    std::map<std::size_t, std::set<int>> seen;
    std::map<std::size_t, int> newest;
    for (const Item& it : wire) {
      auto& s = seen[it.part];
      if (s.count(it.tick)) {
        ++dup;
      } else if (newest.count(it.part) && it.tick < newest[it.part]) {
        ++late;
        s.insert(it.tick);
      } else {
        ++acc;
        s.insert(it.tick);
        newest[it.part] = it.tick;
      }
    }
    std::uint64_t lost = 0;
    for (auto& [part, s] : seen) lost += static_cast<std::uint64_t>(newest[part] + 1) - s.size();

    Feed f;
    for (const Item& it : wire) f.push(it.bytes);
    const auto& st = f.stats();
    SCOPED_TRACE("seed " + std::to_string(seed));
    EXPECT_EQ(st.accepted, acc);
    EXPECT_EQ(st.duplicates, dup);
    EXPECT_EQ(st.late, late);
    EXPECT_EQ(st.lost, lost);
    EXPECT_EQ(st.device_resets, 0u);
    EXPECT_GT(dup + late, 0u);
  }
}

TEST(GloveStream, SequenceAndTimestampWrapsUnwrap) {
  Feed f;
  // Sequence starts 10 before its wrap, the µs counter 0.3 s before its own.
  const std::uint32_t ts0 = 0xFFFFFFFFu - 300000u;
  std::int64_t previous = -1;
  for (int k = 0; k < 100; ++k) {
    const auto seq = static_cast<std::uint16_t>(65526 + k);
    const auto ts = static_cast<std::uint32_t>(ts0 + static_cast<std::uint32_t>(k) * kPeriodUs);
    for (const Bytes& b : tick_reports({seq, ts})) {
      const auto r = f.push(b);
      ASSERT_EQ(r.verdict, ImuGloveReportVerdict::accepted) << k;
      EXPECT_EQ(r.sequence, 65526 + k);
      EXPECT_EQ(r.device_time_us, static_cast<std::int64_t>(ts0) + k * std::int64_t{kPeriodUs});
      EXPECT_EQ(f.samples[0].device_time_us, r.device_time_us);
    }
    EXPECT_GT(f.results.back().device_time_us, previous);
    previous = f.results.back().device_time_us;
  }
  EXPECT_EQ(f.stats().sequence_wraps, 1u);
  EXPECT_EQ(f.stats().timestamp_wraps, 1u);
  EXPECT_EQ(f.stats().lost, 0u);
  EXPECT_EQ(f.stats().device_resets, 0u);
}

TEST(GloveStream, LongGapBeyondHalfTheSequenceRangeIsResolvedByTheTimestamp) {
  Feed f;
  for (std::uint16_t k = 0; k < 10; ++k) f.tick({k, k * kPeriodUs});
  // 40000 ticks (400 s) of silence: the 16-bit difference alone would read
  // it as 25536 ticks back.
  const std::int64_t k = 9 + 40000;
  f.tick({static_cast<std::uint16_t>(k), static_cast<std::uint32_t>(k * kPeriodUs)});
  EXPECT_EQ(f.results.back().verdict, ImuGloveReportVerdict::accepted);
  EXPECT_EQ(f.results.back().sequence, k);
  EXPECT_EQ(f.stats().lost, 2u * 39999u);
  EXPECT_EQ(f.stats().device_resets, 0u);
}

TEST(GloveStream, FlaggedRestartBeginsANewEpochOnce) {
  Feed f;
  for (std::uint16_t k = 0; k < 50; ++k) f.tick({k, 1000000u + k * kPeriodUs});
  // Power cycle: counter and sequence start again; both parts carry the flag.
  const auto restart = tick_reports({0, 20, data_flags::stream_start});
  const auto r0 = f.push(restart[0]);
  EXPECT_EQ(r0.verdict, ImuGloveReportVerdict::accepted);
  EXPECT_TRUE(r0.device_reset);
  EXPECT_EQ(r0.epoch, 1u);
  const auto r1 = f.push(restart[1]);
  EXPECT_EQ(r1.verdict, ImuGloveReportVerdict::accepted);
  EXPECT_FALSE(r1.device_reset);
  EXPECT_EQ(f.push(restart[1]).verdict, ImuGloveReportVerdict::duplicate);
  for (std::uint16_t k = 1; k < 20; ++k) f.tick({k, 20u + k * kPeriodUs});
  const auto& s = f.stats();
  EXPECT_EQ(s.device_resets, 1u);
  EXPECT_EQ(s.lost, 0u);
  EXPECT_EQ(s.duplicates, 1u);
  EXPECT_EQ(f.samples[0].epoch, 1u);
}

TEST(GloveStream, ARestartStampedExactlyLikeTheFirstIsStillARestart) {
  Feed f;
  // Deterministic firmware: every boot's first tick is sequence 0 at counter 1000.
  for (std::uint16_t k = 0; k < 100; ++k) f.tick({k, 1000u + k * kPeriodUs, k == 0 ? data_flags::stream_start : std::uint8_t{0}});
  for (std::uint16_t k = 0; k < 100; ++k) f.tick({k, 1000u + k * kPeriodUs, k == 0 ? data_flags::stream_start : std::uint8_t{0}});
  EXPECT_EQ(f.stats().device_resets, 1u);
  EXPECT_EQ(f.stats().accepted, 400u);
  EXPECT_EQ(f.stats().duplicates, 0u);
}

TEST(GloveStream, UnflaggedRestartIsInferredFromSequenceAndClockDisagreeing) {
  Feed f;
  for (std::uint16_t k = 0; k < 50; ++k) f.tick({k, 1000000u + k * kPeriodUs});
  // The flagged first tick was lost; tick 1 of the new run arrives.
  const auto r = f.push(tick_reports({1, 10020})[0]);
  EXPECT_TRUE(r.device_reset);
  EXPECT_EQ(f.stats().device_resets, 1u);
  for (std::uint16_t k = 2; k < 10; ++k) f.tick({k, 20u + k * kPeriodUs});
  EXPECT_EQ(f.stats().device_resets, 1u);
  EXPECT_EQ(f.stats().lost, 0u);  // part 1 of tick 1 was the first tick's other half: not held against it
}

TEST(GloveStream, AClockThatStopsAgreeingWithTheSequenceIsARestart) {
  Feed f;
  for (std::uint16_t k = 0; k < 50; ++k) f.tick({k, k * kPeriodUs});
  // Half a tick of timestamp jitter is not a restart ...
  f.tick({50, 50 * kPeriodUs + kPeriodUs / 2});
  f.tick({51, 51 * kPeriodUs});
  EXPECT_EQ(f.stats().device_resets, 0u);
  EXPECT_EQ(f.stats().lost, 0u);
  // ... but the next sequence number with the clock a second ahead is not the same run.
  f.tick({52, 52 * kPeriodUs + 1000000});
  EXPECT_EQ(f.stats().device_resets, 1u);
}

TEST(GloveStream, ImuCountChangeIsARestart) {
  Feed f;
  for (std::uint16_t k = 0; k < 10; ++k) f.tick({k, k * kPeriodUs});
  f.tick({10, 10 * kPeriodUs}, 3);
  EXPECT_EQ(f.stats().device_resets, 1u);
  EXPECT_EQ(f.stats().imu_total, 3);
  EXPECT_EQ(f.results.back().sample_count, 3u);
}

TEST(GloveStream, AttachingMidStreamCountsNoLoss) {
  Feed f;
  // The host starts listening between the two reports of tick 500.
  f.push(tick_reports({500, 500 * kPeriodUs})[1]);
  for (std::uint16_t k = 501; k < 600; ++k) f.tick({k, k * kPeriodUs});
  EXPECT_EQ(f.stats().lost, 0u);
  EXPECT_EQ(f.stats().device_resets, 0u);
}

TEST(GloveStream, FlaggedAndRailSamplesAreCountedPerImu) {
  Feed f;
  ImuGloveDataReport r;
  r.imu_total = 7;
  r.first_imu = 4;
  r.timestamp_us = 100;
  r.imus[0].status = imu_status::stale;
  r.imus[1].status = imu_status::sensor_error;
  r.imus[2].gyro = {0, 32767, 0};  // at the rail, not flagged by the device
  const auto res = f.push(bytes_of(encode_data_report(r)));
  ASSERT_EQ(res.sample_count, 3u);
  EXPECT_EQ(f.samples[0].status, imu_status::stale);
  EXPECT_EQ(f.samples[1].status, imu_status::sensor_error);
  EXPECT_EQ(f.samples[2].status, imu_status::gyro_saturated);
  const auto& s = f.stats();
  EXPECT_EQ(s.imus[4].stale, 1u);
  EXPECT_EQ(s.imus[5].sensor_error, 1u);
  EXPECT_EQ(s.imus[6].gyro_saturated, 1u);
  EXPECT_EQ(s.samples_rejected(), 3u);
  EXPECT_EQ(s.samples_good(), 0u);
}

TEST(GloveStream, DecodeErrorsOtherReportsAndOverrunsAreCounted) {
  Feed f;
  f.tick({0, 0});
  Bytes bad = tick_reports({1, kPeriodUs})[0];
  bad[30] ^= 1;
  EXPECT_EQ(f.push(bad).verdict, ImuGloveReportVerdict::decode_error);
  EXPECT_EQ(f.results.back().decode.code, ImuGloveDecodeErrc::crc_mismatch);
  EXPECT_EQ(f.push(Bytes(64, 0)).verdict, ImuGloveReportVerdict::decode_error);  // report ID 0
  EXPECT_EQ(f.push(Bytes{}).verdict, ImuGloveReportVerdict::decode_error);
  ImuGloveDeviceInfo info;
  info.imu_count = 7;
  info.rate_hz = 100;
  EXPECT_EQ(f.push(bytes_of(encode_info_report(info))).verdict, ImuGloveReportVerdict::other_report);
  f.tick({5, 5 * kPeriodUs, data_flags::overrun});
  const auto& s = f.stats();
  EXPECT_EQ(s.decode_errors, 3u);
  EXPECT_EQ(s.decode_errors_by_code[static_cast<std::size_t>(ImuGloveDecodeErrc::crc_mismatch)], 1u);
  EXPECT_EQ(s.decode_errors_by_code[static_cast<std::size_t>(ImuGloveDecodeErrc::unknown_report_id)], 1u);
  EXPECT_EQ(s.decode_errors_by_code[static_cast<std::size_t>(ImuGloveDecodeErrc::empty)], 1u);
  EXPECT_EQ(s.last_decode_error.code, ImuGloveDecodeErrc::empty);
  EXPECT_EQ(s.other_reports, 1u);
  EXPECT_EQ(s.device_overruns, 1u);  // one tick, two reports
  EXPECT_EQ(s.lost, 8u);             // ticks 1-4, both parts
}

TEST(GloveStream, SmallOutputSpanIsNeverOverrun) {
  ImuGloveStreamDecoder d;
  std::array<ImuGloveSample, 2> two{};
  const auto r = d.push(tick_reports({0, 0})[0], two);
  EXPECT_EQ(r.verdict, ImuGloveReportVerdict::accepted);
  EXPECT_EQ(r.sample_count, 2u);
  EXPECT_EQ(d.stats().samples_good(), 4u);  // all four counted, two written
}

}  // namespace
}  // namespace proprio::devices
