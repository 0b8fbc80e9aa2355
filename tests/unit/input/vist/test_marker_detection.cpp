// The colour-blob marker detector: thresholds and shape filters on drawn
// blobs, bad input, and recall / false positives / centroid error on frames
// of the image-level simulator (free hand motion in front of a cluttered
// wall with marker-coloured distractors), through the stereo matcher to 3D.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/sim/stereo_image_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "proprio/vist/marker_detection.hpp"
#include "proprio/vist/stereo_matching.hpp"
#include "support/stereo.hpp"

using namespace proprio;
using namespace proprio::vist;

// Counts heap allocations of every thread (the detector's helper thread
// included), to hold detection to "no allocation in steady state".
namespace {
std::atomic<std::size_t> g_allocations{0};
}
// GCC cannot see that these replace the global pair and warns on free().
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
// The nothrow forms too (std::stable_sort's buffer uses them): a replaced
// delete must only ever free what the replaced new allocated.
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return std::malloc(n ? n : 1);
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }

namespace {

const PinholeCamera& camera() {
  static const PinholeCamera cam = ImuGloveDescription::vist_default().rig.camera;
  return cam;
}

MarkerDetector make_detector(MarkerDetectorOptions o = {}) {
  auto d = MarkerDetector::create(camera(), o);
  EXPECT_TRUE(d.ok()) << (d.ok() ? "" : d.error().message);
  return std::move(*d);
}

// BGR of an HSV_FULL colour (hue 0-255, s 0-1, v 0-255), through OpenCV.
cv::Vec3b bgr_of(int hue_code, double s, double v) {
  cv::Mat hsv(1, 1, CV_8UC3, cv::Scalar(hue_code, std::lround(255.0 * s), std::lround(v)));
  cv::Mat bgr;
  cv::cvtColor(hsv, bgr, cv::COLOR_HSV2BGR_FULL);
  return bgr.at<cv::Vec3b>(0, 0);
}

// An axis-aligned filled ellipse, anti-aliased by 8x8 supersampling, so its
// area centroid is exactly (cx, cy).
void draw_ellipse(cv::Mat& img, double cx, double cy, double rx, double ry, const cv::Vec3b& colour) {
  for (int y = static_cast<int>(std::floor(cy - ry - 1)); y <= static_cast<int>(std::ceil(cy + ry + 1)); ++y) {
    for (int x = static_cast<int>(std::floor(cx - rx - 1)); x <= static_cast<int>(std::ceil(cx + rx + 1)); ++x) {
      if (x < 0 || y < 0 || x >= img.cols || y >= img.rows) continue;
      int in = 0;
      for (int sy = 0; sy < 8; ++sy) {
        for (int sx = 0; sx < 8; ++sx) {
          const double dx = (x - 0.4375 + 0.125 * sx - cx) / rx;
          const double dy = (y - 0.4375 + 0.125 * sy - cy) / ry;
          in += dx * dx + dy * dy <= 1.0;
        }
      }
      const double a = in / 64.0;
      cv::Vec3b& p = img.at<cv::Vec3b>(y, x);
      for (int c = 0; c < 3; ++c) p[c] = cv::saturate_cast<std::uint8_t>((1.0 - a) * p[c] + a * colour[c]);
    }
  }
}

cv::Mat grey_image(int value = 110) {
  return cv::Mat(camera().height_px, camera().width_px, CV_8UC3, cv::Scalar(value, value, value));
}

const Marker* nearest(const MarkerObservations& obs, double u, double v, double* dist = nullptr) {
  const Marker* best = nullptr;
  double best_d = 1e18;
  for (const Marker& m : obs.markers) {
    const double d = std::hypot(m.u_px - u, m.v_px - v);
    if (d < best_d) {
      best_d = d;
      best = &m;
    }
  }
  if (dist) *dist = best_d;
  return best;
}

using proprio::testing_support::hue_distance;

}  // namespace

// ---------------------------------------------------------------------------
// Options and input checks.

TEST(MarkerDetectorOptions, DefaultsValidateAndDescribe) {
  MarkerDetectorOptions o;
  EXPECT_TRUE(o.validate().ok());
  const std::string d = o.describe();
  EXPECT_NE(d.find("red(h=0.0+-12.0"), std::string::npos) << d;
  EXPECT_NE(d.find("depth=0.15..1.00m"), std::string::npos) << d;
  // The default windows sit on the glove's hue codes.
  for (std::size_t h = 0; h < kMarkerHueCount; ++h) {
    EXPECT_EQ(o.hues[h].hue_center, sim::marker_hue_code(static_cast<MarkerHue>(h)));
  }
}

TEST(MarkerDetectorOptions, RejectsOverlappingWindowsAndBadRanges) {
  auto rejects = [](auto mutate, const char* expected) {
    MarkerDetectorOptions o;
    mutate(o);
    const Status st = o.validate();
    ASSERT_FALSE(st.ok()) << expected;
    EXPECT_EQ(st.error().code, Errc::invalid_argument);
    EXPECT_NE(st.error().message.find(expected), std::string::npos) << st.error().message;
  };
  rejects([](MarkerDetectorOptions& o) { o.hues[1].hue_half_width = 40.0; }, "overlap");
  rejects([](MarkerDetectorOptions& o) { o.hues[0].hue_center = 300.0; }, "hue_center");
  rejects([](MarkerDetectorOptions& o) { o.hues[2].hue = MarkerHue::red; }, "MarkerHue order");
  rejects([](MarkerDetectorOptions& o) { o.hues[3].min_saturation = 0.0; }, "min_saturation");
  rejects([](MarkerDetectorOptions& o) { o.min_depth_m = 2.0; }, "min_depth_m < max_depth_m");
  rejects([](MarkerDetectorOptions& o) { o.marker_diameter_m = -0.012; }, "marker_diameter_m");
  rejects([](MarkerDetectorOptions& o) { o.min_solidity = 1.5; }, "min_solidity");
  rejects([](MarkerDetectorOptions& o) { o.coarse_step = 3; }, "coarse_step");
  PinholeCamera bad = camera();
  bad.fx_px = 0.0;
  auto d = MarkerDetector::create(bad, {});
  ASSERT_FALSE(d.ok());
  EXPECT_NE(d.error().message.find("focal"), std::string::npos);
}

TEST(MarkerDetector, AcceptedAreaIsA12mmDiscOverTheDepthRange) {
  MarkerDetectorOptions o;
  o.min_depth_m = 0.2;
  o.max_depth_m = 0.8;
  o.min_area_factor = 0.5;
  o.max_area_factor = 1.5;
  const MarkerDetector d = make_detector(o);
  const double a1 = M_PI * 0.006 * 0.006 * camera().fx_px * camera().fy_px;  // at 1 m
  EXPECT_NEAR(d.min_area_px2(), 0.5 * a1 / (0.8 * 0.8), 1e-9);
  EXPECT_NEAR(d.max_area_px2(), 1.5 * a1 / (0.2 * 0.2), 1e-9);
}

TEST(MarkerDetector, BadImagesAreErrorsNotCrashes) {
  MarkerDetector d = make_detector();
  MarkerObservations out;
  out.markers.push_back(Marker{});
  const cv::Mat good = grey_image();
  struct Case {
    cv::Mat img;
    const char* expected;
  };
  const std::vector<Case> cases = {
      {cv::Mat(), "empty"},
      {cv::Mat(720, 1280, CV_8UC1, cv::Scalar(0)), "CV_8UC3"},
      {cv::Mat(720, 1280, CV_8UC4, cv::Scalar(0)), "CV_8UC3"},
      {cv::Mat(720, 1280, CV_16UC3, cv::Scalar(0)), "CV_8UC3"},
      {cv::Mat(720, 1280, CV_32FC3, cv::Scalar(0)), "CV_8UC3"},
      {cv::Mat(360, 640, CV_8UC3, cv::Scalar(0)), "1280x720"},
      {cv::Mat(721, 1280, CV_8UC3, cv::Scalar(0)), "1280x720"},
  };
  for (const Case& c : cases) {
    const Status st = d.detect(c.img, out);
    ASSERT_FALSE(st.ok()) << c.expected;
    EXPECT_EQ(st.error().code, Errc::invalid_argument);
    EXPECT_NE(st.error().message.find(c.expected), std::string::npos) << st.error().message;
    EXPECT_TRUE(out.markers.empty());
  }
  // Stereo: the bad side is named, on either path, and a good call still works after.
  for (bool parallel : {true, false}) {
    MarkerDetectorOptions o;
    o.parallel_stereo = parallel;
    MarkerDetector s = make_detector(o);
    MarkerObservations l, r;
    Status st = s.detect_stereo(good, cv::Mat(), l, r);
    ASSERT_FALSE(st.ok());
    EXPECT_NE(st.error().message.find("right"), std::string::npos) << st.error().message;
    st = s.detect_stereo(cv::Mat(10, 10, CV_8UC3), good, l, r);
    ASSERT_FALSE(st.ok());
    EXPECT_NE(st.error().message.find("left"), std::string::npos) << st.error().message;
    EXPECT_TRUE(s.detect_stereo(good, good, l, r).ok());
    EXPECT_EQ(l.camera_id, 0);
    EXPECT_EQ(r.camera_id, 1);
  }
  // A view into a bigger image (not continuous) is a valid image.
  cv::Mat big(800, 1400, CV_8UC3, cv::Scalar(110, 110, 110));
  draw_ellipse(big, 100.3 + 700, 200.7, 8, 8, bgr_of(85, 0.9, 220));
  const cv::Mat view = big(cv::Rect(60, 0, 1280, 720));
  ASSERT_FALSE(view.isContinuous());
  ASSERT_TRUE(d.detect(view, out).ok());
  ASSERT_EQ(out.markers.size(), 1u);
  EXPECT_NEAR(out.markers[0].u_px, 100.3 + 700 - 60, 0.1);
}

// ---------------------------------------------------------------------------
// Drawn blobs.

TEST(MarkerDetector, FindsDiscsOfEachHueWithSubpixelCentroids) {
  MarkerDetector d = make_detector();
  cv::Mat img = grey_image();
  struct Disc {
    double u, v, r;
    int hue;  // HSV_FULL
    MarkerHue expected;
  };
  // Red on both sides of 0 (it wraps), the other glove hues a little off
  // centre, radii from a marker at 1 m (3.9 px) to one at 0.2 m (19 px).
  const std::vector<Disc> discs = {
      {100.25, 100.5, 4.0, 0, MarkerHue::red},      {300.7, 120.1, 9.0, 250, MarkerHue::red},
      {500.0, 140.33, 19.0, 6, MarkerHue::red},     {700.4, 300.9, 6.0, 43, MarkerHue::yellow},
      {900.55, 320.2, 12.0, 38, MarkerHue::yellow}, {150.1, 500.6, 7.5, 85, MarkerHue::green},
      {400.9, 520.45, 5.0, 97, MarkerHue::green},   {650.2, 540.8, 10.0, 171, MarkerHue::blue},
      {1100.6, 600.3, 15.0, 158, MarkerHue::blue},
  };
  for (const Disc& c : discs) draw_ellipse(img, c.u, c.v, c.r, c.r, bgr_of(c.hue, 0.9, 220));
  MarkerObservations out;
  ASSERT_TRUE(d.detect(img, out).ok());
  EXPECT_EQ(out.markers.size(), discs.size());
  EXPECT_EQ(d.last_stats().accepted, discs.size());
  for (const Disc& c : discs) {
    double dist = 0.0;
    const Marker* m = nearest(out, c.u, c.v, &dist);
    ASSERT_NE(m, nullptr);
    // The thresholded blob's pixel centres: its digitisation error is about
    // a tenth of a pixel for the smallest discs, less for larger ones.
    EXPECT_LT(dist, c.r < 8.0 ? 0.16 : 0.08) << "disc at " << c.u << "," << c.v << " r " << c.r;
    EXPECT_EQ(sim::marker_hue_from_code(m->hue), c.expected);
    EXPECT_LE(hue_distance(m->hue, c.hue), 2) << "reported " << int(m->hue) << " drawn " << c.hue;
    // Pixel count of the thresholded disc: its area to within its rim.
    EXPECT_NEAR(m->area_px2, M_PI * c.r * c.r, 2.0 * M_PI * c.r * 0.5 + 2.0);
  }
}

TEST(MarkerDetector, AcceptsTiltedMarkersAndRejectsWhatNoMarkerIs) {
  MarkerDetector d = make_detector();
  cv::Mat img = grey_image();
  const cv::Vec3b green = bgr_of(85, 0.9, 220);
  // Accepted: a marker seen 70 degrees off its normal (axes 3:1).
  draw_ellipse(img, 200.5, 100.5, 12.0, 4.1, green);
  // Too thin: a bar (circularity).
  cv::line(img, {400, 100}, {470, 130}, cv::Scalar(green[0], green[1], green[2]), 3, cv::LINE_AA);
  // Not convex: a thick ring segment, the size of a near marker (solidity).
  cv::ellipse(img, {700, 100}, {18, 18}, 0.0, 0.0, 270.0, cv::Scalar(green[0], green[1], green[2]), 6, cv::LINE_AA);
  // Too large: a panel; too small: a speck.
  cv::rectangle(img, {900, 50}, {1000, 150}, cv::Scalar(green[0], green[1], green[2]), cv::FILLED);
  draw_ellipse(img, 1100.0, 100.0, 1.5, 1.5, green);
  // Touching the border: cut, so its centroid would be biased.
  draw_ellipse(img, 4.0, 400.0, 8.0, 8.0, green);
  // Not a glove colour: desaturated, dark, skin, orange, cyan, purple.
  draw_ellipse(img, 200.0, 600.0, 10.0, 10.0, bgr_of(85, 0.3, 220));
  draw_ellipse(img, 300.0, 600.0, 10.0, 10.0, bgr_of(0, 0.9, 45));
  draw_ellipse(img, 400.0, 600.0, 10.0, 10.0, cv::Vec3b(150, 170, 215));
  draw_ellipse(img, 500.0, 600.0, 10.0, 10.0, bgr_of(21, 0.9, 220));
  draw_ellipse(img, 600.0, 600.0, 10.0, 10.0, bgr_of(128, 0.9, 220));
  draw_ellipse(img, 700.0, 600.0, 10.0, 10.0, bgr_of(213, 0.9, 220));
  MarkerObservations out;
  ASSERT_TRUE(d.detect(img, out).ok());
  ASSERT_EQ(out.markers.size(), 1u);
  EXPECT_NEAR(out.markers[0].u_px, 200.5, 0.1);
  EXPECT_NEAR(out.markers[0].v_px, 100.5, 0.1);
  const MarkerDetectionStats& s = d.last_stats();
  EXPECT_GE(s.rejected_circularity, 1u);
  EXPECT_GE(s.rejected_solidity, 1u);
  EXPECT_GE(s.rejected_large + s.rejected_coarse_large, 1u);
  EXPECT_GE(s.rejected_small, 1u);
  EXPECT_GE(s.rejected_border, 1u);
  // With the filters off, the bar, ring and border blob come through.
  MarkerDetectorOptions loose;
  loose.min_circularity = 0.0;
  loose.min_solidity = 0.0;
  loose.reject_border = false;
  MarkerDetector l = make_detector(loose);
  ASSERT_TRUE(l.detect(img, out).ok());
  EXPECT_EQ(out.markers.size(), 4u);
}

TEST(MarkerDetector, ThresholdsAreConfigurable) {
  // A glove whose "green" is a teal (hue 110): missed by default, found once
  // the window is moved.
  cv::Mat img = grey_image();
  draw_ellipse(img, 640.3, 360.6, 10.0, 10.0, bgr_of(110, 0.9, 200));
  MarkerObservations out;
  MarkerDetector def = make_detector();
  ASSERT_TRUE(def.detect(img, out).ok());
  EXPECT_TRUE(out.markers.empty());
  MarkerDetectorOptions o;
  o.hues[2].hue_center = 110.0;
  o.hues[2].hue_half_width = 15.0;
  MarkerDetector tuned = make_detector(o);
  EXPECT_EQ(tuned.classify(bgr_of(110, 0.9, 200)[0], bgr_of(110, 0.9, 200)[1], bgr_of(110, 0.9, 200)[2]), 2);
  ASSERT_TRUE(tuned.detect(img, out).ok());
  ASSERT_EQ(out.markers.size(), 1u);
  EXPECT_NEAR(out.markers[0].hue, 110, 2);
}

// ---------------------------------------------------------------------------
// On the image-level simulator.

namespace {

struct RenderedSession {
  std::vector<sim::StereoImageFrame> frames;
  std::vector<sim::StereoImageTruth> truths;
};

// Free motion of subject 3 (seeded), one frame every 0.5 s for 30 s, with
// the given image options.
RenderedSession render_session(const sim::StereoImageSimOptions& o, std::uint64_t motion_seed, int frames) {
  const HandShape shape = *sim::sim_subject(3)->shape();
  auto simulator = sim::StereoImageSimulator::create(ImuGloveDescription::vist_default(), shape, o);
  EXPECT_TRUE(simulator.ok());
  sim::HandMotionOptions ho;
  ho.seed = motion_seed;
  sim::HandMotionGenerator gen(HandModel(shape), ho);
  RenderedSession s;
  for (int k = 0; k < frames; ++k) {
    const sim::HandMotionFrame m = gen.sample(k * 500'000'000LL);
    sim::StereoImageFrame f;
    sim::StereoImageTruth t;
    simulator->render(m.pose, m.T_world_head, m.time_ns, f, &t);
    if (f.dropped) continue;
    s.frames.push_back(std::move(f));
    s.truths.push_back(std::move(t));
  }
  return s;
}

// The default scene: clutter, 10 distractors, 2 DN noise, 0.6 px blur.
const RenderedSession& default_session() {
  static const RenderedSession s = render_session(sim::StereoImageSimOptions{}, 7, 60);
  return s;
}

// Detections of one camera image assigned to the truth: greedily by
// distance, within gate_px, same hue; the rest to distractors they lie on.
struct Assignment {
  std::vector<int> marker_of_detection;      // index into truth.drawn[c], or -1
  std::vector<int> distractor_of_detection;  // index into truth.distractors[c], or -1
};
Assignment assign(const MarkerObservations& obs, const sim::StereoImageTruth& t, std::size_t c, double gate_px) {
  Assignment a;
  a.marker_of_detection.assign(obs.markers.size(), -1);
  a.distractor_of_detection.assign(obs.markers.size(), -1);
  struct Cand {
    double d;
    std::size_t det, truth;
  };
  std::vector<Cand> cands;
  for (std::size_t j = 0; j < obs.markers.size(); ++j) {
    const MarkerHue h = sim::marker_hue_from_code(obs.markers[j].hue);
    for (std::size_t i = 0; i < t.drawn[c].size(); ++i) {
      const sim::MarkerImageTruth& m = t.drawn[c][i];
      if (m.hue != h || m.area_px2 <= 0.0) continue;
      // Near its projected centre, or near the centroid of what is drawn of
      // it: a marker half hidden behind a finger is still that marker.
      const double d = std::min(std::hypot(obs.markers[j].u_px - m.u_px, obs.markers[j].v_px - m.v_px),
                                std::hypot(obs.markers[j].u_px - m.u_drawn_px, obs.markers[j].v_px - m.v_drawn_px));
      if (d < gate_px) cands.push_back({d, j, i});
    }
  }
  std::sort(cands.begin(), cands.end(), [](const Cand& x, const Cand& y) { return x.d < y.d; });
  std::vector<bool> truth_used(t.drawn[c].size(), false);
  for (const Cand& k : cands) {
    if (a.marker_of_detection[k.det] >= 0 || truth_used[k.truth]) continue;
    a.marker_of_detection[k.det] = static_cast<int>(k.truth);
    truth_used[k.truth] = true;
  }
  // A distractor's visible part may be cut by the hand: anywhere on its disc.
  for (std::size_t j = 0; j < obs.markers.size(); ++j) {
    if (a.marker_of_detection[j] >= 0) continue;
    for (std::size_t i = 0; i < t.distractors[c].size(); ++i) {
      const sim::DistractorImageTruth& dt = t.distractors[c][i];
      const double radius = std::sqrt(dt.unoccluded_area_px2 / M_PI);
      if (std::hypot(obs.markers[j].u_px - dt.u_px, obs.markers[j].v_px - dt.v_px) < radius + gate_px) {
        a.distractor_of_detection[j] = static_cast<int>(i);
        break;
      }
    }
  }
  return a;
}

struct DetectionScore {
  std::size_t images = 0;
  std::size_t drawn = 0, drawn_found = 0;        // every drawn marker
  std::size_t eligible = 0, eligible_found = 0;  // unhidden (>= 95 %) and area >= the detector's minimum
  std::size_t detections = 0, on_markers = 0, on_distractors = 0, spurious = 0;
  double sq_err = 0.0, sq_err_drawn = 0.0, max_err = 0.0;  // eligible found, vs truth / vs drawn centroid
  double area_ratio_sum = 0.0;
  MarkerDetectionStats stats;

  double recall() const { return eligible ? double(eligible_found) / double(eligible) : 0.0; }
  double recall_all() const { return drawn ? double(drawn_found) / double(drawn) : 0.0; }
  double rms() const { return eligible_found ? std::sqrt(sq_err / double(eligible_found)) : 0.0; }
  double rms_drawn() const { return eligible_found ? std::sqrt(sq_err_drawn / double(eligible_found)) : 0.0; }
  // Detections that are neither a marker nor a distractor.
  double false_positive_rate() const { return detections ? double(spurious) / double(detections) : 0.0; }
  void print(const char* name) const {
    std::printf(
        "[%s] %zu images: recall %.4f (%zu/%zu unhidden, area >= min), %.4f of all %zu drawn; %zu detections: %zu "
        "markers, %zu distractors, %zu neither (false-positive rate %.4f); centroid RMS %.3f px vs truth, %.3f px vs "
        "drawn centroid, max %.2f px; detected/drawn area %.3f\n",
        name, images, recall(), eligible_found, eligible, recall_all(), drawn, detections, on_markers, on_distractors,
        spurious, false_positive_rate(), rms(), rms_drawn(), max_err,
        eligible_found ? area_ratio_sum / double(eligible_found) : 0.0);
    std::printf(
        "[%s] rejected: coarse-large %zu, no exact seed %zu, small %zu, large %zu, border %zu, solidity %zu, "
        "circularity %zu; merged seeds %zu\n",
        name, stats.rejected_coarse_large, stats.no_seed, stats.rejected_small, stats.rejected_large,
        stats.rejected_border, stats.rejected_solidity, stats.rejected_circularity, stats.merged);
  }
};

DetectionScore score_session(const RenderedSession& s, MarkerDetector& d, double gate_px = 3.0) {
  DetectionScore sc;
  MarkerObservations obs;
  for (std::size_t f = 0; f < s.frames.size(); ++f) {
    for (std::size_t c = 0; c < 2; ++c) {
      const sim::StereoImageTruth& t = s.truths[f];
      EXPECT_TRUE(d.detect(s.frames[f].images[c], obs).ok());
      sc.stats.add(d.last_stats());
      ++sc.images;
      const Assignment a = assign(obs, t, c, gate_px);
      std::vector<int> det_of_truth(t.drawn[c].size(), -1);
      for (std::size_t j = 0; j < obs.markers.size(); ++j) {
        ++sc.detections;
        if (a.marker_of_detection[j] >= 0) {
          ++sc.on_markers;
          det_of_truth[static_cast<std::size_t>(a.marker_of_detection[j])] = static_cast<int>(j);
        } else if (a.distractor_of_detection[j] >= 0) {
          ++sc.on_distractors;
        } else {
          ++sc.spurious;
        }
      }
      for (std::size_t i = 0; i < t.drawn[c].size(); ++i) {
        const sim::MarkerImageTruth& m = t.drawn[c][i];
        if (m.area_px2 <= 0.0) continue;
        ++sc.drawn;
        const bool found = det_of_truth[i] >= 0;
        sc.drawn_found += found;
        if (m.visible_fraction() < 0.95 || m.area_px2 < d.min_area_px2()) continue;
        ++sc.eligible;
        if (!found) continue;
        ++sc.eligible_found;
        const Marker& o = obs.markers[static_cast<std::size_t>(det_of_truth[i])];
        const double e2 = std::pow(o.u_px - m.u_px, 2) + std::pow(o.v_px - m.v_px, 2);
        sc.sq_err += e2;
        sc.max_err = std::max(sc.max_err, std::sqrt(e2));
        sc.sq_err_drawn += std::pow(o.u_px - m.u_drawn_px, 2) + std::pow(o.v_px - m.v_drawn_px, 2);
        sc.area_ratio_sum += o.area_px2 / m.area_px2;
      }
    }
  }
  return sc;
}

}  // namespace

TEST(MarkerDetectionOnImages, FreeMotionWithClutterAndDistractors) {
  const RenderedSession& s = default_session();
  ASSERT_GE(s.frames.size(), 55u);
  MarkerDetector d = make_detector();
  const DetectionScore sc = score_session(s, d);
  sc.print("detector, default scene");
  ASSERT_GT(sc.eligible, 2000u);
  EXPECT_GE(sc.recall(), 0.95);
  EXPECT_GE(sc.recall_all(), 0.90);
  // Centroid error against the centroid of what was drawn (the detector's
  // own error: noise, blur, highlights, thresholding), and against the
  // noise-free projected centre at the frame's stamp, which adds the motion
  // blur's offset (the stamp is the exposure's start, as UVC cameras stamp)
  // and the perspective offset of a disc's image centroid.
  EXPECT_LT(sc.rms_drawn(), 0.3);
  EXPECT_LT(sc.rms(), 0.6);
  EXPECT_LT(sc.max_err, 3.0);
  // Marker-coloured distractors are found (a colour detector cannot tell
  // them apart; the stereo depth gate removes them). Anything else is rare:
  // slivers of marker-coloured background panels between the fingers.
  EXPECT_GT(sc.on_distractors, 300u);
  EXPECT_LT(sc.false_positive_rate(), 0.02);
  // Area: the thresholded blob is the disc to within its rim.
  EXPECT_NEAR(sc.area_ratio_sum / double(sc.eligible_found), 1.0, 0.1);
}

TEST(MarkerDetectionOnImages, HarderCameraStillWorks) {
  // More sensor noise and a softer lens, another motion and scene seed.
  sim::StereoImageSimOptions o;
  o.pixel_noise_dn = 4.0;
  o.blur_sigma_px = 1.0;
  o.exposure_jitter = 0.15;
  o.distractors = 20;
  o.seed = 99;
  const RenderedSession s = render_session(o, 21, 30);
  MarkerDetector d = make_detector();
  const DetectionScore sc = score_session(s, d);
  sc.print("detector, 4 DN noise, 1 px blur");
  ASSERT_GT(sc.eligible, 800u);
  EXPECT_GE(sc.recall(), 0.93);
  EXPECT_LT(sc.rms(), 0.4);
  EXPECT_LT(sc.false_positive_rate(), 0.035);
}

TEST(MarkerDetectionOnImages, CoarseStepOneFindsTheSameMarkers) {
  const RenderedSession& s = default_session();
  MarkerDetectorOptions o;
  o.coarse_step = 1;
  MarkerDetector fine = make_detector(o);
  MarkerDetector coarse = make_detector();
  const DetectionScore a = score_session(s, fine);
  const DetectionScore b = score_session(s, coarse);
  a.print("detector, coarse step 1");
  // The coarse pass only finds seeds; the blobs are measured at full
  // resolution either way, so only blobs too small to be seen every second
  // pixel can differ.
  EXPECT_GE(a.eligible_found + 2, b.eligible_found);
  EXPECT_LE(a.eligible_found, b.eligible_found + a.eligible / 100);
  EXPECT_NEAR(a.rms(), b.rms(), 0.01);
}

TEST(MarkerDetectionOnImages, StereoMatcherTriangulatesDetectionsNearTheTruth) {
  const RenderedSession& s = default_session();
  MarkerDetector d = make_detector();
  const StereoRig& rig = ImuGloveDescription::vist_default().rig;
  StereoMatchOptions mo;
  mo.pixel_noise_px = 0.3;  // about the detector's centroid error
  auto matcher = StereoMatcher::create(rig, mo);
  ASSERT_TRUE(matcher.ok());
  std::size_t output = 0, correct = 0, wrong = 0, distractor_pairs = 0, both_eligible = 0;
  std::size_t distractor_detections = 0;
  double err_sum = 0.0, err_max = 0.0, depth_sum = 0.0;
  MarkerObservations left, right;
  std::vector<StereoPoint> points;
  for (std::size_t f = 0; f < s.frames.size(); ++f) {
    const sim::StereoImageTruth& t = s.truths[f];
    ASSERT_TRUE(d.detect_stereo(s.frames[f].images[0], s.frames[f].images[1], left, right).ok());
    const Assignment al = assign(left, t, 0, 3.0);
    const Assignment ar = assign(right, t, 1, 3.0);
    for (int i : al.distractor_of_detection) distractor_detections += i >= 0;
    // Markers both cameras show unhidden: what the matcher should pair.
    for (std::size_t i = 0; i < t.drawn[0].size(); ++i) {
      const auto& m = t.drawn[0][i];
      if (m.visible_fraction() < 0.95 || m.area_px2 < d.min_area_px2()) continue;
      for (const auto& r : t.drawn[1]) {
        if (r.marker == m.marker && r.visible_fraction() >= 0.95 && r.area_px2 >= d.min_area_px2()) ++both_eligible;
      }
    }
    matcher->match(left, right, points);
    for (const StereoPoint& p : points) {
      ++output;
      const int ml = al.marker_of_detection[p.left_index];
      const int mr = ar.marker_of_detection[p.right_index];
      if (al.distractor_of_detection[p.left_index] >= 0 || ar.distractor_of_detection[p.right_index] >= 0) {
        ++distractor_pairs;
        continue;
      }
      if (ml < 0 || mr < 0 || t.drawn[0][static_cast<std::size_t>(ml)].marker != t.drawn[1][static_cast<std::size_t>(mr)].marker) {
        ++wrong;
        continue;
      }
      ++correct;
      const Vec3& truth = t.markers.cameras[0][static_cast<std::size_t>(ml)].p_in_leftcam;
      const double e = (p.p_in_leftcam - truth).norm();
      err_sum += e;
      err_max = std::max(err_max, e);
      depth_sum += truth.z();
    }
  }
  const double precision = double(correct) / double(std::max<std::size_t>(output, 1));
  const double recall = double(correct) / double(std::max<std::size_t>(both_eligible, 1));
  const double mean_err = err_sum / double(std::max<std::size_t>(correct, 1));
  std::printf(
      "[detector -> stereo matcher] %zu pairs: %zu correct, %zu wrong, %zu with a distractor (of %zu left "
      "distractor blobs); precision %.4f, recall %.4f of %zu unhidden in both; 3D error mean %.2f mm, max %.2f mm at "
      "mean depth %.3f m\n",
      output, correct, wrong, distractor_pairs, distractor_detections, precision, recall, both_eligible,
      mean_err * 1e3, err_max * 1e3, depth_sum / double(std::max<std::size_t>(correct, 1)));
  ASSERT_GT(both_eligible, 800u);
  EXPECT_GE(precision, 0.97);
  EXPECT_GE(recall, 0.85);
  EXPECT_LT(mean_err, 0.0025);
  // Distractors are on the wall at 2.5 m, beyond the matcher's depth gate.
  EXPECT_GT(distractor_detections, 150u);
  EXPECT_LE(distractor_pairs, distractor_detections / 50);
}

TEST(MarkerDetectionOnImages, DeterministicOnEveryPathAndAllocationFreeWhenWarm) {
  const RenderedSession& s = default_session();
  MarkerDetectorOptions seq;
  seq.parallel_stereo = false;
  MarkerDetector a = make_detector();     // helper thread
  MarkerDetector b = make_detector(seq);  // one thread
  MarkerDetector c = make_detector();     // single images
  MarkerObservations al, ar, bl, br, cl, cr;
  auto same = [](const MarkerObservations& x, const MarkerObservations& y) {
    if (x.markers.size() != y.markers.size()) return false;
    for (std::size_t i = 0; i < x.markers.size(); ++i) {
      const Marker& p = x.markers[i];
      const Marker& q = y.markers[i];
      // Bit for bit (Marker has padding, so field by field).
      if (p.hue != q.hue || std::memcmp(&p.u_px, &q.u_px, sizeof(float)) != 0 ||
          std::memcmp(&p.v_px, &q.v_px, sizeof(float)) != 0 || std::memcmp(&p.area_px2, &q.area_px2, sizeof(float)) != 0) {
        return false;
      }
    }
    return true;
  };
  for (std::size_t f = 0; f < s.frames.size(); ++f) {
    const auto& im = s.frames[f].images;
    ASSERT_TRUE(a.detect_stereo(im[0], im[1], al, ar).ok());
    ASSERT_TRUE(b.detect_stereo(im[0], im[1], bl, br).ok());
    ASSERT_TRUE(c.detect(im[0], cl).ok());
    ASSERT_TRUE(c.detect(im[1], cr).ok());
    EXPECT_TRUE(same(al, bl) && same(al, cl)) << "frame " << f;
    EXPECT_TRUE(same(ar, br) && same(ar, cr)) << "frame " << f;
    EXPECT_EQ(a.last_stats(1).accepted, ar.markers.size());
  }
  // Warm now: a second pass over the same frames allocates nothing, on
  // either thread.
  const std::size_t before = g_allocations.load();
  for (std::size_t f = 0; f < s.frames.size(); ++f) {
    const auto& im = s.frames[f].images;
    (void)a.detect_stereo(im[0], im[1], al, ar);
    (void)c.detect(im[0], cl);
  }
  EXPECT_EQ(g_allocations.load() - before, 0u);
}
