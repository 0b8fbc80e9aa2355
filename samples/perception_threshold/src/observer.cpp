#include "proprio/perception_threshold/observer.hpp"

#include <cmath>
#include <limits>

namespace proprio::perception {
namespace {

// Felt forces below this are not a contact (the emulated device's sensors
// read a few mN of noise and pretension).
constexpr double kFeltContactN = 0.05;
constexpr std::uint64_t kNoiseStream = 7;

double normal_cdf(double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); }

double bisect(const auto& f, double target, double lo, double hi) {
  double flo = f(lo) - target;
  if (flo * (f(hi) - target) > 0) return std::numeric_limits<double>::quiet_NaN();
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    const double fm = f(mid) - target;
    if ((fm < 0) == (flo < 0)) {
      lo = mid;
      flo = fm;
    } else {
      hi = mid;
    }
  }
  return 0.5 * (lo + hi);
}

}  // namespace

double p_correct(const ObserverParams& o, double sigma_p_cm, HapticTarget haptic, double d_cm) {
  const double s = haptic == HapticTarget::true_sphere ? 1.0 : haptic == HapticTarget::false_sphere ? -1.0 : 0.0;
  const double mean = d_cm * d_cm / (2 * sigma_p_cm * sigma_p_cm) + s * o.haptic_weight;
  const double var = d_cm * d_cm / (sigma_p_cm * sigma_p_cm) + o.decision_noise * o.decision_noise +
                     (s != 0 ? o.haptic_noise * o.haptic_noise : 0.0);
  const double p = var > 0 ? normal_cdf(mean / std::sqrt(var)) : (mean > 0 ? 1.0 : mean < 0 ? 0.0 : 0.5);
  return 0.5 * o.lapse + (1 - o.lapse) * p;
}

double true_threshold_cm(const ObserverParams& o, double sigma_p_cm, HapticTarget haptic, double proportion) {
  return bisect([&](double d) { return p_correct(o, sigma_p_cm, haptic, d); }, proportion, 1e-6, 100.0);
}

double true_max_allowable_error_cm(const ObserverParams& o, double sigma_p_cm) {
  return true_threshold_cm(o, sigma_p_cm, HapticTarget::false_sphere, 0.5);
}

double participant_proprioceptive_noise_cm(const ObserverParams& o, std::uint64_t participant_seed) {
  Rng rng(mix_seed(participant_seed, kNoiseStream));
  return o.proprioceptive_noise_cm * std::exp(o.between_participant_sd * rng.normal());
}

double SimulatedObserver::Moments::correlation() const {
  if (n < 2) return 0;
  const double cov = sfx / n - (sf / n) * (sx / n);
  const double vf = sff / n - (sf / n) * (sf / n);
  const double vx = sxx / n - (sx / n) * (sx / n);
  return vf > 0 && vx > 0 ? cov / std::sqrt(vf * vx) : 0.0;
}

SimulatedObserver::SimulatedObserver(const ObserverParams& params, double sigma_p_cm, std::uint64_t seed)
    : params_(params), sigma_p_m_(sigma_p_cm * 0.01), rng_(seed) {}

void SimulatedObserver::begin_answer() {
  blue_ = {};
  red_ = {};
  peak_felt_n_ = 0;
  attribution_ = 0;
}

void SimulatedObserver::feel(double felt_n, double blue_m, double red_m) {
  peak_felt_n_ = std::max(peak_felt_n_, felt_n);
  blue_.add(felt_n, blue_m);
  red_.add(felt_n, red_m);
}

bool SimulatedObserver::choose_blue(const Vec3& p_true, const Vec3& p_blue, const Vec3& p_red) {
  // Draw every random number every time, so one trial's outcome does not
  // shift the random stream of the next.
  const Vec3 e(rng_.normal(), rng_.normal(), rng_.normal());
  const double decision = rng_.normal();
  const double haptic = rng_.normal();
  const bool lapse = rng_.uniform01() < params_.lapse;
  const bool lapse_blue = rng_.below(2) == 0;

  const Vec3 p_felt = p_true + sigma_p_m_ * e;
  const double two_var = 2 * sigma_p_m_ * sigma_p_m_;
  double l_blue = ((p_felt - p_red).squaredNorm() - (p_felt - p_blue).squaredNorm()) / two_var;
  attribution_ = 0;
  if (peak_felt_n_ >= kFeltContactN) {
    const double cb = blue_.correlation(), cr = red_.correlation();
    if (cb != cr) attribution_ = cb > cr ? 1 : -1;
  }
  l_blue += attribution_ * (params_.haptic_weight + params_.haptic_noise * haptic);
  l_blue += params_.decision_noise * decision;
  if (lapse) return lapse_blue;
  return l_blue > 0;
}

}  // namespace proprio::perception
