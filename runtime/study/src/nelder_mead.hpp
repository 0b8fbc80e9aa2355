#pragma once
// A small Nelder-Mead simplex minimiser (Lagarias et al. 1998 coefficients),
// restarted from its best point until a restart no longer improves it, which
// guards against the simplex collapsing early.
#include <functional>
#include <vector>

namespace proprio::study::detail {

struct NelderMeadOptions {
  double initial_step = 0.1;        // per coordinate: step = max(|x| * initial_step, initial_step * 0.25)
  double f_tolerance = 1e-12;       // absolute spread of f over the simplex
  double x_tolerance = 1e-10;       // max vertex distance from the best, per coordinate (relative + absolute)
  int max_evaluations = 20000;
  int max_restarts = 5;
};

struct NelderMeadResult {
  std::vector<double> x;
  double f = 0.0;
  int evaluations = 0;
};

NelderMeadResult nelder_mead(const std::function<double(const std::vector<double>&)>& f, std::vector<double> x0,
                             const NelderMeadOptions& options = {});

}  // namespace proprio::study::detail
