#include "proprio/hid/capture_file.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <fstream>
#include <string>
#include <vector>

#include "proprio/hid/crc16.hpp"
#include "support/temp_dir.hpp"

namespace proprio::hid {
namespace capture_file_test {

// A toy protocol: ID 0x01 starts an 8-byte report, ID 0x02 a 5-byte one,
// every other byte is no ID.
std::size_t toy_size(std::uint8_t id) noexcept { return id == 0x01 ? 8 : id == 0x02 ? 5 : 0; }
const CaptureFraming kToy{&toy_size};

using Bytes = std::vector<std::uint8_t>;

// A report with ID `id`, payload bytes seq, seq+1, ... and its CRC.
Bytes report(std::uint8_t id, std::uint8_t seq) {
  Bytes r(toy_size(id));
  r[0] = id;
  for (std::size_t i = 1; i + 2 < r.size(); ++i) r[i] = static_cast<std::uint8_t>(seq + i);
  const std::uint16_t crc = crc16_ccitt(std::span(r).first(r.size() - 2));
  r[r.size() - 2] = static_cast<std::uint8_t>(crc);
  r[r.size() - 1] = static_cast<std::uint8_t>(crc >> 8);
  return r;
}

Bytes reports(std::size_t count, std::uint8_t id = 0x01) {
  Bytes out;
  for (std::size_t i = 0; i < count; ++i) {
    const Bytes r = report(id, static_cast<std::uint8_t>(i * 3));
    out.insert(out.end(), r.begin(), r.end());
  }
  return out;
}

struct Seen {
  std::uint64_t offset;
  std::size_t size;
  bool intact;
  bool operator==(const Seen&) const = default;
};
std::ostream& operator<<(std::ostream& os, const Seen& s) {
  return os << "{" << s.offset << ", " << s.size << (s.intact ? ", intact}" : ", damaged}");
}

struct ReadOut {
  std::vector<Seen> frames;
  CaptureStats stats;
};

ReadOut drain(Result<CaptureReader> reader) {
  ReadOut out;
  EXPECT_TRUE(reader.ok()) << (reader ? "" : reader.error().message);
  if (!reader) return out;
  CaptureFrame f;
  for (;;) {
    auto more = reader->next(f);
    EXPECT_TRUE(more.ok()) << (more ? "" : more.error().message);
    if (!more || !*more) break;
    out.frames.push_back({f.offset, f.bytes.size(), f.intact});
  }
  out.stats = reader->stats();
  return out;
}

ReadOut read_bytes(const Bytes& bytes, std::size_t window = 1u << 20) {
  CaptureReaderOptions o;
  o.window_bytes = window;
  return drain(CaptureReader::from_memory(bytes, kToy, o));
}

void write_file(const std::filesystem::path& p, const Bytes& bytes) {
  std::ofstream(p, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()),
                                           static_cast<std::streamsize>(bytes.size()));
}

TEST(CaptureReader, YieldsEveryReportOfACleanStreamIntact) {
  Bytes b = reports(2);
  const Bytes small = report(0x02, 9);
  b.insert(b.begin() + 8, small.begin(), small.end());
  const ReadOut r = read_bytes(b);
  EXPECT_EQ(r.frames, (std::vector<Seen>{{0, 8, true}, {8, 5, true}, {13, 8, true}}));
  EXPECT_EQ(r.stats.skipped_bytes, 0u);
  EXPECT_EQ(r.stats.damaged_frames, 0u);
  EXPECT_EQ(r.stats.bytes_consumed, b.size());
}

TEST(CaptureReader, SkipsAGarbagePrefixEvenOneThatStartsWithAnId) {
  // 0x01 claims an 8-byte report; neither it nor the "next" one is intact,
  // and the first intact report is 3 bytes on: not whole reports, skipped.
  Bytes b{0x01, 0x33, 0x44};
  const Bytes rest = reports(3);
  b.insert(b.end(), rest.begin(), rest.end());
  const ReadOut r = read_bytes(b);
  EXPECT_EQ(r.frames, (std::vector<Seen>{{3, 8, true}, {11, 8, true}, {19, 8, true}}));
  EXPECT_EQ(r.stats.skipped_bytes, 3u);

  // Bytes that are no ID are skipped one by one.
  Bytes c{0x00, 0xff, 0x7e};
  c.insert(c.end(), rest.begin(), rest.end());
  const ReadOut s = read_bytes(c);
  EXPECT_EQ(s.frames.size(), 3u);
  EXPECT_EQ(s.stats.skipped_bytes, 3u);
}

TEST(CaptureReader, YieldsATornLastReportShortAndDamaged) {
  Bytes b = reports(3);
  b.resize(b.size() - 3);
  const ReadOut r = read_bytes(b);
  EXPECT_EQ(r.frames, (std::vector<Seen>{{0, 8, true}, {8, 8, true}, {16, 5, false}}));
  EXPECT_EQ(r.stats.damaged_frames, 1u);
  EXPECT_EQ(r.stats.skipped_bytes, 0u);
  EXPECT_EQ(r.stats.bytes_consumed, b.size());
}

TEST(CaptureReader, ACorruptedCrcCostsThatReportOnly) {
  Bytes b = reports(4);
  b[8 + 7] ^= 0x10;  // report 1's CRC
  const ReadOut r = read_bytes(b);
  EXPECT_EQ(r.frames, (std::vector<Seen>{{0, 8, true}, {8, 8, false}, {16, 8, true}, {24, 8, true}}));
  EXPECT_EQ(r.stats.damaged_frames, 1u);
  EXPECT_EQ(r.stats.skipped_bytes, 0u);
}

TEST(CaptureReader, KeepsFramingThroughWholeDamagedReports) {
  Bytes b = reports(6);
  for (std::size_t i = 1; i <= 3; ++i) b[i * 8 + 3] ^= 0x01;  // reports 1-3: payloads
  const ReadOut r = read_bytes(b);
  ASSERT_EQ(r.frames.size(), 6u);
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(r.frames[i], (Seen{i * 8, 8, i == 0 || i > 3})) << "report " << i;
  }
  EXPECT_EQ(r.stats.skipped_bytes, 0u);
}

TEST(CaptureReader, SkipsToTheNextIntactReportWhenFramingShifts) {
  Bytes b = reports(5);
  b.erase(b.begin() + 8 + 2, b.begin() + 8 + 5);  // three bytes out of report 1
  const ReadOut r = read_bytes(b);
  // Report 1 is now 5 bytes, and neither it nor the 8 bytes after it frame a
  // report: 5 bytes are not a whole report, so they are skipped.
  EXPECT_EQ(r.frames, (std::vector<Seen>{{0, 8, true}, {13, 8, true}, {21, 8, true}, {29, 8, true}}));
  EXPECT_EQ(r.stats.skipped_bytes, 5u);
  EXPECT_EQ(r.stats.bytes_consumed, b.size());
}

TEST(CaptureReader, EndsAtOnceOnAnEmptyFile) {
  testing_support::TempDir dir;
  write_file(dir / "empty.bin", {});
  const ReadOut r = drain(CaptureReader::open(dir / "empty.bin", kToy));
  EXPECT_TRUE(r.frames.empty());
  EXPECT_EQ(r.stats.bytes_consumed, 0u);
  EXPECT_EQ(r.stats.skipped_bytes, 0u);
}

TEST(CaptureReader, RefusesAFifoAndAMissingFileNamingThem) {
  testing_support::TempDir dir;
  const auto fifo = dir / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  auto r = CaptureReader::open(fifo, kToy);
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, Errc::invalid_argument);
  EXPECT_NE(r.error().message.find("FIFO"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("capture file"), std::string::npos) << r.error().message;
  auto missing = CaptureReader::open(dir / "nope.bin", kToy);
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, Errc::not_found);
  EXPECT_NE(missing.error().message.find("nope.bin"), std::string::npos) << missing.error().message;
}

TEST(CaptureReader, RefusesAFileAboveTheLimitAsReadInputFileDoes) {
  testing_support::TempDir dir;
  write_file(dir / "big.bin", reports(200));  // 1600 bytes
  CaptureReaderOptions o;
  o.max_bytes = 1000;
  auto r = CaptureReader::open(dir / "big.bin", kToy, o);
  ASSERT_FALSE(r);
  auto whole = read_input_file(dir / "big.bin", "capture file", 1000);
  ASSERT_FALSE(whole);
  EXPECT_EQ(r.error().message, whole.error().message);
}

TEST(CaptureReader, RefusesAFramingThatLeavesNoRoomForTheCrc) {
  const CaptureFraming tiny{[](std::uint8_t id) noexcept -> std::size_t { return id == 7 ? 2 : 0; }};
  const Bytes b{7, 0};
  auto r = CaptureReader::from_memory(b, tiny);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("report ID 7"), std::string::npos) << r.error().message;
}

TEST(CaptureReader, ReadsAFileLargerThanItsWindowAsIfWhole) {
  // 4000 reports, a damaged stretch of 100 whole reports (800 bytes, far more
  // than the 16-byte window), a shifted report and garbage.
  Bytes b = reports(4000);
  for (std::size_t i = 1000; i < 1100; ++i) b[i * 8 + 4] ^= 0x40;
  const Bytes garbage{0x01, 0x02, 0x01, 0x99, 0x02, 0x01, 0x01, 0x01, 0x02, 0x02, 0x02};
  b.insert(b.begin() + 3000 * 8, garbage.begin(), garbage.end());
  b.erase(b.begin() + 2000 * 8 + 1, b.begin() + 2000 * 8 + 4);
  testing_support::TempDir dir;
  write_file(dir / "capture.bin", b);

  const ReadOut whole = read_bytes(b);
  CaptureReaderOptions o;
  o.window_bytes = 16;  // raised to nothing more: twice the largest report
  const ReadOut windowed = drain(CaptureReader::open(dir / "capture.bin", kToy, o));
  EXPECT_EQ(windowed.frames, whole.frames);
  EXPECT_EQ(windowed.stats.skipped_bytes, whole.stats.skipped_bytes);
  EXPECT_EQ(windowed.stats.bytes_consumed, b.size());
  EXPECT_EQ(whole.stats.reread_bytes, 0u);
  // The damaged stretch was searched past the window, then read again.
  EXPECT_GE(windowed.stats.reread_bytes, 800u - 16u);
  EXPECT_EQ(whole.stats.damaged_frames, 100u);
  // 4000 reports less the shifted one; the shifted report's 5 bytes and the
  // garbage are skipped.
  EXPECT_EQ(whole.stats.frames, 3999u);
  EXPECT_EQ(whole.stats.skipped_bytes, 5u + garbage.size());
}

TEST(ReadCaptureFile, HandsEveryFrameOverInOrderThenTheStats) {
  testing_support::TempDir dir;
  Bytes b{0x00, 0x00};
  const Bytes rest = reports(3);
  b.insert(b.end(), rest.begin(), rest.end());
  write_file(dir / "c.bin", b);
  std::vector<std::uint64_t> offsets;
  auto stats = read_capture_file(dir / "c.bin", kToy, {}, [&](const CaptureFrame& f) {
    EXPECT_TRUE(f.intact);
    EXPECT_EQ(Bytes(f.bytes.begin(), f.bytes.end()), Bytes(b.begin() + static_cast<std::ptrdiff_t>(f.offset),
                                                           b.begin() + static_cast<std::ptrdiff_t>(f.offset + 8)));
    offsets.push_back(f.offset);
  });
  ASSERT_TRUE(stats) << stats.error().message;
  EXPECT_EQ(offsets, (std::vector<std::uint64_t>{2, 10, 18}));
  EXPECT_EQ(stats->skipped_bytes, 2u);
  EXPECT_EQ(stats->bytes_consumed, b.size());

  auto missing = read_capture_file(dir / "gone.bin", kToy, {}, [](const CaptureFrame&) { FAIL() << "a frame"; });
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("gone.bin"), std::string::npos) << missing.error().message;
}

}  // namespace capture_file_test
}  // namespace proprio::hid
