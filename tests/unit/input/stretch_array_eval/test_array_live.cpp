// ArrayLiveSource: simulated wearer + emulated board over the fake HID link ->
// StretchDevice -> StretchArrayReader -> C/C0 -> ArrayReconstructor, live.
#include "proprio/stretch_array_eval/array_live.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <thread>

namespace proprio::stretch_array_eval {
namespace {

namespace fs = std::filesystem;

fs::path tiny_model() { return fs::path(PROPRIO_TESTS_DIR) / "data" / "stretch_array_eval" / "tiny_p92.onnx"; }

ArrayLiveOptions quick_options() {
  ArrayLiveOptions o;
  o.model = tiny_model();
  o.motion = "elbow";
  o.rest_s = 0.4;
  // A driver that notices an unplug and comes back quickly.
  o.read_timeout_ns = 20 * kNsPerMillisecond;
  o.reconnect_backoff_min_ns = 5 * kNsPerMillisecond;
  o.reconnect_backoff_max_ns = 50 * kNsPerMillisecond;
  return o;
}

// Polls latest() until pred holds or the deadline passes (a hang fails the
// test instead of stalling it).
bool poll_until(const ArrayLiveSource& source, const std::function<bool(const ArrayLiveSnapshot&)>& pred,
                std::chrono::milliseconds deadline) {
  const auto end = std::chrono::steady_clock::now() + deadline;
  while (std::chrono::steady_clock::now() < end) {
    if (pred(source.latest())) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return pred(source.latest());
}

TEST(ArrayLiveSource, StreamsFiniteReconstructionsWithTruthFromTheEmulatedBoard) {
  auto source = ArrayLiveSource::create_simulated(quick_options());
  ASSERT_TRUE(source) << source.error().message;
  auto& s = **source;
  EXPECT_EQ(s.cell_count(), 92u);
  EXPECT_EQ(s.marker_count(), 19u);
  EXPECT_FALSE(s.latest().frame);
  EXPECT_TRUE(s.latest().stats.calibrating);
  ASSERT_TRUE(s.start().ok());
  // About two seconds of wearing: calibration over the rest, then motion.
  const auto start = std::chrono::steady_clock::now();
  ASSERT_TRUE(poll_until(
      s,
      [&](const ArrayLiveSnapshot& snap) {
        return snap.stats.frames >= 10 && std::chrono::steady_clock::now() - start > std::chrono::seconds(2);
      },
      std::chrono::seconds(20)))
      << s.latest().stats.describe();
  const ArrayLiveSnapshot snap = s.latest();
  s.stop();
  EXPECT_EQ(s.latest().stats.link, "stopped");
  ASSERT_TRUE(snap.frame);
  const ArrayLiveFrame& f = *snap.frame;
  EXPECT_FALSE(snap.stats.calibrating);
  EXPECT_GT(snap.stats.rest_frames, 0u);
  EXPECT_EQ(snap.stats.failed, 0u) << snap.stats.last_error;
  EXPECT_TRUE(snap.stats.last_error.empty()) << snap.stats.last_error;
  EXPECT_GE(snap.stats.cell_frames, snap.stats.frames);
  EXPECT_GT(snap.stats.samples, 168u);
  EXPECT_EQ(snap.stats.link, "streaming");
  EXPECT_EQ(snap.stats.disconnects, 0u);
  ASSERT_EQ(f.vertices_m.size(), s.vertex_count());
  for (const auto& v : f.vertices_m) ASSERT_TRUE(v.allFinite());
  // The simulator's truth rides along for display, at the frame's instant.
  ASSERT_EQ(f.truth_m.size(), s.vertex_count());
  for (const auto& v : f.truth_m) ASSERT_TRUE(v.allFinite());
  EXPECT_TRUE(std::isfinite(f.mean_error_m));
  EXPECT_GT(f.mean_error_m, 0.0);
  // Frames are stamped on the host clock after the board's time zero; the
  // vertices come after the measurements they are made of, and the pipeline
  // does not fall behind (a generous bound: a stall or a backlog is seconds).
  EXPECT_GT(f.measured_ns, s.time_zero_ns());
  EXPECT_GT(f.latency_s, 0.0);
  EXPECT_LT(snap.stats.latency_max_s, 1.0) << snap.stats.describe();
  EXPECT_GE(f.reconstruct_ms, f.arap_ms);
  EXPECT_EQ(f.index + 1, snap.stats.frames);
}

TEST(ArrayLiveSource, AnUnplugIsReportedAndTheStreamComesBack) {
  ArrayLiveOptions o = quick_options();
  o.unplugs.push_back({1'000 * kNsPerMillisecond, 400 * kNsPerMillisecond});
  auto source = ArrayLiveSource::create_simulated(o);
  ASSERT_TRUE(source) << source.error().message;
  auto& s = **source;
  ASSERT_TRUE(s.start().ok());
  // While the cable is out, latest() answers (with the last frame) and says so.
  ASSERT_TRUE(poll_until(
      s, [](const ArrayLiveSnapshot& snap) { return snap.stats.link == "disconnected" || snap.stats.disconnects > 0; },
      std::chrono::seconds(20)))
      << s.latest().stats.describe();
  const std::uint64_t frames_at_unplug = s.latest().stats.frames;
  // The board boots again (a new epoch), the driver reconnects, frames resume.
  ASSERT_TRUE(poll_until(
      s,
      [&](const ArrayLiveSnapshot& snap) {
        return snap.stats.link == "streaming" && snap.stats.epochs >= 1 && snap.stats.frames > frames_at_unplug + 5;
      },
      std::chrono::seconds(20)))
      << s.latest().stats.describe();
  const ArrayLiveSnapshot snap = s.latest();
  s.stop();
  EXPECT_GE(snap.stats.disconnects, 1u);
  ASSERT_TRUE(snap.frame);
  for (const auto& v : snap.frame->vertices_m) ASSERT_TRUE(v.allFinite());
}

TEST(ArrayLiveSource, RefusesARegressorOfAnotherSizeAndAMissingModel) {
  ArrayLiveOptions o = quick_options();
  o.model = fs::path(PROPRIO_TESTS_DIR) / "data" / "stretch_array_recon" / "tiny_regressor.onnx";  // 6 cells
  auto wrong = ArrayLiveSource::create_simulated(o);
  ASSERT_FALSE(wrong);
  EXPECT_NE(wrong.error().message.find("92 cells"), std::string::npos) << wrong.error().message;
  o.model = fs::path(PROPRIO_TESTS_DIR) / "data" / "stretch_array_eval";  // a folder without model.onnx
  auto missing = ArrayLiveSource::create_simulated(o);
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("model.onnx"), std::string::npos) << missing.error().message;
  o.model.clear();
  EXPECT_FALSE(o.validate().ok());
}

TEST(ArrayLiveSource, AUsbBoardThatIsNotThereIsWaitedForWithoutHanging) {
  ArrayLiveOptions o = quick_options();
  // A path that is no hidraw node: the driver cannot open it and keeps retrying.
  auto source = ArrayLiveSource::create_usb(o, {}, "/nonexistent/hidraw-array-live-test");
  ASSERT_TRUE(source) << source.error().message;
  auto& s = **source;
  ASSERT_TRUE(s.start().ok());
  ASSERT_TRUE(poll_until(
      s, [](const ArrayLiveSnapshot& snap) { return snap.stats.link == "disconnected"; }, std::chrono::seconds(10)))
      << s.latest().stats.describe();
  const ArrayLiveSnapshot snap = s.latest();
  EXPECT_FALSE(snap.frame);
  EXPECT_EQ(snap.stats.samples, 0u);
  EXPECT_TRUE(snap.stats.calibrating);
  s.stop();
  EXPECT_EQ(s.latest().stats.link, "stopped");
}

TEST(ArrayLiveSource, ResolvesATrainingFolderToItsModel) {
  const fs::path dir = fs::temp_directory_path() / "proprio_array_live_model";
  fs::remove_all(dir);
  fs::create_directories(dir / "dnn");
  fs::copy_file(tiny_model(), dir / "dnn" / "model.onnx");
  auto from_out = resolve_array_model(dir);
  ASSERT_TRUE(from_out) << from_out.error().message;
  EXPECT_EQ(*from_out, dir / "dnn" / "model.onnx");
  auto from_kind = resolve_array_model(dir / "dnn");
  ASSERT_TRUE(from_kind);
  EXPECT_EQ(*from_kind, dir / "dnn" / "model.onnx");
  fs::remove_all(dir);
}

}  // namespace
}  // namespace proprio::stretch_array_eval
