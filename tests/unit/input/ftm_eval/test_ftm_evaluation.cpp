// The FTM bench's cases on one short held-in session each (subject 0): they run the
// whole pipeline (calibration from the simulated wearer included) and give
// finite errors under generous bounds (several times what the bench
// measures: these catch a broken stage, not a tenth of a degree), and a case
// that cannot run says so instead of printing numbers.
#include <gtest/gtest.h>

#include <cmath>

#include "proprio/ftm_eval/ftm_evaluation.hpp"

namespace proprio::ftm_eval {
namespace ftm_evaluation_test {

FtmBenchOptions fe_small() {
  FtmBenchOptions o;
  o.first_subject = 0;  // held-in: `bench ftm` keeps 10-14 for itself
  o.subjects = 1;
  o.task_s = 6.0;
  o.seed = 3;
  o.disturbance_hold_s = 2.0;
  o.bench_hold_s = 2.0;
  return o;
}

TEST(FtmEvaluation, OnHandCaseRunsTheFullPipeline) {
  const auto r = run_ftm_case(FtmCase::free_motion, fe_small());
  ASSERT_TRUE(r.ran) << r.reason;
  EXPECT_EQ(r.sessions, 1);
  const double mean = r.metric("tracked_mean_deg");
  ASSERT_TRUE(std::isfinite(mean));
  EXPECT_GT(mean, 0.0);
  EXPECT_LT(mean, 12.0);
  EXPECT_GE(r.metric("tracked_p95_deg"), mean);
  EXPECT_LT(r.metric("fingertip_rel_wrist_mean_mm"), 30.0);
  EXPECT_TRUE(std::isfinite(r.metric("synergy_mean_deg")));
  EXPECT_TRUE(std::isfinite(r.metric("thumb_cmc_abduction_mean_deg")));
  ASSERT_FALSE(r.counts.empty());
  EXPECT_GT(r.counts.front().second, 100u);  // frames scored at 50 Hz over ~5 s
}

TEST(FtmEvaluation, ImuBenchMeasuresTheEulerError) {
  const auto r = run_ftm_case(FtmCase::imu_bench, fe_small());
  ASSERT_TRUE(r.ran) << r.reason;
  const double mean = r.metric("euler_mean_deg");
  ASSERT_TRUE(std::isfinite(mean));
  EXPECT_LT(mean, 5.0);
  EXPECT_LT(r.metric("rotation_angle_mean_deg"), 5.0);
}

TEST(FtmEvaluation, DisturbanceCaseCountsBothKindsOfSample) {
  const auto r = run_ftm_case(FtmCase::disturbance, fe_small());
  ASSERT_TRUE(r.ran) << r.reason;
  const double hit = r.metric("detector_hit_rate");
  const double fa = r.metric("detector_false_alarm_rate");
  ASSERT_TRUE(std::isfinite(hit));
  ASSERT_TRUE(std::isfinite(fa));
  EXPECT_GE(hit, 0.0);
  EXPECT_LE(hit, 1.0);
  EXPECT_LT(fa, 0.5);
  // The gated filter must not be worse than a random heading.
  EXPECT_LT(r.metric("heading_during_gated_mean_deg"), 45.0);
  EXPECT_TRUE(std::isfinite(r.metric("heading_during_plain_mean_deg")));
}

// The turn-on offsets (imu_bias.hpp) are what the bench's error was made of:
// estimated from the readings, the error drops well below the ablation's.
TEST(FtmEvaluation, ImuBenchTurnOnBiasEstimationRemovesMostOfTheError) {
  auto o = fe_small();
  const auto with = run_ftm_case(FtmCase::imu_bench, o);
  o.bench_turn_on_bias = false;
  const auto without = run_ftm_case(FtmCase::imu_bench, o);
  ASSERT_TRUE(with.ran) << with.reason;
  ASSERT_TRUE(without.ran) << without.reason;
  EXPECT_LT(with.metric("euler_mean_deg"), 0.8);
  EXPECT_LT(with.metric("euler_mean_deg"), 0.5 * without.metric("euler_mean_deg"));
}

TEST(FtmEvaluation, DisturbanceTruthAndSubjectsAreValidated) {
  auto o = fe_small();
  o.disturbance_truth_heading_deg = 0.0;
  ASSERT_FALSE(o.validate().ok());
  EXPECT_NE(o.validate().error().message.find("disturbance_truth_heading_deg"), std::string::npos);
  o = fe_small();
  o.first_subject = 14;
  o.subjects = 2;  // 14 and 15: there is no subject 15
  ASSERT_FALSE(o.validate().ok());
  EXPECT_NE(o.validate().error().message.find("subjects"), std::string::npos);
  o = fe_small();
  o.detector.norm_tolerance = -1.0;
  ASSERT_FALSE(o.validate().ok());
  EXPECT_NE(o.validate().error().message.find("detector"), std::string::npos);
  // The disturbance case reports the heading-only rate and the simulator's
  // definition beside the headline.
  const auto r = run_ftm_case(FtmCase::disturbance, fe_small());
  ASSERT_TRUE(r.ran) << r.reason;
  EXPECT_TRUE(std::isfinite(r.metric("detector_hit_rate_heading_only")));
  EXPECT_TRUE(std::isfinite(r.metric("detector_hit_rate_field_2deg_3pct")));
}

TEST(FtmEvaluation, CaseThatCannotRunReportsWhy) {
  auto o = fe_small();
  o.task_s = std::nan("");
  const auto r = run_ftm_case(FtmCase::free_motion, o);
  EXPECT_FALSE(r.ran);
  EXPECT_NE(r.reason.find("task_s"), std::string::npos) << r.reason;
  EXPECT_TRUE(r.metrics.empty());
}

TEST(FtmEvaluation, CaseNamesRoundTrip) {
  for (auto c : all_ftm_cases()) {
    auto parsed = parse_ftm_case(to_string(c));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, c);
  }
  EXPECT_FALSE(parse_ftm_case("bogus").ok());
}

}  // namespace ftm_evaluation_test
}  // namespace proprio::ftm_eval
