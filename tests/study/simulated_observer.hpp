#pragma once
// A test observer with a known psychometric function. Each response draws from
// its own stream, seeded by (observer seed, trial number), so a resumed
// session sees exactly the responses the uninterrupted one would have.
#include <cstdint>

#include "proprio/core/random.hpp"
#include "proprio/study/psychometric.hpp"

namespace proprio::study::testing {

struct SimulatedObserver {
  PsychometricModel model = PsychometricModel::weibull;
  PsychometricParams params{5.0, 3.0, 0.5, 0.0};
  std::uint64_t seed = 1;

  bool respond(double stimulus, std::uint64_t trial) const {
    Rng rng(mix_seed(seed, trial));
    return rng.uniform01() < psi(model, params, stimulus);
  }
  double threshold(double proportion) const { return *threshold_at(model, params, proportion); }
};

}  // namespace proprio::study::testing
