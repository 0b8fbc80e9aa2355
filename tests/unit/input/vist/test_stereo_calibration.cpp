// Stereo calibration on synthetic checkerboard pairs with known intrinsics,
// distortion, extrinsics and board poses. The boards are rendered by
// projecting each square (edges subdivided, so distortion bends them) with
// cv::projectPoints, filling polygons at 4x resolution and box-downsampling:
// an anti-aliased image whose pixel (0, 0) is centred at (0, 0), the
// convention under test.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <tuple>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/random.hpp"
#include "proprio/vist/stereo_calibration.hpp"
#include "support/temp_dir.hpp"
#include "support/text.hpp"

using namespace proprio;
using namespace proprio::vist;
using proprio::testing_support::TempDir;

namespace {

using proprio::testing_support::contains;

constexpr int kSupersample = 4;
constexpr int kShift = 8;  // fillPoly fixed-point bits

struct TrueCamera {
  cv::Matx33d K;
  cv::Vec<double, 5> dist;
};

struct TrueRig {
  cv::Size size{1280, 720};
  TrueCamera left, right;
  cv::Matx33d R_rightcam_leftcam;
  cv::Vec3d t_rightcam_leftcam_m;
  cv::Vec3d c_right_in_left_m;  // the right camera's centre in the left frame
};

TrueRig true_rig() {
  TrueRig r;
  r.left = {cv::Matx33d(700.0, 0.0, 643.3, 0.0, 698.0, 356.7, 0.0, 0.0, 1.0), {-0.06, 0.03, 0.0004, -0.0003, 0.0}};
  r.right = {cv::Matx33d(705.0, 0.0, 636.1, 0.0, 703.5, 362.4, 0.0, 0.0, 1.0), {-0.05, 0.02, -0.0002, 0.0003, 0.0}};
  cv::Rodrigues(cv::Vec3d(0.004, -0.012, 0.003), r.R_rightcam_leftcam);
  r.c_right_in_left_m = cv::Vec3d(0.063, 0.0004, -0.0006);
  r.t_rightcam_leftcam_m = -(r.R_rightcam_leftcam * r.c_right_in_left_m);
  return r;
}

CheckerboardSpec test_board() {
  CheckerboardSpec b;
  b.inner_cols = 9;
  b.inner_rows = 6;
  b.square_m = 0.03;
  return b;
}

// Low-resolution pixel coordinates -> fixed-point coordinates at kSupersample
// resolution. A low-res pixel i covers high-res pixels s*i .. s*i+s-1, whose
// centre is s*i + (s-1)/2.
cv::Point to_hi(const cv::Point2d& p) {
  const double s = kSupersample;
  return {static_cast<int>(std::lround((s * p.x + (s - 1) / 2.0) * (1 << kShift))),
          static_cast<int>(std::lround((s * p.y + (s - 1) / 2.0) * (1 << kShift)))};
}

cv::Mat downsample(const cv::Mat& hi, cv::Size size) {
  cv::Mat lo;
  cv::resize(hi, lo, size, 0, 0, cv::INTER_AREA);
  return lo;
}

// A board-frame rectangle's outline, edges subdivided, projected into a
// camera (low-resolution pixels).
std::vector<cv::Point2d> project_quad(double x0, double y0, double x1, double y1, const cv::Vec3d& rvec,
                                      const cv::Vec3d& tvec, const TrueCamera& cam) {
  constexpr int kSteps = 8;
  std::vector<cv::Point3d> pts;
  auto edge = [&](double ax, double ay, double bx, double by) {
    for (int k = 0; k < kSteps; ++k) {
      const double t = static_cast<double>(k) / kSteps;
      pts.emplace_back(ax + t * (bx - ax), ay + t * (by - ay), 0.0);
    }
  };
  edge(x0, y0, x1, y0);
  edge(x1, y0, x1, y1);
  edge(x1, y1, x0, y1);
  edge(x0, y1, x0, y0);
  std::vector<cv::Point2d> px;
  cv::projectPoints(pts, rvec, tvec, cam.K, cam.dist, px);
  return px;
}

// The board seen by one camera, board pose (rvec, tvec) in that camera. Only
// the paper's bounding box is rendered at high resolution; the rest of the
// image is the uniform background anyway.
cv::Mat render_board(const CheckerboardSpec& b, const cv::Vec3d& rvec, const cv::Vec3d& tvec, const TrueCamera& cam,
                     cv::Size size, Rng& rng) {
  constexpr int kBackground = 70;
  const double s = b.square_m;
  // Paper with a one-square white margin around the outer squares.
  const auto paper = project_quad(-2 * s, -2 * s, (b.inner_cols + 1) * s, (b.inner_rows + 1) * s, rvec, tvec, cam);
  cv::Rect roi = cv::boundingRect(std::vector<cv::Point2f>(paper.begin(), paper.end()));
  roi = cv::Rect(roi.x - 3, roi.y - 3, roi.width + 6, roi.height + 6) & cv::Rect(cv::Point(0, 0), size);
  const cv::Point2d origin(roi.x, roi.y);
  auto to_roi_hi = [&](const std::vector<cv::Point2d>& pts) {
    std::vector<cv::Point> out;
    for (const auto& p : pts) out.push_back(to_hi(p - origin));
    return out;
  };
  cv::Mat hi(roi.height * kSupersample, roi.width * kSupersample, CV_8U, cv::Scalar(kBackground));
  cv::fillPoly(hi, std::vector<std::vector<cv::Point>>{to_roi_hi(paper)}, cv::Scalar(235), cv::LINE_8, kShift);
  std::vector<std::vector<cv::Point>> dark;
  for (int j = -1; j < b.inner_rows; ++j) {
    for (int i = -1; i < b.inner_cols; ++i) {
      if (((i + j) & 1) == 0) {
        dark.push_back(to_roi_hi(project_quad(i * s, j * s, (i + 1) * s, (j + 1) * s, rvec, tvec, cam)));
      }
    }
  }
  cv::fillPoly(hi, dark, cv::Scalar(25), cv::LINE_8, kShift);
  cv::Mat lo(size, CV_8U, cv::Scalar(kBackground));
  downsample(hi, roi.size()).copyTo(lo(roi));
  // Sensor-like: a little optical blur and noise. Uniform noise of sigma 1.5
  // grey levels (its shape does not matter here), four 16-bit draws from each
  // 64-bit output: the 22 million samples of a test run stay cheap.
  cv::GaussianBlur(lo, lo, cv::Size(0, 0), 0.5);
  const double half_width = 1.5 * std::sqrt(3.0);
  const double scale = 2.0 * half_width / 65536.0;
  std::uint64_t bits = 0;
  int left_in_bits = 0;
  for (int y = 0; y < lo.rows; ++y) {
    auto* row = lo.ptr<std::uint8_t>(y);
    for (int x = 0; x < lo.cols; ++x) {
      if (left_in_bits == 0) {
        bits = rng.next_u64();
        left_in_bits = 4;
      }
      const double u = static_cast<double>(bits & 0xffff) * scale - half_width;
      bits >>= 16;
      --left_in_bits;
      row[x] = cv::saturate_cast<std::uint8_t>(row[x] + u);
    }
  }
  return lo;
}

struct BoardPose {
  cv::Vec3d rvec, tvec;  // board in the left camera
};

// Board centre in the left camera (m) and tilt (deg, rotation vector).
BoardPose pose(double cx, double cy, double cz, double rx_deg, double ry_deg, double rz_deg) {
  const auto b = test_board();
  const cv::Vec3d rvec(rx_deg * M_PI / 180.0, ry_deg * M_PI / 180.0, rz_deg * M_PI / 180.0);
  cv::Matx33d R;
  cv::Rodrigues(rvec, R);
  const cv::Vec3d centre_in_board((b.inner_cols - 1) * b.square_m / 2.0, (b.inner_rows - 1) * b.square_m / 2.0, 0.0);
  return {rvec, cv::Vec3d(cx, cy, cz) - R * centre_in_board};
}

std::vector<BoardPose> board_poses() {
  return {
      pose(0.0, 0.0, 0.60, 0, 0, 0),          pose(-0.25, -0.12, 0.70, 20, -25, 5),
      pose(0.25, -0.12, 0.70, -20, 25, -5),   pose(-0.25, 0.13, 0.70, -15, -30, 10),
      pose(0.25, 0.13, 0.70, 15, 30, -10),    pose(0.0, 0.0, 0.45, 30, 0, 0),
      pose(0.0, 0.02, 0.50, 0, 35, 0),        pose(0.05, -0.05, 0.80, -30, 10, 20),
      pose(-0.10, 0.05, 0.55, 10, -15, -25),  pose(0.12, 0.06, 0.65, -25, -20, 15),
      pose(-0.30, 0.0, 0.75, 0, 30, 90),      pose(0.30, 0.0, 0.75, 5, -30, -90),
  };
}

// The board pose in the right camera.
void to_right(const TrueRig& rig, const BoardPose& p, cv::Vec3d& rvec, cv::Vec3d& tvec) {
  cv::Matx33d R_left_board;
  cv::Rodrigues(p.rvec, R_left_board);
  cv::Rodrigues(rig.R_rightcam_leftcam * R_left_board, rvec);
  tvec = rig.R_rightcam_leftcam * p.tvec + rig.t_rightcam_leftcam_m;
}

std::vector<cv::Point2d> true_corners(const TrueCamera& cam, const cv::Vec3d& rvec, const cv::Vec3d& tvec) {
  std::vector<cv::Point3d> obj;
  for (const auto& p : test_board().object_points()) obj.emplace_back(p.x, p.y, p.z);
  std::vector<cv::Point2d> px;
  cv::projectPoints(obj, rvec, tvec, cam.K, cam.dist, px);
  return px;
}

struct Synthetic {
  TrueRig rig = true_rig();
  std::vector<BoardPose> poses = board_poses();
  std::vector<cv::Mat> left, right;
  std::vector<BoardDetection> detections;
  Result<StereoCalibration> calibration = make_error(Errc::unavailable, "not run");
  StereoCalibrationOptions options;
};

// Rendered, detected and calibrated once for all tests (the expensive part).
const Synthetic& synthetic() {
  static const Synthetic s = [] {
    Synthetic out;
    Rng rng(mix_seed(20240604, 1));
    for (std::size_t i = 0; i < out.poses.size(); ++i) {
      const auto& p = out.poses[i];
      cv::Vec3d rr, tr;
      to_right(out.rig, p, rr, tr);
      out.left.push_back(render_board(test_board(), p.rvec, p.tvec, out.rig.left, out.rig.size, rng));
      out.right.push_back(render_board(test_board(), rr, tr, out.rig.right, out.rig.size, rng));
      out.detections.push_back(
          detect_board_pair(out.left.back(), out.right.back(), test_board(), "pair_" + std::to_string(i)));
    }
    out.options.board = test_board();
    out.calibration = calibrate_stereo(out.detections, out.options);
    return out;
  }();
  return s;
}

double rel_err(double got, double want) { return std::abs(got - want) / std::abs(want); }

}  // namespace

// --- the synthetic renderer itself --------------------------------------------

TEST(StereoCalibrationRenderer, PutsAreaCentroidsWherePixelCentresAreIntegers) {
  // A polygon's intensity centroid after supersampling must be its geometric
  // centroid, with pixel (0, 0)'s centre at (0, 0): the renderer is the ruler
  // the calibration's pixel convention is measured with. fillPoly fills the
  // high-resolution pixels whose centres are within half a pixel of the
  // polygon, so edges are good to 1/(2 * kSupersample) px: well within what
  // tells the two conventions apart (0.5 px).
  const cv::Size size(64, 48);
  const double tol = 0.5 / kSupersample;
  for (const cv::Point2d c : {cv::Point2d(20.0, 15.0), cv::Point2d(30.3, 21.7), cv::Point2d(41.55, 30.25)}) {
    cv::Mat hi(size.height * kSupersample, size.width * kSupersample, CV_8U, cv::Scalar(0));
    const std::vector<cv::Point> square = {to_hi(c + cv::Point2d(-7.2, -5.1)), to_hi(c + cv::Point2d(7.2, -5.1)),
                                           to_hi(c + cv::Point2d(7.2, 5.1)), to_hi(c + cv::Point2d(-7.2, 5.1))};
    cv::fillPoly(hi, std::vector<std::vector<cv::Point>>{square}, cv::Scalar(255), cv::LINE_8, kShift);
    cv::Mat lo;
    downsample(hi, size).convertTo(lo, CV_64F);
    const cv::Moments m = cv::moments(lo);
    EXPECT_NEAR(m.m10 / m.m00, c.x, tol);
    EXPECT_NEAR(m.m01 / m.m00, c.y, tol);
    // The half-pixel growth adds about 5%; a wrong scale would be far off.
    EXPECT_NEAR(m.m00 / 255.0, 14.4 * 10.2, 0.08 * 14.4 * 10.2);
  }
}

TEST(StereoCalibrationRenderer, EveryBoardIsInsideBothImagesAndDetected) {
  const auto& s = synthetic();
  for (std::size_t i = 0; i < s.poses.size(); ++i) {
    SCOPED_TRACE("pose " + std::to_string(i));
    cv::Vec3d rr, tr;
    to_right(s.rig, s.poses[i], rr, tr);
    for (const auto& [cam, rvec, tvec] : {std::tuple{s.rig.left, s.poses[i].rvec, s.poses[i].tvec},
                                          std::tuple{s.rig.right, rr, tr}}) {
      for (const auto& p : true_corners(cam, rvec, tvec)) {
        EXPECT_GT(p.x, 40.0);
        EXPECT_LT(p.x, s.rig.size.width - 40.0);
        EXPECT_GT(p.y, 40.0);
        EXPECT_LT(p.y, s.rig.size.height - 40.0);
      }
    }
    EXPECT_TRUE(s.detections[i].usable());
  }
}

TEST(StereoCalibration, DetectedCornersMatchTheProjectionInOpenCvPixelConvention) {
  // cornerSubPix reports pixel centres at integers, as PinholeCamera does; a
  // half-pixel convention slip would show here as a 0.5 px mean offset.
  const auto& s = synthetic();
  double sum_dx = 0.0, sum_dy = 0.0, max_err = 0.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < s.poses.size(); ++i) {
    cv::Vec3d rr, tr;
    to_right(s.rig, s.poses[i], rr, tr);
    const auto tl = true_corners(s.rig.left, s.poses[i].rvec, s.poses[i].tvec);
    const auto trr = true_corners(s.rig.right, rr, tr);
    ASSERT_TRUE(s.detections[i].usable());
    for (const auto& [truth, found] :
         {std::pair{&tl, &s.detections[i].corners_left}, std::pair{&trr, &s.detections[i].corners_right}}) {
      ASSERT_EQ(truth->size(), found->size());
      for (std::size_t k = 0; k < truth->size(); ++k) {
        const double dx = (*found)[k].x - (*truth)[k].x, dy = (*found)[k].y - (*truth)[k].y;
        sum_dx += dx;
        sum_dy += dy;
        max_err = std::max(max_err, std::hypot(dx, dy));
        ++n;
      }
    }
  }
  std::printf("corner detection vs truth over %zu corners: mean offset (%.4f, %.4f) px, max %.3f px\n", n,
              sum_dx / n, sum_dy / n, max_err);
  EXPECT_LT(std::abs(sum_dx / n), 0.05);
  EXPECT_LT(std::abs(sum_dy / n), 0.05);
  EXPECT_LT(max_err, 0.5);  // also catches corners matched in the wrong order
}

// --- recovery of the truth -----------------------------------------------------------

TEST(StereoCalibration, RecoversIntrinsicsOfBothCameras) {
  const auto& s = synthetic();
  ASSERT_TRUE(s.calibration.ok()) << s.calibration.error().message;
  const auto& c = *s.calibration;
  EXPECT_EQ(c.image_size, s.rig.size);
  EXPECT_EQ(c.pairs.size(), s.poses.size());
  EXPECT_TRUE(c.skipped.empty());
  for (const auto& [name, got, want] : {std::tuple{"left", c.left, s.rig.left}, std::tuple{"right", c.right, s.rig.right}}) {
    SCOPED_TRACE(name);
    std::printf("%-5s fx %.3f (true %.1f, %.3f%%), fy %.3f (%.1f, %.3f%%), cx %.3f (%.1f, %.3f px), cy %.3f (%.1f, "
                "%.3f px); k1 %.4f (%.3f), k2 %.4f (%.3f)\n",
                name, got.fx(), want.K(0, 0), 100 * rel_err(got.fx(), want.K(0, 0)), got.fy(), want.K(1, 1),
                100 * rel_err(got.fy(), want.K(1, 1)), got.cx(), want.K(0, 2), got.cx() - want.K(0, 2), got.cy(),
                want.K(1, 2), got.cy() - want.K(1, 2), got.dist[0], want.dist[0], got.dist[1], want.dist[1]);
    EXPECT_LT(rel_err(got.fx(), want.K(0, 0)), 0.005);
    EXPECT_LT(rel_err(got.fy(), want.K(1, 1)), 0.005);
    EXPECT_LT(rel_err(got.cx(), want.K(0, 2)), 0.005);
    EXPECT_LT(rel_err(got.cy(), want.K(1, 2)), 0.005);
    EXPECT_NEAR(got.dist[0], want.dist[0], 0.01);
    EXPECT_NEAR(got.dist[1], want.dist[1], 0.03);
    EXPECT_EQ(got.dist[4], 0.0);  // k3 fixed by default
  }
}

TEST(StereoCalibration, RecoversBaselineAndRelativeRotation) {
  const auto& s = synthetic();
  ASSERT_TRUE(s.calibration.ok()) << s.calibration.error().message;
  const auto& c = *s.calibration;
  const double true_baseline = cv::norm(s.rig.c_right_in_left_m);
  cv::Vec3d r_err;
  cv::Rodrigues(c.R_rightcam_leftcam * s.rig.R_rightcam_leftcam.t(), r_err);
  std::printf("baseline %.4f mm (true %.4f mm, %.3f%%), rotation error %.4f deg\n", c.baseline_m() * 1e3,
              true_baseline * 1e3, 100 * rel_err(c.baseline_m(), true_baseline), cv::norm(r_err) * 180 / M_PI);
  EXPECT_LT(rel_err(c.baseline_m(), true_baseline), 0.01);
  EXPECT_LT(cv::norm(r_err), 0.1 * M_PI / 180.0);
}

TEST(StereoCalibration, ReprojectionErrorsAreSubpixelWithoutOutliers) {
  const auto& s = synthetic();
  ASSERT_TRUE(s.calibration.ok()) << s.calibration.error().message;
  const auto& c = *s.calibration;
  std::printf("RMS left %.4f px, right %.4f px, stereo %.4f px\n", c.left.rms_px, c.right.rms_px, c.rms_stereo_px);
  EXPECT_LT(c.left.rms_px, 0.5);
  EXPECT_LT(c.right.rms_px, 0.5);
  EXPECT_LT(c.rms_stereo_px, 0.5);
  EXPECT_GT(c.rms_stereo_px, 0.0);
  EXPECT_TRUE(c.outlier_names().empty());
  for (const auto& p : c.pairs) {
    EXPECT_LT(p.rms_left_px, 0.5) << p.name;
    EXPECT_LT(p.rms_right_px, 0.5) << p.name;
  }
  const std::string d = c.describe();
  EXPECT_TRUE(contains(d, "12 of 12 pairs")) << d;
  EXPECT_TRUE(contains(d, "no outlier pairs")) << d;
}

TEST(StereoCalibration, RectifiedCornersShareRows) {
  const auto& s = synthetic();
  ASSERT_TRUE(s.calibration.ok()) << s.calibration.error().message;
  const auto& c = *s.calibration;
  double worst_detected = 0.0, worst_true = 0.0, sum = 0.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < s.poses.size(); ++i) {
    const auto& d = s.detections[i];
    std::vector<cv::Point2d> l(d.corners_left.begin(), d.corners_left.end());
    std::vector<cv::Point2d> r(d.corners_right.begin(), d.corners_right.end());
    const auto rl = c.rectify_left_points(l), rr = c.rectify_right_points(r);
    ASSERT_EQ(rl.size(), rr.size());
    for (std::size_t k = 0; k < rl.size(); ++k) {
      worst_detected = std::max(worst_detected, std::abs(rl[k].y - rr[k].y));
      sum += std::abs(rl[k].y - rr[k].y);
      ++n;
      EXPECT_GT(rl[k].x - rr[k].x, 0.0) << "disparity must be positive for a right camera at +x";
    }
    // Noise-free projections of the true corners, too.
    cv::Vec3d rvr, tvr;
    to_right(s.rig, s.poses[i], rvr, tvr);
    const auto tl = c.rectify_left_points(true_corners(s.rig.left, s.poses[i].rvec, s.poses[i].tvec));
    const auto tr = c.rectify_right_points(true_corners(s.rig.right, rvr, tvr));
    for (std::size_t k = 0; k < tl.size(); ++k) worst_true = std::max(worst_true, std::abs(tl[k].y - tr[k].y));
  }
  std::printf("rectified row difference: detected corners mean %.4f px, max %.4f px; true corners max %.4f px\n",
              sum / n, worst_detected, worst_true);
  EXPECT_LT(worst_detected, 0.5);
  EXPECT_LT(worst_true, 0.5);
}

TEST(StereoCalibration, RectifiedRigTriangulatesTrueDepth) {
  // The rig written to the glove file (rectified fx, cx, cy, baseline, right
  // camera at +x) must triangulate a point where it is: Z = fx * b / disparity.
  const auto& s = synthetic();
  ASSERT_TRUE(s.calibration.ok()) << s.calibration.error().message;
  const auto& c = *s.calibration;
  const StereoRig rig = c.rectified_rig(30.0, StereoRig::zed_mini_like().T_head_leftcam);
  const PinholeCamera& k = rig.camera;
  Rng rng(mix_seed(20240604, 2));
  double worst = 0.0;
  for (int i = 0; i < 200; ++i) {
    // Inside both images (where the distortion model was fitted), at hand
    // distances.
    const double z = rng.uniform(0.3, 1.0);
    const cv::Vec3d p_left(z * rng.uniform(-0.7, 0.6), z * rng.uniform(-0.4, 0.4), z);
    std::vector<cv::Point2d> pl, pr;
    cv::projectPoints(std::vector<cv::Point3d>{cv::Point3d(p_left)}, cv::Vec3d(), cv::Vec3d(), s.rig.left.K,
                      s.rig.left.dist, pl);
    cv::Vec3d rvec;
    cv::Rodrigues(s.rig.R_rightcam_leftcam, rvec);
    cv::projectPoints(std::vector<cv::Point3d>{cv::Point3d(p_left)}, rvec, s.rig.t_rightcam_leftcam_m,
                      s.rig.right.K, s.rig.right.dist, pr);
    const auto ul = c.rectify_left_points(pl)[0], ur = c.rectify_right_points(pr)[0];
    const double depth = k.fx_px * rig.baseline_m / (ul.x - ur.x);
    const cv::Vec3d p_rect(depth * (ul.x - k.cx_px) / k.fx_px, depth * (ul.y - k.cy_px) / k.fy_px, depth);
    // The rectified left camera is the left camera turned by R_rectleft_leftcam.
    const cv::Vec3d want = c.R_rectleft_leftcam * p_left;
    worst = std::max(worst, cv::norm(p_rect - want) / cv::norm(want));
  }
  std::printf("triangulation with the calibrated rig: worst error %.3f%% of distance\n", 100 * worst);
  EXPECT_LT(worst, 0.01);
}

TEST(StereoCalibration, RectifiedCameraMatchesRectificationOfTheTruth) {
  const auto& s = synthetic();
  ASSERT_TRUE(s.calibration.ok()) << s.calibration.error().message;
  const auto& c = *s.calibration;
  cv::Mat R1, R2, P1, P2, Q;
  cv::stereoRectify(s.rig.left.K, s.rig.left.dist, s.rig.right.K, s.rig.right.dist, s.rig.size,
                    s.rig.R_rightcam_leftcam, s.rig.t_rightcam_leftcam_m, R1, R2, P1, P2, Q, cv::CALIB_ZERO_DISPARITY,
                    s.options.alpha, s.rig.size);
  const PinholeCamera k = c.rectified_camera();
  std::printf("rectified: fx %.3f (truth's %.3f), cx %.3f (%.3f), cy %.3f (%.3f)\n", k.fx_px, P1.at<double>(0, 0),
              k.cx_px, P1.at<double>(0, 2), k.cy_px, P1.at<double>(1, 2));
  EXPECT_LT(rel_err(k.fx_px, P1.at<double>(0, 0)), 0.005);
  EXPECT_LT(rel_err(k.fy_px, P1.at<double>(1, 1)), 0.005);
  EXPECT_LT(rel_err(k.cx_px, P1.at<double>(0, 2)), 0.005);
  EXPECT_LT(rel_err(k.cy_px, P1.at<double>(1, 2)), 0.005);
  EXPECT_EQ(k.width_px, 1280);
  EXPECT_EQ(k.height_px, 720);
  const StereoRig rig = c.rectified_rig(60.0, Pose{});
  EXPECT_LT(rel_err(rig.baseline_m, cv::norm(s.rig.c_right_in_left_m)), 0.01);
  EXPECT_EQ(rig.rate_hz, 60.0);
}

TEST(StereoCalibration, RectifierMapsImagesAsThePointsAre) {
  const auto& s = synthetic();
  ASSERT_TRUE(s.calibration.ok()) << s.calibration.error().message;
  auto rect = StereoRectifier::create(*s.calibration);
  ASSERT_TRUE(rect.ok()) << rect.error().message;
  cv::Mat l, r;
  ASSERT_TRUE(rect->rectify(s.left[0], s.right[0], l, r).ok());
  std::vector<cv::Point2f> cl, cr;
  ASSERT_TRUE(detect_board(l, test_board(), cl));
  ASSERT_TRUE(detect_board(r, test_board(), cr));
  const auto& d = s.detections[0];
  const auto want = s.calibration->rectify_left_points(
      std::vector<cv::Point2d>(d.corners_left.begin(), d.corners_left.end()));
  double worst_row = 0.0, worst_pos = 0.0;
  for (std::size_t k = 0; k < cl.size(); ++k) {
    worst_row = std::max(worst_row, static_cast<double>(std::abs(cl[k].y - cr[k].y)));
    worst_pos = std::max(worst_pos, cv::norm(cv::Point2d(cl[k]) - want[k]));
  }
  EXPECT_LT(worst_row, 0.5);
  EXPECT_LT(worst_pos, 0.3);
  cv::Mat small(100, 100, CV_8U);
  auto st = rect->rectify(small, small, l, r);
  ASSERT_FALSE(st.ok());
  EXPECT_TRUE(contains(st.error().message, "100x100")) << st.error().message;
}

TEST(StereoCalibration, FlagsAPairWhoseBoardMovedBetweenTheShots) {
  const auto& s = synthetic();
  auto dets = s.detections;
  // The right image of pair 4 was taken after the board moved by 5 mm and
  // turned by a degree: consistent in itself, not with the left image.
  const BoardPose& p = s.poses[4];
  cv::Matx33d R, dR;
  cv::Rodrigues(p.rvec, R);
  cv::Rodrigues(cv::Vec3d(0.0, 1.0 * M_PI / 180.0, 0.0), dR);
  cv::Vec3d moved_rvec, rr, tr;
  cv::Rodrigues(dR * R, moved_rvec);
  to_right(s.rig, BoardPose{moved_rvec, p.tvec + cv::Vec3d(0.005, 0.0, 0.0)}, rr, tr);
  const auto moved = true_corners(s.rig.right, rr, tr);
  dets[4].corners_right.assign(moved.begin(), moved.end());
  auto cal = calibrate_stereo(dets, s.options);
  ASSERT_TRUE(cal.ok()) << cal.error().message;
  EXPECT_EQ(cal->outlier_names(), std::vector<std::string>{"pair_4"}) << cal->describe();
  EXPECT_TRUE(contains(cal->describe(), "pair_4")) << cal->describe();
}

TEST(StereoCalibration, PutsRightCornersCountedBackwardsInTheLeftOrder) {
  const auto& d = synthetic().detections[1];
  auto backwards = d.corners_right;
  std::reverse(backwards.begin(), backwards.end());
  match_corner_order(d.corners_left, backwards);
  EXPECT_EQ(backwards, d.corners_right);
  auto same = d.corners_right;
  match_corner_order(d.corners_left, same);
  EXPECT_EQ(same, d.corners_right);
}

// --- save, load, glove file ------------------------------------------------------

TEST(StereoCalibration, SavesAndLoadsEverything) {
  const auto& s = synthetic();
  ASSERT_TRUE(s.calibration.ok()) << s.calibration.error().message;
  const auto& c = *s.calibration;
  TempDir dir;
  for (const std::string name : {"calib.yaml", "calib.json"}) {
    SCOPED_TRACE(name);
    ASSERT_TRUE(c.save(dir / name).ok());
    auto back = StereoCalibration::load(dir / name);
    ASSERT_TRUE(back.ok()) << back.error().message;
    EXPECT_EQ(back->image_size, c.image_size);
    EXPECT_EQ(back->board.inner_cols, 9);
    EXPECT_EQ(back->board.inner_rows, 6);
    EXPECT_DOUBLE_EQ(back->board.square_m, 0.03);
    EXPECT_LT(cv::norm(cv::Mat(back->left.K), cv::Mat(c.left.K)), 1e-9);
    EXPECT_LT(cv::norm(cv::Mat(back->right.dist), cv::Mat(c.right.dist)), 1e-12);
    EXPECT_LT(cv::norm(cv::Mat(back->P_right), cv::Mat(c.P_right)), 1e-9);
    EXPECT_LT(cv::norm(cv::Mat(back->R_rectleft_leftcam), cv::Mat(c.R_rectleft_leftcam)), 1e-12);
    EXPECT_LT(cv::norm(cv::Mat(back->t_rightcam_leftcam_m), cv::Mat(c.t_rightcam_leftcam_m)), 1e-12);
    EXPECT_LT(cv::norm(cv::Mat(back->Q), cv::Mat(c.Q)), 1e-9);
    EXPECT_EQ(back->valid_roi_left, c.valid_roi_left);
    EXPECT_NEAR(back->rms_stereo_px, c.rms_stereo_px, 1e-12);
    EXPECT_NEAR(back->left.intrinsics_sigma_px[2], c.left.intrinsics_sigma_px[2], 1e-12);
    ASSERT_EQ(back->pairs.size(), c.pairs.size());
    EXPECT_EQ(back->pairs[3].name, c.pairs[3].name);
    EXPECT_NEAR(back->pairs[3].rms_right_px, c.pairs[3].rms_right_px, 1e-12);
    const StereoRig a = c.rectified_rig(30, Pose{}), b = back->rectified_rig(30, Pose{});
    EXPECT_NEAR(a.camera.fx_px, b.camera.fx_px, 1e-9);
    EXPECT_NEAR(a.baseline_m, b.baseline_m, 1e-12);
  }
}

TEST(StereoCalibration, LoadSaysWhatIsWrong) {
  TempDir dir;
  auto missing = StereoCalibration::load(dir / "nope.yaml");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, Errc::not_found);
  EXPECT_TRUE(contains(missing.error().message, "proprio calibrate stereo")) << missing.error().message;

  auto other = StereoCalibration::load(dir.write("other.yaml", "%YAML:1.0\n---\nfoo: 1\n"));
  ASSERT_FALSE(other.ok());
  EXPECT_EQ(other.error().code, Errc::parse_error);
  EXPECT_TRUE(contains(other.error().message, "not a proprio stereo calibration")) << other.error().message;

  // A real file with one key removed names that key.
  ASSERT_TRUE(synthetic().calibration.ok());
  ASSERT_TRUE(synthetic().calibration->save(dir / "full.yaml").ok());
  std::ifstream in(dir / "full.yaml");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto at = text.find("P_right:");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, 8, "P_rite:");
  auto broken = StereoCalibration::load(dir.write("broken.yaml", text));
  ASSERT_FALSE(broken.ok());
  EXPECT_TRUE(contains(broken.error().message, "'P_right' is missing")) << broken.error().message;

  auto garbage = StereoCalibration::load(dir.write("garbage.yaml", "%YAML:1.0\n---\n[[[: {\n"));
  ASSERT_FALSE(garbage.ok());
  EXPECT_EQ(garbage.error().code, Errc::parse_error);
}

TEST(StereoCalibration, RigTomlSnippetParsesAsTheGloveFileRig) {
  const auto& s = synthetic();
  ASSERT_TRUE(s.calibration.ok()) << s.calibration.error().message;
  const Pose mount = StereoRig::zed_mini_like().T_head_leftcam;
  const StereoRig rig = s.calibration->rectified_rig(60.0, mount);
  const std::string snippet = rig_toml_snippet(rig);
  EXPECT_EQ(snippet.rfind("[rig]\n", 0), 0u) << snippet;
  EXPECT_TRUE(contains(snippet, "fx_px = ")) << snippet;
  EXPECT_TRUE(contains(snippet, "left_camera_tilt_down_deg = 25")) << snippet;
  // Put it in place of the default glove's [rig] table.
  const std::string glove = ImuGloveDescription::vist_default().to_toml();
  const auto at = glove.find("\n[rig]\n");
  ASSERT_NE(at, std::string::npos);
  auto parsed = ImuGloveDescription::parse(glove.substr(0, at + 1) + snippet, "calibrated.toml");
  ASSERT_TRUE(parsed.ok()) << parsed.error().message << "\n" << snippet;
  const StereoRig& got = parsed->rig;
  EXPECT_EQ(got.camera.width_px, 1280);
  EXPECT_EQ(got.camera.height_px, 720);
  EXPECT_NEAR(got.camera.fx_px, rig.camera.fx_px, 5e-4);
  EXPECT_NEAR(got.camera.fy_px, rig.camera.fy_px, 5e-4);
  EXPECT_NEAR(got.camera.cx_px, rig.camera.cx_px, 5e-4);
  EXPECT_NEAR(got.camera.cy_px, rig.camera.cy_px, 5e-4);
  EXPECT_NEAR(got.baseline_m, rig.baseline_m, 5e-7);
  EXPECT_EQ(got.rate_hz, 60.0);
  EXPECT_LT((got.T_head_leftcam.p - mount.p).norm(), 1e-12);
  EXPECT_LT(angle_between(got.T_head_leftcam.q, mount.q), 1e-9);
}

// --- errors that say what to do --------------------------------------------------

TEST(StereoCalibrationErrors, TooFewOrNoBoards) {
  const auto& s = synthetic();
  std::vector<BoardDetection> few(s.detections.begin(), s.detections.begin() + 3);
  auto r = calibrate_stereo(few, s.options);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error().message, "only 3 of 3 image pairs")) << r.error().message;
  EXPECT_TRUE(contains(r.error().message, "at least 6")) << r.error().message;

  cv::Mat blank(720, 1280, CV_8U, cv::Scalar(128));
  std::vector<BoardDetection> none = {detect_board_pair(blank, blank, test_board(), "blank_0"),
                                      detect_board_pair(blank, blank, test_board(), "blank_1")};
  r = calibrate_stereo(none, s.options);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::not_found);
  EXPECT_TRUE(contains(r.error().message, "INNER corners")) << r.error().message;

  // The board seen by one camera only says so.
  std::vector<BoardDetection> one_sided = {detect_board_pair(s.left[0], blank, test_board(), "half")};
  r = calibrate_stereo(one_sided, s.options);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error().message, "only the left image of 1")) << r.error().message;

  // The wrong corner count (squares instead of inner corners) finds nothing,
  // and quickly (OpenCV's adaptive-threshold search took minutes here).
  auto wrong = test_board();
  wrong.inner_cols = 10;
  wrong.inner_rows = 7;
  std::vector<cv::Point2f> corners;
  EXPECT_FALSE(detect_board(s.left[0], wrong, corners));
}

TEST(StereoCalibrationErrors, InconsistentSizesAndSwappedCameras) {
  const auto& s = synthetic();
  auto dets = s.detections;
  dets[5].image_size = cv::Size(640, 480);
  auto r = calibrate_stereo(dets, s.options);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error().message, "inconsistent image sizes")) << r.error().message;
  EXPECT_TRUE(contains(r.error().message, "pair_5")) << r.error().message;

  cv::Mat small(480, 640, CV_8U, cv::Scalar(128));
  dets = s.detections;
  dets.push_back(detect_board_pair(s.left[0], small, test_board(), "odd_pair"));
  r = calibrate_stereo(dets, s.options);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error().message, "odd_pair")) << r.error().message;

  dets = s.detections;
  for (auto& d : dets) std::swap(d.corners_left, d.corners_right);
  r = calibrate_stereo(dets, s.options);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error().message, "swapped")) << r.error().message;
}

TEST(StereoCalibrationErrors, BoardAndOptions) {
  EXPECT_TRUE(CheckerboardSpec::parse("9x6", 25.0).ok());
  auto b = CheckerboardSpec::parse("9x6", 25.0);
  EXPECT_DOUBLE_EQ(b->square_m, 0.025);
  for (const char* bad : {"9by6", "9x", "x6", "9x6x2", ""}) {
    auto r = CheckerboardSpec::parse(bad, 25.0);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_EQ(r.error().code, Errc::parse_error) << bad;
  }
  auto square = CheckerboardSpec::parse("7x7", 25.0);
  ASSERT_FALSE(square.ok());
  EXPECT_TRUE(contains(square.error().message, "must differ")) << square.error().message;
  auto tiny = CheckerboardSpec::parse("9x6", 0.0);
  ASSERT_FALSE(tiny.ok());
  auto one = CheckerboardSpec::parse("1x6", 25.0);
  ASSERT_FALSE(one.ok());
  EXPECT_TRUE(contains(one.error().message, "10x7 squares has 9x6")) << one.error().message;

  StereoCalibrationOptions o;
  o.alpha = 1.5;
  EXPECT_FALSE(o.validate().ok());
  o.alpha = 0.0;
  o.min_pairs = 2;
  EXPECT_FALSE(o.validate().ok());
  o.min_pairs = 6;
  EXPECT_TRUE(o.validate().ok());
  EXPECT_TRUE(contains(o.describe(), "9x6 inner corners")) << o.describe();
  EXPECT_FALSE(calibrate_stereo({}, o).ok());
}

// --- folders ---------------------------------------------------------------------

TEST(StereoCalibrationFolder, PairsFilesByName) {
  TempDir dir;
  cv::Mat img(8, 8, CV_8U, cv::Scalar(0));
  for (const char* n : {"left_000.png", "right_000.png", "Left-1.png", "Right-1.png", "cam_LEFT_2.jpg",
                        "cam_RIGHT_2.jpg"}) {
    ASSERT_TRUE(cv::imwrite((dir / n).string(), img));
  }
  dir.write("notes.txt", "not an image");
  auto pairs = find_calibration_images(dir.path(), false);
  ASSERT_TRUE(pairs.ok()) << pairs.error().message;
  ASSERT_EQ(pairs->size(), 3u);
  for (const auto& p : *pairs) {
    EXPECT_TRUE(std::filesystem::exists(p.left));
    EXPECT_TRUE(std::filesystem::exists(p.right));
    EXPECT_NE(p.left, p.right);
  }

  // A left without its right.
  ASSERT_TRUE(cv::imwrite((dir / "left_003.png").string(), img));
  auto lonely = find_calibration_images(dir.path(), false);
  ASSERT_FALSE(lonely.ok());
  EXPECT_TRUE(contains(lonely.error().message, "left_003.png (expected right_003.png)")) << lonely.error().message;
  std::filesystem::remove(dir / "left_003.png");

  // An image that belongs to neither side.
  ASSERT_TRUE(cv::imwrite((dir / "board.png").string(), img));
  auto stray = find_calibration_images(dir.path(), false);
  ASSERT_FALSE(stray.ok());
  EXPECT_TRUE(contains(stray.error().message, "neither 'left' nor 'right'")) << stray.error().message;

  // Side by side takes every image.
  auto sbs = find_calibration_images(dir.path(), true);
  ASSERT_TRUE(sbs.ok());
  EXPECT_EQ(sbs->size(), 7u);
}

TEST(StereoCalibrationFolder, SubfoldersAndErrors) {
  TempDir dir;
  auto empty = find_calibration_images(dir.path(), false);
  ASSERT_FALSE(empty.ok());
  EXPECT_EQ(empty.error().code, Errc::not_found);
  EXPECT_TRUE(contains(empty.error().message, "no images")) << empty.error().message;
  auto gone = find_calibration_images(dir / "missing", true);
  ASSERT_FALSE(gone.ok());
  EXPECT_TRUE(contains(gone.error().message, "does not exist")) << gone.error().message;
  auto folder_empty = calibrate_stereo_folder(dir.path(), true, StereoCalibrationOptions{});
  ASSERT_FALSE(folder_empty.ok());

  std::filesystem::create_directories(dir / "left");
  std::filesystem::create_directories(dir / "right");
  cv::Mat img(8, 8, CV_8U, cv::Scalar(0));
  ASSERT_TRUE(cv::imwrite((dir / "left" / "a.png").string(), img));
  ASSERT_TRUE(cv::imwrite((dir / "right" / "a.png").string(), img));
  ASSERT_TRUE(cv::imwrite((dir / "right" / "b.png").string(), img));
  auto r = find_calibration_images(dir.path(), false);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error().message, "right/b.png")) << r.error().message;
  std::filesystem::remove(dir / "right" / "b.png");
  r = find_calibration_images(dir.path(), false);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_EQ(r->size(), 1u);
  EXPECT_EQ((*r)[0].right, dir / "right" / "a.png");

  // Different sizes in one pair, an odd side-by-side width, a damaged file.
  ASSERT_TRUE(cv::imwrite((dir / "right" / "a.png").string(), cv::Mat(8, 6, CV_8U, cv::Scalar(0))));
  auto d = detect_board_in_files((*r)[0], test_board());
  ASSERT_FALSE(d.ok());
  EXPECT_TRUE(contains(d.error().message, "8x8")) << d.error().message;
  ASSERT_TRUE(cv::imwrite((dir / "odd.png").string(), cv::Mat(8, 7, CV_8U, cv::Scalar(0))));
  d = detect_board_in_files({"odd.png", dir / "odd.png", {}}, test_board());
  ASSERT_FALSE(d.ok());
  EXPECT_TRUE(contains(d.error().message, "odd width")) << d.error().message;
  dir.write("bad.png", "this is not a png");
  d = detect_board_in_files({"bad.png", dir / "bad.png", {}}, test_board());
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.error().code, Errc::io_error);
}

TEST(StereoCalibrationFolder, CalibratesSideBySideImagesOnDisk) {
  // The CLI's path: side-by-side PNGs in a folder, progress per image.
  const auto& s = synthetic();
  TempDir dir;
  for (std::size_t i = 0; i < s.left.size(); ++i) {
    cv::Mat sbs;
    cv::hconcat(s.left[i], s.right[i], sbs);
    char name[32];
    std::snprintf(name, sizeof name, "board_%02zu.png", i);
    ASSERT_TRUE(cv::imwrite((dir / name).string(), sbs, {cv::IMWRITE_PNG_COMPRESSION, 1}));
  }
  // One image in another mode stops the run and names both images.
  std::vector<std::string> seen;
  auto progress = [&](std::size_t i, std::size_t n, const BoardDetection& d) {
    EXPECT_EQ(n, s.left.size());
    EXPECT_EQ(i, seen.size());
    seen.push_back(d.name);
  };
  auto cal = calibrate_stereo_folder(dir.path(), true, s.options, progress);
  ASSERT_TRUE(cal.ok()) << cal.error().message;
  EXPECT_EQ(seen.size(), s.left.size());
  EXPECT_EQ(seen.front(), "board_00.png");
  EXPECT_EQ(cal->pairs.size(), s.left.size());
  EXPECT_LT(rel_err(cal->left.fx(), s.rig.left.K(0, 0)), 0.005);
  EXPECT_LT(rel_err(cal->baseline_m(), cv::norm(s.rig.c_right_in_left_m)), 0.01);

  ASSERT_TRUE(cv::imwrite((dir / "board_99.png").string(), cv::Mat(480, 1280, CV_8U, cv::Scalar(128))));
  auto mixed = calibrate_stereo_folder(dir.path(), true, s.options);
  ASSERT_FALSE(mixed.ok());
  EXPECT_TRUE(contains(mixed.error().message, "board_99.png")) << mixed.error().message;
  EXPECT_TRUE(contains(mixed.error().message, "inconsistent image sizes")) << mixed.error().message;
}
