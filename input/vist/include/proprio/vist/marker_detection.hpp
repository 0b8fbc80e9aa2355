#pragma once
// VIST colour-blob marker detection (Lee 2021, §4.3.2): finds the glove's
// coloured markers in one BGR camera image and reports each blob's sub-pixel
// centroid, area and hue as MarkerObservations, the input of the stereo
// matcher (stereo_matching.hpp).
//
// Pipeline (docs/vist-images.md has the numbers and how to tune it):
// 1. Coarse classification. Every coarse_step-th pixel of every
//    coarse_step-th row is classified into "one of the glove hues" or "none"
//    through a 32x32x32 BGR look-up table built from the HSV thresholds. The
//    table is permissive (a cell is a hue's when its centre or a corner
//    passes), so the table's coarseness loses no marker sample; the exact
//    test comes later.
// 2. Coarse connected components: runs of one hue per coarse row, joined to
//    the runs they touch in the row above (8-connected, union-find).
//    Components far larger than a marker can be are rejected here. Each
//    sample of a component that passes the exact test, and is not inside a
//    blob measured already, seeds a blob (a component may hold several).
// 3. Full-resolution blob: a flood fill from the seed with the exact HSV test
//    (hue window, circular, so red wraps around 0; minimum saturation;
//    minimum value). It gives the blob's pixel count, centroid sums, row
//    extents and mean hue.
// 4. Shape filters: area within the range a disc of marker_diameter_m covers
//    between min_depth_m and max_depth_m (pi (d/2)^2 fx fy / z^2, widened by
//    min_area_factor for a tilted or partly hidden marker and by
//    max_area_factor for off-axis stretch and blur); not touching the image
//    border (a cut blob's centroid is biased); solidity (pixels / lattice
//    points of the pixel centres' convex hull, by Pick's theorem: 1 for a
//    digitally convex blob) and circularity (4 pi A / P^2 of that hull grown
//    by half a pixel: 1 for a disc, 0.54 for an ellipse with axes 4:1 (a
//    marker seen 76 deg off its normal), 0.38 for 6:1 (80 deg)).
// 5. Centroid: each blob pixel weighted by its share of the marker's colour
//    (chroma along the blob's hue, ramped from the blob's weakest pixel to its
//    interior mean), so edge pixels count by coverage rather than all or
//    nothing; or the plain mean of the pixel centres (subpixel_weights off).
//
// Hot path: every buffer is kept between calls; after the first images
// detect() allocates nothing (a busier image than any before may grow a
// buffer once). detect_stereo() runs the right image on a helper thread that
// lives as long as the detector. Deterministic: same image, same output, bit
// for bit, with or without the helper thread.
#include <array>
#include <cstdint>
#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/core/result.hpp"

namespace proprio::vist {

// Thresholds of one marker hue, on OpenCV's HSV_FULL scale (hue: 256 steps
// over 360 deg; saturation and value 0-255, as cv::cvtColor(COLOR_BGR2HSV_FULL)
// gives them).
struct HueThreshold {
  MarkerHue hue = MarkerHue::red;
  double hue_center = 0.0;      // HSV_FULL steps, [0, 256)
  double hue_half_width = 12.0;  // accepted: circular distance to the centre <= this
  double min_saturation = 120.0;
  double min_value = 70.0;
};

struct MarkerDetectorOptions {
  // One threshold per glove hue, in MarkerHue order. Windows must not overlap.
  std::array<HueThreshold, kMarkerHueCount> hues = default_hues();

  // Expected blob size: a disc of this diameter between these depths.
  double marker_diameter_m = 0.012;
  double min_depth_m = 0.15;
  double max_depth_m = 1.0;
  // The accepted area is [min_area_factor A(max_depth), max_area_factor A(min_depth)]
  // with A(z) = pi (d/2)^2 fx fy / z^2. min: a marker seen obliquely (cos of
  // the facing angle) or partly hidden; max: off-axis stretch (r/z) and blur.
  double min_area_factor = 0.35;
  double max_area_factor = 1.8;
  double min_solidity = 0.85;
  // 0.4: down to about 5:1 ellipses, markers seen up to about 79 deg off
  // their normal (the detection-level simulator's default facing cutoff is 80).
  double min_circularity = 0.4;
  bool reject_border = true;  // blobs touching the image border are cut: biased centroid
  // Centroid: pixels weighted by their share of the marker's colour (true),
  // or the plain mean of the thresholded blob's pixel centres (false).
  bool subpixel_weights = true;

  // Coarse pass: classify every coarse_step-th pixel (1, 2 or 4). 2 finds
  // every blob of 3 px across or more; 1 also finds the smallest.
  int coarse_step = 2;
  // detect_stereo() runs the right image on a helper thread; false: both on
  // the calling thread (one after the other).
  bool parallel_stereo = true;
  std::size_t reserve_markers = 128;  // blob buffers sized for this many candidates up front

  Status validate() const;
  std::string describe() const;

  // Windows around the glove hues (HSV_FULL: red 0, yellow 43, green 85,
  // blue 171): red +-12 (wrapping through 0), yellow +-12, green +-18, blue
  // +-20; saturation >= 120 (skin is about 60-110), value >= 70.
  static std::array<HueThreshold, kMarkerHueCount> default_hues();
};

// What happened to the candidates of one image.
struct MarkerDetectionStats {
  std::size_t coarse_components = 0;    // coarse connected components of a glove hue
  std::size_t rejected_coarse_large = 0;  // far larger than a marker already at coarse resolution
  std::size_t merged = 0;               // all its passing samples in blobs already measured (one blob, several coarse parts)
  std::size_t no_seed = 0;              // no sample of the component passed the exact test (table cell edges)
  std::size_t rejected_small = 0;       // area below the accepted range
  std::size_t rejected_large = 0;       // area above the accepted range
  std::size_t rejected_border = 0;      // touches the image border
  std::size_t rejected_solidity = 0;
  std::size_t rejected_circularity = 0;
  std::size_t accepted = 0;
  std::array<std::size_t, kMarkerHueCount> accepted_per_hue{};

  void add(const MarkerDetectionStats& o);
};

class MarkerDetector {
 public:
  // Validates the camera (positive size and focal lengths) and the options.
  static Result<MarkerDetector> create(const PinholeCamera& camera, MarkerDetectorOptions options = {});
  ~MarkerDetector();
  MarkerDetector(MarkerDetector&&) noexcept;
  MarkerDetector& operator=(MarkerDetector&&) noexcept;
  MarkerDetector(const MarkerDetector&) = delete;
  MarkerDetector& operator=(const MarkerDetector&) = delete;

  // Detects the markers in one CV_8UC3 BGR image of the camera's size.
  // out.markers is cleared and filled in scan order (top to bottom);
  // out.camera_id is left as it is. An empty image, another type or size is
  // an invalid_argument error (out is then cleared). Not reentrant: one call
  // at a time per detector.
  Status detect(const cv::Mat& bgr, MarkerObservations& out);
  // Left and right image of a stereo pair; the right one on the helper
  // thread when options.parallel_stereo. Sets camera_id 0 and 1.
  Status detect_stereo(const cv::Mat& left_bgr, const cv::Mat& right_bgr, MarkerObservations& out_left,
                       MarkerObservations& out_right);

  // Of the last detect() (camera 0) or detect_stereo() (0: left, 1: right).
  const MarkerDetectionStats& last_stats(std::size_t camera = 0) const noexcept;
  const MarkerDetectorOptions& options() const noexcept;
  const PinholeCamera& camera() const noexcept;
  // The accepted blob area range, square pixels.
  double min_area_px2() const noexcept;
  double max_area_px2() const noexcept;
  // The exact per-pixel test: the hue a BGR colour is classified as, or -1.
  int classify(std::uint8_t b, std::uint8_t g, std::uint8_t r) const noexcept;

 private:
  struct Impl;
  explicit MarkerDetector(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace proprio::vist
