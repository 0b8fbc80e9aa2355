#pragma once
// Psychometric functions and their maximum-likelihood fit, in the Palamedes
// parameterisation (Prins & Kingdom) so published numbers can be compared:
//
//   psi(x) = gamma + (1 - gamma - lambda) * F(x; alpha, beta)
//
// gamma is the guess rate (0.5 for 2AFC), lambda the lapse rate. F is one of
//   weibull            1 - exp(-(x/alpha)^beta)                 (x > 0)
//   logistic           1 / (1 + exp(-beta (x - alpha)))
//   gumbel             1 - exp(-10^(beta (x - alpha)))          (log-Weibull; x in log10 units)
//   cumulative_normal  Phi(beta (x - alpha))                    (beta = 1 / sd)
//
// Goodness of fit and confidence intervals follow Wichmann & Hill (2001):
// deviance against a Monte Carlo distribution from the fitted model, and a
// seeded parametric bootstrap with percentile and BCa intervals.
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <string_view>
#include <vector>

#include "proprio/core/result.hpp"

namespace proprio::study {

enum class PsychometricModel { weibull, logistic, gumbel, cumulative_normal };

const char* to_string(PsychometricModel model) noexcept;
// Accepts "weibull", "logistic", "gumbel" (or "log-weibull"), "normal" (or "cumulative-normal").
Result<PsychometricModel> parse_psychometric_model(std::string_view name);

struct PsychometricParams {
  double alpha = 0.0;   // location (the Weibull's scale)
  double beta = 1.0;    // slope parameter
  double gamma = 0.5;   // guess rate: performance far below threshold
  double lambda = 0.0;  // lapse rate: 1 - lambda is performance far above threshold
};

// The sigmoid F in [0, 1], without guess and lapse rates.
double sigmoid(PsychometricModel model, double alpha, double beta, double x);
// dF/dx.
double sigmoid_derivative(PsychometricModel model, double alpha, double beta, double x);
// x with F(x) = f, for f in (0, 1).
double sigmoid_inverse(PsychometricModel model, double alpha, double beta, double f);

// psi(x): probability of a correct (or "yes") response.
double psi(PsychometricModel model, const PsychometricParams& p, double x);
// The stimulus at which psi reaches `proportion`; an error when the proportion
// lies outside (gamma, 1 - lambda), which the function never reaches.
Result<double> threshold_at(PsychometricModel model, const PsychometricParams& p, double proportion);
// dpsi/dx at x (multiply by the threshold's scale for a dimensionless slope).
double slope_at(PsychometricModel model, const PsychometricParams& p, double x);

// The most trials one level may hold (and the most a data file may hold in
// all): counts are ints.
inline constexpr int kMaxTrials = 1'000'000'000;

// The most binomial draws one bootstrap or goodness-of-fit test may simulate
// (replicas x trials in all): each simulated trial is one random draw, so this
// bounds the run (1e9 draws took 6.5 s of CPU on the 2-vCPU development VM);
// more is refused up front rather than left to look like a hang.
inline constexpr std::int64_t kMaxSimulatedTrials = 2'000'000'000;

// One stimulus level: how many of how many trials were correct.
struct StimulusLevel {
  double level = 0.0;
  int correct = 0;
  int trials = 0;
};

// Checks levels for a fit: finite, counts within 0 <= correct <= trials <=
// kMaxTrials, and at least two levels with trials (Weibull additionally needs
// level > 0).
Status validate_levels(PsychometricModel model, const std::vector<StimulusLevel>& data);

struct FitOptions {
  PsychometricModel model = PsychometricModel::weibull;
  double guess = 0.5;          // gamma, fixed
  bool lapse_free = false;     // false: lambda fixed at `lapse`
  double lapse = 0.0;          // the fixed lambda
  double lapse_max = 0.06;     // free lambda lies in [0, lapse_max]
};

// Checks fit options: the guess rate in [0, 1) and the fixed lapse rate (for
// a free lapse, its maximum) in [0, 1 - guess). Messages name the option that
// holds the bad value as the CLI spells it (--guess, --lapse, --lapse-max).
Status validate_fit_options(const FitOptions& options);
// Checks that a function under `options` reaches `proportion` (the criterion
// that defines the threshold, --threshold): it must lie in (guess, 1 - lapse),
// with the largest lapse a free fit may choose.
Status validate_threshold_proportion(const FitOptions& options, double proportion);

struct PsychometricFit {
  PsychometricModel model = PsychometricModel::weibull;
  PsychometricParams params;
  // Log-likelihood without the binomial coefficients, as Palamedes reports it.
  double log_likelihood = 0.0;
  double deviance = 0.0;  // against the saturated model
  int evaluations = 0;    // of the likelihood, grid included
  // Other maxima the fit reached from other starts whose log-likelihood is
  // within kEquallyLikely of the best: a flat ridge (few trials, or data that
  // separate perfectly) where the data do not pick one function.
  std::vector<PsychometricParams> equally_likely{};
  // Set when the likelihood keeps rising toward an infinitely steep step
  // (responses that separate perfectly): the step may then sit anywhere
  // between these two tested levels at no cost in likelihood.
  std::optional<std::pair<double, double>> step_between{};
};

// Log-likelihood difference below which two solutions count as equally likely
// (a likelihood-ratio chi-square of 0.02: no data could tell them apart).
inline constexpr double kEquallyLikely = 0.01;

struct UniquenessCheck {
  bool unique = true;
  double threshold_min = 0.0, threshold_max = 0.0;  // over the equally likely solutions
  std::string message;                              // empty when unique
};
// Whether the fit's maximum pins down the threshold at `proportion`: not
// unique when equally likely solutions put it more than 3 % of the tested
// range apart (by how much more the search may understate: a flat ridge has
// no ends it could find). The message names the spread and what to do.
UniquenessCheck check_unique_maximum(const PsychometricFit& fit, const std::vector<StimulusLevel>& data,
                                     double proportion);

// Sum over levels of k log psi + (n - k) log(1 - psi).
double log_likelihood(PsychometricModel model, const PsychometricParams& p, const std::vector<StimulusLevel>& data);
// 2 * (logL_saturated - logL_model).
double deviance(PsychometricModel model, const PsychometricParams& p, const std::vector<StimulusLevel>& data);

// Maximum likelihood: a grid search over (alpha, beta[, lambda]) picks the
// starts (the best point, and the extremes of the points nearly as good), a
// bounded Newton method with analytic derivatives polishes each, and the best
// wins; the others that are equally likely go to `equally_likely`.
Result<PsychometricFit> fit_psychometric(const std::vector<StimulusLevel>& data, const FitOptions& options);
// The same, polishing from a given start without the grid.
Result<PsychometricFit> fit_psychometric_from(const std::vector<StimulusLevel>& data, const FitOptions& options,
                                              const PsychometricParams& start);

struct GoodnessOfFit {
  double deviance = 0.0;
  // Fraction of data sets simulated from the fit whose (refitted) deviance is
  // at least the observed one; small values say the model does not fit.
  double p_value = 1.0;
  int simulations = 0;
};
// Simulated data set i comes from Rng(mix_seed(seed, i)) and is refitted from
// its own grid start, exactly as bootstrap_psychometric's replica i with the
// same seed, so a bootstrap's result carries this test for free. `threads`:
// 0 uses every core; the result does not depend on it.
Result<GoodnessOfFit> goodness_of_fit(const std::vector<StimulusLevel>& data, const FitOptions& options,
                                      const PsychometricFit& fit, int simulations, std::uint64_t seed,
                                      int threads = 0);

struct ConfidenceInterval {
  double lower = 0.0;
  double upper = 0.0;
};

struct BootstrapOptions {
  int samples = 1999;
  std::uint64_t seed = 1;
  double coverage = 0.95;         // two-sided
  double threshold_proportion = 0.75;
  bool bca = true;                // BCa needs 2 refits per level for the jackknife
  int threads = 0;                // 0: every core; the result does not depend on it
};

struct BootstrapEstimate {
  double estimate = 0.0;          // from the fit to the data
  double standard_error = 0.0;    // SD of the bootstrap distribution
  ConfidenceInterval percentile;
  ConfidenceInterval bca;         // NaN bounds when BCa is off or undefined
  double bias_correction = 0.0;   // BCa's z0 (NaN when undefined)
  double acceleration = 0.0;      // BCa's a from the jackknife (NaN when BCa is off)
};

struct BootstrapResult {
  int samples = 0;
  int failed_fits = 0;            // simulated sets whose threshold did not exist
  // Refits steeper than any start on the grid (beta > 20 for the Weibull,
  // > 200 / tested range otherwise): simulated data that separate perfectly.
  int steep_refits = 0;
  GoodnessOfFit goodness_of_fit;  // from the same simulated data sets
  double coverage = 0.95;
  double threshold_proportion = 0.75;
  BootstrapEstimate alpha, beta, lambda, threshold, slope;
};

// Parametric bootstrap: simulate binomial data from the fit at the observed
// levels and trial counts, refit each from its own grid start (never from the
// fit, which would pin every refit to it on a flat likelihood), and read
// intervals off the distribution.
Result<BootstrapResult> bootstrap_psychometric(const std::vector<StimulusLevel>& data, const FitOptions& options,
                                               const PsychometricFit& fit, const BootstrapOptions& bootstrap);

// The stimulus where the observed proportion correct first reaches
// `proportion`, interpolated linearly between the two neighbouring levels
// (levels sorted, equal levels pooled). The thesis uses it where the Weibull's
// shape does not fit the data. An error when the data never cross it.
Result<double> interpolated_threshold(const std::vector<StimulusLevel>& data, double proportion);

// Pools equal levels and sorts by level.
std::vector<StimulusLevel> pool_levels(std::vector<StimulusLevel> data);

// BCa's acceleration from jackknife values theta_(i) with weights w_i (how
// many deletions give that value): sum w d^3 / (6 (sum w d^2)^1.5), d = mean -
// theta_(i) (Efron & Tibshirani 1993, eq. 14.15). 0 when the values are equal.
double jackknife_acceleration(const std::vector<double>& values, const std::vector<double>& weights);

// Quantile with linear interpolation between order statistics (R type 7,
// numpy's default); `sorted` must be sorted ascending and non-empty.
double quantile_sorted(const std::vector<double>& sorted, double q);

}  // namespace proprio::study
