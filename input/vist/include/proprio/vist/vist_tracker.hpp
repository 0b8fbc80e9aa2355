#pragma once
// The VIST pipeline (Lee 2021, ch. 4) from sensor data to a 26-joint hand:
//
//   IMU samples (100 Hz, each with its measurement time) ──► filter prediction
//   stereo blobs (30 Hz, capture time, arrive late) ──► stereo matching (§4.3.3)
//        ──► IMU-aided correspondence search (§4.4) ──► marker + constraint correction (§4.5)
//   filter state ──► all 26 OpenXR joints at the IMU rate, predicted to the newest IMU sample
//
// Delayed frames. Camera frames arrive tens of milliseconds after their
// capture. The filter core runs behind real time: IMU samples wait in a queue
// and the core integrates them only up to the capture time of the next frame
// (or, without frames, up to max_frame_latency behind the newest sample).
// Each output pose propagates a copy of the core's nominal state through the
// queued samples to the newest IMU time. For the core this is exactly the
// "state history and re-propagation" of Weiss (2012) without keeping a
// history; a frame captured before the core's time is late and dropped.
//
// Acquisition. The first frame with enough triangulated markers initialises
// the hand without any prior: each IMU's gravity gives its segment's tilt, the
// hand's heading is searched on a grid, and the candidate whose predicted
// markers the correspondence search explains best wins. A hand lost for
// lost_after_s is re-acquired the same way, keeping its calibration.
//
// Not thread-safe: one thread feeds it (VistHandSource wraps it in one).
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/core/hand_pose.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/core/result.hpp"
#include "proprio/vist/correspondence.hpp"
#include "proprio/vist/segment_filter.hpp"
#include "proprio/vist/stereo_matching.hpp"

namespace proprio::vist {

struct TimedImuSample {
  TimeNs time_ns = 0;  // when it was measured (CLOCK_MONOTONIC, or the session's clock)
  ImuSample sample;    // sensor_id = index of the IMU in the glove description
  // The device flagged a clipped axis. A clipped gyro loses the attitude: the
  // sample is rejected. A clipped accelerometer is integrated with its
  // uncertainty raised (FilterOptions::clipped_accel_sigma_mps2).
  bool accel_clipped = false;
  bool gyro_clipped = false;
};

struct VistTrackerOptions {
  Handedness hand = Handedness::right;
  // The nominal hand the glove geometry is scaled from; the filter calibrates
  // per-segment scales from there. Defaults: the middle of the adult range.
  double nominal_hand_length_m = 0.19;
  double nominal_hand_width_m = 0.10;
  FilterOptions filter;
  StereoMatchOptions stereo;
  CorrespondenceOptions correspondence;
  // A frame captured this long before the newest IMU sample can no longer be
  // fused (the core has moved past it). Also how long IMU samples wait.
  double max_frame_latency_s = 0.2;
  // Ablations (Lee 2021, Fig. 4.8): false = vision only (a constant-velocity
  // motion model replaces the IMUs); false = IMU only after acquisition.
  bool use_imu = true;
  bool use_vision = true;
  bool use_constraints = true;
  // Acquisition needs this many triangulated markers, and a candidate this
  // many corresponded ones.
  std::size_t min_acquisition_points = 8;
  std::size_t min_acquisition_matches = 6;
  int acquisition_heading_steps = 24;
  // No marker fused for this long: the hand is lost and will be re-acquired.
  double lost_after_s = 0.5;
  // Re-acquire when more than this fraction of the corresponded markers keeps
  // failing the filter's gate (moving average over frames): a wrong lock.
  double max_gated_fraction = 0.3;
  // Vision-only motion model: white-noise acceleration and angular rate (densities).
  double vision_only_accel_density = 3.0;  // m/s²/√Hz
  double vision_only_gyro_density = 1.5;   // rad/s/√Hz
  // Samples with any axis beyond these are rejected as corrupt (the device's full scale + margin).
  double max_abs_accel_mps2 = 16.0 * 9.80665 * 1.05;
  double max_abs_gyro_radps = 2000.0 * 0.017453292519943295 * 1.05;
  bool reject_saturated = true;  // reject samples whose gyro the device flagged as clipped
  // An IMU sample this much later than the previous one of its IMU waits for
  // the next: if that one is earlier, the jump was a bad stamp (a wall-clock
  // time, a flipped bit) and only that sample is dropped (TimestampGuard).
  double max_imu_time_jump_s = 10.0;

  Status validate() const;
  std::string describe() const;
};

struct VistStats {
  std::uint64_t imu_samples = 0;
  std::uint64_t imu_rejected_non_finite = 0;
  std::uint64_t imu_rejected_saturated = 0;   // gyro clipped or beyond its range
  std::uint64_t imu_accel_clipped = 0;        // used, with the clipped acceleration's uncertainty
  std::uint64_t imu_rejected_out_of_order = 0;  // older than or equal to the previous sample of that IMU
  std::uint64_t imu_rejected_unknown_sensor = 0;
  std::uint64_t imu_rejected_time_jump = 0;  // an isolated jump forward in time, not confirmed by the next sample
  std::uint64_t frames = 0;
  std::uint64_t frames_fused = 0;
  std::uint64_t frames_late = 0;       // captured before the core's time
  std::uint64_t frames_duplicate = 0;  // same capture time as a frame already queued or fused
  std::uint64_t frames_before_init = 0;
  std::uint64_t acquisitions = 0;
  std::uint64_t reacquisitions = 0;
  std::uint64_t markers_fused = 0;
  std::uint64_t markers_gated = 0;
  std::uint64_t stereo_points = 0;
  std::uint64_t correspondences = 0;
  std::string describe() const;
};

// Per-frame diagnostics of the last fused frame.
struct FrameReport {
  TimeNs capture_time_ns = 0;
  std::size_t stereo_points = 0;
  std::size_t correspondences = 0;
  CorrectionStats correction;
  bool acquired = false;
};

class VistTracker {
 public:
  static Result<VistTracker> create(const ImuGloveDescription& glove, VistTrackerOptions options = {});

  // Feed data in arrival order. IMU samples of different IMUs may interleave
  // in any order; each IMU's own samples must come in time order (others are
  // counted and dropped). Returns true when a new output pose is ready.
  bool add_imu(const TimedImuSample& s);
  // One rectified stereo frame: blobs of both cameras, the time both images
  // were captured and where the left camera was then (the headset's tracking).
  void add_stereo_frame(TimeNs capture_time_ns, const MarkerObservations& left, const MarkerObservations& right,
                        const Pose& T_world_leftcam);

  bool initialized() const noexcept { return filter_.initialized(); }
  // The newest output: all 26 joints at the newest IMU time (inactive before acquisition).
  const HandPose& pose() const noexcept { return output_; }
  TimeNs newest_imu_time_ns() const noexcept { return newest_imu_ns_; }
  // Capture time of the newest frame whose markers corrected the filter (at
  // least 3 fused, or an acquisition); 0 before any. Frames that arrive but
  // whose markers all miss the prediction do not count: the IMUs alone carry
  // the hand then, and drift.
  TimeNs last_vision_fix_ns() const noexcept { return last_seen_ns_; }

  const VistStats& stats() const noexcept { return stats_; }
  const FrameReport& last_frame() const noexcept { return last_frame_; }
  const VistFilter& filter() const noexcept { return filter_; }
  VistFilter& filter() noexcept { return filter_; }
  const VistModel& model() const noexcept { return filter_.model(); }
  const VistTrackerOptions& options() const noexcept { return options_; }
  const StereoRig& rig() const noexcept { return rig_; }

  // The hand a filter state describes: all 26 joints, instrumented segments
  // exactly where the filter has them, the rest from the hand model with
  // synergies (DIP = 2/3 PIP, thumb IP = 1/2 MCP) and the ring and little
  // fingers following the middle finger. Angular rates (IMU frame, bias
  // corrected) per segment give velocities; empty: no velocities.
  void reconstruct(std::span<const SegmentState> states, std::span<const Vec3> rates_in_imu, TimeNs t_ns,
                   HandPose& out);

 private:
  VistTracker(const ImuGloveDescription& glove, VistTrackerOptions options, VistFilter filter, StereoMatcher matcher,
              CorrespondenceSearch search, CorrespondenceSearch acquisition_search);
  struct PendingFrame {
    TimeNs capture_ns = 0;
    MarkerObservations left, right;
    Pose T_world_leftcam;
    bool used = false;
  };
  void advance();
  void integrate_queued_until(TimeNs t_ns);
  void process_frame(PendingFrame& f);
  bool acquire(const PendingFrame& f, bool keep_calibration);
  std::size_t correspond(const Pose& T_world_leftcam, std::span<const SegmentState> states,
                         CorrespondenceSearch& search, CorrespondenceResult& result);
  void fuse_correspondences(VistFilter& filter, const Pose& T_world_leftcam, const CorrespondenceResult& result,
                            CorrectionStats& st);
  // Correspondence search against `filter`'s prediction, then its correction. Returns the correspondences.
  std::size_t fuse_frame(VistFilter& filter, const Pose& T_world_leftcam, CorrectionStats& st);
  void update_placed_markers(std::span<const SegmentState> states);
  void update_output();
  void ensure_shape(const SegmentState& dorsum);
  Vec3 mean_accel(std::size_t segment, TimeNs around_ns) const;

  ImuGloveDescription glove_;
  VistTrackerOptions options_;
  StereoRig rig_;
  VistFilter filter_;
  StereoMatcher matcher_;
  CorrespondenceSearch search_;
  CorrespondenceSearch acquisition_search_;
  HandModel hand_model_;
  double model_length_scale_ = 1.0, model_width_scale_ = 1.0;
  int dorsum_ = -1;
  std::vector<int> segment_of_sensor_;  // sensor_id -> segment index (-1: not a filter IMU)

  // IMU queue (arrival order), samples not yet integrated by the core.
  std::vector<TimedImuSample> queue_;
  std::vector<TimeNs> last_sample_ns_;  // per segment, newest accepted
  std::vector<TimestampGuard> imu_time_guards_;  // per segment
  std::vector<TimedImuSample> imu_held_;         // per segment: a sample after a time jump, until the next decides
  bool accept_imu(std::size_t segment, const TimedImuSample& s);
  std::vector<Vec3> last_gyro_, last_accel_;  // per segment, newest accepted (for acquisition and holding)
  TimeNs newest_imu_ns_ = 0;
  bool have_imu_ = false;
  std::vector<PendingFrame> frames_;  // capture-time order
  TimeNs core_time_ns_ = 0;
  TimeNs last_fused_ns_ = 0;
  TimeNs last_seen_ns_ = 0;
  TimeNs acquired_ns_ = 0;
  double gated_fraction_ = 0.0;  // moving average over frames
  struct Candidate {
    std::vector<SegmentState> states;
    std::size_t matches = 0;
    double score = 0.0;
  };
  std::vector<Candidate> candidates_;
  std::optional<VistFilter> acquisition_filter_;

  // Work buffers.
  std::vector<StereoPoint> points_;
  std::vector<Observation3D> observations_;
  std::vector<PlacedMarker> placed_;
  std::vector<Mat3> marker_cov_;
  std::vector<MarkerMeasurement> measurements_;
  CorrespondenceResult corr_, best_corr_;
  std::vector<SegmentState> work_states_;
  std::vector<Vec3> work_rates_;
  std::vector<TimeNs> work_times_;
  std::vector<Vec3> work_gyro_, work_accel_;
  HandPose work_pose_, work_pose_probe_;
  HandPose output_;
  FrameReport last_frame_;
  VistStats stats_;
};

}  // namespace proprio::vist
