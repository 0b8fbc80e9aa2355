#include "proprio/vist/stereo_calibration.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <map>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <sstream>
#include <system_error>
#include <utility>

#include "proprio/core/file_io.hpp"

namespace proprio::vist {

namespace {

std::string fmt_num(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

std::string size_text(const cv::Size& s) { return std::to_string(s.width) + "x" + std::to_string(s.height); }

// At most a few names, then a count: error messages must stay readable with
// hundreds of images.
std::string name_list(const std::vector<std::string>& names, std::size_t max_shown = 5) {
  std::string out;
  for (std::size_t i = 0; i < names.size() && i < max_shown; ++i) out += (i ? ", " : "") + names[i];
  if (names.size() > max_shown) out += " and " + std::to_string(names.size() - max_shown) + " more";
  return out;
}

cv::Mat to_grey(const cv::Mat& image) {
  cv::Mat grey;
  if (image.channels() == 3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else if (image.channels() == 4) {
    cv::cvtColor(image, grey, cv::COLOR_BGRA2GRAY);
  } else {
    grey = image;
  }
  if (grey.depth() != CV_8U) {
    double lo = 0.0, hi = 0.0;
    cv::minMaxLoc(grey, &lo, &hi);
    cv::Mat g8;
    grey.convertTo(g8, CV_8U, hi > lo ? 255.0 / (hi - lo) : 1.0, hi > lo ? -lo * 255.0 / (hi - lo) : 0.0);
    grey = g8;
  }
  return grey;
}

bool finite_all(const cv::Mat& m) { return cv::checkRange(m, true, nullptr, -1e12, 1e12); }

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  double m = *mid;
  if (v.size() % 2 == 0) m = 0.5 * (m + *std::max_element(v.begin(), mid));
  return m;
}

bool is_image_file(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  static const std::set<std::string> kExt = {".png", ".jpg",  ".jpeg", ".bmp", ".tif",
                                             ".tiff", ".pgm", ".ppm",  ".pnm", ".webp"};
  return kExt.count(ext) != 0;
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// "left" in the case it was written in -> "right" in the same case.
std::string right_word_for(std::string_view left_word) {
  if (left_word == "LEFT") return "RIGHT";
  if (left_word == "Left") return "Right";
  return "right";
}

}  // namespace

// --- board -----------------------------------------------------------------

Status CheckerboardSpec::validate() const {
  if (inner_cols < 2 || inner_rows < 2) {
    return make_error(Errc::invalid_argument,
                      "checkerboard " + std::to_string(inner_cols) + "x" + std::to_string(inner_rows) +
                          ": needs at least 2x2 inner corners (count where four squares meet: a board of 10x7 "
                          "squares has 9x6)");
  }
  if (inner_cols == inner_rows) {
    // A square corner grid looks the same turned by 90 degrees, so the left
    // and right detections could be numbered in different orders.
    return make_error(Errc::invalid_argument,
                      "checkerboard " + std::to_string(inner_cols) + "x" + std::to_string(inner_rows) +
                          ": the numbers of inner corners across and down must differ (e.g. 9x6) so the board's "
                          "orientation is unambiguous; print a board with one more or one fewer column");
  }
  if (!(square_m > 0.0) || !(square_m < 1.0)) {
    return make_error(Errc::out_of_range, "checkerboard square size " + fmt_num("%g", square_m * 1e3) +
                                              " mm is not a plausible printed square (0-1000 mm); measure one "
                                              "square of the printed board with a ruler");
  }
  return Status::success();
}

std::string CheckerboardSpec::describe() const {
  return std::to_string(inner_cols) + "x" + std::to_string(inner_rows) + " inner corners, " +
         fmt_num("%.2f", square_m * 1e3) + " mm squares";
}

Result<CheckerboardSpec> CheckerboardSpec::parse(std::string_view cols_x_rows, double square_mm) {
  const std::string text(cols_x_rows);
  int cols = 0, rows = 0;
  char x = 0, extra = 0;
  if (std::sscanf(text.c_str(), "%d%c%d%c", &cols, &x, &rows, &extra) != 3 || (x != 'x' && x != 'X')) {
    return make_error(Errc::parse_error, "board '" + text +
                                             "' is not COLSxROWS; give the inner corners across and down, e.g. "
                                             "9x6 for a board of 10x7 squares");
  }
  CheckerboardSpec b;
  b.inner_cols = cols;
  b.inner_rows = rows;
  b.square_m = square_mm / 1000.0;
  if (auto s = b.validate(); !s) return s.error();
  return b;
}

std::vector<cv::Point3f> CheckerboardSpec::object_points() const {
  std::vector<cv::Point3f> pts;
  pts.reserve(static_cast<std::size_t>(inner_cols * inner_rows));
  for (int r = 0; r < inner_rows; ++r) {
    for (int c = 0; c < inner_cols; ++c) {
      pts.emplace_back(static_cast<float>(c * square_m), static_cast<float>(r * square_m), 0.0f);
    }
  }
  return pts;
}

bool detect_board(const cv::Mat& image, const CheckerboardSpec& board, std::vector<cv::Point2f>& corners) {
  corners.clear();
  if (image.empty()) return false;
  const cv::Mat grey = to_grey(image);
  // Not CALIB_CB_ADAPTIVE_THRESH: in OpenCV 4.6 it makes a board with more or
  // fewer corners than asked for (a wrong --board) take a minute or more per
  // image. One global threshold finds clean boards in milliseconds; the
  // sector-based detector, whose time is bounded (under a second at 720p),
  // covers the uneven lighting adaptive thresholds were for.
  const bool found =
      cv::findChessboardCorners(grey, board.pattern_size(), corners,
                                cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK) ||
      cv::findChessboardCornersSB(grey, board.pattern_size(), corners, cv::CALIB_CB_NORMALIZE_IMAGE);
  if (!found || corners.size() != static_cast<std::size_t>(board.inner_cols * board.inner_rows)) return false;

  // cornerSubPix's window must not reach the neighbouring corners (their
  // edges would pull the estimate), so size it from the closest spacing.
  double spacing = 1e9;
  for (int r = 0; r < board.inner_rows; ++r) {
    for (int c = 0; c < board.inner_cols; ++c) {
      const auto& p = corners[static_cast<std::size_t>(r * board.inner_cols + c)];
      if (c + 1 < board.inner_cols) {
        spacing = std::min(spacing, cv::norm(p - corners[static_cast<std::size_t>(r * board.inner_cols + c + 1)]));
      }
      if (r + 1 < board.inner_rows) {
        spacing =
            std::min(spacing, cv::norm(p - corners[static_cast<std::size_t>((r + 1) * board.inner_cols + c)]));
      }
    }
  }
  const int half = std::clamp(static_cast<int>(0.4 * spacing), 2, 11);
  cv::cornerSubPix(grey, corners, cv::Size(half, half), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  return true;
}

BoardDetection detect_board_pair(const cv::Mat& left, const cv::Mat& right, const CheckerboardSpec& board,
                                 std::string name) {
  BoardDetection d;
  d.name = std::move(name);
  if (left.size() != right.size()) return d;  // image_size stays empty: calibrate_stereo names the pair
  d.image_size = left.size();
  d.found_left = detect_board(left, board, d.corners_left);
  d.found_right = detect_board(right, board, d.corners_right);
  if (d.usable()) match_corner_order(d.corners_left, d.corners_right);
  return d;
}

void match_corner_order(const std::vector<cv::Point2f>& left, std::vector<cv::Point2f>& right) {
  if (left.size() < 2 || right.size() != left.size()) return;
  // The two cameras look the same way, so the first-to-last direction agrees
  // in both images unless one was counted backwards.
  const cv::Point2f dl = left.back() - left.front();
  const cv::Point2f dr = right.back() - right.front();
  if (dl.dot(dr) < 0.0f) std::reverse(right.begin(), right.end());
}

// --- options ---------------------------------------------------------------

Status StereoCalibrationOptions::validate() const {
  if (auto s = board.validate(); !s) return s;
  if (!(alpha >= 0.0 && alpha <= 1.0)) {
    return make_error(Errc::out_of_range, "rectification alpha " + fmt_num("%g", alpha) +
                                              " is outside [0, 1] (0: only valid pixels, 1: all source pixels)");
  }
  if (min_pairs < 3) {
    return make_error(Errc::out_of_range, "min_pairs " + std::to_string(min_pairs) +
                                              " is below 3, the least calibrateCamera can solve");
  }
  if (!(outlier_factor > 1.0) || !(outlier_min_px >= 0.0)) {
    return make_error(Errc::out_of_range, "outlier_factor must exceed 1 and outlier_min_px must be >= 0");
  }
  return Status::success();
}

std::string StereoCalibrationOptions::describe() const {
  std::string s = "board " + board.describe() + ", alpha " + fmt_num("%g", alpha) + ", distortion k1 k2";
  if (!fix_tangential) s += " p1 p2";
  if (!fix_k3) s += " k3";
  s += ", at least " + std::to_string(min_pairs) + " pairs, outliers above " + fmt_num("%g", outlier_factor) +
       "x median and " + fmt_num("%g", outlier_min_px) + " px";
  return s;
}

// --- calibration ------------------------------------------------------------

double StereoCalibration::baseline_m() const { return cv::norm(t_rightcam_leftcam_m); }

PinholeCamera StereoCalibration::rectified_camera() const {
  PinholeCamera c;
  c.width_px = image_size.width;
  c.height_px = image_size.height;
  c.fx_px = P_left(0, 0);
  c.fy_px = P_left(1, 1);
  c.cx_px = P_left(0, 2);
  c.cy_px = P_left(1, 2);
  return c;
}

StereoRig StereoCalibration::rectified_rig(double rate_hz, const Pose& T_head_leftcam) const {
  StereoRig rig;
  rig.camera = rectified_camera();
  // P_right = [f 0 cx -f*b; ...]: the baseline the rectified images imply.
  rig.baseline_m = P_right(0, 0) != 0.0 ? -P_right(0, 3) / P_right(0, 0) : baseline_m();
  rig.rate_hz = rate_hz;
  rig.T_head_leftcam = T_head_leftcam;
  return rig;
}

std::vector<std::string> StereoCalibration::outlier_names() const {
  std::vector<std::string> out;
  for (const auto& p : pairs) {
    if (p.outlier) out.push_back(p.name);
  }
  return out;
}

std::string StereoCalibration::describe() const {
  std::ostringstream s;
  const std::size_t total = pairs.size() + skipped.size();
  s << "stereo calibration: " << size_text(image_size) << " px per camera, board " << board.describe() << "; "
    << pairs.size() << " of " << total << " pairs used";
  if (!skipped.empty()) s << " (board not seen in both: " << name_list(skipped) << ")";
  s << "\n";
  s << "RMS reprojection error: left " << fmt_num("%.3f", left.rms_px) << " px, right " << fmt_num("%.3f", right.rms_px)
    << " px (each camera alone), stereo " << fmt_num("%.3f", rms_stereo_px) << " px\n";
  auto cam = [&](const char* label, const CameraCalibration& c) {
    const auto& sd = c.intrinsics_sigma_px;
    s << label << " fx " << fmt_num("%.2f", c.fx()) << " ± " << fmt_num("%.2f", sd[0]) << ", fy " << fmt_num("%.2f", c.fy())
      << " ± " << fmt_num("%.2f", sd[1]) << ", cx " << fmt_num("%.2f", c.cx()) << " ± " << fmt_num("%.2f", sd[2]) << ", cy "
      << fmt_num("%.2f", c.cy()) << " ± " << fmt_num("%.2f", sd[3]) << " px; k1 " << fmt_num("%.4f", c.dist[0]) << ", k2 "
      << fmt_num("%.4f", c.dist[1]) << ", p1 " << fmt_num("%.5f", c.dist[2]) << ", p2 " << fmt_num("%.5f", c.dist[3])
      << ", k3 " << fmt_num("%.4f", c.dist[4]) << "\n";
  };
  cam("left: ", left);
  cam("right:", right);
  const cv::Matx33d Rt = R_rightcam_leftcam.t();
  const cv::Vec3d c_right_in_left = -(Rt * t_rightcam_leftcam_m);
  cv::Vec3d rvec;
  cv::Rodrigues(R_rightcam_leftcam, rvec);
  s << "right camera in the left camera frame: (" << fmt_num("%.2f", c_right_in_left[0] * 1e3) << ", "
    << fmt_num("%.2f", c_right_in_left[1] * 1e3) << ", " << fmt_num("%.2f", c_right_in_left[2] * 1e3)
    << ") mm, rotated " << fmt_num("%.3f", cv::norm(rvec) * 180.0 / M_PI) << " deg; baseline "
    << fmt_num("%.3f", baseline_m() * 1e3) << " mm\n";
  const PinholeCamera rc = rectified_camera();
  s << "rectified (alpha " << fmt_num("%g", alpha) << "): fx " << fmt_num("%.3f", rc.fx_px) << ", fy "
    << fmt_num("%.3f", rc.fy_px) << ", cx " << fmt_num("%.3f", rc.cx_px) << ", cy " << fmt_num("%.3f", rc.cy_px) << " px ("
    << fmt_num("%.1f", rc.hfov_rad() * 180.0 / M_PI) << " x " << fmt_num("%.1f", rc.vfov_rad() * 180.0 / M_PI)
    << " deg); valid pixels left " << valid_roi_left.width << "x" << valid_roi_left.height << " at ("
    << valid_roi_left.x << ", " << valid_roi_left.y << "), right " << valid_roi_right.width << "x"
    << valid_roi_right.height << " at (" << valid_roi_right.x << ", " << valid_roi_right.y << ")\n";
  const auto outliers = outlier_names();
  if (outliers.empty()) {
    s << "no outlier pairs";
  } else {
    s << "outlier pairs (reprojection error far above the others; check them for blur or a moved board, remove "
         "them and calibrate again):";
    for (const auto& p : pairs) {
      if (p.outlier) {
        s << "\n  " << p.name << ": left " << fmt_num("%.3f", p.rms_left_px) << " px, right "
          << fmt_num("%.3f", p.rms_right_px) << " px";
      }
    }
  }
  return s.str();
}

namespace {

std::vector<cv::Point2d> rectify_points(const std::vector<cv::Point2d>& raw, const CameraCalibration& cam,
                                        const cv::Matx33d& R, const cv::Matx34d& P) {
  if (raw.empty()) return {};
  std::vector<cv::Point2d> out;
  cv::undistortPoints(raw, out, cam.K, cam.dist, R, P);
  return out;
}

}  // namespace

std::vector<cv::Point2d> StereoCalibration::rectify_left_points(const std::vector<cv::Point2d>& raw_px) const {
  return rectify_points(raw_px, left, R_rectleft_leftcam, P_left);
}

std::vector<cv::Point2d> StereoCalibration::rectify_right_points(const std::vector<cv::Point2d>& raw_px) const {
  return rectify_points(raw_px, right, R_rectright_rightcam, P_right);
}

Result<StereoCalibration> calibrate_stereo(const std::vector<BoardDetection>& detections,
                                           const StereoCalibrationOptions& options) {
  if (auto s = options.validate(); !s) return s.error();
  if (detections.empty()) {
    return make_error(Errc::not_found, "no image pairs to calibrate from; take 15-25 pairs of the board at "
                                       "different distances and tilts, see docs/stereo-camera.md");
  }
  const cv::Size size = detections.front().image_size;
  for (const auto& d : detections) {
    if (d.image_size.width <= 0 || d.image_size.height <= 0) {
      return make_error(Errc::invalid_argument, "image pair '" + d.name +
                                                    "' is empty or its left and right images differ in size; "
                                                    "both cameras must run in the same mode");
    }
    if (d.image_size != size) {
      return make_error(Errc::invalid_argument,
                        "inconsistent image sizes: '" + detections.front().name + "' is " + size_text(size) +
                            " per camera but '" + d.name + "' is " + size_text(d.image_size) +
                            "; take all calibration images in the camera mode the tracker will use");
    }
  }

  StereoCalibration cal;
  cal.image_size = size;
  cal.board = options.board;
  cal.alpha = options.alpha;
  std::vector<const BoardDetection*> used;
  const std::size_t n_corners = static_cast<std::size_t>(options.board.inner_cols * options.board.inner_rows);
  for (const auto& d : detections) {
    if (d.usable() && d.corners_left.size() == n_corners && d.corners_right.size() == n_corners) {
      used.push_back(&d);
    } else {
      cal.skipped.push_back(d.name);
    }
  }
  if (used.empty()) {
    std::size_t only_left = 0, only_right = 0;
    for (const auto& d : detections) {
      only_left += d.found_left && !d.found_right;
      only_right += d.found_right && !d.found_left;
    }
    std::string hint = "check that --board counts INNER corners (a board of 10x7 squares is 9x6), that the whole "
                       "board is inside both images, and that it is sharp and evenly lit";
    if (only_left + only_right > 0) {
      hint = "it was found in only the left image of " + std::to_string(only_left) + " and only the right of " +
             std::to_string(only_right) + " pairs: hold it where both cameras see all of it";
    }
    return make_error(Errc::not_found, "the board (" + options.board.describe() + ") was not found in both images "
                                           "of any of the " + std::to_string(detections.size()) +
                                           " image pairs; " + hint);
  }
  if (used.size() < static_cast<std::size_t>(options.min_pairs)) {
    return make_error(Errc::invalid_argument,
                      "only " + std::to_string(used.size()) + " of " + std::to_string(detections.size()) +
                          " image pairs show the whole board in both cameras; calibration needs at least " +
                          std::to_string(options.min_pairs) +
                          " (15-25 recommended: near and far, tilted up to about 40 degrees, covering the image "
                          "corners). Pairs without the board in both: " + name_list(cal.skipped));
  }

  std::vector<std::vector<cv::Point3f>> object(used.size(), options.board.object_points());
  std::vector<std::vector<cv::Point2f>> img_left, img_right;
  for (const auto* d : used) {
    img_left.push_back(d->corners_left);
    img_right.push_back(d->corners_right);
  }

  int flags = 0;
  if (options.fix_k3) flags |= cv::CALIB_FIX_K3;
  if (options.fix_tangential) flags |= cv::CALIB_ZERO_TANGENT_DIST;
  try {
    auto calibrate_one = [&](const std::vector<std::vector<cv::Point2f>>& pts, CameraCalibration& cam) {
      cv::Mat K, D, sd_intr, sd_extr, per_view;
      std::vector<cv::Mat> rvecs, tvecs;
      cam.rms_px = cv::calibrateCamera(
          object, pts, size, K, D, rvecs, tvecs, sd_intr, sd_extr, per_view, flags,
          cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-9));
      cam.K = cv::Matx33d(K);
      D = D.reshape(1, 1);
      for (int i = 0; i < 5; ++i) cam.dist[i] = i < D.cols ? D.at<double>(0, i) : 0.0;
      for (int i = 0; i < 4; ++i) cam.intrinsics_sigma_px[i] = sd_intr.at<double>(i);
    };
    calibrate_one(img_left, cal.left);
    calibrate_one(img_right, cal.right);

    // Refine both cameras jointly with the extrinsics, starting from the
    // single-camera results: every board is then one pose seen by both.
    cv::Mat K1(cal.left.K), D1(cal.left.dist), K2(cal.right.K), D2(cal.right.dist);
    cv::Mat R, T, E, F, per_view;
    cal.rms_stereo_px = cv::stereoCalibrate(
        object, img_left, img_right, K1, D1, K2, D2, size, R, T, E, F, per_view, flags | cv::CALIB_USE_INTRINSIC_GUESS,
        cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-9));
    for (const cv::Mat* m : {&K1, &D1, &K2, &D2, &R, &T}) {
      if (!finite_all(*m)) {
        return make_error(Errc::invalid_argument,
                          "stereo calibration diverged (non-finite result); the boards are probably too similar "
                          "in pose: add pairs with the board tilted and at different distances");
      }
    }
    cal.left.K = cv::Matx33d(K1);
    cal.right.K = cv::Matx33d(K2);
    for (int i = 0; i < 5; ++i) {
      cal.left.dist[i] = D1.reshape(1, 1).at<double>(0, i);
      cal.right.dist[i] = D2.reshape(1, 1).at<double>(0, i);
    }
    cal.R_rightcam_leftcam = cv::Matx33d(R);
    T = T.reshape(1, 3);
    cal.t_rightcam_leftcam_m = cv::Vec3d(T.at<double>(0), T.at<double>(1), T.at<double>(2));

    const cv::Vec3d c_right = -(cal.R_rightcam_leftcam.t() * cal.t_rightcam_leftcam_m);
    if (std::abs(c_right[1]) > std::abs(c_right[0])) {
      return make_error(Errc::unsupported,
                        "the right camera is " + fmt_num("%.1f", c_right[1] * 1e3) +
                            " mm below/above the left one but only " + fmt_num("%.1f", c_right[0] * 1e3) +
                            " mm beside it: VIST needs cameras side by side (a horizontal baseline); check the "
                            "camera mounting and that left and right images are not from the same camera");
    }
    if (c_right[0] <= 0.0) {
      return make_error(Errc::invalid_argument,
                        "the 'right' camera is " + fmt_num("%.1f", -c_right[0] * 1e3) +
                            " mm to the LEFT of the 'left' camera: left and right are swapped (for side-by-side "
                            "images the left half must be the left camera, as seen from behind the camera); swap "
                            "them and calibrate again");
    }

    cv::Mat R1, R2, P1, P2, Q;
    cv::stereoRectify(K1, D1, K2, D2, size, R, T, R1, R2, P1, P2, Q, cv::CALIB_ZERO_DISPARITY, options.alpha, size,
                      &cal.valid_roi_left, &cal.valid_roi_right);
    cal.R_rectleft_leftcam = cv::Matx33d(R1);
    cal.R_rectright_rightcam = cv::Matx33d(R2);
    cal.P_left = cv::Matx34d(P1);
    cal.P_right = cv::Matx34d(P2);
    cal.Q = cv::Matx44d(Q);

    std::vector<double> rms;
    for (std::size_t i = 0; i < used.size(); ++i) {
      PairError e;
      e.name = used[i]->name;
      e.rms_left_px = per_view.at<double>(static_cast<int>(i), 0);
      e.rms_right_px = per_view.at<double>(static_cast<int>(i), 1);
      rms.push_back(std::hypot(e.rms_left_px, e.rms_right_px) / std::sqrt(2.0));
      cal.pairs.push_back(e);
    }
    const double limit = std::max(options.outlier_factor * median(rms), options.outlier_min_px);
    for (std::size_t i = 0; i < cal.pairs.size(); ++i) cal.pairs[i].outlier = rms[i] > limit;
  } catch (const cv::Exception& e) {
    return make_error(Errc::invalid_argument,
                      std::string("OpenCV calibration failed: ") + e.what() +
                          "; usually the board poses are degenerate (all parallel to the image): add tilted views");
  }
  return cal;
}

// --- files ------------------------------------------------------------------

Result<std::vector<CalibrationImagePair>> find_calibration_images(const std::filesystem::path& dir,
                                                                  bool side_by_side) {
  std::error_code ec;
  if (!std::filesystem::exists(dir, ec)) {
    return make_error(Errc::not_found, "calibration image folder '" + dir.string() + "' does not exist");
  }
  if (!std::filesystem::is_directory(dir, ec)) {
    return make_error(Errc::invalid_argument, "'" + dir.string() + "' is not a folder; --images takes the folder "
                                                                   "that holds the calibration images");
  }
  auto images_in = [&](const std::filesystem::path& d) {
    std::vector<std::filesystem::path> files;
    for (const auto& e : std::filesystem::directory_iterator(d, ec)) {
      if (e.is_regular_file(ec) && is_image_file(e.path())) files.push_back(e.path());
    }
    std::sort(files.begin(), files.end());
    return files;
  };
  const auto files = images_in(dir);
  const char* kKinds = ".png, .jpg, .bmp, .tif, .pgm/.ppm, .webp";
  std::vector<CalibrationImagePair> pairs;

  if (side_by_side) {
    for (const auto& f : files) pairs.push_back({f.filename().string(), f, {}});
    if (pairs.empty()) {
      return make_error(Errc::not_found, "no images (" + std::string(kKinds) + ") in '" + dir.string() + "'");
    }
    return pairs;
  }

  if (std::filesystem::is_directory(dir / "left", ec) && std::filesystem::is_directory(dir / "right", ec)) {
    const auto lefts = images_in(dir / "left");
    const auto rights = images_in(dir / "right");
    std::set<std::string> right_names;
    for (const auto& r : rights) right_names.insert(r.filename().string());
    std::vector<std::string> missing;
    for (const auto& l : lefts) {
      const std::string n = l.filename().string();
      if (right_names.erase(n) == 0) {
        missing.push_back("left/" + n);
      } else {
        pairs.push_back({n, l, dir / "right" / n});
      }
    }
    for (const auto& n : right_names) missing.push_back("right/" + n);
    if (!missing.empty()) {
      return make_error(Errc::not_found, "in '" + dir.string() + "', these images have no partner of the same name "
                                             "in the other subfolder: " + name_list(missing) +
                                             "; every left/X needs a right/X taken at the same moment");
    }
    if (pairs.empty()) {
      return make_error(Errc::not_found,
                        "no images (" + std::string(kKinds) + ") in '" + (dir / "left").string() + "'");
    }
    return pairs;
  }

  if (files.empty()) {
    return make_error(Errc::not_found, "no images (" + std::string(kKinds) + ") in '" + dir.string() +
                                           "'; name pairs left_000.png + right_000.png, or use left/ and right/ "
                                           "subfolders");
  }
  std::map<std::string, std::filesystem::path> by_name;
  for (const auto& f : files) by_name[f.filename().string()] = f;
  std::set<std::string> matched_right;
  std::vector<std::string> lonely;
  for (const auto& f : files) {
    const std::string n = f.filename().string();
    const std::string stem = f.stem().string();
    const auto pos = lower(stem).rfind("left");
    if (pos == std::string::npos) continue;
    const std::string right_name =
        stem.substr(0, pos) + right_word_for(stem.substr(pos, 4)) + stem.substr(pos + 4) + f.extension().string();
    if (by_name.count(right_name) == 0) {
      lonely.push_back(n + " (expected " + right_name + ")");
      continue;
    }
    matched_right.insert(right_name);
    pairs.push_back({n + " + " + right_name, f, by_name[right_name]});
  }
  std::size_t unnamed = 0;
  for (const auto& f : files) {
    const std::string n = f.filename().string();
    const std::string l = lower(f.stem().string());
    if (l.find("left") != std::string::npos) continue;
    if (l.find("right") != std::string::npos) {
      if (matched_right.count(n) == 0) lonely.push_back(n + " (no left partner)");
    } else {
      ++unnamed;
    }
  }
  if (!lonely.empty()) {
    return make_error(Errc::not_found, "in '" + dir.string() + "', images without a partner: " + name_list(lonely) +
                                           "; every left image needs a right image whose name differs only in "
                                           "'left' -> 'right'");
  }
  if (pairs.empty()) {
    return make_error(Errc::not_found,
                      "none of the " + std::to_string(files.size()) + " images in '" + dir.string() +
                          "' has 'left' or 'right' in its name; name pairs left_000.png + right_000.png, use "
                          "left/ and right/ subfolders, or pass --side-by-side if each image holds both cameras");
  }
  if (unnamed > 0) {
    return make_error(Errc::invalid_argument,
                      std::to_string(unnamed) + " image(s) in '" + dir.string() +
                          "' have neither 'left' nor 'right' in their names; move them out of the folder so no "
                          "image is silently left out");
  }
  return pairs;
}

Result<BoardDetection> detect_board_in_files(const CalibrationImagePair& pair, const CheckerboardSpec& board) {
  auto read = [](const std::filesystem::path& p) -> Result<cv::Mat> {
    cv::Mat m = cv::imread(p.string(), cv::IMREAD_GRAYSCALE);
    if (m.empty()) {
      std::error_code ec;
      if (!std::filesystem::exists(p, ec)) return make_error(Errc::not_found, "image '" + p.string() + "' is gone");
      return make_error(Errc::io_error, "cannot read image '" + p.string() +
                                            "' (damaged, or a format this OpenCV cannot decode); convert it to PNG "
                                            "or remove it");
    }
    return m;
  };
  auto left = read(pair.left);
  if (!left) return left.error();
  cv::Mat l, r;
  if (pair.right.empty()) {
    if (left->cols % 2 != 0) {
      return make_error(Errc::invalid_argument, "side-by-side image '" + pair.left.string() + "' is " +
                                                    size_text(left->size()) +
                                                    ": an odd width cannot be split into two equal halves; is it "
                                                    "really a side-by-side stereo image?");
    }
    const int w = left->cols / 2;
    l = (*left)(cv::Rect(0, 0, w, left->rows));
    r = (*left)(cv::Rect(w, 0, w, left->rows));
  } else {
    auto right = read(pair.right);
    if (!right) return right.error();
    if (right->size() != left->size()) {
      return make_error(Errc::invalid_argument, "'" + pair.left.string() + "' is " + size_text(left->size()) +
                                                    " but its partner '" + pair.right.string() + "' is " +
                                                    size_text(right->size()) +
                                                    "; both cameras must run in the same mode");
    }
    l = *left;
    r = *right;
  }
  return detect_board_pair(l, r, board, pair.name);
}

Result<StereoCalibration> calibrate_stereo_folder(const std::filesystem::path& dir, bool side_by_side,
                                                  const StereoCalibrationOptions& options,
                                                  const CalibrationProgress& progress) {
  if (auto s = options.validate(); !s) return s.error();
  auto pairs = find_calibration_images(dir, side_by_side);
  if (!pairs) return pairs.error();
  std::vector<BoardDetection> detections;
  detections.reserve(pairs->size());
  for (std::size_t i = 0; i < pairs->size(); ++i) {
    auto d = detect_board_in_files((*pairs)[i], options.board);
    if (!d) return d.error();
    // Fail on the first odd size, before spending time on the rest.
    if (!detections.empty() && d->image_size != detections.front().image_size) {
      return make_error(Errc::invalid_argument,
                        "inconsistent image sizes: '" + detections.front().name + "' is " +
                            size_text(detections.front().image_size) + " per camera but '" + d->name + "' is " +
                            size_text(d->image_size) +
                            "; take all calibration images in the camera mode the tracker will use");
    }
    if (progress) progress(i, pairs->size(), *d);
    detections.push_back(std::move(*d));
  }
  return calibrate_stereo(detections, options);
}

// --- save / load ------------------------------------------------------------

namespace {

constexpr const char* kFormatName = "proprio_stereo_calibration";
constexpr int kFormatVersion = 1;

}  // namespace

Status StereoCalibration::save(const std::filesystem::path& path) const {
  if (auto s = check_output_path(path, "stereo calibration"); !s) return s;
  const bool yaml = path.extension() != ".json";
  std::string text;
  try {
    // Written to memory, then replaced atomically: a crash never leaves half a calibration.
    cv::FileStorage fs(yaml ? ".yaml" : ".json", cv::FileStorage::WRITE | cv::FileStorage::MEMORY);
    if (!fs.isOpened()) return make_error(Errc::io_error, "cannot format calibration '" + path.string() + "'");
    if (yaml) {
      fs.writeComment(
          "Stereo calibration written by 'proprio calibrate stereo' (docs/stereo-camera.md).\n"
          "Pixels: OpenCV convention, the centre of the top-left pixel is (0, 0). Lengths in metres.\n"
          "p_in_rightcam = R_rightcam_leftcam * p_in_leftcam + t_rightcam_leftcam_m.\n"
          "R_rect*, P_*, Q are cv::stereoRectify's R1/R2, P1/P2, Q (CALIB_ZERO_DISPARITY).");
    }
    fs << "format" << kFormatName << "version" << kFormatVersion;
    fs << "image_width" << image_size.width << "image_height" << image_size.height;
    fs << "board_inner_cols" << board.inner_cols << "board_inner_rows" << board.inner_rows << "board_square_m"
       << board.square_m;
    fs << "alpha" << alpha;
    auto cam = [&](const std::string& side, const CameraCalibration& c) {
      fs << "K_" + side << cv::Mat(c.K) << "dist_" + side << cv::Mat(c.dist).reshape(1, 1);
      fs << "intrinsics_sigma_px_" + side << cv::Mat(c.intrinsics_sigma_px).reshape(1, 1);
      fs << "rms_" + side + "_px" << c.rms_px;
    };
    cam("left", left);
    cam("right", right);
    fs << "R_rightcam_leftcam" << cv::Mat(R_rightcam_leftcam);
    fs << "t_rightcam_leftcam_m" << cv::Mat(t_rightcam_leftcam_m);
    fs << "R_rectleft_leftcam" << cv::Mat(R_rectleft_leftcam) << "R_rectright_rightcam"
       << cv::Mat(R_rectright_rightcam);
    fs << "P_left" << cv::Mat(P_left) << "P_right" << cv::Mat(P_right) << "Q" << cv::Mat(Q);
    fs << "valid_roi_left" << valid_roi_left << "valid_roi_right" << valid_roi_right;
    fs << "rms_stereo_px" << rms_stereo_px;
    fs << "pairs" << "[";
    for (const auto& p : pairs) {
      fs << "{" << "name" << p.name << "rms_left_px" << p.rms_left_px << "rms_right_px" << p.rms_right_px
         << "outlier" << static_cast<int>(p.outlier) << "}";
    }
    fs << "]";
    fs << "skipped" << "[";
    for (const auto& n : skipped) fs << n;
    fs << "]";
    text = fs.releaseAndGetString();
  } catch (const cv::Exception& e) {
    return make_error(Errc::io_error, "writing calibration '" + path.string() + "' failed: " + e.what());
  }
  return write_file_atomic(path, text, "stereo calibration");
}

Result<StereoCalibration> StereoCalibration::load(const std::filesystem::path& path) {
  // Read here (a regular file, bounded) and parse from memory: OpenCV's own
  // open would block for ever on a FIFO.
  auto text = read_input_file(path, "stereo calibration", 16 * kMiB);
  if (!text) {
    if (text.error().code != Errc::not_found) return text.error();
    return make_error(Errc::not_found, text.error().message + "; make one with 'proprio calibrate stereo'");
  }
  const std::string where = "calibration '" + path.string() + "'";
  try {
    cv::FileStorage fs(*text, cv::FileStorage::READ | cv::FileStorage::MEMORY);
    if (!fs.isOpened()) return make_error(Errc::io_error, "cannot open " + where + " for reading");
    if (fs["format"].empty() || static_cast<std::string>(fs["format"]) != kFormatName) {
      return make_error(Errc::parse_error, where + " is not a proprio stereo calibration (no 'format: " +
                                               kFormatName + "'); make one with 'proprio calibrate stereo'");
    }
    const int version = static_cast<int>(fs["version"]);
    if (version != kFormatVersion) {
      return make_error(Errc::unsupported, where + " has format version " + std::to_string(version) +
                                               "; this build reads version " + std::to_string(kFormatVersion));
    }
    auto missing = [&](const std::string& key, const std::string& what) {
      return make_error(Errc::parse_error, where + ": '" + key + "' is missing or not " + what +
                                               "; the file is damaged or was edited; calibrate again");
    };
    auto number = [&](const std::string& key, double& out) -> Status {
      const cv::FileNode n = fs[key];
      if (n.empty() || (!n.isReal() && !n.isInt())) return missing(key, "a number");
      out = static_cast<double>(n);
      return Status::success();
    };
    auto integer = [&](const std::string& key, int& out) -> Status {
      const cv::FileNode n = fs[key];
      if (n.empty() || !n.isInt()) return missing(key, "an integer");
      out = static_cast<int>(n);
      return Status::success();
    };
    auto matrix = [&](const std::string& key, int rows, int cols, cv::Mat& out) -> Status {
      cv::Mat m;
      fs[key] >> m;
      if (m.empty() || m.total() != static_cast<std::size_t>(rows * cols) || m.channels() != 1) {
        return missing(key, "a " + std::to_string(rows) + "x" + std::to_string(cols) + " matrix");
      }
      m.reshape(1, rows).convertTo(out, CV_64F);
      if (!finite_all(out)) return missing(key, "finite");
      return Status::success();
    };
    auto rect = [&](const std::string& key, cv::Rect& out) -> Status {
      const cv::FileNode n = fs[key];
      if (n.empty() || !n.isSeq() || n.size() != 4) return missing(key, "a rectangle [x, y, w, h]");
      n >> out;
      return Status::success();
    };

    StereoCalibration c;
    Status s;
    cv::Mat m;
    if (s = integer("image_width", c.image_size.width); !s) return s.error();
    if (s = integer("image_height", c.image_size.height); !s) return s.error();
    if (s = integer("board_inner_cols", c.board.inner_cols); !s) return s.error();
    if (s = integer("board_inner_rows", c.board.inner_rows); !s) return s.error();
    if (s = number("board_square_m", c.board.square_m); !s) return s.error();
    if (s = number("alpha", c.alpha); !s) return s.error();
    if (c.image_size.width <= 0 || c.image_size.height <= 0) return missing("image_width", "a positive size");
    for (auto [side, cam] : {std::pair<std::string, CameraCalibration*>{"left", &c.left}, {"right", &c.right}}) {
      if (s = matrix("K_" + side, 3, 3, m); !s) return s.error();
      cam->K = cv::Matx33d(m);
      if (s = matrix("dist_" + side, 1, 5, m); !s) return s.error();
      for (int i = 0; i < 5; ++i) cam->dist[i] = m.at<double>(0, i);
      if (s = matrix("intrinsics_sigma_px_" + side, 1, 4, m); !s) return s.error();
      for (int i = 0; i < 4; ++i) cam->intrinsics_sigma_px[i] = m.at<double>(0, i);
      if (s = number("rms_" + side + "_px", cam->rms_px); !s) return s.error();
    }
    if (s = matrix("R_rightcam_leftcam", 3, 3, m); !s) return s.error();
    c.R_rightcam_leftcam = cv::Matx33d(m);
    if (s = matrix("t_rightcam_leftcam_m", 3, 1, m); !s) return s.error();
    c.t_rightcam_leftcam_m = cv::Vec3d(m);
    if (s = matrix("R_rectleft_leftcam", 3, 3, m); !s) return s.error();
    c.R_rectleft_leftcam = cv::Matx33d(m);
    if (s = matrix("R_rectright_rightcam", 3, 3, m); !s) return s.error();
    c.R_rectright_rightcam = cv::Matx33d(m);
    if (s = matrix("P_left", 3, 4, m); !s) return s.error();
    c.P_left = cv::Matx34d(m);
    if (s = matrix("P_right", 3, 4, m); !s) return s.error();
    c.P_right = cv::Matx34d(m);
    if (s = matrix("Q", 4, 4, m); !s) return s.error();
    c.Q = cv::Matx44d(m);
    if (s = rect("valid_roi_left", c.valid_roi_left); !s) return s.error();
    if (s = rect("valid_roi_right", c.valid_roi_right); !s) return s.error();
    if (s = number("rms_stereo_px", c.rms_stereo_px); !s) return s.error();
    for (const auto& n : fs["pairs"]) {
      PairError p;
      p.name = static_cast<std::string>(n["name"]);
      p.rms_left_px = static_cast<double>(n["rms_left_px"]);
      p.rms_right_px = static_cast<double>(n["rms_right_px"]);
      p.outlier = static_cast<int>(n["outlier"]) != 0;
      c.pairs.push_back(p);
    }
    for (const auto& n : fs["skipped"]) c.skipped.push_back(static_cast<std::string>(n));
    return c;
  } catch (const cv::Exception& e) {
    return make_error(Errc::parse_error, where + " could not be parsed: " + e.what());
  }
}

// --- glove file -------------------------------------------------------------

std::string rig_toml_snippet(const StereoRig& rig) {
  // Three decimals: a thousandth of a pixel or of a millimetre is far below
  // any calibration's uncertainty, and the table stays readable.
  auto fixed3 = [](double v) {
    std::string t = fmt_num("%.3f", v);
    while (t.size() > 2 && t.back() == '0' && t[t.size() - 2] != '.') t.pop_back();
    return t;
  };
  const PinholeCamera& c = rig.camera;
  std::ostringstream s;
  s << "[rig]\n"
    << "width_px = " << c.width_px << "\n"
    << "height_px = " << c.height_px << "\n"
    // Focal lengths rather than the field of view to_toml prefers: it takes
    // the FOV whenever some decimal text reproduces fx exactly, which for a
    // calibrated fx is a 16-digit angle.
    << "fx_px = " << fixed3(c.fx_px) << "\n"
    << "fy_px = " << fixed3(c.fy_px) << "\n"
    << "cx_px = " << fixed3(c.cx_px) << "\n"
    << "cy_px = " << fixed3(c.cy_px) << "\n"
    << "baseline_mm = " << fixed3(rig.baseline_m * 1e3) << "\n";
  // The rate and the mount exactly as ImuGloveDescription::to_toml writes them (a
  // pure downward tilt as such, anything else as a rotation vector).
  ImuGloveDescription g = ImuGloveDescription::vist_default();
  g.rig = rig;
  const std::string all = g.to_toml();
  std::istringstream in(all.substr(all.find("\n[rig]\n") + 1));
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("rate_hz", 0) == 0 || line.rfind("left_camera_", 0) == 0) s << line << "\n";
  }
  return s.str();
}

// --- rectifier ----------------------------------------------------------------

Result<StereoRectifier> StereoRectifier::create(const StereoCalibration& c) {
  if (c.image_size.width <= 0 || c.image_size.height <= 0 || c.P_left(0, 0) <= 0.0 || c.P_right(0, 0) <= 0.0) {
    return make_error(Errc::invalid_argument,
                      "the stereo calibration has no rectification (empty image size or projection); calibrate "
                      "with 'proprio calibrate stereo'");
  }
  StereoRectifier r;
  r.size_ = c.image_size;
  try {
    // Fixed-point maps: remap runs about twice as fast as with float maps.
    cv::initUndistortRectifyMap(c.left.K, c.left.dist, c.R_rectleft_leftcam, c.P_left, c.image_size, CV_16SC2,
                                r.left_map1_, r.left_map2_);
    cv::initUndistortRectifyMap(c.right.K, c.right.dist, c.R_rectright_rightcam, c.P_right, c.image_size, CV_16SC2,
                                r.right_map1_, r.right_map2_);
  } catch (const cv::Exception& e) {
    return make_error(Errc::invalid_argument, std::string("cannot build rectification maps: ") + e.what());
  }
  return r;
}

Status StereoRectifier::rectify(const cv::Mat& left, const cv::Mat& right, cv::Mat& left_out,
                                cv::Mat& right_out) const {
  if (left.size() != size_ || right.size() != size_) {
    return make_error(Errc::invalid_argument,
                      "images of " + size_text(left.size()) + " and " + size_text(right.size()) +
                          " cannot be rectified with a calibration for " + size_text(size_) +
                          "; run the camera in the calibrated mode or calibrate this one");
  }
  cv::remap(left, left_out, left_map1_, left_map2_, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  cv::remap(right, right_out, right_map1_, right_map2_, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  return Status::success();
}

}  // namespace proprio::vist
