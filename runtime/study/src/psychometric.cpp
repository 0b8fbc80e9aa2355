#include "proprio/study/psychometric.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <boost/math/distributions/normal.hpp>
#include <cmath>
#include <fmt/format.h>
#include <limits>
#include <map>
#include <utility>
#include <thread>

#include "nelder_mead.hpp"
#include "proprio/core/random.hpp"

namespace proprio::study {
namespace {

constexpr double kLn10 = 2.302585092994045684;
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaNFit = std::numeric_limits<double>::quiet_NaN();

double standard_normal_cdf(double z) { return 0.5 * std::erfc(-z / std::sqrt(2.0)); }
double standard_normal_quantile(double p) {
  return boost::math::quantile(boost::math::normal_distribution<double>(0.0, 1.0), p);
}

// k log k/(n p) terms with 0 log 0 = 0.
double xlogy_ratio(double k, double expected) { return k > 0.0 ? k * std::log(k / expected) : 0.0; }

// Empty when a function running from `guess` to `top` = 1 - lapse reaches
// `proportion`; otherwise what is wrong and what to do.
std::string unreachable_proportion(double proportion, double guess, double top) {
  if (proportion > guess && proportion < top) return {};
  return fmt::format("the function never reaches proportion {}: it runs from the guess rate {} to 1 - lapse = {}; "
                     "choose a --threshold between them (e.g. 0.75 for 2AFC)",
                     proportion, guess, top);
}

// Each simulated trial is one draw; see kMaxSimulatedTrials.
Status check_simulation_budget(const std::vector<StimulusLevel>& data, int replicas, std::string_view what) {
  std::int64_t trials = 0;
  for (const StimulusLevel& s : data) trials += std::max(s.trials, 0);
  const std::int64_t draws = trials * std::max(replicas, 0);  // <= 1e9 * INT_MAX: no overflow
  if (draws <= kMaxSimulatedTrials) return Status::success();
  return make_error(Errc::invalid_argument,
                    fmt::format("a {} of {} data sets x {} trials would simulate {} trials, more than the limit of {}; "
                                "use at most {} data sets for this file, or fewer trials",
                                what, replicas, trials, draws, kMaxSimulatedTrials,
                                trials > 0 ? kMaxSimulatedTrials / trials : 0));
}

// Levels with trials only.
std::vector<StimulusLevel> used_levels(const std::vector<StimulusLevel>& data) {
  std::vector<StimulusLevel> out;
  for (const StimulusLevel& s : data) {
    if (s.trials > 0) out.push_back(s);
  }
  return out;
}


// ---------------------------------------------------------------------------
// The likelihood in search coordinates.
//
// Every model is F(z) with z = beta (s - a): for the Weibull s = ln x and
// a = ln alpha (then F(z) = 1 - exp(-e^z)), for the others s = x and a = alpha.
// The search runs over theta = (a, ln beta[, lambda]) inside a box, with
// analytic first and second derivatives, so a bounded Newton method converges
// in a handful of steps; the box only stops separable data (and their
// bootstrap replicas) from running off to infinity, where the threshold means
// nothing anyway.

using Theta = std::array<double, 3>;
using Matrix = std::array<double, 9>;  // row-major 3 x 3
constexpr double kTiny = 1e-300;       // probabilities are clamped here before the log

// F(z), 1 - F(z) (without cancellation: a steep fit's upper levels need it),
// F'(z) and F''(z).
struct SigmoidValues {
  double f = 0.0, fc = 1.0, d1 = 0.0, d2 = 0.0;
};

SigmoidValues sigmoid_z(PsychometricModel model, double z) {
  SigmoidValues v;
  switch (model) {
    case PsychometricModel::weibull:
    case PsychometricModel::gumbel: {
      const double scale = model == PsychometricModel::weibull ? 1.0 : kLn10;
      const double lz = scale * z;
      // Far out the values are exact to double precision; returning them
      // directly also keeps exp() off its slow overflow and underflow paths.
      if (lz > 6.55) {  // e^lz > 700
        v.f = 1.0;
        v.fc = 0.0;
        break;
      }
      if (lz < -700.0) break;
      const double t = std::exp(lz);
      v.f = -std::expm1(-t);
      v.fc = std::exp(-t);
      v.d1 = scale * std::exp(lz - t);
      v.d2 = v.d1 == 0.0 ? 0.0 : scale * v.d1 * (1.0 - t);
      break;
    }
    case PsychometricModel::logistic: {
      const double e = std::abs(z) > 700.0 ? 0.0 : std::exp(-std::abs(z));
      const double big = 1.0 / (1.0 + e), small = e / (1.0 + e);
      v.f = z >= 0.0 ? big : small;
      v.fc = z >= 0.0 ? small : big;
      v.d1 = v.f * v.fc;
      v.d2 = v.d1 * (v.fc - v.f);
      break;
    }
    case PsychometricModel::cumulative_normal: {
      v.f = 0.5 * std::erfc(-z / std::sqrt(2.0));
      v.fc = 0.5 * std::erfc(z / std::sqrt(2.0));
      v.d1 = std::abs(z) > 38.0 ? 0.0 : std::exp(-0.5 * z * z) / std::sqrt(2.0 * M_PI);
      v.d2 = -z * v.d1;
      break;
    }
  }
  return v;
}

// psi and 1 - psi at x for any parameters (the public functions' path).
std::pair<double, double> psi_and_complement(PsychometricModel model, const PsychometricParams& p, double x) {
  SigmoidValues v;
  if (model == PsychometricModel::weibull) {
    if (x > 0.0) v = sigmoid_z(model, p.beta * (std::log(x) - std::log(p.alpha)));
  } else {
    v = sigmoid_z(model, p.beta * (x - p.alpha));
  }
  const double c = 1.0 - p.gamma - p.lambda;
  return {p.gamma + c * v.f, p.lambda + c * v.fc};
}

struct Level {
  double s = 0.0;  // the stimulus on the z axis
  double k = 0.0;  // correct
  double n = 0.0;  // trials
};

double level_log_likelihood(double k, double n, double psi, double q) {
  double ll = 0.0;
  if (k > 0.0) ll += k * std::log(std::max(psi, kTiny));
  if (n > k) ll += (n - k) * std::log(std::max(q, kTiny));
  return ll;
}

double level_deviance(double k, double n, double psi, double q) {
  return 2.0 * (xlogy_ratio(k, n * std::max(psi, kTiny)) + xlogy_ratio(n - k, n * std::max(q, kTiny)));
}

class Likelihood {
 public:
  Likelihood(const std::vector<StimulusLevel>& data, const FitOptions& o) : options_(o) {
    double lo = kInf, hi = -kInf;
    for (const StimulusLevel& s : data) {
      levels_.push_back({axis(s.level), static_cast<double>(s.correct), static_cast<double>(s.trials)});
      lo = std::min(lo, s.level);
      hi = std::max(hi, s.level);
    }
    level_min_ = lo;
    level_max_ = hi;
    // beta is dimensionless for the Weibull and in 1/stimulus units otherwise;
    // the box reaches 100 times beyond the start grid both ways.
    const double span = std::max(hi - lo, 1e-12);
    steep_ = o.model == PsychometricModel::weibull ? std::log(20.0) : std::log(200.0 / span);
    if (o.model == PsychometricModel::weibull) {
      lo_ = {std::log(lo / 100.0), std::log(0.5e-2), 0.0};
      hi_ = {std::log(hi * 100.0), std::log(20e2), 0.0};
    } else {
      lo_ = {lo - 100.0 * span, std::log(0.5e-2 / span), 0.0};
      hi_ = {hi + 100.0 * span, std::log(200e2 / span), 0.0};
    }
    if (o.lapse_free) {
      hi_[2] = o.lapse_max;
    } else {
      lo_[2] = hi_[2] = o.lapse;
    }
  }

  int dimensions() const { return options_.lapse_free ? 3 : 2; }
  const FitOptions& options() const { return options_; }
  const Theta& lower() const { return lo_; }
  const Theta& upper() const { return hi_; }
  double level_min() const { return level_min_; }
  double level_max() const { return level_max_; }
  std::vector<Level>& levels() { return levels_; }
  const std::vector<Level>& levels() const { return levels_; }
  double axis(double x) const { return options_.model == PsychometricModel::weibull ? std::log(x) : x; }

  PsychometricParams params(const Theta& t) const {
    PsychometricParams p;
    p.alpha = options_.model == PsychometricModel::weibull ? std::exp(t[0]) : t[0];
    p.beta = std::exp(t[1]);
    p.gamma = options_.guess;
    p.lambda = options_.lapse_free ? t[2] : options_.lapse;
    return p;
  }
  Theta theta(const PsychometricParams& p) const {
    Theta t{axis(p.alpha), std::log(p.beta), options_.lapse_free ? p.lambda : options_.lapse};
    return clamp(t);
  }
  Theta clamp(Theta t) const {
    for (int i = 0; i < 3; ++i) t[i] = std::clamp(t[i], lo_[i], hi_[i]);
    return t;
  }
  // Steeper than any start on the grid (beta 20 for the Weibull, 200 per
  // tested range otherwise): what data that separate perfectly produce.
  bool steep(const Theta& t) const { return t[1] > steep_; }

  // psi and 1 - psi at every level.
  template <typename Visit>
  void each_level(const Theta& t, Visit visit) const {
    const double beta = std::exp(t[1]);
    const double lambda = options_.lapse_free ? t[2] : options_.lapse;
    const double c = 1.0 - options_.guess - lambda;
    for (const Level& l : levels_) {
      const double z = beta * (l.s - t[0]);
      const SigmoidValues v = sigmoid_z(options_.model, z);
      visit(l, z, v, options_.guess + c * v.f, lambda + c * v.fc);
    }
  }

  double log_likelihood(const Theta& t) const {
    double ll = 0.0;
    each_level(t, [&](const Level& l, double, const SigmoidValues&, double psi, double q) {
      ll += level_log_likelihood(l.k, l.n, psi, q);
    });
    return ll;
  }
  double deviance(const Theta& t) const {
    double d = 0.0;
    each_level(t, [&](const Level& l, double, const SigmoidValues&, double psi, double q) {
      d += level_deviance(l.k, l.n, psi, q);
    });
    return d;
  }

  // The gradient, the negated Hessian (observed information) and the Fisher
  // (expected) information, over the first dimensions() coordinates.
  void derivatives(const Theta& t, Theta& gradient, Matrix& observed, Matrix& expected) const {
    gradient.fill(0.0);
    observed.fill(0.0);
    expected.fill(0.0);
    const double beta = std::exp(t[1]);
    const double lambda = options_.lapse_free ? t[2] : options_.lapse;
    const double c = 1.0 - options_.guess - lambda;
    const int d = dimensions();
    each_level(t, [&](const Level& l, double z, const SigmoidValues& v, double psi_raw, double q_raw) {
      const double psi = std::max(psi_raw, kTiny), q = std::max(q_raw, kTiny);
      const double dp[3] = {-c * v.d1 * beta, c * v.d1 * z, -v.f};
      const double d2[9] = {c * v.d2 * beta * beta, -c * beta * (v.d2 * z + v.d1), v.d1 * beta,
                            -c * beta * (v.d2 * z + v.d1), c * (v.d2 * z * z + v.d1 * z), -v.d1 * z,
                            v.d1 * beta, -v.d1 * z, 0.0};
      const double wrong = l.n - l.k;
      const double w = l.k / psi - wrong / q;
      const double u = l.k / (psi * psi) + wrong / (q * q);
      const double f = l.n / (psi * q);
      for (int i = 0; i < d; ++i) {
        gradient[i] += w * dp[i];
        for (int j = 0; j < d; ++j) {
          observed[3 * i + j] += u * dp[i] * dp[j] - w * d2[3 * i + j];
          expected[3 * i + j] += f * dp[i] * dp[j];
        }
      }
    });
  }

 private:
  FitOptions options_;
  std::vector<Level> levels_;
  Theta lo_{}, hi_{};
  double level_min_ = 0.0, level_max_ = 0.0;
  double steep_ = 0.0;
};

// Solves A x = b on the coordinates in idx (m of them) by Cholesky; false when
// A is not positive definite there.
bool solve_positive(const Matrix& a, const Theta& b, const int* idx, int m, double* x) {
  double l[3][3] = {};
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j <= i; ++j) {
      double sum = a[3 * idx[i] + idx[j]];
      for (int k = 0; k < j; ++k) sum -= l[i][k] * l[j][k];
      if (i == j) {
        if (!(sum > 0.0) || !std::isfinite(sum)) return false;
        l[i][i] = std::sqrt(sum);
      } else {
        l[i][j] = sum / l[j][j];
      }
    }
  }
  double y[3];
  for (int i = 0; i < m; ++i) {
    double sum = b[idx[i]];
    for (int k = 0; k < i; ++k) sum -= l[i][k] * y[k];
    y[i] = sum / l[i][i];
  }
  for (int i = m - 1; i >= 0; --i) {
    double sum = y[i];
    for (int k = i + 1; k < m; ++k) sum -= l[k][i] * x[k];
    x[i] = sum / l[i][i];
  }
  for (int i = 0; i < m; ++i) {
    if (!std::isfinite(x[i])) return false;
  }
  return true;
}

struct Solution {
  Theta theta{};
  double log_likelihood = -kInf;
  int evaluations = 0;
};

// Bounded Newton ascent: the observed information where it is positive
// definite, else the Fisher information (always so, bar a flat direction);
// halving the step until the likelihood rises; coordinates on a bound with the
// gradient pointing out stay there. A simplex takes over in the rare case the
// Newton steps run out before converging.
Solution maximise(const Likelihood& lk, const Theta& start) {
  Solution s;
  s.theta = lk.clamp(start);
  s.log_likelihood = lk.log_likelihood(s.theta);
  s.evaluations = 1;
  const int d = lk.dimensions();
  bool converged = false;
  int small_gains = 0;
  for (int iteration = 0; iteration < 100 && !converged; ++iteration) {
    Theta g;
    Matrix observed, expected;
    lk.derivatives(s.theta, g, observed, expected);
    ++s.evaluations;
    int idx[3];
    int m = 0;
    for (int i = 0; i < d; ++i) {
      const bool held_low = s.theta[i] <= lk.lower()[i] && g[i] <= 0.0;
      const bool held_high = s.theta[i] >= lk.upper()[i] && g[i] >= 0.0;
      if (!held_low && !held_high) idx[m++] = i;
    }
    double step[3];
    if (m == 0) break;
    if (!solve_positive(observed, g, idx, m, step)) {
      double largest = 0.0;
      for (int i = 0; i < m; ++i) largest = std::max(largest, expected[4 * idx[i]]);
      for (int i = 0; i < m; ++i) expected[4 * idx[i]] += 1e-10 * largest;
      if (!solve_positive(expected, g, idx, m, step)) break;
    }
    double decrement = 0.0;
    for (int i = 0; i < m; ++i) decrement += step[i] * g[idx[i]];
    if (!(decrement > 0.0)) {
      converged = true;
      break;
    }
    // Close in (a predicted gain, half the decrement, below 1e-9): the Newton
    // step lands within rounding of the maximum, and halving it in search of
    // a rise that rounding hides would only waste evaluations.
    if (decrement < 2e-9) {
      Theta c = s.theta;
      for (int i = 0; i < m; ++i) c[idx[i]] += step[i];
      c = lk.clamp(c);
      const double ll = lk.log_likelihood(c);
      ++s.evaluations;
      if (ll >= s.log_likelihood - 1e-12 * std::abs(s.log_likelihood)) {
        s.theta = c;
        s.log_likelihood = ll;
      }
      converged = true;
      break;
    }
    bool moved = false;
    double scale = 1.0;
    for (int half = 0; half < 30; ++half, scale *= 0.5) {
      Theta c = s.theta;
      for (int i = 0; i < m; ++i) c[idx[i]] += scale * step[i];
      c = lk.clamp(c);
      const double ll = lk.log_likelihood(c);
      ++s.evaluations;
      if (ll > s.log_likelihood) {
        // Gains this small twice running: where Newton converges quadratically
        // the maximum is then reached to rounding; elsewhere it is a ridge
        // toward infinite slope (separated data) that only creeps upward.
        small_gains = ll - s.log_likelihood < 1e-6 ? small_gains + 1 : 0;
        s.theta = c;
        s.log_likelihood = ll;
        moved = true;
        break;
      }
    }
    // No step raises the likelihood: a maximum to rounding, or a flat ridge.
    if (!moved || small_gains >= 2) converged = true;
  }
  if (!converged) {
    auto objective = [&](const std::vector<double>& u) {
      Theta t{u[0], u[1], d == 3 ? u[2] : lk.lower()[2]};
      for (int i = 0; i < d; ++i) {
        if (t[i] < lk.lower()[i] || t[i] > lk.upper()[i]) return kInf;
      }
      return -lk.log_likelihood(t);
    };
    const detail::NelderMeadResult r =
        detail::nelder_mead(objective, std::vector<double>(s.theta.begin(), s.theta.begin() + d));
    s.evaluations += r.evaluations;
    if (-r.f > s.log_likelihood) {
      for (int i = 0; i < d; ++i) s.theta[i] = r.x[static_cast<std::size_t>(i)];
      s.log_likelihood = -r.f;
    }
  }
  return s;
}

// A grid of starts whose log(psi) and log(1 - psi) at every level are
// computed once, so scoring it for a data set with the same levels (each
// bootstrap replica, each jackknife deletion) is a dot product.
class StartGrid {
 public:
  StartGrid(const Likelihood& lk, int alpha_steps, int beta_steps, const std::vector<double>& lambdas) {
    const PsychometricModel model = lk.options().model;
    const double lo = lk.level_min(), hi = lk.level_max();
    const double span = hi - lo;
    // alpha across (and a little beyond) the tested range, beta over three
    // decades (in 1/stimulus units except for the Weibull).
    const double beta_lo = model == PsychometricModel::weibull ? 0.5 : 0.5 / span;
    const double beta_hi = model == PsychometricModel::weibull ? 20.0 : 200.0 / span;
    for (double lambda : lambdas) {
      for (int i = 0; i < alpha_steps; ++i) {
        const double t = static_cast<double>(i) / (alpha_steps - 1);
        const double a = model == PsychometricModel::weibull
                             ? std::log(lo * 0.5) + t * (std::log(hi * 2.0) - std::log(lo * 0.5))
                             : lo - 0.5 * span + t * 2.0 * span;
        for (int j = 0; j < beta_steps; ++j) {
          const double u = static_cast<double>(j) / (beta_steps - 1);
          points_.push_back({a, std::log(beta_lo) + u * (std::log(beta_hi) - std::log(beta_lo)), lambda});
        }
      }
    }
    const std::size_t n = points_.size();
    log_p_.resize(lk.levels().size() * n);
    log_q_.resize(lk.levels().size() * n);
    for (std::size_t p = 0; p < n; ++p) {
      std::size_t l = 0;
      lk.each_level(points_[p], [&](const Level&, double, const SigmoidValues&, double psi, double q) {
        log_p_[l * n + p] = std::log(std::max(psi, kTiny));
        log_q_[l * n + p] = std::log(std::max(q, kTiny));
        ++l;
      });
    }
  }

  std::size_t size() const { return points_.size(); }
  const Theta& point(std::size_t i) const { return points_[i]; }

  // Log-likelihood of every point for the counts in `levels` (same levels as
  // at construction) into `scores`.
  void score(const std::vector<Level>& levels, std::vector<double>& scores) const {
    const std::size_t n = points_.size();
    scores.assign(n, 0.0);
    double* out = scores.data();
    for (std::size_t l = 0; l < levels.size(); ++l) {
      const double k = levels[l].k, m = levels[l].n - levels[l].k;
      const double* lp = log_p_.data() + l * n;
      const double* lq = log_q_.data() + l * n;
      for (std::size_t p = 0; p < n; ++p) out[p] += k * lp[p] + m * lq[p];
    }
  }

  // The best point; among equal bests (a flat ridge) the middle one, so a
  // ridge's estimate sits in its middle rather than at the grid's first row.
  static std::size_t best(const std::vector<double>& scores) {
    const double top = *std::max_element(scores.begin(), scores.end());
    const double tie = top - 1e-9 * (1.0 + std::abs(top));
    std::size_t count = 0;
    for (double v : scores) count += v >= tie ? 1 : 0;
    std::size_t wanted = count / 2;
    for (std::size_t i = 0; i < scores.size(); ++i) {
      if (scores[i] >= tie && wanted-- == 0) return i;
    }
    return 0;
  }

 private:
  std::vector<Theta> points_;
  std::vector<double> log_p_, log_q_;  // [level * points + point]
};

std::vector<double> grid_lambdas(const FitOptions& o, int steps) {
  if (!o.lapse_free) return {o.lapse};
  std::vector<double> out;
  for (int i = 0; i < steps; ++i) out.push_back(o.lapse_max * i / (steps - 1));
  return out;
}

// The grid used for every refit of simulated or jackknifed data: coarser than
// the first fit's, since its best point only has to start Newton in the right
// basin.
StartGrid refit_grid(const Likelihood& lk) { return StartGrid(lk, 24, 16, grid_lambdas(lk.options(), 3)); }

Solution refit(const Likelihood& lk, const StartGrid& grid, std::vector<double>& scores) {
  grid.score(lk.levels(), scores);
  Solution s = maximise(lk, grid.point(StartGrid::best(scores)));
  s.evaluations += static_cast<int>(grid.size());
  return s;
}

// Runs work(i, worker) for i in [0, count) on `threads` threads (0: every
// core); `make_worker` builds each thread's scratch state. Work writes only
// to slot i of its outputs, so results do not depend on the thread count.
template <typename MakeWorker, typename Work>
void parallel_for(int count, int threads, MakeWorker make_worker, Work work) {
  int n = threads > 0 ? threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  n = std::clamp(n, 1, std::max(1, count / 8));
  std::atomic<int> next{0};
  auto run = [&] {
    auto worker = make_worker();
    for (;;) {
      const int begin = next.fetch_add(8);
      if (begin >= count) break;
      for (int i = begin; i < std::min(count, begin + 8); ++i) work(i, worker);
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < n; ++t) pool.emplace_back(run);
  run();
  for (std::thread& t : pool) t.join();
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
  return kNaNFit;
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
  return kNaNFit;
}

double sigmoid_inverse(PsychometricModel model, double alpha, double beta, double f) {
  switch (model) {
    case PsychometricModel::weibull: return alpha * std::pow(-std::log1p(-f), 1.0 / beta);
    case PsychometricModel::logistic: return alpha + std::log(f / (1.0 - f)) / beta;
    case PsychometricModel::gumbel: return alpha + std::log10(-std::log1p(-f)) / beta;
    case PsychometricModel::cumulative_normal: return alpha + standard_normal_quantile(f) / beta;
  }
  return kNaNFit;
}

double psi(PsychometricModel model, const PsychometricParams& p, double x) {
  return p.gamma + (1.0 - p.gamma - p.lambda) * sigmoid(model, p.alpha, p.beta, x);
}

Result<double> threshold_at(PsychometricModel model, const PsychometricParams& p, double proportion) {
  const double span = 1.0 - p.gamma - p.lambda;
  const double f = (proportion - p.gamma) / span;
  if (std::string why = unreachable_proportion(proportion, p.gamma, 1.0 - p.lambda); !why.empty()) {
    return make_error(Errc::out_of_range, std::move(why));
  }
  if (!(span > 0.0) || !(f > 0.0 && f < 1.0)) {  // rounding at the very ends
    return make_error(Errc::out_of_range, fmt::format("the function reaches proportion {} only at its limit", proportion));
  }
  return sigmoid_inverse(model, p.alpha, p.beta, f);
}

Status validate_fit_options(const FitOptions& o) {
  if (!(o.guess >= 0.0 && o.guess < 1.0)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("--guess {} is outside [0, 1): use 0.5 for 2AFC, 1/m for m-AFC, 0 for yes/no",
                                  o.guess));
  }
  const double value = o.lapse_free ? o.lapse_max : o.lapse;
  if (!(value >= 0.0 && value < 1.0 - o.guess)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("--{} {} is outside [0, 1 - guess) = [0, {}): lapse rates are small proportions, "
                                  "e.g. {}",
                                  o.lapse_free ? "lapse-max" : "lapse", value, 1.0 - o.guess,
                                  o.lapse_free ? "0.06" : "0 or 0.02"));
  }
  return Status::success();
}

Status validate_threshold_proportion(const FitOptions& o, double proportion) {
  if (Status s = validate_fit_options(o); !s) return s;
  const double top = 1.0 - (o.lapse_free ? o.lapse_max : o.lapse);
  if (std::string why = unreachable_proportion(proportion, o.guess, top); !why.empty()) {
    return make_error(Errc::invalid_argument, fmt::format("--threshold {}: {}", proportion, why));
  }
  return Status::success();
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
    if (s.trials > kMaxTrials) {
      return make_error(Errc::invalid_argument,
                        fmt::format("at level {} (row {}): {} trials is more than the {} a level may hold; split or "
                                    "check the data",
                                    s.level, i + 1, s.trials, kMaxTrials));
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
  double ll = 0.0;
  for (const StimulusLevel& s : data) {
    if (s.trials <= 0) continue;
    const auto [q, r] = psi_and_complement(model, p, s.level);
    if (!(q >= 0.0 && q <= 1.0 && r >= 0.0 && r <= 1.0)) return -kInf;
    ll += level_log_likelihood(s.correct, s.trials, q, r);
  }
  return ll;
}

double deviance(PsychometricModel model, const PsychometricParams& p, const std::vector<StimulusLevel>& data) {
  double d = 0.0;
  for (const StimulusLevel& s : data) {
    if (s.trials <= 0) continue;
    const auto [q, r] = psi_and_complement(model, p, s.level);
    d += level_deviance(s.correct, s.trials, q, r);
  }
  return d;
}

namespace {

PsychometricFit make_fit(const Likelihood& lk, const Solution& s, int evaluations) {
  PsychometricFit fit;
  fit.model = lk.options().model;
  fit.params = lk.params(s.theta);
  fit.log_likelihood = s.log_likelihood;
  fit.deviance = lk.deviance(s.theta);
  fit.evaluations = evaluations;
  return fit;
}

}  // namespace

Result<PsychometricFit> fit_psychometric(const std::vector<StimulusLevel>& raw, const FitOptions& options) {
  if (Status s = validate_fit_options(options); !s) return s.error();
  if (Status s = validate_levels(options.model, raw); !s) return s.error();
  const Likelihood lk(used_levels(raw), options);
  const StartGrid grid(lk, 40, 30, grid_lambdas(options, 4));
  std::vector<double> scores;
  grid.score(lk.levels(), scores);

  // Starts: the grid's best point, and points nearly as good spread over
  // their range of alpha (its ends, quarters and middle). Where the maximum is
  // sharp all of them climb to it; along a flat ridge they stay apart, and
  // that is how the fit finds out.
  const std::size_t best_point = StartGrid::best(scores);
  double a_low = kInf, a_high = -kInf;
  for (std::size_t i = 0; i < grid.size(); ++i) {
    if (scores[i] < scores[best_point] - 2.0) continue;
    a_low = std::min(a_low, grid.point(i)[0]);
    a_high = std::max(a_high, grid.point(i)[0]);
  }
  std::vector<std::size_t> starts = {best_point};
  for (double f : {0.0, 0.25, 0.5, 0.75, 1.0}) {
    const double target = a_low + f * (a_high - a_low);
    std::size_t pick = best_point;
    for (std::size_t i = 0; i < grid.size(); ++i) {
      if (scores[i] < scores[best_point] - 2.0) continue;
      const double gap = std::abs(grid.point(i)[0] - target), best_gap = std::abs(grid.point(pick)[0] - target);
      if (gap < best_gap || (gap == best_gap && scores[i] > scores[pick])) pick = i;
    }
    if (std::find(starts.begin(), starts.end(), pick) == starts.end()) starts.push_back(pick);
  }
  std::vector<Solution> solutions;
  int evaluations = static_cast<int>(grid.size());
  for (std::size_t start : starts) {
    solutions.push_back(maximise(lk, grid.point(start)));
    evaluations += solutions.back().evaluations;
  }
  const auto best = std::max_element(solutions.begin(), solutions.end(), [](const Solution& a, const Solution& b) {
    return a.log_likelihood < b.log_likelihood;
  });
  if (!std::isfinite(best->log_likelihood)) {
    return make_error(Errc::invalid_argument, "the likelihood is not finite anywhere the search looked; check the data");
  }
  PsychometricFit fit = make_fit(lk, *best, evaluations);
  for (const Solution& s : solutions) {
    if (&s == &*best || s.log_likelihood < best->log_likelihood - kEquallyLikely) continue;
    bool same = true;
    for (int i = 0; i < lk.dimensions(); ++i) same = same && std::abs(s.theta[i] - best->theta[i]) <= 1e-6 * (1.0 + std::abs(best->theta[i]));
    if (!same) fit.equally_likely.push_back(lk.params(s.theta));
  }
  // Separation: the steepest function the search allows, at the same place,
  // is as likely as the best. Then any step between the two tested levels
  // around it is too, however the search happened to stop.
  Theta steepest = best->theta;
  steepest[1] = lk.upper()[1];
  if (lk.log_likelihood(steepest) >= best->log_likelihood - kEquallyLikely) {
    const double x = fit.params.alpha;
    double below = -kInf, above = kInf;
    for (const StimulusLevel& s : raw) {
      if (s.trials <= 0) continue;
      if (s.level < x) below = std::max(below, s.level);
      if (s.level > x) above = std::min(above, s.level);
    }
    if (std::isfinite(below) && std::isfinite(above)) fit.step_between = std::make_pair(below, above);
  }
  return fit;
}

Result<PsychometricFit> fit_psychometric_from(const std::vector<StimulusLevel>& raw, const FitOptions& options,
                                              const PsychometricParams& start) {
  if (Status s = validate_fit_options(options); !s) return s.error();
  if (Status s = validate_levels(options.model, raw); !s) return s.error();
  if (!(start.beta > 0.0) || (options.model == PsychometricModel::weibull && !(start.alpha > 0.0)) ||
      !std::isfinite(start.alpha) || !std::isfinite(start.beta)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("start alpha {} beta {} is not a valid {} function", start.alpha, start.beta,
                                  to_string(options.model)));
  }
  const Likelihood lk(used_levels(raw), options);
  const Solution s = maximise(lk, lk.theta(start));
  if (!std::isfinite(s.log_likelihood)) {
    return make_error(Errc::invalid_argument, "the likelihood is not finite anywhere the search looked; check the data");
  }
  return make_fit(lk, s, s.evaluations);
}

UniquenessCheck check_unique_maximum(const PsychometricFit& fit, const std::vector<StimulusLevel>& data,
                                     double proportion) {
  UniquenessCheck c;
  const Result<double> t = threshold_at(fit.model, fit.params, proportion);
  if (!t) return c;
  c.threshold_min = c.threshold_max = *t;
  if (fit.step_between) {
    c.threshold_min = std::min(c.threshold_min, fit.step_between->first);
    c.threshold_max = std::max(c.threshold_max, fit.step_between->second);
  }
  for (const PsychometricParams& p : fit.equally_likely) {
    const Result<double> other = threshold_at(fit.model, p, proportion);
    if (!other) continue;
    c.threshold_min = std::min(c.threshold_min, *other);
    c.threshold_max = std::max(c.threshold_max, *other);
  }
  double lo = kInf, hi = -kInf;
  for (const StimulusLevel& s : data) {
    if (s.trials <= 0) continue;
    lo = std::min(lo, s.level);
    hi = std::max(hi, s.level);
  }
  const double spread = c.threshold_max - c.threshold_min;
  if (!(hi > lo) || !(spread > 0.03 * (hi - lo))) return c;
  c.unique = false;
  if (fit.step_between) {
    c.message = fmt::format(
        "the maximum likelihood is not unique: the responses separate perfectly between levels {:.4g} and {:.4g}, "
        "so a step anywhere between them fits as well as the best, and the {} threshold can lie anywhere from "
        "{:.4g} to {:.4g} (the estimate {:.4g} is one arbitrary point of that range); test levels between them, "
        "or more trials, before relying on the threshold or on its confidence interval",
        fit.step_between->first, fit.step_between->second, proportion, c.threshold_min, c.threshold_max, *t);
    return c;
  }
  c.message = fmt::format(
      "the maximum likelihood is not unique: fits as likely as the best (log-likelihood within {}) put the {} "
      "threshold anywhere from {:.4g} to {:.4g} or further (a spread of {:.0f} % of the estimate {:.4g}); the data "
      "do not pin the threshold down (too few trials, or responses that separate perfectly between two levels), so "
      "test more trials near the threshold before relying on it or on its confidence interval",
      kEquallyLikely, proportion, c.threshold_min, c.threshold_max, 100.0 * spread / std::abs(*t), *t);
  return c;
}

namespace {

// The statistics a bootstrap tracks, in a fixed order.
constexpr std::size_t kStats = 5;  // alpha, beta, lambda, threshold, slope
bool statistics_of(const PsychometricFit& fit, double proportion, std::array<double, kStats>& out) {
  const Result<double> t = threshold_at(fit.model, fit.params, proportion);
  if (!t) return false;
  out = {fit.params.alpha, fit.params.beta, fit.params.lambda, *t, slope_at(fit.model, fit.params, *t)};
  return true;
}

// One simulated data set, refitted.
struct Replica {
  bool fitted = false;
  bool has_statistics = false;
  bool steep = false;
  double deviance = 0.0;
  std::array<double, kStats> statistics{};
};

// Replica i: binomial counts from Rng(mix_seed(seed, i)) at the fit's
// probabilities, refitted from its own grid start.
std::vector<Replica> simulate_replicas(const Likelihood& base, const PsychometricFit& fit, int count,
                                       std::uint64_t seed, int threads, double proportion) {
  std::vector<double> probability;
  base.each_level(base.theta(fit.params), [&](const Level&, double, const SigmoidValues&, double psi, double) {
    probability.push_back(psi);
  });
  const StartGrid grid = refit_grid(base);
  std::vector<Replica> out(static_cast<std::size_t>(count));
  struct Worker {
    Likelihood lk;
    std::vector<double> scores;
  };
  parallel_for(
      count, threads, [&] { return Worker{base, {}}; },
      [&](int i, Worker& w) {
        Rng rng(mix_seed(seed, static_cast<std::uint64_t>(i)));
        std::vector<Level>& levels = w.lk.levels();
        for (std::size_t l = 0; l < levels.size(); ++l) {
          const auto trials = static_cast<long long>(levels[l].n);
          long long k = 0;
          for (long long t = 0; t < trials; ++t) k += rng.uniform01() < probability[l] ? 1 : 0;
          levels[l].k = static_cast<double>(k);
        }
        const Solution s = refit(w.lk, grid, w.scores);
        Replica& r = out[static_cast<std::size_t>(i)];
        if (!std::isfinite(s.log_likelihood)) return;
        r.fitted = true;
        r.steep = w.lk.steep(s.theta);
        r.deviance = w.lk.deviance(s.theta);
        PsychometricFit f;
        f.model = fit.model;
        f.params = w.lk.params(s.theta);
        r.has_statistics = statistics_of(f, proportion, r.statistics);
      });
  return out;
}

GoodnessOfFit goodness_from(const std::vector<Replica>& replicas, double observed_deviance) {
  GoodnessOfFit g;
  g.deviance = observed_deviance;
  int at_least = 0;
  for (const Replica& r : replicas) {
    if (!r.fitted) continue;
    ++g.simulations;
    // A relative margin keeps a replica that reproduces the data exactly
    // from counting as better or worse by rounding alone.
    if (r.deviance >= observed_deviance - 1e-9 * (1.0 + observed_deviance)) ++at_least;
  }
  // As Palamedes (PAL_PFML_GoodnessOfFit) and psignifit: the plain fraction.
  g.p_value = g.simulations > 0 ? static_cast<double>(at_least) / g.simulations : kNaNFit;
  return g;
}

}  // namespace

Result<GoodnessOfFit> goodness_of_fit(const std::vector<StimulusLevel>& raw, const FitOptions& options,
                                      const PsychometricFit& fit, int simulations, std::uint64_t seed, int threads) {
  if (simulations < 1) return make_error(Errc::invalid_argument, "goodness of fit needs at least one simulation");
  if (Status s = validate_fit_options(options); !s) return s.error();
  if (Status s = validate_levels(options.model, raw); !s) return s.error();
  if (Status s = check_simulation_budget(raw, simulations, "goodness-of-fit test"); !s) return s.error();
  const Likelihood lk(used_levels(raw), options);
  const std::vector<Replica> replicas = simulate_replicas(lk, fit, simulations, seed, threads, 0.5);
  GoodnessOfFit g = goodness_from(replicas, lk.deviance(lk.theta(fit.params)));
  if (g.simulations == 0) {
    return make_error(Errc::invalid_argument, "no simulated data set could be refitted; check the data and the fit");
  }
  return g;
}

double jackknife_acceleration(const std::vector<double>& values, const std::vector<double>& weights) {
  double total = 0.0, mean = 0.0;
  for (std::size_t i = 0; i < values.size(); ++i) {
    mean += weights[i] * values[i];
    total += weights[i];
  }
  if (!(total > 0.0)) return 0.0;
  mean /= total;
  double num = 0.0, den = 0.0;
  for (std::size_t i = 0; i < values.size(); ++i) {
    const double d = mean - values[i];
    num += weights[i] * d * d * d;
    den += weights[i] * d * d;
  }
  return den > 0.0 ? num / (6.0 * std::pow(den, 1.5)) : 0.0;
}

double quantile_sorted(const std::vector<double>& sorted, double q) {
  if (std::isnan(q) || sorted.empty()) return kNaNFit;
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
  if (Status s = validate_fit_options(options); !s) return s.error();
  if (Status s = validate_levels(options.model, raw); !s) return s.error();
  if (Status s = check_simulation_budget(raw, bootstrap.samples, "bootstrap"); !s) return s.error();
  const std::vector<StimulusLevel> data = used_levels(raw);
  std::array<double, kStats> observed{};
  if (!statistics_of(fit, bootstrap.threshold_proportion, observed)) {
    return threshold_at(fit.model, fit.params, bootstrap.threshold_proportion).error();
  }
  const Likelihood base(data, options);
  const std::vector<Replica> replicas = simulate_replicas(base, fit, bootstrap.samples, bootstrap.seed,
                                                          bootstrap.threads, bootstrap.threshold_proportion);

  std::array<std::vector<double>, kStats> samples;
  BootstrapResult result;
  result.coverage = bootstrap.coverage;
  result.threshold_proportion = bootstrap.threshold_proportion;
  result.goodness_of_fit = goodness_from(replicas, base.deviance(base.theta(fit.params)));
  for (const Replica& r : replicas) {
    if (r.steep) ++result.steep_refits;
    if (!r.has_statistics) {
      ++result.failed_fits;
      continue;
    }
    for (std::size_t k = 0; k < kStats; ++k) samples[k].push_back(r.statistics[k]);
  }
  result.samples = static_cast<int>(samples[0].size());
  if (result.samples < 10) {
    return make_error(Errc::invalid_argument,
                      fmt::format("only {} of {} bootstrap refits gave a threshold at {}; the data cannot pin it down",
                                  result.samples, bootstrap.samples, bootstrap.threshold_proportion));
  }

  // Jackknife (leave one trial out) for the BCa acceleration. With binomial
  // data only two distinct deletions exist per level: a correct or an
  // incorrect trial, weighted by how many of each there are. docs/study.md
  // derives why this (and not a smaller value) is the acceleration.
  std::array<double, kStats> acceleration{};
  bool have_acceleration = false;
  if (bootstrap.bca) {
    std::array<std::vector<double>, kStats> jack;
    std::vector<double> weights;
    Likelihood lk = base;
    const StartGrid grid = refit_grid(base);
    std::vector<double> scores;
    bool ok = true;
    for (std::size_t l = 0; l < data.size() && ok; ++l) {
      for (int drop_correct = 0; drop_correct < 2 && ok; ++drop_correct) {
        const int weight = drop_correct ? data[l].correct : data[l].trials - data[l].correct;
        if (weight == 0) continue;
        lk.levels() = base.levels();
        lk.levels()[l].n -= 1.0;
        lk.levels()[l].k -= drop_correct;
        const Solution s = refit(lk, grid, scores);
        PsychometricFit f;
        f.model = fit.model;
        f.params = lk.params(s.theta);
        std::array<double, kStats> stats{};
        if (!std::isfinite(s.log_likelihood) || !statistics_of(f, bootstrap.threshold_proportion, stats)) {
          ok = false;
          break;
        }
        for (std::size_t k = 0; k < kStats; ++k) jack[k].push_back(stats[k]);
        weights.push_back(weight);
      }
    }
    if (ok && !weights.empty()) {
      have_acceleration = true;
      for (std::size_t k = 0; k < kStats; ++k) acceleration[k] = jackknife_acceleration(jack[k], weights);
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
    e.bca = {kNaNFit, kNaNFit};
    e.bias_correction = kNaNFit;
    e.acceleration = have_acceleration ? acceleration[k] : kNaNFit;
    if (!have_acceleration) continue;
    // Bias correction: where the estimate falls in its bootstrap distribution
    // (ties count half, so a parameter fixed by the options gets z0 = 0).
    const auto below = static_cast<double>(std::lower_bound(v.begin(), v.end(), observed[k]) - v.begin());
    const auto not_above = static_cast<double>(std::upper_bound(v.begin(), v.end(), observed[k]) - v.begin());
    const double fraction = (below + 0.5 * (not_above - below)) / static_cast<double>(v.size());
    if (!(fraction > 0.0 && fraction < 1.0)) continue;
    const double z0 = standard_normal_quantile(fraction);
    const double a = acceleration[k];
    e.bias_correction = z0;
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
