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
// - Camera realism (each effect has its own switch; idealised() turns them all
//   off and gives the images of the simulator before them, byte for byte):
//   motion blur of the markers over the exposure, the hand placed at
//   mid-exposure; vignetting, a smooth illumination gradient and a colour
//   cast of the light (white balance off) on the whole scene; glossy, slightly
//   domed markers with a Blinn-Phong highlight; a small residual lens
//   distortion left by an imperfect calibration (the image is warped by it,
//   the truth and the rig stay the ideal rectified pinhole, so the tracker
//   faces the error); shot noise and read noise with the gain the exposure
//   and the light level need. The pipeline per camera: scene (wall, hand,
//   distractors, markers) -> light and lens shading (exposure, vignetting,
//   gradient, colour cast) -> lens residual (remap) -> blur -> sensor noise.
//
// Conventions are those of stereo_sim.hpp: OpenCV camera axes, (0, 0) is the
// centre of the top-left pixel, hue codes on OpenCV's HSV_FULL scale.
//
// Determinism: the wall texture, the distractor layout and the per-session
// camera draws (lens residual, colour cast, gradient direction, marker gloss)
// come from Rng(mix_seed(seed, stream)) at construction; each frame's random
// draws (exposure, pixel noise) from Rng(mix_seed(mix_seed(seed, stream), t_ns)),
// so a frame depends only on (seed, t, pose, head), not on which frames were
// rendered before. Each random effect has its own stream, so switching one
// off (noise, say) does not change the others (the clutter, the lens).
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>
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

  // ---- Camera realism. On by default: the default images are meant to look
  // like a real head-mounted camera's. idealised() switches all of it off.

  // Motion blur: each marker is smeared over the exposure along its image
  // motion (the hand's joint velocities, HandPose::linear/angular_velocity;
  // a pose without velocities is drawn sharp), and the hand's capsules are
  // drawn where they are at mid-exposure (their own smear is not modelled,
  // nor is the head's motion during the exposure: render() has the head pose
  // at t only). exposure_s: 4 ms, our assumption for an auto-exposed camera
  // indoors at 30-60 Hz that keeps motion blur short (VR tracking cameras run
  // 1-10 ms; it also sets the sensor gain below). timestamp_in_exposure:
  // where the frame's time stamp falls in its exposure, 0 at the start,
  // 0.5 mid, 1 at the end. 0 by default: V4L2's uvcvideo driver stamps
  // buffers at the start of exposure (V4L2_BUF_FLAG_TSTAMP_SRC_SOE), and that
  // stamp is the capture time the live camera path (vist/stereo_camera)
  // reads, so the markers appear on average exposure_s / 2 after it.
  bool motion_blur = true;
  double exposure_s = 0.004;
  double timestamp_in_exposure = 0.0;

  // Sensor noise (the photon transfer model of EMVA 1288): the variance of a
  // pixel is K * S + read^2 (DN^2) for a signal of S DN, with the system gain
  // K in DN per electron (shot noise, Poisson, drawn as its Gaussian limit)
  // and read = pixel_noise_dn; clipped to 0..255. Both are given at
  // exposure_s = 4 ms and light_level 1 (an indoor room); auto-exposure keeps
  // the image as bright with less light or a shorter exposure by raising the
  // gain, so K and read scale with gain_ratio() = (4 ms / exposure_s) /
  // light_level: a darker scene is a noisier one. 0.1 DN/e- is our
  // assumption, not a measurement: a 2 um-pixel sensor of the ZED Mini's
  // class taken as about 5000 e- full well on 255 DN (0.05 DN/e- at unity
  // gain), at twice analogue gain indoors; with 2 DN read noise a mid-grey
  // (128) then has sigma 4.1 DN, a lit marker (235) 5.3 DN. Measure yours:
  // the slope of the variance against the mean over grey-card patches is K.
  // Off: pixel_noise_dn is plain additive Gaussian noise, as before.
  bool sensor_noise = true;
  double sensor_gain_dn_per_e = 0.1;
  double light_level = 1.0;

  // Lens: the rectified images of a real camera keep what its calibration
  // got wrong. Each camera's image is warped by a residual Brown-Conrady
  // distortion (OpenCV's k1, k2, p1, p2 on the rig's normalised coordinates;
  // true distortion minus the calibration's estimate), drawn per camera from
  // zero-mean normals with these sigmas; the rig, the truth and the tracker
  // keep the ideal pinhole. On the ZED Mini-like rig (fx 640, corner radius
  // 1.15 in normalised units) the defaults move a corner pixel by
  // 0.98 px (k1), 0.65 px (k2), 0.68 / 0.43 px (p, x / y), about 1.4 px RMS in
  // all, and the image centre by nothing: the size of the extrapolation
  // error at the corners of a calibration with 0.2-0.3 px RMS reprojection
  // error over its targets. (k1 of 0.005-0.01 would be 5-10 px there.)
  bool lens_residual = true;
  double residual_k1_sigma = 0.001;
  double residual_k2_sigma = 0.0005;
  double residual_p_sigma = 0.0003;

  // Uneven and coloured light, on the whole scene, markers included (so
  // their hues shift as in real images); 0 turns each off.
  // vignetting: relative illumination 1 - vignetting * (1 - cos^4 theta), theta
  // the pixel's angle off the optical axis; 0.4 leaves 67 % at the corners of
  // the 90 deg-wide rig (natural cos^4 falloff alone would leave 18 %; lenses
  // and the ISP's shading correction recover much of it; 60-80 % is typical of
  // a wide M12 lens).
  double vignetting = 0.4;
  // illumination_gradient: a linear ramp of the light across the image, +-this
  // fraction at the middle of the image's edges, its direction drawn per
  // session (a lamp to one side); 0.1 by default.
  double illumination_gradient = 0.1;
  // colour_cast: white balance off: the blue and red gains relative to green
  // are each drawn per session from 1 +- colour_cast (0.04: a few per cent, the
  // scatter of auto white balance under mixed indoor light).
  double colour_cast = 0.04;

  // Specular highlights: each marker is a glossy, shallow dome (a sphere cap of
  // radius marker_dome_radius_m over the disc: 20 mm, a 12 mm marker domed
  // about 1 mm) with a Blinn-Phong highlight of the light (light_dir_in_leftcam)
  // added in white: specular * gloss * (n.h)^specular_shininess of full scale,
  // where n is the dome's normal and h the bisector of the directions to the
  // light and to the camera. Per marker, gloss is drawn from
  // [1 - marker_gloss_spread, 1]. The highlight shows where the dome's normal
  // is h, i.e. on markers that face about halfway between the light and the
  // camera; it is near-white, so it shifts a detected blob's centroid or
  // splits it, as real ones do. Shininess 80: glossy plastic (a highlight
  // about 2 mm across on the dome); 0 specular: off.
  double specular = 0.8;
  double specular_shininess = 80.0;
  double marker_gloss_spread = 0.5;
  double marker_dome_radius_m = 0.02;

  std::uint64_t seed = 1;

  Status validate() const;
  std::string describe() const;

  // The sensor gain relative to its reference (4 ms, light level 1), and the
  // system gain and read noise it gives (used when sensor_noise is on).
  double gain_ratio() const { return (0.004 / exposure_s) / light_level; }
  double effective_gain_dn_per_e() const { return sensor_gain_dn_per_e * gain_ratio(); }
  double effective_read_noise_dn() const { return pixel_noise_dn * gain_ratio(); }

  // Turns every camera-realism effect above off (motion blur, sensor noise
  // model, lens residual, vignetting, gradient, colour cast, highlights); the
  // rest (pixel_noise_dn as plain Gaussian noise, blur, exposure jitter,
  // clutter, distractors) stays as it is.
  void switch_off_camera_realism();
  // The defaults with switch_off_camera_realism(): the images of the
  // simulator before camera realism, byte for byte, for comparison.
  static StereoImageSimOptions idealised();

  // StereoSimOptions with no centroid noise and no shuffle, and a minimum
  // drawn area of 8 px^2.
  static StereoSimOptions default_visibility();
};

// A residual lens distortion (Brown-Conrady, OpenCV's convention, on the
// rig's normalised pinhole coordinates): where a point the ideal pinhole
// projects to (u, v) appears in the image.
struct LensResidual {
  double k1 = 0.0, k2 = 0.0, p1 = 0.0, p2 = 0.0;
  bool zero() const { return k1 == 0.0 && k2 == 0.0 && p1 == 0.0 && p2 == 0.0; }
  Eigen::Vector2d distort_px(const PinholeCamera& camera, double u_px, double v_px) const;
  // The inverse, by fixed-point iteration (exact to 1e-9 px for residuals).
  Eigen::Vector2d undistort_px(const PinholeCamera& camera, double u_px, double v_px) const;
  // The largest displacement over the image's four corner pixels.
  double corner_shift_px(const PinholeCamera& camera) const;
};

// The per-session draws of the camera realism (neutral when an effect is off).
struct CameraLook {
  std::array<LensResidual, 2> lens{};                    // per camera
  std::array<double, 3> colour_gain_bgr{1.0, 1.0, 1.0};  // green is the reference
  double gradient_angle_rad = 0.0;   // the direction the light increases in, in the image (u right, v down)
  std::vector<double> marker_gloss;  // per marker, in [1 - marker_gloss_spread, 1]
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
  // The realism's share: the marker's outward normal (left camera frame, at
  // t); its image motion over the exposure (end minus start, ideal pinhole; 0
  // without motion blur or velocities), so the drawn centroid is
  // (u_px, v_px) + (0.5 - timestamp_in_exposure) * blur; and the strongest
  // specular term drawn on it (fraction of full scale, before clipping; 0:
  // no highlight on it). The drawn area and centroid are those of the ideal
  // image, before the lens residual (LensResidual::distort_px maps them).
  Vec3 normal_in_leftcam = Vec3::Zero();
  double blur_u_px = 0.0;
  double blur_v_px = 0.0;
  double highlight = 0.0;
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
  // skin_offsets_in_segment: soft tissue, as StereoMarkerSimulator::simulate takes it.
  void render(const HandPose& hand_in_world, const Pose& T_world_head, TimeNs t_ns, StereoImageFrame& out,
              StereoImageTruth* truth = nullptr, const std::vector<bool>* hidden_markers = nullptr,
              std::span<const Vec3> skin_offsets_in_segment = {});

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
  // The session's camera realism draws (lens residuals, colour cast, ...).
  const CameraLook& look() const noexcept { return look_; }

 private:
  StereoImageSimulator(StereoMarkerSimulator markers, StereoImageSimOptions options);
  void build_wall();
  void build_distractors();
  void build_camera_look();

  StereoMarkerSimulator markers_;
  StereoImageSimOptions options_;
  cv::Mat wall_;
  Pose T_world_wall_;
  double wall_texel_m_ = 0.004;
  std::vector<Distractor> distractors_;
  std::vector<std::uint8_t> marker_hue_codes_;  // per marker, with its jitter
  std::vector<double> marker_brightness_;       // per marker fabric factor
  std::vector<float> normal_table_;             // inverse normal CDF, for fast seeded pixel noise
  // Camera realism, built once: the per-session draws; per camera, the
  // spatial light factor (CV_32F; empty: none) and the lens residual's remap
  // (fixed-point maps for cv::remap; empty: none); the noise sigma per 8-bit
  // level (sensor_noise).
  CameraLook look_;
  std::array<cv::Mat, 2> light_map_;
  std::array<cv::Mat, 2> lens_map1_, lens_map2_;
  std::array<float, 256> noise_sigma_{};
  // Scratch, kept between frames.
  cv::Mat depth_;    // CV_32F, depth (z, metres) of the nearest hand surface on each pixel's ray
  cv::Mat owner_;    // CV_8U, rigid body (HandJoint index) or marker (64 + index) of that surface; 255: none
  cv::Mat blurred_;  // CV_8UC3
  StereoGroundTruth scratch_truth_;
  std::vector<std::size_t> draw_order_;
  std::vector<double> marker_acc_;  // a marker's accumulated coverage and colour over its exposure
};

}  // namespace proprio::sim
