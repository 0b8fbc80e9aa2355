// Session recording throughput: HandPose records written and read per second,
// and CRC-32 bytes per second. Run: build/dev/tests/proprio_bench --benchmark_filter=Recording
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "proprio/core/recording.hpp"

using namespace proprio;

namespace {

namespace fs = std::filesystem;

constexpr int kPosesPerFile = 1000;

fs::path bench_path(const char* name) {
  return fs::temp_directory_path() / ("proprio_bench_" + std::to_string(::getpid()) + "_" + name);
}

HandPose bench_pose(bool velocity) {
  HandPose p;
  p.active = true;
  p.has_velocity = velocity;
  p.set_all_flags(kJointFullyTracked);
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    const double s = static_cast<double>(i);
    p.T_world_joint[i] = Pose{so3_exp(Vec3(0.1, -0.02 * s, 0.03)), Vec3(0.01 * s, 1.2, -0.3)};
    p.radius_m[i] = 0.008;
    p.linear_velocity_in_world[i] = Vec3(0.1, 0.2, s);
    p.angular_velocity_in_world[i] = Vec3(s, 0.5, -0.1);
  }
  return p;
}

// A file of kPosesPerFile right-hand poses; returns its bytes.
std::vector<std::uint8_t> pose_file(const fs::path& path, bool velocity) {
  auto w = RecordingWriter::create(path, {.overwrite = true});
  if (!w) return {};
  const StreamId id = w->add_stream(StreamKind::hand_pose, "hand/right").value();
  HandPose p = bench_pose(velocity);
  for (int i = 0; i < kPosesPerFile; ++i) {
    p.time_ns = TimeNs{i} * 11'111'111;
    (void)w->write(id, p);
  }
  (void)w->close();
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Arg: 1 = poses carry joint velocities (2.9 KB records), 0 = without (1.7 KB).
// Writes to /dev/null: this is the cost of encoding, CRC and stdio buffering,
// not of the disk (and a long run cannot fill the disk).
void BM_RecordingWriteHandPose(benchmark::State& state) {
  auto w = RecordingWriter::create("/dev/null", {.overwrite = true});
  if (!w) return state.SkipWithError(w.error().message.c_str());
  const StreamId id = w->add_stream(StreamKind::hand_pose, "hand/right").value();
  HandPose p = bench_pose(state.range(0) != 0);
  for (auto _ : state) {
    ++p.time_ns;
    if (!w->write(id, p)) {
      state.SkipWithError("write failed");
      break;
    }
  }
  (void)w->close();
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_RecordingWriteHandPose)->Arg(0)->Arg(1);

template <typename Open>
void read_poses(benchmark::State& state, Open open, std::size_t file_bytes) {
  for (auto _ : state) {
    auto reader = open();
    if (!reader) {
      state.SkipWithError(reader.error().message.c_str());
      break;
    }
    for (;;) {
      auto rec = reader->next();
      if (!rec.ok() || !*rec) break;
      benchmark::DoNotOptimize(std::get<HandPose>((*rec)->payload).T_world_joint[5].p.x());
    }
  }
  state.SetItemsProcessed(state.iterations() * kPosesPerFile);
  state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(file_bytes));
}

void BM_RecordingReadHandPoseFromMemory(benchmark::State& state) {
  const fs::path path = bench_path("read_mem.prec");
  const auto bytes = pose_file(path, state.range(0) != 0);
  fs::remove(path);
  read_poses(state, [&] { return RecordingReader::from_bytes(bytes); }, bytes.size());
}
BENCHMARK(BM_RecordingReadHandPoseFromMemory)->Arg(0)->Arg(1);

void BM_RecordingReadHandPoseFromFile(benchmark::State& state) {
  const fs::path path = bench_path("read_file.prec");
  const auto bytes = pose_file(path, state.range(0) != 0);
  read_poses(state, [&] { return RecordingReader::open(path); }, bytes.size());
  fs::remove(path);
}
BENCHMARK(BM_RecordingReadHandPoseFromFile)->Arg(0)->Arg(1);

void BM_RecordingCrc32(benchmark::State& state) {
  std::vector<std::uint8_t> data(static_cast<std::size_t>(state.range(0)));
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::uint8_t>(i * 131 + 7);
  for (auto _ : state) benchmark::DoNotOptimize(crc32_ieee(data));
  state.SetBytesProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_RecordingCrc32)->Arg(64)->Arg(4096)->Arg(1 << 20);

}  // namespace
