#include "proprio/study/analysis.hpp"

#include <algorithm>
#include <cmath>
#include <fmt/format.h>
#include <sstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "proprio/core/file_io.hpp"
#include "proprio/core/random.hpp"
#include "proprio/study/csv.hpp"
#include "proprio/study/plot.hpp"
#include "proprio/study/session.hpp"

namespace proprio::study {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

struct Trials {
  std::vector<double> stimulus;
  std::vector<int> correct;
};

struct SidecarInfo {
  std::string stimulus, unit, response;
  std::vector<std::string> factors;
  std::vector<std::vector<std::string>> factor_levels;
  json analysis;
};

Result<SidecarInfo> read_sidecar(const fs::path& path) {
  auto text = read_input_file(path, "session sidecar");
  if (!text) return text.error();
  json j = json::parse(*text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) {
    return make_error(Errc::parse_error, fmt::format("{} is not valid JSON; restore it from a backup or delete it "
                                                     "and pass --stimulus/--response/--conditions",
                                                     path.string()));
  }
  if (j.value("format", "") != "proprio-study-session") {
    return make_error(Errc::parse_error, fmt::format("{} is not a proprio study sidecar (format \"{}\")",
                                                     path.string(), j.value("format", "")));
  }
  SidecarInfo s;
  try {
    s.stimulus = j.at("columns").at("stimulus").get<std::string>();
    s.unit = j.at("columns").value("stimulus_unit", "");
    s.response = j.at("columns").at("response").get<std::string>();
    for (const json& f : j.at("factors")) {
      s.factors.push_back(f.at("name").get<std::string>());
      s.factor_levels.push_back(f.at("levels").get<std::vector<std::string>>());
    }
    s.analysis = j.value("analysis", json::object());
  } catch (const json::exception& e) {
    return make_error(Errc::parse_error, fmt::format("{}: missing or malformed field: {}", path.string(), e.what()));
  }
  return s;
}

std::string condition_label(const std::vector<std::string>& names, const std::vector<std::string>& values) {
  if (names.empty()) return "all";
  std::string label;
  for (std::size_t i = 0; i < names.size(); ++i) label += (i ? "," : "") + names[i] + "=" + values[i];
  return label;
}

void analyse_cell(CellAnalysis& cell, const FitOptions& fit_options, double criterion, int bootstrap,
                  std::uint64_t seed, double coverage) {
  cell.threshold = kNaN;
  cell.slope = kNaN;
  cell.interpolated_threshold = kNaN;
  auto interp = interpolated_threshold(cell.data, criterion);
  if (interp) {
    cell.interpolated_threshold = *interp;
  } else {
    cell.interpolation_error = interp.error().message;
  }
  auto fit = fit_psychometric(cell.data, fit_options);
  if (!fit) {
    cell.fit_error = fit.error().message;
    return;
  }
  cell.fit = *fit;
  auto t = threshold_at(fit->model, fit->params, criterion);
  if (!t) {
    cell.fit_error = t.error().message;
    return;
  }
  cell.threshold = *t;
  cell.slope = slope_at(fit->model, fit->params, *t);
  if (bootstrap > 0) {
    BootstrapOptions b;
    b.samples = bootstrap;
    b.seed = seed;
    b.coverage = coverage;
    b.threshold_proportion = criterion;
    auto boot = bootstrap_psychometric(cell.data, fit_options, *fit, b);
    if (boot) {
      cell.percentile_ci = boot->threshold.percentile;
      if (std::isfinite(boot->threshold.bca.lower)) cell.bca_ci = boot->threshold.bca;
    } else {
      cell.fit_error = "bootstrap: " + boot.error().message;
    }
  }
}

json number_or_null(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

json cell_json(const CellAnalysis& c) {
  json j = {{"participant", c.participant}, {"condition", c.condition}};
  json levels = json::array();
  int trials = 0;
  for (const StimulusLevel& s : c.data) {
    levels.push_back({{"level", s.level}, {"correct", s.correct}, {"trials", s.trials}});
    trials += s.trials;
  }
  j["trials"] = trials;
  j["levels"] = levels;
  if (c.fit) {
    j["fit"] = {{"model", to_string(c.fit->model)},
                {"alpha", c.fit->params.alpha},
                {"beta", c.fit->params.beta},
                {"gamma", c.fit->params.gamma},
                {"lambda", c.fit->params.lambda},
                {"log_likelihood", c.fit->log_likelihood},
                {"deviance", c.fit->deviance}};
  }
  j["threshold"] = number_or_null(c.threshold);
  j["slope"] = number_or_null(c.slope);
  if (c.percentile_ci) j["threshold_ci_percentile"] = {c.percentile_ci->lower, c.percentile_ci->upper};
  if (c.bca_ci) j["threshold_ci_bca"] = {c.bca_ci->lower, c.bca_ci->upper};
  j["interpolated_threshold"] = number_or_null(c.interpolated_threshold);
  if (!c.fit_error.empty()) j["fit_error"] = c.fit_error;
  if (!c.interpolation_error.empty()) j["interpolation_error"] = c.interpolation_error;
  return j;
}

json rm_json(const RepeatedMeasuresAnova& a) {
  return {{"subjects", a.subjects},        {"conditions", a.conditions},
          {"f", number_or_null(a.f)},      {"df_conditions", a.df_conditions},
          {"df_error", a.df_error},        {"p", number_or_null(a.p)},
          {"gg_epsilon", a.gg_epsilon},    {"gg_df_conditions", a.gg_df_conditions},
          {"gg_df_error", a.gg_df_error},  {"gg_p", number_or_null(a.gg_p)},
          {"ss_conditions", a.ss_conditions}, {"ss_error", a.ss_error},
          {"partial_eta_squared", number_or_null(a.partial_eta_squared)},
          {"testable", a.testable},        {"not_testable_reason", a.not_testable_reason}};
}

std::string safe_file_name(const std::string& s) {
  std::string out;
  for (char c : s) out += (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_') ? c : '_';
  return out;
}

}  // namespace

Result<std::vector<StimulusLevel>> levels_from_trials(const std::vector<double>& stimulus,
                                                      const std::vector<int>& correct) {
  if (stimulus.size() != correct.size()) {
    return make_error(Errc::invalid_argument, "stimulus and response lists differ in length");
  }
  std::vector<StimulusLevel> out;
  for (std::size_t i = 0; i < stimulus.size(); ++i) {
    if (!std::isfinite(stimulus[i])) return make_error(Errc::invalid_argument, "a stimulus is not finite");
    out.push_back({stimulus[i], correct[i] ? 1 : 0, 1});
  }
  return pool_levels(out);
}

namespace {

// "3, 5, 7-119": trial numbers, runs collapsed.
std::string ranges_text(const std::vector<long long>& v) {
  std::string out;
  for (std::size_t i = 0; i < v.size();) {
    std::size_t j = i;
    while (j + 1 < v.size() && v[j + 1] == v[j] + 1) ++j;
    out += (out.empty() ? "" : ", ") + (j == i ? std::to_string(v[i]) : fmt::format("{}-{}", v[i], v[j]));
    i = j + 1;
  }
  return out;
}

}  // namespace

Status SessionFileChecker::add(const CsvTable& table, const fs::path& sidecar) {
  const auto pc = table.column("participant"), sc = table.column("session"), tc = table.column("trial");
  if (!tc) return Status::success();  // not a session file: nothing to check against
  std::set<std::string> sessions_here;
  Expected e;
  e.file = table.source;
  for (std::size_t r = 0; r < table.rows.size(); ++r) {
    const std::string participant = pc ? table.rows[r][*pc] : fs::path(table.source).stem().string();
    const std::string session = sc ? table.rows[r][*sc] : "1";
    auto trial = table.integer(r, *tc);
    if (!trial) return trial.error();
    const std::string where = fmt::format("{}:{}", table.source, table.lines[r]);
    const std::string key = participant + '\x1f' + session + '\x1f' + std::to_string(*trial);
    if (const auto [it, fresh] = trial_at_.emplace(key, where); !fresh) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{}: trial {} of participant {} (session {}) is already at {}: a trial recorded "
                                    "twice (two runs on one folder, or a copied file) would be counted twice; remove "
                                    "the duplicate rows or file",
                                    where, *trial, printable(participant, 40), printable(session, 10), it->second));
    }
    const std::string skey = participant + '\x1f' + session;
    if (sessions_here.insert(skey).second) {
      if (const auto [it, fresh] = session_in_.emplace(skey, table.source); !fresh) {
        return make_error(Errc::invalid_argument,
                          fmt::format("{}: participant {} (session {}) is also in {}: one session split across two "
                                      "files; keep one file per session",
                                      where, printable(participant, 40), printable(session, 10), it->second));
      }
    }
    e.present.insert(*trial);
  }
  if (sidecar.empty()) return Status::success();
  auto text = read_input_file(sidecar, "session sidecar");
  if (!text) return text.error();
  const json j = json::parse(*text, nullptr, false);
  if (!j.is_object()) return make_error(Errc::parse_error, fmt::format("{} is not valid JSON", sidecar.string()));
  try {
    const long long planned = j.value("planned_trials", 0LL);
    e.status = j.value("status", std::string());
    // Adaptive procedures may stop before their last slot: once the sidecar
    // says "complete", their plan is the trials it says were completed.
    const bool constant = j.value("procedure", std::string()) == "constant";
    e.trials = constant || e.status != "complete" ? planned : j.value("completed_trials", 0LL);
  } catch (const json::exception& ex) {
    return make_error(Errc::parse_error, fmt::format("{}: malformed field: {}", sidecar.string(), ex.what()));
  }
  expected_.push_back(std::move(e));
  return Status::success();
}

Status SessionFileChecker::finish(std::vector<std::string>& notes) const {
  for (const Expected& e : expected_) {
    std::vector<long long> missing;
    for (long long t = 0; t < e.trials; ++t) {
      if (!e.present.count(t)) missing.push_back(t);
    }
    const bool unfinished = e.status != "complete";
    if (missing.empty() && !unfinished) continue;
    const std::string what =
        missing.empty()
            ? fmt::format("{}: its sidecar says the session is not finished (status '{}')", e.file,
                          printable(e.status, 20))
            : fmt::format("{}: {} of {} planned trials are missing (trial {}){}", e.file, missing.size(), e.trials,
                          ranges_text(missing), unfinished ? "; the session is not finished" : "");
    if (!allow_incomplete_) {
      return make_error(Errc::invalid_argument,
                        what + "; run the session again to complete it, or pass --allow-incomplete to analyse the "
                               "trials that are there");
    }
    notes.push_back(what + " (analysed anyway: --allow-incomplete)");
  }
  return Status::success();
}

Result<StudyAnalysis> analyze_study(const fs::path& dir, const StudyAnalysisOptions& options) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    return make_error(Errc::not_found, fmt::format("{} is not a folder; pass the folder holding the session CSVs",
                                                   dir.string()));
  }
  if (Status s = check_study_folder_not_in_use(dir); !s) return s.error();
  if (options.lapse && options.lapse_max) {
    return make_error(Errc::invalid_argument,
                      "give --lapse (a fixed lapse rate) or --lapse-max (a free one up to that value), not both");
  }
  if (options.bootstrap < 0) {
    return make_error(Errc::invalid_argument, "--bootstrap must be 0 (no intervals) or more samples");
  }
  if (!(options.coverage > 0.0 && options.coverage < 1.0)) {
    return make_error(Errc::invalid_argument, fmt::format("coverage {} must lie in (0, 1)", options.coverage));
  }
  SessionFileChecker checker(options.allow_incomplete);
  std::vector<fs::path> csvs;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    if (it->is_regular_file() && it->path().extension() == ".csv") csvs.push_back(it->path());
  }
  std::sort(csvs.begin(), csvs.end());

  StudyAnalysis a;
  const bool columns_given = !options.stimulus_column.empty() && !options.response_column.empty() &&
                             options.conditions_given;
  std::optional<SidecarInfo> first;
  std::map<std::pair<std::string, std::string>, Trials> trials;  // (participant, condition)
  for (const fs::path& csv : csvs) {
    fs::path sidecar = csv;
    sidecar.replace_extension(".json");
    std::optional<SidecarInfo> info;
    if (fs::exists(sidecar)) {
      auto s = read_sidecar(sidecar);
      if (!s) return s.error();
      info = *s;
    } else if (!columns_given) {
      a.notes.push_back(fmt::format("{}: no sidecar (.json) next to it; skipped (give --stimulus, --response and "
                                    "--conditions to read it anyway)",
                                    csv.string()));
      continue;
    }
    const std::string stim_col = !options.stimulus_column.empty() ? options.stimulus_column : info->stimulus;
    const std::string resp_col = !options.response_column.empty() ? options.response_column : info->response;
    const std::vector<std::string> cond_cols = options.conditions_given ? options.condition_columns : info->factors;
    if (a.files.empty()) {
      a.stimulus_column = stim_col;
      a.response_column = resp_col;
      a.condition_columns = cond_cols;
      a.stimulus_unit = info ? info->unit : "";
      if (info) first = info;
    } else if (stim_col != a.stimulus_column || resp_col != a.response_column || cond_cols != a.condition_columns) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{} uses other columns (stimulus '{}', response '{}') than {} ('{}', '{}'); "
                                    "analyse studies with different designs separately",
                                    csv.string(), stim_col, resp_col, a.files.front().string(), a.stimulus_column,
                                    a.response_column));
    }
    auto table = read_csv(csv);
    if (!table) return table.error();
    if (Status s = checker.add(*table, info ? sidecar : fs::path()); !s) return s.error();
    auto sc = table->require_column(stim_col);
    if (!sc) return sc.error();
    auto rc = table->require_column(resp_col);
    if (!rc) return rc.error();
    std::vector<std::size_t> cc;
    for (const std::string& c : cond_cols) {
      auto i = table->require_column(c);
      if (!i) return i.error();
      cc.push_back(*i);
    }
    const std::optional<std::size_t> pc = table->column("participant");
    a.files.push_back(csv);
    for (std::size_t r = 0; r < table->rows.size(); ++r) {
      auto x = table->number(r, *sc);
      if (!x) return x.error();
      auto y = table->integer(r, *rc);
      if (!y) return y.error();
      if (*y != 0 && *y != 1) {
        return make_error(Errc::parse_error, fmt::format("{}:{}: column '{}' must be 0 or 1, found {}",
                                                         table->source, table->lines[r], resp_col, *y));
      }
      std::vector<std::string> values;
      for (std::size_t c : cc) values.push_back(table->rows[r][c]);
      const std::string participant = pc ? table->rows[r][*pc] : csv.stem().string();
      Trials& t = trials[{participant, condition_label(cond_cols, values)}];
      t.stimulus.push_back(*x);
      t.correct.push_back(static_cast<int>(*y));
    }
  }
  if (Status s = checker.finish(a.notes); !s) return s.error();
  if (trials.empty()) {
    return make_error(Errc::not_found,
                      fmt::format("no trials found under {}: expected session CSVs with their .json sidecars, as "
                                  "written by proprio::study::Session",
                                  dir.string()));
  }

  // Settings: the sidecar's analysis section, then the options.
  FitOptions fo;
  double criterion = 0.75;
  if (first) {
    const json& an = first->analysis;
    if (an.contains("model")) {
      auto m = parse_psychometric_model(an["model"].get<std::string>());
      if (m) fo.model = *m;
    }
    fo.guess = an.value("guess", fo.guess);
    if (an.contains("lapse_max")) {
      fo.lapse_free = true;
      fo.lapse_max = an["lapse_max"].get<double>();
    } else {
      fo.lapse = an.value("lapse", 0.0);
    }
    criterion = an.value("threshold", criterion);
  }
  if (options.model) fo.model = *options.model;
  if (options.guess) fo.guess = *options.guess;
  if (options.lapse) {
    fo.lapse_free = false;
    fo.lapse = *options.lapse;
  }
  if (options.lapse_max) {
    fo.lapse_free = true;
    fo.lapse_max = *options.lapse_max;
  }
  if (options.threshold) criterion = *options.threshold;
  // Refused before any fit: a value out of range would fail every fit and
  // leave an empty report behind. A value the options did not give comes
  // from the sidecar.
  if (Status s = validate_threshold_proportion(fo, criterion); !s) {
    return s.error().with_context("analysis settings (the options, else the session sidecar's analysis section)");
  }
  a.fit_options = fo;
  a.criterion = criterion;
  a.method = options.method;
  a.bootstrap = options.bootstrap;
  a.seed = options.seed;
  a.coverage = options.coverage;

  // Conditions in design order when the sidecar knows the factors.
  std::set<std::string> participant_set, condition_set;
  for (const auto& [key, t] : trials) {
    participant_set.insert(key.first);
    condition_set.insert(key.second);
  }
  a.participants.assign(participant_set.begin(), participant_set.end());
  if (first && a.condition_columns == first->factors && !first->factors.empty()) {
    std::vector<std::vector<std::string>> combos(1);
    for (const auto& levels : first->factor_levels) {
      std::vector<std::vector<std::string>> next;
      for (const auto& c : combos) {
        for (const std::string& l : levels) {
          next.push_back(c);
          next.back().push_back(l);
        }
      }
      combos = next;
    }
    for (const auto& c : combos) {
      const std::string label = condition_label(first->factors, c);
      if (condition_set.count(label)) a.conditions.push_back(label);
    }
  }
  for (const std::string& c : condition_set) {
    if (std::find(a.conditions.begin(), a.conditions.end(), c) == a.conditions.end()) a.conditions.push_back(c);
  }

  std::uint64_t stream = 0;
  std::map<std::string, Trials> by_condition;
  for (const std::string& p : a.participants) {
    for (const std::string& c : a.conditions) {
      const auto it = trials.find({p, c});
      if (it == trials.end()) {
        a.notes.push_back(fmt::format("participant {} has no trials in condition {}", p, c));
        continue;
      }
      CellAnalysis cell;
      cell.participant = p;
      cell.condition = c;
      auto levels = levels_from_trials(it->second.stimulus, it->second.correct);
      if (!levels) return levels.error();
      cell.data = *levels;
      analyse_cell(cell, fo, criterion, options.bootstrap, mix_seed(options.seed, stream++), options.coverage);
      a.cells.push_back(std::move(cell));
      Trials& pooled = by_condition[c];
      pooled.stimulus.insert(pooled.stimulus.end(), it->second.stimulus.begin(), it->second.stimulus.end());
      pooled.correct.insert(pooled.correct.end(), it->second.correct.begin(), it->second.correct.end());
    }
  }
  for (const std::string& c : a.conditions) {
    CellAnalysis cell;
    cell.participant = "all";
    cell.condition = c;
    cell.data = *levels_from_trials(by_condition[c].stimulus, by_condition[c].correct);
    analyse_cell(cell, fo, criterion, options.bootstrap, mix_seed(options.seed, stream++), options.coverage);
    a.pooled.push_back(std::move(cell));
  }

  // Between conditions: participants with a threshold in every condition.
  auto threshold_of = [&](const CellAnalysis& c) {
    return options.method == ThresholdMethod::fit ? c.threshold : c.interpolated_threshold;
  };
  if (a.conditions.size() >= 2) {
    std::vector<std::vector<double>> matrix;
    for (const std::string& p : a.participants) {
      std::vector<double> row;
      for (const std::string& c : a.conditions) {
        const auto it = std::find_if(a.cells.begin(), a.cells.end(),
                                     [&](const CellAnalysis& x) { return x.participant == p && x.condition == c; });
        row.push_back(it == a.cells.end() ? kNaN : threshold_of(*it));
      }
      if (std::all_of(row.begin(), row.end(), [](double v) { return std::isfinite(v); })) {
        matrix.push_back(row);
        a.anova_participants.push_back(p);
      } else {
        a.notes.push_back(fmt::format("participant {} lacks a threshold in some condition; left out of the "
                                      "between-condition statistics",
                                      p));
      }
    }
    if (matrix.size() >= 2) {
      auto rm = repeated_measures_anova(matrix);
      if (rm) a.threshold_anova = *rm;
      std::vector<double> ps;
      for (std::size_t i = 0; i < a.conditions.size(); ++i) {
        for (std::size_t j = i + 1; j < a.conditions.size(); ++j) {
          std::vector<double> x, y;
          for (const auto& row : matrix) {
            x.push_back(row[i]);
            y.push_back(row[j]);
          }
          auto t = paired_t_test(x, y);
          if (!t) continue;
          a.comparisons.push_back({a.conditions[i], a.conditions[j], *t, 1.0, 1.0});
          ps.push_back(t->p);
        }
      }
      const std::vector<double> holm_p = holm(ps), bonf_p = bonferroni(ps);
      for (std::size_t k = 0; k < a.comparisons.size(); ++k) {
        a.comparisons[k].p_holm = holm_p[k];
        a.comparisons[k].p_bonferroni = bonf_p[k];
      }
    } else {
      a.notes.push_back("fewer than two participants have thresholds in every condition: no ANOVA on thresholds");
    }

    // At each stimulus level: proportion correct per participant and condition.
    std::set<double> all_levels;
    for (const CellAnalysis& c : a.cells) {
      for (const StimulusLevel& s : c.data) all_levels.insert(s.level);
    }
    if (all_levels.size() > 20) {
      a.notes.push_back("more than 20 distinct stimulus levels (adaptive data?): no per-level ANOVAs");
    } else {
      for (double level : all_levels) {
        std::vector<std::vector<double>> groups(a.conditions.size());
        std::vector<std::vector<double>> rows;
        for (const std::string& p : a.participants) {
          std::vector<double> row;
          for (std::size_t ci = 0; ci < a.conditions.size(); ++ci) {
            double v = kNaN;
            for (const CellAnalysis& c : a.cells) {
              if (c.participant != p || c.condition != a.conditions[ci]) continue;
              for (const StimulusLevel& s : c.data) {
                if (s.level == level && s.trials > 0) v = static_cast<double>(s.correct) / s.trials;
              }
            }
            if (std::isfinite(v)) groups[ci].push_back(v);
            row.push_back(v);
          }
          if (std::all_of(row.begin(), row.end(), [](double v) { return std::isfinite(v); })) rows.push_back(row);
        }
        LevelAnova la;
        la.level = level;
        if (auto ow = one_way_anova(groups)) la.one_way = *ow;
        if (rows.size() >= 2) {
          if (auto rm = repeated_measures_anova(rows)) la.repeated = *rm;
        }
        if (la.one_way || la.repeated) a.level_anovas.push_back(la);
      }
    }
  }
  return a;
}

std::string study_analysis_json(const StudyAnalysis& a) {
  json j;
  j["files"] = json::array();
  for (const fs::path& f : a.files) j["files"].push_back(f.string());
  j["stimulus_column"] = a.stimulus_column;
  j["stimulus_unit"] = a.stimulus_unit;
  j["response_column"] = a.response_column;
  j["condition_columns"] = a.condition_columns;
  j["participants"] = a.participants;
  j["conditions"] = a.conditions;
  j["settings"] = {{"model", to_string(a.fit_options.model)},
                   {"guess", a.fit_options.guess},
                   {"lapse", a.fit_options.lapse_free ? json(nullptr) : json(a.fit_options.lapse)},
                   {"lapse_max", a.fit_options.lapse_free ? json(a.fit_options.lapse_max) : json(nullptr)},
                   {"threshold_proportion", a.criterion},
                   {"threshold_method", a.method == ThresholdMethod::fit ? "fit" : "interpolate"},
                   {"bootstrap_samples", a.bootstrap},
                   {"seed", a.seed},
                   {"coverage", a.coverage}};
  j["cells"] = json::array();
  for (const CellAnalysis& c : a.cells) j["cells"].push_back(cell_json(c));
  j["pooled"] = json::array();
  for (const CellAnalysis& c : a.pooled) j["pooled"].push_back(cell_json(c));
  if (a.threshold_anova) {
    j["threshold_anova"] = rm_json(*a.threshold_anova);
    j["threshold_anova"]["participants"] = a.anova_participants;
  }
  j["comparisons"] = json::array();
  for (const ConditionComparison& c : a.comparisons) {
    j["comparisons"].push_back({{"a", c.a},
                                {"b", c.b},
                                {"n", c.test.n},
                                {"mean_difference", c.test.mean_difference},
                                {"t", number_or_null(c.test.t)},
                                {"df", c.test.df},
                                {"p", number_or_null(c.test.p)},
                                {"p_holm", number_or_null(c.p_holm)},
                                {"p_bonferroni", number_or_null(c.p_bonferroni)},
                                {"cohen_dz", number_or_null(c.test.cohen_dz)},
                                {"testable", c.test.testable},
                                {"not_testable_reason", c.test.not_testable_reason}});
  }
  j["level_anovas"] = json::array();
  for (const LevelAnova& l : a.level_anovas) {
    json e = {{"level", l.level}};
    if (l.one_way) {
      e["one_way"] = {{"f", number_or_null(l.one_way->f)},
                      {"df_between", l.one_way->df_between},
                      {"df_within", l.one_way->df_within},
                      {"p", number_or_null(l.one_way->p)},
                      {"testable", l.one_way->testable},
                      {"not_testable_reason", l.one_way->not_testable_reason}};
    }
    if (l.repeated) e["repeated_measures"] = rm_json(*l.repeated);
    j["level_anovas"].push_back(e);
  }
  j["notes"] = a.notes;
  return j.dump(2);
}

Result<std::vector<fs::path>> write_study_report(const StudyAnalysis& a, const fs::path& out_dir) {
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) {
    return make_error(Errc::io_error, fmt::format("cannot create {}: {}", out_dir.string(), ec.message()));
  }
  std::vector<fs::path> written;
  const fs::path summary = out_dir / "summary.json";
  if (Status s = write_file_atomic(summary, study_analysis_json(a) + "\n", "analysis summary"); !s) return s.error();
  written.push_back(summary);
  const fs::path table = out_dir / "thresholds.csv";
  {
    std::ostringstream out;
    out << "participant,condition,trials,threshold,ci_lower,ci_upper,bca_lower,bca_upper,interpolated_threshold,"
           "alpha,beta,lambda,deviance\n";
    auto num = [](double v) { return std::isfinite(v) ? fmt::format("{}", v) : std::string(); };
    for (const auto* list : {&a.cells, &a.pooled}) {
      for (const CellAnalysis& c : *list) {
        int n = 0;
        for (const StimulusLevel& s : c.data) n += s.trials;
        out << csv_field(c.participant) << ',' << csv_field(c.condition) << ',' << n << ',' << num(c.threshold)
            << ',' << (c.percentile_ci ? num(c.percentile_ci->lower) : "") << ','
            << (c.percentile_ci ? num(c.percentile_ci->upper) : "") << ','
            << (c.bca_ci ? num(c.bca_ci->lower) : "") << ',' << (c.bca_ci ? num(c.bca_ci->upper) : "") << ','
            << num(c.interpolated_threshold) << ',' << (c.fit ? num(c.fit->params.alpha) : "") << ','
            << (c.fit ? num(c.fit->params.beta) : "") << ',' << (c.fit ? num(c.fit->params.lambda) : "") << ','
            << (c.fit ? num(c.fit->deviance) : "") << '\n';
      }
    }
    if (Status s = write_file_atomic(table, out.str(), "thresholds table"); !s) return s.error();
  }
  written.push_back(table);

  const std::string x_label =
      a.stimulus_unit.empty() ? a.stimulus_column : fmt::format("{} ({})", a.stimulus_column, a.stimulus_unit);
  auto plot_of = [&](const std::string& title, const std::vector<const CellAnalysis*>& cells) {
    PsychometricPlot plot;
    plot.title = title;
    plot.x_label = x_label;
    plot.y_label = "proportion " + a.response_column;
    plot.criterion = a.criterion;
    for (const CellAnalysis* c : cells) {
      PsychometricCurve curve;
      curve.label = c->condition;
      curve.data = c->data;
      curve.fit = c->fit;
      const double t = a.method == ThresholdMethod::fit ? c->threshold : c->interpolated_threshold;
      if (std::isfinite(t)) curve.threshold = t;
      if (a.method == ThresholdMethod::fit) curve.threshold_ci = c->bca_ci ? c->bca_ci : c->percentile_ci;
      plot.curves.push_back(curve);
    }
    return plot;
  };
  std::vector<const CellAnalysis*> pooled;
  for (const CellAnalysis& c : a.pooled) pooled.push_back(&c);
  const fs::path all = out_dir / "all_participants.svg";
  if (Status s = write_psychometric_svg(all, plot_of("all participants (pooled trials)", pooled)); !s) {
    return s.error();
  }
  written.push_back(all);
  for (const std::string& p : a.participants) {
    std::vector<const CellAnalysis*> cells;
    for (const CellAnalysis& c : a.cells) {
      if (c.participant == p) cells.push_back(&c);
    }
    const fs::path file = out_dir / ("participant_" + safe_file_name(p) + ".svg");
    if (Status s = write_psychometric_svg(file, plot_of("participant " + p, cells)); !s) return s.error();
    written.push_back(file);
  }
  return written;
}

}  // namespace proprio::study
