#include "proprio/vist/stereo_camera.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <sstream>
#include <system_error>
#include <vector>

#include "proprio/core/log.hpp"

namespace proprio::vist {

namespace {

std::string fmt(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

std::string size_text(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

bool all_digits(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](unsigned char c) { return c >= '0' && c <= '9'; });
}

// "0" -> "/dev/video0": one spelling in messages, and the path is what exists
// or not.
std::string device_path(const std::string& device) { return all_digits(device) ? "/dev/video" + device : device; }

std::string video_devices_present() {
  std::vector<std::string> found;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/dev", ec)) {
    const std::string n = e.path().filename().string();
    if (n.rfind("video", 0) == 0) found.push_back(e.path().string());
  }
  std::sort(found.begin(), found.end());
  if (found.empty()) return "no /dev/video* devices are present";
  std::string s = "present: ";
  for (std::size_t i = 0; i < found.size(); ++i) s += (i ? ", " : "") + found[i];
  return s;
}

class OpenCvVideoSource final : public VideoSource {
 public:
  OpenCvVideoSource(StereoInput input, std::string what, int width_px, int height_px, double fps)
      : input_(input),
        name_(input == StereoInput::device ? device_path(what) : std::move(what)),
        width_(width_px),
        height_(height_px),
        fps_request_(fps) {}

  std::string name() const override { return name_; }
  bool live() const override { return input_ == StereoInput::device; }

  Status open() override {
    close();
    std::error_code ec;
    if (!std::filesystem::exists(name_, ec)) {
      if (live()) {
        return make_error(Errc::not_found, "no camera at " + name_ + " (" + video_devices_present() +
                                               "); plug it in, or list cameras with 'v4l2-ctl --list-devices'");
      }
      return make_error(Errc::not_found, "video file '" + name_ + "' does not exist");
    }
    try {
      if (live()) {
        if (!cap_.open(name_, cv::CAP_V4L2)) {
          return make_error(Errc::io_error,
                            "cannot open camera " + name_ +
                                ": it is busy (another program has it open) or you lack permission (be in the "
                                "'video' group), or it is not a capture device (a UVC camera has two nodes; try the "
                                "other)");
        }
        if (width_ > 0 && height_ > 0) {
          cap_.set(cv::CAP_PROP_FRAME_WIDTH, width_);
          cap_.set(cv::CAP_PROP_FRAME_HEIGHT, height_);
        }
        if (fps_request_ > 0.0) cap_.set(cv::CAP_PROP_FPS, fps_request_);
        const int w = static_cast<int>(cap_.get(cv::CAP_PROP_FRAME_WIDTH));
        const int h = static_cast<int>(cap_.get(cv::CAP_PROP_FRAME_HEIGHT));
        if (width_ > 0 && height_ > 0 && (w != width_ || h != height_)) {
          cap_.release();
          return make_error(Errc::invalid_argument,
                            "camera " + name_ + " delivers " + size_text(w, h) + ", not the requested " +
                                size_text(width_, height_) + "; list its modes with 'v4l2-ctl --list-formats-ext -d " +
                                name_ + "' (a ZED Mini is 2560x720 side by side at 30 or 60 fps)");
        }
        const double got_fps = cap_.get(cv::CAP_PROP_FPS);
        if (fps_request_ > 0.0 && got_fps > 0.0 && std::abs(got_fps - fps_request_) > 0.5) {
          logger().warn("camera {} runs at {:.1f} fps, not the requested {:.1f}", name_, got_fps, fps_request_);
        }
      } else if (!open_file()) {
        return make_error(Errc::unsupported, "cannot decode video '" + name_ +
                                                 "': not a video, or a container or codec this OpenCV build "
                                                 "cannot read (MJPG or FFV1 in .avi always work)");
      }
    } catch (const cv::Exception& e) {
      cap_.release();
      return make_error(Errc::io_error, "opening " + name_ + " failed: " + e.what());
    }
    return Status::success();
  }

  void close() override { cap_.release(); }

  // FFmpeg first: it reads the usual containers and reports their rate. Not
  // CAP_ANY: that also probes camera backends (gPhoto2 enumerates USB and
  // leaks doing so), which a file never needs.
  bool open_file() {
    for (const int api : {cv::CAP_FFMPEG, cv::CAP_GSTREAMER, cv::CAP_IMAGES}) {
      if (cap_.open(name_, api)) return true;
    }
    return false;
  }
  bool grab() override { return cap_.isOpened() && cap_.grab(); }
  bool retrieve(cv::Mat& bgr) override { return cap_.retrieve(bgr) && !bgr.empty(); }
  double backend_time_ms() const override {
    const double t = cap_.get(cv::CAP_PROP_POS_MSEC);
    return t > 0.0 ? t : std::numeric_limits<double>::quiet_NaN();
  }
  double fps() const override {
    const double f = cap_.get(cv::CAP_PROP_FPS);
    return std::isfinite(f) && f > 0.0 ? f : 0.0;
  }

 private:
  StereoInput input_;
  std::string name_;
  int width_, height_;
  double fps_request_;
  // get() is const in meaning but not in OpenCV's signature.
  mutable cv::VideoCapture cap_;
};

// A BGR 8-bit 3-channel image whatever the source decoded.
cv::Mat to_bgr(cv::Mat m) {
  if (m.depth() != CV_8U) {
    cv::Mat m8;
    m.convertTo(m8, CV_8U, m.depth() == CV_16U ? 1.0 / 256.0 : 1.0);
    m = m8;
  }
  if (m.channels() == 3) return m;
  cv::Mat out;
  cv::cvtColor(m, out, m.channels() == 4 ? cv::COLOR_BGRA2BGR : cv::COLOR_GRAY2BGR);
  return out;
}

}  // namespace

const char* to_string(StereoInput v) noexcept { return v == StereoInput::device ? "device" : "file"; }

const char* to_string(FrameTimeSource v) noexcept {
  switch (v) {
    case FrameTimeSource::automatic: return "automatic";
    case FrameTimeSource::backend: return "backend";
    case FrameTimeSource::host: return "host";
  }
  return "?";
}

const char* to_string(FrameTimeOrigin v) noexcept {
  switch (v) {
    case FrameTimeOrigin::backend: return "backend";
    case FrameTimeOrigin::host: return "host";
    case FrameTimeOrigin::file_index: return "file_index";
  }
  return "?";
}

std::optional<FrameTimeSource> parse_frame_time_source(std::string_view s) noexcept {
  if (s == "automatic" || s == "auto") return FrameTimeSource::automatic;
  if (s == "backend") return FrameTimeSource::backend;
  if (s == "host") return FrameTimeSource::host;
  return std::nullopt;
}

const char* to_string(CameraState s) noexcept {
  switch (s) {
    case CameraState::streaming: return "streaming";
    case CameraState::reopening: return "reopening";
    case CameraState::end_of_stream: return "end_of_stream";
    case CameraState::failed: return "failed";
    case CameraState::stopped: return "stopped";
  }
  return "?";
}

std::unique_ptr<VideoSource> make_opencv_source(StereoInput input, const std::string& device_or_file, int width_px,
                                                int height_px, double fps) {
  return std::make_unique<OpenCvVideoSource>(input, device_or_file, width_px, height_px, fps);
}

// --- options ----------------------------------------------------------------

Status StereoCameraOptions::validate() const {
  const bool device = input == StereoInput::device;
  const char* what = device ? "camera" : "video file";
  if (left.empty()) {
    return make_error(Errc::invalid_argument, std::string("no ") + what + " given (" +
                                                  (device ? "e.g. /dev/video0" : "a video file") + ")");
  }
  if (side_by_side && !right.empty()) {
    return make_error(Errc::invalid_argument,
                      std::string("a right ") + what + " ('" + right +
                          "') was given for a side-by-side source, which holds both cameras; drop it, or turn "
                          "side_by_side off for two separate " + (device ? "cameras" : "files"));
  }
  if (!side_by_side && right.empty()) {
    return make_error(Errc::invalid_argument, std::string("two separate ") + (device ? "cameras" : "files") +
                                                  " need the right one too; or set side_by_side if '" + left +
                                                  "' holds both images");
  }
  if (!side_by_side && (device ? device_path(left) == device_path(right) : left == right)) {
    return make_error(Errc::invalid_argument, "left and right are the same " + std::string(what) + " '" + left + "'");
  }
  if ((width_px == 0) != (height_px == 0) || width_px < 0 || height_px < 0 || width_px > 16384 ||
      height_px > 16384) {
    return make_error(Errc::out_of_range, "image size " + size_text(width_px, height_px) +
                                              " per camera: give both width and height (1-16384 px), or 0x0 to take "
                                              "what the source delivers");
  }
  if (!std::isfinite(fps) || fps < 0.0 || fps > 1000.0 || (device && fps == 0.0)) {
    return make_error(Errc::out_of_range, "frame rate " + fmt("%g", fps) + " fps is outside " +
                                              (device ? "(0, 1000]" : "[0, 1000] (0: the file's own rate)"));
  }
  if (!(host_latency_s >= 0.0 && host_latency_s <= 1.0)) {
    return make_error(Errc::out_of_range,
                      "host latency " + fmt("%g", host_latency_s) + " s is outside [0, 1] s (it is in seconds)");
  }
  if (!(std::abs(backend_time_offset_s) <= 1.0)) {
    return make_error(Errc::out_of_range, "backend time offset " + fmt("%g", backend_time_offset_s) +
                                              " s is outside [-1, 1] s (it is in seconds)");
  }
  if (reopen_attempts < 0 || reopen_attempts > 1000 || !(reopen_interval_s >= 0.0 && reopen_interval_s <= 60.0)) {
    return make_error(Errc::out_of_range, "reopen: attempts must be 0-1000 and the interval 0-60 s");
  }
  return Status::success();
}

std::string StereoCameraOptions::describe() const {
  std::ostringstream s;
  const bool device = input == StereoInput::device;
  if (side_by_side) {
    s << "side-by-side " << (device ? "camera " + device_path(left) : "video '" + left + "'");
  } else if (device) {
    s << "cameras " << device_path(left) << " (left) + " << device_path(right) << " (right)";
  } else {
    s << "videos '" << left << "' (left) + '" << right << "' (right)";
  }
  if (width_px > 0) {
    s << ", " << size_text(width_px, height_px) << " per camera";
  } else {
    s << ", size as delivered";
  }
  if (device) {
    s << " at " << fmt("%g", fps) << " fps; timestamps: ";
    switch (time_source) {
      case FrameTimeSource::automatic:
        s << "the backend's capture time while it is CLOCK_MONOTONIC, else host time - "
          << fmt("%g", host_latency_s * 1e3) << " ms";
        break;
      case FrameTimeSource::backend: s << "the backend's capture time"; break;
      case FrameTimeSource::host: s << "host time - " << fmt("%g", host_latency_s * 1e3) << " ms"; break;
    }
    if (time_source != FrameTimeSource::host && backend_time_offset_s != 0.0) {
      s << " (backend time - " << fmt("%g", backend_time_offset_s * 1e3) << " ms)";
    }
    s << "; reopen " << reopen_attempts << "x every " << fmt("%g", reopen_interval_s) << " s if lost";
  } else {
    s << "; timestamps " << fmt("%.9g", ns_to_seconds(file_t0_ns)) << " s + index / "
      << (fps > 0.0 ? fmt("%g", fps) + " fps" : std::string("the file's rate"));
  }
  if (reader_thread) s << "; reader thread (newest frame, drops counted)";
  if (!calibration_file.empty()) s << "; rectified with '" << calibration_file << "'";
  return s.str();
}

// --- camera -----------------------------------------------------------------

StereoCamera::StereoCamera(const StereoCameraOptions& options, std::unique_ptr<VideoSource> left,
                           std::unique_ptr<VideoSource> right, const Clock& clock)
    : options_(options), left_(std::move(left)), right_(std::move(right)), clock_(clock) {}

StereoCamera::~StereoCamera() { stop(); }

Result<std::unique_ptr<StereoCamera>> StereoCamera::open(const StereoCameraOptions& options, const Clock& clock) {
  if (auto s = options.validate(); !s) return s.error();
  const int factor = options.side_by_side ? 2 : 1;
  const int w = options.input == StereoInput::device ? options.width_px * factor : 0;
  const int h = options.input == StereoInput::device ? options.height_px : 0;
  const double fps = options.input == StereoInput::device ? options.fps : 0.0;
  auto left = make_opencv_source(options.input, options.left, w, h, fps);
  std::unique_ptr<VideoSource> right;
  if (!options.side_by_side) right = make_opencv_source(options.input, options.right, w, h, fps);
  return open(options, std::move(left), std::move(right), clock);
}

Result<std::unique_ptr<StereoCamera>> StereoCamera::open(const StereoCameraOptions& options,
                                                         std::unique_ptr<VideoSource> left,
                                                         std::unique_ptr<VideoSource> right, const Clock& clock) {
  if (auto s = options.validate(); !s) return s.error();
  if (!left || (!options.side_by_side && !right) || (options.side_by_side && right)) {
    return make_error(Errc::invalid_argument,
                      "StereoCamera::open needs one source for a side-by-side camera or two otherwise");
  }
  std::unique_ptr<StereoCamera> cam(new StereoCamera(options, std::move(left), std::move(right), clock));
  if (!options.calibration_file.empty()) {
    auto cal = StereoCalibration::load(options.calibration_file);
    if (!cal) return cal.error();
    auto rect = StereoRectifier::create(*cal);
    if (!rect) return rect.error().with_context("rectifying with '" + options.calibration_file + "'");
    cam->rectifier_ = std::move(*rect);
  }
  if (auto s = cam->open_sources(); !s) return s.error();
  if (cam->rectifier_ && options.width_px > 0) {
    const cv::Size want(options.width_px, options.height_px);
    if (cam->rectifier_->image_size() != want) {
      return make_error(Errc::invalid_argument,
                        "calibration '" + options.calibration_file + "' is for " +
                            size_text(cam->rectifier_->image_size().width, cam->rectifier_->image_size().height) +
                            " images but the camera is set to " + size_text(want.width, want.height) +
                            "; use the mode you calibrated in, or calibrate this one");
    }
  }
  if (options.input == StereoInput::file) {
    cam->fps_ = options.fps > 0.0 ? options.fps : cam->left_->fps();
    if (!(cam->fps_ > 0.0)) {
      return make_error(Errc::invalid_argument, "video '" + cam->left_->name() +
                                                    "' has no frame rate in its header; give one (--fps) so frames "
                                                    "can be timestamped");
    }
  } else {
    const double reported = cam->left_->fps();
    cam->fps_ = reported > 0.0 ? reported : options.fps;
  }
  if (options.width_px > 0) cam->set_image_size(cv::Size(options.width_px, options.height_px));
  if (options.reader_thread) cam->mailbox_ = std::make_unique<Mailbox<StereoFrame>>();
  return cam;
}

Status StereoCamera::open_sources() {
  if (auto s = left_->open(); !s) return s;
  if (right_) {
    if (auto s = right_->open(); !s) {
      left_->close();
      return s;
    }
  }
  backend_left_ = {};
  backend_right_ = {};
  return Status::success();
}

Status StereoCamera::set_rectifier(std::optional<StereoRectifier> rectifier) {
  if (started_) {
    return make_error(Errc::invalid_argument, "set the rectifier before reading the first frame");
  }
  const cv::Size size = image_size();
  if (rectifier && !size.empty() && rectifier->image_size() != size) {
    return make_error(Errc::invalid_argument,
                      "the rectifier is for " + size_text(rectifier->image_size().width,
                                                          rectifier->image_size().height) +
                          " images but the camera delivers " + size_text(size.width, size.height));
  }
  rectifier_ = std::move(rectifier);
  return Status::success();
}

Error StereoCamera::fail(CameraState state, Error error) {
  {
    std::lock_guard<std::mutex> lock(error_mutex_);
    error_ = error;
  }
  state_.store(state, std::memory_order_release);
  return error;
}

Error StereoCamera::current_error() const {
  std::lock_guard<std::mutex> lock(error_mutex_);
  return error_;
}

bool StereoCamera::sleep_unless_stopped(double seconds) {
  // Sleep in short steps so stop() never waits for a whole reopen interval.
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < until) {
    if (stop_.load(std::memory_order_acquire)) return false;
    std::this_thread::sleep_for(std::min(std::chrono::duration<double>(0.02),
                                         std::chrono::duration<double>(until - std::chrono::steady_clock::now())));
  }
  return !stop_.load(std::memory_order_acquire);
}

Status StereoCamera::reopen() {
  read_failures_.fetch_add(1, std::memory_order_relaxed);
  state_.store(CameraState::reopening, std::memory_order_release);
  const std::string names = left_->name() + (right_ ? " / " + right_->name() : "");
  left_->close();
  if (right_) right_->close();
  Status last;
  for (int attempt = 1; attempt <= options_.reopen_attempts; ++attempt) {
    logger().warn("camera {} stopped delivering frames; reopening (attempt {} of {})", names, attempt,
                  options_.reopen_attempts);
    if (!sleep_unless_stopped(options_.reopen_interval_s)) {
      return fail(CameraState::stopped, make_error(Errc::unavailable, "camera stopped"));
    }
    last = open_sources();
    if (last) {
      reopens_.fetch_add(1, std::memory_order_relaxed);
      state_.store(CameraState::streaming, std::memory_order_release);
      logger().info("camera {} reopened", names);
      return Status::success();
    }
  }
  std::string why = last ? std::string() : " (last error: " + last.error().message + ")";
  return fail(CameraState::failed,
              make_error(Errc::io_error, "camera " + names +
                                             " stopped delivering frames (unplugged, or the USB link reset) and " +
                                             std::to_string(options_.reopen_attempts) + " reopen attempts " +
                                             fmt("%g", options_.reopen_interval_s) + " s apart failed" + why +
                                             "; reconnect it (a USB 3 port for a ZED Mini) and start again"));
}

TimeNs StereoCamera::stamp(VideoSource& source, TimeNs host_after_grab_ns, std::int64_t index,
                           FrameTimeOrigin& origin, Status& status) {
  if (!source.live()) {
    origin = FrameTimeOrigin::file_index;
    return options_.file_t0_ns + seconds_to_ns(static_cast<double>(index) / fps_);
  }
  const TimeNs host_ns = host_after_grab_ns - seconds_to_ns(options_.host_latency_s);
  if (options_.time_source == FrameTimeSource::host) {
    origin = FrameTimeOrigin::host;
    return host_ns;
  }
  BackendClockCheck& check = &source == left_.get() ? backend_left_ : backend_right_;
  const double backend_ms = source.backend_time_ms();
  const double host_ms = static_cast<double>(host_after_grab_ns) * 1e-6;
  // A CLOCK_MONOTONIC capture time lies a little before the host time at
  // grab; a stream position (ms since the stream started) is far from it.
  const bool plausible = std::isfinite(backend_ms) && backend_ms <= host_ms + 1.0 && host_ms - backend_ms < 1000.0 &&
                         backend_ms > check.last_ms;
  if (plausible && check.trusted) {
    check.last_ms = backend_ms;
    origin = FrameTimeOrigin::backend;
    return static_cast<TimeNs>(std::llround(backend_ms * 1e6)) - seconds_to_ns(options_.backend_time_offset_s);
  }
  const std::string why = "camera " + source.name() + " reports capture time " + fmt("%.3f", backend_ms) +
                          " ms, which is not a CLOCK_MONOTONIC time just before now (" + fmt("%.3f", host_ms) +
                          " ms)";
  if (options_.time_source == FrameTimeSource::backend) {
    status = make_error(Errc::unsupported, why + "; this backend has no usable capture clock: use host timestamps");
    return 0;
  }
  if (check.trusted) {
    check.trusted = false;
    // A backend without a capture clock (NaN) is normal; one whose clock
    // stopped making sense is worth a warning.
    if (std::isfinite(backend_ms)) {
      logger().warn("{}; using host time at grab - {:.1f} ms from now on", why, options_.host_latency_s * 1e3);
    } else {
      logger().debug("camera {} has no backend capture time; using host time at grab - {:.1f} ms", source.name(),
                     options_.host_latency_s * 1e3);
    }
  }
  origin = FrameTimeOrigin::host;
  return host_ns;
}

Result<StereoFrame> StereoCamera::read_frame() {
  for (;;) {
    const CameraState st = state_.load(std::memory_order_acquire);
    if (st == CameraState::end_of_stream || st == CameraState::failed || st == CameraState::stopped) {
      return current_error();
    }
    const bool grabbed_left = left_->grab();
    const TimeNs host_left = clock_.now_ns();
    const bool grabbed_right = right_ ? right_->grab() : grabbed_left;
    const TimeNs host_right = right_ ? clock_.now_ns() : host_left;
    cv::Mat raw_left, raw_right;  // fresh buffers: frames already handed out keep theirs
    bool ok = grabbed_left && grabbed_right && left_->retrieve(raw_left) && (!right_ || right_->retrieve(raw_right));

    if (!ok) {
      if (!left_->live()) {
        const std::string n = std::to_string(next_index_);
        if (right_ && grabbed_left != grabbed_right) {
          const auto& ended = grabbed_left ? right_ : left_;
          const auto& goes_on = grabbed_left ? left_ : right_;
          return fail(CameraState::failed,
                      make_error(Errc::invalid_argument,
                                 "video '" + ended->name() + "' ended after " + n + " frames but '" + goes_on->name() +
                                     "' goes on; the left and right files must hold the same frames"));
        }
        if (grabbed_left && grabbed_right) {
          return fail(CameraState::failed, make_error(Errc::parse_error, "frame " + n + " of video '" +
                                                                             left_->name() +
                                                                             "' cannot be decoded (damaged file?)"));
        }
        return fail(CameraState::end_of_stream,
                    make_error(Errc::out_of_range, "end of video '" + left_->name() + "' after " + n + " frames"));
      }
      if (stop_.load(std::memory_order_acquire)) {
        return fail(CameraState::stopped, make_error(Errc::unavailable, "camera stopped"));
      }
      if (auto s = reopen(); !s) return s.error();
      continue;
    }

    raw_left = to_bgr(std::move(raw_left));
    StereoFrame f;
    if (options_.side_by_side) {
      if (raw_left.cols % 2 != 0) {
        return fail(CameraState::failed,
                    make_error(Errc::invalid_argument, "'" + left_->name() + "' delivers " +
                                                           size_text(raw_left.cols, raw_left.rows) +
                                                           " frames: an odd width is not a side-by-side stereo image"));
      }
      const int w = raw_left.cols / 2;
      f.left = raw_left(cv::Rect(0, 0, w, raw_left.rows));
      f.right = raw_left(cv::Rect(w, 0, w, raw_left.rows));
    } else {
      f.left = raw_left;
      f.right = to_bgr(std::move(raw_right));
      if (f.right.size() != f.left.size()) {
        return fail(CameraState::failed,
                    make_error(Errc::invalid_argument,
                               "left '" + left_->name() + "' delivers " + size_text(f.left.cols, f.left.rows) +
                                   " but right '" + right_->name() + "' " + size_text(f.right.cols, f.right.rows) +
                                   "; run both in the same mode"));
      }
    }
    if (image_size().empty()) set_image_size(f.left.size());
    const cv::Size expected = image_size();
    if (f.left.size() != expected) {
      const std::string per = options_.side_by_side ? " side by side" : "";
      const int factor = options_.side_by_side ? 2 : 1;
      return fail(CameraState::failed,
                  make_error(Errc::invalid_argument,
                             "'" + left_->name() + "' delivers " + size_text(f.left.cols * factor, f.left.rows) +
                                 " frames, not " + size_text(expected.width * factor, expected.height) + per +
                                 "; set the size to what the source delivers"));
    }

    const std::int64_t index = next_index_;
    Status ts_status;
    f.t_ns = stamp(*left_, host_left, index, f.time_origin, ts_status);
    FrameTimeOrigin right_origin = f.time_origin;
    f.t_right_ns = right_ ? stamp(*right_, host_right, index, right_origin, ts_status) : f.t_ns;
    if (!ts_status) return fail(CameraState::failed, ts_status.error());

    if (rectifier_) {
      cv::Mat l, r;
      if (auto s = rectifier_->rectify(f.left, f.right, l, r); !s) return fail(CameraState::failed, s.error());
      f.left = l;
      f.right = r;
      f.rectified = true;
    }
    f.index = index;
    ++next_index_;
    frames_.fetch_add(1, std::memory_order_relaxed);
    return f;
  }
}

void StereoCamera::start() {
  if (started_) return;
  started_ = true;
  if (mailbox_) reader_ = std::thread([this] { reader_loop(); });
}

void StereoCamera::reader_loop() {
  while (!stop_.load(std::memory_order_acquire)) {
    auto f = read_frame();
    if (!f) return;  // read_frame left the state and error for the consumer
    mailbox_->publish(*f);
  }
}

StereoFrame StereoCamera::take(const StereoFrame& frame) {
  // Frames before the first one taken count too: nobody saw them.
  if (frame.index > last_taken_index_ + 1) {
    dropped_.fetch_add(frame.index - last_taken_index_ - 1, std::memory_order_relaxed);
  }
  last_taken_index_ = frame.index;
  return frame;
}

Result<StereoFrame> StereoCamera::next(double timeout_s) {
  start();
  if (!mailbox_) return read_frame();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(std::max(timeout_s, 0.0));
  StereoFrame f;
  for (;;) {
    if (mailbox_->fetch(f)) return take(f);
    // The reader publishes its last frame before it stores a final state, so
    // a final state read here means any last frame is already in the mailbox.
    const CameraState st = state_.load(std::memory_order_acquire);
    if (st == CameraState::end_of_stream || st == CameraState::failed || st == CameraState::stopped) {
      if (mailbox_->fetch(f)) return take(f);
      return current_error();
    }
    if (std::chrono::steady_clock::now() >= deadline) {
      return make_error(Errc::unavailable, "no new frame from " + left_->name() + " within " +
                                               fmt("%g", timeout_s) + " s (camera state: " + to_string(st) + ")");
    }
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
}

std::optional<StereoFrame> StereoCamera::try_latest() {
  start();
  if (!mailbox_) {
    auto f = read_frame();
    if (!f) return std::nullopt;
    return std::move(*f);
  }
  StereoFrame f;
  if (mailbox_->fetch(f)) return take(f);
  return std::nullopt;
}

StereoCameraStats StereoCamera::stats() const noexcept {
  StereoCameraStats s;
  s.frames = frames_.load(std::memory_order_relaxed);
  s.dropped = dropped_.load(std::memory_order_relaxed);
  s.read_failures = read_failures_.load(std::memory_order_relaxed);
  s.reopens = reopens_.load(std::memory_order_relaxed);
  return s;
}

std::string StereoCamera::describe() const {
  std::string s = options_.describe();
  const cv::Size size = image_size();
  if (!size.empty()) s += "; delivering " + size_text(size.width, size.height) + " per camera";
  s += " at " + fmt("%g", fps_) + " fps";
  return s;
}

void StereoCamera::stop() {
  stop_.store(true, std::memory_order_release);
  if (reader_.joinable()) reader_.join();
  const CameraState st = state_.load(std::memory_order_acquire);
  if (st == CameraState::streaming || st == CameraState::reopening) {
    (void)fail(CameraState::stopped, make_error(Errc::unavailable, "the camera was stopped"));
  }
  if (left_) left_->close();
  if (right_) right_->close();
}

}  // namespace proprio::vist
