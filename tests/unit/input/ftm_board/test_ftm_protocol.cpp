// The FTM board's wire protocol (every report, both directions, limits and
// errors) and its stream decoder (gaps, duplicates, reordering, wrap-around,
// restarts), offline.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "proprio/ftm_board/ftm_protocol.hpp"
#include "proprio/ftm_board/ftm_stream.hpp"

namespace proprio::devices::ftm_protocol_test {
namespace {

namespace st = ftm::sample_status;
using Bytes = std::vector<std::uint8_t>;

FtmImuReport ftmp_imu_report(std::uint32_t seq, std::uint32_t ts, std::uint8_t first = 0) {
  FtmImuReport r;
  r.sequence = seq;
  r.timestamp_us = ts;
  r.first_imu = first;
  r.period_us = 5000;
  for (std::size_t i = 0; i < kFtmImusPerReport; ++i) {
    const auto b = static_cast<std::int16_t>(100 * (i + 1) + first);
    r.imus[i].accel = {b, static_cast<std::int16_t>(-b), 2048};
    r.imus[i].gyro = {static_cast<std::int16_t>(b / 2), 7, -9};
    r.imus[i].mag = {120, -340, 560};
    r.imus[i].status = ftm_wire_status::mag_fresh;
  }
  return r;
}

FtmBendReport ftmp_bend_report(std::uint32_t seq, std::uint32_t ts, std::uint8_t count = 5) {
  FtmBendReport r;
  r.sequence = seq;
  r.timestamp_us = ts;
  r.count = count;
  r.period_us = 1000;
  for (std::size_t i = 0; i < count; ++i) {
    for (std::size_t k = 0; k < ftm::kFtmBendCount; ++k) {
      r.samples[i][k].value = static_cast<std::uint16_t>(10000 + 100 * k + i);
    }
  }
  return r;
}

Bytes ftmp_bytes(const auto& array) { return Bytes(array.begin(), array.end()); }

// ---------------------------------------------------------------------------
// Reports

TEST(FtmProtocol, EveryReportRoundTrips) {
  FtmImuReport imu = ftmp_imu_report(0xFFFFFFF0u, 0x89ABCDEFu, 2);
  imu.flags = ftm_flags::stream_start | ftm_flags::overrun;
  imu.accel_range = FtmAccelRange::g16;
  imu.gyro_range = FtmGyroRange::dps250;
  imu.imus[1].accel = {32767, -32768, 0};
  imu.imus[1].status = st::accel_saturated | st::mag_overflow | st::stale;
  auto ri = decode_ftm_imu_report(encode_ftm_imu_report(imu));
  ASSERT_TRUE(ri.ok()) << ri.error().message;
  EXPECT_EQ(*ri, imu);

  FtmBendReport bend = ftmp_bend_report(77, 1234, 3);
  bend.samples[2][1] = {kFtmBendRailCount, ftm_wire_status::over_range};
  auto rb = decode_ftm_bend_report(encode_ftm_bend_report(bend));
  ASSERT_TRUE(rb.ok()) << rb.error().message;
  EXPECT_EQ(*rb, bend);

  FtmDeviceInfo info;
  info.firmware = {2, 3, 4};
  info.streaming = true;
  info.imu_rate_hz = 500;
  info.bend_rate_hz = 2000;
  info.mag_rate_hz = 100;
  info.accel_range = FtmAccelRange::g2;
  info.gyro_range = FtmGyroRange::dps1000;
  info.imus_present = 0x0B;
  info.bends_present = 0x05;
  info.last_command_token = 9;
  info.last_command_result = FtmCommandResult::bad_argument;
  info.timestamp_us = 0xDEADBEEF;
  auto rinfo = decode_ftm_info_report(encode_ftm_info_report(info));
  ASSERT_TRUE(rinfo.ok()) << rinfo.error().message;
  EXPECT_EQ(*rinfo, info);

  for (FtmCommandOp op : {FtmCommandOp::start_streaming, FtmCommandOp::stop_streaming, FtmCommandOp::set_rates,
                          FtmCommandOp::set_ranges}) {
    FtmCommand c;
    c.op = op;
    c.token = 200;
    c.imu_rate_hz = 400;
    c.bend_rate_hz = 1500;
    c.accel_range = FtmAccelRange::g4;
    c.gyro_range = FtmGyroRange::dps500;
    auto rc = decode_ftm_command(encode_ftm_command(c));
    ASSERT_TRUE(rc.ok()) << rc.error().message;
    EXPECT_EQ(*rc, c);
  }
  EXPECT_EQ(ftm_report_size_for_id(0x51), 64u);
  EXPECT_EQ(ftm_report_size_for_id(0x52), 64u);
  EXPECT_EQ(ftm_report_size_for_id(0x53), 32u);
  EXPECT_EQ(ftm_report_size_for_id(0x58), 16u);
  EXPECT_EQ(ftm_report_size_for_id(0x21), 0u);
}

TEST(FtmProtocol, LayoutMatchesTheDocumentByteForByte) {
  // docs/ftm-hid-protocol.md, table 1: a hand-made report.
  FtmImuReport r = ftmp_imu_report(0x04030201u, 0x08070605u, 2);
  r.accel_range = FtmAccelRange::g8;
  r.gyro_range = FtmGyroRange::dps2000;
  const auto b = encode_ftm_imu_report(r);
  EXPECT_EQ(b[0], 0x51);
  EXPECT_EQ(b[1], 0x10);
  EXPECT_EQ(b[2], 0x01);
  EXPECT_EQ(b[5], 0x04);
  EXPECT_EQ(b[6], 0x05);
  EXPECT_EQ(b[11], 2);
  EXPECT_EQ(b[12], 0x32);  // accel code 2, gyro code 3 << 4
  EXPECT_EQ(b[14] | b[15] << 8, 5000);
  EXPECT_EQ(b[16], ftm_wire_status::mag_fresh);
  EXPECT_EQ(static_cast<std::int16_t>(b[17] | b[18] << 8), 102);  // IMU 2 accel x
  EXPECT_EQ(static_cast<std::int16_t>(b[29] | b[30] << 8), 120);  // IMU 2 compass x
  EXPECT_EQ(b[35], ftm_wire_status::mag_fresh);                   // IMU 3 status
  const std::uint16_t crc = hid::crc16_ccitt(std::span(b).first(62));
  EXPECT_EQ(b[62] | b[63] << 8, crc);
}

TEST(FtmProtocol, FramingErrorsSayWhatIsWrong) {
  const auto good = encode_ftm_imu_report(ftmp_imu_report(1, 2));
  Bytes b = ftmp_bytes(good);

  auto empty = decode_ftm_imu_report(std::span<const std::uint8_t>());
  ASSERT_FALSE(empty.ok());
  EXPECT_NE(empty.error().message.find("empty"), std::string::npos);

  Bytes shorter(b.begin(), b.end() - 1);
  auto len = decode_ftm_imu_report(shorter);
  ASSERT_FALSE(len.ok());
  EXPECT_NE(len.error().message.find("63 bytes"), std::string::npos) << len.error().message;
  EXPECT_NE(len.error().message.find("exactly 64"), std::string::npos);

  Bytes crc = b;
  crc[20] ^= 0x10;
  FtmImuReport out;
  const FtmDecodeStatus s = decode_ftm_imu_report(crc, out);
  EXPECT_EQ(s.code, FtmDecodeErrc::crc_mismatch);
  auto crc_r = decode_ftm_imu_report(crc);
  ASSERT_FALSE(crc_r.ok());
  EXPECT_NE(crc_r.error().message.find("CRC mismatch"), std::string::npos);
  EXPECT_NE(crc_r.error().message.find("IMU report (ID 0x51)"), std::string::npos);

  FtmImuReport v2 = ftmp_imu_report(1, 2);
  v2.version = 0x21;
  auto ver = decode_ftm_imu_report(encode_ftm_imu_report(v2));
  ASSERT_FALSE(ver.ok());
  EXPECT_EQ(ver.error().code, Errc::unsupported);
  EXPECT_NE(ver.error().message.find("version 2.1"), std::string::npos) << ver.error().message;
  // A newer minor of the same major still decodes.
  v2.version = 0x17;
  EXPECT_TRUE(decode_ftm_imu_report(encode_ftm_imu_report(v2)).ok());

  auto wrong = decode_ftm_imu_report(encode_ftm_bend_report(ftmp_bend_report(1, 2)));
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.error().message.find("0x52"), std::string::npos);
  EXPECT_NE(wrong.error().message.find("bend-sensor report"), std::string::npos);
  Bytes stretch = b;
  stretch[0] = 0x21;
  auto foreign = decode_ftm_imu_report(stretch);
  ASSERT_FALSE(foreign.ok());
  EXPECT_NE(foreign.error().message.find("stretch board"), std::string::npos) << foreign.error().message;
}

TEST(FtmProtocol, FieldChecksBehindAValidCrc) {
  FtmBendReport none = ftmp_bend_report(1, 2);
  none.count = 0;
  FtmBendReport out;
  EXPECT_EQ(decode_ftm_bend_report(encode_ftm_bend_report(none), out).code, FtmDecodeErrc::bad_count);
  none.count = 6;
  auto six = decode_ftm_bend_report(encode_ftm_bend_report(none));
  ASSERT_FALSE(six.ok());
  EXPECT_NE(six.error().message.find("bad sample count 6"), std::string::npos);

  FtmImuReport first = ftmp_imu_report(1, 2);
  first.first_imu = 1;
  FtmImuReport imu_out;
  EXPECT_EQ(decode_ftm_imu_report(encode_ftm_imu_report(first), imu_out).code, FtmDecodeErrc::bad_first_imu);
  first.first_imu = 0;
  first.period_us = 0;
  EXPECT_EQ(decode_ftm_imu_report(encode_ftm_imu_report(first), imu_out).code, FtmDecodeErrc::bad_period);

  FtmDeviceInfo info;
  info.imu_rate_hz = 5;
  FtmDeviceInfo info_out;
  EXPECT_EQ(decode_ftm_info_report(encode_ftm_info_report(info), info_out).code, FtmDecodeErrc::bad_period);

  auto cmd = encode_ftm_command(FtmCommand{});
  cmd[2] = 0x09;
  const std::uint16_t crc = hid::crc16_ccitt(std::span(cmd).first(14));
  cmd[14] = static_cast<std::uint8_t>(crc);
  cmd[15] = static_cast<std::uint8_t>(crc >> 8);
  auto unknown = decode_ftm_command(cmd);
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.error().message.find("opcode 0x09"), std::string::npos);
}

// ---------------------------------------------------------------------------
// Units and limits

TEST(FtmUnits, ImuSamplesSurviveTheWireWithinHalfACount) {
  for (FtmAccelRange ar : {FtmAccelRange::g2, FtmAccelRange::g4, FtmAccelRange::g8, FtmAccelRange::g16}) {
    for (FtmGyroRange gr : {FtmGyroRange::dps250, FtmGyroRange::dps2000}) {
      ftm::FtmImuSample s;
      s.accel_mps2 = Vec3(0.3, -9.7, 1.25);
      s.gyro_radps = Vec3(-1.1, 0.02, 3.0);
      s.mag_uT = Vec3(21.5, -4.2, -43.7);
      s.mag_fresh = true;
      const ftm::FtmImuSample back = imu_sample_from_wire(quantise_imu(s, ar, gr), ar, gr);
      const double a = accel_mps2_per_count(ar), g = gyro_radps_per_count(gr);
      for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(back.accel_mps2[i], s.accel_mps2[i], 0.5 * a + 1e-12);
        EXPECT_NEAR(back.gyro_radps[i], s.gyro_radps[i], 0.5 * g + 1e-12);
        EXPECT_NEAR(back.mag_uT[i], s.mag_uT[i], 0.5 * kFtmMagUtPerCount + 1e-12);
      }
      EXPECT_TRUE(back.mag_fresh);
      EXPECT_EQ(back.status, 0);
    }
  }
  // Scale factors are the MPU-9250 datasheet's.
  EXPECT_NEAR(accel_mps2_per_count(FtmAccelRange::g2), 9.80665 / 16384.0, 1e-15);
  EXPECT_NEAR(gyro_radps_per_count(FtmGyroRange::dps2000), (3.14159265358979323846 / 180.0) / 16.4, 1e-12);
}

TEST(FtmUnits, TheCompassTravelsInTheAk8963sAxes) {
  ftm::FtmImuSample s;
  s.mag_uT = Vec3(15.0, 30.0, 45.0);  // accelerometer axes
  const FtmImuRaw raw = quantise_imu(s, kFtmDefaultAccelRange, kFtmDefaultGyroRange);
  EXPECT_EQ(raw.mag[0], 200);   // die x = accel y
  EXPECT_EQ(raw.mag[1], 100);   // die y = accel x
  EXPECT_EQ(raw.mag[2], -300);  // die z = -accel z
  const ftm::FtmImuSample back = imu_sample_from_wire(raw, kFtmDefaultAccelRange, kFtmDefaultGyroRange);
  EXPECT_NEAR(back.mag_uT.x(), 15.0, 1e-12);
  EXPECT_NEAR(back.mag_uT.y(), 30.0, 1e-12);
  EXPECT_NEAR(back.mag_uT.z(), 45.0, 1e-12);
}

TEST(FtmUnits, SaturationOverflowAndNanSetTheRightBits) {
  const double a8 = accel_mps2_per_count(FtmAccelRange::g8);
  ftm::FtmImuSample s;
  s.accel_mps2 = Vec3(9.0 * kFtmStandardGravity, 0.0, -1.0);  // beyond ±8 g on x
  FtmImuRaw raw = quantise_imu(s, FtmAccelRange::g8, FtmGyroRange::dps2000);
  EXPECT_EQ(raw.accel[0], 32767);
  EXPECT_EQ(raw.status, st::accel_saturated);
  ftm::FtmImuSample back = imu_sample_from_wire(raw, FtmAccelRange::g8, FtmGyroRange::dps2000);
  EXPECT_EQ(back.status, st::accel_saturated);
  EXPECT_NEAR(back.accel_mps2.x(), 32767 * a8, 1e-9);
  // The negative rail too, and a host that sees a rail the board did not flag flags it.
  s.accel_mps2 = Vec3::Zero();
  s.gyro_radps = Vec3(0.0, -40.0, 0.0);  // beyond -2000 °/s
  raw = quantise_imu(s, FtmAccelRange::g8, FtmGyroRange::dps2000);
  EXPECT_EQ(raw.gyro[1], -32768);
  EXPECT_EQ(raw.status, st::gyro_saturated);
  raw.status = 0;
  EXPECT_EQ(imu_sample_from_wire(raw, FtmAccelRange::g8, FtmGyroRange::dps2000).status, st::gyro_saturated);
  // Just inside full scale is not saturated.
  s.gyro_radps = Vec3(0.0, -34.8, 0.0);
  EXPECT_EQ(quantise_imu(s, FtmAccelRange::g8, FtmGyroRange::dps2000).status, 0);

  // Compass beyond ±4912 µT: HOFL, only the compass is spoilt.
  s = {};
  s.mag_uT = Vec3(0.0, 0.0, 5000.0);
  s.mag_fresh = true;
  raw = quantise_imu(s, FtmAccelRange::g8, FtmGyroRange::dps2000);
  EXPECT_EQ(raw.status, st::mag_overflow | ftm_wire_status::mag_fresh);
  back = imu_sample_from_wire(raw, FtmAccelRange::g8, FtmGyroRange::dps2000);
  EXPECT_EQ(back.status, st::mag_overflow);
  EXPECT_TRUE(back.mag_fresh);
  s.mag_uT = Vec3(0.0, 0.0, 4900.0);  // inside the AK8963's range
  EXPECT_EQ(quantise_imu(s, FtmAccelRange::g8, FtmGyroRange::dps2000).status, ftm_wire_status::mag_fresh);

  // NaN anywhere: sensor_error with zeros, never a half-converted value.
  for (int which = 0; which < 3; ++which) {
    s = {};
    s.accel_mps2 = Vec3(1.0, 2.0, 3.0);
    s.gyro_radps = Vec3(0.1, 0.2, 0.3);
    s.mag_uT = Vec3(10.0, 20.0, 30.0);
    const double nan = std::numeric_limits<double>::quiet_NaN();
    (which == 0 ? s.accel_mps2 : which == 1 ? s.gyro_radps : s.mag_uT)[which] = nan;
    raw = quantise_imu(s, FtmAccelRange::g8, FtmGyroRange::dps2000);
    EXPECT_EQ(raw.status, st::sensor_error) << which;
    EXPECT_EQ(raw.accel, (std::array<std::int16_t, 3>{}));
    EXPECT_EQ(raw.gyro, (std::array<std::int16_t, 3>{}));
    EXPECT_EQ(raw.mag, (std::array<std::int16_t, 3>{}));
    back = imu_sample_from_wire(raw, FtmAccelRange::g8, FtmGyroRange::dps2000);
    EXPECT_TRUE(back.accel_mps2.allFinite() && back.gyro_radps.allFinite() && back.mag_uT.allFinite());
    EXPECT_EQ(back.status, st::sensor_error);
  }
  s = {};
  s.accel_mps2 = Vec3(std::numeric_limits<double>::infinity(), 0.0, 0.0);
  EXPECT_EQ(quantise_imu(s, FtmAccelRange::g8, FtmGyroRange::dps2000).status, st::sensor_error);
}

TEST(FtmUnits, BendCapacitanceLimits) {
  FtmBendRaw raw = quantise_bend(123.456);
  EXPECT_EQ(raw.value, 12346);
  EXPECT_EQ(raw.status, 0);
  ftm::FtmBendSample back = bend_sample_from_wire(raw);
  EXPECT_NEAR(back.capacitance_pF, 123.456, 0.005 + 1e-12);
  EXPECT_EQ(back.status, 0);

  raw = quantise_bend(kFtmBendFullScalePf);
  EXPECT_EQ(raw.value, kFtmBendRailCount - 1);
  EXPECT_EQ(raw.status, 0);
  raw = quantise_bend(700.0);
  EXPECT_EQ(raw.value, kFtmBendRailCount);
  EXPECT_EQ(raw.status, ftm_wire_status::over_range);
  EXPECT_EQ(bend_sample_from_wire(raw).status, st::sensor_error);
  raw.status = 0;  // the rail alone is enough for the host
  EXPECT_EQ(bend_sample_from_wire(raw).status, st::sensor_error);

  raw = quantise_bend(-3.0);
  EXPECT_EQ(raw.value, 0);
  EXPECT_EQ(raw.status, st::sensor_error);
  raw = quantise_bend(std::numeric_limits<double>::quiet_NaN());
  EXPECT_EQ(raw.value, 0);
  EXPECT_EQ(raw.status, st::sensor_error);
  back = bend_sample_from_wire(raw);
  EXPECT_EQ(back.capacitance_pF, 0.0);
  EXPECT_EQ(back.status, st::sensor_error);
  raw = quantise_bend(1e300);
  EXPECT_EQ(raw.status, ftm_wire_status::over_range);
  EXPECT_EQ(quantise_bend(50.0, st::stale).status, st::stale);
}

// ---------------------------------------------------------------------------
// Stream decoder

struct FtmpStream {
  FtmStreamDecoder decoder;
  std::vector<FtmBoardSample> samples;
  FtmPushResult push(const auto& bytes, TimeNs receive_ns = 0) {
    std::array<FtmBoardSample, kFtmMaxSamplesPerReport> out;
    const FtmPushResult r = decoder.push(bytes, out, receive_ns);
    for (std::size_t i = 0; i < r.sample_count; ++i) samples.push_back(out[i]);
    return r;
  }
};

TEST(FtmStream, DecodesSamplesIntoTheContractsUnitsWithDeviceTimes) {
  FtmpStream s;
  FtmImuReport a = ftmp_imu_report(10, 50'000, 0);
  a.flags = ftm_flags::stream_start;
  const FtmPushResult ra = s.push(encode_ftm_imu_report(a), 77);
  EXPECT_EQ(ra.verdict, FtmReportVerdict::accepted);
  ASSERT_EQ(ra.sample_count, 2u);
  EXPECT_FALSE(ra.device_reset);
  EXPECT_EQ(s.samples[0].event.kind, ftm::FtmEvent::Kind::imu);
  EXPECT_EQ(s.samples[1].event.index, 1);
  EXPECT_EQ(s.samples[0].device_time_us, 50'000);
  EXPECT_EQ(s.samples[0].receive_ns, 77);
  EXPECT_NEAR(s.samples[0].event.imu.accel_mps2.z(), 2048 * accel_mps2_per_count(kFtmDefaultAccelRange), 1e-12);
  EXPECT_TRUE(s.samples[0].event.imu.mag_fresh);

  FtmBendReport b = ftmp_bend_report(40, 48'000, 5);
  b.flags = ftm_flags::stream_start;
  const FtmPushResult rb = s.push(encode_ftm_bend_report(b));
  EXPECT_EQ(rb.verdict, FtmReportVerdict::accepted);
  ASSERT_EQ(rb.sample_count, 15u);
  EXPECT_EQ(rb.last_device_time_us, 52'000);
  // Time-major: sample i of sensor k.
  EXPECT_EQ(s.samples[2 + 3 * 4 + 2].device_time_us, 52'000);
  EXPECT_EQ(s.samples[2 + 3 * 4 + 2].event.index, 2);
  EXPECT_EQ(s.samples[2 + 3 * 4 + 2].sequence, 44);
  EXPECT_NEAR(s.samples[2 + 3 * 4 + 2].event.bend.capacitance_pF, (10000 + 200 + 4) * 0.01, 1e-9);
  EXPECT_EQ(s.decoder.stats().imu_samples, 2u);
  EXPECT_EQ(s.decoder.stats().bend_samples, 15u);
  EXPECT_EQ(s.decoder.stats().device_resets, 0u);
}

TEST(FtmStream, GapsDuplicatesAndLateReportsAreAccountedPerSample) {
  FtmpStream s;
  std::uint32_t ts = 1'000'000;
  s.push(encode_ftm_imu_report(ftmp_imu_report(0, ts)));
  s.push(encode_ftm_imu_report(ftmp_imu_report(1, ts + 5000)));
  // Ticks 2 and 3 lost on IMUs 0-1, tick 4 arrives.
  EXPECT_EQ(s.push(encode_ftm_imu_report(ftmp_imu_report(4, ts + 20'000))).verdict, FtmReportVerdict::accepted);
  EXPECT_EQ(s.decoder.stats().lost_imu_samples, 4u);
  EXPECT_EQ(s.decoder.stats().gaps, 1u);
  // Tick 3 turns up late: dropped, but no longer lost.
  EXPECT_EQ(s.push(encode_ftm_imu_report(ftmp_imu_report(3, ts + 15'000))).verdict, FtmReportVerdict::late);
  EXPECT_EQ(s.decoder.stats().lost_imu_samples, 2u);
  // Tick 4 again: a duplicate.
  EXPECT_EQ(s.push(encode_ftm_imu_report(ftmp_imu_report(4, ts + 20'000))).verdict, FtmReportVerdict::duplicate);
  // IMUs 2-3 have their own sequence: their tick 0 after tick 4 of the others is no loss and no duplicate.
  EXPECT_EQ(s.push(encode_ftm_imu_report(ftmp_imu_report(0, ts, 2))).verdict, FtmReportVerdict::accepted);
  EXPECT_EQ(s.push(encode_ftm_imu_report(ftmp_imu_report(1, ts + 5000, 2))).verdict, FtmReportVerdict::accepted);
  // Bend: 5 samples per report; one report lost is 15 samples.
  s.push(encode_ftm_bend_report(ftmp_bend_report(0, ts)));
  s.push(encode_ftm_bend_report(ftmp_bend_report(10, ts + 10'000)));
  EXPECT_EQ(s.decoder.stats().lost_bend_samples, 15u);
  // A corrupted report is a decode error, counted by reason.
  auto bad = encode_ftm_bend_report(ftmp_bend_report(15, ts + 15'000));
  bad[30] ^= 1;
  EXPECT_EQ(s.push(bad).verdict, FtmReportVerdict::decode_error);
  const FtmStreamStats& st = s.decoder.stats();
  EXPECT_EQ(st.decode_errors_by_code[static_cast<std::size_t>(FtmDecodeErrc::crc_mismatch)], 1u);
  EXPECT_EQ(st.accepted + st.duplicates + st.late + st.decode_errors + st.other_reports, st.reports);
  EXPECT_EQ(st.duplicates, 1u);
  EXPECT_EQ(st.late, 1u);
  EXPECT_EQ(st.device_resets, 0u);
  // An info report in the stream is neither data nor error.
  EXPECT_EQ(s.push(encode_ftm_info_report(FtmDeviceInfo{})).verdict, FtmReportVerdict::other_report);
}

TEST(FtmStream, SequenceAndTimestampWrapAround) {
  FtmpStream s;
  std::uint32_t seq = 0xFFFFFFFEu;
  std::uint32_t ts = 0xFFFFFFFFu - 7000;
  std::int64_t prev_us = -1;
  for (int i = 0; i < 6; ++i) {
    const FtmPushResult r = s.push(encode_ftm_imu_report(ftmp_imu_report(seq, ts)));
    ASSERT_EQ(r.verdict, FtmReportVerdict::accepted) << i;
    EXPECT_GT(r.device_time_us, prev_us);
    EXPECT_EQ(static_cast<std::uint32_t>(r.device_time_us), ts);
    prev_us = r.device_time_us;
    ++seq;
    ts += 5000;
  }
  EXPECT_EQ(s.decoder.stats().sequence_wraps, 1u);
  EXPECT_EQ(s.decoder.stats().timestamp_wraps, 1u);
  EXPECT_EQ(s.decoder.stats().lost_imu_samples, 0u);
  EXPECT_EQ(s.decoder.stats().device_resets, 0u);
  EXPECT_EQ(s.samples.back().sequence, 0xFFFFFFFEll + 5);
}

TEST(FtmStream, ARestartedBoardBeginsOneEpochForAllChannels) {
  FtmpStream s;
  for (std::uint32_t n = 0; n < 5; ++n) {
    FtmImuReport a = ftmp_imu_report(n, 3'000'000 + 5000 * n, 0);
    FtmImuReport b = ftmp_imu_report(n, 3'000'000 + 5000 * n, 2);
    a.flags = b.flags = n == 0 ? ftm_flags::stream_start : 0;
    s.push(encode_ftm_imu_report(a));
    s.push(encode_ftm_imu_report(b));
  }
  s.push(encode_ftm_bend_report(ftmp_bend_report(0, 3'000'000)));
  // The board boots again: every channel's first report is flagged.
  FtmImuReport a = ftmp_imu_report(0, 100, 0);
  a.flags = ftm_flags::stream_start;
  const FtmPushResult ra = s.push(encode_ftm_imu_report(a));
  EXPECT_EQ(ra.verdict, FtmReportVerdict::accepted);
  EXPECT_TRUE(ra.device_reset);
  EXPECT_EQ(ra.epoch, 1u);
  FtmImuReport b = ftmp_imu_report(0, 100, 2);
  b.flags = ftm_flags::stream_start;
  const FtmPushResult rb = s.push(encode_ftm_imu_report(b));
  EXPECT_FALSE(rb.device_reset);
  EXPECT_EQ(rb.epoch, 1u);
  // The bend channel's flagged report was lost: its unflagged next one follows the epoch.
  const FtmPushResult rc = s.push(encode_ftm_bend_report(ftmp_bend_report(5, 5100)));
  EXPECT_EQ(rc.verdict, FtmReportVerdict::accepted);
  EXPECT_FALSE(rc.device_reset);
  EXPECT_EQ(s.decoder.stats().device_resets, 1u);
  EXPECT_EQ(s.decoder.stats().lost_imu_samples, 0u);
  EXPECT_EQ(s.decoder.stats().lost_bend_samples, 0u);
  // A duplicate of a channel's first report is not a restart.
  const FtmPushResult dup = s.push(encode_ftm_imu_report(a));
  EXPECT_EQ(dup.verdict, FtmReportVerdict::duplicate);
  EXPECT_EQ(s.decoder.stats().device_resets, 1u);

  // A restart whose flagged reports were all lost: sequence and clock disagree.
  FtmpStream u;
  for (std::uint32_t n = 0; n < 50; ++n) u.push(encode_ftm_imu_report(ftmp_imu_report(n, 1'000'000 + 5000 * n)));
  const FtmPushResult r = u.push(encode_ftm_imu_report(ftmp_imu_report(3, 15'000)));
  EXPECT_TRUE(r.device_reset);
  EXPECT_EQ(r.verdict, FtmReportVerdict::accepted);
  EXPECT_EQ(u.decoder.stats().device_resets, 1u);
  EXPECT_EQ(u.decoder.stats().lost_imu_samples, 0u);
}

}  // namespace
}  // namespace proprio::devices::ftm_protocol_test
