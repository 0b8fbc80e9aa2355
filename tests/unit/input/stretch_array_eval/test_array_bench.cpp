// bench array's two flat cases on short runs: they measure what they say
// (an ideal board recovers eq. 4.8 exactly, so its error is the model's
// alone; the resistances make the board under-read stretch).
#include "proprio/stretch_array_eval/array_bench.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace proprio::stretch_array_eval {
namespace {

TEST(ArrayBench, ErrorStatsAreTheUsualOnes) {
  const ErrorStats s = ErrorStats::of({1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20});
  EXPECT_EQ(s.samples, 20u);
  EXPECT_DOUBLE_EQ(s.mean, 10.5);
  EXPECT_DOUBLE_EQ(s.p95, 19.0);
  EXPECT_DOUBLE_EQ(s.max, 20.0);
  EXPECT_NEAR(s.std, std::sqrt(33.25), 1e-12);
  EXPECT_EQ(ErrorStats::of({}).samples, 0u);
}

TEST(ArrayBench, UniaxialCellFollowsTheStageAndAnIdealBoardFollowsTheCell) {
  BenchArrayOptions o;
  o.uniaxial_positions = 7;
  o.uniaxial_max_stretch = 1.5;
  auto r = bench_uniaxial(o);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->stage_positions, 7u);
  // Eq. 4.2 on the cell's own length: an ideal board is off only by the
  // clamps' edge effects and the rest's discretisation.
  EXPECT_LT(r->relative_length_error_ideal.mean, 0.01);
  // The board's noise, counter and parasitics alone cost little; the strips'
  // resistance, which grows with the stretch, makes it under-read more.
  BenchArrayOptions no_r = o;
  no_r.board.resistance.enabled = false;
  auto without = bench_uniaxial(no_r);
  ASSERT_TRUE(without) << without.error().message;
  EXPECT_LT(without->relative_length_error.mean, 0.015);
  EXPECT_GT(r->relative_length_error.mean, 2 * without->relative_length_error.mean);
  // Incompressible: the middle narrows to about 1/sqrt(1.5).
  EXPECT_NEAR(r->width_ratio_at_max, 1.0 / std::sqrt(1.5), 0.03);
}

TEST(ArrayBench, StringPullIdealBoardIsExactAndTheRealOneIsNot) {
  BenchArrayOptions o;
  o.string_pull_seconds = 3.0;
  auto r = bench_string_pull(o);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->frames, 23u);  // 24 frames less the rest one
  EXPECT_EQ(r->cells, 92u);
  EXPECT_GT(r->max_area_ratio, 1.01);
  // The ideal board is read at row instants while the strings move, so even
  // it is not exact, but close.
  EXPECT_LT(r->relative_error_ideal.mean, 0.01);
  EXPECT_GT(r->relative_error.mean, r->relative_error_ideal.mean);
  EXPECT_LT(r->relative_error.mean, 0.2);
}

}  // namespace
}  // namespace proprio::stretch_array_eval
