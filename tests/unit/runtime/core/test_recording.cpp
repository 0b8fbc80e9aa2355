#include "proprio/core/recording.hpp"

#include <gtest/gtest.h>

#include "support/temp_dir.hpp"
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>

namespace proprio {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

// ------------------------------------------------------------------ fixtures and helpers

using proprio::testing_support::TempDir;

Bytes read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
void write_bytes(const fs::path& p, const Bytes& b) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

std::uint64_t bits(double v) { return std::bit_cast<std::uint64_t>(v); }
std::uint32_t bits(float v) { return std::bit_cast<std::uint32_t>(v); }

HandPose make_hand_pose(TimeNs t, Handedness hand, bool velocity, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  HandPose p;
  p.time_ns = t;
  p.hand = hand;
  p.active = true;
  p.has_velocity = velocity;
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    p.T_world_joint[i].q = so3_exp(Vec3(u(rng), u(rng), u(rng)) * 2.0);
    p.T_world_joint[i].p = Vec3(u(rng), u(rng), u(rng));
    p.radius_m[i] = 0.005 + 0.01 * std::abs(u(rng));
    p.flags[i] = static_cast<std::uint8_t>(rng());
    if (velocity) {
      p.linear_velocity_in_world[i] = Vec3(u(rng), u(rng), u(rng));
      p.angular_velocity_in_world[i] = Vec3(u(rng), u(rng), u(rng)) * 10.0;
    }
  }
  return p;
}

void expect_same(const Vec3& a, const Vec3& b) {
  for (int i = 0; i < 3; ++i) EXPECT_EQ(bits(a[i]), bits(b[i]));
}
void expect_same(const Pose& a, const Pose& b) {
  for (int i = 0; i < 4; ++i) EXPECT_EQ(bits(a.q.coeffs()[i]), bits(b.q.coeffs()[i]));
  expect_same(a.p, b.p);
}
void expect_same_doubles(const std::vector<double>& a, const std::vector<double>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_EQ(bits(a[i]), bits(b[i])) << "#" << i;
}
void expect_same(const ImuSample& a, const ImuSample& b) {
  EXPECT_EQ(a.sensor_id, b.sensor_id);
  expect_same(a.accel_mps2, b.accel_mps2);
  expect_same(a.gyro_radps, b.gyro_radps);
  ASSERT_EQ(a.mag_T.has_value(), b.mag_T.has_value());
  if (a.mag_T) expect_same(*a.mag_T, *b.mag_T);
}
void expect_same(const MarkerObservations& a, const MarkerObservations& b) {
  EXPECT_EQ(a.camera_id, b.camera_id);
  ASSERT_EQ(a.markers.size(), b.markers.size());
  for (std::size_t i = 0; i < a.markers.size(); ++i) {
    EXPECT_EQ(a.markers[i].hue, b.markers[i].hue);
    EXPECT_EQ(bits(a.markers[i].u_px), bits(b.markers[i].u_px));
    EXPECT_EQ(bits(a.markers[i].v_px), bits(b.markers[i].v_px));
    EXPECT_EQ(bits(a.markers[i].area_px2), bits(b.markers[i].area_px2));
  }
}
void expect_same(const CapacitanceFrame& a, const CapacitanceFrame& b) { expect_same_doubles(a.values_F, b.values_F); }
void expect_same(const HandPose& a, const HandPose& b) {
  EXPECT_EQ(a.time_ns, b.time_ns);
  EXPECT_EQ(a.hand, b.hand);
  ASSERT_EQ(a.active, b.active);
  if (!a.active) return;
  ASSERT_EQ(a.has_velocity, b.has_velocity);
  EXPECT_EQ(a.flags, b.flags);
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    expect_same(a.T_world_joint[i], b.T_world_joint[i]);
    EXPECT_EQ(bits(a.radius_m[i]), bits(b.radius_m[i]));
    if (a.has_velocity) {
      expect_same(a.linear_velocity_in_world[i], b.linear_velocity_in_world[i]);
      expect_same(a.angular_velocity_in_world[i], b.angular_velocity_in_world[i]);
    }
  }
}
void expect_same(const JointAngles& a, const JointAngles& b) {
  EXPECT_EQ(a.hand, b.hand);
  expect_same_doubles(a.angles_rad, b.angles_rad);
}
void expect_same(const RigidPose& a, const RigidPose& b) { expect_same(a.T_world_body, b.T_world_body); }
void expect_same(const Event& a, const Event& b) { EXPECT_EQ(a.text, b.text); }
void expect_same(const RawBytes& a, const RawBytes& b) { EXPECT_EQ(a.bytes, b.bytes); }

void expect_same(const Record& a, const Record& b) {
  EXPECT_EQ(a.stream, b.stream);
  EXPECT_EQ(a.time_ns, b.time_ns);
  ASSERT_EQ(a.kind(), b.kind());
  std::visit([&](const auto& va) { expect_same(va, std::get<std::decay_t<decltype(va)>>(b.payload)); }, a.payload);
}

Status write_record(RecordingWriter& w, const Record& r) {
  return std::visit(
      [&](const auto& v) -> Status {
        if constexpr (std::is_same_v<std::decay_t<decltype(v)>, HandPose>) {
          return w.write(r.stream, v);
        } else {
          return w.write(r.stream, v, r.time_ns);
        }
      },
      r.payload);
}

struct ReadBack {
  std::vector<Record> records;
  std::vector<Error> errors;
  RecordingSummary summary;
  std::vector<StreamInfo> streams;
};

ReadBack read_all(RecordingReader& reader) {
  ReadBack out;
  for (int guard = 0; guard < 1'000'000; ++guard) {
    auto r = reader.next();
    if (!r) {
      out.errors.push_back(r.error());
      continue;
    }
    if (!*r) break;
    out.records.push_back(std::move(**r));
  }
  out.summary = reader.summary();
  out.streams = reader.streams();
  return out;
}
ReadBack read_all(std::span<const std::uint8_t> bytes) {
  auto reader = RecordingReader::from_bytes(bytes);
  EXPECT_TRUE(reader.ok()) << reader.error().message;
  return reader ? read_all(*reader) : ReadBack{};
}

// Streams and records covering every payload type and awkward values.
struct Session {
  std::vector<std::pair<StreamKind, std::string>> streams;
  std::vector<Record> records;
};

Session every_kind_session() {
  Session s;
  s.streams = {{StreamKind::imu, "imu/0"},
               {StreamKind::markers, "cam/stereo/markers"},
               {StreamKind::capacitance, "glove/right/capacitance"},
               {StreamKind::hand_pose, "hand/right/ground_truth"},
               {StreamKind::joint_angles, "hand/right/joint_angles_ground_truth"},
               {StreamKind::rigid_pose, "head/ground_truth"},
               {StreamKind::event, "events"},
               {StreamKind::raw, "device/glove/raw"}};
  const double nd = std::numeric_limits<double>::denorm_min();
  ImuSample imu{7, Vec3(0.1, -0.0, 9.81), Vec3(1e-300, nd, -3.5), std::nullopt};
  ImuSample imu_mag = imu;
  imu_mag.mag_T = Vec3(2e-5, -4e-5, 3.3e-5);
  MarkerObservations markers{1, {{12, 320.25f, 240.5f, 33.0f}, {200, -0.0f, 1e-30f, 0.0f}, {255, 1e6f, 2.f, 3.f}}};
  CapacitanceFrame cap{{1.5e-12, 0.0, -0.0, 3.25e-11, std::numeric_limits<double>::max()}};
  HandPose inactive;
  inactive.time_ns = 30;
  inactive.hand = Handedness::left;
  JointAngles angles{Handedness::left, {0.1, -0.2, 1.5707963267948966, 0.0}};
  RigidPose head{Pose{so3_exp(Vec3(0.1, 0.2, -0.3)), Vec3(0.0, 1.7, -0.25)}};
  const TimeNs big = std::numeric_limits<TimeNs>::max();
  s.records = {
      {0, -5, imu},
      {0, 10, imu_mag},
      {1, 11, markers},
      {1, 12, MarkerObservations{0, {}}},
      {2, 13, cap},
      {2, 14, CapacitanceFrame{}},
      {3, 20, make_hand_pose(20, Handedness::right, true, 1)},
      {3, 21, make_hand_pose(21, Handedness::right, false, 2)},
      {3, 30, inactive},
      {4, 40, angles},
      {5, 50, head},
      {6, 60, Event{"trial 3 start \xE2\x9C\x93 {\"block\": 2}"}},
      {6, 61, Event{""}},
      {7, big, RawBytes{{0x00, 0xFF, 0x10, 0x00}}},
  };
  return s;
}

void write_session(RecordingWriter& w, const Session& s) {
  for (const auto& [kind, name] : s.streams) {
    ASSERT_TRUE(w.add_stream(kind, name, "{\"source\": \"" + name + "\"}").ok());
  }
  for (const Record& r : s.records) {
    const Status st = write_record(w, r);
    ASSERT_TRUE(st.ok()) << st.error().message;
  }
}

Bytes session_bytes(const fs::path& path, const Session& s) {
  auto w = RecordingWriter::create(path, {.overwrite = true});
  EXPECT_TRUE(w.ok());
  write_session(*w, s);
  EXPECT_TRUE(w->close().ok());
  return read_bytes(path);
}

// 20 HandPose records after one stream definition.
Session pose_session(int n = 20) {
  Session s;
  s.streams = {{StreamKind::hand_pose, "hand/right"}};
  for (int i = 0; i < n; ++i) {
    const TimeNs t = 1'000'000 + i * 11'111'111;
    s.records.push_back({0, t, make_hand_pose(t, Handedness::right, i % 3 == 0, static_cast<std::uint64_t>(i))});
  }
  return s;
}

// Offsets where the file header and then each record end, End included,
// walked through the length fields independently of the reader.
std::vector<std::uint64_t> record_ends(const Bytes& file) {
  std::vector<std::uint64_t> ends{20};
  while (ends.back() + 16 <= file.size()) {
    std::uint64_t len = 0;
    for (int i = 0; i < 4; ++i) len |= std::uint64_t{file[ends.back() + static_cast<std::size_t>(i)]} << (8 * i);
    ends.push_back(ends.back() + 16 + len + 4);
  }
  return ends;
}

// Hand-built files, for what the writer cannot produce.
Bytes file_header(std::uint16_t major, std::uint16_t minor) {
  Bytes h = {0x89, 'P', 'R', 'P', '\r', '\n', 0x1A, '\n'};
  for (int i = 0; i < 2; ++i) h.push_back(static_cast<std::uint8_t>(major >> (8 * i)));
  for (int i = 0; i < 2; ++i) h.push_back(static_cast<std::uint8_t>(minor >> (8 * i)));
  for (const std::uint8_t b : {20, 0, 0, 0}) h.push_back(b);
  const std::uint32_t crc = crc32_ieee(h);
  for (int i = 0; i < 4; ++i) h.push_back(static_cast<std::uint8_t>(crc >> (8 * i)));
  return h;
}
void append_record(Bytes& out, std::uint8_t type, StreamId stream, TimeNs t, const Bytes& payload) {
  Bytes r;
  const auto put = [&](std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) r.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  };
  put(payload.size(), 4);
  put(type, 1);
  put(0, 1);
  put(stream, 2);
  put(static_cast<std::uint64_t>(t), 8);
  r.insert(r.end(), payload.begin(), payload.end());
  put(crc32_ieee(r), 4);
  out.insert(out.end(), r.begin(), r.end());
}
Bytes stream_def(StreamKind kind, const std::string& name) {
  Bytes p(4 + name.size() + 4, 0);  // kind, reserved, name length, name, empty meta
  p[0] = static_cast<std::uint8_t>(kind);
  p[2] = static_cast<std::uint8_t>(name.size());
  std::copy(name.begin(), name.end(), p.begin() + 4);
  return p;
}
// Recomputes the CRC of the record starting at offset (after a test edited it).
void refresh_crc(Bytes& file, std::size_t offset) {
  std::uint32_t len = 0;
  for (int i = 0; i < 4; ++i) len |= static_cast<std::uint32_t>(file[offset + static_cast<std::size_t>(i)]) << (8 * i);
  const std::size_t end = offset + 16 + len;
  const std::uint32_t crc = crc32_ieee(std::span(file).subspan(offset, 16 + len));
  for (int i = 0; i < 4; ++i) file[end + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(crc >> (8 * i));
}

// ------------------------------------------------------------------ CRC

TEST(RecordingCrc, MatchesPublishedCheckValueAndBitwiseReference) {
  const std::string check = "123456789";
  EXPECT_EQ(crc32_ieee(std::span(reinterpret_cast<const std::uint8_t*>(check.data()), check.size())), 0xCBF43926u);
  EXPECT_EQ(crc32_ieee({}), 0u);

  std::mt19937 rng(3);
  Bytes data(300);
  for (auto& b : data) b = static_cast<std::uint8_t>(rng());
  for (std::size_t off = 0; off < 9; ++off) {
    for (std::size_t len = 0; off + len <= data.size(); len += 7) {
      std::uint32_t ref = 0xFFFFFFFFu;  // the textbook bit-at-a-time definition
      for (std::size_t i = off; i < off + len; ++i) {
        ref ^= data[i];
        for (int k = 0; k < 8; ++k) ref = (ref & 1u) ? 0xEDB88320u ^ (ref >> 1) : ref >> 1;
      }
      const auto part = std::span(data).subspan(off, len);
      ASSERT_EQ(crc32_ieee(part), ~ref) << "offset " << off << " length " << len;
      EXPECT_EQ(crc32_ieee(part.subspan(len / 2), crc32_ieee(part.first(len / 2))), ~ref) << "chained";
    }
  }
}

// ------------------------------------------------------------------ round trip

TEST(Recording, RoundTripsEveryPayloadTypeBitExactly) {
  TempDir dir;
  const Session s = every_kind_session();
  const fs::path path = dir / "all.prec";
  {
    auto w = RecordingWriter::create(path);
    ASSERT_TRUE(w.ok()) << w.error().message;
    write_session(*w, s);
    EXPECT_EQ(w->records_written(), s.streams.size() + s.records.size());
    ASSERT_TRUE(w->close().ok());
  }
  auto reader = RecordingReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_EQ(reader->format_major(), kRecordingFormatMajor);
  EXPECT_EQ(reader->format_minor(), kRecordingFormatMinor);
  const ReadBack back = read_all(*reader);
  EXPECT_TRUE(back.errors.empty());
  ASSERT_EQ(back.records.size(), s.records.size());
  for (std::size_t i = 0; i < s.records.size(); ++i) {
    SCOPED_TRACE("record " + std::to_string(i));
    expect_same(back.records[i], s.records[i]);
  }
  ASSERT_EQ(back.streams.size(), s.streams.size());
  for (std::size_t i = 0; i < s.streams.size(); ++i) {
    EXPECT_EQ(back.streams[i].id, i);
    EXPECT_EQ(back.streams[i].kind, s.streams[i].first);
    EXPECT_EQ(back.streams[i].name, s.streams[i].second);
    EXPECT_EQ(back.streams[i].meta, "{\"source\": \"" + s.streams[i].second + "\"}");
  }
  EXPECT_EQ(back.streams[3].records, 3u);
  EXPECT_EQ(reader->find_stream("events")->records, 2u);
  EXPECT_EQ(reader->stream(5)->name, "head/ground_truth");
  EXPECT_EQ(reader->find_stream("nope"), nullptr);
  EXPECT_EQ(back.summary.end, RecordingEnd::clean);
  EXPECT_TRUE(back.summary.clean());
  EXPECT_EQ(back.summary.records, s.streams.size() + s.records.size());
  EXPECT_EQ(back.summary.valid_bytes, fs::file_size(path));
  EXPECT_EQ(back.summary.ignored_bytes, 0u);
}

TEST(Recording, InactiveHandPoseStoresOnlyTimeHandAndFlag) {
  HandPose p = make_hand_pose(99, Handedness::left, true, 5);
  p.active = false;
  TempDir dir;
  auto w = RecordingWriter::create(dir / "a.prec");
  const StreamId id = w->add_stream(StreamKind::hand_pose, "hand/left").value();
  ASSERT_TRUE(w->write(id, p).ok());
  ASSERT_TRUE(w->close().ok());
  const Bytes file = read_bytes(dir / "a.prec");
  const ReadBack back = read_all(file);
  ASSERT_EQ(back.records.size(), 1u);
  const auto& q = std::get<HandPose>(back.records[0].payload);
  EXPECT_EQ(q.time_ns, 99);
  EXPECT_EQ(q.hand, Handedness::left);
  EXPECT_FALSE(q.active);
  EXPECT_TRUE(q.T_world_joint[3].q.coeffs() == Quat::Identity().coeffs());
}

TEST(Recording, WritingTheSameContentTwiceGivesIdenticalBytes) {
  TempDir dir;
  const Session s = every_kind_session();
  const Bytes a = session_bytes(dir / "a.prec", s);
  const Bytes b = session_bytes(dir / "b.prec", s);
  EXPECT_GT(a.size(), 1000u);
  EXPECT_EQ(a, b);
}

TEST(Recording, EmptySessionIsCleanAndReadable) {
  TempDir dir;
  auto w = RecordingWriter::create(dir / "empty.prec");
  ASSERT_TRUE(w.ok());
  ASSERT_TRUE(w->close().ok());
  EXPECT_FALSE(w->is_open());
  EXPECT_TRUE(w->close().ok()) << "closing twice is harmless";
  const ReadBack back = read_all(read_bytes(dir / "empty.prec"));
  EXPECT_TRUE(back.records.empty());
  EXPECT_TRUE(back.summary.clean());
}

TEST(Recording, DestructorAndMoveCloseTheFileCleanly) {
  TempDir dir;
  {
    auto w = RecordingWriter::create(dir / "d.prec");
    RecordingWriter moved = std::move(w.value());
    const StreamId id = moved.add_stream(StreamKind::event, "events").value();
    ASSERT_TRUE(moved.write(id, Event{"x"}, 1).ok());
  }
  const ReadBack back = read_all(read_bytes(dir / "d.prec"));
  EXPECT_EQ(back.records.size(), 1u);
  EXPECT_EQ(back.summary.end, RecordingEnd::clean);
}

// ------------------------------------------------------------------ crash and corruption

TEST(Recording, CrashAfterFlushLeavesEveryFlushedRecordReadable) {
  TempDir dir;
  const fs::path path = dir / "live.prec";
  auto w = RecordingWriter::create(path);
  const Session s = pose_session(5);
  write_session(*w, s);
  ASSERT_TRUE(w->flush().ok());
  // What a crash right now leaves on disk: everything flushed, no End record.
  const Bytes snapshot = read_bytes(path);
  const ReadBack back = read_all(snapshot);
  ASSERT_EQ(back.records.size(), 5u);
  expect_same(back.records[4], s.records[4]);
  EXPECT_EQ(back.summary.end, RecordingEnd::missing_end);
  EXPECT_FALSE(back.summary.clean());
  EXPECT_NE(back.summary.detail.find("no End record"), std::string::npos) << back.summary.detail;
  EXPECT_EQ(back.summary.ignored_bytes, 0u);
}

TEST(Recording, TruncationAtAnyByteReturnsExactlyTheCompleteRecords) {
  TempDir dir;
  const Session s = pose_session(20);
  const Bytes file = session_bytes(dir / "t.prec", s);
  const std::vector<std::uint64_t> ends = record_ends(file);  // header, stream def, 20 poses, End
  ASSERT_EQ(ends.size(), 23u);
  ASSERT_EQ(ends.back(), file.size());

  std::vector<std::uint64_t> cuts;
  for (std::uint64_t c = ends[18]; c < file.size(); ++c) cuts.push_back(c);  // inside the last 3 poses and End
  std::mt19937_64 rng(11);
  for (int i = 0; i < 40; ++i) cuts.push_back(rng() % file.size());

  for (const std::uint64_t cut : cuts) {
    SCOPED_TRACE("cut at byte " + std::to_string(cut));
    const auto prefix = std::span(file).first(cut);
    auto reader = RecordingReader::from_bytes(prefix);
    if (cut < ends[0]) {
      ASSERT_FALSE(reader.ok());
      EXPECT_EQ(reader.error().code, Errc::parse_error);
      continue;
    }
    const ReadBack back = read_all(*reader);
    EXPECT_TRUE(back.errors.empty());
    // Complete records: those whose end lies at or before the cut (minus header and stream def).
    const auto complete = static_cast<std::size_t>(std::upper_bound(ends.begin(), ends.end(), cut) - ends.begin());
    const std::size_t poses = std::min<std::size_t>(complete >= 2 ? complete - 2 : 0, 20);
    ASSERT_EQ(back.records.size(), poses);
    for (std::size_t i = 0; i < poses; ++i) expect_same(back.records[i], s.records[i]);
    const std::uint64_t last_end = ends[complete - 1];
    EXPECT_EQ(back.summary.valid_bytes, last_end);
    EXPECT_EQ(back.summary.ignored_bytes, cut - last_end);
    EXPECT_EQ(back.summary.end, cut == last_end ? RecordingEnd::missing_end : RecordingEnd::truncated);
    EXPECT_FALSE(back.summary.clean());
  }
}

TEST(Recording, TruncatedFileOnDiskReadsUpToItsLastCompleteRecord) {
  TempDir dir;
  const fs::path path = dir / "cut.prec";
  const Bytes file = session_bytes(path, pose_session(6));
  const std::vector<std::uint64_t> ends = record_ends(file);
  fs::resize_file(path, ends[5] + 100);  // 100 bytes into the 5th pose
  auto reader = RecordingReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  const ReadBack back = read_all(*reader);
  EXPECT_EQ(back.records.size(), 4u);
  EXPECT_EQ(back.summary.end, RecordingEnd::truncated);
  EXPECT_EQ(back.summary.ignored_bytes, 100u);
  EXPECT_NE(back.summary.detail.find("file ends inside record #6"), std::string::npos) << back.summary.detail;
  EXPECT_NE(back.summary.detail.find("at byte " + std::to_string(ends[5])), std::string::npos)
      << back.summary.detail;
}

TEST(Recording, FlippedPayloadByteLosesOnlyThatRecord) {
  TempDir dir;
  const Session s = pose_session(10);
  const Bytes file = session_bytes(dir / "c.prec", s);
  const std::vector<std::uint64_t> ends = record_ends(file);
  const std::uint64_t start = ends[7];  // record #8 = pose 6
  Bytes bad = file;
  bad[start + 16 + 500] ^= 0x04;
  const ReadBack back = read_all(bad);
  // Every pose but #6 comes back: the reader resynchronises on the next record.
  ASSERT_EQ(back.records.size(), 9u);
  for (std::size_t i = 0; i < 9; ++i) expect_same(back.records[i], s.records[i < 6 ? i : i + 1]);
  EXPECT_EQ(back.summary.end, RecordingEnd::corrupt);
  EXPECT_FALSE(back.summary.clean());
  EXPECT_NE(back.summary.detail.find("record #8"), std::string::npos) << back.summary.detail;
  EXPECT_NE(back.summary.detail.find("at byte " + std::to_string(start)), std::string::npos) << back.summary.detail;
  EXPECT_NE(back.summary.detail.find("CRC"), std::string::npos) << back.summary.detail;
  EXPECT_NE(back.summary.detail.find("1 records lost"), std::string::npos) << back.summary.detail;
  EXPECT_EQ(back.summary.corrupt_regions, 1u);
  EXPECT_EQ(back.summary.first_corrupt_offset, start);
  EXPECT_EQ(back.summary.skipped_bytes, ends[8] - start);
  EXPECT_EQ(back.summary.lost_records, 1u);
  EXPECT_EQ(back.summary.valid_bytes, file.size() - (ends[8] - start));
  EXPECT_EQ(back.summary.ignored_bytes, ends[8] - start);
}

TEST(Recording, HugeLengthFieldIsCorruptionNotAnAllocation) {
  TempDir dir;
  const Session s = pose_session(3);
  Bytes file = session_bytes(dir / "l.prec", s);
  const std::vector<std::uint64_t> ends = record_ends(file);
  file[ends[2] + 3] = 0x7F;  // length of the 2nd pose ~2 GiB
  const ReadBack back = read_all(file);
  ASSERT_EQ(back.records.size(), 2u);
  expect_same(back.records[1], s.records[2]);
  EXPECT_EQ(back.summary.end, RecordingEnd::corrupt);
  EXPECT_NE(back.summary.detail.find("above the limit"), std::string::npos) << back.summary.detail;
}

// A damaged length field that still fits the size limit used to pass for a
// writer cut off mid-record: half the file ignored, reported as a crash.
TEST(Recording, PlausibleBadLengthMidFileIsCorruptionNotTruncation) {
  TempDir dir;
  const Session s = pose_session(40);
  Bytes file = session_bytes(dir / "m.prec", s);
  const std::vector<std::uint64_t> ends = record_ends(file);
  const std::uint64_t start = ends[11];  // pose 10
  const std::uint64_t len = file.size() - start + 1000;  // past the end of the file, well under 16 MiB
  for (int i = 0; i < 4; ++i) file[start + i] = static_cast<std::uint8_t>(len >> (8 * i));
  const ReadBack back = read_all(file);
  ASSERT_EQ(back.records.size(), 39u);
  expect_same(back.records[10], s.records[11]);
  expect_same(back.records[38], s.records[39]);
  EXPECT_EQ(back.summary.end, RecordingEnd::corrupt);
  EXPECT_NE(back.summary.detail.find("beyond the end of the file"), std::string::npos) << back.summary.detail;
  EXPECT_EQ(back.summary.detail.find("cut off"), std::string::npos) << back.summary.detail;
  EXPECT_EQ(back.summary.lost_records, 1u);
  EXPECT_EQ(back.summary.skipped_bytes, ends[12] - start);
}

TEST(Recording, SeveralDamagedRegionsAreEachSkippedAndCounted) {
  TempDir dir;
  const Session s = pose_session(30);
  const Bytes file = session_bytes(dir / "r.prec", s);
  const std::vector<std::uint64_t> ends = record_ends(file);
  Bytes bad;
  // Junk spliced in before pose 5, and poses 20-22 zeroed (unwritten blocks).
  bad.insert(bad.end(), file.begin(), file.begin() + static_cast<std::ptrdiff_t>(ends[6]));
  std::mt19937_64 rng(3);
  for (int i = 0; i < 777; ++i) bad.push_back(static_cast<std::uint8_t>(rng()));
  bad.insert(bad.end(), file.begin() + static_cast<std::ptrdiff_t>(ends[6]), file.end());
  const std::uint64_t zero_from = ends[21] + 777, zero_to = ends[24] + 777;
  std::fill(bad.begin() + static_cast<std::ptrdiff_t>(zero_from), bad.begin() + static_cast<std::ptrdiff_t>(zero_to), 0);

  const ReadBack back = read_all(bad);
  EXPECT_EQ(back.records.size(), 27u);
  expect_same(back.records.back(), s.records.back());
  EXPECT_EQ(back.summary.end, RecordingEnd::corrupt);
  EXPECT_EQ(back.summary.corrupt_regions, 2u);
  EXPECT_EQ(back.summary.skipped_bytes, 777u + (zero_to - zero_from));
  EXPECT_EQ(back.summary.first_corrupt_offset, ends[6]);
  EXPECT_EQ(back.summary.lost_records, 3u);
  EXPECT_EQ(back.summary.valid_bytes + back.summary.ignored_bytes, bad.size());
  EXPECT_NE(back.summary.detail.find("2 regions"), std::string::npos) << back.summary.detail;
}

TEST(Recording, DamageRunningToTheEndIsCorruptAndCounted) {
  TempDir dir;
  const Session s = pose_session(8);
  Bytes file = session_bytes(dir / "e.prec", s);
  const std::vector<std::uint64_t> ends = record_ends(file);
  for (std::size_t i = ends[5] + 20; i < file.size(); ++i) file[i] ^= 0x5A;
  const ReadBack back = read_all(file);
  EXPECT_EQ(back.records.size(), 4u);
  EXPECT_EQ(back.summary.end, RecordingEnd::corrupt);
  EXPECT_NE(back.summary.detail.find("no intact record after the damage"), std::string::npos) << back.summary.detail;
  EXPECT_EQ(back.summary.skipped_bytes, file.size() - ends[5]);
  EXPECT_EQ(back.summary.valid_bytes + back.summary.ignored_bytes, file.size());
}

// A crafted tail of back-to-back plausible record headers, each claiming a
// ~1 MiB payload that ends on another plausible header: every 16-byte step is a
// candidate worth a 1 MiB CRC, ~200 000 of them, which used to take hours. The
// search is bounded and gives up, saying so.
TEST(Recording, ResyncOverCraftedPlausibleHeadersGivesUpWithinItsBudget) {
  TempDir dir;
  const Session s = pose_session(6);
  Bytes file = session_bytes(dir / "c.prec", s);
  const std::vector<std::uint64_t> ends = record_ends(file);
  file.resize(ends[4]);
  file[ends[3] + 30] ^= 0xFF;  // record #4 fails its CRC: the search starts there
  constexpr std::uint32_t kLen = (1u << 20) - 20;  // header + payload + CRC = 1 MiB: the next header lines up
  static_assert((16 + kLen + 4) % 16 == 0);
  const std::uint8_t fake[16] = {static_cast<std::uint8_t>(kLen), static_cast<std::uint8_t>(kLen >> 8),
                                 static_cast<std::uint8_t>(kLen >> 16), static_cast<std::uint8_t>(kLen >> 24),
                                 2, 0, 7, 0,  // data record, stream 7
                                 0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x08};
  while (file.size() < ends[4] + (4u << 20)) file.insert(file.end(), std::begin(fake), std::end(fake));

  const ReadBack back = read_all(file);
  EXPECT_EQ(back.records.size(), 2u);  // the poses before the damaged one
  EXPECT_EQ(back.summary.end, RecordingEnd::corrupt);
  EXPECT_TRUE(back.summary.resync_gave_up);
  EXPECT_NE(back.summary.detail.find("gave up searching"), std::string::npos) << back.summary.detail;
  // The work done is bounded by the budget, not by (candidates x record length).
  const std::uint64_t budget = kRecordingResyncBudgetFileSizes * file.size() + kRecordingResyncBudgetExtraBytes;
  EXPECT_LE(back.summary.resync_checked_bytes, budget);
  EXPECT_GT(back.summary.resync_checked_bytes, budget - (1u << 20)) << "the search went on until the budget";
  EXPECT_EQ(back.summary.valid_bytes + back.summary.ignored_bytes, file.size());
}

// A plausible header is CRC-checked only when its record ends the file or is
// followed by another plausible header: junk claiming long payloads costs no CRC.
TEST(Recording, ResyncSkipsCandidatesNotFollowedByARecord) {
  TempDir dir;
  const Session s = pose_session(8);
  const Bytes good = session_bytes(dir / "j.prec", s);
  const std::vector<std::uint64_t> ends = record_ends(good);
  Bytes file(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(ends[3]));
  // Junk: headers claiming 1000-byte payloads followed by zeros, then the rest.
  const std::uint8_t fake[16] = {0xE8, 0x03, 0, 0, 2, 0, 7, 0, 1, 2, 3, 4, 5, 6, 7, 8};
  for (int i = 0; i < 200; ++i) file.insert(file.end(), std::begin(fake), std::end(fake));
  file.insert(file.end(), 1024, 0);
  file.insert(file.end(), good.begin() + static_cast<std::ptrdiff_t>(ends[3]), good.end());

  const ReadBack back = read_all(file);
  EXPECT_EQ(back.records.size(), 8u);
  EXPECT_EQ(back.summary.end, RecordingEnd::corrupt);
  EXPECT_EQ(back.summary.corrupt_regions, 1u);
  EXPECT_FALSE(back.summary.resync_gave_up);
  // Only the real record after the junk was CRC-checked (one pose record).
  EXPECT_EQ(back.summary.resync_checked_bytes, ends[4] - ends[3] - 4);
}

TEST(Recording, SeekGoesBackToARecordReadBefore) {
  TempDir dir;
  const Session s = pose_session(6);
  const fs::path path = dir / "k.prec";
  session_bytes(path, s);
  auto reader = RecordingReader::open(path);
  ASSERT_TRUE(reader.ok());
  std::vector<std::uint64_t> offsets;
  while (auto r = reader->next()) {
    if (!*r) break;
    offsets.push_back(reader->last_record_offset());
  }
  ASSERT_EQ(offsets.size(), 6u);
  ASSERT_TRUE(reader->seek(offsets[3]).ok());
  auto again = reader->next();
  ASSERT_TRUE(again.ok() && again->has_value());
  expect_same(**again, s.records[3]);
  EXPECT_EQ(reader->last_record_offset(), offsets[3]);
  EXPECT_FALSE(reader->seek(1).ok());
}

TEST(Recording, AWriterNeverReplacesAFileThisProcessReads) {
  TempDir dir;
  const fs::path path = dir / "in.prec";
  const Bytes original = session_bytes(path, pose_session(3));
  auto reader = RecordingReader::open(path);
  ASSERT_TRUE(reader.ok());
  fs::create_symlink(path, dir / "link.prec");
  for (const fs::path& same : {path, dir / "link.prec", dir / "." / "in.prec"}) {
    SCOPED_TRACE(same.string());
    auto w = RecordingWriter::create(same, {.overwrite = true});
    ASSERT_FALSE(w.ok());
    EXPECT_NE(w.error().message.find("input"), std::string::npos) << w.error().message;
  }
  EXPECT_EQ(read_bytes(path), original);
}

TEST(Recording, ReaderRefusesAFifoWithoutBlocking) {
  TempDir dir;
  const fs::path fifo = dir / "pipe.prec";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  auto reader = RecordingReader::open(fifo);
  ASSERT_FALSE(reader.ok());
  EXPECT_NE(reader.error().message.find("FIFO"), std::string::npos) << reader.error().message;
}

// ------------------------------------------------------------------ time stamps

TEST(TimestampGuard, AnIsolatedFarFutureStampCostsOneSample) {
  TimestampGuard g(kNsPerSecond);
  std::vector<TimeNs> accepted;
  std::size_t rejected = 0;
  TimeNs held = 0;
  const auto feed = [&](TimeNs t) {
    const auto s = g.check(t);
    if (s.release_held) accepted.push_back(held);
    if (s.reject_held) ++rejected;
    if (s.accept) accepted.push_back(t);
    if (s.hold) held = t;
    if (!s.accept && !s.hold) ++rejected;
    return s;
  };
  feed(0);  // held: the first sample waits for the second
  EXPECT_TRUE(feed(10).release_held);
  feed(20);
  EXPECT_TRUE(feed(1'700'000'000'000'000'000).hold);  // a CLOCK_REALTIME stamp
  EXPECT_TRUE(feed(30).reject_held);
  feed(40);
  EXPECT_FALSE(feed(35).accept);  // out of order
  EXPECT_EQ(accepted, (std::vector<TimeNs>{0, 10, 20, 30, 40}));
  EXPECT_EQ(rejected, 2u);
}

TEST(TimestampGuard, APauseConfirmedByTheNextSampleIsKept) {
  TimestampGuard g(kNsPerSecond);
  g.check(0);
  g.check(10);
  EXPECT_TRUE(g.check(100 * kNsPerSecond).hold);
  const auto s = g.check(100 * kNsPerSecond + 10);
  EXPECT_TRUE(s.release_held);
  EXPECT_TRUE(s.accept);
  EXPECT_EQ(g.last_accepted_ns(), 100 * kNsPerSecond + 10);
  // Extreme stamps do not overflow.
  EXPECT_TRUE(g.check(std::numeric_limits<TimeNs>::max()).hold);
  EXPECT_TRUE(g.check(std::numeric_limits<TimeNs>::min()).reject_held);
  EXPECT_FALSE(g.finish());
}

TEST(TimestampGuard, AOneSampleStreamIsAccepted) {
  TimestampGuard g;
  EXPECT_TRUE(g.check(5).hold);
  EXPECT_TRUE(g.finish());
  EXPECT_EQ(g.last_accepted_ns(), 5);
}

TEST(Recording, RemovedRecordIsCaughtByTheEndCount) {
  TempDir dir;
  const Bytes file = session_bytes(dir / "s.prec", pose_session(4));
  const std::vector<std::uint64_t> ends = record_ends(file);
  Bytes spliced(file.begin(), file.begin() + static_cast<std::ptrdiff_t>(ends[2]));
  spliced.insert(spliced.end(), file.begin() + static_cast<std::ptrdiff_t>(ends[3]), file.end());
  const ReadBack back = read_all(spliced);
  EXPECT_EQ(back.records.size(), 3u);
  EXPECT_EQ(back.summary.end, RecordingEnd::corrupt);
  EXPECT_NE(back.summary.detail.find("counts 5 records, but 4 were read"), std::string::npos) << back.summary.detail;
}

TEST(Recording, BytesAfterTheEndRecordAreReported) {
  TempDir dir;
  Bytes file = session_bytes(dir / "g.prec", pose_session(2));
  for (const std::uint8_t b : {1, 2, 3}) file.push_back(b);
  const ReadBack back = read_all(file);
  EXPECT_EQ(back.records.size(), 2u);
  EXPECT_EQ(back.summary.end, RecordingEnd::clean);
  EXPECT_EQ(back.summary.ignored_bytes, 3u);
  EXPECT_FALSE(back.summary.clean());
  EXPECT_NE(back.summary.detail.find("3 bytes after the End record"), std::string::npos);
}

// ------------------------------------------------------------------ headers and versions

TEST(Recording, BadHeadersGiveErrorsThatSayWhatIsWrong) {
  TempDir dir;
  const Bytes good = session_bytes(dir / "good.prec", pose_session(1));
  const auto open_error = [&](const Bytes& bytes) {
    write_bytes(dir / "bad.prec", bytes);
    auto r = RecordingReader::open(dir / "bad.prec");
    EXPECT_FALSE(r.ok());
    return r.ok() ? Error{} : r.error();
  };

  Error e = open_error({});
  EXPECT_EQ(e.code, Errc::parse_error);
  EXPECT_NE(e.message.find("is empty"), std::string::npos) << e.message;
  EXPECT_NE(e.message.find("bad.prec"), std::string::npos) << e.message;

  const std::string text = "time,x,y,z\n0,1,2,3\n1,2,3,4\n";
  e = open_error(Bytes(text.begin(), text.end()));
  EXPECT_NE(e.message.find("not a Proprio recording (bad magic"), std::string::npos) << e.message;

  Bytes mangled = good;  // CR LF -> LF, as a text-mode copy does
  mangled.erase(mangled.begin() + 4);
  e = open_error(mangled);
  EXPECT_NE(e.message.find("text-mode transfer"), std::string::npos) << e.message;

  e = open_error(Bytes(good.begin(), good.begin() + 12));
  EXPECT_NE(e.message.find("cut short inside its file header"), std::string::npos) << e.message;

  Bytes newer = file_header(2, 3);
  append_record(newer, 200, 0, 0, Bytes(10, 0));
  e = open_error(newer);
  EXPECT_EQ(e.code, Errc::unsupported);
  EXPECT_NE(e.message.find("version 2.3, newer than this build supports (1.x)"), std::string::npos) << e.message;
  EXPECT_NE(e.message.find("update Proprio"), std::string::npos) << e.message;

  Bytes damaged = good;
  damaged[15] ^= 0x01;  // header length, caught by the header CRC
  e = open_error(damaged);
  EXPECT_NE(e.message.find("damaged file header"), std::string::npos) << e.message;

  auto missing = RecordingReader::open(dir / "nope.prec");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, Errc::not_found);
  EXPECT_NE(missing.error().message.find("nope.prec"), std::string::npos);

  auto directory = RecordingReader::open(dir / ".");
  ASSERT_FALSE(directory.ok());
  EXPECT_NE(directory.error().message.find("is a directory"), std::string::npos) << directory.error().message;
}

TEST(Recording, NewerMinorVersionIsReadAndUnknownPartsAreSkipped) {
  const auto build = [](std::uint16_t minor) {
    Bytes f = file_header(1, minor);
    append_record(f, 1, 0, 0, stream_def(StreamKind::event, "events"));
    append_record(f, 1, 1, 0, stream_def(static_cast<StreamKind>(200), "future/thing"));
    append_record(f, 2, 1, 5, Bytes{1, 2, 3});  // data of the unknown kind
    append_record(f, 9, 0, 6, Bytes{4, 5});      // unknown record type
    append_record(f, 2, 0, 7, Bytes{'h', 'i'});
    Bytes imu_def = stream_def(StreamKind::joint_angles, "angles");
    append_record(f, 1, 2, 0, imu_def);
    Bytes angles = {1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xF0, 0x3F, 0xAA, 0xBB};  // 1.0, then 2 new bytes
    append_record(f, 2, 2, 8, angles);
    append_record(f, 3, 0xFFFF, 0, Bytes{7, 0, 0, 0, 0, 0, 0, 0});
    return f;
  };

  const ReadBack newer = read_all(build(kRecordingFormatMinor + 1));
  EXPECT_TRUE(newer.errors.empty());
  ASSERT_EQ(newer.records.size(), 2u);
  EXPECT_EQ(std::get<Event>(newer.records[0].payload).text, "hi");
  EXPECT_EQ(std::get<JointAngles>(newer.records[1].payload).angles_rad, std::vector<double>{1.0});
  EXPECT_EQ(newer.summary.skipped_records, 2u);
  EXPECT_EQ(newer.summary.end, RecordingEnd::clean);
  ASSERT_EQ(newer.streams.size(), 3u);
  EXPECT_FALSE(is_known(newer.streams[1].kind));
  EXPECT_EQ(to_string(newer.streams[1].kind), "unknown");

  // In a file of this build's own version, extra payload bytes are a defect.
  const ReadBack same = read_all(build(kRecordingFormatMinor));
  ASSERT_EQ(same.errors.size(), 1u);
  EXPECT_NE(same.errors[0].message.find("2 unexpected bytes"), std::string::npos) << same.errors[0].message;
  EXPECT_EQ(same.records.size(), 1u);
  EXPECT_EQ(same.summary.invalid_records, 1u);
}

// ------------------------------------------------------------------ validation

TEST(Recording, WriterRefusesNonFiniteValuesAndStaysUsable) {
  TempDir dir;
  const fs::path path = dir / "v.prec";
  auto w = RecordingWriter::create(path);
  const StreamId hand = w->add_stream(StreamKind::hand_pose, "hand/right").value();
  const StreamId head = w->add_stream(StreamKind::rigid_pose, "head/ground_truth").value();
  const StreamId imu = w->add_stream(StreamKind::imu, "imu/0").value();
  const StreamId cap = w->add_stream(StreamKind::capacitance, "glove/capacitance").value();
  ASSERT_TRUE(w->flush().ok());
  const auto size_before = fs::file_size(path);

  HandPose p = make_hand_pose(5, Handedness::right, false, 9);
  p.joint(HandJoint::index_tip).p.y() = std::nan("");
  Status st = w->write(hand, p);
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, Errc::invalid_argument);
  EXPECT_NE(st.error().message.find("joint 'index_tip' position has a non-finite value (NaN"), std::string::npos)
      << st.error().message;
  EXPECT_NE(st.error().message.find("hand/right"), std::string::npos) << st.error().message;

  p = make_hand_pose(5, Handedness::right, false, 9);
  p.joint(HandJoint::wrist).q.coeffs() *= 2.0;
  st = w->write(hand, p);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("joint 'wrist' orientation has norm 2"), std::string::npos) << st.error().message;

  st = w->write(head, RigidPose{Pose{Quat::Identity(), Vec3(0, std::numeric_limits<double>::infinity(), 0)}}, 1);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("body position"), std::string::npos) << st.error().message;

  st = w->write(imu, ImuSample{0, Vec3::Zero(), Vec3(0, 0, std::nan("")), std::nullopt}, 1);
  EXPECT_NE(st.error().message.find("gyroscope"), std::string::npos) << st.error().message;
  st = w->write(cap, CapacitanceFrame{{1e-12, std::nan("")}}, 1);
  EXPECT_NE(st.error().message.find("capacitance value #1 is nan"), std::string::npos) << st.error().message;

  ASSERT_TRUE(w->flush().ok());
  EXPECT_EQ(fs::file_size(path), size_before) << "refused values write nothing";
  ASSERT_TRUE(w->write(hand, make_hand_pose(6, Handedness::right, false, 9)).ok());
  ASSERT_TRUE(w->close().ok());
  EXPECT_EQ(read_all(read_bytes(path)).records.size(), 1u);
}

TEST(Recording, ReaderRejectsNonFinitePoseFromAnotherWriterAndGoesOn) {
  TempDir dir;
  const Session s = pose_session(3);
  Bytes file = session_bytes(dir / "n.prec", s);
  const std::vector<std::uint64_t> ends = record_ends(file);
  // Pose 1: joint 0 position x sits after hand/flags/count (4), 26 flags and 4 quaternion doubles.
  const std::size_t x = ends[2] + 16 + 4 + 26 + 32;
  const std::uint64_t nan = bits(std::nan(""));
  for (int i = 0; i < 8; ++i) file[x + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(nan >> (8 * i));
  refresh_crc(file, ends[2]);

  auto reader = RecordingReader::from_bytes(file);
  auto first = reader->next();
  ASSERT_TRUE(first.ok() && *first);
  auto second = reader->next();
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.error().code, Errc::parse_error);
  EXPECT_NE(second.error().message.find("joint 'palm' position has a non-finite value"), std::string::npos)
      << second.error().message;
  EXPECT_NE(second.error().message.find("at byte " + std::to_string(ends[2])), std::string::npos);
  EXPECT_NE(second.error().message.find("'hand/right'"), std::string::npos);
  auto third = reader->next();
  ASSERT_TRUE(third.ok() && *third);
  expect_same(**third, s.records[2]);
  const ReadBack rest = read_all(*reader);
  EXPECT_TRUE(rest.records.empty());
  EXPECT_EQ(rest.summary.end, RecordingEnd::clean);
  EXPECT_EQ(rest.summary.invalid_records, 1u);
  EXPECT_FALSE(rest.summary.clean());
}

TEST(Recording, ReaderRejectsBadCountsAndUndefinedStreams) {
  Bytes f = file_header(1, 0);
  append_record(f, 1, 0, 0, stream_def(StreamKind::capacitance, "cap"));
  append_record(f, 2, 0, 1, Bytes{0xFF, 0xFF, 0xFF, 0x0F, 1, 2, 3});  // 268M values in 3 bytes
  append_record(f, 2, 4, 2, Bytes{});                                 // stream 4 never defined
  append_record(f, 1, 0, 0, stream_def(StreamKind::event, "again"));  // id 0 twice
  append_record(f, 2, 0, 3, Bytes{1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xF0, 0x3F});
  const ReadBack back = read_all(f);
  ASSERT_EQ(back.errors.size(), 3u);
  EXPECT_NE(back.errors[0].message.find("count 268435455 needs"), std::string::npos) << back.errors[0].message;
  EXPECT_NE(back.errors[1].message.find("never defined"), std::string::npos) << back.errors[1].message;
  EXPECT_NE(back.errors[2].message.find("defined twice"), std::string::npos) << back.errors[2].message;
  ASSERT_EQ(back.records.size(), 1u);
  EXPECT_EQ(std::get<CapacitanceFrame>(back.records[0].payload).values_F, std::vector<double>{1.0});
  EXPECT_EQ(back.summary.end, RecordingEnd::missing_end);
}

TEST(Recording, WriterChecksStreamsNamesAndState) {
  TempDir dir;
  auto w = RecordingWriter::create(dir / "w.prec");
  const StreamId hand = w->add_stream(StreamKind::hand_pose, "hand/right").value();

  Status st = w->write(hand, ImuSample{}, 0);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("stream 'hand/right' holds hand_pose records; cannot write imu"),
            std::string::npos)
      << st.error().message;
  st = w->write(StreamId{9}, Event{"x"}, 0);
  EXPECT_NE(st.error().message.find("no stream with id 9"), std::string::npos) << st.error().message;

  auto dup = w->add_stream(StreamKind::event, "hand/right");
  ASSERT_FALSE(dup.ok());
  EXPECT_NE(dup.error().message.find("already exists"), std::string::npos);
  auto spaced = w->add_stream(StreamKind::event, "my events");
  ASSERT_FALSE(spaced.ok());
  EXPECT_NE(spaced.error().message.find("printable ASCII without spaces"), std::string::npos);
  EXPECT_FALSE(w->add_stream(StreamKind::event, "").ok());
  EXPECT_FALSE(w->add_stream(static_cast<StreamKind>(77), "x").ok());

  st = w->write(w->add_stream(StreamKind::raw, "raw").value(), RawBytes{Bytes(kRecordingMaxPayloadBytes + 1)}, 0);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("split the data"), std::string::npos) << st.error().message;

  ASSERT_TRUE(w->close().ok());
  st = w->write(hand, make_hand_pose(1, Handedness::right, false, 1));
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("is closed"), std::string::npos);
  EXPECT_EQ(read_all(read_bytes(dir / "w.prec")).summary.end, RecordingEnd::clean);
}

TEST(Recording, RefusesToOverwriteUnlessAsked) {
  TempDir dir;
  const fs::path path = dir / "o.prec";
  ASSERT_TRUE(RecordingWriter::create(path).ok());
  auto again = RecordingWriter::create(path);
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.error().message.find("already exists"), std::string::npos);
  EXPECT_NE(again.error().message.find("--force"), std::string::npos);
  EXPECT_TRUE(RecordingWriter::create(path, {.overwrite = true}).ok());

  auto nodir = RecordingWriter::create(dir / "missing" / "x.prec");
  ASSERT_FALSE(nodir.ok());
  EXPECT_EQ(nodir.error().code, Errc::not_found);
  EXPECT_NE(nodir.error().message.find("create its folder first"), std::string::npos);
}

// ------------------------------------------------------------------ fuzz seed corpus

#ifdef PROPRIO_TEST_DATA_DIR
fs::path corpus_dir() { return fs::path(PROPRIO_TEST_DATA_DIR).parent_path() / "fuzz" / "corpus" / "recording_reader"; }

// PROPRIO_REGEN_CORPUS=1 ctest -R RecordingSeedCorpus rewrites the fuzz seeds
// after a format change; commit the result.
TEST(RecordingSeedCorpus, Regenerate) {
  const char* regen = std::getenv("PROPRIO_REGEN_CORPUS");
  if (!regen || std::string(regen) != "1") GTEST_SKIP() << "set PROPRIO_REGEN_CORPUS=1 to rewrite the seeds";
  const fs::path out = corpus_dir();
  fs::create_directories(out);
  TempDir dir;

  session_bytes(dir / "tmp", {});
  write_bytes(out / "empty_session.prec", read_bytes(dir / "tmp"));

  Session kinds = every_kind_session();
  std::get<HandPose>(kinds.records[6].payload).has_velocity = false;  // keep the seed small
  const Bytes all = session_bytes(dir / "tmp", kinds);
  write_bytes(out / "every_kind.prec", all);
  const std::vector<std::uint64_t> ends = record_ends(all);
  write_bytes(out / "every_kind_truncated.prec",
              Bytes(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(ends[ends.size() - 3] + 9)));
  // Damage mid-file, for the resynchronisation: a flipped byte in one record,
  // junk between two others.
  Bytes damaged = all;
  damaged[ends[3] + 17] ^= 0x20;
  damaged.insert(damaged.begin() + static_cast<std::ptrdiff_t>(ends[6]), {0x13, 0x00, 0x00, 0x00, 0x02, 0x00, 0x01});
  write_bytes(out / "every_kind_damaged_mid.prec", damaged);

  Session hands;
  hands.streams = {{StreamKind::hand_pose, "hand/left"}, {StreamKind::hand_pose, "hand/right"}};
  HandPose lost;
  lost.time_ns = 2;
  hands.records = {{0, 1, make_hand_pose(1, Handedness::left, true, 3)}, {0, 2, lost},
                   {1, 3, make_hand_pose(3, Handedness::right, false, 4)}};
  write_bytes(out / "two_hands.prec", session_bytes(dir / "tmp", hands));

  Bytes future = file_header(1, kRecordingFormatMinor + 1);
  append_record(future, 1, 0, 0, stream_def(static_cast<StreamKind>(200), "future/thing"));
  append_record(future, 2, 0, 5, Bytes{1, 2, 3});
  append_record(future, 9, 0, 6, Bytes{4, 5});
  write_bytes(out / "newer_minor.prec", future);

  for (const auto& e : fs::directory_iterator(out)) EXPECT_LT(fs::file_size(e.path()), 8192u) << e.path();
}

TEST(RecordingSeedCorpus, EverySeedStillReads) {
  const fs::path dir = corpus_dir();
  ASSERT_TRUE(fs::is_directory(dir)) << dir << " is missing; run with PROPRIO_REGEN_CORPUS=1";
  std::size_t seeds = 0;
  for (const auto& e : fs::directory_iterator(dir)) {
    SCOPED_TRACE(e.path().string());
    ++seeds;
    auto reader = RecordingReader::open(e.path());
    ASSERT_TRUE(reader.ok()) << reader.error().message;
    const ReadBack back = read_all(*reader);
    const std::string name = e.path().filename().string();
    // Damage that hits a stream definition makes that stream's data an error.
    if (name.find("damaged") == std::string::npos) {
      EXPECT_TRUE(back.errors.empty());
    }
    const RecordingEnd expected = name.find("truncated") != std::string::npos ? RecordingEnd::truncated
                                  : name.find("damaged") != std::string::npos   ? RecordingEnd::corrupt
                                  : name.find("newer_minor") != std::string::npos ? RecordingEnd::missing_end
                                                                                   : RecordingEnd::clean;
    EXPECT_EQ(back.summary.end, expected);
  }
  EXPECT_GE(seeds, 5u);
}
#endif

}  // namespace
}  // namespace proprio
