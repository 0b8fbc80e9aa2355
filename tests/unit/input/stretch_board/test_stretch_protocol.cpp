// The stretch read-out board's HID wire protocol (codec) and the stream
// decoder that tracks measurement numbers, timestamps and flagged readings.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <set>
#include <string>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"
#include "proprio/stretch_board/stretch_stream.hpp"
#include "support/devices.hpp"

// A namespace of this file's own: its helpers share names with the glove
// protocol tests' (Feed, Decoded, valid_report, ...) in the unity build.
namespace proprio::devices::stretch_protocol_test {
namespace {

using Bytes = std::vector<std::uint8_t>;

using proprio::testing_support::bytes_of;

std::uint32_t le32(const Bytes& b, std::size_t at) {
  return static_cast<std::uint32_t>(b[at]) | static_cast<std::uint32_t>(b[at + 1]) << 8 |
         static_cast<std::uint32_t>(b[at + 2]) << 16 | static_cast<std::uint32_t>(b[at + 3]) << 24;
}

// Recomputes the CRC after a test edited the bytes, so the edit reaches the field checks.
void fix_crc(Bytes& b) {
  const std::uint16_t crc = hid::crc16_ccitt(std::span(b).first(b.size() - 2));
  b[b.size() - 2] = static_cast<std::uint8_t>(crc);
  b[b.size() - 1] = static_cast<std::uint8_t>(crc >> 8);
}

StretchDataReport random_report(Rng& rng) {
  StretchDataReport r;
  r.top_strips = static_cast<std::uint8_t>(1 + rng.below(kStretchMaxStrips));
  r.bottom_strips = static_cast<std::uint8_t>(1 + rng.below(kStretchMaxStrips));
  r.count = static_cast<std::uint8_t>(1 + rng.below(kStretchMeasurementsPerReport));
  r.sequence = static_cast<std::uint32_t>(rng.next_u64());
  r.timestamp_us = static_cast<std::uint32_t>(rng.next_u64());
  r.flags = static_cast<std::uint8_t>(rng.below(4));
  for (std::size_t i = 0; i < r.count; ++i) {
    auto& m = r.measurements[i];
    m.combination = static_cast<std::uint16_t>(rng.below(r.combination_count()));
    m.status = static_cast<StretchMeasurementStatus>(rng.below(4));
    m.value = static_cast<std::uint32_t>(rng.below(kStretchMaxCapacitanceCount + 1));
  }
  return r;
}

// ---------------------------------------------------------------------------
// Layout

TEST(StretchProtocol, DataReportBytesFollowTheDocumentedLayout) {
  StretchDataReport r;
  r.sequence = 0x12345678;
  r.timestamp_us = 0xDEADBEEF;
  r.flags = stretch_flags::stream_start | stretch_flags::overrun;
  r.count = 3;
  r.top_strips = 13;
  r.bottom_strips = 14;
  r.measurements[0] = {181, StretchMeasurementStatus::ok, 20123};  // 20.123 pF
  r.measurements[1] = {0, StretchMeasurementStatus::saturated, kStretchMaxCapacitanceCount};
  r.measurements[2] = {0xAA, StretchMeasurementStatus::no_signal, 0};
  const auto a = encode_stretch_data_report(r);
  const Bytes b = bytes_of(a);
  ASSERT_EQ(b.size(), 64u);
  EXPECT_EQ(b[0], 0x21);
  EXPECT_EQ(b[1], 0x11);  // version 1.1
  EXPECT_EQ(le32(b, 2), 0x12345678u);
  EXPECT_EQ(b[2], 0x78);  // little-endian
  EXPECT_EQ(le32(b, 6), 0xDEADBEEFu);
  EXPECT_EQ(b[10], 0x03);
  EXPECT_EQ(b[11], 3);
  EXPECT_EQ(b[12], 13);
  EXPECT_EQ(b[13], 14);
  // Measurement u32: combination bits 0-9, status bits 10-11, fF bits 12-31.
  EXPECT_EQ(le32(b, 14), 181u | 0u << 10 | 20123u << 12);
  EXPECT_EQ(le32(b, 18), 0u | 1u << 10 | 0xFFFFFu << 12);
  EXPECT_EQ(le32(b, 22), 0xAAu | 3u << 10);
  const std::uint8_t m0[4] = {0xB5, 0xB0, 0xE9, 0x04};  // 181 + (20123 << 12) = 0x04E9B0B5
  EXPECT_EQ(0, std::memcmp(&b[14], m0, 4));
  for (std::size_t i = 26; i < 62; ++i) EXPECT_EQ(b[i], 0) << i;  // slots past count are zero
  const std::uint16_t crc = hid::crc16_ccitt(std::span(b).first(62));
  EXPECT_EQ(b[62], crc & 0xFF);
  EXPECT_EQ(b[63], crc >> 8);
}

TEST(StretchProtocol, InfoAndCommandBytesFollowTheDocumentedLayout) {
  StretchDeviceInfo info;
  info.firmware = {2, 7, 13};
  info.top_strips = 13;
  info.bottom_strips = 14;
  info.streaming = true;
  info.rate_hz = 960;
  info.full_scale_ff = 1000000;
  info.parasitic_ff = 15250;
  info.last_command_token = 0xA5;
  info.last_command_result = StretchCommandResult::bad_argument;
  info.timestamp_us = 0xFFFFFFF0u;
  const Bytes ib = bytes_of(encode_stretch_info_report(info));
  ASSERT_EQ(ib.size(), 32u);
  const std::uint8_t head[10] = {0x22, 0x11, 2, 7, 13, 13, 14, 1, 0xC0, 0x03};
  EXPECT_EQ(0, std::memcmp(ib.data(), head, 10));
  EXPECT_EQ(le32(ib, 10), 1000000u);
  EXPECT_EQ(le32(ib, 14), 15250u);
  EXPECT_EQ(ib[18], 0xA5);
  EXPECT_EQ(ib[19], 3);
  EXPECT_EQ(le32(ib, 20), 0xFFFFFFF0u);
  for (std::size_t i = 24; i < 30; ++i) EXPECT_EQ(ib[i], 0) << i;
  auto back = decode_stretch_info_report(ib);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(*back, info);
  EXPECT_EQ(back->combination_count(), 182u);

  StretchCommand c;
  c.op = StretchCommandOp::set_rate;
  c.token = 77;
  c.rate_hz = 0x0FA0;
  const Bytes cb = bytes_of(encode_stretch_command(c));
  ASSERT_EQ(cb.size(), 16u);
  const std::uint8_t cmd[6] = {0x30, 0x11, 0x03, 77, 0xA0, 0x0F};
  EXPECT_EQ(0, std::memcmp(cb.data(), cmd, 6));
  for (std::size_t i = 6; i < 14; ++i) EXPECT_EQ(cb[i], 0) << i;
  for (auto op : {StretchCommandOp::start_streaming, StretchCommandOp::stop_streaming, StretchCommandOp::set_rate}) {
    c.op = op;
    auto cback = decode_stretch_command(encode_stretch_command(c));
    ASSERT_TRUE(cback.ok()) << cback.error().message;
    EXPECT_EQ(*cback, c);
  }
  EXPECT_EQ(stretch_report_size_for_id(0x21), 64u);
  EXPECT_EQ(stretch_report_size_for_id(0x22), 32u);
  EXPECT_EQ(stretch_report_size_for_id(0x30), 16u);
  EXPECT_EQ(stretch_report_size_for_id(0x01), 0u);
}

TEST(StretchProtocol, DataReportRoundTripsBitExact) {
  Rng rng(42);
  for (int n = 0; n < 2000; ++n) {
    const StretchDataReport r = random_report(rng);
    const auto bytes = encode_stretch_data_report(r);
    StretchDataReport back;
    const auto s = decode_stretch_data_report(bytes, back);
    ASSERT_TRUE(s.ok()) << describe(s);
    ASSERT_EQ(back, r);
    ASSERT_EQ(encode_stretch_data_report(back), bytes);
  }
}

// ---------------------------------------------------------------------------
// Every error path, with the numbers in the status and a message that says what.

StretchDataReport valid_report() {
  StretchDataReport r;
  r.top_strips = 13;
  r.bottom_strips = 14;
  r.count = 12;
  r.sequence = 9;
  r.timestamp_us = 1000;
  for (std::size_t i = 0; i < 12; ++i) r.measurements[i] = {static_cast<std::uint16_t>(i), {}, 1000};
  return r;
}

TEST(StretchProtocolErrors, EmptyAndWrongLengths) {
  StretchDataReport out;
  auto s = decode_stretch_data_report({}, out);
  EXPECT_EQ(s.code, StretchDecodeErrc::empty);
  const auto good = encode_stretch_data_report(valid_report());
  for (std::size_t len : {1u, 63u}) {
    s = decode_stretch_data_report(std::span(good).first(len), out);
    EXPECT_EQ(s.code, StretchDecodeErrc::bad_length) << len;
    EXPECT_EQ(s.expected, 64u);
    EXPECT_EQ(s.actual, len);
  }
  Bytes longer = bytes_of(good);
  longer.push_back(0);
  s = decode_stretch_data_report(longer, out);
  EXPECT_EQ(s.code, StretchDecodeErrc::bad_length);
  EXPECT_NE(describe(s).find("65 bytes"), std::string::npos) << describe(s);
}

TEST(StretchProtocolErrors, UnknownReportIdNamesTheImuGloveAndVersionIsChecked) {
  StretchDataReport out;
  Bytes b = bytes_of(encode_stretch_data_report(valid_report()));
  b[0] = 0x01;  // the IMU glove's data report
  auto s = decode_stretch_data_report(b, out);
  EXPECT_EQ(s.code, StretchDecodeErrc::unknown_report_id);
  EXPECT_EQ(s.expected, 0x21u);
  EXPECT_EQ(s.actual, 0x01u);
  EXPECT_NE(describe(s).find("IMU glove"), std::string::npos) << describe(s);

  StretchDataReport v2 = valid_report();
  v2.version = 0x20;  // protocol 2.0, with a valid CRC
  s = decode_stretch_data_report(encode_stretch_data_report(v2), out);
  EXPECT_EQ(s.code, StretchDecodeErrc::unsupported_version);
  EXPECT_EQ(s.expected, 1u);
  EXPECT_EQ(s.actual, 0x20u);
  auto result = decode_stretch_data_report(encode_stretch_data_report(v2));
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, Errc::unsupported);
  EXPECT_NE(result.error().message.find("version 2.0"), std::string::npos) << result.error().message;
  EXPECT_NE(result.error().message.find("measurement report (ID 0x21)"), std::string::npos)
      << result.error().message;

  // A newer minor of the same major decodes.
  StretchDataReport v13 = valid_report();
  v13.version = 0x13;
  EXPECT_TRUE(decode_stretch_data_report(encode_stretch_data_report(v13), out).ok());
  EXPECT_EQ(out.version, 0x13);
}

TEST(StretchProtocolErrors, CrcMismatchCarriesBothValues) {
  Bytes b = bytes_of(encode_stretch_data_report(valid_report()));
  b[20] ^= 0x10;
  StretchDataReport out;
  const auto s = decode_stretch_data_report(b, out);
  ASSERT_EQ(s.code, StretchDecodeErrc::crc_mismatch);
  EXPECT_EQ(s.expected, static_cast<std::uint32_t>(b[62] | b[63] << 8));
  EXPECT_EQ(s.actual, hid::crc16_ccitt(std::span(b).first(62)));
  EXPECT_NE(s.expected, s.actual);
  auto result = decode_stretch_data_report(b);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, Errc::parse_error);
  char carried_hex[8], computed_hex[8];
  std::snprintf(carried_hex, sizeof carried_hex, "0x%04x", s.expected);
  std::snprintf(computed_hex, sizeof computed_hex, "0x%04x", s.actual);
  EXPECT_NE(result.error().message.find(carried_hex), std::string::npos) << result.error().message;
  EXPECT_NE(result.error().message.find(computed_hex), std::string::npos) << result.error().message;
}

TEST(StretchProtocolErrors, EverySingleBitFlipIsDetected) {
  for (const Bytes& good : {bytes_of(encode_stretch_data_report(valid_report())),
                            bytes_of(encode_stretch_command(StretchCommand{}))}) {
    for (std::size_t byte = 0; byte < good.size(); ++byte) {
      for (int bit = 0; bit < 8; ++bit) {
        Bytes b = good;
        b[byte] ^= static_cast<std::uint8_t>(1u << bit);
        StretchDataReport r;
        StretchCommand c;
        EXPECT_FALSE(decode_stretch_data_report(b, r).ok() || decode_stretch_command(b, c).ok())
            << "byte " << byte << " bit " << bit;
      }
    }
  }
}

TEST(StretchProtocolErrors, FieldChecksBehindAValidCrc) {
  StretchDataReport out;
  for (int count : {0, 13, 255}) {
    StretchDataReport r = valid_report();
    r.count = static_cast<std::uint8_t>(count);
    Bytes b = bytes_of(encode_stretch_data_report(r));
    const auto s = decode_stretch_data_report(b, out);
    EXPECT_EQ(s.code, StretchDecodeErrc::bad_count) << count;
    EXPECT_EQ(s.actual, static_cast<std::uint32_t>(count));
  }
  for (auto [top, bottom] : {std::pair{0, 14}, {13, 0}, {33, 14}, {13, 200}}) {
    StretchDataReport r = valid_report();
    r.top_strips = static_cast<std::uint8_t>(top);
    r.bottom_strips = static_cast<std::uint8_t>(bottom);
    const auto s = decode_stretch_data_report(encode_stretch_data_report(r), out);
    EXPECT_EQ(s.code, StretchDecodeErrc::bad_strip_count) << top << " x " << bottom;
    EXPECT_EQ(s.expected, static_cast<std::uint32_t>(top));
    EXPECT_EQ(s.actual, static_cast<std::uint32_t>(bottom));
  }
  // A combination beyond 13 x 14 = 182 in the last slot; out is left as it was.
  StretchDataReport r = valid_report();
  r.measurements[11].combination = 182;
  out = StretchDataReport{};
  auto s = decode_stretch_data_report(encode_stretch_data_report(r), out);
  EXPECT_EQ(s.code, StretchDecodeErrc::bad_combination);
  EXPECT_EQ(s.expected, 182u);
  EXPECT_EQ(s.actual, 182u);
  EXPECT_EQ(out, StretchDataReport{});
  EXPECT_NE(describe(s).find("0 to 181"), std::string::npos) << describe(s);
  // Slots past count are not checked (nor decoded): they carry nothing.
  r = valid_report();
  r.count = 4;
  Bytes b = bytes_of(encode_stretch_data_report(r));
  b[14 + 4 * 10] = 0xFF;
  b[14 + 4 * 10 + 1] = 0x03;  // combination 1023 in slot 10
  fix_crc(b);
  ASSERT_TRUE(decode_stretch_data_report(b, out).ok());
  EXPECT_EQ(out.measurements[10], StretchMeasurementRaw{});

  StretchDeviceInfo info;
  info.top_strips = 13;
  info.bottom_strips = 14;
  info.rate_hz = 0;
  auto ir = decode_stretch_info_report(encode_stretch_info_report(info));
  ASSERT_FALSE(ir.ok());
  EXPECT_NE(ir.error().message.find("bad rate 0 measurements/s"), std::string::npos) << ir.error().message;
  info.rate_hz = kStretchMaxRateHz + 1;
  StretchDeviceInfo iout;
  EXPECT_EQ(decode_stretch_info_report(encode_stretch_info_report(info), iout).code, StretchDecodeErrc::bad_rate);
  info.rate_hz = 960;
  info.full_scale_ff = kStretchMaxCapacitanceCount + 1;
  EXPECT_EQ(decode_stretch_info_report(encode_stretch_info_report(info), iout).code, StretchDecodeErrc::bad_full_scale);
  info.full_scale_ff = 0;
  EXPECT_EQ(decode_stretch_info_report(encode_stretch_info_report(info), iout).code, StretchDecodeErrc::bad_full_scale);
  info.full_scale_ff = 500000;
  info.bottom_strips = 0;
  EXPECT_EQ(decode_stretch_info_report(encode_stretch_info_report(info), iout).code,
            StretchDecodeErrc::bad_strip_count);
  // A result code from a newer minor reads as none.
  info.bottom_strips = 14;
  Bytes ib = bytes_of(encode_stretch_info_report(info));
  ib[19] = 9;
  fix_crc(ib);
  ASSERT_TRUE(decode_stretch_info_report(ib, iout).ok());
  EXPECT_EQ(iout.last_command_result, StretchCommandResult::none);

  Bytes cmd = bytes_of(encode_stretch_command({}));
  cmd[2] = 0x04;  // SET_RANGES exists for the IMU glove, not here
  fix_crc(cmd);
  StretchCommand c;
  s = decode_stretch_command(cmd, c);
  EXPECT_EQ(s.code, StretchDecodeErrc::unknown_command);
  EXPECT_EQ(s.actual, 0x04u);
  // A measurement report handed to the command decoder is the wrong report, not garbage.
  EXPECT_EQ(decode_stretch_command(encode_stretch_data_report(valid_report()), c).code,
            StretchDecodeErrc::unknown_report_id);
}

TEST(StretchProtocolErrors, EveryCodeHasANameAndAMessage) {
  std::set<std::string> names;
  for (std::size_t i = 0; i < kStretchDecodeErrcCount; ++i) {
    const StretchDecodeStatus s{static_cast<StretchDecodeErrc>(i), 1, 2};
    EXPECT_STRNE(to_string(s.code), "unknown") << i;
    names.insert(to_string(s.code));
    EXPECT_FALSE(describe(s).empty());
    if (i > 0) {
      EXPECT_NE(to_error(s).message.find("stretch board"), std::string::npos);
    }
  }
  EXPECT_EQ(names.size(), kStretchDecodeErrcCount);
  for (std::size_t i = 0; i < kStretchMeasurementStatusCount; ++i) {
    EXPECT_STRNE(to_string(static_cast<StretchMeasurementStatus>(i)), "unknown");
  }
}

// ---------------------------------------------------------------------------
// Protocol 1.1: single-strip rows

StretchDataReport single_strip_report(std::uint8_t top, std::uint8_t bottom) {
  StretchDataReport r;
  r.top_strips = top;
  r.bottom_strips = bottom;
  r.flags = stretch_flags::single_strips;
  r.count = 12;
  const std::size_t rows = stretch_row_count(top, bottom, true);
  // The last 12 rows: the tail of the pairs (when there are few singles) and every single strip it reaches.
  for (std::size_t i = 0; i < 12; ++i) {
    const std::size_t c = rows >= 12 ? rows - 12 + i : i % rows;
    r.measurements[i] = {static_cast<std::uint16_t>(c), StretchMeasurementStatus::ok,
                         static_cast<std::uint32_t>(1000 + i)};
  }
  return r;
}

TEST(StretchProtocol11, CombinationsBeyondThePairsAreSingleStripsTopFirst) {
  // 3 x 2: pairs 0-5 as (c / 2, c % 2), then T0 T1 T2 B0 B1 as 6-10.
  const std::vector<StretchSources> expected = {{0, 0}, {0, 1}, {1, 0}, {1, 1}, {2, 0}, {2, 1},
                                                {0, kStretchNoStrip}, {1, kStretchNoStrip}, {2, kStretchNoStrip},
                                                {kStretchNoStrip, 0}, {kStretchNoStrip, 1}};
  ASSERT_EQ(stretch_row_count(3, 2, true), expected.size());
  EXPECT_EQ(stretch_row_count(3, 2, false), 6u);
  for (std::size_t c = 0; c < expected.size(); ++c) {
    EXPECT_EQ(stretch_sources(c, 3, 2), expected[c]) << c;
    EXPECT_EQ(stretch_sources(c, 3, 2).single(), c >= 6) << c;
  }
  EXPECT_EQ(stretch_sources(11, 3, 2), StretchSources{});  // beyond the plan: no strips
  EXPECT_EQ(stretch_sources(0, 3, 0), StretchSources{});
}

TEST(StretchProtocol11, DataReportWithSingleStripsRoundTripsAndSaysSo) {
  Rng rng(11);
  for (int n = 0; n < 2000; ++n) {
    StretchDataReport r = random_report(rng);
    // Strip counts whose rows fit the 10-bit field: n k + n + k <= 1024 holds up to 31 x 31.
    r.top_strips = static_cast<std::uint8_t>(1 + rng.below(31));
    r.bottom_strips = static_cast<std::uint8_t>(1 + rng.below(31));
    r.flags = static_cast<std::uint8_t>(rng.below(4) | stretch_flags::single_strips);
    ASSERT_TRUE(r.single_strips());
    const std::size_t pairs = static_cast<std::size_t>(r.top_strips) * r.bottom_strips;
    ASSERT_EQ(r.combination_count(), pairs + r.top_strips + r.bottom_strips);
    for (std::size_t i = 0; i < r.count; ++i) {
      // Half of them single strips.
      r.measurements[i].combination = static_cast<std::uint16_t>(
          i % 2 ? pairs + rng.below(r.top_strips + r.bottom_strips) : rng.below(pairs));
    }
    const auto bytes = encode_stretch_data_report(r);
    EXPECT_EQ(bytes[10] & 0x04, 0x04);
    StretchDataReport back;
    const auto s = decode_stretch_data_report(bytes, back);
    ASSERT_TRUE(s.ok()) << describe(s);
    ASSERT_EQ(back, r);
    ASSERT_TRUE(back.single_strips());
    ASSERT_EQ(encode_stretch_data_report(back), bytes);
  }
  // The very last row of a 12 x 12 array: bottom strip 11 alone, combination 167.
  StretchDataReport r = single_strip_report(12, 12);
  ASSERT_EQ(r.measurements[11].combination, 167u);
  const auto back = decode_stretch_data_report(encode_stretch_data_report(r));
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back->measurements[11].combination, 167u);
  EXPECT_EQ(stretch_sources(167, 12, 12), (StretchSources{kStretchNoStrip, 11}));
}

TEST(StretchProtocol11, InfoReportCarriesTheSingleStripFlag) {
  StretchDeviceInfo info;
  info.top_strips = 12;
  info.bottom_strips = 12;
  info.rate_hz = 960;
  info.streaming = true;
  info.single_strips = true;
  const Bytes b = bytes_of(encode_stretch_info_report(info));
  EXPECT_EQ(b[1], 0x11);
  EXPECT_EQ(b[7], 0x03);  // bit 0 streaming, bit 1 single strips
  auto back = decode_stretch_info_report(b);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(*back, info);
  EXPECT_EQ(back->combination_count(), 168u);
  info.single_strips = false;
  EXPECT_EQ(decode_stretch_info_report(encode_stretch_info_report(info))->combination_count(), 144u);
}

TEST(StretchProtocol11, AVersion10BoardHasNoSingleStripRowsWhateverItsReservedBitsSay) {
  // A 1.0 board: the bit 1.1 calls single_strips was reserved, so it means nothing,
  // and a combination past the pairs is refused with a message that says what is missing.
  StretchDataReport r = single_strip_report(12, 12);
  r.version = 0x10;
  EXPECT_FALSE(r.single_strips());
  EXPECT_EQ(r.combination_count(), 144u);
  StretchDataReport out;
  const auto s = decode_stretch_data_report(encode_stretch_data_report(r), out);
  EXPECT_EQ(s.code, StretchDecodeErrc::bad_combination);
  EXPECT_EQ(s.expected, 144u);
  EXPECT_EQ(s.actual, 156u);  // the first single strip in the report: 168 - 12
  const std::string m = describe(s);
  EXPECT_NE(m.find("bad combination 156"), std::string::npos) << m;
  EXPECT_NE(m.find("0 to 143"), std::string::npos) << m;
  EXPECT_NE(m.find("single_strips flag"), std::string::npos) << m;
  // A 1.1 report without the flag is refused the same way.
  r.version = kStretchProtocolVersion;
  r.flags = 0;
  EXPECT_EQ(decode_stretch_data_report(encode_stretch_data_report(r), out).code, StretchDecodeErrc::bad_combination);
  // The pairs of a 1.0 board decode as they always did.
  r = valid_report();
  r.version = 0x10;
  r.flags = stretch_flags::single_strips;
  ASSERT_TRUE(decode_stretch_data_report(encode_stretch_data_report(r), out).ok());
  EXPECT_FALSE(out.single_strips());
  // A 1.0 info report with bit 1 of its state byte set: no single strips.
  StretchDeviceInfo info;
  info.version = 0x10;
  info.top_strips = 12;
  info.bottom_strips = 12;
  info.rate_hz = 960;
  info.single_strips = true;  // encoded as bit 1 ...
  const Bytes ib = bytes_of(encode_stretch_info_report(info));
  EXPECT_EQ(ib[7] & 0x02, 0x02);
  auto back = decode_stretch_info_report(ib);  // ... which 1.0 reserved
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_FALSE(back->single_strips);
  EXPECT_EQ(back->combination_count(), 144u);
}

TEST(StretchProtocol11, PlansWhoseRowsOverflowTheCombinationFieldAreRefused) {
  // 31 x 31 + 62 = 1023 rows fit; 32 x 31 + 63 = 1055 do not; 32 x 32 pairs alone (1024) still do.
  StretchDataReport r = single_strip_report(31, 31);
  StretchDataReport out;
  ASSERT_TRUE(decode_stretch_data_report(encode_stretch_data_report(r), out).ok());
  EXPECT_EQ(out.measurements[11].combination, 1022u);
  r.top_strips = 32;
  const auto s = decode_stretch_data_report(encode_stretch_data_report(r), out);
  EXPECT_EQ(s.code, StretchDecodeErrc::too_many_rows);
  EXPECT_EQ(s.actual, 1055u);
  const std::string m = describe(s);
  EXPECT_NE(m.find("32 x 31 strips"), std::string::npos) << m;
  EXPECT_NE(m.find("1055"), std::string::npos) << m;
  EXPECT_NE(m.find("1024"), std::string::npos) << m;
  r.flags = 0;
  r.bottom_strips = 32;
  for (auto& mm : r.measurements) mm.combination = 1023;
  EXPECT_TRUE(decode_stretch_data_report(encode_stretch_data_report(r), out).ok());

  StretchDeviceInfo info;
  info.top_strips = 32;
  info.bottom_strips = 32;
  info.rate_hz = 960;
  info.single_strips = true;
  const auto ir = decode_stretch_info_report(encode_stretch_info_report(info));
  ASSERT_FALSE(ir.ok());
  EXPECT_NE(ir.error().message.find("too many rows"), std::string::npos) << ir.error().message;
  EXPECT_NE(ir.error().message.find("device info report"), std::string::npos) << ir.error().message;
}

TEST(StretchStream, SingleStripSamplesNameTheirOneStripAndAPlanChangeIsARestart) {
  StretchStreamDecoder d;
  std::array<StretchSample, kStretchMeasurementsPerReport> out;
  StretchDataReport r = single_strip_report(3, 2);  // 11 rows: 12 measurements wrap to row 0
  r.flags |= stretch_flags::stream_start;
  auto res = d.push(encode_stretch_data_report(r), out);
  ASSERT_EQ(res.verdict, StretchReportVerdict::accepted);
  ASSERT_EQ(res.sample_count, 12u);
  EXPECT_TRUE(d.stats().single_strips);
  for (std::size_t i = 0; i < 12; ++i) {
    const StretchSources src = stretch_sources(out[i].combination, 3, 2);
    EXPECT_EQ(out[i].top_strip, src.top_strip) << i;
    EXPECT_EQ(out[i].bottom_strip, src.bottom_strip) << i;
  }
  EXPECT_EQ(out[6].top_strip, 0);
  EXPECT_EQ(out[6].bottom_strip, kStretchNoStrip);
  EXPECT_EQ(out[10].top_strip, kStretchNoStrip);
  EXPECT_EQ(out[10].bottom_strip, 1);
  // The next report without the flag (firmware reconfigured): a new epoch, not a continuation.
  StretchDataReport pairs = valid_report();
  pairs.top_strips = 3;
  pairs.bottom_strips = 2;
  pairs.sequence = 12;
  pairs.timestamp_us = r.timestamp_us + 12'500;
  for (std::size_t i = 0; i < 12; ++i) pairs.measurements[i].combination = static_cast<std::uint16_t>(i % 6);
  res = d.push(encode_stretch_data_report(pairs), out);
  EXPECT_EQ(res.verdict, StretchReportVerdict::accepted);
  EXPECT_TRUE(res.device_reset);
  EXPECT_FALSE(d.stats().single_strips);

  // A decoder that needs single strips refuses the pairs-only board's reports.
  StretchStreamOptions o;
  o.require_single_strips = true;
  StretchStreamDecoder strict(o);
  EXPECT_EQ(strict.push(encode_stretch_data_report(pairs), out).verdict, StretchReportVerdict::wrong_layout);
  EXPECT_EQ(strict.push(encode_stretch_data_report(r), out).verdict, StretchReportVerdict::accepted);
  EXPECT_EQ(strict.stats().wrong_layout, 1u);
}

// ---------------------------------------------------------------------------
// Units and quantisation

TEST(StretchUnits, QuantisationIsToTheNearestFemtofarad) {
  Rng rng(7);
  double worst = 0.0;
  for (int n = 0; n < 20000; ++n) {
    const double pf = rng.uniform(0.0, 999.0);
    const StretchMeasurementRaw m = quantise_capacitance(5, pf, 1000000);
    ASSERT_EQ(m.status, StretchMeasurementStatus::ok) << pf;
    EXPECT_EQ(m.combination, 5);
    worst = std::max(worst, std::fabs(stretch_count_to_pf(m.value) - pf));
  }
  EXPECT_LE(worst, 0.0005 + 1e-12);
  EXPECT_GT(worst, 0.00045);  // and not finer: a wrong unit would show
  EXPECT_EQ(quantise_capacitance(0, 20.0).value, 20000u);
  EXPECT_DOUBLE_EQ(kStretchWireFullScalePf, 1048.575);
}

TEST(StretchUnits, OutOfRangeReadingsAreFlagged) {
  auto m = quantise_capacitance(3, 500.0, 400000);  // above a 400 pF full scale
  EXPECT_EQ(m.status, StretchMeasurementStatus::saturated);
  EXPECT_EQ(m.value, 400000u);
  m = quantise_capacitance(3, 399.9996, 400000);  // rounds to full scale: saturated too
  EXPECT_EQ(m.status, StretchMeasurementStatus::saturated);
  m = quantise_capacitance(3, 1e300);  // far beyond 32 bits: clamped, not undefined
  EXPECT_EQ(m.status, StretchMeasurementStatus::saturated);
  EXPECT_EQ(m.value, kStretchMaxCapacitanceCount);
  m = quantise_capacitance(3, -0.2);
  EXPECT_EQ(m.status, StretchMeasurementStatus::below_zero);
  EXPECT_EQ(m.value, 0u);
  m = quantise_capacitance(3, -0.0004);  // rounds to 0: a valid zero
  EXPECT_EQ(m.status, StretchMeasurementStatus::ok);
  for (double bad : {std::nan(""), double{INFINITY}, -double{INFINITY}}) {
    m = quantise_capacitance(3, bad);
    EXPECT_EQ(m.status, StretchMeasurementStatus::no_signal);
    EXPECT_EQ(m.value, 0u);
  }
  // A full scale beyond the wire's 20 bits is the wire's.
  EXPECT_EQ(quantise_capacitance(0, 2000.0, 0xFFFFFFFF).value, kStretchMaxCapacitanceCount);

  // The host flags the rail even when the board did not.
  StretchMeasurementRaw quiet{7, StretchMeasurementStatus::ok, kStretchMaxCapacitanceCount};
  EXPECT_EQ(host_status(quiet), StretchMeasurementStatus::saturated);
  quiet.value -= 1;
  EXPECT_EQ(host_status(quiet), StretchMeasurementStatus::ok);
  quiet.status = StretchMeasurementStatus::below_zero;
  EXPECT_EQ(host_status(quiet), StretchMeasurementStatus::below_zero);
}

// ---------------------------------------------------------------------------
// Stream decoder

constexpr double kPeriodUs = 1e6 / 960.0;  // 1041.67 µs

// The value a test board reads for measurement number n: identifies it.
std::uint32_t value_for(std::int64_t n) { return static_cast<std::uint32_t>(1000 + (n * 37) % 900000); }

struct Rep {
  std::uint32_t seq;
  std::uint32_t ts;
  std::uint8_t flags = 0;
  std::uint8_t count = 12;
  std::uint8_t top = 13;
  std::uint8_t bottom = 14;
};

// A report as the board sends it: measurement seq + i measures combination
// (seq + i) mod (top x bottom), and reads value_for(seq + i) fF.
Bytes report(Rep r) {
  StretchDataReport d;
  d.sequence = r.seq;
  d.timestamp_us = r.ts;
  d.flags = r.flags;
  d.count = r.count;
  d.top_strips = r.top;
  d.bottom_strips = r.bottom;
  for (std::size_t i = 0; i < r.count; ++i) {
    const std::uint32_t n = r.seq + static_cast<std::uint32_t>(i);
    d.measurements[i] = {static_cast<std::uint16_t>(n % (r.top * r.bottom)), {}, value_for(n)};
  }
  return bytes_of(encode_stretch_data_report(d));
}

// Report k of an evenly paced run: 12 measurements each.
std::uint32_t ts_of(std::int64_t measurement, std::uint32_t ts0 = 5000) {
  return static_cast<std::uint32_t>(ts0 + static_cast<std::int64_t>(std::llround(measurement * kPeriodUs)));
}
Bytes nth(std::int64_t k, std::uint8_t flags = 0) {
  return report({static_cast<std::uint32_t>(12 * k), ts_of(12 * k), flags});
}

struct Feed {
  explicit Feed(StretchStreamOptions o = {}) : decoder(o) {}
  StretchStreamDecoder decoder;
  std::array<StretchSample, 12> samples{};
  std::vector<StretchPushResult> results;
  StretchPushResult push(const Bytes& b, TimeNs rx = 0) {
    results.push_back(decoder.push(b, samples, rx));
    return results.back();
  }
  const StretchStreamStats& stats() const { return decoder.stats(); }
};

TEST(StretchStream, InOrderStreamIsAllAcceptedAndMeasuresThePeriod) {
  Feed f;
  for (int k = 0; k < 500; ++k) f.push(nth(k, k == 0 ? stretch_flags::stream_start : 0));
  const auto& s = f.stats();
  EXPECT_EQ(s.reports, 500u);
  EXPECT_EQ(s.accepted, 500u);
  EXPECT_EQ(s.lost, 0u);
  EXPECT_EQ(s.gaps, 0u);
  EXPECT_EQ(s.duplicates, 0u);
  EXPECT_EQ(s.device_resets, 0u);
  EXPECT_EQ(s.measurements, 6000u);
  EXPECT_EQ(s.measurements_good(), 6000u);
  EXPECT_EQ(s.top_strips, 13);
  EXPECT_EQ(s.bottom_strips, 14);
  EXPECT_NEAR(s.measurement_period_us, kPeriodUs, 0.01);
}

TEST(StretchStream, SamplesCarryCombinationValueAndTheirOwnDeviceTime) {
  Feed f;
  f.push(nth(0, stretch_flags::stream_start), 111);
  const auto r = f.push(nth(16), 777);  // 15 reports lost on the way: 180 measurements
  ASSERT_EQ(r.verdict, StretchReportVerdict::accepted);
  ASSERT_EQ(r.sample_count, 12u);
  EXPECT_EQ(f.stats().lost, 180u);
  EXPECT_EQ(f.stats().gaps, 1u);
  for (std::size_t i = 0; i < 12; ++i) {
    const StretchSample& s = f.samples[i];
    const std::int64_t n = 192 + static_cast<std::int64_t>(i);
    EXPECT_EQ(s.sequence, n);
    EXPECT_EQ(s.combination, n % 182);
    EXPECT_EQ(s.top_strip, (n % 182) / 14);
    EXPECT_EQ(s.bottom_strip, (n % 182) % 14);
    EXPECT_DOUBLE_EQ(s.capacitance_pf, value_for(n) * 1e-3);
    EXPECT_EQ(s.status, StretchMeasurementStatus::ok);
    EXPECT_EQ(s.receive_ns, 777);
    EXPECT_EQ(s.epoch, 0u);
    // Measurement i is i periods after measurement 0 (the nominal period: a
    // 192-measurement gap is too long to measure it from).
    EXPECT_NEAR(static_cast<double>(s.device_time_us), 5000 + n * kPeriodUs, 1.0) << i;
  }
  EXPECT_EQ(r.device_time_us, f.samples[0].device_time_us);
  EXPECT_EQ(r.last_device_time_us, f.samples[11].device_time_us);
}

TEST(StretchStream, BatchSizesMayVaryAndGapsCountMeasurements) {
  Feed f;
  std::uint32_t n = 0;
  std::uint64_t dropped = 0;
  Rng rng(3);
  for (int k = 0; k < 400; ++k) {
    const auto count = static_cast<std::uint8_t>(1 + rng.below(12));
    const Bytes b = report({n, ts_of(n), 0, count});
    if (k % 7 == 3) {
      dropped += count;
    } else {
      ASSERT_EQ(f.push(b).verdict, StretchReportVerdict::accepted);
    }
    n += count;
  }
  // The last report was not dropped, so every gap is closed.
  EXPECT_EQ(f.stats().lost, dropped);
  EXPECT_EQ(f.stats().device_resets, 0u);
  EXPECT_EQ(f.stats().measurements + dropped, n);
}

TEST(StretchStream, DuplicatesAndReorderedReportsAreDroppedAndCounted) {
  Feed f;
  for (int k = 0; k < 30; ++k) f.push(nth(k));
  // Report 31 overtakes 30; 29 comes again.
  EXPECT_EQ(f.push(nth(31)).verdict, StretchReportVerdict::accepted);
  EXPECT_EQ(f.stats().lost, 12u);  // report 30 looks lost for now
  EXPECT_EQ(f.push(nth(30)).verdict, StretchReportVerdict::late);
  EXPECT_EQ(f.stats().lost, 0u);  // ... until it turns up
  EXPECT_EQ(f.push(nth(31)).verdict, StretchReportVerdict::duplicate);
  EXPECT_EQ(f.push(nth(29)).verdict, StretchReportVerdict::duplicate);
  EXPECT_EQ(f.push(nth(30)).verdict, StretchReportVerdict::duplicate);  // the late one, again
  EXPECT_EQ(f.push(nth(32)).verdict, StretchReportVerdict::accepted);
  const auto& s = f.stats();
  EXPECT_EQ(s.duplicates, 3u);
  EXPECT_EQ(s.late, 1u);
  EXPECT_EQ(s.lost, 0u);
  EXPECT_EQ(s.device_resets, 0u);
  // No measurements from dropped reports: the late report's would have gone back in time.
  EXPECT_EQ(s.measurements, 32u * 12u);
}

// A reference model of what the decoder must count, run against random
// drops, duplicates and reorders (within the 1024-measurement window).
TEST(StretchStream, CountsMatchAReferenceModelUnderRandomFaults) {
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    Rng rng(seed);
    struct Item {
      int report;
      Bytes bytes;
    };
    std::vector<Item> wire;
    const int reports = 3000;
    for (int k = 0; k < reports; ++k) {
      if (k > 0 && rng.uniform01() < 0.05) continue;  // lost (never the very first)
      wire.push_back({k, nth(k)});
      if (rng.uniform01() < 0.03) wire.push_back(wire.back());
    }
    for (std::size_t i = 4; i + 4 < wire.size(); ++i) {
      if (rng.uniform01() < 0.03) std::swap(wire[i], wire[i + 1 + rng.below(4)]);
    }
    // Reference: the newest report seen and the set seen.
    std::uint64_t dup = 0, late = 0, acc = 0;
    std::set<int> seen;
    int newest = -1;
    for (const Item& it : wire) {
      if (seen.count(it.report)) {
        ++dup;
      } else if (it.report < newest) {
        ++late;
        seen.insert(it.report);
      } else {
        ++acc;
        seen.insert(it.report);
        newest = it.report;
      }
    }
    const std::uint64_t lost = 12u * (static_cast<std::uint64_t>(newest + 1) - seen.size());

    Feed f;
    for (const Item& it : wire) f.push(it.bytes);
    const auto& st = f.stats();
    SCOPED_TRACE("seed " + std::to_string(seed));
    EXPECT_EQ(st.accepted, acc);
    EXPECT_EQ(st.duplicates, dup);
    EXPECT_EQ(st.late, late);
    EXPECT_EQ(st.lost, lost);
    EXPECT_EQ(st.device_resets, 0u);
    EXPECT_EQ(st.measurements, 12u * acc);
    EXPECT_GT(dup + late, 0u);
  }
}

TEST(StretchStream, SequenceAndTimestampWrapsUnwrap) {
  Feed f;
  // The counter starts 60 measurements before its wrap, the µs counter 50 ms before its own.
  const std::uint32_t seq0 = 0xFFFFFFFFu - 59u;
  const std::uint32_t ts0 = 0xFFFFFFFFu - 50000u;
  std::int64_t previous = -1;
  for (int k = 0; k < 100; ++k) {
    const std::int64_t n = 12 * k;
    const Bytes b = report({static_cast<std::uint32_t>(seq0 + n), ts_of(n, ts0)});
    const auto r = f.push(b);
    ASSERT_EQ(r.verdict, StretchReportVerdict::accepted) << k;
    EXPECT_EQ(r.sequence, static_cast<std::int64_t>(seq0) + n);
    EXPECT_EQ(r.device_time_us, static_cast<std::int64_t>(ts0) + std::llround(n * kPeriodUs));
    EXPECT_EQ(static_cast<std::uint32_t>(f.samples[0].device_time_us), ts_of(n, ts0));  // equal modulo 2^32
    EXPECT_GT(r.device_time_us, previous);
    previous = f.samples[11].device_time_us;
  }
  EXPECT_EQ(f.stats().sequence_wraps, 1u);
  EXPECT_EQ(f.stats().timestamp_wraps, 1u);
  EXPECT_EQ(f.stats().lost, 0u);
  EXPECT_EQ(f.stats().device_resets, 0u);
}

TEST(StretchStream, SilenceLongerThanTheMicrosecondCounterWrapIsResolvedByTheSequence) {
  Feed f;
  for (int k = 0; k < 10; ++k) f.push(nth(k));
  // 100 minutes of silence (the host stopped reading; the board went on):
  // the µs counter wrapped once and the 32-bit difference alone would place
  // the report 28.4 minutes after the last.
  const std::int64_t n = 12 * 9 + std::llround(6000e6 / kPeriodUs / 12) * 12;
  const auto r = f.push(report({static_cast<std::uint32_t>(n), ts_of(n)}));
  EXPECT_EQ(r.verdict, StretchReportVerdict::accepted);
  EXPECT_FALSE(r.device_reset);
  EXPECT_EQ(r.sequence, n);
  EXPECT_EQ(r.device_time_us, 5000 + std::llround(n * kPeriodUs));
  EXPECT_EQ(f.stats().timestamp_wraps, 1u);
  EXPECT_EQ(f.stats().lost, static_cast<std::uint64_t>(n - 120));
  f.push(report({static_cast<std::uint32_t>(n + 12), ts_of(n + 12)}));
  EXPECT_EQ(f.stats().device_resets, 0u);
}

TEST(StretchStream, FlaggedRestartBeginsANewEpochOnce) {
  Feed f;
  for (int k = 0; k < 50; ++k) f.push(report({static_cast<std::uint32_t>(12 * k), ts_of(12 * k, 1000000)}));
  // Power cycle: counter and sequence start again.
  const auto r0 = f.push(nth(0, stretch_flags::stream_start));
  EXPECT_EQ(r0.verdict, StretchReportVerdict::accepted);
  EXPECT_TRUE(r0.device_reset);
  EXPECT_EQ(r0.epoch, 1u);
  EXPECT_EQ(f.push(nth(0, stretch_flags::stream_start)).verdict, StretchReportVerdict::duplicate);
  for (int k = 1; k < 20; ++k) f.push(nth(k));
  const auto& s = f.stats();
  EXPECT_EQ(s.device_resets, 1u);
  EXPECT_EQ(s.lost, 0u);
  EXPECT_EQ(s.duplicates, 1u);
  EXPECT_EQ(f.samples[0].epoch, 1u);
}

TEST(StretchStream, ARestartStampedExactlyLikeTheFirstIsStillARestart) {
  for (bool with_receive_times : {false, true}) {
    SCOPED_TRACE(with_receive_times ? "receive times" : "no receive times");
    Feed f;
    // Deterministic firmware: every boot's first report is sequence 0 at counter 5000.
    TimeNs rx = with_receive_times ? 1'000'000 : 0;
    for (int boot = 0; boot < 2; ++boot) {
      for (int k = 0; k < 100; ++k) {
        f.push(nth(k, k == 0 ? stretch_flags::stream_start : 0), rx);
        if (with_receive_times) rx += 12'500'000;
      }
    }
    EXPECT_EQ(f.stats().device_resets, 1u);
    EXPECT_EQ(f.stats().accepted, 200u);
    EXPECT_EQ(f.stats().duplicates, 0u);
  }
}

TEST(StretchStream, UnflaggedRestartIsInferredFromSequenceAndClockDisagreeing) {
  Feed f;
  for (int k = 0; k < 50; ++k) f.push(report({static_cast<std::uint32_t>(12 * k), ts_of(12 * k, 1000000)}));
  // The flagged first report was lost; the second of the new run arrives.
  const auto r = f.push(nth(1));
  EXPECT_TRUE(r.device_reset);
  for (int k = 2; k < 10; ++k) f.push(nth(k));
  EXPECT_EQ(f.stats().device_resets, 1u);
  EXPECT_EQ(f.stats().lost, 0u);  // nothing is counted across a restart
}

TEST(StretchStream, AClockThatStopsAgreeingWithTheSequenceIsARestart) {
  Feed f;
  for (int k = 0; k < 50; ++k) f.push(nth(k));
  // Timestamp jitter of 3 periods is not a restart ...
  f.push(report({12 * 50, ts_of(12 * 50) + 3 * 1042}));
  f.push(nth(51));
  EXPECT_EQ(f.stats().device_resets, 0u);
  EXPECT_EQ(f.stats().lost, 0u);
  // ... but the next report with the clock a second ahead is not the same run.
  f.push(report({12 * 52, ts_of(12 * 52) + 1000000}));
  EXPECT_EQ(f.stats().device_resets, 1u);
}

TEST(StretchStream, StripCountChangeIsARestart) {
  Feed f;
  for (int k = 0; k < 10; ++k) f.push(nth(k));
  const auto r = f.push(report({120, ts_of(120), 0, 12, 12, 12}));
  EXPECT_TRUE(r.device_reset);
  EXPECT_EQ(f.stats().top_strips, 12);
  EXPECT_EQ(f.stats().bottom_strips, 12);
  EXPECT_EQ(f.samples[0].top_strip, (120 % 144) / 12);
}

TEST(StretchStream, ABoardWithOtherStripCountsThanTheLayoutIsRefused) {
  StretchStreamOptions o;
  o.expected_top_strips = 13;
  o.expected_bottom_strips = 14;
  Feed f(o);
  EXPECT_EQ(f.push(nth(0)).verdict, StretchReportVerdict::accepted);
  const auto r = f.push(report({12, ts_of(12), 0, 12, 12, 12}));
  EXPECT_EQ(r.verdict, StretchReportVerdict::wrong_layout);
  EXPECT_EQ(r.sample_count, 0u);
  EXPECT_EQ(f.push(nth(2)).verdict, StretchReportVerdict::accepted);
  EXPECT_EQ(f.stats().wrong_layout, 1u);
  EXPECT_EQ(f.stats().device_resets, 0u);
  EXPECT_EQ(f.stats().measurements, 24u);
}

TEST(StretchStream, AttachingMidStreamCountsNoLoss) {
  Feed f;
  for (int k = 500; k < 600; ++k) f.push(nth(k));
  EXPECT_EQ(f.stats().lost, 0u);
  EXPECT_EQ(f.stats().device_resets, 0u);
  EXPECT_EQ(f.results.front().sequence, 6000);
}

TEST(StretchStream, FlaggedAndRailMeasurementsAreCounted) {
  Feed f;
  StretchDataReport d;
  d.top_strips = 2;
  d.bottom_strips = 3;
  d.count = 5;
  d.measurements[0] = {0, StretchMeasurementStatus::saturated, 400000};
  d.measurements[1] = {1, StretchMeasurementStatus::below_zero, 0};
  d.measurements[2] = {2, StretchMeasurementStatus::no_signal, 0};
  d.measurements[3] = {3, StretchMeasurementStatus::ok, kStretchMaxCapacitanceCount};  // at the rail, unflagged
  d.measurements[4] = {3, StretchMeasurementStatus::ok, 12345};
  const auto res = f.push(bytes_of(encode_stretch_data_report(d)));
  ASSERT_EQ(res.sample_count, 5u);
  EXPECT_EQ(f.samples[0].status, StretchMeasurementStatus::saturated);
  EXPECT_DOUBLE_EQ(f.samples[0].capacitance_pf, 400.0);
  EXPECT_EQ(f.samples[1].status, StretchMeasurementStatus::below_zero);
  EXPECT_EQ(f.samples[2].status, StretchMeasurementStatus::no_signal);
  EXPECT_EQ(f.samples[3].status, StretchMeasurementStatus::saturated);
  EXPECT_EQ(f.samples[4].status, StretchMeasurementStatus::ok);
  EXPECT_EQ(f.samples[3].top_strip, 1);
  EXPECT_EQ(f.samples[3].bottom_strip, 0);
  const auto& s = f.stats();
  EXPECT_EQ(s.by_status[1], 2u);
  EXPECT_EQ(s.by_status[2], 1u);
  EXPECT_EQ(s.by_status[3], 1u);
  EXPECT_EQ(s.measurements_good(), 1u);
  EXPECT_EQ(s.measurements_flagged(), 4u);
  EXPECT_EQ(s.flagged_by_combination[3], 1u);
  EXPECT_EQ(s.flagged_by_combination[4], 0u);
}

TEST(StretchStream, DecodeErrorsOtherReportsAndOverrunsAreCounted) {
  Feed f;
  f.push(nth(0));
  Bytes bad = nth(1);
  bad[30] ^= 1;
  EXPECT_EQ(f.push(bad).verdict, StretchReportVerdict::decode_error);
  EXPECT_EQ(f.results.back().decode.code, StretchDecodeErrc::crc_mismatch);
  EXPECT_EQ(f.push(Bytes(64, 0)).verdict, StretchReportVerdict::decode_error);  // report ID 0
  EXPECT_EQ(f.push(Bytes{}).verdict, StretchReportVerdict::decode_error);
  StretchDeviceInfo info;
  info.top_strips = 13;
  info.bottom_strips = 14;
  info.rate_hz = 960;
  EXPECT_EQ(f.push(bytes_of(encode_stretch_info_report(info))).verdict, StretchReportVerdict::other_report);
  f.push(nth(5, stretch_flags::overrun));
  const auto& s = f.stats();
  EXPECT_EQ(s.decode_errors, 3u);
  EXPECT_EQ(s.decode_errors_by_code[static_cast<std::size_t>(StretchDecodeErrc::crc_mismatch)], 1u);
  EXPECT_EQ(s.decode_errors_by_code[static_cast<std::size_t>(StretchDecodeErrc::unknown_report_id)], 1u);
  EXPECT_EQ(s.decode_errors_by_code[static_cast<std::size_t>(StretchDecodeErrc::empty)], 1u);
  EXPECT_EQ(s.last_decode_error.code, StretchDecodeErrc::empty);
  EXPECT_EQ(s.other_reports, 1u);
  EXPECT_EQ(s.device_overruns, 1u);
  EXPECT_EQ(s.lost, 48u);  // reports 1-4
  EXPECT_EQ(s.reports, s.accepted + s.duplicates + s.late + s.decode_errors + s.other_reports + s.wrong_layout);
}

TEST(StretchStream, SmallOutputSpanIsNeverOverrun) {
  StretchStreamDecoder d;
  std::array<StretchSample, 5> five{};
  const auto r = d.push(nth(0), five);
  EXPECT_EQ(r.verdict, StretchReportVerdict::accepted);
  EXPECT_EQ(r.sample_count, 5u);
  EXPECT_EQ(d.stats().measurements, 12u);  // all counted, five written
}

}  // namespace
}  // namespace proprio::devices::stretch_protocol_test
