#pragma once
// An emulated VIST rig: a simulated wearer behind the same code paths a real
// glove and camera take, in real time, for tests, benchmarks and the demo
// (the OpenXR layer's `vist` source with input "emulated").
//
//   simulated wearer (proprio::sim: subject, seed; HandMotionGenerator)
//     -> ImuSimulator -> ImuGloveEmulator, served over a hid::FakeHidLink
//        (ImuGloveEmulatorServer) -> a real ImuGloveDevice (decoding, clock sync)
//     -> StereoImageSimulator, rendered at each grab of a vist::VideoSource
//        -> a real StereoCamera -> MarkerDetector (VistLiveInput)
//     -> ground truth: truth_at(), and rows in a HandTruthWriter CSV
//
// Time: the wearer's time zero is start(); everything is CLOCK_MONOTONIC.
// The camera captures on a grid of the rig's rate from time zero; a frame is
// stamped with its capture time and delivered when it has been rendered, so
// rendering time is real camera latency. A frame that could not be rendered
// before its successor was due is skipped (a dropped frame).
//
// The head and the world. The camera sits on the head at the head pose the
// HeadPoseProvider gives for the capture time (the OpenXR layer: the headset,
// in the source's LOCAL or STAGE space), or at the fallback head when it
// gives none. The wearer stands still: the simulated hand moves in front of
// its resting head, and that resting head is placed (once, at the first head
// pose the provider gives) where the headset then is, turned to its heading,
// upright. Before that the resting head is the fallback head. So the hand is
// in view when the wearer looks at it, and stays where it is when the headset
// walks away. The re-placement is a rigid move about the vertical, which the
// IMUs (gravity along -Y) cannot feel; the tracker sees the hand jump once and
// re-acquires it. Truth is in the same world frame.
//
// Faults for tests: the IMU board's cable (link().unplug_for) and the camera
// (unplug_camera_for: grabs fail and the camera cannot be opened).
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "proprio/core/hand_pose.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/imu_glove_board/imu_glove_device.hpp"
#include "proprio/imu_glove_board/imu_glove_emulator.hpp"
#include "proprio/sim/hand_motion.hpp"
#include "proprio/vist/vist_live.hpp"
#include "proprio/vist/vist_live_source.hpp"

namespace proprio::vist_eval {

struct EmulatedVistOptions {
  int subject = 3;  // proprio::sim::sim_subject id
  std::uint64_t seed = 1;
  Handedness hand = Handedness::right;
  sim::MotionProtocol protocol = sim::MotionProtocol::free_motion;
  // The rendered images (and the rig the tracker is given) at this fraction
  // of the glove description's camera resolution. Rendering is the
  // emulation's own cost, not the system's: on the 2-vCPU VM a stereo pair
  // took 46-52 ms at the thesis rig's 1280x720 (so about a third of the 30 Hz
  // frames were skipped) and 13 ms at 0.5 (640x360), with the same keypoint
  // accuracy (2.3-2.4 mm and 2.45 mm; tests/unit/input/vist_eval). 1: the
  // rig's own resolution, detector cost included.
  double camera_scale = 0.5;
  double imu_clock_error_ppm = 20.0;    // the board's crystal, which the clock sync must absorb
  devices::ImuGloveServeOptions serve;  // USB latency of the emulated board
  // The camera's reopen policy (StereoCamera): lost frames are retried this
  // often before the camera is given up and opened anew.
  int camera_reopen_attempts = 3;
  double camera_reopen_interval_s = 1.0;
  // Where the wearer's true hand is written (HandTruthWriter CSV); empty: not.
  std::string truth_path;

  Status validate() const;
  std::string describe() const;
};

struct EmulatedVistStats {
  std::uint64_t frames_rendered = 0;
  std::uint64_t frames_skipped = 0;       // due while the previous one was still being rendered
  std::uint64_t frames_without_head = 0;  // rendered from the fallback head
  double render_ms_mean = 0.0;            // rendering one stereo pair, wall clock
  double render_ms_max = 0.0;
  std::uint64_t imu_ticks = 0;  // board ticks served (emulator statistics)
  std::uint64_t imu_reports_sent = 0;
  std::uint64_t truth_rows = 0;
  bool anchored = false;    // the wearer was placed at the provider's head
  std::string truth_error;  // the truth file's write error, if any
  std::string describe() const;
};

// The glove description with its camera at `scale` of its resolution
// (intrinsics scaled, the principal point kept at the same place).
ImuGloveDescription scale_camera(const ImuGloveDescription& glove, double scale);

class EmulatedVistRig {
 public:
  // `glove` is what the tracker is given too (scale_camera applied already).
  // fallback_T_world_head: where the head is when `head` is null or says no.
  static Result<std::shared_ptr<EmulatedVistRig>> create(const ImuGloveDescription& glove,
                                                         const EmulatedVistOptions& options,
                                                         vist::HeadPoseProvider head,
                                                         const Pose& fallback_T_world_head);
  ~EmulatedVistRig();  // stops the board
  EmulatedVistRig(const EmulatedVistRig&) = delete;
  EmulatedVistRig& operator=(const EmulatedVistRig&) = delete;

  // Time zero of the wearer is now; the board powers up and streams.
  void start();
  TimeNs time_zero_ns() const;

  // A real driver on the board's cable (not started).
  std::unique_ptr<devices::ImuGloveDevice> make_glove_device(devices::ImuGloveDeviceOptions options = {});
  // Opens a StereoCamera on the rendering video source (for VistLiveInput).
  vist::StereoCameraOpener camera_opener();

  hid::FakeHidLink& link() noexcept { return *link_; }
  // The camera stops delivering and cannot be opened for this long.
  void unplug_camera_for(DurationNs duration_ns);

  // The wearer's true hand at t_ns (CLOCK_MONOTONIC) in the source's world
  // frame, with velocities. Thread-safe.
  HandPose truth_at(TimeNs t_ns);
  // The wearer's frame (the simulator's world) in the source's world.
  Pose T_world_wearer() const;
  EmulatedVistStats stats() const;
  const ImuGloveDescription& glove() const noexcept;
  const EmulatedVistOptions& options() const noexcept;

  struct Impl;

 private:
  explicit EmulatedVistRig(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
  std::shared_ptr<hid::FakeHidLink> link_;
};

struct EmulatedVist {
  std::unique_ptr<vist::VistLiveSource> source;  // owns the rig too
  std::shared_ptr<EmulatedVistRig> rig;          // for faults, truth and statistics
};

// The emulated rig behind a VistLiveSource: the tracker gets the scaled glove
// description, the hand the options name and the head provider (also the
// camera's). source_options.live.T_world_head_fixed is the fallback head.
Result<EmulatedVist> start_emulated_vist(const ImuGloveDescription& glove, const EmulatedVistOptions& options,
                                         vist::VistLiveSourceOptions source_options = {},
                                         vist::HeadPoseProvider head = nullptr,
                                         devices::ImuGloveDeviceOptions glove_options = {});

}  // namespace proprio::vist_eval
