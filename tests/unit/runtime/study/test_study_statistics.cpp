// ANOVA, repeated-measures ANOVA with Greenhouse-Geisser, paired t and the
// multiple-comparison corrections against small cases worked by hand.
//
// Expected numbers: sums of squares and F by hand (checked with plain Python,
// no libraries). p-values: F(2, d2) and t(2) have closed-form tails,
//   P(F > f) = (1 + 2 f / d2)^(-d2 / 2)   and   P(|T| > t) = 1 - t / sqrt(2 + t^2);
// the Greenhouse-Geisser p (non-integer dfs) comes from Simpson integration of
// the F density in Python (2e5 panels), and epsilon from the eigen-free
// formula tr(S)^2 / ((k-1) tr(S^2)) on orthonormal contrasts (Helmert), which
// is a different route from the double-centred covariance the library uses.
#include <gtest/gtest.h>

#include <cmath>

#include "proprio/study/statistics.hpp"

namespace proprio::study {
namespace {

TEST(OneWayAnova, MatchesAHandWorkedCase) {
  // Group means 3.5, 7, 5/3; grand mean 59/12.
  const std::vector<std::vector<double>> groups = {{2, 4, 3, 5}, {6, 7, 5, 8, 9}, {1, 2, 2}};
  auto a = one_way_anova(groups);
  ASSERT_TRUE(a) << a.error().message;
  EXPECT_NEAR(a->ss_between, 59.333333333333333, 1e-9);
  EXPECT_NEAR(a->ss_within, 15.666666666666667, 1e-9);
  EXPECT_EQ(a->df_between, 2.0);
  EXPECT_EQ(a->df_within, 9.0);
  EXPECT_NEAR(a->f, 17.04255319148936, 1e-9);
  const double p_closed = std::pow(1.0 + 2.0 * a->f / 9.0, -4.5);  // 0.00087019990032
  EXPECT_NEAR(a->p, p_closed, 1e-12);
  EXPECT_NEAR(a->p, 0.0008701999003212655, 1e-12);
  EXPECT_NEAR(a->eta_squared, 59.333333333333333 / 75.0, 1e-12);
}

TEST(RepeatedMeasuresAnova, MatchesAHandWorkedCaseWithGreenhouseGeisser) {
  // 5 subjects x 3 conditions.
  const std::vector<std::vector<double>> d = {{10, 12, 15}, {8, 11, 11}, {9, 9, 14}, {11, 15, 16}, {7, 10, 12}};
  auto a = repeated_measures_anova(d);
  ASSERT_TRUE(a) << a.error().message;
  EXPECT_NEAR(a->ss_conditions, 52.93333333333333, 1e-9);
  EXPECT_NEAR(a->ss_subjects, 39.33333333333335, 1e-9);
  EXPECT_NEAR(a->ss_error, 9.066666666666663, 1e-9);
  EXPECT_EQ(a->df_conditions, 2.0);
  EXPECT_EQ(a->df_error, 8.0);
  EXPECT_NEAR(a->f, 23.352941176470598, 1e-9);
  EXPECT_NEAR(a->p, 0.0004573238376834246, 1e-12);  // closed form for df1 = 2
  EXPECT_NEAR(a->gg_epsilon, 0.6468942361499722, 1e-10);
  EXPECT_NEAR(a->gg_df_conditions, 1.2937884722999444, 1e-9);
  EXPECT_NEAR(a->gg_df_error, 5.175153889199778, 1e-9);
  EXPECT_NEAR(a->gg_p, 0.0035398479840319046, 1e-8);  // Simpson integration
  EXPECT_GT(a->gg_p, a->p);  // the correction is conservative
}

TEST(RepeatedMeasuresAnova, SphericalDataNeedNoCorrection) {
  // Pure subject offsets plus a condition effect with compound-symmetric
  // noise: the differences between conditions all have the same variance, so
  // epsilon is 1 exactly.
  const std::vector<std::vector<double>> d = {{1, 2, 3}, {2, 3, 4}, {0, 1, 2}, {1, 4, 2}, {3, 1, 2}, {2, 2, 5}};
  auto a = repeated_measures_anova(d);
  ASSERT_TRUE(a);
  EXPECT_GE(a->gg_epsilon, 0.5);
  EXPECT_LE(a->gg_epsilon, 1.0);
  // With two conditions epsilon is always 1 (one contrast).
  auto two = repeated_measures_anova({{1, 2}, {2, 4}, {3, 3}, {1, 5}});
  ASSERT_TRUE(two);
  EXPECT_DOUBLE_EQ(two->gg_epsilon, 1.0);
  EXPECT_NEAR(two->gg_p, two->p, 1e-15);
}

TEST(RepeatedMeasuresAnova, TwoConditionsEqualsPairedTSquared) {
  const std::vector<double> a = {5.1, 6.3, 4.8, 7.2, 6.0, 5.5};
  const std::vector<double> b = {4.2, 6.0, 4.9, 6.1, 5.2, 4.4};
  std::vector<std::vector<double>> d;
  for (std::size_t i = 0; i < a.size(); ++i) d.push_back({a[i], b[i]});
  auto rm = repeated_measures_anova(d);
  auto t = paired_t_test(a, b);
  ASSERT_TRUE(rm && t);
  EXPECT_NEAR(rm->f, t->t * t->t, 1e-9);
  EXPECT_NEAR(rm->p, t->p, 1e-9);
}

TEST(PairedT, MatchesAHandWorkedCase) {
  // Differences 1, 1.5, 0.5: mean 1, sd 0.5, t = 1 / (0.5 / sqrt 3) = 2 sqrt 3.
  auto t = paired_t_test({5.0, 7.0, 6.5}, {4.0, 5.5, 6.0});
  ASSERT_TRUE(t) << t.error().message;
  EXPECT_DOUBLE_EQ(t->mean_difference, 1.0);
  EXPECT_NEAR(t->sd_difference, 0.5, 1e-15);
  EXPECT_NEAR(t->t, 2.0 * std::sqrt(3.0), 1e-12);
  EXPECT_EQ(t->df, 2.0);
  const double closed = 1.0 - t->t / std::sqrt(2.0 + t->t * t->t);  // 0.07417990022744858
  EXPECT_NEAR(t->p, closed, 1e-12);
  EXPECT_NEAR(t->cohen_dz, 2.0, 1e-12);
  // The t(2) quantile has a closed form, t_q = (2q - 1) sqrt(2 / (4 q (1 - q))):
  // 4.30265 for q = 0.975, as in printed tables.
  const double tcrit = (2 * 0.975 - 1) * std::sqrt(2.0 / (4 * 0.975 * 0.025));
  EXPECT_NEAR(tcrit, 4.30265, 1e-5);
  EXPECT_NEAR(t->ci_lower, 1.0 - tcrit * 0.5 / std::sqrt(3.0), 1e-9);
  EXPECT_NEAR(t->ci_upper, 1.0 + tcrit * 0.5 / std::sqrt(3.0), 1e-9);
}

TEST(MultipleComparisons, BonferroniAndHolmByHand) {
  const std::vector<double> p = {0.01, 0.04, 0.03, 0.005};
  // Bonferroni: each times 4.
  const std::vector<double> bonf = bonferroni(p);
  const std::vector<double> bonf_expected = {0.04, 0.16, 0.12, 0.02};
  // Holm: sorted 0.005*4 = 0.02, 0.01*3 = 0.03, 0.03*2 = 0.06, 0.04*1 = 0.04 -> 0.06 (monotone).
  const std::vector<double> h = holm(p);
  const std::vector<double> holm_expected = {0.03, 0.06, 0.06, 0.02};
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_NEAR(bonf[i], bonf_expected[i], 1e-15) << i;
    EXPECT_NEAR(h[i], holm_expected[i], 1e-15) << i;
  }
  EXPECT_EQ(bonferroni({0.5, 0.6})[1], 1.0);  // capped
  EXPECT_EQ(adjust_p(p, PAdjust::none), p);
}

TEST(Statistics, RejectsBadInput) {
  EXPECT_FALSE(one_way_anova({{1, 2, 3}}));
  EXPECT_FALSE(one_way_anova({{1, 2}, {}}));
  auto nan = one_way_anova({{1, std::nan("")}, {2, 3}});
  ASSERT_FALSE(nan);
  EXPECT_NE(nan.error().message.find("finite"), std::string::npos);
  EXPECT_FALSE(repeated_measures_anova({{1, 2, 3}}));
  EXPECT_FALSE(repeated_measures_anova({{1, 2, 3}, {1, 2}}));
  EXPECT_FALSE(paired_t_test({1, 2}, {1}));
  EXPECT_FALSE(paired_t_test({1}, {2}));
  EXPECT_FALSE(parse_p_adjust("sidak"));
}

// Issue 23.9: data without variance gave F = inf, p = 0, partial eta^2 = 1.
TEST(Statistics, DegenerateDataAreNotTestable) {
  auto flat = repeated_measures_anova({{1, 1, 1}, {1, 1, 1}, {1, 1, 1}});
  ASSERT_TRUE(flat) << flat.error().message;
  EXPECT_FALSE(flat->testable);
  EXPECT_FALSE(flat->not_testable_reason.empty());
  EXPECT_TRUE(std::isnan(flat->f));
  EXPECT_TRUE(std::isnan(flat->p));
  EXPECT_TRUE(std::isnan(flat->gg_p));
  EXPECT_TRUE(std::isnan(flat->partial_eta_squared));
  // Everyone at 100 % in one level, the same offsets elsewhere: no error variance.
  auto ceiling = repeated_measures_anova({{1.0, 0.5}, {1.0, 0.5}, {1.0, 0.5}, {1.0, 0.5}});
  ASSERT_TRUE(ceiling);
  EXPECT_FALSE(ceiling->testable);
  EXPECT_TRUE(std::isnan(ceiling->p));
  // Additive data (subject offset + condition effect, nothing else).
  auto additive = repeated_measures_anova({{0.1, 0.3, 0.7}, {1.1, 1.3, 1.7}, {2.1, 2.3, 2.7}});
  ASSERT_TRUE(additive);
  EXPECT_FALSE(additive->testable) << "round-off error variance is not variance: F " << additive->f;
  auto ow = one_way_anova({{0.1, 0.1}, {0.3, 0.3}});
  ASSERT_TRUE(ow);
  EXPECT_FALSE(ow->testable);
  EXPECT_TRUE(std::isnan(ow->f));
  auto pt = paired_t_test({0.3, 0.5, 0.9}, {0.1, 0.3, 0.7});  // every difference 0.2 (in round-off)
  ASSERT_TRUE(pt);
  EXPECT_FALSE(pt->testable);
  EXPECT_TRUE(std::isnan(pt->p));
  EXPECT_TRUE(std::isnan(pt->t));
  // A not-testable comparison is no comparison for the corrections.
  const std::vector<double> ps = {0.01, std::nan(""), 0.04};
  EXPECT_NEAR(bonferroni(ps)[0], 0.02, 1e-15);
  EXPECT_TRUE(std::isnan(bonferroni(ps)[1]));
  EXPECT_NEAR(holm(ps)[2], 0.04, 1e-15);
  EXPECT_TRUE(std::isnan(holm(ps)[1]));
}

TEST(Statistics, RoundOffSumsOfSquaresAreNoEffect) {
  // A Latin square: the conditions' means are equal, but computed with
  // round-off (0.1 + 0.2 != 0.3): their sum of squares is exactly 0, F = 0, p = 1.
  auto a = repeated_measures_anova({{0.1 + 0.2, 0.4, 0.2}, {0.4, 0.2, 0.3}, {0.2, 0.3, 0.4}});
  ASSERT_TRUE(a) << a.error().message;
  ASSERT_TRUE(a->testable) << a->not_testable_reason;
  EXPECT_EQ(a->ss_conditions, 0.0);
  EXPECT_EQ(a->f, 0.0);
  EXPECT_EQ(a->p, 1.0);
  // Real data stay testable and unchanged (the hand-worked case's F).
  auto real = repeated_measures_anova({{10, 12, 15}, {8, 11, 11}, {9, 9, 14}, {11, 15, 16}, {7, 10, 12}});
  ASSERT_TRUE(real);
  EXPECT_TRUE(real->testable);
  EXPECT_GT(real->f, 1.0);
}

}  // namespace
}  // namespace proprio::study
