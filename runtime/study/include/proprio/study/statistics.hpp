#pragma once
// The statistics a psychophysics paper reports: one-way ANOVA, repeated-
// measures ANOVA with the Greenhouse-Geisser correction, paired t-tests, and
// Bonferroni / Holm corrections for multiple comparisons. p-values come from
// Boost.Math's F and Student-t distributions.
#include <string>
#include <vector>

#include "proprio/core/result.hpp"

namespace proprio::study {

double mean(const std::vector<double>& x);
// Sample standard deviation (n - 1); NaN for fewer than two values.
double sample_sd(const std::vector<double>& x);

// Degenerate data (no variance at all, or none in the error term: every value
// equal, every participant at 100 %) cannot be tested: an F or t there would
// be infinite or 0/0, not evidence. Such results have testable = false, a
// reason in not_testable_reason, and NaN test statistics, p-values and
// effect sizes. Sums of squares below kRoundOffRelative of the total (or of
// the data's own magnitude) are round-off and are reported as exactly 0.
inline constexpr double kRoundOffRelative = 1e-12;

struct OneWayAnova {
  double ss_between = 0.0, ss_within = 0.0;
  double df_between = 0.0, df_within = 0.0;
  double f = 0.0;
  double p = 1.0;
  double eta_squared = 0.0;  // ss_between / ss_total
  bool testable = true;
  std::string not_testable_reason;
};
// groups[g] holds the observations of group g (independent groups).
Result<OneWayAnova> one_way_anova(const std::vector<std::vector<double>>& groups);

struct RepeatedMeasuresAnova {
  int subjects = 0;
  int conditions = 0;
  double ss_conditions = 0.0, ss_subjects = 0.0, ss_error = 0.0;
  double df_conditions = 0.0, df_error = 0.0;
  double f = 0.0;
  double p = 1.0;               // assuming sphericity
  double gg_epsilon = 1.0;      // Greenhouse-Geisser, in [1/(k-1), 1]
  double gg_df_conditions = 0.0, gg_df_error = 0.0;
  double gg_p = 1.0;            // with both dfs scaled by epsilon
  double partial_eta_squared = 0.0;
  bool testable = true;
  std::string not_testable_reason;
};
// data[s][c]: subject s in condition c; every subject has every condition.
Result<RepeatedMeasuresAnova> repeated_measures_anova(const std::vector<std::vector<double>>& data);

struct PairedT {
  int n = 0;
  double mean_difference = 0.0;  // mean of a - b
  double sd_difference = 0.0;
  double t = 0.0;
  double df = 0.0;
  double p = 1.0;                // two-sided
  double cohen_dz = 0.0;         // mean / sd of the differences
  double ci_lower = 0.0, ci_upper = 0.0;  // of the mean difference
  bool testable = true;          // false when every difference is the same (no spread)
  std::string not_testable_reason;
};
Result<PairedT> paired_t_test(const std::vector<double>& a, const std::vector<double>& b, double coverage = 0.95);

enum class PAdjust { none, bonferroni, holm };
Result<PAdjust> parse_p_adjust(const std::string& name);  // "none", "bonferroni", "holm"
const char* to_string(PAdjust method) noexcept;
// Adjusted p-values, in the input's order, capped at 1; NaN (not testable) stays NaN and
// does not count as a comparison.
std::vector<double> bonferroni(const std::vector<double>& p);
std::vector<double> holm(const std::vector<double>& p);
std::vector<double> adjust_p(const std::vector<double>& p, PAdjust method);

}  // namespace proprio::study
