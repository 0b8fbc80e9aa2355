// The fingertip device's wire protocol: byte layouts pinned field by field,
// round trips, every malformed-byte case with the field its message names,
// and the sequence accounting of both receiving ends.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/fingertip_device/fingertip_protocol.hpp"

namespace proprio::devices {
namespace {

using Report = std::array<std::uint8_t, kFingertipReportSize>;

// After editing a field, the CRC is made right again, so the decoder's field
// checks (not its CRC check) have to catch the edit.
void fix_crc(Report& b) {
  const std::uint16_t crc = hid::crc16_ccitt(std::span<const std::uint8_t>(b).first(62));
  b[62] = static_cast<std::uint8_t>(crc);
  b[63] = static_cast<std::uint8_t>(crc >> 8);
}

std::uint32_t u32_at(const Report& b, std::size_t at) {
  return static_cast<std::uint32_t>(b[at]) | static_cast<std::uint32_t>(b[at + 1]) << 8 |
         static_cast<std::uint32_t>(b[at + 2]) << 16 | static_cast<std::uint32_t>(b[at + 3]) << 24;
}

FingertipCommand sample_command() {
  FingertipCommand c;
  c.sequence = 0x1234;
  c.mode = FingertipMode::force;
  c.flags = fingertip_command_flags::enable | fingertip_command_flags::sequence_reset;
  c.count = 3;
  c.values = {1000, -250, 7};
  c.host_time_ns = 0x0102030405060708;
  return c;
}

FingertipFeedback sample_feedback() {
  FingertipFeedback f;
  f.sequence = 65535;
  f.applied_sequence = 17;
  f.device_time_us = 0xA1B2C3D4;
  f.status = fingertip_status::enabled | fingertip_status::ramping;
  f.motor_count = 2;
  f.fsr_count = 1;
  f.mode = FingertipMode::motor_angles;
  f.command_result = FingertipCommandResult::ok;
  f.encoder_counts = {-5, 4096, 0};
  f.fsr_force_mn = {987, 0, 0};
  f.current_ma = {-120, 300, 0};
  f.rejected_commands = 3;
  f.applied_host_time_ns = -42;
  f.ramp_permille = 500;
  return f;
}

FingertipDeviceInfo sample_info() {
  FingertipDeviceInfo i;
  i.firmware = {2, 1, 9};
  i.kind = FingertipDeviceKind::band_2dof;
  i.motor_count = 2;
  i.fsr_count = 1;
  i.hand = Handedness::right;
  i.finger = Finger::index;
  i.control_rate_hz = 2000;
  i.feedback_rate_hz = 1000;
  i.encoder_counts_per_rev = 1024;
  i.gear_ratio_milli = 16000;
  i.watchdog_ms = 50;
  i.ramp_ms = 100;
  i.max_normal_force_mn = 2500;
  i.max_shear_force_mn = 1200;
  i.min_angle_urad = -500000;
  i.max_angle_urad = 1200000;
  i.max_current_ma = 600;
  i.set_serial("FT-R-INDEX-07");
  return i;
}

TEST(FingertipProtocol, CommandLayoutIsPinnedByteByByte) {
  const Report b = encode_fingertip_command(sample_command());
  EXPECT_EQ(b[0], 0x50);
  EXPECT_EQ(b[1], 0x10);
  EXPECT_EQ(b[2], 0x34);  // sequence, little-endian
  EXPECT_EQ(b[3], 0x12);
  EXPECT_EQ(b[4], 2);     // force
  EXPECT_EQ(b[5], 0x05);  // enable | sequence_reset
  EXPECT_EQ(b[6], 3);
  EXPECT_EQ(b[7], 0);
  EXPECT_EQ(u32_at(b, 8), 1000u);
  EXPECT_EQ(u32_at(b, 12), static_cast<std::uint32_t>(-250));
  EXPECT_EQ(u32_at(b, 16), 7u);
  EXPECT_EQ(u32_at(b, 20), 0x05060708u);
  EXPECT_EQ(u32_at(b, 24), 0x01020304u);
  for (std::size_t i = 28; i < 62; ++i) { EXPECT_EQ(b[i], 0) << "reserved byte " << i; }
  const std::uint16_t crc = hid::crc16_ccitt(std::span<const std::uint8_t>(b).first(62));
  EXPECT_EQ(b[62], crc & 0xFF);
  EXPECT_EQ(b[63], crc >> 8);
}

TEST(FingertipProtocol, FeedbackLayoutIsPinnedByteByByte) {
  const Report b = encode_fingertip_feedback(sample_feedback());
  EXPECT_EQ(b[0], 0x41);
  EXPECT_EQ(b[1], 0x10);
  EXPECT_EQ(b[2], 0xFF);
  EXPECT_EQ(b[3], 0xFF);
  EXPECT_EQ(b[4], 17);
  EXPECT_EQ(u32_at(b, 6), 0xA1B2C3D4u);
  EXPECT_EQ(b[10], 0x21);  // enabled | ramping
  EXPECT_EQ(b[11], 0x00);
  EXPECT_EQ(b[12], 2);
  EXPECT_EQ(b[13], 1);
  EXPECT_EQ(b[14], 1);
  EXPECT_EQ(b[15], 1);
  EXPECT_EQ(u32_at(b, 16), static_cast<std::uint32_t>(-5));
  EXPECT_EQ(u32_at(b, 20), 4096u);
  EXPECT_EQ(u32_at(b, 24), 0u);  // motor 3 does not exist
  EXPECT_EQ(u32_at(b, 28), 987u);
  EXPECT_EQ(b[40], static_cast<std::uint8_t>(-120 & 0xFF));
  EXPECT_EQ(b[41], static_cast<std::uint8_t>((-120 >> 8) & 0xFF));
  EXPECT_EQ(b[42], 300 & 0xFF);
  EXPECT_EQ(b[46], 3);
  EXPECT_EQ(b[48], static_cast<std::uint8_t>(-42));
  EXPECT_EQ(b[55], 0xFF);  // sign of the i64
  EXPECT_EQ(b[56], 500 & 0xFF);
  EXPECT_EQ(b[57], 500 >> 8);
}

TEST(FingertipProtocol, InfoLayoutIsPinnedByteByByte) {
  const Report b = encode_fingertip_info(sample_info());
  EXPECT_EQ(b[0], 0x42);
  EXPECT_EQ(b[2], 2);
  EXPECT_EQ(b[4], 9);
  EXPECT_EQ(b[5], 1);  // band_2dof
  EXPECT_EQ(b[6], 2);
  EXPECT_EQ(b[7], 1);
  EXPECT_EQ(b[8], 2);  // right
  EXPECT_EQ(b[9], 1);  // index
  EXPECT_EQ(b[10] | b[11] << 8, 2000);
  EXPECT_EQ(b[12] | b[13] << 8, 1000);
  EXPECT_EQ(u32_at(b, 14), 1024u);
  EXPECT_EQ(u32_at(b, 18), 16000u);
  EXPECT_EQ(b[22] | b[23] << 8, 50);
  EXPECT_EQ(u32_at(b, 26), 2500u);
  EXPECT_EQ(u32_at(b, 34), static_cast<std::uint32_t>(-500000));
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(&b[44]), 13), "FT-R-INDEX-07");
  EXPECT_EQ(b[57], 0);  // NUL padding
  FingertipDeviceInfo unassigned = sample_info();
  unassigned.hand.reset();
  unassigned.finger.reset();
  const Report u = encode_fingertip_info(unassigned);
  EXPECT_EQ(u[8], 0);
  EXPECT_EQ(u[9], 0xFF);
}

TEST(FingertipProtocol, RandomReportsRoundTripExactly) {
  Rng rng(7);
  auto i32 = [&] { return static_cast<std::int32_t>(rng.next_u64()); };
  for (int n = 0; n < 2000; ++n) {
    FingertipCommand c;
    c.sequence = static_cast<std::uint16_t>(rng.next_u64());
    c.mode = rng.below(2) ? FingertipMode::force : FingertipMode::motor_angles;
    c.flags = static_cast<std::uint8_t>(rng.below(8));
    c.count = static_cast<std::uint8_t>(1 + rng.below(3));
    for (std::size_t i = 0; i < c.count; ++i) c.values[i] = i32();
    c.host_time_ns = static_cast<std::int64_t>(rng.next_u64());
    FingertipCommand c2;
    ASSERT_TRUE(decode_fingertip_command(encode_fingertip_command(c), c2).ok());
    ASSERT_EQ(c2, c);

    FingertipFeedback f;
    f.sequence = static_cast<std::uint16_t>(rng.next_u64());
    f.applied_sequence = static_cast<std::uint16_t>(rng.next_u64());
    f.device_time_us = static_cast<std::uint32_t>(rng.next_u64());
    f.status = static_cast<std::uint16_t>(rng.below(256));
    f.motor_count = static_cast<std::uint8_t>(1 + rng.below(3));
    f.fsr_count = static_cast<std::uint8_t>(rng.below(4));
    f.mode = static_cast<FingertipMode>(rng.below(3));
    f.command_result = static_cast<FingertipCommandResult>(rng.below(5));
    for (std::size_t i = 0; i < f.motor_count; ++i) {
      f.encoder_counts[i] = i32();
      f.current_ma[i] = static_cast<std::int16_t>(rng.next_u64());
    }
    for (std::size_t i = 0; i < f.fsr_count; ++i) f.fsr_force_mn[i] = i32();
    f.rejected_commands = static_cast<std::uint16_t>(rng.next_u64());
    f.applied_host_time_ns = static_cast<std::int64_t>(rng.next_u64());
    f.ramp_permille = static_cast<std::uint16_t>(rng.below(1001));
    FingertipFeedback f2;
    ASSERT_TRUE(decode_fingertip_feedback(encode_fingertip_feedback(f), f2).ok());
    ASSERT_EQ(f2, f);
  }
  FingertipDeviceInfo info;
  ASSERT_TRUE(decode_fingertip_info(encode_fingertip_info(sample_info()), info).ok());
  EXPECT_EQ(info, sample_info());
  EXPECT_EQ(info.serial_view(), "FT-R-INDEX-07");
}

TEST(FingertipProtocol, ValuesPastTheCountsAreNotTrusted) {
  Report b = encode_fingertip_command(sample_command());
  b[6] = 1;  // one value; bytes 12-19 still hold the others
  fix_crc(b);
  FingertipCommand c;
  ASSERT_TRUE(decode_fingertip_command(b, c).ok());
  EXPECT_EQ(c.values[0], 1000);
  EXPECT_EQ(c.values[1], 0);
  EXPECT_EQ(c.values[2], 0);

  FingertipFeedback in = sample_feedback();
  in.motor_count = 3;
  in.fsr_count = 3;
  in.encoder_counts[2] = 99;
  in.fsr_force_mn[2] = 99;
  Report fb = encode_fingertip_feedback(in);
  fb[12] = 1;  // claims one motor and no force sensors
  fb[13] = 0;
  fix_crc(fb);
  FingertipFeedback f;
  ASSERT_TRUE(decode_fingertip_feedback(fb, f).ok());
  EXPECT_EQ(f.encoder_counts[1], 0);
  EXPECT_EQ(f.encoder_counts[2], 0);
  EXPECT_EQ(f.fsr_force_mn[0], 0);
  EXPECT_EQ(f.current_ma[1], 0);
}

TEST(FingertipProtocol, ReservedBitsAndMinorVersionsAreIgnored) {
  Report b = encode_fingertip_command(sample_command());
  b[1] = 0x1F;   // 1.15: a later minor of the same major
  b[5] |= 0xF0;  // reserved flag bits
  b[40] = 0xAB;  // a reserved byte
  fix_crc(b);
  FingertipCommand c;
  ASSERT_TRUE(decode_fingertip_command(b, c).ok());
  EXPECT_EQ(c.flags, fingertip_command_flags::enable | fingertip_command_flags::sequence_reset);
}

struct Malformed {
  const char* name;
  std::vector<std::uint8_t> bytes;
  FingertipDecodeErrc code;
  const char* message_part;  // the field or fact the message must name
};

template <typename Decode>
void expect_all(const std::vector<Malformed>& cases, Decode decode) {
  for (const Malformed& m : cases) {
    SCOPED_TRACE(m.name);
    const FingertipDecodeStatus s = decode(m.bytes);
    EXPECT_EQ(s.code, m.code) << to_string(s.code) << ": " << describe(s);
    const std::string text = describe(s);
    EXPECT_NE(text.find(m.message_part), std::string::npos) << text;
  }
}

std::vector<std::uint8_t> edited(Report b, std::size_t at, std::uint8_t value, bool crc = true) {
  b[at] = value;
  if (crc) fix_crc(b);
  return {b.begin(), b.end()};
}

TEST(FingertipProtocol, EveryMalformedCommandGivesItsOwnClearError) {
  const Report good = encode_fingertip_command(sample_command());
  std::vector<std::uint8_t> truncated(good.begin(), good.end() - 1);
  std::vector<std::uint8_t> longer(good.begin(), good.end());
  longer.push_back(0);
  Report glove_id = good;
  glove_id[0] = 0x01;
  Report bad_crc = good;
  bad_crc[10] ^= 0x04;
  const std::vector<Malformed> cases = {
      {"empty", {}, FingertipDecodeErrc::empty, "0 bytes"},
      {"truncated", truncated, FingertipDecodeErrc::bad_length, "63 bytes"},
      {"too long", longer, FingertipDecodeErrc::bad_length, "65 bytes"},
      {"glove report ID", {glove_id.begin(), glove_id.end()}, FingertipDecodeErrc::unknown_report_id, "IMU glove"},
      {"feedback ID", edited(good, 0, 0x41, false), FingertipDecodeErrc::unknown_report_id, "feedback report"},
      {"stretch ID", edited(good, 0, 0x30, false), FingertipDecodeErrc::unknown_report_id, "stretch glove"},
      {"version 2.0", edited(good, 1, 0x20), FingertipDecodeErrc::unsupported_version, "version 2.0"},
      {"bad CRC", {bad_crc.begin(), bad_crc.end()}, FingertipDecodeErrc::crc_mismatch, "CRC mismatch"},
      {"mode 0", edited(good, 4, 0), FingertipDecodeErrc::bad_mode, "bad mode 0"},
      {"mode 3", edited(good, 4, 3), FingertipDecodeErrc::bad_mode, "bad mode 3"},
      {"count 0", edited(good, 6, 0), FingertipDecodeErrc::bad_value_count, "byte 6"},
      {"count 4", edited(good, 6, 4), FingertipDecodeErrc::bad_value_count, "value count 4"},
  };
  expect_all(cases, [](const std::vector<std::uint8_t>& b) {
    FingertipCommand c;
    return decode_fingertip_command(b, c);
  });
  // The Result form says which report it was and keeps the error class.
  auto r = decode_fingertip_command(edited(good, 1, 0x20));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::unsupported);
  EXPECT_NE(r.error().message.find("command report (ID 0x50)"), std::string::npos) << r.error().message;
  auto p = decode_fingertip_command(truncated);
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error().code, Errc::parse_error);
}

TEST(FingertipProtocol, EveryMalformedFeedbackGivesItsOwnClearError) {
  const Report good = encode_fingertip_feedback(sample_feedback());
  Report big_ramp = good;
  big_ramp[56] = 0xE9;  // 1001
  big_ramp[57] = 0x03;
  fix_crc(big_ramp);
  const std::vector<Malformed> cases = {
      {"command ID", edited(good, 0, 0x50, false), FingertipDecodeErrc::unknown_report_id, "command report"},
      {"motors 0", edited(good, 12, 0), FingertipDecodeErrc::bad_motor_count, "motor count 0"},
      {"motors 4", edited(good, 12, 4), FingertipDecodeErrc::bad_motor_count, "motor count 4"},
      {"fsrs 4", edited(good, 13, 4), FingertipDecodeErrc::bad_fsr_count, "force sensor count 4"},
      {"mode 3", edited(good, 14, 3), FingertipDecodeErrc::bad_mode, "bad mode 3"},
      {"result 9", edited(good, 15, 9), FingertipDecodeErrc::bad_command_result, "byte 15"},
      {"ramp 1001", {big_ramp.begin(), big_ramp.end()}, FingertipDecodeErrc::bad_ramp, "1001 permille"},
      {"version 0.1", edited(good, 1, 0x01), FingertipDecodeErrc::unsupported_version, "version 0.1"},
  };
  expect_all(cases, [](const std::vector<std::uint8_t>& b) {
    FingertipFeedback f;
    return decode_fingertip_feedback(b, f);
  });
}

TEST(FingertipProtocol, EveryMalformedInfoGivesItsOwnClearError) {
  const Report good = encode_fingertip_info(sample_info());
  auto with_u16 = [&](std::size_t at, std::uint16_t v) {
    Report b = good;
    b[at] = static_cast<std::uint8_t>(v);
    b[at + 1] = static_cast<std::uint8_t>(v >> 8);
    fix_crc(b);
    return std::vector<std::uint8_t>(b.begin(), b.end());
  };
  auto with_u32 = [&](std::size_t at, std::uint32_t v) {
    Report b = good;
    for (int i = 0; i < 4; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (8 * i));
    fix_crc(b);
    return std::vector<std::uint8_t>(b.begin(), b.end());
  };
  const std::vector<Malformed> cases = {
      {"kind 0", edited(good, 5, 0), FingertipDecodeErrc::bad_kind, "byte 5"},
      {"kind 4", edited(good, 5, 4), FingertipDecodeErrc::bad_kind, "device kind 4"},
      {"motors 0", edited(good, 6, 0), FingertipDecodeErrc::bad_motor_count, "motor count 0"},
      {"fsrs 7", edited(good, 7, 7), FingertipDecodeErrc::bad_fsr_count, "count 7"},
      {"hand 3", edited(good, 8, 3), FingertipDecodeErrc::bad_assignment, "hand 3 in byte 8"},
      {"finger 5", edited(good, 9, 5), FingertipDecodeErrc::bad_assignment, "finger 5 in byte 9"},
      {"control rate 0", with_u16(10, 0), FingertipDecodeErrc::bad_rate, "bad rate 0 Hz"},
      {"control rate 20000", with_u16(10, 20000), FingertipDecodeErrc::bad_rate, "bad rate 20000 Hz"},
      {"feedback above control", with_u16(12, 4000), FingertipDecodeErrc::bad_rate, "at most the control rate"},
      {"feedback 0", with_u16(12, 0), FingertipDecodeErrc::bad_rate, "bad rate 0 Hz"},
      {"counts 0", with_u32(14, 0), FingertipDecodeErrc::bad_encoder_resolution, "counts/rev"},
      {"gear 0", with_u32(18, 0), FingertipDecodeErrc::bad_gear_ratio, "gear ratio"},
      {"watchdog 0", with_u16(22, 0), FingertipDecodeErrc::bad_watchdog, "watchdog period 0 ms"},
      {"min above max", with_u32(34, 2'000'000), FingertipDecodeErrc::bad_angle_limits, "2000000 µrad"},
      {"serial control char", edited(good, 46, 0x07), FingertipDecodeErrc::bad_serial, "byte 2 of it is 0x07"},
  };
  expect_all(cases, [](const std::vector<std::uint8_t>& b) {
    FingertipDeviceInfo i;
    return decode_fingertip_info(b, i);
  });
}

TEST(FingertipProtocol, EverySingleBitFlipIsDetected) {
  for (const Report& good : {encode_fingertip_command(sample_command()), encode_fingertip_feedback(sample_feedback()),
                             encode_fingertip_info(sample_info())}) {
    for (std::size_t bit = 8; bit < kFingertipReportSize * 8; ++bit) {  // byte 0 is the ID: a flip there is a wrong ID
      Report b = good;
      b[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
      FingertipCommand c;
      FingertipFeedback f;
      FingertipDeviceInfo i;
      const bool any = decode_fingertip_command(b, c).ok() || decode_fingertip_feedback(b, f).ok() ||
                       decode_fingertip_info(b, i).ok();
      ASSERT_FALSE(any) << "bit " << bit << " of report 0x" << std::hex << int(good[0]);
    }
  }
}

TEST(FingertipProtocol, RejectedReportsLeaveTheOutputUntouched) {
  FingertipCommand c = sample_command();
  const FingertipCommand before = c;
  Report b = encode_fingertip_command(sample_command());
  b[6] = 9;
  fix_crc(b);
  EXPECT_FALSE(decode_fingertip_command(b, c).ok());
  EXPECT_EQ(c, before);
}

TEST(FingertipProtocol, SiValuesRoundAndSaturateOnTheWire) {
  std::int32_t v = 0;
  EXPECT_TRUE(fingertip_to_wire(0.0000016, kFingertipUradPerRad, v));
  EXPECT_EQ(v, 2);  // to the nearest µrad
  EXPECT_TRUE(fingertip_to_wire(-1.2346, kFingertipMnPerN, v));
  EXPECT_EQ(v, -1235);
  EXPECT_TRUE(fingertip_to_wire(1e12, kFingertipMnPerN, v));
  EXPECT_EQ(v, std::numeric_limits<std::int32_t>::max());
  EXPECT_TRUE(fingertip_to_wire(-1e12, kFingertipMnPerN, v));
  EXPECT_EQ(v, std::numeric_limits<std::int32_t>::min());
  v = 77;
  EXPECT_FALSE(fingertip_to_wire(std::nan(""), 1.0, v));
  EXPECT_FALSE(fingertip_to_wire(std::numeric_limits<double>::infinity(), 1.0, v));
  EXPECT_EQ(v, 77);
}

// The encoder the driver and haptics' emulated device share: the unit follows
// the mode, only c.count values are written, a non-finite one is reported.
TEST(FingertipProtocol, CommandValuesFromSiFollowTheModeAndCount) {
  FingertipCommand c;
  c.mode = FingertipMode::motor_angles;
  c.count = 2;
  c.values = {5, 6, 7};
  const std::array<double, kFingertipMaxMotors> angles_rad{0.0000016, -0.25, 9.0};
  EXPECT_TRUE(set_fingertip_command_values(c, angles_rad));
  EXPECT_EQ(c.values, (std::array<std::int32_t, kFingertipMaxMotors>{2, -250000, 7}));

  c.mode = FingertipMode::force;
  c.count = 3;
  const std::array<double, kFingertipMaxMotors> force_n{1.2346, 1e12, std::nan("")};
  EXPECT_FALSE(set_fingertip_command_values(c, force_n));
  EXPECT_EQ(c.values, (std::array<std::int32_t, kFingertipMaxMotors>{1235, std::numeric_limits<std::int32_t>::max(), 7}));
}

TEST(FingertipProtocol, InfoConvertsCountsToOutputAngles) {
  const FingertipDeviceInfo info = sample_info();
  EXPECT_DOUBLE_EQ(info.gear_ratio(), 16.0);
  EXPECT_NEAR(info.output_angle_rad(1024 * 16), 2.0 * M_PI, 1e-12);
  EXPECT_NEAR(info.output_angle_rad(-1024 * 4), -M_PI / 2.0, 1e-12);
  const std::string text = describe(info);
  EXPECT_NE(text.find("band_2dof"), std::string::npos) << text;
  EXPECT_NE(text.find("right index"), std::string::npos) << text;
  EXPECT_NE(text.find("FT-R-INDEX-07"), std::string::npos) << text;
  EXPECT_EQ(describe_fingertip_status(fingertip_status::enabled | fingertip_status::fault_stall), "enabled|fault_stall");
  EXPECT_EQ(describe_fingertip_status(0), "none");
}

TEST(FingertipSequence, CountsGapsStaleReportsWrapsAndRestarts) {
  FingertipSequenceTracker t;
  EXPECT_EQ(t.observe(65530, false).verdict, FingertipSequenceVerdict::first);
  EXPECT_EQ(t.observe(65531, false).verdict, FingertipSequenceVerdict::in_order);
  const FingertipSequenceResult gap = t.observe(65534, false);
  EXPECT_EQ(gap.verdict, FingertipSequenceVerdict::gap);
  EXPECT_EQ(gap.lost, 2u);
  EXPECT_EQ(t.observe(65535, false).verdict, FingertipSequenceVerdict::in_order);
  EXPECT_EQ(t.observe(0, false).verdict, FingertipSequenceVerdict::in_order);  // wraps
  const FingertipSequenceResult wrap_gap = t.observe(3, false);
  EXPECT_EQ(wrap_gap.verdict, FingertipSequenceVerdict::gap);
  EXPECT_EQ(wrap_gap.lost, 2u);
  EXPECT_EQ(t.observe(3, false).verdict, FingertipSequenceVerdict::stale);      // duplicate
  EXPECT_EQ(t.observe(65535, false).verdict, FingertipSequenceVerdict::stale);  // reordered, older
  EXPECT_FALSE(t.observe(2, false).accepted());
  EXPECT_EQ(t.observe(100, true).verdict, FingertipSequenceVerdict::restart);
  EXPECT_EQ(t.newest(), 100);
}

TEST(FingertipSequence, ASenderThatRestartedSilentlyIsResynchronised) {
  FingertipSequenceTracker t;
  (void)t.observe(10000, false);
  std::uint16_t seq = 0;  // restarted at 0 without saying so: looks older than 10000
  for (std::uint32_t i = 1; i < kFingertipResyncAfterStale; ++i) {
    EXPECT_EQ(t.observe(seq++, false).verdict, FingertipSequenceVerdict::stale) << i;
  }
  EXPECT_EQ(t.observe(seq++, false).verdict, FingertipSequenceVerdict::resync);
  EXPECT_EQ(t.observe(seq++, false).verdict, FingertipSequenceVerdict::in_order);
}

TEST(FingertipSequence, FeedbackStreamCountsEveryKindOfFailure) {
  FingertipFeedbackStream stream;
  FingertipFeedback out;
  FingertipFeedback f = sample_feedback();
  auto push = [&](std::uint16_t seq, std::uint16_t status = 0) {
    f.sequence = seq;
    f.status = status;
    return stream.push(encode_fingertip_feedback(f), out);
  };
  EXPECT_TRUE(push(10, fingertip_status::device_start).accepted());
  EXPECT_TRUE(push(11).accepted());
  EXPECT_EQ(out.sequence, 11);
  EXPECT_TRUE(push(15).accepted());  // 12-14 lost
  EXPECT_FALSE(push(15).accepted());  // duplicate
  EXPECT_EQ(out.sequence, 15);
  Report crc = encode_fingertip_feedback(f);
  crc[20] ^= 1;
  EXPECT_EQ(stream.push(crc, out).decode.code, FingertipDecodeErrc::crc_mismatch);
  Report version = encode_fingertip_feedback(f);
  version[1] = 0x30;
  fix_crc(version);
  EXPECT_EQ(stream.push(version, out).decode.code, FingertipDecodeErrc::unsupported_version);
  const std::array<std::uint8_t, 3> runt{0x41, 0x10, 0};
  EXPECT_EQ(stream.push(runt, out).decode.code, FingertipDecodeErrc::bad_length);
  EXPECT_TRUE(push(3, fingertip_status::device_start).accepted());  // the device rebooted
  const FingertipLinkCounters& c = stream.counters();
  EXPECT_EQ(c.received, 8u);
  EXPECT_EQ(c.accepted, 4u);
  EXPECT_EQ(c.sequence_gaps, 1u);
  EXPECT_EQ(c.lost, 3u);
  EXPECT_EQ(c.stale, 1u);
  EXPECT_EQ(c.crc_failures, 1u);
  EXPECT_EQ(c.bad_versions, 1u);
  EXPECT_EQ(c.malformed, 1u);
  EXPECT_EQ(c.restarts, 1u);
  EXPECT_EQ(c.by_error[static_cast<std::size_t>(FingertipDecodeErrc::bad_length)], 1u);
}

TEST(FingertipSequence, CommandStreamHonoursSequenceReset) {
  FingertipCommandStream stream;
  FingertipCommand out;
  FingertipCommand c = sample_command();
  c.flags = fingertip_command_flags::enable;
  c.sequence = 500;
  EXPECT_TRUE(stream.push(encode_fingertip_command(c), out).accepted());
  c.sequence = 499;
  EXPECT_FALSE(stream.push(encode_fingertip_command(c), out).accepted());
  EXPECT_EQ(out.sequence, 500);
  c.sequence = 1;  // a new host session
  c.flags |= fingertip_command_flags::sequence_reset;
  const FingertipStreamResult r = stream.push(encode_fingertip_command(c), out);
  EXPECT_TRUE(r.accepted());
  EXPECT_EQ(r.sequence.verdict, FingertipSequenceVerdict::restart);
  EXPECT_EQ(out.sequence, 1);
  EXPECT_EQ(stream.counters().stale, 1u);
}

}  // namespace
}  // namespace proprio::devices
