// VIST IMU-aided correspondence search (Lee 2021, §4.4): priors (4.10-4.12),
// CPD translation (4.7-4.9), assignment (4.13), against hand-made cases and
// the stereo-marker simulator's ground truth.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <unordered_set>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/core/random.hpp"
#include "proprio/sim/hand_motion.hpp"
#include "proprio/sim/stereo_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "proprio/vist/correspondence.hpp"
#include "support/stereo.hpp"

using namespace proprio;
using namespace proprio::vist;

namespace {

constexpr double kDeg = 3.14159265358979323846 / 180.0;

using proprio::testing_support::test_rig;

PredictedMarker facing_marker(const Vec3& p, MarkerHue hue, std::size_t glove_index,
                              HandJoint segment = HandJoint::wrist) {
  PredictedMarker m;
  m.glove_index = glove_index;
  m.segment = segment;
  m.hue = hue;
  m.p_in_leftcam = p;
  m.normal_in_leftcam = -p.normalized();  // looks straight at the left camera
  m.covariance = std::pow(0.005, 2) * Mat3::Identity();
  return m;
}

}  // namespace

// --- Priors ------------------------------------------------------------------

TEST(VistCorrespondencePriors, FacingFactorFollowsEq410) {
  const double amin = 45 * kDeg, amax = 90 * kDeg;
  EXPECT_DOUBLE_EQ(facing_factor(30 * kDeg, amin, amax), 1.0);
  EXPECT_NEAR(facing_factor(67.5 * kDeg, amin, amax), 0.5, 1e-12);
  EXPECT_DOUBLE_EQ(facing_factor(100 * kDeg, amin, amax), 0.0);
  EXPECT_DOUBLE_EQ(facing_factor(45 * kDeg, amin, amax), 1.0);
  EXPECT_NEAR(facing_factor(90 * kDeg, amin, amax), 0.0, 1e-12);
  // The angle is to the ray from the marker to the camera (Fig. 4.4-A).
  EXPECT_NEAR(facing_angle(Vec3(0, 0, 1), Vec3(0, 0, -1), Vec3::Zero()), 0.0, 1e-12);
  EXPECT_NEAR(facing_angle(Vec3(0, 0, 1), Vec3(1, 0, 0), Vec3::Zero()), 90 * kDeg, 1e-12);
}

TEST(VistCorrespondencePriors, FovFactorIsHalfOnTheBorderAndOneInside) {
  const PinholeCamera cam;
  const Eigen::Matrix2d cov = Eigen::Matrix2d::Identity() * 25.0;  // 5 px sigma
  // The image edge is half a pixel outside the first / last pixel centre.
  EXPECT_NEAR(fov_factor(-0.5, 360.0, cov, cam), 0.5, 1e-12);
  EXPECT_NEAR(fov_factor(1279.5, 360.0, cov, cam), 0.5, 1e-12);
  EXPECT_NEAR(fov_factor(640.0, -0.5, cov, cam), 0.5, 1e-12);
  EXPECT_NEAR(fov_factor(640.0, 360.0, cov, cam), 1.0, 1e-12);
  // One sigma inside / outside the nearest (left) edge: Phi(+-1).
  EXPECT_NEAR(fov_factor(4.5, 360.0, cov, cam), 0.841344746, 1e-6);
  EXPECT_NEAR(fov_factor(-5.5, 360.0, cov, cam), 0.158655254, 1e-6);
  // The sigma along the nearest edge's normal is used: v variance for the top edge.
  Eigen::Matrix2d aniso;
  aniso << 1e6, 0, 0, 1.0;
  EXPECT_NEAR(fov_factor(640.0, 2.5, aniso, cam), 0.998650102, 1e-8);  // Phi(3)
}

TEST(VistCorrespondencePriors, OccludedMarkerGetsZeroPrior) {
  const StereoRig rig = test_rig();
  // A finger bone across the view at 30 cm, 1 cm radius.
  SegmentCapsules caps;
  caps.count = 1;
  caps.capsules[0] = SegmentCapsule{Vec3(-0.05, 0.0, 0.30), Vec3(0.10, 0.0, 0.30), 0.01, HandJoint::index_proximal};
  const PredictedMarker behind = facing_marker(Vec3(0.03, 0.0, 0.40), MarkerHue::red, 0, HandJoint::middle_proximal);
  const PredictedMarker front = facing_marker(Vec3(0.03, 0.0, 0.25), MarkerHue::red, 1, HandJoint::middle_proximal);
  const PredictedMarker aside = facing_marker(Vec3(0.03, 0.08, 0.40), MarkerHue::red, 2, HandJoint::middle_proximal);
  const PredictedMarker own = facing_marker(Vec3(0.03, 0.0, 0.40), MarkerHue::red, 3, HandJoint::index_proximal);
  EXPECT_TRUE(occluded(behind.p_in_leftcam, behind.segment, caps, rig, 0));
  EXPECT_TRUE(occluded(behind.p_in_leftcam, behind.segment, caps, rig, 1));
  EXPECT_FALSE(occluded(front.p_in_leftcam, front.segment, caps, rig, 0));
  EXPECT_FALSE(occluded(aside.p_in_leftcam, aside.segment, caps, rig, 0));
  EXPECT_FALSE(occluded(own.p_in_leftcam, own.segment, caps, rig, 0));  // its own segment never hides it

  const std::vector<PredictedMarker> markers{behind, front, aside, own};
  std::vector<double> priors(markers.size());
  std::vector<MarkerPrior> details(markers.size());
  CorrespondenceOptions o;
  ASSERT_TRUE(marker_priors(markers, caps, rig, o, priors, details).ok());
  EXPECT_EQ(priors[0], 0.0);
  EXPECT_TRUE(details[0].occluded);
  EXPECT_GT(priors[1], 0.9);
  EXPECT_GT(priors[2], 0.9);
  EXPECT_GT(priors[3], 0.9);
  o.occlusion = false;
  ASSERT_TRUE(marker_priors(markers, caps, rig, o, priors, details).ok());
  EXPECT_GT(priors[0], 0.9);
}

TEST(VistCorrespondencePriors, PriorIsProductOverBothCameras) {
  const StereoRig rig = test_rig();
  // Normal at 67.5 deg to the left camera's ray and more than 67.5 to the right's.
  PredictedMarker m = facing_marker(Vec3(0.0, 0.0, 0.4), MarkerHue::red, 0);
  const Vec3 to_cam = -m.p_in_leftcam.normalized();
  m.normal_in_leftcam = (Eigen::AngleAxisd(-67.5 * kDeg, Vec3::UnitY()) * to_cam).normalized();
  std::vector<double> priors(1);
  std::vector<MarkerPrior> d(1);
  ASSERT_TRUE(marker_priors(std::span<const PredictedMarker>(&m, 1), SegmentCapsules{}, rig, {}, priors, d).ok());
  EXPECT_NEAR(d[0].facing[0], 0.5, 1e-9);
  // The right camera (at +baseline along x) sees it at a different angle.
  const double alpha_right = facing_angle(m.p_in_leftcam, m.normal_in_leftcam, Vec3(rig.baseline_m, 0, 0));
  EXPECT_GT(std::abs(alpha_right - 67.5 * kDeg), 5 * kDeg);
  EXPECT_NEAR(d[0].facing[1], facing_factor(alpha_right, 45 * kDeg, 90 * kDeg), 1e-12);
  EXPECT_NEAR(priors[0], d[0].facing[0] * d[0].facing[1] * d[0].fov[0] * d[0].fov[1], 1e-15);
  // Behind the camera: nothing.
  m.p_in_leftcam = Vec3(0, 0, -0.2);
  ASSERT_TRUE(marker_priors(std::span<const PredictedMarker>(&m, 1), SegmentCapsules{}, rig, {}, priors, d).ok());
  EXPECT_EQ(priors[0], 0.0);
}

// --- Hand-made CPD case -------------------------------------------------------

TEST(VistCorrespondenceSearch, RecoversCommonOffsetAndAssignment) {
  std::vector<PredictedMarker> markers;
  // Four red markers 2.5 cm apart (closer than a typical same-hue spacing on
  // the glove) and one blue one.
  for (int k = 0; k < 4; ++k) {
    markers.push_back(facing_marker(Vec3(-0.04 + 0.025 * k, 0.01 * (k % 2), 0.40), MarkerHue::red, 10 + k));
  }
  markers.push_back(facing_marker(Vec3(0.0, 0.05, 0.40), MarkerHue::blue, 20));
  const std::vector<double> priors(markers.size(), 1.0);
  const Vec3 offset(0.010, -0.004, 0.003);  // ~1.1 cm, more than one marker sigma
  Rng rng(7);
  // Observation k is marker order[k].
  const std::vector<std::size_t> order{2, 0, 4, 3, 1};
  std::vector<Observation3D> obs;
  for (std::size_t j : order) {
    Observation3D ob;
    ob.hue = static_cast<std::uint8_t>(markers[j].hue);
    ob.p_in_leftcam = markers[j].p_in_leftcam + offset + Vec3(rng.normal(0, 0.001), rng.normal(0, 0.001), rng.normal(0, 0.001));
    ob.covariance = std::pow(0.0015, 2) * Mat3::Identity();
    obs.push_back(ob);
  }
  CorrespondenceSearch search;
  CorrespondenceResult r;
  r.reserve(16);
  ASSERT_TRUE(search.match(markers, priors, obs, r).ok());
  ASSERT_EQ(r.assignments.size(), obs.size());
  EXPECT_TRUE(r.outliers.empty());
  for (const Assignment& a : r.assignments) {
    EXPECT_EQ(a.marker, markers[order[a.observation]].glove_index) << "observation " << a.observation;
    EXPECT_GE(a.posterior, 0.9);
  }
  EXPECT_TRUE(r.converged);
  EXPECT_LT((r.translation_in_leftcam[0] - offset).norm(), 0.0015) << r.translation_in_leftcam[0].transpose();
}

TEST(VistCorrespondenceSearch, FarObservationAndUnknownHueAreOutliers) {
  std::vector<PredictedMarker> markers{facing_marker(Vec3(0, 0, 0.4), MarkerHue::red, 0),
                                       facing_marker(Vec3(0.03, 0, 0.4), MarkerHue::red, 1)};
  const std::vector<double> priors(2, 1.0);
  std::vector<Observation3D> obs(3);
  obs[0].hue = 0;
  obs[0].p_in_leftcam = Vec3(0.0005, 0, 0.4);
  obs[1].hue = 0;
  obs[1].p_in_leftcam = Vec3(0.0, 0.12, 0.4);  // 12 cm from everything
  obs[2].hue = 9;                              // not a glove hue
  obs[2].p_in_leftcam = Vec3(0.03, 0, 0.4);
  CorrespondenceSearch search;
  CorrespondenceResult r;
  ASSERT_TRUE(search.match(markers, priors, obs, r).ok());
  ASSERT_EQ(r.assignments.size(), 1u);
  EXPECT_EQ(r.assignments[0].observation, 0u);
  EXPECT_EQ(r.assignments[0].marker, 0u);
  EXPECT_EQ(r.outliers, (std::vector<std::size_t>{1, 2}));
}

TEST(VistCorrespondenceSearch, DuplicateObservationsKeepOne) {
  std::vector<PredictedMarker> markers{facing_marker(Vec3(0, 0, 0.4), MarkerHue::green, 5)};
  const std::vector<double> priors(1, 1.0);
  std::vector<Observation3D> obs(2);
  obs[0].hue = obs[1].hue = static_cast<std::uint8_t>(MarkerHue::green);
  obs[0].p_in_leftcam = Vec3(0.004, 0, 0.4);
  obs[1].p_in_leftcam = Vec3(-0.001, 0, 0.4);
  for (auto rule : {CorrespondenceOptions::DuplicateRule::max_posterior, CorrespondenceOptions::DuplicateRule::min_distance}) {
    CorrespondenceOptions o;
    o.duplicate_rule = rule;
    o.translation_prior_sigma_m = 0.001;  // keep eta near 0 so the nearer one is obvious
    CorrespondenceSearch search(o);
    CorrespondenceResult r;
    ASSERT_TRUE(search.match(markers, priors, obs, r).ok());
    ASSERT_EQ(r.assignments.size(), 1u);
    EXPECT_EQ(r.assignments[0].observation, 1u);
    EXPECT_EQ(r.outliers, (std::vector<std::size_t>{0}));
  }
}

TEST(VistCorrespondenceSearch, CapacityAndOptionErrors) {
  CorrespondenceOptions bad;
  bad.outlier_weight = 1.0;
  EXPECT_FALSE(bad.validate().ok());
  EXPECT_FALSE(CorrespondenceSearch::create(bad).ok());
  auto s = CorrespondenceSearch::create({}, 2, 2);
  ASSERT_TRUE(s.ok());
  std::vector<PredictedMarker> markers(3);
  std::vector<double> priors(3, 1.0);
  CorrespondenceResult r;
  const Status st = s->match(markers, priors, {}, r);
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, Errc::out_of_range);
  EXPECT_FALSE(CorrespondenceOptions{}.describe().empty());
}

// --- Against the simulators ---------------------------------------------------

namespace {

struct SessionStats {
  std::size_t frames = 0;
  std::size_t observations = 0;  // true (stereo-visible) observations
  std::size_t assigned = 0;      // true observations given a marker
  std::size_t correct = 0;
  std::size_t distractors = 0;
  std::size_t distractors_assigned = 0;
  std::vector<std::size_t> signature;  // every assignment, for determinism

  double accuracy() const { return assigned ? double(correct) / double(assigned) : 0.0; }
  double recall() const { return observations ? double(correct) / double(observations) : 0.0; }
};

// A 30 s free-motion session of subject 3 wearing the default VIST glove. The
// observations are the simulator's ground-truth 3D marker centres of the
// markers both cameras see, plus 1.5 mm noise; the "IMU-predicted" pose is the
// ground truth with its wrist moved ~1 cm, turned ~3 deg and every finger
// angle off by ~3 deg. `distractors` random points with glove hues per frame
// are mixed in.
// Errors of the "IMU-predicted" pose: standard deviations per axis / per angle.
struct Perturbation {
  double wrist_m = 0.006;          // per axis: ~1 cm in norm
  double wrist_rad = 1.75 * kDeg;  // per axis: ~3 deg in angle
  double finger_rad = 3.0 * kDeg;  // every joint angle
};

SessionStats run_session(const CorrespondenceOptions& options, double duration_s = 30.0, int distractors = 0,
                         std::uint64_t seed = 11, Perturbation err = {}) {
  const ImuGloveDescription glove = ImuGloveDescription::vist_default();
  const HandShape shape = *sim::sim_subject(3)->shape();
  sim::StereoSimOptions so;
  so.facing = sim::FacingModel::linear_ramp;  // the thesis's own visibility model (4.10)
  so.seed = seed;
  auto simulator = sim::StereoMarkerSimulator::create(glove, shape, so);
  EXPECT_TRUE(simulator.ok());
  sim::HandMotionOptions mo;
  mo.seed = seed;
  sim::HandMotionGenerator gen(HandModel(shape), mo);
  const HandModel model(shape);
  const std::vector<PlacedMarker> placed = glove.place_markers(shape);
  const std::vector<Mat3> cov(placed.size(), std::pow(0.005, 2) * Mat3::Identity());
  CorrespondenceSearch search(options);
  CorrespondenceResult result;
  result.reserve(128);
  Rng rng(mix_seed(seed, 99));
  SessionStats st;
  std::vector<Observation3D> obs;
  std::vector<std::size_t> truth_marker;  // per observation; SIZE_MAX for distractors
  sim::simulate_session(gen, *simulator, duration_s,
                        [&](const sim::HandMotionFrame& mf, const sim::StereoFrame&, const sim::StereoGroundTruth& gt) {
    ++st.frames;
    obs.clear();
    truth_marker.clear();
    std::unordered_set<std::size_t> right;
    for (const auto& t : gt.cameras[1]) right.insert(t.glove_index);
    for (const auto& t : gt.cameras[0]) {
      if (!right.count(t.glove_index)) continue;
      Observation3D o;
      o.hue = static_cast<std::uint8_t>(placed[t.glove_index].hue);
      o.p_in_leftcam = t.p_in_leftcam + Vec3(rng.normal(0, 0.0015), rng.normal(0, 0.0015), rng.normal(0, 0.0015));
      o.covariance = std::pow(0.0015, 2) * Mat3::Identity();
      obs.push_back(o);
      truth_marker.push_back(t.glove_index);
    }
    st.observations += obs.size();
    // IMU-predicted pose: the truth, perturbed.
    HandAngles angles = mf.angles;
    for (double& a : angles) a += rng.normal(0, err.finger_rad);
    angles = model.limits().clamp(angles);
    Pose T_wrist = mf.T_world_wrist;
    T_wrist.p += Vec3(rng.normal(0, err.wrist_m), rng.normal(0, err.wrist_m), rng.normal(0, err.wrist_m));
    T_wrist.q = (T_wrist.q * so3_exp(Vec3(rng.normal(0, err.wrist_rad), rng.normal(0, err.wrist_rad),
                                          rng.normal(0, err.wrist_rad))))
                    .normalized();
    const HandPose predicted = model.forward(Handedness::right, angles, T_wrist, mf.time_ns);
    // Distractors: random points in a box around the predicted hand.
    if (distractors > 0) {
      const Pose T_leftcam_world = gt.T_world_leftcam.inverse();
      const Vec3 c = T_leftcam_world * predicted.joint(HandJoint::palm).p;
      for (int k = 0; k < distractors; ++k) {
        Observation3D o;
        o.hue = static_cast<std::uint8_t>(rng.below(kMarkerHueCount));
        o.p_in_leftcam = c + Vec3(rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1));
        o.covariance = std::pow(0.0015, 2) * Mat3::Identity();
        obs.push_back(o);
        truth_marker.push_back(SIZE_MAX);
      }
      st.distractors += static_cast<std::size_t>(distractors);
    }
    ASSERT_TRUE(search.search(predicted, gt.T_world_leftcam, simulator->rig(), placed, cov, obs, result).ok());
    for (const Assignment& a : result.assignments) {
      st.signature.push_back(a.observation * 1000 + a.marker);
      if (truth_marker[a.observation] == SIZE_MAX) {
        ++st.distractors_assigned;
        continue;
      }
      ++st.assigned;
      if (truth_marker[a.observation] == a.marker) ++st.correct;
    }
  });
  return st;
}

}  // namespace

void report(const char* label, const SessionStats& with, const SessionStats& without) {
  std::cout << "[ correspondence ] " << label << ": " << with.frames << " frames, "
            << double(with.observations) / double(with.frames) << " observations/frame\n"
            << "[ correspondence ]   priors on : accuracy " << 100.0 * with.accuracy() << " %, recall "
            << 100.0 * with.recall() << " %\n"
            << "[ correspondence ]   priors off: accuracy " << 100.0 * without.accuracy() << " %, recall "
            << 100.0 * without.recall() << " %\n";
}

TEST(VistCorrespondenceSim, AccurateOnFreeMotion) {
  // Prediction errors: wrist ~1 cm and ~3 deg, fingers ~3 deg per joint angle.
  const SessionStats with = run_session(CorrespondenceOptions{});
  CorrespondenceOptions no_priors;
  no_priors.use_priors = false;
  const SessionStats without = run_session(no_priors);
  report("30 s free motion, subject 3, nominal prediction errors", with, without);
  RecordProperty("accuracy_priors_on", std::to_string(with.accuracy()));
  RecordProperty("recall_priors_on", std::to_string(with.recall()));
  RecordProperty("accuracy_priors_off", std::to_string(without.accuracy()));
  EXPECT_GE(with.frames, 890u);
  EXPECT_GE(with.accuracy(), 0.98);
  EXPECT_GE(with.recall(), 0.90);
}

TEST(VistCorrespondenceSim, PriorsMatterWhenThePredictionIsWorse) {
  // With the nominal errors both variants are near perfect; at 2.5x the
  // errors (wrist ~2.5 cm / ~7.5 deg, fingers ~7.5 deg) same-hue neighbours
  // get confused, and the priors (facing, FOV, occlusion) remove candidates
  // that cannot be seen (Fig. 4.8-D's point).
  Perturbation e;
  e.wrist_m *= 2.5;
  e.wrist_rad *= 2.5;
  e.finger_rad *= 2.5;
  const SessionStats with = run_session(CorrespondenceOptions{}, 30.0, 0, 11, e);
  CorrespondenceOptions no_priors;
  no_priors.use_priors = false;
  const SessionStats without = run_session(no_priors, 30.0, 0, 11, e);
  report("30 s free motion, subject 3, 2.5x prediction errors", with, without);
  RecordProperty("accuracy_priors_on_2p5x", std::to_string(with.accuracy()));
  RecordProperty("accuracy_priors_off_2p5x", std::to_string(without.accuracy()));
  EXPECT_GE(with.accuracy(), 0.95);
  EXPECT_LT(without.accuracy(), with.accuracy());
}

TEST(VistCorrespondenceSim, DistractorsAreMostlyRejected) {
  const SessionStats st = run_session(CorrespondenceOptions{}, 10.0, 3);
  const double rate = double(st.distractors_assigned) / double(st.distractors);
  std::cout << "[ correspondence ] distractors: " << st.distractors << ", assigned " << 100.0 * rate
            << " %; true observations: accuracy " << 100.0 * st.accuracy() << " %, recall " << 100.0 * st.recall()
            << " %\n";
  RecordProperty("distractor_assigned_rate", std::to_string(rate));
  EXPECT_LT(rate, 0.2);
  EXPECT_GE(st.accuracy(), 0.95);
}

TEST(VistCorrespondenceSim, Deterministic) {
  const SessionStats a = run_session(CorrespondenceOptions{}, 3.0, 2);
  const SessionStats b = run_session(CorrespondenceOptions{}, 3.0, 2);
  EXPECT_FALSE(a.signature.empty());
  EXPECT_EQ(a.signature, b.signature);
}

