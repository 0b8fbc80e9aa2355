#include "proprio/study/statistics.hpp"

#include <algorithm>
#include <boost/math/distributions/fisher_f.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <fmt/format.h>
#include <limits>
#include <numeric>

namespace proprio::study {
namespace {

constexpr double kNaNStat = std::numeric_limits<double>::quiet_NaN();

Status all_finite(const std::vector<double>& x, const std::string& what) {
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (!std::isfinite(x[i])) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{}, value {} is {}: statistics need finite numbers (remove or fill missing "
                                    "values first)",
                                    what, i + 1, x[i]));
    }
  }
  return Status::success();
}

// The scale round-off is judged against: the larger of the centred total and
// the data's raw sum of squares times the relative tolerance (all-equal
// values of 0.1 leave ~1e-30 of centred "variance" behind).
double round_off_floor(double ss_total, double ss_raw) {
  return kRoundOffRelative * std::max(ss_total, 1e-8 * ss_raw);
}

// Upper tail of F(df1, df2) beyond f.
double f_upper_tail(double f, double df1, double df2) {
  if (!(f >= 0.0) || std::isinf(f)) return kNaNStat;
  return boost::math::cdf(boost::math::complement(boost::math::fisher_f_distribution<double>(df1, df2), f));
}

}  // namespace

double mean(const std::vector<double>& x) {
  if (x.empty()) return kNaNStat;
  return std::accumulate(x.begin(), x.end(), 0.0) / static_cast<double>(x.size());
}

double sample_sd(const std::vector<double>& x) {
  if (x.size() < 2) return kNaNStat;
  const double m = mean(x);
  double ss = 0.0;
  for (double v : x) ss += (v - m) * (v - m);
  return std::sqrt(ss / static_cast<double>(x.size() - 1));
}

Result<OneWayAnova> one_way_anova(const std::vector<std::vector<double>>& groups) {
  if (groups.size() < 2) {
    return make_error(Errc::invalid_argument,
                      fmt::format("one-way ANOVA needs at least two groups; got {}", groups.size()));
  }
  std::size_t total_n = 0;
  double grand = 0.0;
  for (std::size_t g = 0; g < groups.size(); ++g) {
    if (groups[g].empty()) {
      return make_error(Errc::invalid_argument, fmt::format("group {} has no observations", g + 1));
    }
    if (Status s = all_finite(groups[g], fmt::format("group {}", g + 1)); !s) return s.error();
    total_n += groups[g].size();
    grand += std::accumulate(groups[g].begin(), groups[g].end(), 0.0);
  }
  if (total_n <= groups.size()) {
    return make_error(Errc::invalid_argument,
                      fmt::format("one-way ANOVA needs more observations ({}) than groups ({})", total_n,
                                  groups.size()));
  }
  grand /= static_cast<double>(total_n);
  OneWayAnova a;
  double ss_raw = 0.0;
  for (const std::vector<double>& g : groups) {
    const double m = mean(g);
    a.ss_between += static_cast<double>(g.size()) * (m - grand) * (m - grand);
    for (double v : g) {
      a.ss_within += (v - m) * (v - m);
      ss_raw += v * v;
    }
  }
  a.df_between = static_cast<double>(groups.size() - 1);
  a.df_within = static_cast<double>(total_n - groups.size());
  const double floor = round_off_floor(a.ss_between + a.ss_within, ss_raw);
  if (a.ss_between <= floor) a.ss_between = 0.0;
  if (a.ss_within <= floor) a.ss_within = 0.0;
  if (a.ss_within == 0.0) {
    a.testable = false;
    a.not_testable_reason = a.ss_between == 0.0 ? "every value is the same: no variance to test"
                                                : "no variance within any group: the test needs spread within groups";
    a.f = a.p = a.eta_squared = kNaNStat;
    return a;
  }
  a.f = (a.ss_between / a.df_between) / (a.ss_within / a.df_within);
  a.p = f_upper_tail(a.f, a.df_between, a.df_within);
  a.eta_squared = a.ss_between / (a.ss_between + a.ss_within);
  return a;
}

Result<RepeatedMeasuresAnova> repeated_measures_anova(const std::vector<std::vector<double>>& data) {
  const std::size_t n = data.size();
  if (n < 2) {
    return make_error(Errc::invalid_argument,
                      fmt::format("repeated-measures ANOVA needs at least two subjects; got {}", n));
  }
  const std::size_t k = data[0].size();
  if (k < 2) {
    return make_error(Errc::invalid_argument,
                      fmt::format("repeated-measures ANOVA needs at least two conditions; got {}", k));
  }
  for (std::size_t s = 0; s < n; ++s) {
    if (data[s].size() != k) {
      return make_error(Errc::invalid_argument,
                        fmt::format("subject {} has {} conditions but subject 1 has {}; every subject needs a value "
                                    "in every condition",
                                    s + 1, data[s].size(), k));
    }
    if (Status st = all_finite(data[s], fmt::format("subject {}", s + 1)); !st) return st.error();
  }
  const double dn = static_cast<double>(n), dk = static_cast<double>(k);
  std::vector<double> subject_mean(n, 0.0), condition_mean(k, 0.0);
  double grand = 0.0;
  for (std::size_t s = 0; s < n; ++s) {
    for (std::size_t c = 0; c < k; ++c) {
      subject_mean[s] += data[s][c] / dk;
      condition_mean[c] += data[s][c] / dn;
      grand += data[s][c] / (dn * dk);
    }
  }
  RepeatedMeasuresAnova a;
  a.subjects = static_cast<int>(n);
  a.conditions = static_cast<int>(k);
  double ss_total = 0.0, ss_raw = 0.0;
  for (std::size_t s = 0; s < n; ++s) {
    for (std::size_t c = 0; c < k; ++c) {
      ss_total += (data[s][c] - grand) * (data[s][c] - grand);
      ss_raw += data[s][c] * data[s][c];
    }
  }
  for (std::size_t c = 0; c < k; ++c) a.ss_conditions += dn * (condition_mean[c] - grand) * (condition_mean[c] - grand);
  for (std::size_t s = 0; s < n; ++s) a.ss_subjects += dk * (subject_mean[s] - grand) * (subject_mean[s] - grand);
  // The error term as the residual of the subject x condition table, not as
  // a difference of totals: the difference leaves round-off behind.
  for (std::size_t s = 0; s < n; ++s) {
    for (std::size_t c = 0; c < k; ++c) {
      const double r = data[s][c] - subject_mean[s] - condition_mean[c] + grand;
      a.ss_error += r * r;
    }
  }
  const double floor = round_off_floor(ss_total, ss_raw);
  if (a.ss_conditions <= floor) a.ss_conditions = 0.0;
  if (a.ss_subjects <= floor) a.ss_subjects = 0.0;
  if (a.ss_error <= floor) a.ss_error = 0.0;
  a.df_conditions = dk - 1.0;
  a.df_error = (dk - 1.0) * (dn - 1.0);
  if (a.ss_error == 0.0) {
    a.testable = false;
    a.not_testable_reason =
        a.ss_conditions == 0.0 && a.ss_subjects == 0.0
            ? "every value is the same: no variance to test"
            : "no error variance: every subject differs between the conditions by exactly the same amounts "
              "(e.g. everyone at ceiling), so F would be infinite or 0/0";
    a.f = a.p = a.gg_p = a.partial_eta_squared = kNaNStat;
    a.gg_df_conditions = a.df_conditions;
    a.gg_df_error = a.df_error;
    return a;
  }
  a.f = (a.ss_conditions / a.df_conditions) / (a.ss_error / a.df_error);
  a.p = f_upper_tail(a.f, a.df_conditions, a.df_error);
  a.partial_eta_squared = a.ss_conditions / (a.ss_conditions + a.ss_error);

  // Greenhouse-Geisser epsilon from the double-centred covariance matrix of
  // the conditions: eps = (trace S*)^2 / ((k - 1) * sum S*_ij^2).
  std::vector<std::vector<double>> cov(k, std::vector<double>(k, 0.0));
  for (std::size_t i = 0; i < k; ++i) {
    for (std::size_t j = 0; j < k; ++j) {
      for (std::size_t s = 0; s < n; ++s) {
        cov[i][j] += (data[s][i] - condition_mean[i]) * (data[s][j] - condition_mean[j]) / (dn - 1.0);
      }
    }
  }
  std::vector<double> row_mean(k, 0.0);
  double cov_mean = 0.0;
  for (std::size_t i = 0; i < k; ++i) {
    for (std::size_t j = 0; j < k; ++j) {
      row_mean[i] += cov[i][j] / dk;
      cov_mean += cov[i][j] / (dk * dk);
    }
  }
  double trace = 0.0, sum_sq = 0.0;
  for (std::size_t i = 0; i < k; ++i) {
    for (std::size_t j = 0; j < k; ++j) {
      // The covariance matrix is symmetric, so column means equal row means.
      const double centred = cov[i][j] - row_mean[i] - row_mean[j] + cov_mean;
      sum_sq += centred * centred;
      if (i == j) trace += centred;
    }
  }
  a.gg_epsilon = sum_sq > 0.0 ? std::clamp(trace * trace / ((dk - 1.0) * sum_sq), 1.0 / (dk - 1.0), 1.0) : 1.0;
  a.gg_df_conditions = a.gg_epsilon * a.df_conditions;
  a.gg_df_error = a.gg_epsilon * a.df_error;
  a.gg_p = f_upper_tail(a.f, a.gg_df_conditions, a.gg_df_error);
  return a;
}

Result<PairedT> paired_t_test(const std::vector<double>& a, const std::vector<double>& b, double coverage) {
  if (a.size() != b.size()) {
    return make_error(Errc::invalid_argument,
                      fmt::format("a paired t-test needs the same subjects in both conditions: {} vs {} values",
                                  a.size(), b.size()));
  }
  if (a.size() < 2) {
    return make_error(Errc::invalid_argument,
                      fmt::format("a paired t-test needs at least two pairs; got {}", a.size()));
  }
  if (!(coverage > 0.0 && coverage < 1.0)) {
    return make_error(Errc::invalid_argument, fmt::format("confidence level {} must lie in (0, 1)", coverage));
  }
  if (Status s = all_finite(a, "first condition"); !s) return s.error();
  if (Status s = all_finite(b, "second condition"); !s) return s.error();
  std::vector<double> d(a.size());
  for (std::size_t i = 0; i < a.size(); ++i) d[i] = a[i] - b[i];
  PairedT t;
  t.n = static_cast<int>(d.size());
  t.mean_difference = mean(d);
  t.sd_difference = sample_sd(d);
  t.df = static_cast<double>(d.size() - 1);
  double ss = 0.0, ss_raw = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ss += (d[i] - t.mean_difference) * (d[i] - t.mean_difference);
    ss_raw += a[i] * a[i] + b[i] * b[i];
  }
  if (ss <= round_off_floor(ss, ss_raw + static_cast<double>(d.size()) * t.mean_difference * t.mean_difference)) {
    t.sd_difference = 0.0;
    t.testable = false;
    t.not_testable_reason = t.mean_difference == 0.0
                                ? "the two conditions are identical for every subject: nothing to test"
                                : "every subject differs by exactly the same amount: no spread to test against";
    t.t = t.p = t.cohen_dz = kNaNStat;
    t.ci_lower = t.ci_upper = t.mean_difference;
    return t;
  }
  const double se = t.sd_difference / std::sqrt(static_cast<double>(d.size()));
  const boost::math::students_t_distribution<double> dist(t.df);
  const double t_crit = boost::math::quantile(boost::math::complement(dist, 0.5 * (1.0 - coverage)));
  t.t = t.mean_difference / se;
  t.p = 2.0 * boost::math::cdf(boost::math::complement(dist, std::abs(t.t)));
  t.cohen_dz = t.mean_difference / t.sd_difference;
  t.ci_lower = t.mean_difference - t_crit * se;
  t.ci_upper = t.mean_difference + t_crit * se;
  return t;
}

Result<PAdjust> parse_p_adjust(const std::string& name) {
  if (name == "none") return PAdjust::none;
  if (name == "bonferroni") return PAdjust::bonferroni;
  if (name == "holm") return PAdjust::holm;
  return make_error(Errc::invalid_argument,
                    fmt::format("unknown p-value correction '{}': choose none, bonferroni or holm", name));
}

const char* to_string(PAdjust method) noexcept {
  switch (method) {
    case PAdjust::none: return "none";
    case PAdjust::bonferroni: return "bonferroni";
    case PAdjust::holm: return "holm";
  }
  return "?";
}

// Tests that were not testable (NaN p) are not comparisons: they stay NaN
// and do not count in the number of comparisons.
std::vector<double> bonferroni(const std::vector<double>& p) {
  const auto m = static_cast<double>(std::count_if(p.begin(), p.end(), [](double v) { return !std::isnan(v); }));
  std::vector<double> out(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) out[i] = std::isnan(p[i]) ? kNaNStat : std::min(1.0, p[i] * m);
  return out;
}

std::vector<double> holm(const std::vector<double>& p) {
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (!std::isnan(p[i])) order.push_back(i);
  }
  const std::size_t m = order.size();
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return p[a] < p[b]; });
  std::vector<double> out(p.size(), kNaNStat);
  double running = 0.0;  // adjusted p-values never decrease along the sorted order
  for (std::size_t r = 0; r < m; ++r) {
    running = std::max(running, std::min(1.0, static_cast<double>(m - r) * p[order[r]]));
    out[order[r]] = running;
  }
  return out;
}

std::vector<double> adjust_p(const std::vector<double>& p, PAdjust method) {
  switch (method) {
    case PAdjust::bonferroni: return bonferroni(p);
    case PAdjust::holm: return holm(p);
    case PAdjust::none: break;
  }
  return p;
}

}  // namespace proprio::study
