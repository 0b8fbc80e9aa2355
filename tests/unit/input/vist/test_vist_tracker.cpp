// The VIST tracker end to end on simulated subjects (ground truth from the
// simulators, never from the tracker), and its handling of broken input.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "proprio/sim/imu_sim.hpp"
#include "proprio/sim/stereo_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "proprio/vist/vist_tracker.hpp"
#include "proprio/vist_eval/evaluation.hpp"

namespace proprio::vist {
namespace {

vist_eval::SessionResult run(vist_eval::SessionSpec spec, const VistTrackerOptions& options = {}) {
  auto r = vist_eval::run_session(ImuGloveDescription::vist_default(), spec, options);
  EXPECT_TRUE(r) << r.error().message;
  return r ? *r : vist_eval::SessionResult{};
}

// A glove measured against its file to half a millimetre: the tracker then
// trusts the drawn marker places that much (the default assumes a hand-sewn
// glove, FilterOptions::marker_extra_sigma_m).
VistTrackerOptions precisely_measured_glove() {
  VistTrackerOptions o;
  o.filter.marker_extra_sigma_m = 0.0005;
  return o;
}

// The tracker's own accuracy, on the idealised simulator (the glove exactly
// as drawn, rigid on the bones): what is left is the tracker's error, not the
// glove's (GloveAsBuiltCostsAccuracy below).
TEST(VistTracker, FreeMotionOfTwoSubjectsIsAccurate) {
  for (int subject : {2, 12}) {
    vist_eval::SessionSpec spec;
    spec.idealise();
    spec.subject = subject;
    spec.duration_s = 20.0;
    spec.calibration_check_s = 18.0;
    const auto r = run(spec, precisely_measured_glove());
    ASSERT_TRUE(r.acquired) << "subject " << subject;
    EXPECT_LT(r.acquisition_time_s, 1.0);
    // The targets are 6 mm and 97 %; a short session is held to the same.
    EXPECT_LT(r.keypoints.mean_mm, 6.0) << "subject " << subject;
    EXPECT_GT(r.keypoints.pck20, 0.97) << "subject " << subject;
    EXPECT_LT(r.scale_error_max, 0.03) << "subject " << subject;
    EXPECT_LT(r.mounting_error_max_deg, 3.0) << "subject " << subject;
    for (double t : r.keypoint_mean_mm) EXPECT_TRUE(std::isfinite(t));
    EXPECT_EQ(r.stats.imu_rejected_non_finite, 0u);
  }
}

// The glove as built: markers off their drawn places cost accuracy the
// tracker cannot remove (it reads the drawn file). The 6 mm target is
// missed there (docs/benchmarks.md); this bounds the regression and checks the
// effect is real.
TEST(VistTracker, GloveAsBuiltCostsAccuracy) {
  vist_eval::SessionSpec spec;
  spec.subject = 2;
  spec.duration_s = 20.0;
  const auto built = run(spec);
  spec.glove_build = sim::GloveBuildErrors::as_drawn();
  const auto drawn = run(spec);
  ASSERT_TRUE(built.acquired);
  EXPECT_GT(built.keypoints.mean_mm, 1.5 * drawn.keypoints.mean_mm);
  EXPECT_LT(built.keypoints.mean_mm, 15.0);
  EXPECT_GT(built.keypoints.pck20, 0.9);
}

// Recovery is judged against 10 mm, so on the idealised simulator (with
// every effect on, the steady error is near that).
TEST(VistTracker, RecoversAfterTheHandLeavesTheView) {
  vist_eval::SessionSpec spec;
  spec.idealise();
  spec.subject = 5;
  spec.duration_s = 34.0;
  spec.challenge = vist_eval::Challenge::out_of_view;
  const auto r = run(spec, precisely_measured_glove());
  ASSERT_EQ(r.recovery_s.size(), 2u);
  for (double t : r.recovery_s) {
    EXPECT_GE(t, 0.0) << "never back within 10 mm";
    // The target is 0.5 s; `proprio bench vist` reports the measured
    // worst case. Here: back within a few seconds, every time.
    EXPECT_LT(t, 5.0);
  }
}

TEST(VistTracker, ResumesAfterTheImuBoardIsUnplugged) {
  vist_eval::SessionSpec spec;
  spec.subject = 8;
  spec.duration_s = 14.0;
  spec.challenge = vist_eval::Challenge::imu_unplug;
  const auto r = run(spec);
  ASSERT_EQ(r.recovery_s.size(), 1u);
  EXPECT_GE(r.recovery_s[0], 0.0);
  EXPECT_LT(r.recovery_s[0], 1.0);
}

TEST(VistTracker, WithoutTheImuAblationItIsWorse) {
  vist_eval::SessionSpec spec;
  spec.subject = 4;
  spec.duration_s = 15.0;
  const auto full = run(spec);
  spec.ablation = vist_eval::Ablation::vision_only;
  const auto vision = run(spec);
  EXPECT_GT(vision.keypoints.mean_mm, 1.5 * full.keypoints.mean_mm);
}

// Broken input: counted, never a NaN pose.
class VistTrackerInput : public ::testing::Test {
 protected:
  void SetUp() override {
    auto t = VistTracker::create(ImuGloveDescription::vist_default());
    ASSERT_TRUE(t) << t.error().message;
    tracker_.emplace(std::move(*t));
  }
  TimedImuSample sample(TimeNs t, std::uint16_t id) {
    TimedImuSample s;
    s.time_ns = t;
    s.sample.sensor_id = id;
    s.sample.accel_mps2 = Vec3(0, 9.81, 0);
    return s;
  }
  std::optional<VistTracker> tracker_;
};

TEST_F(VistTrackerInput, CountsAndDropsBadImuSamples) {
  auto& t = *tracker_;
  auto nan = sample(10, 0);
  nan.sample.gyro_radps.x() = std::numeric_limits<double>::quiet_NaN();
  t.add_imu(nan);
  auto sat = sample(20, 0);
  sat.gyro_clipped = true;
  t.add_imu(sat);
  auto clipped_accel = sample(25, 0);  // used: its gyro is good
  clipped_accel.accel_clipped = true;
  t.add_imu(clipped_accel);
  auto huge = sample(30, 0);
  huge.sample.accel_mps2.x() = 1e4;
  t.add_imu(huge);
  t.add_imu(sample(40, 0));
  t.add_imu(sample(40, 0));  // duplicate
  t.add_imu(sample(35, 0));  // out of order
  t.add_imu(sample(50, 99));  // no such IMU
  const auto& s = t.stats();
  EXPECT_EQ(s.imu_samples, 8u);
  EXPECT_EQ(s.imu_rejected_non_finite, 1u);
  EXPECT_EQ(s.imu_rejected_saturated, 2u);
  EXPECT_EQ(s.imu_accel_clipped, 1u);
  EXPECT_EQ(s.imu_rejected_out_of_order, 2u);
  EXPECT_EQ(s.imu_rejected_unknown_sensor, 1u);
  EXPECT_FALSE(t.initialized());
  EXPECT_FALSE(t.pose().active);
}

// One far-future stamp (a CLOCK_REALTIME time from another writer) used to
// make every later sample of that IMU "out of order": fusion silently stopped.
TEST_F(VistTrackerInput, AnIsolatedFarFutureStampCostsOneSample) {
  auto& t = *tracker_;
  constexpr TimeNs kStep = 10'000'000;
  for (TimeNs i = 1; i <= 5; ++i) t.add_imu(sample(i * kStep, 0));
  t.add_imu(sample(1'700'000'000'000'000'000, 0));
  for (TimeNs i = 6; i <= 20; ++i) t.add_imu(sample(i * kStep, 0));
  const auto& s = t.stats();
  EXPECT_EQ(s.imu_rejected_time_jump, 1u);
  EXPECT_EQ(s.imu_rejected_out_of_order, 0u);
  EXPECT_EQ(t.newest_imu_time_ns(), 20 * kStep);
  EXPECT_NE(s.describe().find("1 time jumps"), std::string::npos) << s.describe();

  // A real pause is kept: the next sample confirms the new timeline.
  t.add_imu(sample(100 * kNsPerSecond, 0));
  t.add_imu(sample(100 * kNsPerSecond + kStep, 0));
  EXPECT_EQ(t.newest_imu_time_ns(), 100 * kNsPerSecond + kStep);
  EXPECT_EQ(s.imu_rejected_time_jump, 1u);
}

// The same when the bad stamp is an IMU's very first sample.
TEST_F(VistTrackerInput, AFarFutureFirstStampCostsOneSample) {
  auto& t = *tracker_;
  constexpr TimeNs kStep = 10'000'000;
  t.add_imu(sample(1'700'000'000'000'000'000, 0));
  for (TimeNs i = 1; i <= 10; ++i) t.add_imu(sample(i * kStep, 0));
  const auto& s = t.stats();
  EXPECT_EQ(s.imu_rejected_time_jump, 1u);
  EXPECT_EQ(s.imu_rejected_out_of_order, 0u);
  EXPECT_EQ(t.newest_imu_time_ns(), 10 * kStep);
}

TEST_F(VistTrackerInput, CountsDuplicateFramesAndWaitsForImuBeforeAcquiring) {
  auto& t = *tracker_;
  MarkerObservations left, right;
  left.camera_id = 0;
  right.camera_id = 1;
  t.add_stereo_frame(1'000'000'000, left, right, Pose::identity());
  t.add_stereo_frame(1'000'000'000, left, right, Pose::identity());
  EXPECT_EQ(t.stats().frames, 2u);
  EXPECT_EQ(t.stats().frames_duplicate, 1u);
  EXPECT_FALSE(t.initialized());  // no IMU data and no markers: nothing to start from
}

TEST(VistTrackerOptions, ValidateRejectsNonsense) {
  VistTrackerOptions o;
  o.use_imu = false;
  o.use_vision = false;
  EXPECT_FALSE(o.validate());
  o = {};
  o.nominal_hand_length_m = 1.9;  // centimetres typed as metres would be 0.19
  const auto st = o.validate();
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().message.find("metres"), std::string::npos);
  EXPECT_FALSE(VistTracker::create(ImuGloveDescription::vist_default(), o));
}

}  // namespace
}  // namespace proprio::vist
