#include "proprio/study/psychometric.hpp"

#include <algorithm>
#include <array>
#include <boost/math/distributions/normal.hpp>
#include <cmath>
#include <fmt/format.h>
#include <limits>
#include <map>

#include "nelder_mead.hpp"
#include "proprio/core/random.hpp"

namespace proprio::study {
namespace {

constexpr double kLn10 = 2.302585092994045684;
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double standard_normal_cdf(double z) { return 0.5 * std::erfc(-z / std::sqrt(2.0)); }
double standard_normal_quantile(double p) {
  return boost::math::quantile(boost::math::normal_distribution<double>(0.0, 1.0), p);
}

// k log k/(n p) terms with 0 log 0 = 0.
double xlogy_ratio(double k, double expected) { return k > 0.0 ? k * std::log(k / expected) : 0.0; }

// The search works in unconstrained coordinates: log(alpha) for the Weibull
// (alpha > 0), log(beta) always (beta > 0), and lambda = max (1 + sin u) / 2
// when the lapse is free, so every simplex point is a valid function.
struct Parameterisation {
  FitOptions options;
  double log_beta_min = 0.0, log_beta_max = 0.0;  // search box for log(beta)
  double u_alpha_min = 0.0, u_alpha_max = 0.0;    // search box for alpha's coordinate

  std::size_t dimensions() const { return options.lapse_free ? 3 : 2; }

  PsychometricParams to_params(const std::vector<double>& u) const {
    PsychometricParams p;
    p.alpha = options.model == PsychometricModel::weibull ? std::exp(u[0]) : u[0];
    p.beta = std::exp(u[1]);
    p.gamma = options.guess;
    p.lambda = options.lapse_free ? options.lapse_max * 0.5 * (1.0 + std::sin(u[2])) : options.lapse;
    return p;
  }
  std::vector<double> to_search(const PsychometricParams& p) const {
    std::vector<double> u(dimensions());
    u[0] = options.model == PsychometricModel::weibull ? std::log(p.alpha) : p.alpha;
    u[1] = std::log(p.beta);
    if (options.lapse_free) {
      const double s = options.lapse_max > 0.0 ? std::clamp(2.0 * p.lambda / options.lapse_max - 1.0, -1.0, 1.0) : 0.0;
      u[2] = std::asin(s);
    }
    return u;
  }
};

Status validate_options(const FitOptions& o) {
  if (!(o.guess >= 0.0 && o.guess < 1.0)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("guess rate {} is outside [0, 1): use 0.5 for 2AFC, 1/m for m-AFC, 0 for yes/no", o.guess));
  }
  if (o.lapse_free) {
    if (!(o.lapse_max >= 0.0 && o.lapse_max < 1.0 - o.guess)) {
      return make_error(Errc::invalid_argument,
                        fmt::format("maximum lapse rate {} must lie in [0, 1 - guess) (e.g. 0.06)", o.lapse_max));
    }
  } else if (!(o.lapse >= 0.0 && o.lapse < 1.0 - o.guess)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("lapse rate {} must lie in [0, 1 - guess) (e.g. 0 or 0.02)", o.lapse));
  }
  return Status::success();
}

// Levels with trials only.
std::vector<StimulusLevel> used_levels(const std::vector<StimulusLevel>& data) {
  std::vector<StimulusLevel> out;
  for (const StimulusLevel& s : data) {
    if (s.trials > 0) out.push_back(s);
  }
  return out;
}

Result<PsychometricFit> polish(const std::vector<StimulusLevel>& data, const Parameterisation& param,
                               const PsychometricParams& start, int evaluations_so_far) {
  const PsychometricModel model = param.options.model;
  auto objective = [&](const std::vector<double>& u) {
    if (u[1] < param.log_beta_min || u[1] > param.log_beta_max) return kInf;
    if (u[0] < param.u_alpha_min || u[0] > param.u_alpha_max) return kInf;
    return -log_likelihood(model, param.to_params(u), data);
  };
  detail::NelderMeadOptions nm;
  // A start outside the search box (a caller's guess) is moved inside it.
  std::vector<double> u0 = param.to_search(start);
  u0[0] = std::clamp(u0[0], param.u_alpha_min, param.u_alpha_max);
  u0[1] = std::clamp(u0[1], param.log_beta_min, param.log_beta_max);
  const detail::NelderMeadResult r = detail::nelder_mead(objective, u0, nm);
  if (!std::isfinite(r.f)) {
    return make_error(Errc::invalid_argument, "the likelihood is not finite anywhere the search looked; check the data");
  }
  PsychometricFit fit;
  fit.model = model;
  fit.params = param.to_params(r.x);
  fit.log_likelihood = -r.f;
  fit.deviance = deviance(model, fit.params, data);
  fit.evaluations = evaluations_so_far + r.evaluations;
  return fit;
}

Parameterisation make_parameterisation(const std::vector<StimulusLevel>& data, const FitOptions& options) {
  Parameterisation param{options};
  double lo = kInf, hi = -kInf;
  for (const StimulusLevel& s : data) {
    lo = std::min(lo, s.level);
    hi = std::max(hi, s.level);
  }
  // beta is dimensionless for the Weibull and in 1/stimulus units otherwise.
  // The box is generous (beta 100 times beyond the grid both ways, alpha up to
  // 100 times the tested range away) and only stops small or separable data
  // sets (and their bootstrap replicas) from running off to infinity, where
  // the threshold means nothing anyway.
  const double span = std::max(hi - lo, 1e-12);
  if (options.model == PsychometricModel::weibull) {
    param.log_beta_min = std::log(0.5e-2);
    param.log_beta_max = std::log(20e2);
    param.u_alpha_min = std::log(lo / 100.0);
    param.u_alpha_max = std::log(hi * 100.0);
  } else {
    param.log_beta_min = std::log(0.5e-2 / span);
    param.log_beta_max = std::log(200e2 / span);
    param.u_alpha_min = lo - 100.0 * span;
    param.u_alpha_max = hi + 100.0 * span;
  }
  return param;
}

}  // namespace

const char* to_string(PsychometricModel model) noexcept {
  switch (model) {
    case PsychometricModel::weibull: return "weibull";
    case PsychometricModel::logistic: return "logistic";
    case PsychometricModel::gumbel: return "gumbel";
    case PsychometricModel::cumulative_normal: return "normal";
  }
  return "?";
}

Result<PsychometricModel> parse_psychometric_model(std::string_view name) {
  if (name == "weibull") return PsychometricModel::weibull;
  if (name == "logistic") return PsychometricModel::logistic;
  if (name == "gumbel" || name == "log-weibull") return PsychometricModel::gumbel;
  if (name == "normal" || name == "cumulative-normal" || name == "cumulative_normal") {
    return PsychometricModel::cumulative_normal;
  }
  return make_error(Errc::invalid_argument, fmt::format("unknown psychometric model '{}': choose weibull, logistic, "
                                                        "gumbel or normal",
                                                        name));
}

double sigmoid(PsychometricModel model, double alpha, double beta, double x) {
  switch (model) {
    case PsychometricModel::weibull:
      return x <= 0.0 ? 0.0 : -std::expm1(-std::pow(x / alpha, beta));
    case PsychometricModel::logistic:
      return 1.0 / (1.0 + std::exp(-beta * (x - alpha)));
    case PsychometricModel::gumbel:
      return -std::expm1(-std::pow(10.0, beta * (x - alpha)));
    case PsychometricModel::cumulative_normal:
      return standard_normal_cdf(beta * (x - alpha));
  }
  return kNaN;
}

double sigmoid_derivative(PsychometricModel model, double alpha, double beta, double x) {
  switch (model) {
    case PsychometricModel::weibull: {
      if (x <= 0.0) return 0.0;
      const double r = std::pow(x / alpha, beta);
      return beta / x * r * std::exp(-r);
    }
    case PsychometricModel::logistic: {
      const double f = sigmoid(model, alpha, beta, x);
      return beta * f * (1.0 - f);
    }
    case PsychometricModel::gumbel: {
      const double t = std::pow(10.0, beta * (x - alpha));
      return kLn10 * beta * t * std::exp(-t);
    }
    case PsychometricModel::cumulative_normal: {
      const double z = beta * (x - alpha);
      return beta * std::exp(-0.5 * z * z) / std::sqrt(2.0 * M_PI);
    }
  }
  return kNaN;
}

double sigmoid_inverse(PsychometricModel model, double alpha, double beta, double f) {
  switch (model) {
    case PsychometricModel::weibull: return alpha * std::pow(-std::log1p(-f), 1.0 / beta);
    case PsychometricModel::logistic: return alpha + std::log(f / (1.0 - f)) / beta;
    case PsychometricModel::gumbel: return alpha + std::log10(-std::log1p(-f)) / beta;
    case PsychometricModel::cumulative_normal: return alpha + standard_normal_quantile(f) / beta;
  }
  return kNaN;
}

double psi(PsychometricModel model, const PsychometricParams& p, double x) {
  return p.gamma + (1.0 - p.gamma - p.lambda) * sigmoid(model, p.alpha, p.beta, x);
}

Result<double> threshold_at(PsychometricModel model, const PsychometricParams& p, double proportion) {
  const double span = 1.0 - p.gamma - p.lambda;
  const double f = (proportion - p.gamma) / span;
  if (!(span > 0.0) || !(f > 0.0 && f < 1.0)) {
    return make_error(Errc::out_of_range,
                      fmt::format("the function never reaches proportion {}: it runs from the guess rate {} to 1 - "
                                  "lapse = {}",
                                  proportion, p.gamma, 1.0 - p.lambda));
  }
  return sigmoid_inverse(model, p.alpha, p.beta, f);
}

double slope_at(PsychometricModel model, const PsychometricParams& p, double x) {
  return (1.0 - p.gamma - p.lambda) * sigmoid_derivative(model, p.alpha, p.beta, x);
}

Status validate_levels(PsychometricModel model, const std::vector<StimulusLevel>& data) {
  int with_trials = 0;
  for (std::size_t i = 0; i < data.size(); ++i) {
    const StimulusLevel& s = data[i];
    if (!std::isfinite(s.level)) {
      return make_error(Errc::invalid_argument, fmt::format("level {} (row {}) is not a finite number", s.level, i + 1));
    }
    if (s.trials < 0 || s.correct < 0 || s.correct > s.trials) {
      return make_error(Errc::invalid_argument,
                        fmt::format("at level {} (row {}): {} correct of {} trials is impossible; need 0 <= correct "
                                    "<= trials",
                                    s.level, i + 1, s.correct, s.trials));
    }
    if (model == PsychometricModel::weibull && s.level <= 0.0 && s.trials > 0) {
      return make_error(Errc::invalid_argument,
                        fmt::format("the Weibull needs positive stimulus levels, but row {} has level {}; use the "
                                    "logistic or normal model, or the Gumbel on log10 levels",
                                    i + 1, s.level));
    }
    if (s.trials > 0) ++with_trials;
  }
  std::map<double, int> distinct;
  for (const StimulusLevel& s : data) {
    if (s.trials > 0) distinct[s.level] += s.trials;
  }
  if (distinct.size() < 2) {
    return make_error(Errc::invalid_argument,
                      fmt::format("a psychometric fit needs trials at two or more different levels; got {}",
                                  distinct.size()));
  }
  (void)with_trials;
  return Status::success();
}

double log_likelihood(PsychometricModel model, const PsychometricParams& p, const std::vector<StimulusLevel>& data) {
  constexpr double kEps = 1e-300;
  double ll = 0.0;
  for (const StimulusLevel& s : data) {
    if (s.trials <= 0) continue;
    const double q = psi(model, p, s.level);
    if (!(q >= 0.0 && q <= 1.0)) return -kInf;
    if (s.correct > 0) ll += s.correct * std::log(std::max(q, kEps));
    if (s.trials > s.correct) ll += (s.trials - s.correct) * std::log(std::max(1.0 - q, kEps));
  }
  return ll;
}

double deviance(PsychometricModel model, const PsychometricParams& p, const std::vector<StimulusLevel>& data) {
  double d = 0.0;
  for (const StimulusLevel& s : data) {
    if (s.trials <= 0) continue;
    const double q = std::clamp(psi(model, p, s.level), 1e-300, 1.0 - 1e-16);
    const double k = s.correct, n = s.trials;
    d += xlogy_ratio(k, n * q) + xlogy_ratio(n - k, n * (1.0 - q));
  }
  return 2.0 * d;
}

Result<PsychometricFit> fit_psychometric(const std::vector<StimulusLevel>& raw, const FitOptions& options) {
  if (Status s = validate_options(options); !s) return s.error();
  if (Status s = validate_levels(options.model, raw); !s) return s.error();
  const std::vector<StimulusLevel> data = used_levels(raw);
  const Parameterisation param = make_parameterisation(data, options);

  double lo = kInf, hi = -kInf;
  for (const StimulusLevel& s : data) {
    lo = std::min(lo, s.level);
    hi = std::max(hi, s.level);
  }
  // Grid: alpha across (and a little beyond) the tested range, beta over
  // three decades, lambda at a few values; the best point starts the simplex.
  constexpr int kAlphaSteps = 40, kBetaSteps = 30;
  std::vector<double> alphas, betas, lambdas;
  for (int i = 0; i < kAlphaSteps; ++i) {
    const double t = static_cast<double>(i) / (kAlphaSteps - 1);
    if (options.model == PsychometricModel::weibull) {
      alphas.push_back(std::exp(std::log(lo * 0.5) + t * (std::log(hi * 2.0) - std::log(lo * 0.5))));
    } else {
      const double span = hi - lo;
      alphas.push_back(lo - 0.5 * span + t * 2.0 * span);
    }
  }
  const double beta_lo = options.model == PsychometricModel::weibull ? 0.5 : 0.5 / (hi - lo);
  const double beta_hi = options.model == PsychometricModel::weibull ? 20.0 : 200.0 / (hi - lo);
  for (int i = 0; i < kBetaSteps; ++i) {
    const double t = static_cast<double>(i) / (kBetaSteps - 1);
    betas.push_back(std::exp(std::log(beta_lo) + t * (std::log(beta_hi) - std::log(beta_lo))));
  }
  if (options.lapse_free) {
    lambdas = {0.0, 0.25 * options.lapse_max, 0.5 * options.lapse_max, options.lapse_max};
  } else {
    lambdas = {options.lapse};
  }
  PsychometricParams best{alphas[0], betas[0], options.guess, lambdas[0]};
  double best_ll = -kInf;
  int evaluations = 0;
  for (double lambda : lambdas) {
    for (double alpha : alphas) {
      for (double beta : betas) {
        const PsychometricParams p{alpha, beta, options.guess, lambda};
        const double ll = log_likelihood(options.model, p, data);
        ++evaluations;
        if (ll > best_ll) {
          best_ll = ll;
          best = p;
        }
      }
    }
  }
  // A lapse on the boundary sits where sin() is flat; start just inside.
  if (options.lapse_free) best.lambda = std::clamp(best.lambda, 0.05 * options.lapse_max, 0.95 * options.lapse_max);
  return polish(data, param, best, evaluations);
}

Result<PsychometricFit> fit_psychometric_from(const std::vector<StimulusLevel>& raw, const FitOptions& options,
                                              const PsychometricParams& start) {
  if (Status s = validate_options(options); !s) return s.error();
  if (Status s = validate_levels(options.model, raw); !s) return s.error();
  const std::vector<StimulusLevel> data = used_levels(raw);
  PsychometricParams p = start;
  p.gamma = options.guess;
  if (!options.lapse_free) p.lambda = options.lapse;
  if (options.lapse_free) p.lambda = std::clamp(p.lambda, 0.05 * options.lapse_max, 0.95 * options.lapse_max);
  return polish(data, make_parameterisation(data, options), p, 0);
}

namespace {

std::vector<StimulusLevel> simulate(const std::vector<StimulusLevel>& data, PsychometricModel model,
                                    const PsychometricParams& p, Rng& rng) {
  std::vector<StimulusLevel> out = data;
  for (StimulusLevel& s : out) {
    const double q = psi(model, p, s.level);
    int k = 0;
    for (int t = 0; t < s.trials; ++t) k += rng.uniform01() < q ? 1 : 0;
    s.correct = k;
  }
  return out;
}

// The statistics a bootstrap tracks, in a fixed order.
constexpr std::size_t kStats = 5;  // alpha, beta, lambda, threshold, slope
bool statistics_of(const PsychometricFit& fit, double proportion, std::array<double, kStats>& out) {
  const Result<double> t = threshold_at(fit.model, fit.params, proportion);
  if (!t) return false;
  out = {fit.params.alpha, fit.params.beta, fit.params.lambda, *t, slope_at(fit.model, fit.params, *t)};
  return true;
}

}  // namespace

Result<GoodnessOfFit> goodness_of_fit(const std::vector<StimulusLevel>& raw, const FitOptions& options,
                                      const PsychometricFit& fit, int simulations, std::uint64_t seed) {
  if (simulations < 1) return make_error(Errc::invalid_argument, "goodness of fit needs at least one simulation");
  if (Status s = validate_levels(options.model, raw); !s) return s.error();
  const std::vector<StimulusLevel> data = used_levels(raw);
  Rng rng(seed);
  GoodnessOfFit g;
  g.deviance = deviance(fit.model, fit.params, data);
  g.simulations = simulations;
  int at_least = 0;
  for (int i = 0; i < simulations; ++i) {
    const std::vector<StimulusLevel> sim = simulate(data, fit.model, fit.params, rng);
    Result<PsychometricFit> refit = fit_psychometric_from(sim, options, fit.params);
    if (!refit) return refit.error();
    if (refit->deviance >= g.deviance) ++at_least;
  }
  // As Palamedes (PAL_PFML_GoodnessOfFit): the plain fraction.
  g.p_value = static_cast<double>(at_least) / simulations;
  return g;
}

double quantile_sorted(const std::vector<double>& sorted, double q) {
  if (std::isnan(q) || sorted.empty()) return kNaN;
  const double h = (static_cast<double>(sorted.size()) - 1.0) * std::clamp(q, 0.0, 1.0);
  const auto lo = static_cast<std::size_t>(std::floor(h));
  const std::size_t hi = std::min(lo + 1, sorted.size() - 1);
  return sorted[lo] + (h - static_cast<double>(lo)) * (sorted[hi] - sorted[lo]);
}

Result<BootstrapResult> bootstrap_psychometric(const std::vector<StimulusLevel>& raw, const FitOptions& options,
                                               const PsychometricFit& fit, const BootstrapOptions& bootstrap) {
  if (bootstrap.samples < 10) {
    return make_error(Errc::invalid_argument,
                      fmt::format("a bootstrap needs at least 10 samples (1999 is usual); got {}", bootstrap.samples));
  }
  if (!(bootstrap.coverage > 0.0 && bootstrap.coverage < 1.0)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("confidence level {} must lie in (0, 1), e.g. 0.95", bootstrap.coverage));
  }
  if (Status s = validate_levels(options.model, raw); !s) return s.error();
  const std::vector<StimulusLevel> data = used_levels(raw);
  std::array<double, kStats> observed{};
  if (!statistics_of(fit, bootstrap.threshold_proportion, observed)) {
    return threshold_at(fit.model, fit.params, bootstrap.threshold_proportion).error();
  }

  Rng rng(bootstrap.seed);
  std::array<std::vector<double>, kStats> samples;
  BootstrapResult result;
  result.coverage = bootstrap.coverage;
  result.threshold_proportion = bootstrap.threshold_proportion;
  for (int i = 0; i < bootstrap.samples; ++i) {
    const std::vector<StimulusLevel> sim = simulate(data, fit.model, fit.params, rng);
    Result<PsychometricFit> refit = fit_psychometric_from(sim, options, fit.params);
    std::array<double, kStats> stats{};
    if (!refit || !statistics_of(*refit, bootstrap.threshold_proportion, stats)) {
      ++result.failed_fits;
      continue;
    }
    for (std::size_t k = 0; k < kStats; ++k) samples[k].push_back(stats[k]);
  }
  result.samples = static_cast<int>(samples[0].size());
  if (result.samples < 10) {
    return make_error(Errc::invalid_argument,
                      fmt::format("only {} of {} bootstrap refits gave a threshold at {}; the data cannot pin it down",
                                  result.samples, bootstrap.samples, bootstrap.threshold_proportion));
  }

  // Jackknife (leave one trial out) for the BCa acceleration. With binomial
  // data only two distinct deletions exist per level: a correct or an
  // incorrect trial, weighted by how many of each there are.
  std::array<double, kStats> acceleration{};
  bool have_acceleration = false;
  if (bootstrap.bca) {
    std::vector<std::pair<std::array<double, kStats>, double>> jack;  // (statistics, weight)
    bool ok = true;
    for (std::size_t l = 0; l < data.size() && ok; ++l) {
      for (int drop_correct = 0; drop_correct < 2 && ok; ++drop_correct) {
        const int weight = drop_correct ? data[l].correct : data[l].trials - data[l].correct;
        if (weight == 0) continue;
        std::vector<StimulusLevel> d = data;
        d[l].trials -= 1;
        d[l].correct -= drop_correct;
        Result<PsychometricFit> refit = fit_psychometric_from(d, options, fit.params);
        std::array<double, kStats> stats{};
        if (!refit || !statistics_of(*refit, bootstrap.threshold_proportion, stats)) {
          ok = false;
          break;
        }
        jack.emplace_back(stats, weight);
      }
    }
    if (ok && !jack.empty()) {
      have_acceleration = true;
      for (std::size_t k = 0; k < kStats; ++k) {
        double total = 0.0, mean = 0.0;
        for (const auto& [s, w] : jack) {
          mean += w * s[k];
          total += w;
        }
        mean /= total;
        double num = 0.0, den = 0.0;
        for (const auto& [s, w] : jack) {
          const double d = mean - s[k];
          num += w * d * d * d;
          den += w * d * d;
        }
        acceleration[k] = den > 0.0 ? num / (6.0 * std::pow(den, 1.5)) : 0.0;
      }
    }
  }

  const double tail = 0.5 * (1.0 - bootstrap.coverage);
  BootstrapEstimate* targets[kStats] = {&result.alpha, &result.beta, &result.lambda, &result.threshold,
                                        &result.slope};
  for (std::size_t k = 0; k < kStats; ++k) {
    std::vector<double>& v = samples[k];
    std::sort(v.begin(), v.end());
    BootstrapEstimate& e = *targets[k];
    e.estimate = observed[k];
    double mean = 0.0;
    for (double x : v) mean += x;
    mean /= static_cast<double>(v.size());
    double ss = 0.0;
    for (double x : v) ss += (x - mean) * (x - mean);
    e.standard_error = std::sqrt(ss / static_cast<double>(v.size() - 1));
    e.percentile = {quantile_sorted(v, tail), quantile_sorted(v, 1.0 - tail)};
    e.bca = {kNaN, kNaN};
    if (!have_acceleration) continue;
    // Bias correction: where the estimate falls in its bootstrap distribution
    // (ties count half, so a parameter fixed by the options gets z0 = 0).
    const auto below = static_cast<double>(std::lower_bound(v.begin(), v.end(), observed[k]) - v.begin());
    const auto not_above = static_cast<double>(std::upper_bound(v.begin(), v.end(), observed[k]) - v.begin());
    const double fraction = (below + 0.5 * (not_above - below)) / static_cast<double>(v.size());
    if (!(fraction > 0.0 && fraction < 1.0)) continue;
    const double z0 = standard_normal_quantile(fraction);
    const double a = acceleration[k];
    auto adjusted = [&](double q) {
      const double z = standard_normal_quantile(q);
      return standard_normal_cdf(z0 + (z0 + z) / (1.0 - a * (z0 + z)));
    };
    e.bca = {quantile_sorted(v, adjusted(tail)), quantile_sorted(v, adjusted(1.0 - tail))};
  }
  return result;
}

std::vector<StimulusLevel> pool_levels(std::vector<StimulusLevel> data) {
  std::map<double, StimulusLevel> pooled;
  for (const StimulusLevel& s : data) {
    StimulusLevel& p = pooled[s.level];
    p.level = s.level;
    p.correct += s.correct;
    p.trials += s.trials;
  }
  std::vector<StimulusLevel> out;
  for (const auto& [level, s] : pooled) out.push_back(s);
  return out;
}

Result<double> interpolated_threshold(const std::vector<StimulusLevel>& data, double proportion) {
  for (const StimulusLevel& s : data) {
    if (!std::isfinite(s.level) || s.trials < 0 || s.correct < 0 || s.correct > s.trials) {
      return make_error(Errc::invalid_argument,
                        fmt::format("level {}: {} correct of {} trials is not valid data", s.level, s.correct, s.trials));
    }
  }
  std::vector<StimulusLevel> pooled = used_levels(pool_levels(data));
  if (pooled.size() < 2) {
    return make_error(Errc::invalid_argument, "linear interpolation needs trials at two or more levels");
  }
  auto rate = [](const StimulusLevel& s) { return static_cast<double>(s.correct) / s.trials; };
  if (rate(pooled[0]) >= proportion) {
    return make_error(Errc::out_of_range,
                      fmt::format("the proportion correct is already {:.3f} at the lowest level {}, at or above {}; "
                                  "the threshold lies below the tested range",
                                  rate(pooled[0]), pooled[0].level, proportion));
  }
  for (std::size_t i = 1; i < pooled.size(); ++i) {
    const double p0 = rate(pooled[i - 1]), p1 = rate(pooled[i]);
    if (p1 >= proportion) {
      const double t = (proportion - p0) / (p1 - p0);
      return pooled[i - 1].level + t * (pooled[i].level - pooled[i - 1].level);
    }
  }
  return make_error(Errc::out_of_range,
                    fmt::format("the proportion correct never reaches {} (highest {:.3f}); the threshold lies above "
                                "the tested range",
                                proportion, rate(pooled.back())));
}

}  // namespace proprio::study
