#pragma once
// Stereo camera input for VIST: a side-by-side UVC stereo camera (ZED Mini:
// one /dev/videoN delivering 2560x720, left camera in the left half), two
// separate cameras, or recorded video (one side-by-side file or a pair of
// files). Frames come out as left/right BGR images with the time they were
// *measured* on CLOCK_MONOTONIC, optionally rectified with a calibration
// (stereo_calibration.hpp). docs/stereo-camera.md is the user's guide.
//
// Timestamps (FrameTimeSource):
// - Files: t0 + index / fps. A file has no clock; the grid is exact and
//   reproducible, which replays and tests want.
// - Devices: OpenCV 4.6's V4L2 backend answers CAP_PROP_POS_MSEC with the
//   kernel's buffer timestamp (struct v4l2_buffer.timestamp, as ms). For UVC
//   cameras uvcvideo stamps buffers on CLOCK_MONOTONIC (flag
//   V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC), near the start of the frame's exposure
//   or reception, so it is the capture time we want and free of the
//   user-space scheduling jitter of a host timestamp. Other backends
//   (GStreamer, FFmpeg) report a stream position instead. So in `automatic`
//   mode a device frame uses the backend time only while it looks like a
//   monotonic capture time: within a second before the host time at grab and
//   increasing; otherwise (and from then on, with a warning) it is the host
//   time when grab() returned minus host_latency_s.
//
// Threads: without a reader thread, next() reads from the source on the
// caller's thread. A live V4L2 device queues a few buffers, so a slow caller
// gets stale frames; with reader_thread the camera is drained continuously on
// its own thread and next()/try_latest() hand out the newest frame through a
// lock-free mailbox; frames replaced before the consumer took them are counted
// as dropped.
//
// Failures: a device that stops delivering (unplugged, USB reset) is closed
// and reopened up to reopen_attempts times, reopen_interval_s apart; then the
// camera is in the failed state and every call returns the error. The end of a
// file is the end_of_stream state (Errc::out_of_range).
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include <opencv2/core.hpp>

#include "proprio/core/mailbox.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/vist/stereo_calibration.hpp"

namespace proprio::vist {

enum class StereoInput : std::uint8_t { device, file };

enum class FrameTimeSource : std::uint8_t {
  automatic,  // devices: backend capture time while it is plausible, else host; files: index / fps
  backend,    // devices: the backend's capture time or an error; files: index / fps
  host,       // devices: host time at grab minus host_latency_s; files: index / fps
};

// Where one frame's timestamp came from.
enum class FrameTimeOrigin : std::uint8_t { backend, host, file_index };

const char* to_string(StereoInput v) noexcept;
const char* to_string(FrameTimeSource v) noexcept;
const char* to_string(FrameTimeOrigin v) noexcept;
std::optional<FrameTimeSource> parse_frame_time_source(std::string_view s) noexcept;

struct StereoCameraOptions {
  StereoInput input = StereoInput::device;
  // A device ("/dev/video0", or its number "0") or a video file. With
  // side_by_side it is the only source; otherwise the left camera's.
  std::string left = "/dev/video0";
  std::string right;  // the right camera or file, only when !side_by_side
  bool side_by_side = true;
  // Each camera's image; a side-by-side frame is twice as wide. 0 x 0 takes
  // what the source delivers (a device's current mode, a file's size).
  int width_px = 1280;
  int height_px = 720;
  // Devices: the rate requested from the camera. Files: the timestamp grid;
  // 0 takes the rate in the file's header.
  double fps = 30.0;
  FrameTimeSource time_source = FrameTimeSource::automatic;
  // Devices with host timestamps: from the middle of the exposure to grab()
  // returning (exposure, readout, USB transfer, driver). About one frame
  // period for a UVC camera; measure it for your camera (docs/stereo-camera.md).
  double host_latency_s = 0.035;
  // Devices with backend timestamps: subtracted from them (uvcvideo stamps the
  // start of a frame; half the exposure time moves it to the middle).
  double backend_time_offset_s = 0.0;
  TimeNs file_t0_ns = 0;  // the first file frame's timestamp
  int reopen_attempts = 3;  // after a device stops delivering; 0 fails at once
  double reopen_interval_s = 1.0;
  bool reader_thread = false;
  // Rectify every frame with this calibration ('proprio calibrate stereo --out').
  std::string calibration_file;

  Status validate() const;
  std::string describe() const;
};

struct StereoFrame {
  // BGR, 8 bit. Unrectified side-by-side frames are two views into one buffer
  // (not continuous); the buffer is never reused by the camera.
  cv::Mat left;
  cv::Mat right;
  TimeNs t_ns = 0;        // measured time of the left image, CLOCK_MONOTONIC (files: t0 + index / fps)
  TimeNs t_right_ns = 0;  // of the right image (the same for a side-by-side source)
  std::int64_t index = 0;  // frames read from the source since open, from 0; keeps counting across reopens
  FrameTimeOrigin time_origin = FrameTimeOrigin::host;
  bool rectified = false;
};

enum class CameraState : std::uint8_t { streaming, reopening, end_of_stream, failed, stopped };
const char* to_string(CameraState s) noexcept;

struct StereoCameraStats {
  std::int64_t frames = 0;         // frames read from the source
  std::int64_t dropped = 0;        // reader thread: frames replaced before anyone took them
  std::int64_t read_failures = 0;  // times a device stopped delivering
  std::int64_t reopens = 0;        // successful reopens after that
};

// One stream of images: a camera or a video file. StereoCamera reads one
// (side by side) or two. open_video_source() makes the cv::VideoCapture one;
// other backends (and tests scripting failures) implement their own.
class VideoSource {
 public:
  virtual ~VideoSource() = default;
  virtual std::string name() const = 0;  // "/dev/video0", "left.avi": for messages
  virtual bool live() const = 0;         // a device (true) or a file
  // Opens, or reopens after close(); the error says what to do.
  virtual Status open() = 0;
  virtual void close() = 0;
  // grab() takes the next frame (false: end of file or the device failed),
  // retrieve() decodes it. Split so two cameras are grabbed close together.
  virtual bool grab() = 0;
  virtual bool retrieve(cv::Mat& bgr) = 0;
  // The backend's capture time of the last grabbed frame, ms (OpenCV's
  // CAP_PROP_POS_MSEC), or NaN if it has none.
  virtual double backend_time_ms() const = 0;
  // The frame rate the source reports, 0 if unknown.
  virtual double fps() const = 0;
};

// cv::VideoCapture on a V4L2 device (requesting width x height at fps when
// they are > 0) or on a video file (FFmpeg). Not opened yet: call open().
std::unique_ptr<VideoSource> make_opencv_source(StereoInput input, const std::string& device_or_file, int width_px,
                                                int height_px, double fps);

// One thread consumes frames (next, try_latest, set_rectifier, start, stop);
// state() and stats() may be read from any thread.
class StereoCamera {
 public:
  // Opens the sources the options name and, if calibration_file is set,
  // builds the rectification maps. The clock must outlive the camera.
  static Result<std::unique_ptr<StereoCamera>> open(const StereoCameraOptions& options,
                                                    const Clock& clock = MonotonicClock::instance());
  // With sources made elsewhere: one side-by-side source (right == nullptr)
  // or two. options.left/right are then only names; everything else applies.
  static Result<std::unique_ptr<StereoCamera>> open(const StereoCameraOptions& options,
                                                    std::unique_ptr<VideoSource> left,
                                                    std::unique_ptr<VideoSource> right,
                                                    const Clock& clock = MonotonicClock::instance());
  ~StereoCamera();
  StereoCamera(const StereoCamera&) = delete;
  StereoCamera& operator=(const StereoCamera&) = delete;

  // Rectify frames with these maps (nullopt: stop rectifying). Only before the
  // first frame is read, because the reader thread uses them.
  Status set_rectifier(std::optional<StereoRectifier> rectifier);
  // Starts reading: the reader thread, if the options ask for one. The first
  // next() or try_latest() does this too; call it to start grabbing earlier.
  void start();

  // The next frame. Without a reader thread: reads it now (blocking on the
  // source; reopening a lost device). With one: the newest frame newer than the
  // last one returned, waiting up to timeout_s. Errors: end of file
  // (Errc::out_of_range), device lost for good (Errc::io_error), wrong frame
  // size (Errc::invalid_argument), nothing within timeout_s (Errc::unavailable).
  Result<StereoFrame> next(double timeout_s = 1.0);
  // Reader thread: the newest frame if one arrived since the last call, else
  // nullopt, never waiting. Without a reader thread: reads a frame now like
  // next(), nullopt on an error (state() says which).
  std::optional<StereoFrame> try_latest();

  CameraState state() const noexcept { return state_.load(std::memory_order_acquire); }
  StereoCameraStats stats() const noexcept;
  const StereoCameraOptions& options() const noexcept { return options_; }
  // Each camera's image size; empty until known (0x0 options: the first frame).
  cv::Size image_size() const noexcept {
    return {image_width_.load(std::memory_order_acquire), image_height_.load(std::memory_order_acquire)};
  }
  double fps() const noexcept { return fps_; }
  std::string describe() const;
  // Stops the reader thread and closes the sources; next() then fails.
  void stop();

 private:
  StereoCamera(const StereoCameraOptions& options, std::unique_ptr<VideoSource> left,
               std::unique_ptr<VideoSource> right, const Clock& clock);
  Status open_sources();
  Result<StereoFrame> read_frame();  // from the source, on the reading thread
  Error fail(CameraState state, Error error);
  Status reopen();
  TimeNs stamp(VideoSource& source, TimeNs host_after_grab_ns, std::int64_t index, FrameTimeOrigin& origin,
               Status& status);
  void set_image_size(cv::Size s) noexcept {
    image_width_.store(s.width, std::memory_order_release);
    image_height_.store(s.height, std::memory_order_release);
  }
  void reader_loop();
  bool sleep_unless_stopped(double seconds);
  Error current_error() const;
  StereoFrame take(const StereoFrame& frame);  // consumer side: count drops

  StereoCameraOptions options_;
  std::unique_ptr<VideoSource> left_;
  std::unique_ptr<VideoSource> right_;
  const Clock& clock_;
  std::optional<StereoRectifier> rectifier_;
  // Written once by the reading thread, read by anyone.
  std::atomic<int> image_width_{0}, image_height_{0};
  double fps_ = 0.0;

  // Reading thread (the caller's or the reader's).
  std::int64_t next_index_ = 0;
  struct BackendClockCheck {
    bool trusted = true;  // until a frame fails the plausibility test
    double last_ms = 0.0;
  };
  BackendClockCheck backend_left_, backend_right_;
  bool started_ = false;

  std::atomic<CameraState> state_{CameraState::streaming};
  std::atomic<bool> stop_{false};
  std::atomic<std::int64_t> frames_{0}, dropped_{0}, read_failures_{0}, reopens_{0};
  mutable std::mutex error_mutex_;  // only the rare terminal error, never per frame
  Error error_;

  // Reader thread.
  std::unique_ptr<Mailbox<StereoFrame>> mailbox_;
  std::thread reader_;
  std::int64_t last_taken_index_ = -1;  // consumer-owned
};

}  // namespace proprio::vist
