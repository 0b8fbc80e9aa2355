#pragma once
// Detection-level stereo marker simulator: what a head-mounted, rectified
// stereo camera's colour-blob detector reports for a glove's markers, without
// rendering images. For each camera it gives the 2D blob centroids per hue,
// honouring the field of view, the marker's facing angle (Lee 2021, §4.4,
// camera-facing factor), self-occlusion by the hand's own geometry, pixel
// noise and dropped frames. Ground truth (which marker, where in 3D, the
// noise-free pixel) is kept apart so a tracker under test cannot peek.
//
// Conventions
// - Cameras: rectified pinhole, OpenCV axes (x right, y down, z forward).
//   T_world_leftcam = T_world_head * rig.T_head_leftcam; the right camera is
//   at +baseline along the left camera's x axis, same orientation, so
//   disparity u_left - u_right = fx * baseline / z and v_left == v_right.
// - Pixels: (0, 0) is the centre of the top-left pixel (as in recording.hpp);
//   u = fx x/z + cx, v = fy y/z + cy.
// - Hue: Marker::hue is OpenCV's HSV_FULL scale (256 steps over 360°), as the
//   recording format defines it: red 0, yellow 43, green 85, blue 171. Convert
//   with marker_hue_code() / marker_hue_from_code().
// - Area: a disc of diameter d whose normal makes angle alpha with the ray to
//   the camera covers, to first order, pi (d/2)^2 fx fy cos(alpha) r / z^3
//   square pixels (r = range, z = depth): on the optical axis this is the
//   familiar pi (d/2)^2 f^2 cos(alpha) / z^2; off axis, perspective stretches
//   it by r/z = 1/cos(off-axis angle).
// - Randomness: each frame's noise, drops and soft-facing draws come from
//   Rng(mix_seed(options.seed, t_ns)), consumed in a fixed order, so a frame
//   depends only on (seed, t, pose, head) and not on which frames were
//   simulated before, nor on which other markers were visible. Two gloves
//   (two hands) in one session need different seeds, or their noise is the
//   same.
#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/hand_pose.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/core/result.hpp"
#include "proprio/sim/hand_motion.hpp"

namespace proprio::sim {

// MarkerHue -> Marker::hue (OpenCV HSV_FULL, 0-255 over 360°), rounded the
// way cv::cvtColor(COLOR_BGR2HSV_FULL) rounds.
std::uint8_t marker_hue_code(MarkerHue hue) noexcept;
// The glove hue nearest to a detected HSV_FULL hue (circular distance).
MarkerHue marker_hue_from_code(std::uint8_t code) noexcept;

enum class FacingModel : std::uint8_t {
  // Seen iff the facing angle is below facing_max_deg.
  cutoff,
  // Lee 2021 eq. (4.10): seen with probability 1 below alpha_min, falling
  // linearly to 0 at alpha_max (seeded draw per marker and camera).
  linear_ramp,
};
std::string_view to_string(FacingModel m) noexcept;

// Why a marker is or is not in a camera's observations (first failing test,
// in this order).
enum class MarkerVisibility : std::uint8_t {
  visible = 0,
  dropped,       // the whole stereo frame was dropped
  no_hand,       // the hand pose is inactive
  behind,        // depth below min_depth_m (behind or too close to the camera)
  outside_fov,   // the blob is not entirely inside the image
  facing_away,   // facing angle beyond the cutoff or the ramp's draw failed
  too_small,     // blob area below min_area_px2
  occluded,      // the line of sight passes through the hand
  noise_outside, // the noisy centroid left the image
};
std::string_view to_string(MarkerVisibility v) noexcept;

struct StereoSimOptions {
  double pixel_noise_px = 0.3;    // sigma of the centroid noise, per axis, pixels
  double area_noise_fraction = 0.0;  // sigma of the blob area, as a fraction of it
  double drop_probability = 0.0;  // chance a whole stereo frame is lost
  FacingModel facing = FacingModel::cutoff;
  // Facing angle: between the marker's outward normal and the direction from
  // the marker to the camera centre. 180 disables the cutoff test.
  double facing_max_deg = 80.0;
  double facing_alpha_min_deg = 45.0;  // linear_ramp: Lee 2021's pilot values
  double facing_alpha_max_deg = 90.0;
  bool occlusion = true;
  // Start of the occlusion ray off the marker's surface, along its normal, so
  // the marker's own point never hides it.
  double occlusion_offset_m = 0.002;
  // Forearm capsule from the wrist back along the wrist's +Z (0: none). The
  // hand model has no forearm; this assumes a neutral wrist, so it is off by
  // default.
  double forearm_length_m = 0.0;
  double min_area_px2 = 20.0;  // blob detectors reject smaller blobs as noise
  double min_depth_m = 0.05;   // nearer than this the blob is out of focus / not found
  bool shuffle = true;         // observations in random order (trackers must not rely on it)
  std::uint64_t seed = 1;

  Status validate() const;
  std::string describe() const;
};

// Ground truth of one observation, aligned index for index with the
// observations of the same camera.
struct MarkerTruth {
  std::size_t marker = 0;       // position in the simulator's markers() (== PlacedMarker::index for place_markers())
  std::size_t glove_index = 0;  // PlacedMarker::index
  Vec3 p_in_leftcam = Vec3::Zero();  // true 3D centre in the LEFT camera frame (for both cameras)
  double u_px = 0.0;  // noise-free centroid in this camera
  double v_px = 0.0;
  double area_px2 = 0.0;  // noise-free area
  double facing_deg = 0.0;  // angle between the marker's normal and the ray to this camera
};

struct StereoFrame {
  TimeNs time_ns = 0;
  bool dropped = false;  // true: both cameras' observations are empty
  std::array<MarkerObservations, 2> cameras;  // [0] left (camera_id 0), [1] right (camera_id 1)
};

struct StereoGroundTruth {
  TimeNs time_ns = 0;
  Pose T_world_leftcam;
  std::array<std::vector<MarkerTruth>, 2> cameras;  // aligned with StereoFrame::cameras[c].markers
  // Per camera, per marker (position in markers()): why it is or is not seen.
  std::array<std::vector<MarkerVisibility>, 2> visibility;

  std::size_t visible_count(std::size_t camera) const;
  // Markers seen by both cameras (what a stereo matcher could triangulate).
  std::size_t stereo_count() const;
};

// A capsule (segment with radius), the hand's occlusion primitive.
struct Capsule {
  Vec3 a = Vec3::Zero();
  Vec3 b = Vec3::Zero();
  double radius_m = 0.0;
};
// True when the segment p0-p1 comes closer than the radius to the capsule's
// axis, i.e. passes through (or touches) the capsule.
bool segment_hits_capsule(const Vec3& p0, const Vec3& p1, const Capsule& c) noexcept;
// Squared distance between segments p0-p1 and q0-q1 (Ericson, Real-Time
// Collision Detection, §5.1.9), robust to degenerate segments.
double segment_segment_distance_sq(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1) noexcept;

// The hand as capsules for the occlusion test, from a pose's joints and radii:
// one per bone between consecutive joints of each finger (radius: the smaller
// of its two joint radii), the four metacarpals make the palm (they overlap,
// so no line of sight slips between them; the palm's radial edge is the index
// metacarpal's surface), a capsule across the carpal row, and an optional
// forearm. `owner[i]` is the segment (joint) a capsule
// belongs to; the palm, carpal and forearm capsules belong to the WRIST.
struct HandCapsules {
  static constexpr std::size_t kMax = 24;
  std::array<Capsule, kMax> capsules{};
  std::array<HandJoint, kMax> owner{};
  std::size_t count = 0;
};
HandCapsules hand_capsules(const HandPose& hand_in_world, double forearm_length_m = 0.0);

class StereoMarkerSimulator {
 public:
  // Markers as ImuGloveDescription::place_markers(shape, markers_hand) gives
  // them, in their segment frames. A pose of the other hand sees them
  // mirrored (x -> -x in every segment frame, as HandModel and
  // place_markers mirror), so one simulator serves both hands. Options must
  // validate().
  StereoMarkerSimulator(StereoRig rig, std::vector<PlacedMarker> markers, StereoSimOptions options = {},
                        Handedness markers_hand = Handedness::right);
  // Validates the rig and options and places the glove's markers on this hand.
  static Result<StereoMarkerSimulator> create(const ImuGloveDescription& glove, const HandShape& shape,
                                              StereoSimOptions options = {});

  // The blobs both cameras see of a hand at time t, with the head (and so the
  // cameras) at T_world_head. Fills `truth` when given. Thread-safe (const,
  // no shared state).
  // skin_offsets_in_segment (empty, or one per marker): where soft tissue has
  // moved each marker from its place this frame (sim/soft_tissue.hpp), in its
  // segment frame as placed (mirrored with the place for the other hand).
  StereoFrame simulate(const HandPose& hand_in_world, const Pose& T_world_head, TimeNs t_ns,
                       StereoGroundTruth* truth = nullptr, std::span<const Vec3> skin_offsets_in_segment = {}) const;

  Pose T_world_leftcam(const Pose& T_world_head) const { return T_world_head * rig_.T_head_leftcam; }
  // Noise-free projection of a point in the left camera frame into camera 0/1.
  Eigen::Vector2d project(const Vec3& p_in_leftcam, std::size_t camera) const;

  const StereoRig& rig() const noexcept { return rig_; }
  const std::vector<PlacedMarker>& markers() const noexcept { return markers_; }
  const StereoSimOptions& options() const noexcept { return options_; }
  Handedness markers_hand() const noexcept { return markers_hand_; }

 private:
  StereoRig rig_;
  std::vector<PlacedMarker> markers_;
  StereoSimOptions options_;
  Handedness markers_hand_ = Handedness::right;
};

// Steps a hand-motion generator at the rig rate (frame k at k / rate_hz) for
// duration_s and simulates each frame.
using StereoFrameCallback =
    std::function<void(const HandMotionFrame& motion, const StereoFrame& frame, const StereoGroundTruth& truth)>;
void simulate_session(HandMotionGenerator& motion, const StereoMarkerSimulator& sim, double duration_s,
                      const StereoFrameCallback& on_frame);

// Recording: one `markers` stream per rig, named "cam/<rig_name>/markers" as
// docs/recording-format.md prescribes; each frame writes one record per
// camera (camera_id 0 left, 1 right). The meta carries the intrinsics,
// baseline, rate, hue encoding and the simulator options (with the seed).
Result<StreamId> add_stereo_stream(RecordingWriter& writer, const StereoMarkerSimulator& sim,
                                   std::string_view rig_name = "stereo");
// A dropped frame writes nothing (no image arrived); a frame with no markers
// seen writes empty observations.
Status write_stereo_frame(RecordingWriter& writer, StreamId stream, const StereoFrame& frame);

}  // namespace proprio::sim
