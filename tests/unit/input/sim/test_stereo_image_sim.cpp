// The image-level stereo simulator: its images show the markers the
// detection-level simulator reports, where it reports them, with the wall,
// distractors and hand in a consistent 3D scene; it is deterministic.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/sim/stereo_image_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "support/stereo.hpp"

using namespace proprio;
using namespace proprio::sim;

namespace {

HandShape subject_shape(int id = 3) { return *sim_subject(id)->shape(); }

// Exact pixels: no blur, no noise, no exposure change, and none of the
// camera realism (motion blur, lens residual, uneven or coloured light,
// highlights, the sensor noise model).
StereoImageSimOptions clean_options() {
  StereoImageSimOptions o = StereoImageSimOptions::idealised();
  o.pixel_noise_dn = 0.0;
  o.blur_sigma_px = 0.0;
  o.exposure_jitter = 0.0;
  return o;
}

StereoImageSimulator make_sim(const StereoImageSimOptions& o, int subject = 3) {
  auto sim = StereoImageSimulator::create(ImuGloveDescription::vist_default(), subject_shape(subject), o);
  EXPECT_TRUE(sim.ok()) << (sim.ok() ? "" : sim.error().message);
  return std::move(*sim);
}

// Free motion of subject 3, sampled every 0.4 s.
std::vector<HandMotionFrame> motion_frames(int count, std::uint64_t seed = 3, Handedness hand = Handedness::right) {
  HandMotionOptions mo;
  mo.seed = seed;
  mo.hand = hand;
  HandMotionGenerator gen(HandModel(subject_shape()), mo);
  std::vector<HandMotionFrame> out;
  for (int k = 0; k < count; ++k) out.push_back(gen.sample(k * 400'000'000LL));
  return out;
}

// HSV_FULL of one pixel, as cv::cvtColor computes it.
cv::Vec3b hsv_full_at(const cv::Mat& bgr, double u, double v) {
  const int x = static_cast<int>(std::lround(u));
  const int y = static_cast<int>(std::lround(v));
  cv::Mat px = bgr(cv::Rect(x, y, 1, 1)).clone();
  cv::Mat hsv;
  cv::cvtColor(px, hsv, cv::COLOR_BGR2HSV_FULL);
  return hsv.at<cv::Vec3b>(0, 0);
}

using proprio::testing_support::hue_distance;

// A plain grey (128) wall and nothing else, in exact pixels: each camera
// effect's share of the image is then plain to see.
StereoImageSimOptions plain_wall() {
  StereoImageSimOptions o = clean_options();
  o.clutter = false;
  o.distractors = 0;
  return o;
}

const Pose kHeadRest{Quat::Identity(), Vec3(0.0, 1.6, 0.0)};

// Weighted first and second moments of an image window.
struct Moments {
  double w = 0.0, u = 0.0, v = 0.0, uu = 0.0, uv = 0.0, vv = 0.0;
  void add(double weight, double x, double y) {
    w += weight;
    u += weight * x;
    v += weight * y;
    uu += weight * x * x;
    uv += weight * x * y;
    vv += weight * y * y;
  }
  Eigen::Vector2d mean() const { return {u / w, v / w}; }
  Eigen::Matrix2d cov() const {
    const Eigen::Vector2d m = mean();
    Eigen::Matrix2d c;
    c << uu / w - m.x() * m.x(), uv / w - m.x() * m.y(), uv / w - m.x() * m.y(), vv / w - m.y() * m.y();
    return c;
  }
};

// Moments of weight(x, y) over the square window of half size `half` around
// `centre`; false when it leaves the image.
template <class Weight>
bool window_moments(const cv::Mat& img, const Eigen::Vector2d& centre, double half, const Weight& weight, Moments& m) {
  const int x0 = static_cast<int>(std::floor(centre.x() - half)), x1 = static_cast<int>(std::ceil(centre.x() + half));
  const int y0 = static_cast<int>(std::floor(centre.y() - half)), y1 = static_cast<int>(std::ceil(centre.y() + half));
  if (x0 < 1 || y0 < 1 || x1 > img.cols - 2 || y1 > img.rows - 2) return false;
  m = Moments{};
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) m.add(weight(x, y), x, y);
  }
  return m.w > 0.0;
}

// Sum over the channels of |a - b| at a pixel.
double abs_diff(const cv::Mat& a, const cv::Mat& b, int x, int y) {
  const cv::Vec3b p = a.at<cv::Vec3b>(y, x), q = b.at<cv::Vec3b>(y, x);
  return std::abs(p[0] - q[0]) + std::abs(p[1] - q[1]) + std::abs(p[2] - q[2]);
}

// The share of a pixel a colour `top` covers, blended over the same pixel of
// `under` (the image without it): the pixel is (1 - a) under + a top.
double coverage_of(const cv::Vec3d& top, const cv::Mat& img, const cv::Mat& under, int x, int y) {
  const cv::Vec3b p = img.at<cv::Vec3b>(y, x), q = under.at<cv::Vec3b>(y, x);
  double num = 0.0, den = 0.0;
  for (int ch = 0; ch < 3; ++ch) {
    num += (p[ch] - q[ch]) * (top[ch] - q[ch]);
    den += (top[ch] - q[ch]) * (top[ch] - q[ch]);
  }
  return den > 0.0 ? std::max(0.0, num / den) : 0.0;
}

}  // namespace

TEST(StereoImageSimOptions, DefaultsValidateAndDescribeNamesTheSeed) {
  StereoImageSimOptions o;
  EXPECT_TRUE(o.validate().ok());
  o.seed = 4242;
  EXPECT_NE(o.describe().find("seed=4242"), std::string::npos) << o.describe();
  EXPECT_NE(o.describe().find("noise=2.00DN"), std::string::npos) << o.describe();
}

TEST(StereoImageSimOptions, CameraRealismIsOnByDefaultAndIdealisedSwitchesItOff) {
  const StereoImageSimOptions real;
  EXPECT_TRUE(real.motion_blur && real.sensor_noise && real.lens_residual);
  EXPECT_GT(real.vignetting, 0.0);
  EXPECT_GT(real.illumination_gradient, 0.0);
  EXPECT_GT(real.colour_cast, 0.0);
  EXPECT_GT(real.specular, 0.0);
  EXPECT_DOUBLE_EQ(real.gain_ratio(), 1.0);
  const StereoImageSimOptions ideal = StereoImageSimOptions::idealised();
  EXPECT_TRUE(ideal.validate().ok());
  EXPECT_FALSE(ideal.motion_blur || ideal.sensor_noise || ideal.lens_residual);
  EXPECT_EQ(ideal.vignetting, 0.0);
  EXPECT_EQ(ideal.illumination_gradient, 0.0);
  EXPECT_EQ(ideal.colour_cast, 0.0);
  EXPECT_EQ(ideal.specular, 0.0);
  // The rest stays as it was: the old noise, blur and jitter.
  EXPECT_EQ(ideal.pixel_noise_dn, real.pixel_noise_dn);
  EXPECT_EQ(ideal.blur_sigma_px, real.blur_sigma_px);
  EXPECT_EQ(ideal.exposure_jitter, real.exposure_jitter);
  // describe() names every camera field.
  const std::string d = real.describe();
  for (const char* field : {"motion_blur=on", "exposure=4.00ms", "stamp_in_exposure=0.00", "sensor_noise=on",
                            "gain 0.100DN/e-", "light_level 1.00", "read 2.00DN", "lens_residual=on", "k1 sigma 0.001",
                            "k2 sigma 0.0005", "p sigma 0.0003", "vignetting=0.40", "illumination_gradient=0.10",
                            "colour_cast=0.040", "specular=0.80", "shininess 80", "gloss spread 0.50", "dome 20.0mm"}) {
    EXPECT_NE(d.find(field), std::string::npos) << field << " not in " << d;
  }
  EXPECT_NE(ideal.describe().find("motion_blur=off"), std::string::npos);
  // Less light or a shorter exposure: more gain, more noise.
  StereoImageSimOptions dim;
  dim.light_level = 0.25;
  dim.exposure_s = 0.002;
  EXPECT_DOUBLE_EQ(dim.effective_gain_dn_per_e(), 0.1 * 8.0);
  EXPECT_DOUBLE_EQ(dim.effective_read_noise_dn(), 2.0 * 8.0);
}

TEST(StereoImageSimOptions, RejectsBadValuesWithAMessage) {
  auto rejects = [](auto mutate, const char* expected) {
    StereoImageSimOptions o;
    mutate(o);
    const Status st = o.validate();
    ASSERT_FALSE(st.ok()) << expected;
    EXPECT_EQ(st.error().code, Errc::invalid_argument);
    EXPECT_NE(st.error().message.find(expected), std::string::npos) << st.error().message;
  };
  rejects([](StereoImageSimOptions& o) { o.pixel_noise_dn = -1.0; }, "pixel_noise_dn");
  rejects([](StereoImageSimOptions& o) { o.blur_sigma_px = NAN; }, "blur_sigma_px");
  rejects([](StereoImageSimOptions& o) { o.background_depth_m = 0.0; }, "background_depth_m");
  rejects([](StereoImageSimOptions& o) { o.distractors = -1; }, "distractors");
  rejects([](StereoImageSimOptions& o) { o.distractor_min_diameter_m = 0.2; }, "distractor");
  rejects([](StereoImageSimOptions& o) { o.skin_bgr[1] = 300.0; }, "skin_bgr");
  rejects([](StereoImageSimOptions& o) { o.light_dir_in_leftcam = Vec3::Zero(); }, "light_dir_in_leftcam");
  rejects([](StereoImageSimOptions& o) { o.marker_saturation = 0.0; }, "marker_saturation");
  rejects([](StereoImageSimOptions& o) { o.clutter_hue_clearance[3] = 70.0; }, "clutter_hue_clearance");
  // Centroid noise belongs to the detection-level simulator, not to images.
  rejects([](StereoImageSimOptions& o) { o.visibility.pixel_noise_px = 0.3; }, "pixels carry the noise");
  rejects([](StereoImageSimOptions& o) { o.visibility.shuffle = true; }, "pixels carry the noise");
  rejects([](StereoImageSimOptions& o) { o.visibility.min_depth_m = -1.0; }, "min_depth_m");
  // Camera realism: NaN, infinities and out-of-range values, named.
  rejects([](StereoImageSimOptions& o) { o.exposure_s = NAN; }, "exposure_s");
  rejects([](StereoImageSimOptions& o) { o.exposure_s = 0.0; }, "exposure_s");
  rejects([](StereoImageSimOptions& o) { o.timestamp_in_exposure = NAN; }, "timestamp_in_exposure");
  rejects([](StereoImageSimOptions& o) { o.timestamp_in_exposure = 1.5; }, "timestamp_in_exposure");
  rejects([](StereoImageSimOptions& o) { o.sensor_gain_dn_per_e = NAN; }, "sensor_gain_dn_per_e");
  rejects([](StereoImageSimOptions& o) { o.sensor_gain_dn_per_e = -0.1; }, "sensor_gain_dn_per_e");
  rejects([](StereoImageSimOptions& o) { o.light_level = INFINITY; }, "light_level");
  rejects([](StereoImageSimOptions& o) { o.light_level = 0.0; }, "light_level");
  rejects(
      [](StereoImageSimOptions& o) {
        o.light_level = 0.02;
        o.pixel_noise_dn = 4.0;
      },
      "sensor_noise");
  rejects([](StereoImageSimOptions& o) { o.residual_k1_sigma = NAN; }, "residual_k1_sigma");
  rejects([](StereoImageSimOptions& o) { o.residual_k2_sigma = -1e-3; }, "residual_k2_sigma");
  rejects([](StereoImageSimOptions& o) { o.residual_p_sigma = INFINITY; }, "residual_p_sigma");
  rejects([](StereoImageSimOptions& o) { o.vignetting = NAN; }, "vignetting");
  rejects([](StereoImageSimOptions& o) { o.vignetting = 1.2; }, "vignetting");
  rejects([](StereoImageSimOptions& o) { o.illumination_gradient = NAN; }, "illumination_gradient");
  rejects([](StereoImageSimOptions& o) { o.colour_cast = -0.01; }, "colour_cast");
  rejects([](StereoImageSimOptions& o) { o.colour_cast = NAN; }, "colour_cast");
  rejects([](StereoImageSimOptions& o) { o.specular = NAN; }, "specular");
  rejects([](StereoImageSimOptions& o) { o.specular_shininess = 0.0; }, "specular_shininess");
  rejects([](StereoImageSimOptions& o) { o.marker_gloss_spread = NAN; }, "marker_gloss_spread");
  rejects([](StereoImageSimOptions& o) { o.marker_dome_radius_m = 0.0; }, "marker_dome_radius_m");
  rejects([](StereoImageSimOptions& o) { o.marker_dome_radius_m = NAN; }, "marker_dome_radius_m");

  StereoImageSimOptions bad;
  bad.exposure_jitter = 0.9;
  auto sim = StereoImageSimulator::create(ImuGloveDescription::vist_default(), subject_shape(), bad);
  ASSERT_FALSE(sim.ok());
  EXPECT_NE(sim.error().message.find("exposure_jitter"), std::string::npos);

  // A marker simulator with centroid noise cannot be wrapped.
  StereoSimOptions noisy;
  noisy.pixel_noise_px = 0.3;
  auto markers = StereoMarkerSimulator::create(ImuGloveDescription::vist_default(), subject_shape(), noisy);
  ASSERT_TRUE(markers.ok());
  auto wrapped = StereoImageSimulator::create(std::move(*markers), StereoImageSimOptions{});
  ASSERT_FALSE(wrapped.ok());
  EXPECT_NE(wrapped.error().message.find("default_visibility"), std::string::npos);
}

TEST(StereoImageSim, RendersTwoRigSizedBgrImagesAndSharesTheDetectionTruth) {
  StereoImageSimulator sim = make_sim(StereoImageSimOptions{});
  const auto motion = motion_frames(3);
  StereoImageFrame frame;
  StereoImageTruth truth;
  for (const HandMotionFrame& m : motion) {
    sim.render(m.pose, m.T_world_head, m.time_ns, frame, &truth);
    ASSERT_FALSE(frame.dropped);
    EXPECT_EQ(frame.time_ns, m.time_ns);
    for (std::size_t c = 0; c < 2; ++c) {
      EXPECT_EQ(frame.images[c].cols, 1280);
      EXPECT_EQ(frame.images[c].rows, 720);
      EXPECT_EQ(frame.images[c].type(), CV_8UC3);
      // Exactly the markers the detection-level simulator sees, in its order.
      ASSERT_EQ(truth.drawn[c].size(), truth.markers.cameras[c].size());
      EXPECT_EQ(truth.drawn[c].size(), truth.markers.visible_count(c));
      for (std::size_t i = 0; i < truth.drawn[c].size(); ++i) {
        EXPECT_EQ(truth.drawn[c][i].marker, truth.markers.cameras[c][i].marker);
        EXPECT_EQ(truth.drawn[c][i].u_px, truth.markers.cameras[c][i].u_px);
      }
    }
    // The same frame from the detection-level simulator alone.
    StereoGroundTruth direct;
    sim.marker_simulator().simulate(m.pose, m.T_world_head, m.time_ns, &direct);
    EXPECT_EQ(direct.visibility, truth.markers.visibility);
  }
}

TEST(StereoImageSim, VisibleMarkersAppearAtTheirTruePositionsInTheirHue) {
  StereoImageSimulator sim = make_sim(clean_options());
  StereoImageFrame frame;
  StereoImageTruth truth;
  std::size_t checked = 0;
  double max_centroid_err = 0.0;
  // Both hands: the left glove is the mirror image, normals included (a wrong
  // normal would show as an area off the detection simulator's cos(alpha) formula).
  std::vector<HandMotionFrame> frames = motion_frames(10);
  for (const HandMotionFrame& m : motion_frames(6, 5, Handedness::left)) frames.push_back(m);
  for (const HandMotionFrame& m : frames) {
    sim.render(m.pose, m.T_world_head, m.time_ns, frame, &truth);
    for (std::size_t c = 0; c < 2; ++c) {
      for (std::size_t i = 0; i < truth.drawn[c].size(); ++i) {
        const MarkerImageTruth& d = truth.drawn[c][i];
        const MarkerTruth& mt = truth.markers.cameras[c][i];
        EXPECT_LE(d.area_px2, d.unoccluded_area_px2 + 1e-9);
        // Unhidden, and big enough that its centre pixel is all marker.
        if (d.visible_fraction() < 0.999 || d.area_px2 < 40.0) continue;
        ++checked;
        // The drawn disc covers what the detection simulator's first-order
        // area formula says (to perspective and 4x4 sampling)...
        EXPECT_NEAR(d.area_px2, mt.area_px2, 0.1 * mt.area_px2 + 2.0) << "marker " << d.marker;
        // ...its coverage centroid is the projected centre (a disc's image
        // centroid differs from its projected centre by a perspective term
        // well below a tenth of a pixel at hand distance)...
        const double err = std::hypot(d.u_drawn_px - d.u_px, d.v_drawn_px - d.v_px);
        max_centroid_err = std::max(max_centroid_err, err);
        EXPECT_LT(err, 0.15) << "marker " << d.marker;
        // ...and the pixel there has the marker's hue, saturated.
        const cv::Vec3b hsv = hsv_full_at(frame.images[c], d.u_px, d.v_px);
        EXPECT_LE(hue_distance(hsv[0], d.hue_code), 2) << "marker " << d.marker;
        EXPECT_LE(hue_distance(d.hue_code, marker_hue_code(d.hue)), 3);
        EXPECT_GT(hsv[1], 180);
      }
    }
  }
  EXPECT_GT(checked, 200u);
  std::printf("[ image sim ] %zu unhidden markers checked, coverage centroid vs projected centre max %.3f px\n", checked,
              max_centroid_err);
}

TEST(StereoImageSim, HiddenMarkersAreNotDrawnAndTheTruthCallsThemOccluded) {
  StereoImageSimOptions o = clean_options();
  o.distractors = 0;  // no marker-coloured disc may show through where a marker was
  StereoImageSimulator sim = make_sim(o);
  StereoImageFrame plain, hiding;
  StereoImageTruth plain_truth, hiding_truth;
  std::size_t hidden_seen = 0;
  for (const HandMotionFrame& m : motion_frames(6)) {
    sim.render(m.pose, m.T_world_head, m.time_ns, plain, &plain_truth);
    // Hide every other marker the left camera sees unhidden.
    std::vector<bool> hidden(sim.marker_simulator().markers().size(), false);
    std::vector<const MarkerImageTruth*> to_hide;
    for (std::size_t i = 0; i < plain_truth.drawn[0].size(); i += 2) {
      const MarkerImageTruth& d = plain_truth.drawn[0][i];
      if (d.visible_fraction() < 0.999 || d.area_px2 < 40.0) continue;
      hidden[d.marker] = true;
      to_hide.push_back(&d);
    }
    sim.render(m.pose, m.T_world_head, m.time_ns, hiding, &hiding_truth, &hidden);
    for (std::size_t c = 0; c < 2; ++c) {
      ASSERT_EQ(hiding_truth.drawn[c].size(), hiding_truth.markers.cameras[c].size());
      for (const MarkerTruth& mt : hiding_truth.markers.cameras[c]) EXPECT_FALSE(hidden[mt.marker]);
      for (std::size_t k = 0; k < hidden.size(); ++k) {
        if (hidden[k] && plain_truth.markers.visibility[c][k] == MarkerVisibility::visible) {
          EXPECT_EQ(hiding_truth.markers.visibility[c][k], MarkerVisibility::occluded);
        }
      }
    }
    // Where a hidden marker was, the left image no longer has its hue.
    for (const MarkerImageTruth* d : to_hide) {
      const cv::Vec3b was = hsv_full_at(plain.images[0], d->u_px, d->v_px);
      const cv::Vec3b now = hsv_full_at(hiding.images[0], d->u_px, d->v_px);
      EXPECT_LE(hue_distance(was[0], d->hue_code), 2);
      // Skin, or the wall where the capsules do not reach: never the marker's saturated hue.
      EXPECT_FALSE(hue_distance(now[0], d->hue_code) <= 3 && now[1] > 150)
          << "marker " << d->marker << " still drawn (hue " << int(now[0]) << ", saturation " << int(now[1]) << ")";
      ++hidden_seen;
    }
  }
  EXPECT_GT(hidden_seen, 10u);
}

TEST(StereoImageSim, TheHandCoversTheBackgroundWithSkin) {
  StereoImageSimOptions o = clean_options();
  StereoImageSimulator sim = make_sim(o);
  StereoImageFrame frame;
  StereoImageTruth truth;
  std::size_t checked = 0;
  for (const HandMotionFrame& m : motion_frames(6)) {
    sim.render(m.pose, m.T_world_head, m.time_ns, frame, &truth);
    const Pose T_lc_world = truth.markers.T_world_leftcam.inverse();
    // The middle of the middle metacarpal: inside the hand, so whatever the
    // camera sees along that ray first is skin (back, palm or a curled
    // finger) or a marker; check it is skin-like (orange, low saturation) in
    // the left image when it is in view.
    const Vec3 p_in_lc = T_lc_world * (0.5 * (m.pose.joint(HandJoint::middle_metacarpal).p +
                                              m.pose.joint(HandJoint::middle_proximal).p));
    if (p_in_lc.z() < 0.1) continue;
    const Eigen::Vector2d uv = sim.marker_simulator().project(p_in_lc, 0);
    if (uv.x() < 0 || uv.y() < 0 || uv.x() > 1279 || uv.y() > 719) continue;
    cv::Mat hsv;
    cv::cvtColor(frame.images[0], hsv, cv::COLOR_BGR2HSV_FULL);
    int skin = 0, marker = 0, total = 0;
    for (int dy = -2; dy <= 2; ++dy) {
      for (int dx = -2; dx <= 2; ++dx) {
        const cv::Vec3b p = hsv.at<cv::Vec3b>(static_cast<int>(uv.y()) + dy, static_cast<int>(uv.x()) + dx);
        ++total;
        // Skin (150,170,215) BGR: hue about 14, saturation about 77.
        if (hue_distance(p[0], 14) <= 8 && p[1] > 40 && p[1] < 110) ++skin;
        // Or a marker on the glove: saturated, near a glove hue.
        for (auto h : {MarkerHue::red, MarkerHue::yellow, MarkerHue::green, MarkerHue::blue}) {
          if (p[1] > 150 && hue_distance(p[0], marker_hue_code(h)) <= 6) ++marker;
        }
      }
    }
    ++checked;
    // Skin, and markers where they are, but not the wall behind.
    EXPECT_GE(skin, 3) << "frame at " << m.time_ns;
    EXPECT_GE(skin + marker, total * 4 / 5) << "frame at " << m.time_ns;
  }
  EXPECT_GE(checked, 3u);
}

TEST(StereoImageSim, DistractorsAreStaticInTheWorldWithBackgroundDisparity) {
  StereoImageSimOptions o = clean_options();
  o.distractors = 40;
  StereoImageSimulator sim = make_sim(o);
  ASSERT_EQ(sim.distractors().size(), 40u);
  const StereoRig& rig = sim.rig();
  StereoImageFrame frame;
  StereoImageTruth truth;
  std::size_t paired = 0;
  for (const HandMotionFrame& m : motion_frames(4)) {
    sim.render(m.pose, m.T_world_head, m.time_ns, frame, &truth);
    const Pose T_lc_world = truth.markers.T_world_leftcam.inverse();
    for (const DistractorImageTruth& l : truth.distractors[0]) {
      // Where it is: the static world point, seen from this head pose.
      const Vec3 p = T_lc_world * sim.distractors()[l.distractor].p_in_world;
      EXPECT_LT((p - l.p_in_leftcam).norm(), 1e-9);
      EXPECT_NEAR(l.u_px, rig.camera.fx_px * p.x() / p.z() + rig.camera.cx_px, 1e-6);
      // About the background depth (head sway moves the camera a little).
      EXPECT_NEAR(p.z(), o.background_depth_m, 0.4);
      for (const DistractorImageTruth& r : truth.distractors[1]) {
        if (r.distractor != l.distractor) continue;
        ++paired;
        EXPECT_NEAR(l.v_px, r.v_px, 1e-6);  // rectified: same row
        EXPECT_NEAR(l.u_px - r.u_px, rig.camera.fx_px * rig.baseline_m / p.z(), 1e-6);
        // The pixel at an unhidden distractor's centre has its hue.
        if (l.area_px2 > 0.99 * l.unoccluded_area_px2 && l.area_px2 > 30.0) {
          const cv::Vec3b hsv = hsv_full_at(frame.images[0], l.u_px, l.v_px);
          EXPECT_LE(hue_distance(hsv[0], sim.distractors()[l.distractor].hue_code), 2);
        }
      }
    }
  }
  EXPECT_GT(paired, 60u);
}

TEST(StereoImageSim, HeadMotionMovesTheBackground) {
  // A plain wall with many distractors and no hand: the distractors are the
  // only features.
  StereoImageSimOptions o = clean_options();
  o.clutter = false;
  o.distractors = 60;
  StereoImageSimulator sim = make_sim(o);
  HandPose no_hand;  // inactive
  const Pose head_a{Quat::Identity(), Vec3(0.0, 1.6, 0.0)};
  // Turn the head 3 degrees to the left and move it 2 cm right.
  const Pose head_b{Quat(Eigen::AngleAxisd(3.0 * M_PI / 180.0, Vec3::UnitY())), Vec3(0.02, 1.6, 0.0)};
  StereoImageFrame a, b;
  StereoImageTruth ta, tb;
  sim.render(no_hand, head_a, 0, a, &ta);
  sim.render(no_hand, head_b, 0, b, &tb);
  std::size_t both = 0;
  for (const DistractorImageTruth& da : ta.distractors[0]) {
    for (const DistractorImageTruth& db : tb.distractors[0]) {
      if (da.distractor != db.distractor || da.area_px2 < 30.0 || db.area_px2 < 30.0) continue;
      auto inside = [](const DistractorImageTruth& t) {
        return t.u_px > 20 && t.v_px > 20 && t.u_px < 1260 && t.v_px < 700;
      };
      if (!inside(da) || !inside(db)) continue;
      ++both;
      // Turning left moves the world to the right in the image (about fx
      // tan(3 deg) = 34 px, less the translation's 5 px and the tilt's share).
      EXPECT_GT(db.u_px - da.u_px, 15.0);
      // Each image shows the distractor where its truth says.
      const int hue = sim.distractors()[da.distractor].hue_code;
      EXPECT_LE(hue_distance(hsv_full_at(a.images[0], da.u_px, da.v_px)[0], hue), 2);
      EXPECT_LE(hue_distance(hsv_full_at(b.images[0], db.u_px, db.v_px)[0], hue), 2);
    }
  }
  EXPECT_GT(both, 15u);
  // And the wall is grey where no distractor is.
  const cv::Vec3b corner = a.images[0].at<cv::Vec3b>(2, 2);
  EXPECT_EQ(corner, cv::Vec3b(128, 128, 128));
}

TEST(StereoImageSim, DeterministicAndIndependentOfFrameHistory) {
  const StereoImageSimOptions o;  // noise, blur, exposure jitter on
  StereoImageSimulator a = make_sim(o);
  StereoImageSimulator b = make_sim(o);
  const auto motion = motion_frames(3);
  StereoImageFrame fa, fb;
  // b renders frame 2 first, then 1: same bytes as a in order 1, 2.
  b.render(motion[2].pose, motion[2].T_world_head, motion[2].time_ns, fb);
  for (std::size_t k : {std::size_t{1}, std::size_t{2}}) {
    a.render(motion[k].pose, motion[k].T_world_head, motion[k].time_ns, fa);
    b.render(motion[k].pose, motion[k].T_world_head, motion[k].time_ns, fb);
    for (std::size_t c = 0; c < 2; ++c) {
      ASSERT_TRUE(fa.images[c].isContinuous() && fb.images[c].isContinuous());
      EXPECT_EQ(0, std::memcmp(fa.images[c].data, fb.images[c].data, fa.images[c].total() * 3)) << "frame " << k;
    }
  }
  // Another seed: another wall and other noise.
  StereoImageSimOptions other = o;
  other.seed = 2;
  StereoImageSimulator c = make_sim(other);
  StereoImageFrame fc;
  c.render(motion[2].pose, motion[2].T_world_head, motion[2].time_ns, fc);
  EXPECT_GT(cv::norm(fa.images[0], fc.images[0], cv::NORM_L1), 1e6);
}

TEST(StereoImageSim, PixelNoiseHasTheConfiguredSigmaAndItsOwnStream) {
  StereoImageSimOptions o = clean_options();
  StereoImageSimulator clean = make_sim(o);
  o.pixel_noise_dn = 3.0;
  StereoImageSimulator noisy = make_sim(o);
  const auto motion = motion_frames(1);
  StereoImageFrame fc, fn;
  clean.render(motion[0].pose, motion[0].T_world_head, motion[0].time_ns, fc);
  noisy.render(motion[0].pose, motion[0].T_world_head, motion[0].time_ns, fn);
  // Noise is the only difference (its own random stream); away from 0 and
  // 255, where clipping would bias it, it is zero-mean with sigma 3.
  double sum = 0.0, sum2 = 0.0;
  std::size_t n = 0;
  const cv::Mat& a = fc.images[0];
  const cv::Mat& b = fn.images[0];
  for (int y = 0; y < a.rows; ++y) {
    const std::uint8_t* pa = a.ptr<std::uint8_t>(y);
    const std::uint8_t* pb = b.ptr<std::uint8_t>(y);
    for (int x = 0; x < 3 * a.cols; ++x) {
      if (pa[x] < 15 || pa[x] > 240) continue;
      const double d = static_cast<double>(pb[x]) - pa[x];
      sum += d;
      sum2 += d * d;
      ++n;
    }
  }
  ASSERT_GT(n, 1000000u);
  const double mean = sum / static_cast<double>(n);
  const double sigma = std::sqrt(sum2 / static_cast<double>(n) - mean * mean);
  EXPECT_NEAR(mean, 0.0, 0.02);
  // Rounding to integers adds 1/12 DN^2 of variance.
  EXPECT_NEAR(sigma, std::sqrt(9.0 + 1.0 / 12.0), 0.05);
}

TEST(StereoImageSim, DroppedFramesFollowTheDetectionSimulator) {
  StereoImageSimOptions o = clean_options();
  o.visibility.drop_probability = 0.3;
  StereoImageSimulator sim = make_sim(o);
  StereoImageFrame frame;
  StereoImageTruth truth;
  int dropped = 0;
  const auto motion = motion_frames(40);
  for (const HandMotionFrame& m : motion) {
    sim.render(m.pose, m.T_world_head, m.time_ns, frame, &truth);
    StereoGroundTruth direct;
    const StereoFrame f = sim.marker_simulator().simulate(m.pose, m.T_world_head, m.time_ns, &direct);
    EXPECT_EQ(frame.dropped, f.dropped);
    if (frame.dropped) {
      ++dropped;
      EXPECT_TRUE(frame.images[0].empty() && frame.images[1].empty());
      EXPECT_TRUE(truth.drawn[0].empty() && truth.drawn[1].empty());
    } else {
      EXPECT_FALSE(frame.images[0].empty());
    }
  }
  EXPECT_GT(dropped, 4);
  EXPECT_LT(dropped, 24);
}

// ---- Camera realism: each effect against its model.

TEST(StereoImageSim, VignettingFollowsTheCos4Falloff) {
  StereoImageSimOptions o = plain_wall();
  o.vignetting = 0.4;
  StereoImageSimulator sim = make_sim(o);
  StereoImageFrame f;
  sim.render(HandPose{}, kHeadRest, 0, f);
  const PinholeCamera& k = sim.rig().camera;
  // Relative illumination 1 - 0.4 (1 - cos^4 theta), theta off the optical axis.
  auto model = [&](int x, int y) {
    const double xn = (x - k.cx_px) / k.fx_px, yn = (y - k.cy_px) / k.fy_px;
    const double cos2 = 1.0 / (1.0 + xn * xn + yn * yn);
    return 1.0 - 0.4 * (1.0 - cos2 * cos2);
  };
  double worst = 0.0;
  for (std::size_t c = 0; c < 2; ++c) {
    for (int y = 0; y < k.height_px; y += 13) {
      for (int x = 0; x < k.width_px; x += 17) {
        const cv::Vec3b p = f.images[c].at<cv::Vec3b>(y, x);
        for (int ch = 0; ch < 3; ++ch) worst = std::max(worst, std::abs(p[ch] - 128.0 * model(x, y)));
      }
    }
  }
  EXPECT_LE(worst, 0.51);  // rounding to 8 bits
  const cv::Vec3b centre = f.images[0].at<cv::Vec3b>(360, 640);
  const cv::Vec3b corner = f.images[0].at<cv::Vec3b>(0, 0);
  const double ratio = static_cast<double>(corner[1]) / centre[1];
  EXPECT_NEAR(ratio, model(0, 0) / model(640, 360), 0.01);
  EXPECT_LT(ratio, 0.7);
  std::printf("[ image sim ] vignetting 0.4: corner / centre %.3f (model %.3f)\n", ratio,
              model(0, 0) / model(640, 360));
}

TEST(StereoImageSim, IlluminationGradientIsALinearRampInItsSessionDirection) {
  StereoImageSimOptions o = plain_wall();
  o.illumination_gradient = 0.2;
  StereoImageSimulator sim = make_sim(o);
  StereoImageFrame f;
  sim.render(HandPose{}, kHeadRest, 0, f);
  const PinholeCamera& k = sim.rig().camera;
  const double a = sim.look().gradient_angle_rad;
  auto model = [&](int x, int y) {
    return 1.0 +
           0.2 * ((x - k.cx_px) / (0.5 * k.width_px) * std::cos(a) + (y - k.cy_px) / (0.5 * k.height_px) * std::sin(a));
  };
  double worst = 0.0;
  for (std::size_t c = 0; c < 2; ++c) {
    for (int y = 0; y < k.height_px; y += 13) {
      for (int x = 0; x < k.width_px; x += 17) {
        const cv::Vec3b p = f.images[c].at<cv::Vec3b>(y, x);
        for (int ch = 0; ch < 3; ++ch) worst = std::max(worst, std::abs(p[ch] - 128.0 * model(x, y)));
      }
    }
  }
  EXPECT_LE(worst, 0.51);
  // Across the image, along the ramp: about +-20 % at the edges' middles.
  const double span =
      std::abs(model(k.width_px - 1, 360) - model(0, 360)) + std::abs(model(640, k.height_px - 1) - model(640, 0));
  EXPECT_GT(span, 0.39);
}

TEST(StereoImageSim, ColourCastShiftsTheChannelsOfTheWholeSceneMarkersIncluded) {
  StereoImageSimOptions o = plain_wall();
  o.colour_cast = 0.05;
  StereoImageSimulator cast = make_sim(o);
  StereoImageSimulator neutral = make_sim(plain_wall());
  const std::array<double, 3> gain = cast.look().colour_gain_bgr;
  EXPECT_EQ(gain[1], 1.0);  // green is the reference
  for (int ch : {0, 2}) EXPECT_LE(std::abs(gain[ch] - 1.0), 0.05);
  EXPECT_GT(std::abs(gain[0] - 1.0) + std::abs(gain[2] - 1.0), 0.005);
  // A grey wall's channel means move by the cast.
  StereoImageFrame f;
  cast.render(HandPose{}, kHeadRest, 0, f);
  const cv::Scalar mean = cv::mean(f.images[0]);
  for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(mean[ch], 128.0 * gain[ch], 0.51) << "channel " << ch;
  std::printf("[ image sim ] colour cast: grey wall B G R means %.2f %.2f %.2f (gains %.4f 1 %.4f)\n", mean[0], mean[1],
              mean[2], gain[0], gain[2]);
  // The hand and its markers too: every pixel is the neutral one times the
  // channel's gain (to rounding; unless clipped).
  std::size_t marker_pixels = 0;
  for (const HandMotionFrame& m : motion_frames(2)) {
    StereoImageFrame a, b;
    StereoImageTruth truth;
    cast.render(m.pose, m.T_world_head, m.time_ns, a, &truth);
    neutral.render(m.pose, m.T_world_head, m.time_ns, b);
    for (std::size_t c = 0; c < 2; ++c) {
      double worst = 0.0;
      for (int y = 0; y < a.images[c].rows; ++y) {
        for (int x = 0; x < a.images[c].cols; ++x) {
          const cv::Vec3b p = a.images[c].at<cv::Vec3b>(y, x), q = b.images[c].at<cv::Vec3b>(y, x);
          for (int ch = 0; ch < 3; ++ch) {
            const double expect = q[ch] * gain[ch];
            if (expect < 254.5) worst = std::max(worst, std::abs(p[ch] - expect));
          }
        }
      }
      EXPECT_LE(worst, 1.0);
      for (const MarkerImageTruth& d : truth.drawn[c]) marker_pixels += static_cast<std::size_t>(d.area_px2);
    }
  }
  EXPECT_GT(marker_pixels, 1000u);
}

TEST(StereoImageSim, LensResidualMovesImagePointsByItsDistortionWhileTheTruthStaysIdeal) {
  StereoImageSimOptions o = plain_wall();
  o.distractors = 60;
  StereoImageSimulator ideal = make_sim(o);
  // Ten times the default sigmas, so the shifts are several pixels.
  o.lens_residual = true;
  o.residual_k1_sigma = 0.01;
  o.residual_k2_sigma = 0.005;
  o.residual_p_sigma = 0.003;
  StereoImageSimulator warped = make_sim(o);
  const PinholeCamera& k = ideal.rig().camera;
  StereoImageFrame fi, fw;
  StereoImageTruth ti, tw;
  ideal.render(HandPose{}, kHeadRest, 0, fi, &ti);
  warped.render(HandPose{}, kHeadRest, 0, fw, &tw);
  std::size_t checked = 0;
  double max_shift = 0.0, max_err = 0.0;
  for (std::size_t c = 0; c < 2; ++c) {
    const LensResidual& lens = warped.look().lens[c];
    ASSERT_FALSE(lens.zero());
    // The truth is the ideal pinhole's, untouched by the lens.
    ASSERT_EQ(ti.distractors[c].size(), tw.distractors[c].size());
    for (std::size_t i = 0; i < ti.distractors[c].size(); ++i) {
      EXPECT_EQ(ti.distractors[c][i].u_px, tw.distractors[c][i].u_px);
      EXPECT_EQ(ti.distractors[c][i].v_px, tw.distractors[c][i].v_px);
    }
    // The wall is grey 128: a disc's weight is its colour's distance from it,
    // linear in coverage, so the weighted centroid is the disc's.
    for (const DistractorImageTruth& d : ti.distractors[c]) {
      if (d.area_px2 < 30.0 || d.area_px2 < 0.999 * d.unoccluded_area_px2) continue;
      const double half = std::sqrt(d.area_px2 / M_PI) + 3.0;
      const bool isolated =
          std::all_of(ti.distractors[c].begin(), ti.distractors[c].end(), [&](const DistractorImageTruth& e) {
            return &e == &d || std::hypot(e.u_px - d.u_px, e.v_px - d.v_px) >
                                   2.0 * half + std::sqrt(e.unoccluded_area_px2 / M_PI) + 12.0;
          });
      if (!isolated) continue;
      auto grey_distance = [](const cv::Mat& img) {
        return [&img](int x, int y) {
          const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
          return std::abs(p[0] - 128.0) + std::abs(p[1] - 128.0) + std::abs(p[2] - 128.0);
        };
      };
      Moments mi, mw;
      if (!window_moments(fi.images[c], {d.u_px, d.v_px}, half, grey_distance(fi.images[c]), mi)) continue;
      const Eigen::Vector2d expected = lens.distort_px(k, mi.mean().x(), mi.mean().y());
      if (!window_moments(fw.images[c], expected, half, grey_distance(fw.images[c]), mw)) continue;
      ++checked;
      max_shift = std::max(max_shift, (expected - mi.mean()).norm());
      max_err = std::max(max_err, (mw.mean() - expected).norm());
      EXPECT_LT((mw.mean() - expected).norm(), 0.1) << "camera " << c << " distractor " << d.distractor;
    }
  }
  EXPECT_GE(checked, 15u);
  EXPECT_GT(max_shift, 3.0);
  std::printf("[ image sim ] lens residual: %zu discs moved by up to %.2f px, measured vs model within %.3f px\n",
              checked, max_shift, max_err);
  // The default residual: about a pixel at the corners, nothing at the centre.
  StereoImageSimOptions d = plain_wall();
  d.lens_residual = true;
  StereoImageSimulator def = make_sim(d);
  for (std::size_t c = 0; c < 2; ++c) {
    const LensResidual& lens = def.look().lens[c];
    const double corner = lens.corner_shift_px(k);
    EXPECT_GT(corner, 0.2);
    EXPECT_LT(corner, 5.0);
    EXPECT_LT((lens.distort_px(k, k.cx_px, k.cy_px) - Eigen::Vector2d(k.cx_px, k.cy_px)).norm(), 1e-12);
    const Eigen::Vector2d back = lens.undistort_px(k, 3.0, 5.0);
    EXPECT_LT((lens.distort_px(k, back.x(), back.y()) - Eigen::Vector2d(3.0, 5.0)).norm(), 1e-9);
    std::printf(
        "[ image sim ] default lens residual, camera %zu: k1 %.5f k2 %.5f p1 %.5f p2 %.5f, corner shift %.2f px\n", c,
        lens.k1, lens.k2, lens.p1, lens.p2, corner);
  }
}

TEST(StereoImageSim, MotionBlurSmearsMarkersAlongTheirImageMotionOverTheExposure) {
  StereoImageSimOptions o = plain_wall();
  o.motion_blur = true;
  o.exposure_s = 0.008;
  o.timestamp_in_exposure = 0.5;  // mid-exposure stamp: the smear is centred on the truth
  StereoImageSimulator sim = make_sim(o);
  o.timestamp_in_exposure = 0.0;  // start-of-exposure stamp
  StereoImageSimulator soe = make_sim(o);
  const StereoRig& rig = sim.rig();
  const std::size_t marker_count = sim.marker_simulator().markers().size();
  const std::vector<bool> hide_all(marker_count, true);
  auto reach = [](const MarkerImageTruth& d) {  // half the extent of its smeared image, generously
    return 2.0 * std::sqrt(d.unoccluded_area_px2 / M_PI) + 0.5 * std::hypot(d.blur_u_px, d.blur_v_px) + 2.0;
  };
  std::size_t blurs = 0, shifts = 0, smears = 0;
  double worst_elongation = 0.0;
  for (const HandMotionFrame& m : motion_frames(3)) {
    // The whole hand translating at a known velocity (0.8, 0.4, 0.2) m/s in
    // the left camera's axes; no rotation.
    const Pose T_world_lc = sim.marker_simulator().T_world_leftcam(m.T_world_head);
    const Vec3 v_lc(0.8, 0.4, 0.2);
    HandPose moving = m.pose;
    moving.has_velocity = true;
    for (std::size_t j = 0; j < kHandJointCount; ++j) {
      moving.linear_velocity_in_world[j] = T_world_lc.q * v_lc;
      moving.angular_velocity_in_world[j].setZero();
    }
    HandPose still = m.pose;
    still.has_velocity = false;
    StereoImageFrame fm, fe;
    StereoImageTruth tm, te;
    sim.render(moving, m.T_world_head, m.time_ns, fm, &tm);
    soe.render(moving, m.T_world_head, m.time_ns, fe, &te);
    for (std::size_t c = 0; c < 2; ++c) {
      for (std::size_t i = 0; i < tm.drawn[c].size(); ++i) {
        const MarkerImageTruth& dm = tm.drawn[c][i];
        // The smear: the image motion of the centre over the exposure,
        // d(u, v) = f (v_xy z - p_xy v_z) / z^2 * exposure to first order.
        const Vec3 p = tm.markers.cameras[c][i].p_in_leftcam - Vec3(c == 1 ? rig.baseline_m : 0.0, 0.0, 0.0);
        const Eigen::Vector2d expected(
            rig.camera.fx_px * (v_lc.x() * p.z() - p.x() * v_lc.z()) / (p.z() * p.z()) * 0.008,
            rig.camera.fy_px * (v_lc.y() * p.z() - p.y() * v_lc.z()) / (p.z() * p.z()) * 0.008);
        const Eigen::Vector2d blur(dm.blur_u_px, dm.blur_v_px);
        EXPECT_LT((blur - expected).norm(), 0.02 * expected.norm() + 0.02) << "marker " << dm.marker;
        ++blurs;
        // Stamped at the start of the exposure, the marker shows half a smear later.
        const MarkerImageTruth& de = te.drawn[c][i];
        if (dm.visible_fraction() > 0.999 && de.visible_fraction() > 0.999 && dm.area_px2 > 40.0) {
          const Eigen::Vector2d shift(de.u_drawn_px - dm.u_drawn_px, de.v_drawn_px - dm.v_drawn_px);
          EXPECT_LT((shift - 0.5 * blur).norm(), 0.03 * blur.norm() + 0.1) << "marker " << dm.marker;
          ++shifts;
        }
      }
    }
    // In the pixels: a spread-out subset of the markers (the rest hidden),
    // each measured against the same image without markers, moving and still.
    std::vector<bool> hide_others(marker_count, true);
    std::vector<const MarkerImageTruth*> chosen;
    std::vector<const MarkerImageTruth*> by_size;
    for (const MarkerImageTruth& d : tm.drawn[0]) by_size.push_back(&d);
    std::sort(by_size.begin(), by_size.end(), [](auto* a, auto* b) { return a->area_px2 > b->area_px2; });
    for (const MarkerImageTruth* d : by_size) {
      if (d->visible_fraction() < 0.999 || d->area_px2 < 40.0) continue;
      const bool apart = std::all_of(chosen.begin(), chosen.end(), [&](const MarkerImageTruth* e) {
        return std::max(std::abs(e->u_drawn_px - d->u_drawn_px), std::abs(e->v_drawn_px - d->v_drawn_px)) >
               reach(*d) + reach(*e) + 1.0;
      });
      if (!apart) continue;
      chosen.push_back(d);
      hide_others[d->marker] = false;
    }
    StereoImageFrame fm_sub, fm_bg, fs_sub, fs_bg;
    StereoImageTruth tm_sub, ts_sub, scratch;
    sim.render(moving, m.T_world_head, m.time_ns, fm_sub, &tm_sub, &hide_others);
    sim.render(moving, m.T_world_head, m.time_ns, fm_bg, &scratch, &hide_all);
    sim.render(still, m.T_world_head, m.time_ns, fs_sub, &ts_sub, &hide_others);
    sim.render(still, m.T_world_head, m.time_ns, fs_bg, &scratch, &hide_all);
    for (std::size_t c = 0; c < 2; ++c) {
      ASSERT_EQ(tm_sub.drawn[c].size(), ts_sub.drawn[c].size());
      for (std::size_t i = 0; i < tm_sub.drawn[c].size(); ++i) {
        const MarkerImageTruth& dm = tm_sub.drawn[c][i];
        const MarkerImageTruth& ds = ts_sub.drawn[c][i];
        EXPECT_EQ(ds.blur_u_px, 0.0);
        if (dm.visible_fraction() < 0.999 || ds.visible_fraction() < 0.999 || dm.area_px2 < 40.0) continue;
        const bool isolated =
            std::all_of(tm_sub.drawn[c].begin(), tm_sub.drawn[c].end(), [&](const MarkerImageTruth& e) {
              return &e == &dm || e.area_px2 <= 0.0 ||
                     std::max(std::abs(e.u_drawn_px - dm.u_drawn_px), std::abs(e.v_drawn_px - dm.v_drawn_px)) >
                         reach(dm) + reach(e) + 1.0;
            });
        if (!isolated) continue;
        const Eigen::Vector2d blur(dm.blur_u_px, dm.blur_v_px);
        // Its colour: the still marker's centre pixel (all marker; without
        // rotation it keeps its shade over the exposure). Weights: coverage.
        const cv::Vec3b centre = fs_sub.images[c].at<cv::Vec3b>(static_cast<int>(std::lround(ds.v_drawn_px)),
                                                                static_cast<int>(std::lround(ds.u_drawn_px)));
        const cv::Vec3d top(centre[0], centre[1], centre[2]);
        Moments mm, ms;
        if (!window_moments(
                fm_sub.images[c], {dm.u_drawn_px, dm.v_drawn_px}, reach(dm),
                [&](int x, int y) { return coverage_of(top, fm_sub.images[c], fm_bg.images[c], x, y); }, mm) ||
            !window_moments(
                fs_sub.images[c], {ds.u_drawn_px, ds.v_drawn_px}, reach(dm),
                [&](int x, int y) { return coverage_of(top, fs_sub.images[c], fs_bg.images[c], x, y); }, ms)) {
          continue;
        }
        // Coverage is conserved: the smear spreads the same disc.
        EXPECT_NEAR(mm.w, ms.w, 0.02 * ms.w + 1.0) << "marker " << dm.marker;
        ++smears;
        // Centred where the still marker is; stretched along the motion by
        // the variance of a uniform smear of its length, L^2 / 12, and not across.
        EXPECT_LT((mm.mean() - ms.mean()).norm(), 0.1) << "marker " << dm.marker;
        const Eigen::Vector2d along = blur.normalized();
        const Eigen::Vector2d across(-along.y(), along.x());
        const Eigen::Matrix2d dc = mm.cov() - ms.cov();
        const double added = along.dot(dc * along);
        const double model = blur.squaredNorm() / 12.0;
        worst_elongation = std::max(worst_elongation, std::abs(added / model - 1.0));
        EXPECT_NEAR(added, model, 0.03 * model + 0.1) << "marker " << dm.marker << ", smear " << blur.norm() << " px";
        EXPECT_LT(std::abs(across.dot(dc * across)), 0.02 * model + 0.15) << "marker " << dm.marker;
      }
    }
  }
  EXPECT_GT(blurs, 40u);
  EXPECT_GT(shifts, 20u);
  EXPECT_GE(smears, 5u);
  std::printf(
      "[ image sim ] motion blur: %zu smears measured in pixels, added variance along the motion within %.1f %% "
      "of L^2/12\n",
      smears, 100.0 * worst_elongation);
}

TEST(StereoImageSim, SensorNoiseVarianceGrowsWithTheSignalAtTheGain) {
  // A grey wall under strong vignetting and a gradient: a range of levels.
  StereoImageSimOptions o = plain_wall();
  o.vignetting = 0.7;
  o.illumination_gradient = 0.5;
  StereoImageSimulator clean = make_sim(o);
  o.sensor_noise = true;
  o.sensor_gain_dn_per_e = 0.2;
  o.pixel_noise_dn = 1.5;  // the read noise
  StereoImageSimulator noisy = make_sim(o);
  o.light_level = 0.5;  // half the light: twice the gain
  StereoImageSimulator dim = make_sim(o);
  StereoImageFrame fc, fn, fd;
  clean.render(HandPose{}, kHeadRest, 5, fc);
  noisy.render(HandPose{}, kHeadRest, 5, fn);
  dim.render(HandPose{}, kHeadRest, 5, fd);
  // Variance of the noise per level, and its straight line: slope K, intercept read^2 + 1/12 (rounding).
  auto fit = [&](const cv::Mat& noisy_img) {
    std::array<double, 256> n{}, s1{}, s2{};
    const cv::Mat& a = fc.images[0];
    for (int y = 0; y < a.rows; ++y) {
      const std::uint8_t* pa = a.ptr<std::uint8_t>(y);
      const std::uint8_t* pb = noisy_img.ptr<std::uint8_t>(y);
      for (int x = 0; x < 3 * a.cols; ++x) {
        const double d = static_cast<double>(pb[x]) - pa[x];
        n[pa[x]] += 1.0;
        s1[pa[x]] += d;
        s2[pa[x]] += d * d;
      }
    }
    double sw = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
    int levels = 0, lo = 255, hi = 0;
    for (int level = 20; level < 230; ++level) {
      if (n[level] < 2000.0) continue;
      const double mean = s1[level] / n[level];
      const double var = s2[level] / n[level] - mean * mean;
      sw += 1.0;
      sx += level;
      sy += var;
      sxx += level * level;
      sxy += level * var;
      ++levels;
      lo = std::min(lo, level);
      hi = std::max(hi, level);
    }
    const double slope = (sw * sxy - sx * sy) / (sw * sxx - sx * sx);
    const double intercept = (sy - slope * sx) / sw;
    std::printf("[ image sim ] noise variance vs level %d-%d (%d levels): slope %.4f DN/e-, intercept %.3f DN^2\n", lo,
                hi, levels, slope, intercept);
    EXPECT_GT(hi - lo, 80);
    return std::make_pair(slope, intercept);
  };
  const auto [k1, r1] = fit(fn.images[0]);
  EXPECT_NEAR(k1, 0.2, 0.01);
  EXPECT_NEAR(r1, 1.5 * 1.5 + 1.0 / 12.0, 0.4);
  const auto [k2, r2] = fit(fd.images[0]);
  EXPECT_NEAR(k2, 0.4, 0.02);
  EXPECT_NEAR(r2, 3.0 * 3.0 + 1.0 / 12.0, 0.8);
}

TEST(StereoImageSim, GlossyMarkersShowAHighlightWhereTheDomeNormalBisectsLightAndView) {
  StereoImageSimOptions o = clean_options();
  o.clutter = false;
  StereoImageSimulator matte = make_sim(o);
  o.specular = 1.0;
  o.marker_gloss_spread = 0.0;
  StereoImageSimulator glossy = make_sim(o);
  const StereoRig& rig = glossy.rig();
  const Vec3 light = o.light_dir_in_leftcam.normalized();
  std::size_t checked = 0, highlighted_drawn = 0;
  double worst = 0.0;
  HandMotionOptions mo;
  mo.seed = 3;
  HandMotionGenerator gen(HandModel(subject_shape()), mo);
  for (int k = 0; k < 40 && checked < 6; ++k) {
    const HandMotionFrame m = gen.sample(k * 250'000'000LL);
    StereoImageFrame fg, fm;
    StereoImageTruth tg, tm;
    glossy.render(m.pose, m.T_world_head, m.time_ns, fg, &tg);
    bool any = false;
    for (std::size_t c = 0; c < 2; ++c) {
      for (const MarkerImageTruth& d : tg.drawn[c]) any = any || d.highlight > 0.5;
    }
    if (!any) continue;
    matte.render(m.pose, m.T_world_head, m.time_ns, fm, &tm);
    for (std::size_t c = 0; c < 2; ++c) {
      for (std::size_t i = 0; i < tg.drawn[c].size(); ++i) {
        const MarkerImageTruth& d = tg.drawn[c][i];
        EXPECT_EQ(tm.drawn[c][i].highlight, 0.0);
        if (d.highlight > 0.5) ++highlighted_drawn;
        if (d.highlight < 0.5 || d.visible_fraction() < 0.999 || d.area_px2 < 80.0) continue;
        // Where the dome's normal is the bisector h of the directions to the
        // light and to the camera: offset R (h - (h.n) n) from the centre.
        const PlacedMarker& pm = glossy.marker_simulator().markers()[d.marker];
        const double r = 0.5 * pm.diameter_m;
        const Vec3 centre = tg.markers.cameras[c][i].p_in_leftcam - Vec3(c == 1 ? rig.baseline_m : 0.0, 0.0, 0.0);
        const Vec3 n = d.normal_in_leftcam;
        Vec3 off = Vec3::Zero();
        for (int it = 0; it < 5; ++it) {
          const Vec3 h = (light - (centre + off).normalized()).normalized();
          off = o.marker_dome_radius_m * (h - h.dot(n) * n);
        }
        if (off.norm() > 0.7 * r) continue;  // near the rim: cut by the disc's edge
        const Vec3 spot = centre + off;
        const Eigen::Vector2d predicted(rig.camera.fx_px * spot.x() / spot.z() + rig.camera.cx_px,
                                        rig.camera.fy_px * spot.y() / spot.z() + rig.camera.cy_px);
        // The highlight in the pixels: what the glossy image adds to the
        // matte one, within the marker; its peak (clipped at white, so the
        // centroid of the pixels above half the peak) and its brightest pixel.
        const double half = std::sqrt(d.area_px2 / M_PI);
        const int x0 = static_cast<int>(d.u_drawn_px - half), x1 = static_cast<int>(d.u_drawn_px + half);
        const int y0 = static_cast<int>(d.v_drawn_px - half), y1 = static_cast<int>(d.v_drawn_px + half);
        double best = -1.0;
        Eigen::Vector2d at = Eigen::Vector2d::Zero();
        for (int y = y0; y <= y1; ++y) {
          for (int x = x0; x <= x1; ++x) {
            const double gain = abs_diff(fg.images[c], fm.images[c], x, y);
            if (gain > best) {
              best = gain;
              at = {static_cast<double>(x), static_cast<double>(y)};
            }
          }
        }
        Moments peak_spot;
        for (int y = y0; y <= y1; ++y) {
          for (int x = x0; x <= x1; ++x) {
            const double gain = abs_diff(fg.images[c], fm.images[c], x, y);
            if (gain >= 0.5 * best) peak_spot.add(gain, x, y);
          }
        }
        ++checked;
        const double miss = (peak_spot.mean() - predicted).norm();
        worst = std::max(worst, miss);
        EXPECT_LT(miss, 0.8) << "marker " << d.marker << " camera " << c;
        // Near-white there, against the matte marker's saturated colour.
        const cv::Vec3b shiny = hsv_full_at(fg.images[c], at.x(), at.y());
        const cv::Vec3b plain = hsv_full_at(fm.images[c], at.x(), at.y());
        EXPECT_LT(shiny[1], 110) << "marker " << d.marker;
        EXPECT_GT(shiny[2], 220) << "marker " << d.marker;
        EXPECT_GT(plain[1], 180) << "marker " << d.marker;
      }
    }
  }
  EXPECT_GE(checked, 4u);
  std::printf("[ image sim ] highlights: %zu drawn, %zu checked, peak within %.2f px of the dome's bisector point\n",
              highlighted_drawn, checked, worst);
}

TEST(StereoImageSim, EachCameraEffectDrawsFromItsOwnStream) {
  const StereoImageSimOptions all = plain_wall();
  auto with_all = [&] {
    StereoImageSimOptions o = all;
    o.lens_residual = true;
    o.vignetting = 0.4;
    o.illumination_gradient = 0.1;
    o.colour_cast = 0.04;
    o.specular = 0.8;
    o.motion_blur = true;
    o.sensor_noise = true;
    return o;
  };
  const StereoImageSimulator ref = make_sim(with_all());
  const CameraLook& a = ref.look();
  // Switching any one effect off leaves the others' draws as they were.
  for (int off = 0; off < 5; ++off) {
    StereoImageSimOptions o = with_all();
    switch (off) {
      case 0: o.lens_residual = false; break;
      case 1: o.colour_cast = 0.0; break;
      case 2: o.specular = 0.0; break;
      case 3: o.motion_blur = false; break;
      default: o.sensor_noise = false; break;
    }
    const StereoImageSimulator sim = make_sim(o);
    const CameraLook& b = sim.look();
    for (std::size_t c = 0; c < 2; ++c) {
      if (off == 0) {
        EXPECT_TRUE(b.lens[c].zero());
      } else {
        EXPECT_EQ(b.lens[c].k1, a.lens[c].k1);
        EXPECT_EQ(b.lens[c].p2, a.lens[c].p2);
      }
    }
    if (off != 1) {
      EXPECT_EQ(b.colour_gain_bgr, a.colour_gain_bgr);
    }
    EXPECT_EQ(b.gradient_angle_rad, a.gradient_angle_rad);
    EXPECT_EQ(b.marker_gloss, a.marker_gloss);
    EXPECT_EQ(sim.distractors().size(), ref.distractors().size());
  }
  // The left and right lenses differ (each camera its own residual).
  EXPECT_NE(a.lens[0].k1, a.lens[1].k1);
}
