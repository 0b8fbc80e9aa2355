#pragma once
// VIST with a real glove: the wiring from the devices to the tracker.
//
//   IMU board --USB HID--> ImuGloveDevice (reader thread: decode, hid::ClockSync)
//        --sample callback--> VistHandSource::push_imu
//   stereo camera --> StereoCamera --> camera thread: MarkerDetector on both
//        images --> VistHandSource::push_stereo_frame (at the capture time,
//        with the camera's pose in the world at that time)
//
// Every timestamp is CLOCK_MONOTONIC: ImuGloveDevice maps the board's µs
// counter there and StereoCamera stamps device frames there, so the tracker
// sees one time base and fuses late frames at their capture time.
//
// Where the camera is: the stereo rig sits on the head (ImuGloveDescription's
// rig.T_head_leftcam). With an HMD, pass a head pose provider (the engine
// asks OpenXR for the VIEW space at the frame's time); without one the head
// is fixed at options.T_world_head_fixed, i.e. the camera does not move.
//
// A video file instead of a camera is played in real time: each frame is
// held back until its timestamp (file_t0_ns + index / fps) plus
// file_latency_s has come, as a live camera would deliver it. The end of the
// file ends the camera thread; the glove keeps streaming.
//
// Unplugs: the glove reconnects on its own (ImuGloveDevice); a camera that
// stops delivering is reopened by StereoCamera. Given a camera, a camera lost
// for good (StereoCamera's `failed`) ends the camera thread. Given a
// StereoCameraOpener instead, the camera thread opens the camera itself and
// keeps trying (camera_retry_s apart) while it is not there, and again after
// it is lost: a camera plugged in later is picked up. Neither stops the
// other: the tracker runs on what arrives and re-acquires when both are back.
// (VistLiveSource, vist_live_source.hpp, is the whole thing as a HandSource.)
#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/imu_glove_board/imu_glove_device.hpp"
#include "proprio/vist/marker_detection.hpp"
#include "proprio/vist/stereo_camera.hpp"
#include "proprio/vist/vist_hand_source.hpp"

namespace proprio::vist {

// The head (OpenXR VIEW frame) in the world at t_ns, or false if unknown then
// (the frame is dropped and counted). Called on the camera thread.
using HeadPoseProvider = std::function<bool(TimeNs t_ns, Pose& T_world_head)>;

// Opens the stereo camera, on the camera thread (so a camera that is slow to
// open or not there yet never holds up the caller). An error is retried.
using StereoCameraOpener = std::function<Result<std::unique_ptr<StereoCamera>>()>;

struct VistLiveOptions {
  MarkerDetectorOptions detector;
  // The head when no provider is given: standing, looking along -Z.
  Pose T_world_head_fixed{Quat::Identity(), Vec3(0.0, 1.6, 0.0)};
  // Video files: the delay from a frame's timestamp to its delivery.
  double file_latency_s = 0.03;
  // With a StereoCameraOpener: the wait between attempts to open a camera
  // that is not there, and after a camera was lost for good.
  double camera_retry_s = 1.0;

  Status validate() const;
  std::string describe() const;
};

struct VistLiveStats {
  hid::LinkState glove_state = hid::LinkState::stopped;
  CameraState camera_state = CameraState::stopped;
  std::string camera_error;                // why the camera thread ended, or why no camera is open now
  bool camera_open = false;                // a camera is open (it may still be reopening)
  std::uint64_t camera_opens = 0;          // cameras opened (1 for a camera given to create)
  std::uint64_t camera_open_failures = 0;  // StereoCameraOpener calls that failed
  std::uint64_t imu_samples = 0;          // pushed to the tracker
  std::uint64_t imu_unknown_sensor = 0;   // sensor id not in the glove description: dropped
  std::uint64_t frames = 0;               // stereo frames detected and pushed
  TimeNs last_frame_capture_ns = 0;       // of the newest frame pushed; 0: none yet
  std::uint64_t frames_without_head = 0;  // no head pose at the capture time: dropped
  std::uint64_t detection_errors = 0;
  std::uint64_t markers_detected = 0;     // over all frames, both cameras
  double detection_ms_mean = 0.0;         // detector time per stereo pair
  std::string describe() const;
};

class VistLiveInput {
 public:
  // Takes the glove and the camera (both not started yet) and feeds `sink`,
  // which must outlive this object. The sink's glove description says how
  // many IMUs there are and which camera the detector expects.
  static Result<std::unique_ptr<VistLiveInput>> create(VistHandSource& sink, const ImuGloveDescription& glove,
                                                       std::unique_ptr<devices::ImuGloveDevice> glove_device,
                                                       std::unique_ptr<StereoCamera> camera,
                                                       VistLiveOptions options = {},
                                                       HeadPoseProvider head = nullptr,
                                                       const Clock& clock = MonotonicClock::instance());
  // The same with a camera the camera thread opens itself (and reopens).
  // Each camera opened must deliver the rig's image size; one that does not
  // is closed again and the error kept in stats().camera_error.
  static Result<std::unique_ptr<VistLiveInput>> create_with_opener(
      VistHandSource& sink, const ImuGloveDescription& glove, std::unique_ptr<devices::ImuGloveDevice> glove_device,
      StereoCameraOpener open_camera, VistLiveOptions options = {}, HeadPoseProvider head = nullptr,
      const Clock& clock = MonotonicClock::instance());
  ~VistLiveInput();  // stop()s
  VistLiveInput(const VistLiveInput&) = delete;
  VistLiveInput& operator=(const VistLiveInput&) = delete;

  // Starts the glove's reader thread and the camera thread.
  Status start();
  // Stops both and joins them. The sink keeps what it has.
  void stop();
  bool camera_running() const noexcept { return camera_running_.load(std::memory_order_acquire); }
  // Capture time of the newest stereo frame pushed to the tracker; 0: none yet.
  TimeNs last_frame_capture_ns() const noexcept { return last_frame_ns_.load(std::memory_order_acquire); }

  VistLiveStats stats() const;
  devices::ImuGloveDevice& glove_device() noexcept { return *glove_; }

 private:
  VistLiveInput(VistHandSource& sink, std::size_t imu_count, const PinholeCamera& camera_model, Pose T_head_leftcam,
                std::unique_ptr<devices::ImuGloveDevice> glove, std::unique_ptr<StereoCamera> camera,
                StereoCameraOpener opener, MarkerDetector detector, VistLiveOptions options, HeadPoseProvider head,
                const Clock& clock);
  static Result<std::unique_ptr<VistLiveInput>> make(VistHandSource& sink, const ImuGloveDescription& glove,
                                                     std::unique_ptr<devices::ImuGloveDevice> glove_device,
                                                     std::unique_ptr<StereoCamera> camera, StereoCameraOpener opener,
                                                     VistLiveOptions options, HeadPoseProvider head,
                                                     const Clock& clock);
  void camera_loop();
  bool open_camera();                 // camera thread: one attempt with the opener
  void drop_camera(std::string why);  // camera thread: close it, keep why
  bool wait_until(TimeNs t_ns);  // false: stopping

  VistHandSource& sink_;
  std::size_t imu_count_;
  PinholeCamera camera_model_;  // the rig's: what every camera must deliver
  Pose T_head_leftcam_;
  std::unique_ptr<devices::ImuGloveDevice> glove_;
  // Replaced only by the camera thread, under stats_mutex_ (stats() reads its state).
  std::unique_ptr<StereoCamera> camera_;
  StereoCameraOpener opener_;             // null: camera_ is the only camera
  std::string last_logged_camera_error_;  // camera thread: log each new reason once
  MarkerDetector detector_;
  VistLiveOptions options_;
  HeadPoseProvider head_;
  const Clock& clock_;

  std::atomic<std::uint64_t> imu_samples_{0}, imu_unknown_{0};
  mutable std::mutex stats_mutex_;
  VistLiveStats camera_stats_;  // the camera thread's part, under stats_mutex_
  double detection_ms_sum_ = 0.0;

  std::atomic<TimeNs> last_frame_ns_{0};
  std::atomic<bool> stop_{false};
  std::atomic<bool> camera_running_{false};
  std::thread camera_thread_;
};

}  // namespace proprio::vist
