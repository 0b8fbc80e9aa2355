#pragma once
// The simulated participant's decision model (docs/perception-threshold.md).
//
// An ideal-observer with noise. At the end of the answer phase the observer
// feels where its fingertip is, p_felt = p_true + e with e ~ N(0, sigma_p^2 I),
// and sees the two spheres s_blue and s_red. Proprioception alone gives the
// log-likelihood ratio that blue is the finger:
//   L_p = (|p_felt - s_red|^2 - |p_felt - s_blue|^2) / (2 sigma_p^2).
// When a contact force was felt, the observer attributes it to the sphere whose
// drawn contact with the cylinder went with it (the higher correlation between
// felt force and that sphere's drawn penetration over the answer phase), and
// that sphere gains haptic evidence w + N(0, sigma_h^2). Decision noise
// N(0, sigma_d^2) is added and the larger side is chosen; with probability
// lambda the answer is a coin flip instead (a lapse).
//
// For an offset d between the spheres this gives the closed form
//   P(correct) = lambda/2 + (1 - lambda) Phi((d^2/(2 sigma_p^2) + s w) / sqrt(d^2/sigma_p^2 + sigma_d^2 + [s != 0] sigma_h^2))
// with s = +1 (haptics on the true sphere), -1 (on the false one), 0 (none),
// so the ground-truth thresholds of a simulated participant are known exactly.
// The observer reads only what a participant perceives: its own felt finger
// position (with noise), the drawn spheres and cylinder, and the force the
// fingertip device renders.
#include <cstdint>

#include "proprio/core/math.hpp"
#include "proprio/core/random.hpp"
#include "proprio/perception_threshold/protocol.hpp"

namespace proprio::perception {

// The model's psychometric functions and thresholds, from the closed form.
double p_correct(const ObserverParams& params, double proprioceptive_noise_cm, HapticTarget haptic, double offset_cm);
// The offset (cm) where p_correct reaches `proportion`; NaN if it never does in (0, 100 cm].
double true_threshold_cm(const ObserverParams& params, double proprioceptive_noise_cm, HapticTarget haptic,
                         double proportion);
// With haptics on the false sphere, the offset where the haptic sphere is
// chosen half the time: the thesis's "maximum allowable tracking error".
double true_max_allowable_error_cm(const ObserverParams& params, double proprioceptive_noise_cm);
// A participant's proprioceptive noise: the population value times exp(N(0, sd)).
double participant_proprioceptive_noise_cm(const ObserverParams& params, std::uint64_t participant_seed);

class SimulatedObserver {
 public:
  SimulatedObserver(const ObserverParams& params, double proprioceptive_noise_cm, std::uint64_t seed);

  void begin_answer();
  // Every servo tick of the answer phase: the force the fingertip device
  // renders (what is felt) and each drawn sphere's penetration into the cylinder.
  void feel(double felt_force_n, double blue_penetration_m, double red_penetration_m);
  // The answer: true for blue.
  bool choose_blue(const Vec3& p_true_finger_in_world, const Vec3& p_blue_in_world, const Vec3& p_red_in_world);
  // Which sphere the felt force was attributed to in the last answer: +1 blue, -1 red, 0 none.
  int last_attribution() const noexcept { return attribution_; }

 private:
  struct Moments {
    double n = 0, sf = 0, sff = 0, sx = 0, sxx = 0, sfx = 0;
    void add(double f, double x) {
      n += 1;
      sf += f;
      sff += f * f;
      sx += x;
      sxx += x * x;
      sfx += f * x;
    }
    double correlation() const;
  };
  ObserverParams params_;
  double sigma_p_m_;
  Rng rng_;
  Moments blue_, red_;
  double peak_felt_n_ = 0;
  int attribution_ = 0;
};

}  // namespace proprio::perception
