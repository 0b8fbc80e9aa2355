#include "proprio/core/one_euro_filter.hpp"

#include <cmath>
#include <cstdio>

namespace proprio {
namespace {

// Smoothing factor of an exponential filter with cutoff fc at step dt (eq. 1-2 of the paper).
double alpha(double cutoff_hz, double dt_s) {
  const double tau = 1.0 / (2.0 * M_PI * cutoff_hz);
  return 1.0 / (1.0 + tau / dt_s);
}

}  // namespace

Status OneEuroOptions::validate() const {
  if (!(min_cutoff_hz > 0.0) || !(derivative_cutoff_hz > 0.0) || !(beta >= 0.0) || !std::isfinite(min_cutoff_hz) ||
      !std::isfinite(derivative_cutoff_hz) || !std::isfinite(beta)) {
    return make_error(Errc::invalid_argument,
                      "1€ filter: min_cutoff_hz and derivative_cutoff_hz must be > 0 and beta >= 0 (got " + describe() +
                          ")");
  }
  return {};
}

std::string OneEuroOptions::describe() const {
  char buf[128];
  std::snprintf(buf, sizeof buf, "min_cutoff=%.3g Hz beta=%.3g d_cutoff=%.3g Hz", min_cutoff_hz, beta,
                derivative_cutoff_hz);
  return buf;
}

OneEuroFilter::OneEuroFilter(std::size_t channels, OneEuroOptions options)
    : options_(options), x_(channels, 0.0), dx_(channels, 0.0) {}

void OneEuroFilter::reset() noexcept { primed_ = false; }

void OneEuroFilter::filter(TimeNs t_ns, double* values) noexcept {
  if (!primed_ || t_ns <= last_ns_) {
    for (std::size_t i = 0; i < x_.size(); ++i) {
      x_[i] = values[i];
      dx_[i] = 0.0;
    }
    last_ns_ = t_ns;
    primed_ = true;
    return;
  }
  const double dt = 1e-9 * static_cast<double>(t_ns - last_ns_);
  last_ns_ = t_ns;
  const double a_d = alpha(options_.derivative_cutoff_hz, dt);
  for (std::size_t i = 0; i < x_.size(); ++i) {
    const double v = values[i];
    if (!std::isfinite(v) || !std::isfinite(x_[i])) {
      x_[i] = v;
      dx_[i] = 0.0;
      continue;
    }
    const double raw_dx = (v - x_[i]) / dt;
    dx_[i] += a_d * (raw_dx - dx_[i]);
    const double cutoff = options_.min_cutoff_hz + options_.beta * std::abs(dx_[i]);
    x_[i] += alpha(cutoff, dt) * (v - x_[i]);
    values[i] = x_[i];
  }
}

}  // namespace proprio
