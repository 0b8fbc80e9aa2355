#pragma once
// An instrumented glove as data: which hand segments it tracks, where its IMUs
// sit, where its visual markers are (position, outward normal, hue), and the
// stereo camera that sees them. Both the simulators (ground truth) and the VIST
// tracker read the same description, so a user describes their own glove once,
// in a TOML file (config/vist_glove.toml is the thesis's glove; the format is
// documented in docs/vist-glove.md).
//
// Segment frames are XR joint frames (hand_joint.hpp): a segment named by a
// joint is the bone that starts at that joint (+Z back toward the wrist, +Y
// out of the back of the hand). The dorsum is the WRIST frame: the model's
// metacarpals are rigid with it.
//
// Handedness. A description is written for the right hand. The left glove is
// its mirror image (as HandModel mirrors the hand): a marker "toward the little
// finger" stays toward the little finger, which is +X of a right-hand segment
// frame and -X of a left-hand one. The one-argument place_* are the right hand.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/result.hpp"

namespace proprio {

enum class MarkerHue : std::uint8_t { red = 0, yellow = 1, green = 2, blue = 3 };
inline constexpr std::size_t kMarkerHueCount = 4;
std::string_view to_string(MarkerHue h) noexcept;
std::optional<MarkerHue> parse_marker_hue(std::string_view s) noexcept;
// Hue in OpenCV's 0-179 HSV scale (red 0, yellow 30, green 60, blue 120).
int opencv_hue(MarkerHue h) noexcept;

// Segments a glove item may sit on: the wrist (the dorsum) and every joint
// that starts a bone (metacarpal, proximal, intermediate, distal). Not the
// palm joint (it has no bone of its own) and not the tips.
bool is_glove_segment(HandJoint j) noexcept;
// "wrist" or "dorsum" -> wrist; otherwise an XR joint name that is_glove_segment.
std::optional<HandJoint> parse_glove_segment(std::string_view s) noexcept;

struct ImuMount {
  std::string name;                    // "dorsum", "index_proximal", ...
  HandJoint segment = HandJoint::wrist;
  // Nominal placement on the segment, as a fraction of the bone length from
  // the joint toward the next one, on the back of the finger (dorsal surface).
  double along_fraction = 0.5;
  Quat q_segment_imu = Quat::Identity();  // nominal IMU axes in the segment frame
  // Dorsum only: along_fraction is then a fraction of hand length from the
  // wrist, and this the fraction of hand width, + toward the little finger.
  double across_fraction = 0.0;
};

struct MarkerSpec {
  HandJoint segment = HandJoint::wrist;
  MarkerHue hue = MarkerHue::red;
  // Finger segments: fraction of the bone length from the joint, and the angle
  // around the bone from the dorsal direction (+Y) toward +X, degrees (+X is
  // toward the little finger in a right-hand segment frame).
  // Dorsum (WRIST segment): along_fraction is the fraction of hand length from
  // the wrist toward the knuckles, around_deg is replaced by across_fraction.
  double along_fraction = 0.5;
  double around_deg = 0.0;
  double across_fraction = 0.0;  // dorsum only: fraction of hand width, + toward the little finger
  double diameter_m = 0.012;
};

// A marker placed on a particular hand: where it is on its segment.
struct PlacedMarker {
  std::size_t index = 0;  // into ImuGloveDescription::markers
  HandJoint segment = HandJoint::wrist;
  MarkerHue hue = MarkerHue::red;
  Vec3 p_in_segment = Vec3::Zero();
  Vec3 normal_in_segment = Vec3::UnitY();  // outward, unit
  double diameter_m = 0.012;
};

struct PlacedImu {
  std::size_t index = 0;  // into ImuGloveDescription::imus
  HandJoint segment = HandJoint::wrist;
  Pose T_segment_imu;  // nominal, before any mounting error
};

// Rectified pinhole camera, OpenCV convention: x right, y down, z forward.
struct PinholeCamera {
  int width_px = 1280;
  int height_px = 720;
  double fx_px = 640.0;
  double fy_px = 623.5;
  double cx_px = 639.5;
  double cy_px = 359.5;

  // Focal lengths from the full field of view, principal point at the image
  // centre ((W-1)/2, (H-1)/2 in the pixel-centre convention). Radians.
  static PinholeCamera from_fov(int width_px, int height_px, double hfov_rad, double vfov_rad);
  double hfov_rad() const;
  double vfov_rad() const;
};

struct StereoRig {
  PinholeCamera camera;      // both cameras after rectification
  double baseline_m = 0.063;  // right camera at +x of the left one
  double rate_hz = 30.0;
  // The left camera in the head (OpenXR VIEW) frame. OpenXR looks along -Z
  // with +Y up; the camera looks along its +Z with +Y down.
  Pose T_head_leftcam;

  // ZED Mini-like: 1280x720, 90x60 deg, 63 mm baseline, 30 Hz, the left camera
  // 31.5 mm left of the head centre, 80 mm forward, tilted 25 deg down.
  static StereoRig zed_mini_like();
  // The rotation of a camera that looks straight ahead along the head's -Z,
  // image +y along the head's -Y, then pitched down by tilt_down_rad.
  static Quat head_camera_rotation(double tilt_down_rad);
  // Right camera: baseline_m along the left camera's +x.
  Pose T_head_rightcam() const;
};

struct ImuGloveDescription {
  std::string name;
  std::vector<ImuMount> imus;
  std::vector<MarkerSpec> markers;
  StereoRig rig;
  std::string origin;  // file it came from

  static Result<ImuGloveDescription> load(const std::filesystem::path& path);
  static Result<ImuGloveDescription> parse(std::string_view toml_text, const std::string& source_name);
  // The glove of Lee 2021 (ch. 4): 7 IMUs, 37 markers in 4 hues, a ZED Mini-like rig.
  static ImuGloveDescription vist_default();

  // Segments the glove instruments, in order of first appearance.
  std::vector<HandJoint> segments() const;
  // Right hand.
  std::vector<PlacedMarker> place_markers(const HandShape& shape) const;
  std::vector<PlacedImu> place_imus(const HandShape& shape) const;
  // Either hand; the left is the mirror image of the right (see the top of this file).
  std::vector<PlacedMarker> place_markers(const HandShape& shape, Handedness hand) const;
  std::vector<PlacedImu> place_imus(const HandShape& shape, Handedness hand) const;
  std::string describe() const;
  // The description in the file format parse() reads (docs/vist-glove.md);
  // parse(to_toml()) gives this description back.
  std::string to_toml() const;
};

}  // namespace proprio
