// proprio psychometric fit, proprio stats anova|rm-anova|paired-t and
// proprio study analyze|check (proprio::study; docs/study.md).
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "commands.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/core/random.hpp"
#include "proprio/study/analysis.hpp"
#include "proprio/study/completion_time.hpp"
#include "proprio/study/csv.hpp"
#include "proprio/study/design.hpp"
#include "proprio/study/plot.hpp"
#include "proprio/study/psychometric.hpp"
#include "proprio/study/statistics.hpp"

namespace proprio::cli {
namespace {

using namespace proprio::study;
using nlohmann::json;
namespace fs = std::filesystem;

json number_or_null(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

// ---------------------------------------------------------------------------
// psychometric fit

struct FitArgs {
  std::string data;
  std::string model = "weibull";
  double guess = 0.5;
  std::optional<double> lapse;
  std::optional<double> lapse_max;
  double threshold = 0.75;
  int bootstrap = 0;
  std::uint64_t seed = 1;
  int gof = 0;
  double coverage = 0.95;
  std::string plot;
  bool json = false;
};

Result<std::vector<StimulusLevel>> read_levels(const std::string& path) {
  auto table = read_csv(path);
  if (!table) return table.error();
  auto lc = table->require_column("level");
  if (!lc) return lc.error();
  auto cc = table->require_column("correct");
  if (!cc) return cc.error();
  auto tc = table->require_column("trials");
  if (!tc) return tc.error();
  std::vector<StimulusLevel> out;
  long long total = 0;
  for (std::size_t r = 0; r < table->rows.size(); ++r) {
    auto level = table->number(r, *lc);
    if (!level) return level.error();
    auto correct = table->integer(r, *cc);
    if (!correct) return correct.error();
    auto trials = table->integer(r, *tc);
    if (!trials) return trials.error();
    if (*trials < 0 || *correct < 0 || *correct > *trials) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{}:{}: {} correct of {} trials is impossible", path, table->lines[r], *correct,
                                    *trials));
    }
    // Counts are ints in the fit; checked here so they never wrap.
    total += *trials;
    if (*trials > kMaxTrials || total > kMaxTrials) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{}:{}: {} trials {}is more than the {} a fit takes; check the counts", path,
                                    table->lines[r], *trials > kMaxTrials ? *trials : total,
                                    *trials > kMaxTrials ? "" : "in all up to this row ", kMaxTrials));
    }
    out.push_back({*level, static_cast<int>(*correct), static_cast<int>(*trials)});
  }
  if (out.empty()) {
    return make_error(Errc::invalid_argument, fmt::format("{}: no data rows below the header", path));
  }
  return out;
}

int run_fit(const FitArgs& args) {
  constexpr int kMaxSimulations = 1'000'000;
  if (args.bootstrap != 0 && (args.bootstrap < 10 || args.bootstrap > kMaxSimulations)) {
    return report_error(make_error(Errc::invalid_argument,
                                   fmt::format("--bootstrap {}: give 0 (no bootstrap) or from 10 to {} samples (1999 "
                                               "is usual)",
                                               args.bootstrap, kMaxSimulations)));
  }
  if (args.gof < 0 || args.gof > kMaxSimulations) {
    return report_error(make_error(Errc::invalid_argument,
                                   fmt::format("--gof {}: give 0 (no goodness-of-fit test) or from 1 to {} "
                                               "simulations (e.g. 1999)",
                                               args.gof, kMaxSimulations)));
  }
  auto data = read_levels(args.data);
  if (!data) return report_error(data.error());
  auto model = parse_psychometric_model(args.model);
  if (!model) return report_error(model.error());
  FitOptions o;
  o.model = *model;
  o.guess = args.guess;
  if (args.lapse_max) {
    o.lapse_free = true;
    o.lapse_max = *args.lapse_max;
  } else {
    o.lapse = args.lapse.value_or(0.0);
  }
  auto fit = fit_psychometric(*data, o);
  if (!fit) return report_error(fit.error().with_context(args.data));
  auto threshold = threshold_at(fit->model, fit->params, args.threshold);
  if (!threshold) {
    return report_error(threshold.error().with_context(fmt::format("{} (--threshold {})", args.data, args.threshold)));
  }
  const double slope = slope_at(fit->model, fit->params, *threshold);
  const UniquenessCheck unique = check_unique_maximum(*fit, *data, args.threshold);
  if (!unique.unique) std::fprintf(stderr, "warning: %s: %s\n", args.data.c_str(), unique.message.c_str());
  std::optional<BootstrapResult> boot;
  if (args.bootstrap > 0) {
    BootstrapOptions b;
    b.samples = args.bootstrap;
    b.seed = args.seed;
    b.coverage = args.coverage;
    b.threshold_proportion = args.threshold;
    auto r = bootstrap_psychometric(*data, o, *fit, b);
    if (!r) return report_error(r.error().with_context(args.data));
    boot = *r;
  }
  // The goodness-of-fit test's simulated data sets are the bootstrap's (same
  // seed, same replicas), so with --gof equal to --bootstrap it costs nothing.
  std::optional<GoodnessOfFit> gof;
  if (args.gof > 0 && boot && args.gof == args.bootstrap) {
    gof = boot->goodness_of_fit;
  } else if (args.gof > 0) {
    auto g = goodness_of_fit(*data, o, *fit, args.gof, args.seed);
    if (!g) return report_error(g.error().with_context(args.data));
    gof = *g;
  }
  auto interp = interpolated_threshold(*data, args.threshold);
  if (!args.plot.empty()) {
    PsychometricPlot plot;
    plot.title = fmt::format("{} fit to {}", to_string(o.model), fs::path(args.data).filename().string());
    plot.criterion = args.threshold;
    PsychometricCurve c;
    c.label = "data";
    c.data = *data;
    c.fit = *fit;
    c.threshold = *threshold;
    if (boot) c.threshold_ci = std::isfinite(boot->threshold.bca.lower) ? boot->threshold.bca : boot->threshold.percentile;
    plot.curves.push_back(c);
    if (Status s = write_psychometric_svg(args.plot, plot); !s) return report_error(s.error());
  }

  if (args.json) {
    json j = {{"data", args.data},
              {"model", to_string(o.model)},
              {"alpha", fit->params.alpha},
              {"beta", fit->params.beta},
              {"gamma", fit->params.gamma},
              {"lambda", fit->params.lambda},
              {"lapse_free", o.lapse_free},
              {"log_likelihood", fit->log_likelihood},
              {"deviance", fit->deviance},
              {"threshold_proportion", args.threshold},
              {"threshold", *threshold},
              {"slope_at_threshold", slope},
              {"interpolated_threshold", interp ? json(*interp) : json(nullptr)},
              {"unique_maximum", unique.unique}};
    if (!unique.unique) {
      j["equally_likely_thresholds"] = {unique.threshold_min, unique.threshold_max};
      j["warnings"] = json::array({unique.message});
    }
    if (gof) j["goodness_of_fit"] = {{"deviance", gof->deviance}, {"p", gof->p_value}, {"simulations", gof->simulations}};
    if (boot) {
      auto est = [](const BootstrapEstimate& e) {
        return json{{"estimate", e.estimate},
                    {"se", e.standard_error},
                    {"percentile", {e.percentile.lower, e.percentile.upper}},
                    {"bca", {number_or_null(e.bca.lower), number_or_null(e.bca.upper)}}};
      };
      j["bootstrap"] = {{"samples", boot->samples},
                        {"failed", boot->failed_fits},
                        {"steep_refits", boot->steep_refits},
                        {"seed", args.seed},
                        {"coverage", boot->coverage},
                        {"threshold", est(boot->threshold)},
                        {"slope", est(boot->slope)},
                        {"alpha", est(boot->alpha)},
                        {"beta", est(boot->beta)},
                        {"lambda", est(boot->lambda)}};
    }
    if (!args.plot.empty()) j["plot"] = args.plot;
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("%s fit (ML) to %s: alpha %.6g  beta %.6g  gamma %.3g  lambda %.4g%s\n", to_string(o.model),
              args.data.c_str(), fit->params.alpha, fit->params.beta, fit->params.gamma, fit->params.lambda,
              o.lapse_free ? " (free)" : "");
  std::printf("log-likelihood %.4f  deviance %.4f", fit->log_likelihood, fit->deviance);
  if (gof) std::printf("  (goodness of fit p = %.3f, %d simulations)", gof->p_value, gof->simulations);
  std::printf("\nthreshold at %.3g: %.6g  slope there %.6g\n", args.threshold, *threshold, slope);
  if (boot) {
    std::printf("bootstrap (%d samples, seed %llu): %.0f%% CI percentile [%.6g, %.6g]  BCa [%.6g, %.6g]  SE %.4g\n",
                boot->samples, static_cast<unsigned long long>(args.seed), 100 * boot->coverage,
                boot->threshold.percentile.lower, boot->threshold.percentile.upper, boot->threshold.bca.lower,
                boot->threshold.bca.upper, boot->threshold.standard_error);
    if (boot->steep_refits > 0) {
      std::printf("  %d of %d refits are steeper than any start on the search grid (simulated responses that "
                  "separate perfectly)\n",
                  boot->steep_refits, boot->samples + boot->failed_fits);
    }
  }
  if (interp) {
    std::printf("linear-interpolation threshold: %.6g\n", *interp);
  } else {
    std::printf("linear-interpolation threshold: none (%s)\n", interp.error().message.c_str());
  }
  if (!args.plot.empty()) std::printf("plot: %s\n", args.plot.c_str());
  return 0;
}

// ---------------------------------------------------------------------------
// stats

// A wide table: one row per subject, one numeric column per condition, and
// perhaps a column of subject ids, which is not a condition.
struct WideTable {
  std::string subject_column;                // empty: none
  std::vector<std::string> conditions;
  std::vector<std::vector<double>> values;  // [row][condition], NaN where empty
};

// "Subject", "ID", "participant_id", "Subject ID" -> "subject", "id", ...
std::string normalised_header(const std::string& h) {
  std::string out;
  for (char c : h) {
    const auto u = static_cast<unsigned char>(c);
    out += (c == ' ' || c == '-' || c == '.') ? '_' : static_cast<char>(std::tolower(u));
  }
  return out;
}

bool looks_like_subject_id(const std::string& header) {
  static const std::set<std::string> names = {
      "subject",    "subjects",       "subject_id", "subjectid", "subj",  "subj_id", "sid",
      "participant", "participants",  "participant_id", "participantid", "pid", "id", "vp", "proband"};
  return names.count(normalised_header(header)) > 0;
}

Result<WideTable> read_wide(const std::string& path, bool allow_empty, const std::string& subject_column,
                            bool subjects_are_rows) {
  auto table = read_csv(path);
  if (!table) return table.error();
  WideTable w;
  std::optional<std::size_t> id_col;
  if (!subject_column.empty()) {
    for (std::size_t c = 0; c < table->header.size() && !id_col; ++c) {
      if (table->header[c] == subject_column) id_col = c;
    }
    for (std::size_t c = 0; c < table->header.size() && !id_col; ++c) {
      if (normalised_header(table->header[c]) == normalised_header(subject_column)) id_col = c;
    }
    if (!id_col) {
      auto missing = table->require_column(subject_column);
      return make_error(Errc::not_found, missing.error().message + " (--subject-column)");
    }
  } else {
    for (std::size_t c = 0; c < table->header.size(); ++c) {
      if (!looks_like_subject_id(table->header[c])) continue;
      if (id_col) {
        return make_error(Errc::invalid_argument,
                          fmt::format("{}: columns '{}' and '{}' both look like subject ids; say which one is with "
                                      "--subject-column NAME",
                                      table->source, printable(table->header[*id_col], 60),
                                      printable(table->header[c], 60)));
      }
      id_col = c;
    }
  }
  // Said every time, on stderr: which column is not a condition changes F and p.
  if (id_col) {
    w.subject_column = table->header[*id_col];
    std::fprintf(stderr, "%s: column '%s' holds the subject ids (not a condition)%s\n", table->source.c_str(),
                 printable(w.subject_column, 60).c_str(),
                 subject_column.empty() ? "; name another with --subject-column" : "");
  } else {
    std::fprintf(stderr,
                 "%s: no subject id column (subject, participant, id, participant_id, ...): every column is a "
                 "condition; if one holds ids, name it with --subject-column\n",
                 table->source.c_str());
  }
  std::vector<std::size_t> cols;
  for (std::size_t c = 0; c < table->header.size(); ++c) {
    if (id_col && c == *id_col) continue;
    w.conditions.push_back(table->header[c]);
    cols.push_back(c);
  }
  if (cols.size() < 2) {
    return make_error(Errc::invalid_argument,
                      fmt::format("{}: need two or more condition columns (besides the subject id column)",
                                  table->source));
  }
  std::map<std::string, int> seen_ids;
  for (std::size_t r = 0; r < table->rows.size(); ++r) {
    if (id_col && subjects_are_rows) {
      const std::string& id = table->rows[r][*id_col];
      const auto [it, fresh] = seen_ids.emplace(id, table->lines[r]);
      if (!fresh) {
        return make_error(Errc::invalid_argument,
                          fmt::format("{}:{}: subject '{}' appears again (first on line {}); each subject needs "
                                      "exactly one row",
                                      table->source, table->lines[r], printable(id, 60), it->second));
      }
    }
    std::vector<double> row;
    for (std::size_t c : cols) {
      if (allow_empty && table->rows[r][c].empty()) {
        row.push_back(std::nan(""));
        continue;
      }
      auto v = table->number(r, c);
      if (!v) {
        return make_error(Errc::parse_error,
                          v.error().message +
                              (allow_empty ? "" : "; every subject needs a value in every condition") +
                              (id_col ? "" : "; if this column holds subject ids, name it with --subject-column"));
      }
      row.push_back(*v);
    }
    w.values.push_back(row);
  }
  if (w.values.size() < 2) {
    return make_error(Errc::invalid_argument, fmt::format("{}: need at least two rows", table->source));
  }
  return w;
}

json rm_json(const RepeatedMeasuresAnova& a) {
  return {{"subjects", a.subjects},       {"conditions", a.conditions},
          {"ss_conditions", a.ss_conditions}, {"ss_subjects", a.ss_subjects},
          {"ss_error", a.ss_error},       {"df_conditions", a.df_conditions},
          {"df_error", a.df_error},       {"f", number_or_null(a.f)},
          {"p", number_or_null(a.p)},     {"gg_epsilon", a.gg_epsilon},
          {"gg_df_conditions", a.gg_df_conditions}, {"gg_df_error", a.gg_df_error},
          {"gg_p", number_or_null(a.gg_p)}, {"partial_eta_squared", number_or_null(a.partial_eta_squared)},
          {"testable", a.testable},       {"not_testable_reason", a.not_testable_reason}};
}

json subject_column_json(const WideTable& w) {
  return w.subject_column.empty() ? json(nullptr) : json(w.subject_column);
}

// A test that could not be computed (degenerate data) is a result, printed
// as such, but not a success a script may take a p-value from.
constexpr int kNotTestableExit = 1;

struct StatsArgs {
  std::string data;
  std::string correction = "holm";
  std::string subject_column;
  bool json = false;
};

int run_rm_anova(const StatsArgs& args) {
  auto w = read_wide(args.data, false, args.subject_column, true);
  if (!w) return report_error(w.error());
  auto a = repeated_measures_anova(w->values);
  if (!a) return report_error(a.error().with_context(args.data));
  if (args.json) {
    json j = rm_json(*a);
    j["condition_names"] = w->conditions;
    j["subject_column"] = subject_column_json(*w);
    std::printf("%s\n", j.dump(2).c_str());
    return a->testable ? 0 : kNotTestableExit;
  }
  std::printf("repeated-measures ANOVA, %d subjects x %d conditions\n", a->subjects, a->conditions);
  if (!a->testable) {
    std::printf("  not testable: %s\n", a->not_testable_reason.c_str());
    return kNotTestableExit;
  }
  std::printf("  F(%g, %g) = %.4f, p = %.6g   partial eta^2 = %.3f\n", a->df_conditions, a->df_error, a->f, a->p,
              a->partial_eta_squared);
  std::printf("  Greenhouse-Geisser epsilon = %.4f: F(%.3f, %.3f), p = %.6g\n", a->gg_epsilon, a->gg_df_conditions,
              a->gg_df_error, a->gg_p);
  return 0;
}

int run_anova(const StatsArgs& args) {
  auto w = read_wide(args.data, true, args.subject_column, false);
  if (!w) return report_error(w.error());
  std::vector<std::vector<double>> groups(w->conditions.size());
  for (const auto& row : w->values) {
    for (std::size_t c = 0; c < row.size(); ++c) {
      if (std::isfinite(row[c])) groups[c].push_back(row[c]);
    }
  }
  auto a = one_way_anova(groups);
  if (!a) return report_error(a.error().with_context(args.data));
  if (args.json) {
    json j = {{"groups", w->conditions}, {"ss_between", a->ss_between}, {"ss_within", a->ss_within},
              {"df_between", a->df_between}, {"df_within", a->df_within}, {"f", number_or_null(a->f)},
              {"p", number_or_null(a->p)}, {"eta_squared", number_or_null(a->eta_squared)},
              {"testable", a->testable}, {"not_testable_reason", a->not_testable_reason},
              {"subject_column", subject_column_json(*w)}};
    std::printf("%s\n", j.dump(2).c_str());
    return a->testable ? 0 : kNotTestableExit;
  }
  if (!a->testable) {
    std::printf("one-way ANOVA, %zu groups: not testable: %s\n", groups.size(), a->not_testable_reason.c_str());
    return kNotTestableExit;
  }
  std::printf("one-way ANOVA, %zu groups: F(%g, %g) = %.4f, p = %.6g, eta^2 = %.3f\n", groups.size(), a->df_between,
              a->df_within, a->f, a->p, a->eta_squared);
  return 0;
}

int run_paired_t(const StatsArgs& args) {
  auto w = read_wide(args.data, false, args.subject_column, true);
  if (!w) return report_error(w.error());
  auto method = parse_p_adjust(args.correction);
  if (!method) return report_error(method.error());
  struct Pair {
    std::size_t i, j;
    PairedT t;
  };
  std::vector<Pair> pairs;
  std::vector<double> ps;
  for (std::size_t i = 0; i < w->conditions.size(); ++i) {
    for (std::size_t j = i + 1; j < w->conditions.size(); ++j) {
      std::vector<double> a, b;
      for (const auto& row : w->values) {
        a.push_back(row[i]);
        b.push_back(row[j]);
      }
      auto t = paired_t_test(a, b);
      if (!t) return report_error(t.error().with_context(args.data));
      pairs.push_back({i, j, *t});
      ps.push_back(t->p);
    }
  }
  const std::vector<double> adjusted = adjust_p(ps, *method);
  const bool all_testable =
      std::all_of(pairs.begin(), pairs.end(), [](const Pair& p) { return p.t.testable; });
  if (args.json) {
    json arr = json::array();
    for (std::size_t k = 0; k < pairs.size(); ++k) {
      const PairedT& t = pairs[k].t;
      arr.push_back({{"a", w->conditions[pairs[k].i]},
                     {"b", w->conditions[pairs[k].j]},
                     {"n", t.n},
                     {"mean_difference", t.mean_difference},
                     {"sd_difference", t.sd_difference},
                     {"t", number_or_null(t.t)},
                     {"df", t.df},
                     {"p", number_or_null(t.p)},
                     {"p_adjusted", number_or_null(adjusted[k])},
                     {"cohen_dz", number_or_null(t.cohen_dz)},
                     {"ci95", {t.ci_lower, t.ci_upper}},
                     {"testable", t.testable},
                     {"not_testable_reason", t.not_testable_reason}});
    }
    std::printf("%s\n", json({{"correction", to_string(*method)},
                               {"subject_column", subject_column_json(*w)},
                               {"comparisons", arr}})
                             .dump(2)
                             .c_str());
    return all_testable ? 0 : kNotTestableExit;
  }
  std::printf("paired t-tests (%s correction over %zu comparisons)\n", to_string(*method), pairs.size());
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    const PairedT& t = pairs[k].t;
    if (!t.testable) {
      std::printf("  %s - %s: mean %.4g, not testable: %s\n", w->conditions[pairs[k].i].c_str(),
                  w->conditions[pairs[k].j].c_str(), t.mean_difference, t.not_testable_reason.c_str());
      continue;
    }
    std::printf("  %s - %s: mean %.4g [%.4g, %.4g], t(%g) = %.4f, p = %.6g, adjusted p = %.6g, dz = %.3f\n",
                w->conditions[pairs[k].i].c_str(), w->conditions[pairs[k].j].c_str(), t.mean_difference, t.ci_lower,
                t.ci_upper, t.df, t.t, t.p, adjusted[k], t.cohen_dz);
  }
  return all_testable ? 0 : kNotTestableExit;
}

// ---------------------------------------------------------------------------
// study analyze / check

struct AnalyzeArgs {
  std::string dir;
  std::string out;
  std::string model;
  std::optional<double> guess, lapse, lapse_max, threshold;
  int bootstrap = 999;
  std::uint64_t seed = 1;
  std::string method = "fit";
  std::string stimulus, response;
  std::optional<std::string> conditions;
  bool allow_incomplete = false;
  bool json = false;
};

std::string fmt_or_dash(double v) { return std::isfinite(v) ? fmt::format("{:.4g}", v) : std::string("-"); }

// Timed-task studies (sidecar kind "completion-time", e.g. peg-in-hole):
// normalised times, RM-ANOVA with Greenhouse-Geisser, post-hoc tests, plot.
bool is_completion_time_study(const fs::path& dir) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    if (e.path().extension() != ".json") continue;
    auto kind = sidecar_kind(e.path());
    if (kind && *kind == "completion-time") return true;
  }
  return false;
}

int run_completion_time_analyze(const AnalyzeArgs& args) {
  CompletionTimeOptions o;
  o.allow_incomplete = args.allow_incomplete;
  auto a = analyze_completion_time_study(args.dir, o);
  if (!a) return report_error(a.error());
  const fs::path out = args.out.empty() ? fs::path(args.dir) / "report" : fs::path(args.out);
  auto files = write_completion_time_report(*a, out, "Normalised completion time per setting");
  if (!files) return report_error(files.error());
  if (args.json) {
    std::printf("%s\n", completion_time_json(*a).c_str());
  } else {
    std::printf("%s\nReport in %s: anova.txt, summary.json, normalised_times.csv, normalised_time.svg\n",
                completion_time_text(*a).c_str(), out.c_str());
  }
  return 0;
}

int run_analyze(const AnalyzeArgs& args) {
  if (is_completion_time_study(args.dir)) return run_completion_time_analyze(args);
  StudyAnalysisOptions o;
  if (!args.model.empty()) {
    auto m = parse_psychometric_model(args.model);
    if (!m) return report_error(m.error());
    o.model = *m;
  }
  o.guess = args.guess;
  o.lapse = args.lapse;
  o.lapse_max = args.lapse_max;
  o.threshold = args.threshold;
  o.bootstrap = args.bootstrap;
  o.seed = args.seed;
  o.allow_incomplete = args.allow_incomplete;
  if (args.method == "fit") {
    o.method = ThresholdMethod::fit;
  } else if (args.method == "interpolate") {
    o.method = ThresholdMethod::interpolate;
  } else {
    return report_error(make_error(Errc::invalid_argument, "--method must be fit or interpolate"));
  }
  o.stimulus_column = args.stimulus;
  o.response_column = args.response;
  if (args.conditions) {
    o.conditions_given = true;
    std::string rest = *args.conditions;
    while (!rest.empty()) {
      const auto comma = rest.find(',');
      const std::string name = rest.substr(0, comma);
      if (!name.empty()) o.condition_columns.push_back(name);
      rest = comma == std::string::npos ? "" : rest.substr(comma + 1);
    }
  }
  auto a = analyze_study(args.dir, o);
  if (!a) return report_error(a.error());
  const fs::path out = args.out.empty() ? fs::path(args.dir) / "report" : fs::path(args.out);
  auto files = write_study_report(*a, out);
  if (!files) return report_error(files.error());
  if (args.json) {
    std::printf("%s\n", study_analysis_json(*a).c_str());
    return 0;
  }
  std::printf("study: %zu files, %zu participants, %zu conditions; %s fit, threshold at %.3g%s\n", a->files.size(),
              a->participants.size(), a->conditions.size(), to_string(a->fit_options.model), a->criterion,
              a->bootstrap > 0 ? fmt::format(", {} bootstrap samples (seed {})", a->bootstrap, a->seed).c_str() : "");
  const std::string unit = a->stimulus_unit.empty() ? "" : " " + a->stimulus_unit;
  std::printf("\n%-12s %-28s %7s %12s %22s %12s\n", "participant", "condition", "trials", "threshold",
              fmt::format("{:.0f}% CI (BCa)", 100 * a->coverage).c_str(), "interpolated");
  for (const auto* list : {&a->cells, &a->pooled}) {
    for (const CellAnalysis& c : *list) {
      int n = 0;
      for (const StimulusLevel& s : c.data) n += s.trials;
      const auto ci = c.bca_ci ? c.bca_ci : c.percentile_ci;
      std::printf("%-12s %-28s %7d %12s %22s %12s\n", c.participant.c_str(), c.condition.c_str(), n,
                  fmt_or_dash(c.threshold).c_str(),
                  ci ? fmt::format("[{:.4g}, {:.4g}]", ci->lower, ci->upper).c_str() : "-",
                  fmt_or_dash(c.interpolated_threshold).c_str());
    }
  }
  std::printf("(thresholds in%s)\n", unit.empty() ? " stimulus units" : unit.c_str());
  if (a->threshold_anova) {
    const RepeatedMeasuresAnova& r = *a->threshold_anova;
    if (r.testable) {
      std::printf("\nrepeated-measures ANOVA on %s thresholds (%d participants): F(%g, %g) = %.3f, p = %.4g; "
                  "GG eps = %.3f, F(%.2f, %.2f), p = %.4g\n",
                  args.method.c_str(), r.subjects, r.df_conditions, r.df_error, r.f, r.p, r.gg_epsilon,
                  r.gg_df_conditions, r.gg_df_error, r.gg_p);
    } else {
      std::printf("\nrepeated-measures ANOVA on %s thresholds (%d participants): not testable: %s\n",
                  args.method.c_str(), r.subjects, r.not_testable_reason.c_str());
    }
    for (const ConditionComparison& c : a->comparisons) {
      if (!c.test.testable) {
        std::printf("  %s vs %s: not testable: %s\n", c.a.c_str(), c.b.c_str(), c.test.not_testable_reason.c_str());
        continue;
      }
      std::printf("  %s vs %s: t(%g) = %.3f, p = %.4g, Holm p = %.4g\n", c.a.c_str(), c.b.c_str(), c.test.df,
                  c.test.t, c.test.p, c.p_holm);
    }
  }
  if (!a->level_anovas.empty()) {
    std::printf("\nper level, proportion %s across conditions:\n", a->response_column.c_str());
    for (const LevelAnova& l : a->level_anovas) {
      std::printf("  %g%s:", l.level, unit.c_str());
      if (l.one_way && l.one_way->testable) {
        std::printf("  one-way F(%g, %g) = %.3f, p = %.4g", l.one_way->df_between, l.one_way->df_within,
                    l.one_way->f, l.one_way->p);
      } else if (l.one_way) {
        std::printf("  one-way: not testable (%s)", l.one_way->not_testable_reason.c_str());
      }
      if (l.repeated && l.repeated->testable) {
        std::printf(";  RM F(%g, %g) = %.3f, GG p = %.4g", l.repeated->df_conditions, l.repeated->df_error,
                    l.repeated->f, l.repeated->gg_p);
      } else if (l.repeated) {
        std::printf(";  RM: not testable (%s)", l.repeated->not_testable_reason.c_str());
      }
      std::printf("\n");
    }
  }
  for (const std::string& n : a->notes) std::printf("note: %s\n", n.c_str());
  std::printf("\nreport: %s (summary.json, thresholds.csv, %zu plots)\n", out.string().c_str(), files->size() - 2);
  return 0;
}

int run_check(const std::string& path, int participant_index) {
  auto d = StudyDesign::load_file(path);
  if (!d) return report_error(d.error());
  const auto cells = condition_cells(*d);
  std::printf("%s: study '%s', seed %llu, procedure %s\n", path.c_str(), d->name.c_str(),
              static_cast<unsigned long long>(d->seed), to_string(d->procedure.kind));
  std::printf("  %zu condition cells:", cells.size());
  for (const auto& c : cells) std::printf(" [%s]", c.label.c_str());
  std::printf("\n  columns: stimulus '%s'%s, response '%s'\n", d->stimulus_column.c_str(),
              d->stimulus_unit.empty() ? "" : (" (" + d->stimulus_unit + ")").c_str(), d->response_column.c_str());
  if (!d->block_factor.empty()) {
    std::printf("  blocks by '%s', counterbalance %s; participant %d gets:", d->block_factor.c_str(),
                to_string(d->counterbalance), participant_index);
    for (int b : block_order(*d, participant_index)) std::printf(" %s", d->block_groups[static_cast<std::size_t>(b)].label.c_str());
    std::printf("\n");
  }
  std::printf("  planned trial slots per session: %zu\n",
              plan_trials(*d, participant_index, mix_seed(mix_seed(d->seed, static_cast<std::uint64_t>(participant_index)), 1)).size());
  return 0;
}

}  // namespace

constexpr const char* kSubjectColumnHelp =
    "the column of subject ids, which is not a condition (default: a column named subject, participant, id, "
    "participant_id, ..., in any case)";

void add_study_commands(CLI::App& app, int& exit_code) {
  // psychometric fit
  auto* psy = add_command(app, "psychometric");
  auto fit_args = std::make_shared<FitArgs>();
  auto* fit = psy->add_subcommand("fit", "Maximum-likelihood fit of a psychometric function to level,correct,trials data");
  fit->add_option("--data", fit_args->data, "CSV with columns level, correct, trials")->required();
  fit->add_option("--model", fit_args->model, "weibull, logistic, gumbel or normal")->capture_default_str();
  fit->add_option("--guess", fit_args->guess, "guess rate gamma (0.5 for 2AFC)")->capture_default_str();
  auto* lapse = fit->add_option("--lapse", fit_args->lapse, "fixed lapse rate lambda (default 0)");
  auto* lapse_max = fit->add_option("--lapse-max", fit_args->lapse_max, "free lapse rate in [0, VALUE], e.g. 0.06");
  lapse->excludes(lapse_max);
  fit->add_option("--threshold", fit_args->threshold, "proportion correct that defines the threshold")
      ->capture_default_str();
  fit->add_option("--bootstrap", fit_args->bootstrap,
                  "parametric bootstrap samples for CIs (e.g. 1999; 0 = none); uses every core")
      ->capture_default_str();
  fit->add_option("--seed", fit_args->seed, "seed of the bootstrap and goodness-of-fit simulations")
      ->capture_default_str();
  fit->add_option("--gof", fit_args->gof,
                  "Monte Carlo goodness-of-fit simulations (e.g. 1999; 0 = none); equal to --bootstrap, it reuses the "
                  "bootstrap's")
      ->capture_default_str();
  fit->add_option("--coverage", fit_args->coverage, "confidence level of the intervals")->capture_default_str();
  fit->add_option("--plot", fit_args->plot, "write an SVG plot of data, fit, threshold and CI");
  fit->add_flag("--json", fit_args->json, "print the result as JSON");
  fit->callback([fit_args, &exit_code] { exit_code = run_fit(*fit_args); });

  // stats
  auto* stats = add_command(app, "stats");
  auto stats_args = std::make_shared<StatsArgs>();
  auto* rm = stats->add_subcommand("rm-anova", "Repeated-measures ANOVA with the Greenhouse-Geisser correction");
  rm->add_option("--data", stats_args->data, "CSV: one row per subject, one column per condition")->required();
  rm->add_option("--subject-column", stats_args->subject_column, kSubjectColumnHelp);
  rm->add_flag("--json", stats_args->json, "print the result as JSON");
  rm->callback([stats_args, &exit_code] { exit_code = run_rm_anova(*stats_args); });
  auto* ow = stats->add_subcommand("anova", "One-way ANOVA, one column per group (empty cells allowed)");
  ow->add_option("--data", stats_args->data, "CSV: one column per group")->required();
  ow->add_option("--subject-column", stats_args->subject_column, kSubjectColumnHelp);
  ow->add_flag("--json", stats_args->json, "print the result as JSON");
  ow->callback([stats_args, &exit_code] { exit_code = run_anova(*stats_args); });
  auto* pt = stats->add_subcommand("paired-t", "Paired t-tests between every pair of conditions, corrected");
  pt->add_option("--data", stats_args->data, "CSV: one row per subject, one column per condition")->required();
  pt->add_option("--correction", stats_args->correction, "holm, bonferroni or none")->capture_default_str();
  pt->add_option("--subject-column", stats_args->subject_column, kSubjectColumnHelp);
  pt->add_flag("--json", stats_args->json, "print the result as JSON");
  pt->callback([stats_args, &exit_code] { exit_code = run_paired_t(*stats_args); });

  // study
  auto* study = add_command(app, "study");
  auto an = std::make_shared<AnalyzeArgs>();
  auto* analyze = study->add_subcommand("analyze", "Fits, thresholds with CIs, statistics and plots for a folder of "
                                                   "session CSVs");
  analyze->add_option("dir", an->dir, "folder with the session CSVs and their .json sidecars")->required();
  analyze->add_option("--out", an->out, "report folder (default DIR/report)");
  analyze->add_option("--model", an->model, "override the design's model: weibull, logistic, gumbel, normal");
  analyze->add_option("--guess", an->guess, "override the guess rate");
  auto* al = analyze->add_option("--lapse", an->lapse, "fixed lapse rate");
  auto* alm = analyze->add_option("--lapse-max", an->lapse_max, "free lapse rate in [0, VALUE]");
  al->excludes(alm);
  analyze->add_option("--threshold", an->threshold, "proportion correct that defines the threshold");
  analyze->add_option("--bootstrap", an->bootstrap, "bootstrap samples per fit (0 = no CIs)")->capture_default_str();
  analyze->add_option("--seed", an->seed, "bootstrap seed")->capture_default_str();
  analyze->add_option("--method", an->method, "threshold the statistics use: fit or interpolate")
      ->capture_default_str();
  analyze->add_option("--stimulus", an->stimulus, "stimulus column (default: from the sidecar)");
  analyze->add_option("--response", an->response, "0/1 response column (default: from the sidecar), e.g. "
                                                  "chose_haptic_sphere");
  analyze->add_option("--conditions", an->conditions, "comma-separated condition columns (default: the factors)");
  analyze->add_flag("--allow-incomplete", an->allow_incomplete,
                    "analyse sessions with trials missing from their plan (unfinished or damaged) instead of "
                    "refusing them");
  analyze->add_flag("--json", an->json, "print the analysis as JSON");
  analyze->callback([an, &exit_code] { exit_code = run_analyze(*an); });

  auto check_path = std::make_shared<std::string>();
  auto check_index = std::make_shared<int>(0);
  auto* check = study->add_subcommand("check", "Validate a study design file and show its plan");
  check->add_option("design", *check_path, "design TOML (config/studies/*.toml)")->required();
  check->add_option("--participant-index", *check_index, "whose block order to show")->capture_default_str();
  check->callback([check_path, check_index, &exit_code] { exit_code = run_check(*check_path, *check_index); });
}

}  // namespace proprio::cli
