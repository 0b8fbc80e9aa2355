#pragma once
// The VIST evaluation protocol (Lee 2021, §4.6, made repeatable): simulated
// subjects with varied hand sizes wear the glove, follow a motion protocol in
// front of a head-mounted stereo camera, and the tracker's output is compared
// with the simulator's ground truth at every IMU tick.
//
// The simulators (input/sim) know the truth; the tracker only ever sees what
// a device would deliver: IMU readings with jittered timestamps, and stereo
// blobs (detections, or blobs found by the OpenCV detector in rendered images)
// that arrive camera_latency_s after their capture. The keypoints are the
// thesis's: dorsum (the palm joint), thumb, index and middle fingertips.
#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/result.hpp"
#include "proprio/sim/glove_as_built.hpp"
#include "proprio/sim/hand_motion.hpp"
#include "proprio/sim/soft_tissue.hpp"
#include "proprio/vist/vist_session.hpp"
#include "proprio/vist/vist_tracker.hpp"

namespace proprio::vist_eval {

enum class Challenge : std::uint8_t {
  none,
  occlude_half,     // half the markers hidden for 2 s, every 10 s
  out_of_view,      // the hand out of the cameras' view for 3 s, every 12 s
  distractors,      // static blobs of marker colours in the background
  dropped_frames,   // 10 % of stereo frames lost
  imu_unplug,       // the IMU board unplugged for 1 s every 15 s (from 10 s), then back
};
enum class Ablation : std::uint8_t {
  full,
  imu_only,         // vision only for acquisition, then IMU + constraints
  vision_only,      // no IMU: constant-velocity motion model
  no_imu_priors,    // correspondence search without the IMU-predicted marker priors
};
enum class FrameMode : std::uint8_t { detections, images };
std::string_view to_string(Challenge c) noexcept;
std::string_view to_string(Ablation a) noexcept;
std::string_view to_string(FrameMode m) noexcept;
std::optional<FrameMode> parse_frame_mode(std::string_view s) noexcept;

// The simulator's departures from an idealised glove and camera, each of
// which a session can switch off (the benchmark's realism ablation).
enum class RealismEffect : std::uint8_t {
  glove_build,     // markers and IMUs off their drawn places (sim/glove_as_built.hpp)
  sliding,         // skin sliding with the joints (sim/soft_tissue.hpp)
  wobble,          // the skin patch ringing on its bone
  slip,            // the glove creeping over the session
  camera,          // the image simulator's camera realism (images mode only)
  natural_motion,  // continuous natural movement instead of the thesis's free-motion protocol
  tremor,          // physiological tremor on the natural movement
  flicks,          // quick flicks of the wrist and fingers in the natural movement
};
inline constexpr std::array<RealismEffect, 8> kRealismEffects{
    RealismEffect::glove_build, RealismEffect::sliding,        RealismEffect::wobble, RealismEffect::slip,
    RealismEffect::camera,      RealismEffect::natural_motion, RealismEffect::tremor, RealismEffect::flicks};
std::string_view to_string(RealismEffect e) noexcept;
std::optional<RealismEffect> parse_realism_effect(std::string_view s) noexcept;

struct SessionSpec {
  int subject = 0;             // proprio::sim::sim_subject id
  double duration_s = 60.0;
  std::uint64_t seed = 1;
  Challenge challenge = Challenge::none;
  Ablation ablation = Ablation::full;
  FrameMode mode = FrameMode::detections;
  // Natural movement by default; switch_off(natural_motion) gives the thesis's free-motion protocol.
  sim::MotionProtocol protocol = sim::MotionProtocol::natural;
  Handedness hand = Handedness::right;
  double camera_latency_s = 0.05;   // capture to arrival of a stereo frame
  double warmup_s = 5.0;            // not scored: acquisition and first calibration
  double pixel_noise_px = 0.3;
  int distractor_count = 20;
  // The glove the simulators wear: built and donned with errors against the
  // description the tracker reads (sim/glove_as_built.hpp). One glove per seed;
  // each session (subject) is a donning. as_drawn() for the idealised glove.
  sim::GloveBuildErrors glove_build;
  // The skin and fabric under the glove's markers and IMUs (sim/soft_tissue.hpp):
  // sliding with the joints, wobble, slip. rigid() for mounts fixed to the bones.
  sim::SoftTissueOptions soft_tissue;
  // Images mode: false renders with the camera's idealised look (no motion
  // blur, distortion residual, uneven or coloured light, highlights).
  bool camera_realism = true;
  // Natural motion only (sim::HandMotionOptions).
  bool tremor = true;
  bool flicks = true;

  // Turns one realism effect off (natural_motion: the thesis's free-motion protocol).
  void switch_off(RealismEffect e);
  // Every realism effect off: the idealised simulator of the first wave.
  void idealise() {
    for (RealismEffect e : kRealismEffects) switch_off(e);
  }
  // Calibration accuracy is read at this time (the issue: "after 30 s").
  double calibration_check_s = 30.0;
  // When set, the session is also recorded there (vist_session.hpp): the
  // sensor data as the tracker received it, ground truth and the live output,
  // for `proprio track vist --session`.
  std::filesystem::path record_path;
  bool overwrite_record = false;
};

struct ErrorSummary {
  std::size_t samples = 0;
  double mean_mm = 0.0;
  double median_mm = 0.0;
  double p95_mm = 0.0;
  double pck20 = 0.0;   // fraction of keypoint errors <= 20 mm
  double pck35 = 0.0;
  double auc50 = 0.0;   // area under PCK(t) for t in [0, 50] mm, normalised to [0, 1]
};

struct SessionResult {
  SessionSpec spec;
  double hand_length_m = 0.0, hand_width_m = 0.0;
  bool acquired = false;
  double acquisition_time_s = -1.0;
  ErrorSummary keypoints;   // dorsum + 3 fingertips pooled
  ErrorSummary all_joints;  // all 26 joints pooled
  std::array<double, 4> keypoint_mean_mm{};  // dorsum, thumb tip, index tip, middle tip
  // Calibration at calibration_check_s: worst relative scale error over the
  // segment axes the markers span, and worst IMU mounting error.
  double scale_error_max = -1.0;
  double scale_error_mean = -1.0;
  double mounting_error_max_deg = -1.0;
  double mounting_error_mean_deg = -1.0;
  // Consistency: NEES of the segment poses (6 DOF) at fused frames.
  double nees_mean = 0.0;
  double nees_in_95 = 0.0;  // fraction of NEES samples within the two-sided 95 % chi²(6) interval
  std::size_t nees_samples = 0;
  // Out-of-view: seconds from the hand's return until the keypoint error is
  // back under 10 mm, per event (-1: never within the event's window).
  std::vector<double> recovery_s;
  double sim_seconds = 0.0;
  double wall_seconds = 0.0;      // whole loop: simulators + tracker
  double tracker_seconds = 0.0;   // tracker only
  vist::VistStats stats;
  // Raw per-sample errors (mm) behind the summaries, for pooling.
  std::vector<float> keypoint_errors_mm, joint_errors_mm;
};

// Runs one session. `glove` is usually ImuGloveDescription::vist_default().
Result<SessionResult> run_session(const ImuGloveDescription& glove, const SessionSpec& spec,
                                  const vist::VistTrackerOptions& base_options = {});

// Pools sessions of one kind: sample-weighted errors, worst calibration.
struct Aggregate {
  std::string name;
  std::size_t sessions = 0;
  ErrorSummary keypoints, all_joints;
  std::array<double, 4> keypoint_mean_mm{};
  double scale_error_max = -1.0, mounting_error_max_deg = -1.0;
  double nees_mean = 0.0, nees_in_95 = 0.0;
  std::vector<double> recovery_s;
  double realtime_factor = 0.0;  // simulated seconds per wall second (whole loop, one thread)
  double tracker_realtime_factor = 0.0;
  std::size_t acquisitions_failed = 0;
};
Aggregate aggregate(std::string name, const std::vector<SessionResult>& sessions);

// Replays a recorded VIST session (vist_session.hpp) through a fresh tracker
// in file (arrival) order, as `proprio track vist --session` does. Scores the
// output against the file's ground truth when it has one, and writes the
// output (with the ground truth) to output_path when set.
struct TrackSessionOptions {
  vist::VistTrackerOptions tracker;  // hand and nominal hand size come from the session
  double warmup_s = 5.0;             // from the first IMU sample; not scored
  std::filesystem::path output_path;
  bool overwrite_output = false;
};
struct TrackSessionResult {
  vist::VistSessionInfo info;
  std::uint64_t imu_samples = 0, stereo_frames = 0, poses = 0, ground_truth_poses = 0;
  std::uint64_t skipped_records = 0;
  RecordingSummary recording;
  bool scored = false;  // the session has ground truth covering the output
  ErrorSummary keypoints, all_joints;
  std::array<double, 4> keypoint_mean_mm{};
  double session_seconds = 0.0;  // first to last IMU sample
  double tracker_seconds = 0.0;  // wall time inside the tracker
  vist::VistStats stats;
};
Result<TrackSessionResult> track_session(const std::filesystem::path& session, const TrackSessionOptions& options = {});

// Mean, median, p95, PCK and AUC of a set of errors (reorders them).
ErrorSummary summarize(std::vector<float>& errors_mm);

}  // namespace proprio::vist_eval
