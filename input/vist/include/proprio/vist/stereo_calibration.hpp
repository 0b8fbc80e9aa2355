#pragma once
// Stereo calibration of VIST's head-mounted camera from checkerboard image
// pairs, and the rectification that turns it into the rectified pinhole rig
// (proprio::StereoRig) that the tracker and the glove file describe.
//
// Pipeline: findChessboardCorners (findChessboardCornersSB where that fails)
// + cornerSubPix per image, calibrateCamera per
// camera (its result seeds the next step), stereoCalibrate (intrinsics refined
// jointly with the extrinsics), stereoRectify with CALIB_ZERO_DISPARITY (so
// both rectified cameras share one principal point, as StereoRig assumes) and
// initUndistortRectifyMap for whole images.
//
// Pixel coordinates: OpenCV's corner coordinates and principal points put the
// centre of the top-left pixel at (0, 0), which is the convention of
// PinholeCamera, so rectified fx, fy, cx, cy are copied without a shift (the
// synthetic-board test checks this to a twentieth of a pixel).
//
// Frames and names: p_in_rightcam = R_rightcam_leftcam * p_in_leftcam +
// t_rightcam_leftcam_m (OpenCV's R, T from stereoCalibrate). The rectified
// frames ("rectleft", "rectright") are the physical cameras rotated by
// stereoRectify's R1, R2; StereoRig's left camera is the rectified left one.
#include <cstddef>
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"

namespace proprio::vist {

// A printed checkerboard, counted by its INNER corners (where four squares
// meet), as OpenCV counts them: a board of 10 x 7 squares has 9 x 6.
struct CheckerboardSpec {
  int inner_cols = 9;
  int inner_rows = 6;
  double square_m = 0.025;  // edge of one square, metres

  Status validate() const;
  std::string describe() const;
  // "9x6" (cols x rows of inner corners) and the square edge in millimetres,
  // the units a user measures a printed board in.
  static Result<CheckerboardSpec> parse(std::string_view cols_x_rows, double square_mm);
  // Corner positions on the board: x along a row (cols), y down the columns,
  // z = 0, row-major, the order findChessboardCorners reports them in.
  std::vector<cv::Point3f> object_points() const;
  cv::Size pattern_size() const { return {inner_cols, inner_rows}; }
};

// Corners found in one image pair (OpenCV pixel coordinates, see the top).
struct BoardDetection {
  std::string name;  // what the user calls this pair (file names), for messages
  cv::Size image_size;  // of each camera's image
  bool found_left = false;
  bool found_right = false;
  std::vector<cv::Point2f> corners_left;
  std::vector<cv::Point2f> corners_right;
  bool usable() const { return found_left && found_right; }
};

// Finds the whole board (all inner corners) in one image, BGR or grey, and
// refines the corners to subpixel accuracy. False if not all corners are seen.
bool detect_board(const cv::Mat& image, const CheckerboardSpec& board, std::vector<cv::Point2f>& corners);
// The corner grid looks the same turned by half a turn, so the detector may
// count one image's corners from the opposite end of the board; this reverses
// `right` if so (judged by the direction from first to last corner).
void match_corner_order(const std::vector<cv::Point2f>& left, std::vector<cv::Point2f>& right);
// Both images of a pair, corners in matching order (match_corner_order).
// Images of different sizes give an empty image_size, which calibrate_stereo
// reports.
BoardDetection detect_board_pair(const cv::Mat& left, const cv::Mat& right, const CheckerboardSpec& board,
                                 std::string name);

struct StereoCalibrationOptions {
  CheckerboardSpec board;
  // stereoRectify's free scaling: 0 keeps only pixels valid in both rectified
  // images (no black borders, narrower view), 1 keeps every source pixel.
  double alpha = 0.0;
  // k3 stays 0 unless asked for: with a normal lens and a dozen boards it only
  // fits noise at the image corners.
  bool fix_k3 = true;
  bool fix_tangential = false;  // p1 = p2 = 0
  // Fewer usable pairs than this is an error: each pair adds 6 unknowns.
  int min_pairs = 6;
  // A pair is flagged as an outlier when its stereo RMS reprojection error
  // exceeds both outlier_factor times the median over all pairs and
  // outlier_min_px (a clean set has every pair near the median).
  double outlier_factor = 3.0;
  double outlier_min_px = 0.5;

  Status validate() const;
  std::string describe() const;
};

struct CameraCalibration {
  cv::Matx33d K = cv::Matx33d::eye();  // fx 0 cx; 0 fy cy; 0 0 1 (pixels)
  cv::Vec<double, 5> dist{};           // k1 k2 p1 p2 k3 (OpenCV's plumb-bob model)
  // One-sigma uncertainties from calibrateCamera (fx, fy, cx, cy), pixels.
  cv::Vec4d intrinsics_sigma_px{};
  double rms_px = 0.0;  // RMS reprojection error of the single-camera calibration

  double fx() const { return K(0, 0); }
  double fy() const { return K(1, 1); }
  double cx() const { return K(0, 2); }
  double cy() const { return K(1, 2); }
};

// Reprojection error of one pair after the stereo calibration.
struct PairError {
  std::string name;
  double rms_left_px = 0.0;
  double rms_right_px = 0.0;
  bool outlier = false;
};

struct StereoCalibration {
  cv::Size image_size;  // of each camera, before and after rectification
  CheckerboardSpec board;
  double alpha = 0.0;
  CameraCalibration left;
  CameraCalibration right;
  cv::Matx33d R_rightcam_leftcam = cv::Matx33d::eye();
  cv::Vec3d t_rightcam_leftcam_m{};
  // stereoRectify's R1, R2 (camera -> rectified camera), P1, P2, Q.
  cv::Matx33d R_rectleft_leftcam = cv::Matx33d::eye();
  cv::Matx33d R_rectright_rightcam = cv::Matx33d::eye();
  cv::Matx34d P_left = cv::Matx34d::zeros();
  cv::Matx34d P_right = cv::Matx34d::zeros();
  cv::Matx44d Q = cv::Matx44d::zeros();
  cv::Rect valid_roi_left;  // rectified pixels valid in each image
  cv::Rect valid_roi_right;
  double rms_stereo_px = 0.0;   // stereoCalibrate's RMS over both cameras
  std::vector<PairError> pairs;  // the pairs used, in input order
  std::vector<std::string> skipped;  // pairs without the whole board in both images

  // Distance between the camera centres (not only its x part).
  double baseline_m() const;
  // The rectified pinhole camera both rectified images share.
  PinholeCamera rectified_camera() const;
  // The rig for a glove file. The mount and rate are not calibrated here: the
  // mount is the rectified left camera's pose in the head frame.
  StereoRig rectified_rig(double rate_hz, const Pose& T_head_leftcam) const;
  std::vector<std::string> outlier_names() const;
  // A multi-line report: RMS errors, intrinsics with sigmas, baseline, the
  // rectified camera, flagged pairs.
  std::string describe() const;

  // Raw (distorted) pixels -> rectified pixels of the same camera.
  std::vector<cv::Point2d> rectify_left_points(const std::vector<cv::Point2d>& raw_px) const;
  std::vector<cv::Point2d> rectify_right_points(const std::vector<cv::Point2d>& raw_px) const;

  // OpenCV FileStorage YAML (.yaml/.yml) or JSON (.json); everything above.
  Status save(const std::filesystem::path& path) const;
  static Result<StereoCalibration> load(const std::filesystem::path& path);
};

// Runs calibrateCamera, stereoCalibrate and stereoRectify on detections (the
// pairs that are not usable() are listed in skipped). Errors say what to do:
// too few pairs, inconsistent image sizes, cameras swapped or stacked.
Result<StereoCalibration> calibrate_stereo(const std::vector<BoardDetection>& detections,
                                           const StereoCalibrationOptions& options);

// Image pairs in a folder. Side by side: every image, split down the middle
// (left half = left camera). Otherwise either subfolders left/ and right/ with
// the same file names, or files whose names differ only in "left"/"right"
// (left_000.png + right_000.png, cam_left3.jpg + cam_right3.jpg). Sorted by name.
struct CalibrationImagePair {
  std::string name;
  std::filesystem::path left;   // the side-by-side image when right is empty
  std::filesystem::path right;
};
Result<std::vector<CalibrationImagePair>> find_calibration_images(const std::filesystem::path& dir,
                                                                  bool side_by_side);
// Reads one pair (both files, or one side-by-side image) and detects the board.
Result<BoardDetection> detect_board_in_files(const CalibrationImagePair& pair, const CheckerboardSpec& board);

// Called after each pair is read and searched: index from 0, count, result.
using CalibrationProgress = std::function<void(std::size_t index, std::size_t count, const BoardDetection&)>;
// find_calibration_images + detect_board_in_files + calibrate_stereo, with a
// check that every image has the same size, naming the first that differs.
Result<StereoCalibration> calibrate_stereo_folder(const std::filesystem::path& dir, bool side_by_side,
                                                  const StereoCalibrationOptions& options,
                                                  const CalibrationProgress& progress = {});

// The [rig] table of a glove file (docs/vist-glove.md) for this rig: focal
// lengths, principal point and baseline with three decimals (0.001 px and
// 0.001 mm, far below calibration error), the rate and the mount as
// ImuGloveDescription::to_toml writes them.
std::string rig_toml_snippet(const StereoRig& rig);

// Undistort-and-rectify maps for whole images (initUndistortRectifyMap).
// Rectifying an image costs a remap; a tracker that only needs blob centroids
// can instead detect on the raw images and use rectify_*_points.
class StereoRectifier {
 public:
  static Result<StereoRectifier> create(const StereoCalibration& calibration);
  cv::Size image_size() const { return size_; }
  // Outputs are reallocated only when their size or type differs. Images must
  // have the calibrated size.
  Status rectify(const cv::Mat& left, const cv::Mat& right, cv::Mat& left_out, cv::Mat& right_out) const;

 private:
  cv::Size size_;
  cv::Mat left_map1_, left_map2_, right_map1_, right_map2_;
};

}  // namespace proprio::vist
