// Monte Carlo accuracy of the analysis: bootstrap confidence intervals must
// cover the true threshold of simulated observers about as often as they say.
#include <gtest/gtest.h>

#include <cstdio>

#include "proprio/core/random.hpp"
#include "proprio/study/psychometric.hpp"

namespace proprio::study {
namespace {

TEST(BootstrapCoverage, NinetyFivePercentIntervalsCoverTheTrueThreshold) {
  // A 2AFC observer with a known Weibull; the method of constant stimuli at
  // six levels around threshold, 40 trials each (240 trials, a typical
  // session). 100 simulated experiments, each with a 400-sample bootstrap.
  const PsychometricParams truth{5.0, 3.0, 0.5, 0.0};
  const double true_threshold = *threshold_at(PsychometricModel::weibull, truth, 0.75);
  const std::vector<double> levels = {1.5, 3.0, 4.5, 6.0, 7.5, 9.0};
  constexpr int kExperiments = 100;
  int covered_percentile = 0, covered_bca = 0, finished = 0;
  for (int e = 0; e < kExperiments; ++e) {
    Rng rng(mix_seed(2024, static_cast<std::uint64_t>(e)));
    std::vector<StimulusLevel> data;
    for (double x : levels) {
      int k = 0;
      for (int t = 0; t < 40; ++t) k += rng.uniform01() < psi(PsychometricModel::weibull, truth, x) ? 1 : 0;
      data.push_back({x, k, 40});
    }
    FitOptions o;
    auto fit = fit_psychometric(data, o);
    ASSERT_TRUE(fit) << fit.error().message;
    BootstrapOptions b;
    b.samples = 400;
    b.seed = mix_seed(99, static_cast<std::uint64_t>(e));
    auto boot = bootstrap_psychometric(data, o, *fit, b);
    if (!boot) continue;
    ++finished;
    const ConfidenceInterval p = boot->threshold.percentile, c = boot->threshold.bca;
    covered_percentile += (p.lower <= true_threshold && true_threshold <= p.upper) ? 1 : 0;
    covered_bca += (c.lower <= true_threshold && true_threshold <= c.upper) ? 1 : 0;
  }
  std::printf("bootstrap coverage of the 75%% threshold over %d experiments: percentile %d%%, BCa %d%%\n", finished,
              covered_percentile * 100 / finished, covered_bca * 100 / finished);
  ASSERT_GE(finished, 95);
  // Nominal 95%; with 100 experiments the binomial SD is about 2.2 points, so
  // anything from 88% to 100% is consistent with a correct interval, and a
  // badly biased or too-narrow interval (say 80%) fails.
  EXPECT_GE(covered_percentile, finished * 88 / 100);
  EXPECT_GE(covered_bca, finished * 88 / 100);
  // Intervals that are far too wide would cover every time with room to spare;
  // 100% in both is allowed, but the widths are checked in the unit tests.
}

}  // namespace
}  // namespace proprio::study
