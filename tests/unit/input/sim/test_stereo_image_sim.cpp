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

// Exact pixels: no blur, no noise, no exposure change.
StereoImageSimOptions clean_options() {
  StereoImageSimOptions o;
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

}  // namespace

TEST(StereoImageSimOptions, DefaultsValidateAndDescribeNamesTheSeed) {
  StereoImageSimOptions o;
  EXPECT_TRUE(o.validate().ok());
  o.seed = 4242;
  EXPECT_NE(o.describe().find("seed=4242"), std::string::npos) << o.describe();
  EXPECT_NE(o.describe().find("noise=2.00DN"), std::string::npos) << o.describe();
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
