#include "proprio/perception_threshold/report.hpp"

#include <fmt/format.h>

#include <cmath>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>

#include "proprio/core/file_io.hpp"
#include "proprio/study/csv.hpp"
#include "proprio/study/plot.hpp"

namespace proprio::perception {
namespace {

namespace fs = std::filesystem;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string condition_of(const std::string& label) {
  const auto eq = label.find('=');
  return eq == std::string::npos ? label : label.substr(eq + 1);
}

double interpolated(const std::vector<study::StimulusLevel>& data, double proportion) {
  auto t = study::interpolated_threshold(data, proportion);
  return t ? *t : kNaN;
}

// The haptic sphere is chosen less as the offset grows: the 50% point of a
// falling curve is the 50% point of its complement, which rises.
double falling_crossing(std::vector<study::StimulusLevel> data, double proportion) {
  for (auto& l : data) l.correct = l.trials - l.correct;
  return interpolated(data, 1.0 - proportion);
}

std::string cm(double v) { return std::isfinite(v) ? fmt::format("{:.2f} cm", v) : std::string("n/a"); }

// (participant, condition) -> offset -> (chose haptic, trials)
using ChoiceTable = std::map<std::pair<std::string, std::string>, std::map<double, std::pair<int, int>>>;

Status read_choices(const std::vector<fs::path>& files, const std::string& stimulus_column, ChoiceTable& out) {
  for (const fs::path& f : files) {
    auto t = study::read_csv(f);
    if (!t) return t.error();
    const auto participant = t->require_column("participant");
    const auto haptics = t->require_column("haptics");
    const auto stimulus = t->require_column(stimulus_column);
    const auto chose = t->require_column("chose_haptic_sphere");
    for (const auto* c : {&participant, &haptics, &stimulus, &chose}) {
      if (!*c) return c->error();
    }
    for (std::size_t r = 0; r < t->rows.size(); ++r) {
      const std::string& h = t->rows[r][*haptics];
      if (h == "none") continue;
      auto x = t->number(r, *stimulus);
      auto c = t->integer(r, *chose);
      if (!x) return x.error();
      if (!c || (*c != 0 && *c != 1)) {
        return make_error(Errc::invalid_argument, fmt::format("{}:{}: chose_haptic_sphere must be 0 or 1 in haptic "
                                                              "conditions", f.string(), t->lines[r]));
      }
      for (const std::string& p : {t->rows[r][*participant], std::string("all")}) {
        auto& cell = out[{p, h}][*x];
        cell.first += static_cast<int>(*c);
        cell.second += 1;
      }
    }
  }
  return {};
}

std::vector<study::StimulusLevel> levels_of(const std::map<double, std::pair<int, int>>& m) {
  std::vector<study::StimulusLevel> v;
  for (const auto& [x, c] : m) v.push_back({x, c.first, c.second});
  return v;
}

}  // namespace

Result<PerceptionReport> analyze_perception_study(const fs::path& dir, const PerceptionReportOptions& options) {
  study::StudyAnalysisOptions ao;
  ao.bootstrap = options.bootstrap;
  ao.seed = options.seed;
  // Weibull cannot fit the haptic conditions (their curves need not start at
  // 50%), so the between-condition statistics use interpolated thresholds, as
  // the thesis's haptic thresholds are.
  ao.method = study::ThresholdMethod::interpolate;
  auto a = study::analyze_study(dir, ao);
  if (!a) return a.error();
  PerceptionReport r;
  r.analysis = std::move(*a);
  const auto& an = r.analysis;
  if (an.condition_columns != std::vector<std::string>{"haptics"}) {
    return make_error(Errc::invalid_argument, fmt::format("{}: not a perception-threshold study (its condition "
                                                          "column must be 'haptics')", dir.string()));
  }
  r.threshold_none_cm = r.threshold_true_sphere_cm = r.threshold_false_sphere_cm = kNaN;
  for (const auto& c : an.pooled) {
    const std::string h = condition_of(c.condition);
    if (h == "none") {
      r.threshold_none_cm = c.threshold;
      // Percentile, not BCa: with a few hundred trials BCa's intervals cover
      // the simulated truth too rarely (docs/perception-threshold.md).
      r.threshold_none_ci = c.percentile_ci;
    } else if (h == "true_sphere") {
      r.threshold_true_sphere_cm = c.interpolated_threshold;
    } else if (h == "false_sphere") {
      r.threshold_false_sphere_cm = c.interpolated_threshold;
    }
  }

  ChoiceTable choices;
  if (auto s = read_choices(an.files, an.stimulus_column, choices); !s) return s.error();
  r.max_allowable_error_cm = kNaN;
  for (const std::string h : {"true_sphere", "false_sphere"}) {
    auto it = choices.find({"all", h});
    if (it == choices.end()) continue;
    r.chose_haptic.push_back({h, levels_of(it->second)});
    if (h == "false_sphere") r.max_allowable_error_cm = falling_crossing(r.chose_haptic.back().data, 0.5);
  }
  for (const std::string& p : an.participants) {
    auto it = choices.find({p, "false_sphere"});
    if (it != choices.end()) r.max_allowable_error_by_participant.push_back({p, falling_crossing(levels_of(it->second), 0.5)});
  }

  // The summary a paper's results section needs.
  std::string& md = r.summary_markdown;
  md += fmt::format("# Perception threshold: {} participants, {} files\n\n", an.participants.size(), an.files.size());
  md += "Detection threshold of the visual-proprioceptive conflict: the offset at which the true sphere is picked 75% "
        "of the time (thesis: 5.11 cm without haptics, 3.28 cm with haptics on the true sphere, 6.05 cm on the false "
        "one).\n\n| condition | threshold | method |\n|---|---|---|\n";
  md += fmt::format("| none | {} (95% percentile bootstrap CI {}) | Weibull fit, pooled |\n", cm(r.threshold_none_cm),
                    r.threshold_none_ci ? fmt::format("{:.2f} to {:.2f}", r.threshold_none_ci->lower,
                                                      r.threshold_none_ci->upper)
                                        : std::string("n/a"));
  md += fmt::format("| haptics on the true sphere | {} | linear interpolation, pooled |\n",
                    cm(r.threshold_true_sphere_cm));
  md += fmt::format("| haptics on the false sphere | {} | linear interpolation, pooled |\n\n",
                    cm(r.threshold_false_sphere_cm));
  md += fmt::format("Maximum allowable tracking error (haptics on the false sphere, haptic sphere chosen 50% of the "
                    "time; thesis: 3.50 cm): **{}**\n\n", cm(r.max_allowable_error_cm));
  md += "Per participant (interpolated thresholds, cm):\n\n| participant | none (Weibull) | none | true sphere | false "
        "sphere | max allowable |\n|---|---|---|---|---|---|\n";
  for (const std::string& p : an.participants) {
    std::map<std::string, const study::CellAnalysis*> cells;
    for (const auto& c : an.cells) {
      if (c.participant == p) cells[condition_of(c.condition)] = &c;
    }
    auto get = [&](const char* h, bool fit) {
      auto it = cells.find(h);
      if (it == cells.end()) return std::string("-");
      const double v = fit ? it->second->threshold : it->second->interpolated_threshold;
      return std::isfinite(v) ? fmt::format("{:.2f}", v) : std::string("n/a");
    };
    double mae = kNaN;
    for (const auto& [id, v] : r.max_allowable_error_by_participant) {
      if (id == p) mae = v;
    }
    md += fmt::format("| {} | {} | {} | {} | {} | {} |\n", p, get("none", true), get("none", false),
                      get("true_sphere", false), get("false_sphere", false),
                      std::isfinite(mae) ? fmt::format("{:.2f}", mae) : "n/a");
  }
  if (an.threshold_anova) {
    const auto& t = *an.threshold_anova;
    if (!t.testable) {
      md += fmt::format("\nRepeated-measures ANOVA on the interpolated thresholds ({} participants with all three "
                        "conditions): not testable: {}\n",
                        t.subjects, t.not_testable_reason);
    } else {
    md += fmt::format("\nRepeated-measures ANOVA on the interpolated thresholds ({} participants with all three "
                      "conditions): F({:.0f}, {:.0f}) = {:.2f}, p = {:.4f}; Greenhouse-Geisser epsilon = {:.3f}, "
                      "p = {:.4f}; partial eta^2 = {:.3f}\n",
                      t.subjects, t.df_conditions, t.df_error, t.f, t.p, t.gg_epsilon, t.gg_p, t.partial_eta_squared);
    }
    for (const auto& c : an.comparisons) {
      if (!c.test.testable) {
        md += fmt::format("- {} vs {}: not testable: {}\n", c.a, c.b, c.test.not_testable_reason);
        continue;
      }
      md += fmt::format("- {} vs {}: mean difference {:.2f} cm, t({:.0f}) = {:.2f}, p = {:.4f} (Holm {:.4f})\n", c.a,
                        c.b, c.test.mean_difference, c.test.df, c.test.t, c.test.p, c.p_holm);
    }
  }
  md += "\nOne-way ANOVA across haptic conditions on the proportion correct at each offset (the thesis's test), and "
        "the repeated-measures version:\n\n| offset | one-way F | p | repeated-measures F | p (GG) |\n|---|---|---|---|---|\n";
  for (const auto& l : an.level_anovas) {
    const bool ow = l.one_way && l.one_way->testable, rm = l.repeated && l.repeated->testable;
    md += fmt::format("| {:g} | {} | {} | {} | {} |\n", l.level,
                      ow ? fmt::format("F({:.0f}, {:.0f}) = {:.2f}", l.one_way->df_between, l.one_way->df_within,
                                       l.one_way->f)
                         : l.one_way ? "not testable" : "-",
                      ow ? fmt::format("{:.4f}", l.one_way->p) : "-",
                      rm ? fmt::format("F({:.0f}, {:.0f}) = {:.2f}", l.repeated->df_conditions, l.repeated->df_error,
                                       l.repeated->f)
                         : l.repeated ? "not testable" : "-",
                      rm ? fmt::format("{:.4f}", l.repeated->gg_p) : "-");
  }
  for (const auto& n : an.notes) md += "\nNote: " + n;
  return r;
}

Result<std::vector<fs::path>> write_perception_report(const PerceptionReport& r, const fs::path& out_dir) {
  auto written = study::write_study_report(r.analysis, out_dir);
  if (!written) return written.error();
  study::PsychometricPlot plot;
  plot.title = "choosing the sphere with haptic feedback (thesis Fig. 2.9)";
  plot.x_label = fmt::format("{} ({})", r.analysis.stimulus_column, r.analysis.stimulus_unit);
  plot.y_label = "proportion choosing the haptic sphere";
  plot.criterion = 0.5;
  for (const auto& c : r.chose_haptic) {
    study::PsychometricCurve curve;
    curve.label = "haptics on the " + std::string(c.condition == "true_sphere" ? "true" : "false") + " sphere";
    curve.data = c.data;
    if (c.condition == "false_sphere" && std::isfinite(r.max_allowable_error_cm)) {
      curve.threshold = r.max_allowable_error_cm;
    }
    plot.curves.push_back(curve);
  }
  const fs::path choice = out_dir / "chose_haptic.svg";
  if (auto s = study::write_psychometric_svg(choice, plot); !s) return s.error();
  written->push_back(choice);

  const fs::path md = out_dir / "summary.md";
  if (Status s = write_file_atomic(md, r.summary_markdown, "summary"); !s) return s.error();
  written->push_back(md);

  nlohmann::json j;
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  j["threshold_none_cm"] = num(r.threshold_none_cm);
  if (r.threshold_none_ci) j["threshold_none_ci_cm"] = {r.threshold_none_ci->lower, r.threshold_none_ci->upper};
  j["threshold_true_sphere_cm"] = num(r.threshold_true_sphere_cm);
  j["threshold_false_sphere_cm"] = num(r.threshold_false_sphere_cm);
  j["max_allowable_error_cm"] = num(r.max_allowable_error_cm);
  for (const auto& [p, v] : r.max_allowable_error_by_participant) j["max_allowable_error_by_participant_cm"][p] = num(v);
  const fs::path thesis = out_dir / "thesis_summary.json";
  if (Status s = write_file_atomic(thesis, j.dump(2) + "\n", "thesis summary"); !s) return s.error();
  written->push_back(thesis);
  return written;
}

}  // namespace proprio::perception
