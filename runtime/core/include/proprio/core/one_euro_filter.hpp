#pragma once
// The 1€ filter (Casiez, Roussel & Vogel, "1€ Filter: A Simple Speed-based
// Low-pass Filter for Noisy Input in Interactive Systems", CHI 2012): a
// first-order low-pass whose cutoff rises with the signal's speed, so a still
// hand does not jitter and a fast one does not lag. Each channel is filtered
// on its own, with the time step taken from the samples' timestamps.
#include <cstddef>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"

namespace proprio {

struct OneEuroOptions {
  double min_cutoff_hz = 1.0;  // cutoff at rest: lower = less jitter, more lag when slow
  double beta = 0.5;           // cutoff increase per unit of speed (signal units per second)
  double derivative_cutoff_hz = 1.0;

  Status validate() const;
  std::string describe() const;
};

class OneEuroFilter {
 public:
  explicit OneEuroFilter(std::size_t channels = 1, OneEuroOptions options = {});

  // Filters one sample of every channel in place. The first sample, a time
  // that does not advance, or a non-finite value resets the affected state
  // (the sample passes through unfiltered).
  void filter(TimeNs t_ns, double* values) noexcept;
  void reset() noexcept;
  std::size_t channels() const noexcept { return x_.size(); }
  const OneEuroOptions& options() const noexcept { return options_; }

 private:
  OneEuroOptions options_;
  std::vector<double> x_, dx_;
  TimeNs last_ns_ = 0;
  bool primed_ = false;
};

}  // namespace proprio
