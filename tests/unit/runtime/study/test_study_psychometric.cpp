// Psychometric fits against Palamedes' published demo answers, plus the
// function algebra (inverse, slope) checked against finite differences.
#include <gtest/gtest.h>

#include <cmath>

#include "proprio/core/random.hpp"
#include "proprio/study/psychometric.hpp"

namespace proprio::study {
namespace {

// Palamedes demo data (PAL_PFML_Demo): 100 trials at each of six levels.
std::vector<StimulusLevel> palamedes_demo() {
  return {{0.01, 59, 100}, {0.03, 53, 100}, {0.05, 68, 100}, {0.07, 83, 100}, {0.09, 92, 100}, {0.11, 99, 100}};
}

void expect_relative(double actual, double expected, double tolerance, const char* what) {
  EXPECT_LE(std::abs(actual - expected), tolerance * std::abs(expected))
      << what << ": got " << actual << ", expected " << expected;
}

TEST(PsychometricFit, WeibullNoLapseMatchesPalamedes) {
  FitOptions o;
  o.model = PsychometricModel::weibull;
  o.guess = 0.5;
  o.lapse = 0.0;
  auto fit = fit_psychometric(palamedes_demo(), o);
  ASSERT_TRUE(fit) << fit.error().message;
  expect_relative(fit->params.alpha, 0.069154, 1e-4, "alpha");
  expect_relative(fit->params.beta, 2.69185, 1e-4, "beta");
  expect_relative(fit->log_likelihood, -280.4940, 1e-4, "log-likelihood");
  auto t75 = threshold_at(fit->model, fit->params, 0.75);
  ASSERT_TRUE(t75);
  expect_relative(*t75, 0.0603511, 1e-4, "75% threshold");
  EXPECT_NEAR(psi(fit->model, fit->params, *t75), 0.75, 1e-12);
}

TEST(PsychometricFit, WeibullLapse002MatchesPalamedes) {
  FitOptions o;
  o.lapse = 0.02;
  auto fit = fit_psychometric(palamedes_demo(), o);
  ASSERT_TRUE(fit) << fit.error().message;
  expect_relative(fit->params.alpha, 0.0667925, 1e-4, "alpha");
  expect_relative(fit->params.beta, 2.90434, 1e-4, "beta");
  EXPECT_EQ(fit->params.lambda, 0.02);
}

TEST(PsychometricFit, LogisticLapse002MatchesPalamedes) {
  FitOptions o;
  o.model = PsychometricModel::logistic;
  o.lapse = 0.02;
  auto fit = fit_psychometric(palamedes_demo(), o);
  ASSERT_TRUE(fit) << fit.error().message;
  expect_relative(fit->params.alpha, 0.0584006, 1e-4, "alpha");
  expect_relative(fit->params.beta, 71.0136, 1e-4, "beta");
}

TEST(PsychometricFit, FreeLapseStaysInBoundsAndFitsAtLeastAsWell) {
  FitOptions fixed;
  FitOptions free = fixed;
  free.lapse_free = true;
  free.lapse_max = 0.06;
  auto a = fit_psychometric(palamedes_demo(), fixed);
  auto b = fit_psychometric(palamedes_demo(), free);
  ASSERT_TRUE(a && b);
  EXPECT_GE(b->params.lambda, 0.0);
  EXPECT_LE(b->params.lambda, 0.06);
  // lambda = 0 is inside the free model, so its optimum cannot be worse.
  EXPECT_GE(b->log_likelihood, a->log_likelihood - 1e-9);
}

TEST(PsychometricFit, RecoversGeneratingParametersFromLargeSamples) {
  // Expected counts (rounded) from a known function: every model must find
  // parameters close to the generating ones.
  struct Case {
    PsychometricModel model;
    PsychometricParams truth;
    std::vector<double> levels;
  };
  const std::vector<Case> cases = {
      {PsychometricModel::weibull, {4.0, 3.0, 0.5, 0.0}, {1, 2, 3, 4, 5, 6, 7}},
      {PsychometricModel::logistic, {4.0, 1.5, 0.5, 0.0}, {1, 2, 3, 4, 5, 6, 7}},
      {PsychometricModel::gumbel, {0.6, 3.0, 0.5, 0.0}, {0.0, 0.2, 0.4, 0.6, 0.8, 1.0}},
      {PsychometricModel::cumulative_normal, {0.0, 1.0, 0.0, 0.0}, {-2, -1, -0.5, 0, 0.5, 1, 2}},
  };
  for (const Case& c : cases) {
    std::vector<StimulusLevel> data;
    for (double x : c.levels) {
      const int n = 100000;
      data.push_back({x, static_cast<int>(std::lround(n * psi(c.model, c.truth, x))), n});
    }
    FitOptions o;
    o.model = c.model;
    o.guess = c.truth.gamma;
    auto fit = fit_psychometric(data, o);
    ASSERT_TRUE(fit) << to_string(c.model) << ": " << fit.error().message;
    EXPECT_NEAR(fit->params.alpha, c.truth.alpha, 2e-3 * (1 + std::abs(c.truth.alpha))) << to_string(c.model);
    EXPECT_NEAR(fit->params.beta, c.truth.beta, 1e-2 * c.truth.beta) << to_string(c.model);
    EXPECT_LT(fit->deviance, 1.0) << to_string(c.model);
  }
}

TEST(PsychometricFunction, InverseAndSlopeAgreeWithTheFunction) {
  const PsychometricParams p{0.3, 2.5, 0.5, 0.03};
  for (PsychometricModel m : {PsychometricModel::weibull, PsychometricModel::logistic, PsychometricModel::gumbel,
                              PsychometricModel::cumulative_normal}) {
    for (double target : {0.6, 0.75, 0.9}) {
      auto x = threshold_at(m, p, target);
      ASSERT_TRUE(x) << to_string(m);
      EXPECT_NEAR(psi(m, p, *x), target, 1e-12) << to_string(m);
      const double h = 1e-6;
      const double numeric = (psi(m, p, *x + h) - psi(m, p, *x - h)) / (2 * h);
      EXPECT_NEAR(slope_at(m, p, *x), numeric, 1e-6 * (1 + std::abs(numeric))) << to_string(m);
    }
    // Outside (gamma, 1 - lambda) there is no threshold.
    EXPECT_FALSE(threshold_at(m, p, 0.4));
    EXPECT_FALSE(threshold_at(m, p, 0.98));
  }
}

TEST(PsychometricFit, DevianceOfSaturatedDataIsZeroAndGrowsWithMisfit) {
  const PsychometricParams p{0.06, 3.0, 0.5, 0.0};
  std::vector<StimulusLevel> exact;
  for (double x : {0.02, 0.04, 0.06, 0.08}) {
    // Counts chosen so k/n equals psi to within rounding (n large).
    const int n = 1000000;
    exact.push_back({x, static_cast<int>(std::lround(n * psi(PsychometricModel::weibull, p, x))), n});
  }
  EXPECT_LT(deviance(PsychometricModel::weibull, p, exact), 1e-3);
  PsychometricParams off = p;
  off.alpha = 0.07;
  EXPECT_GT(deviance(PsychometricModel::weibull, off, exact), 100.0);
}

TEST(PsychometricFit, GoodnessOfFitIsSeededAndFlagsAWrongModel) {
  FitOptions o;
  auto fit = fit_psychometric(palamedes_demo(), o);
  ASSERT_TRUE(fit);
  auto g1 = goodness_of_fit(palamedes_demo(), o, *fit, 200, 7);
  auto g2 = goodness_of_fit(palamedes_demo(), o, *fit, 200, 7);
  ASSERT_TRUE(g1 && g2);
  EXPECT_EQ(g1->p_value, g2->p_value);
  EXPECT_NEAR(g1->deviance, fit->deviance, 1e-12);
  // Palamedes' demo data fit the Weibull acceptably.
  EXPECT_GT(g1->p_value, 0.05);

  // Non-monotonic data (a dip in the middle) do not fit any sigmoid.
  const std::vector<StimulusLevel> bad = {{1, 50, 100}, {2, 95, 100}, {3, 55, 100}, {4, 98, 100}, {5, 60, 100}};
  auto bad_fit = fit_psychometric(bad, o);
  ASSERT_TRUE(bad_fit);
  auto g = goodness_of_fit(bad, o, *bad_fit, 200, 7);
  ASSERT_TRUE(g);
  EXPECT_LT(g->p_value, 0.01);
}

TEST(PsychometricBootstrap, IsReproducibleForASeedAndBracketsTheEstimate) {
  FitOptions o;
  auto fit = fit_psychometric(palamedes_demo(), o);
  ASSERT_TRUE(fit);
  BootstrapOptions b;
  b.samples = 200;
  b.seed = 42;
  auto r1 = bootstrap_psychometric(palamedes_demo(), o, *fit, b);
  auto r2 = bootstrap_psychometric(palamedes_demo(), o, *fit, b);
  ASSERT_TRUE(r1 && r2) << (r1 ? "" : r1.error().message);
  EXPECT_EQ(r1->threshold.percentile.lower, r2->threshold.percentile.lower);
  EXPECT_EQ(r1->threshold.bca.upper, r2->threshold.bca.upper);
  for (const BootstrapEstimate* e : {&r1->alpha, &r1->threshold}) {
    EXPECT_LT(e->percentile.lower, e->estimate);
    EXPECT_GT(e->percentile.upper, e->estimate);
    EXPECT_LT(e->bca.lower, e->estimate);
    EXPECT_GT(e->bca.upper, e->estimate);
    EXPECT_GT(e->standard_error, 0.0);
  }
  // A different seed gives a different (but similar) interval.
  b.seed = 43;
  auto r3 = bootstrap_psychometric(palamedes_demo(), o, *fit, b);
  ASSERT_TRUE(r3);
  EXPECT_NE(r3->threshold.percentile.lower, r1->threshold.percentile.lower);
  EXPECT_NEAR(r3->threshold.percentile.lower, r1->threshold.percentile.lower, 0.005);
}

TEST(InterpolatedThreshold, InterpolatesBetweenTheBracketingLevels) {
  // 0.5 at 1, 0.6 at 2, 0.9 at 3: 0.75 lies halfway between 2 and 3.
  const std::vector<StimulusLevel> d = {{3, 9, 10}, {1, 5, 10}, {2, 6, 10}};
  auto t = interpolated_threshold(d, 0.75);
  ASSERT_TRUE(t) << t.error().message;
  EXPECT_DOUBLE_EQ(*t, 2.5);
  // Non-monotonic data: the first crossing counts.
  const std::vector<StimulusLevel> dip = {{1, 4, 10}, {2, 8, 10}, {3, 6, 10}, {4, 10, 10}};
  auto t2 = interpolated_threshold(dip, 0.75);
  ASSERT_TRUE(t2);
  EXPECT_NEAR(*t2, 1.0 + (0.75 - 0.4) / (0.8 - 0.4), 1e-12);
  EXPECT_FALSE(interpolated_threshold(d, 0.95));  // never reached
  EXPECT_FALSE(interpolated_threshold(d, 0.4));   // already above at the lowest level
}

TEST(PsychometricFit, RejectsBadInputWithAClearMessage) {
  FitOptions o;
  auto one_level = fit_psychometric({{0.05, 5, 10}}, o);
  ASSERT_FALSE(one_level);
  EXPECT_NE(one_level.error().message.find("two or more"), std::string::npos);
  auto nan_level = fit_psychometric({{std::nan(""), 5, 10}, {0.1, 8, 10}}, o);
  ASSERT_FALSE(nan_level);
  EXPECT_NE(nan_level.error().message.find("finite"), std::string::npos);
  auto impossible = fit_psychometric({{0.05, 12, 10}, {0.1, 8, 10}}, o);
  ASSERT_FALSE(impossible);
  auto negative = fit_psychometric({{-1, 5, 10}, {0.1, 8, 10}}, o);
  ASSERT_FALSE(negative);
  EXPECT_NE(negative.error().message.find("positive"), std::string::npos);
  o.lapse_free = true;
  o.lapse_max = 0.7;
  EXPECT_FALSE(fit_psychometric(palamedes_demo(), o));
  EXPECT_FALSE(parse_psychometric_model("probit"));
  EXPECT_EQ(*parse_psychometric_model("normal"), PsychometricModel::cumulative_normal);
}

}  // namespace
}  // namespace proprio::study
