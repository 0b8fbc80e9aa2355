#pragma once
// Adaptive psychophysical procedures. Each picks the next stimulus for one
// condition and learns from the response; "correct" moves toward harder
// (smaller) stimuli. All state is a function of the responses recorded, so a
// resumed session rebuilds it by replaying its CSV.
//
//  - Staircase: transformed up/down (Levitt 1971; 1-up-N-down converges on
//    p^N = 0.5: 70.7% for N = 2, 79.4% for N = 3) and weighted up/down
//    (Kaernbach 1991; step_up / step_down = p / (1 - p) converges on p).
//  - Quest (Watson & Pelli 1983): Bayesian posterior over the threshold with a
//    known slope; each trial is placed at the posterior mean.
//  - Psi (Kontsevich & Tyler 1999), generalised to a lapse grid as in QUEST+
//    (Watson 2017): joint posterior over (alpha, beta, lambda); each trial
//    goes where the expected posterior entropy is least.
//  - Interleaved: several procedures in one condition, chosen at random each
//    trial among those not finished.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/study/psychometric.hpp"

namespace proprio::study {

// What a procedure asks for: a stimulus, and which of its tracks asked.
struct StimulusRequest {
  double stimulus = 0.0;
  int track = 0;  // interleaved tracks: 0..n-1; others 0
};

struct ProcedureEstimate {
  double threshold = 0.0;  // in stimulus units, at the procedure's target
  double sd = 0.0;         // posterior SD (QUEST, Psi) or SD of reversal values (staircase); NaN if unknown
  int trials = 0;
  int reversals = 0;       // staircases only
};

class Procedure {
 public:
  virtual ~Procedure() = default;
  virtual const char* kind() const noexcept = 0;
  // `rng` serves only random choices between tracks; seed it per trial so a
  // replay makes the same choices.
  virtual StimulusRequest next(Rng& rng) = 0;
  virtual void record(const StimulusRequest& request, bool correct) = 0;
  virtual bool finished() const = 0;
  virtual ProcedureEstimate estimate() const = 0;
  virtual std::unique_ptr<Procedure> clone() const = 0;
};

struct StaircaseSettings {
  double start = 1.0;
  int down = 2;                     // consecutive correct responses before a step down (harder)
  int up = 1;                       // consecutive wrong responses before a step up (easier)
  std::vector<double> steps = {1.0};  // down-step size after 0, 1, 2... reversals (the last one repeats)
  double up_ratio = 1.0;            // step_up = step_down * up_ratio (weighted: target / (1 - target))
  bool log_steps = false;           // steps multiply (x * 10^step) instead of add
  double min = -1e300, max = 1e300; // stimulus range
  int max_trials = 50;
  int max_reversals = 0;            // 0: stop by trials only
  int discard_reversals = 2;        // the first reversals are left out of the estimate
};
// Checks the settings ("where" names the config key for messages).
Status validate(const StaircaseSettings& s, const std::string& where);
// up_ratio for a weighted up/down staircase converging on `target`.
double weighted_up_ratio(double target);
// The proportion correct a 1-up-N-down staircase converges on: 0.5^(1/N).
double transformed_target(int down);

struct QuestSettings {
  PsychometricModel model = PsychometricModel::weibull;
  double beta = 3.5, guess = 0.5, lapse = 0.01;
  double target = 0.75;             // the threshold's proportion correct
  double prior_mean = 1.0, prior_sd = 1.0;  // Gaussian prior on the threshold
  double grid_min = 0.0, grid_max = 2.0;    // threshold grid (and the stimulus range)
  int grid_points = 201;
  int max_trials = 40;
  double stop_sd = 0.0;             // > 0: also stop once the posterior SD falls below this
};
Status validate(const QuestSettings& s, const std::string& where);

struct PsiSettings {
  PsychometricModel model = PsychometricModel::weibull;
  double guess = 0.5;
  double target = 0.75;             // for the reported threshold
  std::vector<double> alphas;       // parameter grids
  std::vector<double> betas;
  std::vector<double> lapses = {0.0};
  std::vector<double> stimuli;      // candidate stimuli
  int max_trials = 40;
};
Status validate(const PsiSettings& s, const std::string& where);
// n values from lo to hi, evenly (log = evenly in log; lo, hi > 0).
std::vector<double> spaced(double lo, double hi, int n, bool log = false);

class Staircase final : public Procedure {
 public:
  explicit Staircase(StaircaseSettings settings);
  const char* kind() const noexcept override { return settings_.up_ratio == 1.0 ? "staircase" : "weighted-staircase"; }
  StimulusRequest next(Rng& rng) override;
  void record(const StimulusRequest& request, bool correct) override;
  bool finished() const override;
  ProcedureEstimate estimate() const override;
  std::unique_ptr<Procedure> clone() const override { return std::make_unique<Staircase>(*this); }
  const std::vector<double>& reversal_levels() const { return reversals_; }
  double current() const { return level_; }

 private:
  StaircaseSettings settings_;
  double level_;
  int run_correct_ = 0, run_wrong_ = 0;
  int last_direction_ = 0;  // -1 down, +1 up, 0 none yet
  int trials_ = 0;
  std::vector<double> reversals_;
};

class Quest final : public Procedure {
 public:
  explicit Quest(QuestSettings settings);
  const char* kind() const noexcept override { return "quest"; }
  StimulusRequest next(Rng& rng) override;
  void record(const StimulusRequest& request, bool correct) override;
  bool finished() const override;
  ProcedureEstimate estimate() const override;
  std::unique_ptr<Procedure> clone() const override { return std::make_unique<Quest>(*this); }

 private:
  double p_correct(double threshold, double x) const;
  QuestSettings settings_;
  std::vector<double> grid_, log_posterior_;
  int trials_ = 0;
};

class Psi final : public Procedure {
 public:
  explicit Psi(PsiSettings settings);
  const char* kind() const noexcept override { return "psi"; }
  StimulusRequest next(Rng& rng) override;
  void record(const StimulusRequest& request, bool correct) override;
  bool finished() const override;
  ProcedureEstimate estimate() const override;
  std::unique_ptr<Procedure> clone() const override { return std::make_unique<Psi>(*this); }
  // Posterior means of the parameters (estimate() reports the posterior mean threshold).
  PsychometricParams posterior_mean() const;

 private:
  PsiSettings settings_;
  std::vector<double> posterior_;        // normalised, over alphas x betas x lapses
  std::vector<std::vector<double>> p_correct_;  // [stimulus][parameter cell]
  int trials_ = 0;
};

class Interleaved final : public Procedure {
 public:
  explicit Interleaved(std::vector<std::unique_ptr<Procedure>> tracks);
  Interleaved(const Interleaved& other);
  const char* kind() const noexcept override;
  StimulusRequest next(Rng& rng) override;
  void record(const StimulusRequest& request, bool correct) override;
  bool finished() const override;
  // The mean of the tracks' thresholds (SD: their spread).
  ProcedureEstimate estimate() const override;
  std::unique_ptr<Procedure> clone() const override { return std::make_unique<Interleaved>(*this); }
  const Procedure& track(int i) const { return *tracks_[static_cast<std::size_t>(i)]; }
  int tracks() const { return static_cast<int>(tracks_.size()); }

 private:
  std::vector<std::unique_ptr<Procedure>> tracks_;
};

}  // namespace proprio::study
