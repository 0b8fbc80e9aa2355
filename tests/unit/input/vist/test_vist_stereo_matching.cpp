// VIST left-right stereo matching (Lee 2021, §4.3.3): hand-made geometry,
// robustness to bad blobs, and accuracy against the stereo simulator.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/random.hpp"
#include "proprio/sim/hand_motion.hpp"
#include "proprio/sim/stereo_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "proprio/vist/stereo_matching.hpp"
#include "support/stereo.hpp"

using namespace proprio;
using namespace proprio::vist;

namespace {

using proprio::testing_support::test_rig;

Marker project(const StereoRig& rig, const Vec3& p_in_leftcam, bool right, std::uint8_t hue = 0,
               float area = 100.0f) {
  const PinholeCamera& c = rig.camera;
  const double x = right ? p_in_leftcam.x() - rig.baseline_m : p_in_leftcam.x();
  Marker m;
  m.hue = hue;
  m.u_px = static_cast<float>(c.fx_px * x / p_in_leftcam.z() + c.cx_px);
  m.v_px = static_cast<float>(c.fy_px * p_in_leftcam.y() / p_in_leftcam.z() + c.cy_px);
  m.area_px2 = area;
  return m;
}

StereoMatcher make_matcher(StereoMatchOptions o = {}) {
  auto m = StereoMatcher::create(test_rig(), o);
  EXPECT_TRUE(m.ok());
  return std::move(m).value();
}

// Float pixels cannot hold the exact projection; rebuild the point from the
// stored pixels to compare at 1e-9.
Vec3 from_pixels(const StereoRig& rig, const Marker& l, const Marker& r) {
  return StereoMatcher::triangulate(rig, l.u_px, l.v_px, r.u_px, r.v_px);
}

TEST(VistStereoMatching, ThreePointsOfOneHueTriangulateExactly) {
  const StereoRig rig = test_rig();
  const std::vector<Vec3> pts = {{0.02, -0.03, 0.30}, {-0.05, 0.01, 0.45}, {0.08, 0.06, 0.60}};
  MarkerObservations left, right;
  for (const Vec3& p : pts) left.markers.push_back(project(rig, p, false));
  // Right in another order: the matcher must not rely on it.
  for (std::size_t k : {2u, 0u, 1u}) right.markers.push_back(project(rig, pts[k], true));
  StereoMatcher matcher = make_matcher();
  std::vector<StereoPoint> out;
  const StereoMatchStats& st = matcher.match(left, right, out);
  ASSERT_EQ(out.size(), 3u) << "dist " << st.rejected_distance << " ratio " << st.rejected_ratio;
  const std::size_t right_of[3] = {1, 2, 0};
  for (const StereoPoint& s : out) {
    EXPECT_EQ(s.hue, MarkerHue::red);
    EXPECT_EQ(s.right_index, right_of[s.left_index]);
    const Vec3 expect = from_pixels(rig, left.markers[s.left_index], right.markers[s.right_index]);
    EXPECT_NEAR((s.p_in_leftcam - expect).norm(), 0.0, 1e-9);
    // And the float pixels are within 1e-4 px of the truth: the point within a few micrometres.
    EXPECT_NEAR((s.p_in_leftcam - pts[s.left_index]).norm(), 0.0, 2e-5);
    EXPECT_GT(s.posterior, 0.99);
    EXPECT_TRUE(s.cov_p_in_leftcam.isApprox(s.cov_p_in_leftcam.transpose()));
    EXPECT_GT(s.cov_p_in_leftcam(2, 2), s.cov_p_in_leftcam(0, 0));  // depth is the weak axis
  }
}

TEST(VistStereoMatching, TriangulationFormulasAndCovariance) {
  const StereoRig rig = test_rig();
  // Exact doubles: d = 100 px -> z = 640 * 0.063 / 100.
  const Vec3 p = StereoMatcher::triangulate(rig, 739.5, 459.5, 639.5, 459.5);
  EXPECT_NEAR(p.z(), 0.4032, 1e-12);
  EXPECT_NEAR(p.x(), 100.0 * 0.4032 / 640.0, 1e-12);
  EXPECT_NEAR(p.y(), 100.0 * 0.4032 / 623.5, 1e-12);
  // Covariance against central differences of triangulate().
  const double u[4] = {739.5, 639.5, 459.5, 459.5};  // u_l, u_r, v_l, v_r
  Eigen::Matrix<double, 3, 4> J;
  for (int k = 0; k < 4; ++k) {
    double a[4], b[4];
    for (int q = 0; q < 4; ++q) a[q] = b[q] = u[q];
    a[k] += 1e-4;
    b[k] -= 1e-4;
    J.col(k) = (StereoMatcher::triangulate(rig, a[0], a[2], a[1], a[3]) -
                StereoMatcher::triangulate(rig, b[0], b[2], b[1], b[3])) /
               2e-4;
  }
  const Mat3 expect = 0.25 * J * J.transpose();
  const Mat3 cov = StereoMatcher::triangulation_covariance(rig, 739.5, 459.5, 639.5, 459.5, 0.5);
  EXPECT_LT((cov - expect).norm(), 1e-9);
  // Depth sigma = z^2 / (fx b) * sqrt(2) sigma_px.
  EXPECT_NEAR(std::sqrt(cov(2, 2)), 0.4032 * 0.4032 / (640.0 * 0.063) * std::sqrt(2.0) * 0.5, 1e-9);
}

TEST(VistStereoMatching, OptionsAndRigValidate) {
  EXPECT_TRUE(StereoMatchOptions{}.validate().ok());
  EXPECT_FALSE(StereoMatchOptions{}.describe().empty());
  StereoMatchOptions o;
  o.outlier_weight = 1.0;
  EXPECT_FALSE(o.validate().ok());
  o = {};
  o.pixel_noise_px = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(o.validate().ok());
  o = {};
  o.min_depth_m = 2.0;
  EXPECT_FALSE(StereoMatcher::create(test_rig(), o).ok());
  StereoRig rig = test_rig();
  rig.baseline_m = 0.0;
  EXPECT_FALSE(StereoMatcher::create(rig, {}).ok());
}

TEST(VistStereoRobustness, EmptyAndOneSidedInputs) {
  const StereoRig rig = test_rig();
  StereoMatcher matcher = make_matcher();
  std::vector<StereoPoint> out;
  MarkerObservations empty, some;
  some.markers.push_back(project(rig, {0.0, 0.0, 0.4}, false));
  EXPECT_EQ(matcher.match(empty, empty, out).matched, 0u);
  EXPECT_TRUE(out.empty());
  EXPECT_EQ(matcher.match(some, empty, out).left_without_candidate, 1u);
  EXPECT_TRUE(out.empty());
  EXPECT_EQ(matcher.match(empty, some, out).matched, 0u);
  EXPECT_TRUE(out.empty());
}

TEST(VistStereoRobustness, NonFiniteAndForeignHueBlobsAreRejectedAndCounted) {
  const StereoRig rig = test_rig();
  MarkerObservations left, right;
  const Vec3 p(0.01, 0.02, 0.4);
  left.markers.push_back(project(rig, p, false, 85));
  right.markers.push_back(project(rig, p, true, 85));
  Marker nan_blob = left.markers[0];
  nan_blob.u_px = std::numeric_limits<float>::quiet_NaN();
  left.markers.push_back(nan_blob);
  Marker inf_blob = right.markers[0];
  inf_blob.v_px = std::numeric_limits<float>::infinity();
  right.markers.push_back(inf_blob);
  Marker purple = left.markers[0];
  purple.hue = 213;  // 300 deg: no glove hue
  left.markers.push_back(purple);
  StereoMatcher matcher = make_matcher();
  std::vector<StereoPoint> out;
  const StereoMatchStats& st = matcher.match(left, right, out);
  EXPECT_EQ(st.rejected_non_finite, 2u);
  EXPECT_EQ(st.rejected_hue, 1u);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].hue, MarkerHue::green);
  EXPECT_EQ(out[0].left_index, 0u);
  EXPECT_EQ(out[0].right_index, 0u);
  EXPECT_TRUE(out[0].p_in_leftcam.allFinite());
}

TEST(VistStereoRobustness, DuplicatesNeverShareABlob) {
  const StereoRig rig = test_rig();
  MarkerObservations left, right;
  const Vec3 p(0.0, 0.0, 0.4);
  left.markers = {project(rig, p, false), project(rig, p, false)};  // the detector reported one blob twice
  right.markers = {project(rig, p, true)};
  StereoMatcher matcher = make_matcher();
  std::vector<StereoPoint> out;
  matcher.match(left, right, out);
  // Two identical left blobs for one right blob are ambiguous: the ratio test refuses both.
  EXPECT_TRUE(out.empty());
  // Duplicated on both sides: still at most one use of every blob.
  right.markers.push_back(right.markers[0]);
  matcher.match(left, right, out);
  std::set<std::uint32_t> used_l, used_r;
  for (const StereoPoint& s : out) {
    EXPECT_TRUE(used_l.insert(s.left_index).second);
    EXPECT_TRUE(used_r.insert(s.right_index).second);
  }
}

TEST(VistStereoRobustness, GatesRejectImpossiblePairs) {
  const StereoRig rig = test_rig();
  StereoMatcher matcher = make_matcher();
  std::vector<StereoPoint> out;
  MarkerObservations left, right;
  // Different rows (10 px apart).
  left.markers = {project(rig, {0.0, 0.0, 0.4}, false)};
  right.markers = {project(rig, {0.0, 0.0, 0.4}, true)};
  right.markers[0].v_px += 10.0f;
  EXPECT_EQ(matcher.match(left, right, out).left_without_candidate, 1u);
  // Too far (3 m) and behind the baseline (negative disparity).
  left.markers = {project(rig, {0.0, 0.0, 3.0}, false), project(rig, {0.0, 0.1, 0.4}, false)};
  right.markers = {project(rig, {0.0, 0.0, 3.0}, true), project(rig, {0.0, 0.1, 0.4}, true)};
  std::swap(left.markers[1].u_px, right.markers[1].u_px);
  EXPECT_EQ(matcher.match(left, right, out).left_without_candidate, 2u);
  // Area mismatch (factor 5).
  left.markers = {project(rig, {0.0, 0.0, 0.4}, false, 0, 100.0f)};
  right.markers = {project(rig, {0.0, 0.0, 0.4}, true, 0, 20.0f)};
  EXPECT_EQ(matcher.match(left, right, out).left_without_candidate, 1u);
  EXPECT_TRUE(out.empty());
}

// ---------------------------------------------------------------------------
// Against the stereo simulator.

struct SessionScore {
  std::size_t frames = 0;
  std::size_t output = 0;
  std::size_t correct = 0;
  std::size_t stereo_visible = 0;
  std::size_t distractors_in = 0;
  std::size_t distractors_matched = 0;
  double err_sum_m = 0.0;
  double err_max_m = 0.0;
  double depth_sum_m = 0.0;
  double nees_sum = 0.0;  // e^T cov^-1 e over correct pairs: about 3 if the covariance is honest
  StereoMatchStats rejections;  // counts summed over the session
  double precision() const { return output ? static_cast<double>(correct) / static_cast<double>(output) : 1.0; }
  double recall() const {
    return stereo_visible ? static_cast<double>(correct) / static_cast<double>(stereo_visible) : 1.0;
  }
  double mean_err_m() const { return correct ? err_sum_m / static_cast<double>(correct) : 0.0; }
};

// Free motion of subject 3, 30 s at 30 Hz, 0.3 px noise. distractors > 0 adds
// that many false blobs to the left camera only, each of a glove hue on the
// row of a real left blob of that hue (the hardest place for them), at a
// random column.
SessionScore run_session(const StereoMatchOptions& mo, int distractors, std::uint64_t seed = 7) {
  const HandShape shape = *sim::sim_subject(3)->shape();
  const ImuGloveDescription glove = ImuGloveDescription::vist_default();
  sim::StereoSimOptions so;
  so.pixel_noise_px = 0.3;
  so.seed = seed;
  auto simulator = sim::StereoMarkerSimulator::create(glove, shape, so);
  EXPECT_TRUE(simulator.ok());
  sim::HandMotionOptions ho;
  ho.seed = seed;
  sim::HandMotionGenerator gen(HandModel(shape), ho);
  auto matcher = StereoMatcher::create(glove.rig, mo);
  EXPECT_TRUE(matcher.ok());
  Rng rng(seed + 1000);
  SessionScore score;
  std::vector<StereoPoint> out;
  sim::simulate_session(gen, *simulator, 30.0, [&](const sim::HandMotionFrame&, const sim::StereoFrame& f,
                                                    const sim::StereoGroundTruth& truth) {
    ++score.frames;
    MarkerObservations left = f.cameras[0];
    const std::size_t real_left = left.markers.size();
    for (int k = 0; k < distractors && real_left > 0; ++k) {
      Marker m = left.markers[static_cast<std::size_t>(rng.below(real_left))];
      m.u_px = static_cast<float>(rng.uniform(0.0, glove.rig.camera.width_px - 1.0));
      m.v_px += static_cast<float>(rng.uniform(-1.0, 1.0));
      left.markers.push_back(m);
    }
    score.distractors_in += left.markers.size() - real_left;
    const StereoMatchStats& st = matcher->match(left, f.cameras[1], out);
    score.rejections.left_without_candidate += st.left_without_candidate;
    score.rejections.rejected_distance += st.rejected_distance;
    score.rejections.rejected_ratio += st.rejected_ratio;
    score.rejections.rejected_not_mutual += st.rejected_not_mutual;
    score.rejections.em_iterations += st.em_iterations;
    score.stereo_visible += truth.stereo_count();
    for (const StereoPoint& s : out) {
      ++score.output;
      if (s.left_index >= real_left) {
        ++score.distractors_matched;
        continue;
      }
      const sim::MarkerTruth& tl = truth.cameras[0][s.left_index];
      const sim::MarkerTruth& tr = truth.cameras[1][s.right_index];
      if (tl.marker != tr.marker) continue;
      ++score.correct;
      const double e = (s.p_in_leftcam - tl.p_in_leftcam).norm();
      score.err_sum_m += e;
      score.err_max_m = std::max(score.err_max_m, e);
      score.depth_sum_m += tl.p_in_leftcam.z();
      const Vec3 err = s.p_in_leftcam - tl.p_in_leftcam;
      score.nees_sum += err.dot(s.cov_p_in_leftcam.ldlt().solve(err));
    }
  });
  return score;
}

void print(const char* name, const SessionScore& s) {
  std::printf(
      "[%s] frames %zu, stereo-visible %zu, output %zu, correct %zu: precision %.4f recall %.4f, 3D error mean "
      "%.2f mm max %.2f mm at mean depth %.3f m; distractors %zu, matched %zu\n",
      name, s.frames, s.stereo_visible, s.output, s.correct, s.precision(), s.recall(), s.mean_err_m() * 1e3,
      s.err_max_m * 1e3, s.correct ? s.depth_sum_m / static_cast<double>(s.correct) : 0.0, s.distractors_in,
      s.distractors_matched);
  std::printf("[%s] left blobs without candidate %zu, distance-rejected %zu, ratio-rejected %zu, not mutual %zu; "
              "EM iterations per frame %.1f; mean NEES %.2f (3 = consistent)\n",
              name, s.rejections.left_without_candidate, s.rejections.rejected_distance,
              s.rejections.rejected_ratio, s.rejections.rejected_not_mutual,
              static_cast<double>(s.rejections.em_iterations) / static_cast<double>(std::max<std::size_t>(s.frames, 1)),
              s.correct ? s.nees_sum / static_cast<double>(s.correct) : 0.0);
}

TEST(VistStereoSimulation, FreeMotionPrecisionRecallAndError) {
  StereoMatchOptions mo;
  mo.pixel_noise_px = 0.3;  // the simulator's noise, as a pilot test would tune it
  const SessionScore s = run_session(mo, 0);
  print("sim, sigma 0.3 px", s);
  ASSERT_EQ(s.frames, 900u);
  EXPECT_GE(s.precision(), 0.99);
  EXPECT_GE(s.recall(), 0.90);
  EXPECT_LT(s.mean_err_m(), 0.002);
  // The propagated covariance matches the actual error (NEES ~ 3 for 3-D).
  const double nees = s.nees_sum / static_cast<double>(s.correct);
  EXPECT_GT(nees, 2.0);
  EXPECT_LT(nees, 4.5);
}

TEST(VistStereoSimulation, DefaultOptionsAlsoWork) {
  // Default pixel_noise_px (1 px) overestimates the simulator's 0.3 px.
  const SessionScore s = run_session(StereoMatchOptions{}, 0, 11);
  print("sim, default options", s);
  EXPECT_GE(s.precision(), 0.99);
  EXPECT_GE(s.recall(), 0.85);
}

TEST(VistStereoSimulation, DistractorsInOneCameraAreRarelyMatched) {
  StereoMatchOptions mo;
  mo.pixel_noise_px = 0.3;
  const SessionScore s = run_session(mo, 3);
  print("sim, 3 left-only distractors per frame", s);
  ASSERT_GT(s.distractors_in, 2000u);
  // Distractors sit on the rows of real blobs of their hue, so some fall where
  // a real right blob without a left partner (occluded) expects one: rare.
  EXPECT_LT(static_cast<double>(s.distractors_matched) / static_cast<double>(s.distractors_in), 0.05);
  EXPECT_GE(s.precision(), 0.97);
  EXPECT_GE(s.recall(), 0.80);
}

TEST(VistStereoSimulation, DeterministicAndAllocationFreeAfterWarmUp) {
  const HandShape shape = *sim::sim_subject(3)->shape();
  const ImuGloveDescription glove = ImuGloveDescription::vist_default();
  auto simulator = sim::StereoMarkerSimulator::create(glove, shape, {});
  ASSERT_TRUE(simulator.ok());
  sim::HandMotionGenerator gen(HandModel(shape), sim::HandMotionOptions{});
  std::vector<sim::StereoFrame> frames;
  for (int k = 0; k < 120; ++k) {
    const sim::HandMotionFrame m = gen.sample(k * 33'333'333LL);
    frames.push_back(simulator->simulate(m.pose, m.T_world_head, m.time_ns));
  }
  auto a = StereoMatcher::create(glove.rig, {});
  auto b = StereoMatcher::create(glove.rig, {});
  ASSERT_TRUE(a.ok() && b.ok());
  std::vector<StereoPoint> out_a, out_b;
  a->match(frames[0].cameras[0], frames[0].cameras[1], out_a);  // warm-up
  const std::size_t capacity = out_a.capacity();
  const StereoPoint* data = out_a.data();
  for (const sim::StereoFrame& f : frames) {
    a->match(f.cameras[0], f.cameras[1], out_a);
    b->match(f.cameras[0], f.cameras[1], out_b);
    ASSERT_EQ(out_a.size(), out_b.size());
    for (std::size_t k = 0; k < out_a.size(); ++k) {
      EXPECT_EQ(out_a[k].left_index, out_b[k].left_index);
      EXPECT_EQ(out_a[k].right_index, out_b[k].right_index);
      EXPECT_EQ(out_a[k].p_in_leftcam, out_b[k].p_in_leftcam);  // bit for bit
      EXPECT_EQ(out_a[k].posterior, out_b[k].posterior);
    }
    EXPECT_EQ(a->last_stats().zeta_px, b->last_stats().zeta_px);
  }
  EXPECT_EQ(out_a.capacity(), capacity);
  EXPECT_EQ(out_a.data(), data);
}

}  // namespace
