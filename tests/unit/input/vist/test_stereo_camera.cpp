// StereoCamera: video files written with cv::VideoWriter (frame split, the
// file timestamp grid, end of file, size checks) and scripted sources for what
// needs a device (backend vs host timestamps, unplug and reopen, the reader
// thread's newest-frame hand-over and drop count). No timing assertions.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <functional>
#include <cmath>
#include <filesystem>
#include <memory>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <semaphore>
#include <string>
#include <thread>
#include <vector>

#include "proprio/vist/stereo_camera.hpp"
#include "support/temp_dir.hpp"
#include "support/text.hpp"

using namespace proprio;
using namespace proprio::vist;
using proprio::testing_support::TempDir;

namespace {

using proprio::testing_support::contains;

// Left half blue-ish, brighter with the frame index; right half green.
cv::Mat sbs_frame(int index, cv::Size eye) {
  cv::Mat f(eye.height, eye.width * 2, CV_8UC3, cv::Scalar(40, 200, 40));
  f(cv::Rect(0, 0, eye.width, eye.height)).setTo(cv::Scalar(40 + 20 * index, 40, 40));
  return f;
}

// Writes frames with the first codec this OpenCV can write; empty if none.
std::string write_video(const std::filesystem::path& path, const std::vector<cv::Mat>& frames, double fps) {
  const std::pair<const char*, int> codecs[] = {{"MJPG", cv::VideoWriter::fourcc('M', 'J', 'P', 'G')},
                                                {"FFV1", cv::VideoWriter::fourcc('F', 'F', 'V', '1')}};
  for (const auto& [name, fourcc] : codecs) {
    cv::VideoWriter w(path.string(), fourcc, fps, frames.front().size());
    if (!w.isOpened()) continue;
    for (const auto& f : frames) w.write(f);
    w.release();
    return name;
  }
  return {};
}

std::vector<cv::Mat> sbs_frames(int n, cv::Size eye) {
  std::vector<cv::Mat> v;
  for (int i = 0; i < n; ++i) v.push_back(sbs_frame(i, eye));
  return v;
}

StereoCameraOptions file_options(const std::filesystem::path& file, cv::Size eye) {
  StereoCameraOptions o;
  o.input = StereoInput::file;
  o.left = file.string();
  o.side_by_side = true;
  o.width_px = eye.width;
  o.height_px = eye.height;
  o.fps = 0.0;
  return o;
}

// --- scripted source ------------------------------------------------------------

struct Script {
  bool live = true;
  cv::Size frame_size{64, 32};
  int frames = 1000;         // frames per open; then grab() fails (unplug, or end of file)
  int failing_reopens = 0;   // open() calls after the first that fail
  ManualClock* clock = nullptr;
  DurationNs advance_per_grab_ns = 33'000'000;
  std::function<double(std::int64_t index, TimeNs now_ns)> backend_ms;  // NaN if unset
  std::counting_semaphore<1 << 20>* gate = nullptr;  // grab() takes a permit (5 s at most)
};

struct ScriptState {
  std::atomic<bool> abort{false};  // a gated grab() gives up
  int opens = 0;
  int delivered = 0;  // since the last open
  std::int64_t total = 0;
  double last_backend_ms = std::nan("");
};

class ScriptedSource final : public VideoSource {
 public:
  ScriptedSource(Script s, std::shared_ptr<ScriptState> st, std::string name = "scripted")
      : s_(std::move(s)), st_(std::move(st)), name_(std::move(name)) {}
  std::string name() const override { return name_; }
  bool live() const override { return s_.live; }
  Status open() override {
    ++st_->opens;
    if (st_->opens > 1 && st_->opens - 1 <= s_.failing_reopens) {
      return make_error(Errc::not_found, "no camera at " + name_);
    }
    st_->delivered = 0;
    open_ = true;
    return Status::success();
  }
  void close() override { open_ = false; }
  bool grab() override {
    if (s_.gate) {
      bool got = false;
      for (int i = 0; i < 500 && !got && !st_->abort; ++i) got = s_.gate->try_acquire_for(std::chrono::milliseconds(10));
      if (!got) return false;
    }
    if (!open_ || st_->delivered >= s_.frames) return false;
    if (s_.clock) s_.clock->advance(s_.advance_per_grab_ns);
    st_->last_backend_ms =
        s_.backend_ms ? s_.backend_ms(st_->total, s_.clock ? s_.clock->now_ns() : 0) : std::nan("");
    ++st_->delivered;
    ++st_->total;
    return true;
  }
  bool retrieve(cv::Mat& bgr) override {
    const cv::Size eye(s_.frame_size.width / 2, s_.frame_size.height);
    bgr = sbs_frame(static_cast<int>(st_->total - 1) % 10, eye);
    if (bgr.size() != s_.frame_size) cv::resize(bgr, bgr, s_.frame_size, 0, 0, cv::INTER_NEAREST);
    return true;
  }
  double backend_time_ms() const override { return st_->last_backend_ms; }
  double fps() const override { return 30.0; }

 private:
  Script s_;
  std::shared_ptr<ScriptState> st_;
  std::string name_;
  bool open_ = false;
};

StereoCameraOptions device_options() {
  StereoCameraOptions o;
  o.input = StereoInput::device;
  o.left = "scripted";
  o.width_px = 32;
  o.height_px = 32;
  o.fps = 30.0;
  o.reopen_interval_s = 0.0;
  return o;
}

std::unique_ptr<StereoCamera> open_scripted(const StereoCameraOptions& o, Script s,
                                            std::shared_ptr<ScriptState> st, const Clock& clock) {
  auto cam = StereoCamera::open(o, std::make_unique<ScriptedSource>(std::move(s), std::move(st)), nullptr, clock);
  EXPECT_TRUE(cam.ok()) << cam.error().message;
  return cam.ok() ? std::move(*cam) : nullptr;
}

bool wait_for_state(const StereoCamera& cam, CameraState want) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (cam.state() != want) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

}  // namespace

// --- options ---------------------------------------------------------------------

TEST(StereoCameraOptions, ValidateSaysWhatIsWrong) {
  StereoCameraOptions o;
  EXPECT_TRUE(o.validate().ok());
  EXPECT_TRUE(contains(o.describe(), "side-by-side camera /dev/video0")) << o.describe();
  EXPECT_TRUE(contains(o.describe(), "1280x720 per camera at 30 fps")) << o.describe();

  auto expect_error = [](StereoCameraOptions bad, std::string_view needle) {
    const auto s = bad.validate();
    ASSERT_FALSE(s.ok()) << needle;
    EXPECT_TRUE(contains(s.error().message, needle)) << s.error().message;
  };
  StereoCameraOptions b = o;
  b.right = "/dev/video2";
  expect_error(b, "side-by-side source");
  b.side_by_side = false;
  EXPECT_TRUE(b.validate().ok()) << b.validate().error().message;
  EXPECT_TRUE(contains(b.describe(), "cameras /dev/video0 (left) + /dev/video2 (right)")) << b.describe();
  b.right = "0";
  expect_error(b, "the same camera");
  b.right.clear();
  expect_error(b, "need the right one too");
  b = o;
  b.left.clear();
  expect_error(b, "no camera given");
  b = o;
  b.width_px = 0;
  expect_error(b, "give both width and height");
  b.height_px = 0;
  EXPECT_TRUE(b.validate().ok());
  b = o;
  b.fps = 0.0;
  expect_error(b, "frame rate");
  b.input = StereoInput::file;
  EXPECT_TRUE(b.validate().ok());  // files: 0 takes the file's rate
  b = o;
  b.host_latency_s = 35.0;
  expect_error(b, "in seconds");
  b = o;
  b.reopen_attempts = -1;
  expect_error(b, "reopen");

  StereoCameraOptions f = file_options("/tmp/x.avi", {640, 480});
  f.file_t0_ns = 2'000'000'000;
  f.reader_thread = true;
  f.calibration_file = "cal.yaml";
  const std::string d = f.describe();
  EXPECT_TRUE(contains(d, "side-by-side video '/tmp/x.avi'")) << d;
  EXPECT_TRUE(contains(d, "timestamps 2 s + index / the file's rate")) << d;
  EXPECT_TRUE(contains(d, "reader thread")) << d;
  EXPECT_TRUE(contains(d, "rectified with 'cal.yaml'")) << d;
  EXPECT_EQ(parse_frame_time_source("host"), FrameTimeSource::host);
  EXPECT_FALSE(parse_frame_time_source("wall").has_value());
}

TEST(StereoCameraDevice, MissingOrUnopenableDeviceIsAClearError) {
  StereoCameraOptions o;
  o.left = "/dev/video_proprio_test_missing";
  auto cam = StereoCamera::open(o);
  ASSERT_FALSE(cam.ok());
  EXPECT_EQ(cam.error().code, Errc::not_found);
  EXPECT_TRUE(contains(cam.error().message, "no camera at /dev/video_proprio_test_missing"))
      << cam.error().message;
  EXPECT_TRUE(contains(cam.error().message, "v4l2-ctl --list-devices")) << cam.error().message;

  TempDir dir;
  o.left = dir.write("not_a_camera", "plain file").string();
  cam = StereoCamera::open(o);
  ASSERT_FALSE(cam.ok());
  EXPECT_EQ(cam.error().code, Errc::io_error);
  EXPECT_TRUE(contains(cam.error().message, "cannot open camera")) << cam.error().message;
}

// --- video files ------------------------------------------------------------------

TEST(StereoCameraFile, SplitsSideBySideFramesAndTimesThemFromTheirIndex) {
  TempDir dir;
  const cv::Size eye(160, 120);
  const auto path = dir / "sbs.avi";
  if (write_video(path, sbs_frames(8, eye), 25.0).empty()) GTEST_SKIP() << "this OpenCV has no video writer";
  auto o = file_options(path, eye);
  o.file_t0_ns = 5 * kNsPerSecond;
  auto cam = StereoCamera::open(o);
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  EXPECT_DOUBLE_EQ((*cam)->fps(), 25.0);
  for (int i = 0; i < 8; ++i) {
    SCOPED_TRACE("frame " + std::to_string(i));
    auto f = (*cam)->next();
    ASSERT_TRUE(f.ok()) << f.error().message;
    EXPECT_EQ(f->index, i);
    EXPECT_EQ(f->t_ns, 5 * kNsPerSecond + i * 40 * kNsPerMillisecond);
    EXPECT_EQ(f->t_right_ns, f->t_ns);
    EXPECT_EQ(f->time_origin, FrameTimeOrigin::file_index);
    EXPECT_FALSE(f->rectified);
    ASSERT_EQ(f->left.size(), eye);
    ASSERT_EQ(f->right.size(), eye);
    ASSERT_EQ(f->left.type(), CV_8UC3);
    const cv::Scalar l = cv::mean(f->left), r = cv::mean(f->right);
    EXPECT_NEAR(l[0], 40 + 20 * i, 12.0);  // blue grows with the index: the frames are in order
    EXPECT_LT(l[1], 70.0);
    EXPECT_GT(r[1], 170.0);  // the right half is green
    EXPECT_LT(r[0], 70.0);
  }
  auto end = (*cam)->next();
  ASSERT_FALSE(end.ok());
  EXPECT_EQ(end.error().code, Errc::out_of_range);
  EXPECT_TRUE(contains(end.error().message, "end of video")) << end.error().message;
  EXPECT_TRUE(contains(end.error().message, "after 8 frames")) << end.error().message;
  EXPECT_EQ((*cam)->state(), CameraState::end_of_stream);
  EXPECT_EQ((*cam)->next().error().code, Errc::out_of_range);  // and stays there
  EXPECT_EQ((*cam)->stats().frames, 8);
}

TEST(StereoCameraFile, ConfiguredRateOverridesTheFileHeader) {
  TempDir dir;
  const cv::Size eye(64, 48);
  const auto path = dir / "sbs.avi";
  if (write_video(path, sbs_frames(3, eye), 30.0).empty()) GTEST_SKIP() << "this OpenCV has no video writer";
  auto o = file_options(path, eye);
  o.fps = 10.0;
  o.file_t0_ns = -kNsPerSecond;
  auto cam = StereoCamera::open(o);
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  for (int i = 0; i < 3; ++i) {
    auto f = (*cam)->next();
    ASSERT_TRUE(f.ok()) << f.error().message;
    EXPECT_EQ(f->t_ns, -kNsPerSecond + i * 100 * kNsPerMillisecond);
  }
}

TEST(StereoCameraFile, PairOfFilesMustEndTogether) {
  TempDir dir;
  const cv::Size eye(64, 48);
  std::vector<cv::Mat> left, right;
  for (int i = 0; i < 6; ++i) left.push_back(sbs_frame(i, eye)(cv::Rect(0, 0, 64, 48)).clone());
  for (int i = 0; i < 4; ++i) right.push_back(sbs_frame(i, eye)(cv::Rect(64, 0, 64, 48)).clone());
  if (write_video(dir / "l.avi", left, 30.0).empty() || write_video(dir / "r.avi", right, 30.0).empty()) {
    GTEST_SKIP() << "this OpenCV has no video writer";
  }
  auto o = file_options(dir / "l.avi", eye);
  o.side_by_side = false;
  o.right = (dir / "r.avi").string();
  auto cam = StereoCamera::open(o);
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  for (int i = 0; i < 4; ++i) {
    auto f = (*cam)->next();
    ASSERT_TRUE(f.ok()) << f.error().message;
    EXPECT_GT(cv::mean(f->left)[0], 30.0);
    EXPECT_GT(cv::mean(f->right)[1], 170.0);
  }
  auto f = (*cam)->next();
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.error().code, Errc::invalid_argument);
  EXPECT_TRUE(contains(f.error().message, "r.avi' ended after 4 frames")) << f.error().message;
  EXPECT_EQ((*cam)->state(), CameraState::failed);
}

TEST(StereoCameraFile, WrongSizeMissingFileAndNotAVideo) {
  TempDir dir;
  const cv::Size eye(160, 120);
  const auto path = dir / "sbs.avi";
  if (write_video(path, sbs_frames(2, eye), 25.0).empty()) GTEST_SKIP() << "this OpenCV has no video writer";
  auto cam = StereoCamera::open(file_options(path, {640, 480}));
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  auto f = (*cam)->next();
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.error().code, Errc::invalid_argument);
  EXPECT_TRUE(contains(f.error().message, "delivers 320x120 frames, not 1280x480 side by side"))
      << f.error().message;
  EXPECT_EQ((*cam)->state(), CameraState::failed);

  // 0x0 takes the file's size.
  cam = StereoCamera::open(file_options(path, {0, 0}));
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  ASSERT_TRUE((*cam)->next().ok());
  EXPECT_EQ((*cam)->image_size(), eye);

  auto missing = StereoCamera::open(file_options(dir / "nope.avi", eye));
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, Errc::not_found);
  auto text = StereoCamera::open(file_options(dir.write("text.avi", "not a video"), eye));
  ASSERT_FALSE(text.ok());
  EXPECT_TRUE(contains(text.error().message, "cannot decode video")) << text.error().message;
}

TEST(StereoCameraFile, ReaderThreadHandsOverTheNewestFrameAndCountsDrops) {
  TempDir dir;
  const cv::Size eye(64, 48);
  const auto path = dir / "sbs.avi";
  if (write_video(path, sbs_frames(12, eye), 30.0).empty()) GTEST_SKIP() << "this OpenCV has no video writer";
  auto o = file_options(path, eye);
  o.reader_thread = true;
  auto cam = StereoCamera::open(o);
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  (*cam)->start();
  ASSERT_TRUE(wait_for_state(**cam, CameraState::end_of_stream));
  // Nobody took frames while the whole file was read: only the last is left.
  auto f = (*cam)->next(5.0);
  ASSERT_TRUE(f.ok()) << f.error().message;
  EXPECT_EQ(f->index, 11);
  EXPECT_EQ(f->t_ns, seconds_to_ns(11.0 / 30.0));
  EXPECT_EQ((*cam)->stats().frames, 12);
  EXPECT_EQ((*cam)->stats().dropped, 11);
  auto end = (*cam)->next(5.0);
  ASSERT_FALSE(end.ok());
  EXPECT_EQ(end.error().code, Errc::out_of_range);
}

// --- scripted sources: what needs a device ------------------------------------

TEST(StereoCameraScripted, SplitsSideBySideFramesExactly) {
  ManualClock clock(0);
  auto st = std::make_shared<ScriptState>();
  Script s;
  s.frame_size = {64, 32};
  auto cam = open_scripted(device_options(), s, st, clock);
  ASSERT_TRUE(cam);
  auto f = cam->next();
  ASSERT_TRUE(f.ok()) << f.error().message;
  EXPECT_EQ(f->left.at<cv::Vec3b>(5, 31), cv::Vec3b(40, 40, 40));
  EXPECT_EQ(f->right.at<cv::Vec3b>(5, 0), cv::Vec3b(40, 200, 40));
  EXPECT_EQ(f->left.size(), cv::Size(32, 32));
  cam->stop();
  EXPECT_EQ(cam->state(), CameraState::stopped);
  f = cam->next();
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.error().code, Errc::unavailable);

  Script odd;
  odd.frame_size = {63, 32};
  auto o = device_options();
  o.width_px = 0;
  o.height_px = 0;
  cam = open_scripted(o, odd, std::make_shared<ScriptState>(), clock);
  ASSERT_TRUE(cam);
  f = cam->next();
  ASSERT_FALSE(f.ok());
  EXPECT_TRUE(contains(f.error().message, "odd width")) << f.error().message;
}

TEST(StereoCameraScripted, UsesTheBackendTimeWhenItIsAMonotonicCaptureTime) {
  ManualClock clock(1000 * kNsPerSecond);
  auto st = std::make_shared<ScriptState>();
  Script s;
  s.clock = &clock;
  // Like V4L2: the buffer timestamp, 12 ms before the frame reached us.
  s.backend_ms = [](std::int64_t, TimeNs now) { return static_cast<double>(now) * 1e-6 - 12.0; };
  auto o = device_options();
  o.backend_time_offset_s = 0.002;
  auto cam = open_scripted(o, s, st, clock);
  ASSERT_TRUE(cam);
  for (int i = 1; i <= 3; ++i) {
    auto f = cam->next();
    ASSERT_TRUE(f.ok()) << f.error().message;
    EXPECT_EQ(f->time_origin, FrameTimeOrigin::backend);
    EXPECT_EQ(f->t_ns, 1000 * kNsPerSecond + i * 33 * kNsPerMillisecond - 14 * kNsPerMillisecond);
  }
}

TEST(StereoCameraScripted, FallsBackToHostTimeForAStreamPosition) {
  ManualClock clock(1000 * kNsPerSecond);
  auto st = std::make_shared<ScriptState>();
  Script s;
  s.clock = &clock;
  // Like GStreamer/FFmpeg: milliseconds since the stream started.
  s.backend_ms = [](std::int64_t index, TimeNs) { return 33.3 * static_cast<double>(index + 1); };
  auto o = device_options();
  o.host_latency_s = 0.040;
  auto cam = open_scripted(o, s, st, clock);
  ASSERT_TRUE(cam);
  for (int i = 1; i <= 3; ++i) {
    auto f = cam->next();
    ASSERT_TRUE(f.ok()) << f.error().message;
    EXPECT_EQ(f->time_origin, FrameTimeOrigin::host);
    EXPECT_EQ(f->t_ns, 1000 * kNsPerSecond + i * 33 * kNsPerMillisecond - 40 * kNsPerMillisecond);
  }

  // Demanding the backend's time is then an error that says what to use.
  o.time_source = FrameTimeSource::backend;
  cam = open_scripted(o, s, std::make_shared<ScriptState>(), clock);
  ASSERT_TRUE(cam);
  auto f = cam->next();
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.error().code, Errc::unsupported);
  EXPECT_TRUE(contains(f.error().message, "use host timestamps")) << f.error().message;
  EXPECT_EQ(cam->state(), CameraState::failed);

  // Host mode ignores even a good backend clock.
  s.backend_ms = [](std::int64_t, TimeNs now) { return static_cast<double>(now) * 1e-6 - 1.0; };
  o.time_source = FrameTimeSource::host;
  cam = open_scripted(o, s, std::make_shared<ScriptState>(), clock);
  ASSERT_TRUE(cam);
  f = cam->next();
  ASSERT_TRUE(f.ok());
  EXPECT_EQ(f->time_origin, FrameTimeOrigin::host);
  EXPECT_EQ(f->t_ns, clock.now_ns() - 40 * kNsPerMillisecond);
}

TEST(StereoCameraScripted, ReopensADeviceThatStoppedDelivering) {
  ManualClock clock(0);
  auto st = std::make_shared<ScriptState>();
  Script s;
  s.frames = 3;           // then "unplugged"
  s.failing_reopens = 1;  // the first reopen finds nothing, the second works
  auto o = device_options();
  o.reopen_attempts = 3;
  auto cam = open_scripted(o, s, st, clock);
  ASSERT_TRUE(cam);
  for (int i = 0; i < 5; ++i) {
    auto f = cam->next();
    ASSERT_TRUE(f.ok()) << f.error().message;
    EXPECT_EQ(f->index, i);  // the count goes on across the reopen
  }
  EXPECT_EQ(cam->state(), CameraState::streaming);
  EXPECT_EQ(cam->stats().read_failures, 1);
  EXPECT_EQ(cam->stats().reopens, 1);
  EXPECT_EQ(st->opens, 3);
}

TEST(StereoCameraScripted, GivesUpAfterTheReopenAttempts) {
  ManualClock clock(0);
  auto st = std::make_shared<ScriptState>();
  Script s;
  s.frames = 2;
  s.failing_reopens = 100;
  auto o = device_options();
  o.reopen_attempts = 3;
  auto cam = open_scripted(o, s, st, clock);
  ASSERT_TRUE(cam);
  ASSERT_TRUE(cam->next().ok());
  ASSERT_TRUE(cam->next().ok());
  auto f = cam->next();
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.error().code, Errc::io_error);
  EXPECT_TRUE(contains(f.error().message, "stopped delivering frames")) << f.error().message;
  EXPECT_TRUE(contains(f.error().message, "3 reopen attempts")) << f.error().message;
  EXPECT_TRUE(contains(f.error().message, "no camera at scripted")) << f.error().message;
  EXPECT_EQ(cam->state(), CameraState::failed);
  EXPECT_EQ(cam->next().error().code, Errc::io_error);
  EXPECT_EQ(st->opens, 4);
  EXPECT_EQ(cam->stats().reopens, 0);
}

TEST(StereoCameraScripted, ReaderThreadDeliversEveryFrameToAConsumerThatKeepsUp) {
  ManualClock clock(0);
  auto st = std::make_shared<ScriptState>();
  std::counting_semaphore<1 << 20> gate(0);
  Script s;
  s.live = false;  // ends cleanly when the gate times out
  s.gate = &gate;
  auto o = device_options();
  o.input = StereoInput::file;
  o.reader_thread = true;
  auto cam = open_scripted(o, s, st, clock);
  ASSERT_TRUE(cam);
  EXPECT_FALSE(cam->try_latest().has_value());  // nothing released yet
  for (int i = 0; i < 10; ++i) {
    gate.release();
    auto f = cam->next(10.0);
    ASSERT_TRUE(f.ok()) << f.error().message;
    EXPECT_EQ(f->index, i);
  }
  EXPECT_EQ(cam->stats().dropped, 0);
  EXPECT_FALSE(cam->try_latest().has_value());
  gate.release(3);
  // Three more frames arrive while nobody looks; the newest wins.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (cam->stats().frames < 13 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  auto f = cam->next(10.0);
  ASSERT_TRUE(f.ok()) << f.error().message;
  EXPECT_EQ(f->index, 12);
  EXPECT_EQ(cam->stats().dropped, 2);
  st->abort = true;
  cam->stop();
  EXPECT_NE(cam->state(), CameraState::streaming);
  EXPECT_FALSE(cam->next(0.0).ok());
}

TEST(StereoCameraScripted, RectifiesWithACalibration) {
  ManualClock clock(0);
  // An ideal rig whose rectified principal point is 10 px further right: the
  // image content moves 10 px right, nothing else changes.
  StereoCalibration c;
  c.image_size = {32, 32};
  c.left.K = cv::Matx33d(50, 0, 15.5, 0, 50, 15.5, 0, 0, 1);
  c.right.K = c.left.K;
  c.P_left = cv::Matx34d(50, 0, 25.5, 0, 0, 50, 15.5, 0, 0, 0, 1, 0);
  c.P_right = cv::Matx34d(50, 0, 25.5, -50 * 0.06, 0, 50, 15.5, 0, 0, 0, 1, 0);
  TempDir dir;
  ASSERT_TRUE(c.save(dir / "cal.yaml").ok());
  auto o = device_options();
  o.calibration_file = (dir / "cal.yaml").string();
  auto cam = StereoCamera::open(o, std::make_unique<ScriptedSource>(Script{}, std::make_shared<ScriptState>()),
                                nullptr, clock);
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  auto f = (*cam)->next();
  ASSERT_TRUE(f.ok()) << f.error().message;
  EXPECT_TRUE(f->rectified);
  EXPECT_EQ(f->right.at<cv::Vec3b>(16, 5), cv::Vec3b(0, 0, 0));  // shifted in from outside
  EXPECT_EQ(f->right.at<cv::Vec3b>(16, 15), cv::Vec3b(40, 200, 40));
  EXPECT_FALSE((*cam)->set_rectifier(std::nullopt).ok());  // too late: frames are flowing

  // A calibration for another image size is refused up front.
  o.width_px = 64;
  auto wrong = StereoCamera::open(o, std::make_unique<ScriptedSource>(Script{}, std::make_shared<ScriptState>()),
                                  nullptr, clock);
  ASSERT_FALSE(wrong.ok());
  EXPECT_TRUE(contains(wrong.error().message, "is for 32x32 images")) << wrong.error().message;
}

TEST(StereoCameraScripted, NeedsTheRightNumberOfSources) {
  ManualClock clock(0);
  auto o = device_options();
  auto two = StereoCamera::open(o, std::make_unique<ScriptedSource>(Script{}, std::make_shared<ScriptState>()),
                                std::make_unique<ScriptedSource>(Script{}, std::make_shared<ScriptState>()), clock);
  EXPECT_FALSE(two.ok());
  o.side_by_side = false;
  o.right = "other";
  auto one = StereoCamera::open(o, std::make_unique<ScriptedSource>(Script{}, std::make_shared<ScriptState>()),
                                nullptr, clock);
  EXPECT_FALSE(one.ok());
}
