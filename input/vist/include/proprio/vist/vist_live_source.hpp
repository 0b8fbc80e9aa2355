#pragma once
// VIST live as one HandSource that owns its whole pipeline: the tracker
// (VistHandSource), the device wiring (VistLiveInput: the glove's reader
// thread, the camera thread) and whatever those need to stay alive (an
// emulator). What the OpenXR layer's `vist` source with input "device" or
// "emulated" and `proprio track vist --live` run.
//
// Starting never waits for hardware: the glove connects whenever it is
// plugged in (ImuGloveDevice) and the camera is opened on the camera thread,
// retried until it appears and again after it is lost. Only configuration
// errors fail start (files that cannot be read, a calibration that does not
// match the glove description's rig).
//
// Inactive hand: besides what the tracker says (not acquired yet, no IMU data:
// the history goes stale), the hand is reported inactive while no stereo frame
// has corrected the tracker for vision_timeout_s: the camera is gone, the head
// pose is unknown so frames cannot be placed in the world, or frames arrive
// but none of their markers fit the prediction (a lock lost after a replug).
// The IMUs alone would drift, and a hand that drifts away is worse than none.
//
// The camera's place: the stereo rig sits on the head at the glove
// description's rig.T_head_leftcam (the rectified left camera in the OpenXR
// VIEW frame), so the glove file must hold the rig of the camera in use: the
// [rig] table `proprio calibrate stereo --glove <file>` prints, with the
// mount measured on the headset. The calibration file itself only rectifies;
// start_vist_devices refuses one whose rectified camera is not the rig's.
#include <memory>
#include <string>

#include "proprio/core/hand_source.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/tracked_pose_provider.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/vist/vist_hand_source.hpp"
#include "proprio/vist/vist_live.hpp"

namespace proprio::vist {

struct VistLiveSourceOptions {
  VistHandSourceOptions source;
  VistLiveOptions live;
  // The hand is inactive once the newest stereo frame whose markers corrected
  // the tracker (VistTracker::last_vision_fix_ns) is this much older than the
  // time asked for (seconds).
  double vision_timeout_s = 1.0;

  Status validate() const;
  std::string describe() const;
};

class VistLiveSource final : public HandSource {
 public:
  // Creates the tracker for `glove` and starts the glove's reader thread and
  // the camera thread. keep_alive is destroyed after both threads have
  // stopped: whatever the glove's transport or the opener's cameras use.
  static Result<std::unique_ptr<VistLiveSource>> start(
      const ImuGloveDescription& glove, std::unique_ptr<devices::ImuGloveDevice> glove_device,
      StereoCameraOpener open_camera, VistLiveSourceOptions options = {}, HeadPoseProvider head = nullptr,
      std::shared_ptr<void> keep_alive = {}, const Clock& clock = MonotonicClock::instance());
  ~VistLiveSource() override;  // stops the threads, then lets keep_alive go
  VistLiveSource(const VistLiveSource&) = delete;
  VistLiveSource& operator=(const VistLiveSource&) = delete;

  std::string_view name() const noexcept override { return "vist"; }
  bool available(Handedness hand) const noexcept override { return tracker_->available(hand); }
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override;
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override;

  Handedness hand() const noexcept { return options_.source.tracker.hand; }
  VistLiveStats live_stats() const { return input_->stats(); }
  VistSourceStats tracker_stats() const { return tracker_->stats(); }
  VistHandSource& tracker() noexcept { return *tracker_; }
  VistLiveInput& input() noexcept { return *input_; }
  const VistLiveSourceOptions& options() const noexcept { return options_; }

 private:
  VistLiveSource(VistLiveSourceOptions options, std::unique_ptr<VistHandSource> tracker,
                 std::shared_ptr<void> keep_alive);
  bool vision_lost(TimeNs t_ns) const noexcept;

  VistLiveSourceOptions options_;
  std::unique_ptr<VistHandSource> tracker_;  // declared first: destroyed last
  std::shared_ptr<void> keep_alive_;
  std::unique_ptr<VistLiveInput> input_;  // declared last: stopped first
};

// The IMU board's USB IDs, any serial (what `proprio track vist --live` and
// the layer use unless told otherwise).
hid::HidDeviceSelector imu_glove_selector();

// The real devices.
struct VistDeviceOptions {
  // A side-by-side stereo camera (/dev/videoN, or its number), the left one of
  // two cameras (with camera_right), or a video file (a regular file; played
  // in real time from when the camera thread opens it).
  std::string camera = "/dev/video0";
  std::string camera_right;
  // `proprio calibrate stereo --out` file: frames are rectified with it.
  std::string stereo_calibration;
  hid::HidDeviceSelector imu = imu_glove_selector();

  bool camera_is_file() const;
  Status validate() const;
  std::string describe() const;
};

// The glove over hidapi and the camera the options name, opened on the camera
// thread. Fails only on configuration errors: a camera that is neither a
// device path nor an existing file, a calibration file that cannot be read or
// whose rectified camera is not the glove description's rig.
Result<std::unique_ptr<VistLiveSource>> start_vist_devices(const ImuGloveDescription& glove,
                                                           const VistDeviceOptions& devices,
                                                           VistLiveSourceOptions options = {},
                                                           HeadPoseProvider head = nullptr);

// The head (TrackedPose::head) from what the host tracks; null for null (the
// head then stays at VistLiveOptions::T_world_head_fixed). `poses` must
// outlive the provider.
HeadPoseProvider head_pose_provider(TrackedPoseProvider* poses);

}  // namespace proprio::vist
