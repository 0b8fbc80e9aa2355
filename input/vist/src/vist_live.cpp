#include "proprio/vist/vist_live.hpp"

#include <chrono>
#include <cmath>
#include <fmt/format.h>

#include "proprio/core/log.hpp"

namespace proprio::vist {

Status VistLiveOptions::validate() const {
  if (auto s = detector.validate(); !s) return s;
  if (!std::isfinite(file_latency_s) || file_latency_s < 0.0 || file_latency_s > 1.0) {
    return make_error(Errc::invalid_argument,
                      fmt::format("VIST live: file_latency_s = {} must be in [0, 1] s", file_latency_s));
  }
  if (!std::isfinite(camera_retry_s) || camera_retry_s < 0.01 || camera_retry_s > 60.0) {
    return make_error(Errc::invalid_argument,
                      fmt::format("VIST live: camera_retry_s = {} must be in [0.01, 60] s", camera_retry_s));
  }
  if (!T_world_head_fixed.p.allFinite() || !T_world_head_fixed.q.coeffs().allFinite() ||
      std::abs(T_world_head_fixed.q.norm() - 1.0) > 1e-6) {
    return make_error(Errc::invalid_argument, "VIST live: T_world_head_fixed must be finite with a unit quaternion");
  }
  return {};
}

std::string VistLiveOptions::describe() const {
  const Vec3& p = T_world_head_fixed.p;
  return fmt::format(
      "VIST live: head (without a provider) fixed at ({:.3f}, {:.3f}, {:.3f}) m; video files "
      "delivered {:.0f} ms after their timestamps; a missing camera retried every {:g} s\n  {}",
      p.x(), p.y(), p.z(), 1e3 * file_latency_s, camera_retry_s, detector.describe());
}

std::string VistLiveStats::describe() const {
  std::string s = fmt::format("glove {}, {} IMU samples", hid::to_string(glove_state), imu_samples);
  if (imu_unknown_sensor > 0) s += fmt::format(" ({} from IMUs the glove file does not have)", imu_unknown_sensor);
  s += fmt::format("; camera {}{}, {} stereo frames, {:.1f} markers per frame, detection {:.2f} ms per pair",
                   camera_open ? to_string(camera_state) : "not open",
                   camera_opens > 1 ? fmt::format(" (opened {} times)", camera_opens) : std::string(), frames,
                   frames > 0 ? static_cast<double>(markers_detected) / static_cast<double>(frames) : 0.0,
                   detection_ms_mean);
  if (frames_without_head > 0) s += fmt::format(", {} without a head pose", frames_without_head);
  if (detection_errors > 0) s += fmt::format(", {} detection errors", detection_errors);
  if (!camera_error.empty()) s += " (" + camera_error + ")";
  return s;
}

namespace {

Status check_camera_size(const StereoCamera& camera, const ImuGloveDescription& glove) {
  const cv::Size size = camera.image_size();
  const PinholeCamera& expected = glove.rig.camera;
  if (!size.empty() && (size.width != expected.width_px || size.height != expected.height_px)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("VIST live: the camera delivers {}x{} images but the glove description's rig ({}) "
                                  "is {}x{}; set the rig's camera to the camera's (rectified) intrinsics",
                                  size.width, size.height, glove.origin.empty() ? glove.name : glove.origin,
                                  expected.width_px, expected.height_px));
  }
  return {};
}

}  // namespace

Result<std::unique_ptr<VistLiveInput>> VistLiveInput::create(VistHandSource& sink, const ImuGloveDescription& glove,
                                                             std::unique_ptr<devices::ImuGloveDevice> glove_device,
                                                             std::unique_ptr<StereoCamera> camera,
                                                             VistLiveOptions options, HeadPoseProvider head,
                                                             const Clock& clock) {
  if (!camera) return make_error(Errc::invalid_argument, "VIST live: no stereo camera");
  if (auto s = check_camera_size(*camera, glove); !s) return s.error();
  return make(sink, glove, std::move(glove_device), std::move(camera), nullptr, std::move(options), std::move(head),
              clock);
}

Result<std::unique_ptr<VistLiveInput>> VistLiveInput::create_with_opener(
    VistHandSource& sink, const ImuGloveDescription& glove, std::unique_ptr<devices::ImuGloveDevice> glove_device,
    StereoCameraOpener open_camera, VistLiveOptions options, HeadPoseProvider head, const Clock& clock) {
  if (!open_camera) return make_error(Errc::invalid_argument, "VIST live: no way to open a stereo camera");
  return make(sink, glove, std::move(glove_device), nullptr, std::move(open_camera), std::move(options),
              std::move(head), clock);
}

Result<std::unique_ptr<VistLiveInput>> VistLiveInput::make(VistHandSource& sink, const ImuGloveDescription& glove,
                                                           std::unique_ptr<devices::ImuGloveDevice> glove_device,
                                                           std::unique_ptr<StereoCamera> camera,
                                                           StereoCameraOpener opener, VistLiveOptions options,
                                                           HeadPoseProvider head, const Clock& clock) {
  if (!glove_device) return make_error(Errc::invalid_argument, "VIST live: no glove device");
  if (glove_device->running()) return make_error(Errc::invalid_argument, "VIST live: the glove is already started");
  if (auto s = options.validate(); !s) return s.error();
  if (glove.imus.empty()) return make_error(Errc::invalid_argument, "VIST live: the glove description has no IMUs");
  auto detector = MarkerDetector::create(glove.rig.camera, options.detector);
  if (!detector) return detector.error();
  return std::unique_ptr<VistLiveInput>(new VistLiveInput(
      sink, glove.imus.size(), glove.rig.camera, glove.rig.T_head_leftcam, std::move(glove_device), std::move(camera),
      std::move(opener), std::move(*detector), std::move(options), std::move(head), clock));
}

VistLiveInput::VistLiveInput(VistHandSource& sink, std::size_t imu_count, const PinholeCamera& camera_model,
                             Pose T_head_leftcam, std::unique_ptr<devices::ImuGloveDevice> glove,
                             std::unique_ptr<StereoCamera> camera, StereoCameraOpener opener, MarkerDetector detector,
                             VistLiveOptions options, HeadPoseProvider head, const Clock& clock)
    : sink_(sink),
      imu_count_(imu_count),
      camera_model_(camera_model),
      T_head_leftcam_(T_head_leftcam),
      glove_(std::move(glove)),
      camera_(std::move(camera)),
      opener_(std::move(opener)),
      detector_(std::move(detector)),
      options_(std::move(options)),
      head_(std::move(head)),
      clock_(clock) {
  if (camera_) {
    camera_stats_.camera_open = true;
    camera_stats_.camera_opens = 1;
  }
  // The glove's reader thread pushes straight into the tracker's queue: one
  // hand-off, and the samples keep the order the board sent them in.
  glove_->set_sample_callback([this](const devices::ImuGloveSample& g) {
    if (g.imu.sensor_id >= imu_count_) {
      imu_unknown_.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    TimedImuSample s;
    s.time_ns = g.time_ns;
    s.sample = g.imu;
    s.accel_clipped = (g.status & devices::imu_status::accel_saturated) != 0;
    s.gyro_clipped = (g.status & devices::imu_status::gyro_saturated) != 0;
    sink_.push_imu(s);
    imu_samples_.fetch_add(1, std::memory_order_relaxed);
  });
}

VistLiveInput::~VistLiveInput() { stop(); }

Status VistLiveInput::start() {
  if (camera_thread_.joinable() || glove_->running()) {
    return make_error(Errc::invalid_argument, "VIST live: already started");
  }
  stop_.store(false, std::memory_order_release);
  if (auto s = glove_->start(); !s) return s;
  camera_running_.store(true, std::memory_order_release);
  camera_thread_ = std::thread([this] { camera_loop(); });
  return {};
}

void VistLiveInput::stop() {
  stop_.store(true, std::memory_order_release);
  if (camera_thread_.joinable()) camera_thread_.join();
  glove_->stop();
  if (camera_) camera_->stop();
}

bool VistLiveInput::wait_until(TimeNs t_ns) {
  while (!stop_.load(std::memory_order_acquire)) {
    const TimeNs left = t_ns - clock_.now_ns();
    if (left <= 0) return true;
    std::this_thread::sleep_for(std::chrono::nanoseconds(std::min<TimeNs>(left, 20 * kNsPerMillisecond)));
  }
  return false;
}

bool VistLiveInput::open_camera() {
  auto camera = opener_();
  Status fits;
  if (!camera) {
    fits = camera.error();
  } else if (!*camera) {
    fits = make_error(Errc::unavailable, "the camera opener returned nothing");
  } else if (const cv::Size size = (*camera)->image_size();
             !size.empty() && (size.width != camera_model_.width_px || size.height != camera_model_.height_px)) {
    fits = make_error(Errc::invalid_argument,
                      fmt::format("the camera delivers {}x{} images but the glove description's rig is {}x{}",
                                  size.width, size.height, camera_model_.width_px, camera_model_.height_px));
  }
  if (!fits) {
    if (camera && *camera) (*camera)->stop();
    const std::string why = fits.error().message;
    if (why != last_logged_camera_error_) {
      logger().warn("VIST live: no stereo camera: {}; trying again every {:g} s", why, options_.camera_retry_s);
      last_logged_camera_error_ = why;
    }
    std::lock_guard lock(stats_mutex_);
    ++camera_stats_.camera_open_failures;
    camera_stats_.camera_error = why;
    return false;
  }
  logger().info("VIST live: camera open: {}", (*camera)->describe());
  last_logged_camera_error_.clear();
  std::lock_guard lock(stats_mutex_);
  camera_ = std::move(*camera);
  camera_stats_.camera_open = true;
  ++camera_stats_.camera_opens;
  camera_stats_.camera_error.clear();
  return true;
}

void VistLiveInput::drop_camera(std::string why) {
  camera_->stop();
  if (why != last_logged_camera_error_) {
    logger().warn("VIST live: camera lost: {}; reopening every {:g} s", why, options_.camera_retry_s);
    last_logged_camera_error_ = why;
  }
  std::unique_ptr<StereoCamera> gone;
  {
    std::lock_guard lock(stats_mutex_);
    gone = std::move(camera_);
    camera_stats_.camera_open = false;
    camera_stats_.camera_error = std::move(why);
  }
}

void VistLiveInput::camera_loop() {
  std::string ended;
  while (!stop_.load(std::memory_order_acquire)) {
    if (!camera_) {
      if (!opener_) break;
      if (!open_camera()) {
        if (!wait_until(clock_.now_ns() + seconds_to_ns(options_.camera_retry_s))) break;
        continue;
      }
    }
    const bool file = camera_->options().input == StereoInput::file;
    auto frame = camera_->next(0.25);
    if (!frame) {
      if (frame.error().code == Errc::unavailable) continue;  // nothing yet: check for stop, wait again
      if (frame.error().code == Errc::out_of_range) {
        ended = "end of the video";
        break;
      }
      if (!opener_) {
        ended = frame.error().message;
        break;
      }
      drop_camera(frame.error().message);
      if (!wait_until(clock_.now_ns() + seconds_to_ns(options_.camera_retry_s))) break;
      continue;
    }
    if (file && !wait_until(frame->t_ns + seconds_to_ns(options_.file_latency_s))) break;
    VistStereoFrame out;
    out.capture_time_ns = frame->t_ns;
    const auto t0 = std::chrono::steady_clock::now();
    const Status detected = detector_.detect_stereo(frame->left, frame->right, out.left, out.right);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    Pose T_world_head = options_.T_world_head_fixed;
    const bool have_head = !head_ || head_(frame->t_ns, T_world_head);
    {
      std::lock_guard lock(stats_mutex_);
      if (!detected) {
        ++camera_stats_.detection_errors;
        camera_stats_.camera_error = detected.error().message;
        continue;
      }
      if (!have_head) {
        ++camera_stats_.frames_without_head;
        continue;
      }
      ++camera_stats_.frames;
      camera_stats_.markers_detected += out.left.markers.size() + out.right.markers.size();
      camera_stats_.last_frame_capture_ns = frame->t_ns;
      detection_ms_sum_ += ms;
    }
    out.T_world_leftcam = T_world_head * T_head_leftcam_;
    sink_.push_stereo_frame(std::move(out));
    last_frame_ns_.store(frame->t_ns, std::memory_order_release);
  }
  {
    std::lock_guard lock(stats_mutex_);
    if (!ended.empty()) camera_stats_.camera_error = ended;
  }
  camera_running_.store(false, std::memory_order_release);
}

VistLiveStats VistLiveInput::stats() const {
  VistLiveStats s;
  {
    std::lock_guard lock(stats_mutex_);
    s = camera_stats_;
    s.detection_ms_mean = s.frames > 0 ? detection_ms_sum_ / static_cast<double>(s.frames) : 0.0;
    s.camera_state = camera_ ? camera_->state() : CameraState::stopped;
  }
  s.glove_state = glove_->state();
  s.imu_samples = imu_samples_.load(std::memory_order_relaxed);
  s.imu_unknown_sensor = imu_unknown_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace proprio::vist
