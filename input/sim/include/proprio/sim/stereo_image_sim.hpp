#pragma once
// Image-level stereo marker simulator: renders what the head-mounted,
// rectified stereo camera sees of a glove, as two BGR images, so that a real
// colour-blob detector (proprio::vist::MarkerDetector) can be tested on
// pixels rather than on ideal centroids.
//
// It shares its geometry and ground truth with the detection-level simulator
// (stereo_sim.hpp): StereoMarkerSimulator decides which markers each camera
// sees (field of view, facing, self-occlusion, drops), and this renderer draws
// exactly those. Ground truth (which marker is where) is returned apart from
// the images, so a detector under test cannot peek.
//
// The scene
// - Background: a textured, cluttered wall fixed in the world (seeded
//   texture: smooth colour noise, rectangles, lines, ellipses and polygons in
//   desaturated, dark and saturated colours). It is a plane at
//   background_depth_m in front of the left camera when the head is at
//   T_world_head_rest, so head motion moves it and the two cameras see it
//   with the disparity of its depth. Saturated clutter takes hues between the
//   glove's hues (orange, cyan, purple, ...: the near misses a detector must
//   reject) or is drawn as shapes no marker has (long bars, big panels);
//   marker-coloured blobs in the scene are the distractors, which have ground
//   truth.
// - Distractors: discs in the glove's hues on the wall (static in the world,
//   at background depth, so with the right stereo disparity; they do not
//   overlap each other).
// - The hand: the capsules of hand_capsules() (the same ones the detection
//   simulator's occlusion test uses), ray-cast per pixel with a depth buffer
//   and shaded skin, so it looks like a hand, hides the background and
//   partly hides markers of other segments behind it.
// - Markers: each marker the detection simulator reports visible is drawn as
//   the exact perspective image of a disc (its diameter, centre and outward
//   normal), 4x4 supersampled at its edge, shaded (Lambert + ambient) with a
//   per-marker fabric brightness and hue jitter. Nearer markers and other
//   hand segments hide parts of it; the truth says how much
//   (MarkerImageTruth::visible_fraction()). The detection simulator's test is
//   a single line of sight to the centre, so a marker it calls visible can be
//   partly hidden here, and one it calls hidden is not drawn at all.
// - Camera: a per-frame exposure factor, optional Gaussian blur (optics,
//   demosaicing), then Gaussian pixel noise per channel; dropped frames as in
//   the detection simulator.
//
// Conventions are those of stereo_sim.hpp: OpenCV camera axes, (0, 0) is the
// centre of the top-left pixel, hue codes on OpenCV's HSV_FULL scale.
//
// Determinism: the wall texture and the distractor layout come from
// Rng(mix_seed(seed, stream)) at construction; each frame's random draws
// (exposure, pixel noise) from Rng(mix_seed(mix_seed(seed, stream), t_ns)), so a frame
// depends only on (seed, t, pose, head), not on which frames were rendered
// before. Each random effect has its own stream, so switching noise off does
// not change the clutter or the hand.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/hand_pose.hpp"
#include "proprio/core/result.hpp"
#include "proprio/sim/stereo_sim.hpp"

namespace proprio::sim {

struct StereoImageSimOptions {
  // Visibility and geometry, handed to the detection-level simulator. Its
  // centroid noise does not apply to images (the pixels carry the noise), so
  // pixel_noise_px and area_noise_fraction must be 0 and shuffle must be off;
  // its seed is replaced by `seed` below. min_area_px2 decides which tiny
  // blobs are drawn at all: keep it below the detector's minimum area so that
  // the detector's own size filter is what is tested.
  StereoSimOptions visibility = default_visibility();

  // Pixels: sigma of the additive Gaussian noise per channel, in 8-bit steps
  // (2 is our assumption for a ZED Mini-class sensor indoors; measure yours
  // on a grey card), and of an optional Gaussian blur
  // (0: none), pixels.
  double pixel_noise_dn = 2.0;
  double blur_sigma_px = 0.6;
  // Global brightness of a frame: a factor drawn uniformly from
  // [1 - exposure_jitter, 1 + exposure_jitter] per frame (auto-exposure hunting).
  double exposure_jitter = 0.05;

  // Background wall: depth along the resting left camera's optical axis
  // (metres) and the resting head pose that anchors it in the world
  // (HandMotionOptions' default).
  double background_depth_m = 2.5;
  Pose T_world_head_rest{Quat::Identity(), Vec3(0.0, 1.6, 0.0)};
  bool clutter = true;       // false: a plain grey (128) wall
  int clutter_shapes = 400;  // rectangles, lines, ellipses and polygons on the whole wall
  // Saturated clutter keeps at least this far from each glove hue (HSV_FULL
  // steps, circular; red, yellow, green, blue); desaturated and dark clutter
  // takes any hue. The defaults are 4 steps outside the detector's default
  // hue windows (+-12, 12, 18, 20), so orange, cyan and purple clutter comes
  // close to them without being marker-coloured.
  std::array<double, kMarkerHueCount> clutter_hue_clearance{16.0, 16.0, 22.0, 24.0};
  // Marker-coloured shapes no marker could be (long bars, big panels), besides
  // the clutter shapes.
  int clutter_marker_coloured_shapes = 12;

  // Distractor discs in the glove's hues on the wall, with their diameter range
  // (metres; at 2.5 m, 20-100 mm is 5-26 px across, the image size of a marker
  // between 0.3 and 1.5 m).
  int distractors = 10;
  double distractor_min_diameter_m = 0.02;
  double distractor_max_diameter_m = 0.10;

  // The hand: skin colour (BGR, 0-255, fully lit; hue about 14 HSV_FULL steps,
  // saturation about 77 of 255).
  std::array<double, 3> skin_bgr{150.0, 170.0, 215.0};
  // Light: direction TO the light in the left camera frame (above and behind
  // the camera, so the backs of the hand and of the markers are lit), and the
  // share of ambient light.
  Vec3 light_dir_in_leftcam{0.2, -0.8, -0.55};
  double ambient = 0.45;
  // Markers: saturation (0-1), brightness of a fully lit marker (0-255), and
  // the per-marker spread of fabric brightness (fraction) and hue (HSV_FULL steps).
  double marker_saturation = 0.88;
  double marker_value = 235.0;
  double marker_brightness_jitter = 0.1;
  double marker_hue_jitter = 3.0;

  std::uint64_t seed = 1;

  Status validate() const;
  std::string describe() const;

  // StereoSimOptions with no centroid noise and no shuffle, and a minimum
  // drawn area of 8 px^2.
  static StereoSimOptions default_visibility();
};

// One drawn marker, aligned index for index with StereoGroundTruth::cameras[c]
// (the markers the detection simulator reports visible in camera c).
struct MarkerImageTruth {
  std::size_t marker = 0;  // position in markers() (as MarkerTruth::marker)
  MarkerHue hue = MarkerHue::red;
  std::uint8_t hue_code = 0;  // the hue it was drawn with (HSV_FULL, incl. jitter)
  double u_px = 0.0;  // noise-free projection of the disc's centre (== MarkerTruth::u_px)
  double v_px = 0.0;
  // Of the disc's image: its area and centroid as drawn (pixel coverage, after
  // partial occlusion by other hand segments), and its area if nothing hid it.
  double area_px2 = 0.0;
  double unoccluded_area_px2 = 0.0;
  double u_drawn_px = 0.0;
  double v_drawn_px = 0.0;
  double visible_fraction() const { return unoccluded_area_px2 > 0.0 ? area_px2 / unoccluded_area_px2 : 0.0; }
};

// A distractor disc as it appears in one camera (only those drawn, i.e. with
// some pixel in the image and not entirely behind the hand).
struct DistractorImageTruth {
  std::size_t distractor = 0;  // index into distractors()
  MarkerHue hue = MarkerHue::red;
  double u_px = 0.0;  // projection of the disc's centre
  double v_px = 0.0;
  double area_px2 = 0.0;  // drawn coverage
  double unoccluded_area_px2 = 0.0;
  Vec3 p_in_leftcam = Vec3::Zero();
};

struct StereoImageTruth {
  StereoGroundTruth markers;  // the detection-level truth: visibility, 3D, noise-free centroids
  std::array<std::vector<MarkerImageTruth>, 2> drawn;  // aligned with markers.cameras[c]
  std::array<std::vector<DistractorImageTruth>, 2> distractors;
};

struct StereoImageFrame {
  TimeNs time_ns = 0;
  bool dropped = false;  // true: no images arrived (both Mats are empty)
  std::array<cv::Mat, 2> images;  // [0] left, [1] right: CV_8UC3 BGR, rig-sized
};

// A distractor disc fixed in the world.
struct Distractor {
  MarkerHue hue = MarkerHue::red;
  std::uint8_t hue_code = 0;
  Vec3 p_in_world = Vec3::Zero();
  Vec3 normal_in_world = Vec3::UnitZ();
  double diameter_m = 0.05;
  double value = 200.0;  // brightness, 0-255
};

class StereoImageSimulator {
 public:
  // Validates the options and the rig, builds the detection-level simulator
  // for the glove on this hand shape, and draws the wall texture.
  static Result<StereoImageSimulator> create(const ImuGloveDescription& glove, const HandShape& shape,
                                             StereoImageSimOptions options = {});
  // Renders around an existing detection-level simulator (its options must
  // have no centroid noise and no shuffle; see StereoImageSimOptions::visibility,
  // which is ignored here).
  static Result<StereoImageSimulator> create(StereoMarkerSimulator markers, StereoImageSimOptions options = {});

  // Renders one stereo frame into `out` (its Mats are reused when they have
  // the right size and type) and fills `truth` when given. Not thread-safe:
  // it keeps scratch buffers between calls (one simulator per thread).
  // hidden_markers (per marker, as markers()): markers covered by something
  // the scene does not model (a hand-held object, the other hand); they are
  // not drawn, the skin under them is, and the truth calls them occluded.
  void render(const HandPose& hand_in_world, const Pose& T_world_head, TimeNs t_ns, StereoImageFrame& out,
              StereoImageTruth* truth = nullptr, const std::vector<bool>* hidden_markers = nullptr);

  const StereoMarkerSimulator& marker_simulator() const noexcept { return markers_; }
  const StereoImageSimOptions& options() const noexcept { return options_; }
  const StereoRig& rig() const noexcept { return markers_.rig(); }
  const std::vector<Distractor>& distractors() const noexcept { return distractors_; }
  // The wall (texture, BGR) and its frame: origin at the centre of texel
  // (0, 0), x along the texture's columns, y along its rows, z into the wall
  // (away from the resting camera); one texel is wall_texel_m() metres.
  const cv::Mat& wall_texture() const noexcept { return wall_; }
  const Pose& T_world_wall() const noexcept { return T_world_wall_; }
  double wall_texel_m() const noexcept { return wall_texel_m_; }

 private:
  StereoImageSimulator(StereoMarkerSimulator markers, StereoImageSimOptions options);
  void build_wall();
  void build_distractors();

  StereoMarkerSimulator markers_;
  StereoImageSimOptions options_;
  cv::Mat wall_;
  Pose T_world_wall_;
  double wall_texel_m_ = 0.004;
  std::vector<Distractor> distractors_;
  std::vector<std::uint8_t> marker_hue_codes_;  // per marker, with its jitter
  std::vector<double> marker_brightness_;       // per marker fabric factor
  std::vector<float> normal_table_;             // inverse normal CDF, for fast seeded pixel noise
  // Scratch, kept between frames.
  cv::Mat depth_;    // CV_32F, depth (z, metres) of the nearest hand surface on each pixel's ray
  cv::Mat owner_;    // CV_8U, rigid body (HandJoint index) or marker (64 + index) of that surface; 255: none
  cv::Mat blurred_;  // CV_8UC3
  StereoGroundTruth scratch_truth_;
  std::vector<std::size_t> draw_order_;
};

}  // namespace proprio::sim
