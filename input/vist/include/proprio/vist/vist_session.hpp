#pragma once
// A VIST session as a recording (docs/recording-format.md): everything the
// tracker consumed, in the order it arrived, so `proprio track vist --session`
// replays it through the tracker exactly as it ran live.
//
// Streams (names follow the format's conventions):
//   imu/<n>              imu          IMU n of the glove (n = sensor_id = index in the glove description)
//   imu/<n>/clipped/accel, .../gyro, .../both
//                        imu          its samples the device flagged as clipped (declared on the first one)
//   cam/vist/markers     markers      one record per camera image (camera_id 0 = left, 1 = right), at capture time
//   cam/vist/leftcam     rigid_pose   T_world_leftcam at the same capture time, written before the two images
//   hand/<side>/ground_truth  hand_pose   simulator or mocap truth (optional)
//   hand/<side>/vist     hand_pose    the tracker's live output (optional)
// The markers stream's meta is JSON: {"glove_toml": <the glove description,
// docs/vist-glove.md>, "hand": "right", "nominal_hand_length_m", "nominal_hand_width_m"}.
// Record times are measurement times; file order is arrival order (a stereo
// frame arrives tens of ms after its capture, after later IMU samples).
#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <variant>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/hand_pose.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/core/result.hpp"
#include "proprio/vist/vist_tracker.hpp"

namespace proprio::vist {

inline constexpr const char* kVistMarkersStream = "cam/vist/markers";
inline constexpr const char* kVistLeftCamStream = "cam/vist/leftcam";

struct VistSessionInfo {
  ImuGloveDescription glove;
  Handedness hand = Handedness::right;
  double nominal_hand_length_m = 0.19;
  double nominal_hand_width_m = 0.10;
};

class VistSessionWriter {
 public:
  static Result<VistSessionWriter> create(const std::filesystem::path& path, const VistSessionInfo& info,
                                          bool overwrite = false);
  Status write_imu(const TimedImuSample& s);
  // Flushes: a crash loses at most the frame being written.
  Status write_stereo_frame(TimeNs capture_time_ns, const MarkerObservations& left, const MarkerObservations& right,
                            const Pose& T_world_leftcam);
  Status write_ground_truth(const HandPose& pose);
  Status write_output(const HandPose& pose);
  Status close();

 private:
  explicit VistSessionWriter(RecordingWriter w) : writer_(std::move(w)) {}
  // clip: accel_clipped + 2 * gyro_clipped.
  Result<StreamId> imu_stream(std::uint16_t sensor_id, std::size_t clip);
  RecordingWriter writer_;
  std::array<std::vector<std::optional<StreamId>>, 4> imu_streams_;  // per clip kind, per sensor
  StreamId markers_ = 0, leftcam_ = 0, truth_ = 0, output_ = 0;
};

// One stereo frame as recorded.
struct VistStereoFrame {
  TimeNs capture_time_ns = 0;
  MarkerObservations left, right;
  Pose T_world_leftcam;
};
struct VistGroundTruth {
  HandPose pose;
};
using VistSessionItem = std::variant<TimedImuSample, VistStereoFrame, VistGroundTruth>;

class VistSessionReader {
 public:
  // Reads the header and streams up to the first data record; errors say what
  // is missing (not a VIST session, no glove description, bad meta).
  static Result<VistSessionReader> open(const std::filesystem::path& path);

  const VistSessionInfo& info() const noexcept { return info_; }
  // The next item in arrival order, or nullopt at the end. Damaged records are
  // skipped and counted; the tracker's own outputs in the file are ignored.
  Result<std::optional<VistSessionItem>> next();
  std::uint64_t skipped_records() const noexcept { return skipped_; }
  const RecordingSummary& summary() const noexcept { return reader_.summary(); }

 private:
  explicit VistSessionReader(RecordingReader r) : reader_(std::move(r)) {}
  RecordingReader reader_;
  VistSessionInfo info_;
  std::optional<Record> lookahead_;
  std::uint64_t skipped_ = 0;
};

}  // namespace proprio::vist
