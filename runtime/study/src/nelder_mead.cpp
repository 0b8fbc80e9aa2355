#include "nelder_mead.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace proprio::study::detail {
namespace {

// One simplex run from x0; stops on tolerance or the evaluation budget.
NelderMeadResult run_simplex(const std::function<double(const std::vector<double>&)>& f, const std::vector<double>& x0,
                             const NelderMeadOptions& options, int budget) {
  const std::size_t n = x0.size();
  std::vector<std::vector<double>> vertex(n + 1, x0);
  std::vector<double> value(n + 1);
  int evaluations = 0;
  auto eval = [&](const std::vector<double>& x) {
    ++evaluations;
    const double v = f(x);
    // NaN would poison every comparison; treat it as "infinitely bad".
    return std::isnan(v) ? std::numeric_limits<double>::infinity() : v;
  };
  for (std::size_t i = 0; i < n; ++i) {
    const double step = std::max(std::abs(x0[i]) * options.initial_step, options.initial_step * 0.25);
    vertex[i + 1][i] += step;
  }
  for (std::size_t i = 0; i <= n; ++i) value[i] = eval(vertex[i]);

  std::vector<std::size_t> order(n + 1);
  std::vector<double> centroid(n), trial(n), trial2(n);
  while (evaluations < budget) {
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return value[a] < value[b]; });
    const std::size_t best = order.front(), worst = order.back(), second = order[n - 1];

    // Converged when both the values and the vertices have come together.
    double x_spread = 0.0;
    for (std::size_t i = 0; i <= n; ++i) {
      for (std::size_t j = 0; j < n; ++j) {
        const double scale = 1.0 + std::abs(vertex[best][j]);
        x_spread = std::max(x_spread, std::abs(vertex[i][j] - vertex[best][j]) / scale);
      }
    }
    if (std::abs(value[worst] - value[best]) <= options.f_tolerance && x_spread <= options.x_tolerance) break;

    std::fill(centroid.begin(), centroid.end(), 0.0);
    for (std::size_t i = 0; i <= n; ++i) {
      if (i == worst) continue;
      for (std::size_t j = 0; j < n; ++j) centroid[j] += vertex[i][j] / static_cast<double>(n);
    }
    for (std::size_t j = 0; j < n; ++j) trial[j] = centroid[j] + (centroid[j] - vertex[worst][j]);
    const double f_reflect = eval(trial);
    if (f_reflect < value[best]) {
      for (std::size_t j = 0; j < n; ++j) trial2[j] = centroid[j] + 2.0 * (centroid[j] - vertex[worst][j]);
      const double f_expand = eval(trial2);
      if (f_expand < f_reflect) {
        vertex[worst] = trial2;
        value[worst] = f_expand;
      } else {
        vertex[worst] = trial;
        value[worst] = f_reflect;
      }
      continue;
    }
    if (f_reflect < value[second]) {
      vertex[worst] = trial;
      value[worst] = f_reflect;
      continue;
    }
    // Contract: outside when the reflection beat the worst, else inside.
    const bool outside = f_reflect < value[worst];
    for (std::size_t j = 0; j < n; ++j) {
      trial2[j] = outside ? centroid[j] + 0.5 * (trial[j] - centroid[j])
                          : centroid[j] + 0.5 * (vertex[worst][j] - centroid[j]);
    }
    const double f_contract = eval(trial2);
    if (f_contract < (outside ? f_reflect : value[worst])) {
      vertex[worst] = trial2;
      value[worst] = f_contract;
      continue;
    }
    // Shrink toward the best vertex.
    for (std::size_t i = 0; i <= n; ++i) {
      if (i == best) continue;
      for (std::size_t j = 0; j < n; ++j) vertex[i][j] = vertex[best][j] + 0.5 * (vertex[i][j] - vertex[best][j]);
      value[i] = eval(vertex[i]);
    }
  }
  const auto best_it = std::min_element(value.begin(), value.end());
  return {vertex[static_cast<std::size_t>(best_it - value.begin())], *best_it, evaluations};
}

}  // namespace

NelderMeadResult nelder_mead(const std::function<double(const std::vector<double>&)>& f, std::vector<double> x0,
                             const NelderMeadOptions& options) {
  NelderMeadResult result = run_simplex(f, x0, options, options.max_evaluations);
  for (int restart = 0; restart < options.max_restarts && result.evaluations < options.max_evaluations; ++restart) {
    NelderMeadResult again = run_simplex(f, result.x, options, options.max_evaluations - result.evaluations);
    const bool improved = again.f < result.f - options.f_tolerance;
    again.evaluations += result.evaluations;
    if (again.f <= result.f) {
      result = std::move(again);
    } else {
      result.evaluations = again.evaluations;
    }
    if (!improved) break;
  }
  return result;
}

}  // namespace proprio::study::detail
