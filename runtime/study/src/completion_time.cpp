#include "proprio/study/completion_time.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "proprio/core/file_io.hpp"
#include "proprio/study/analysis.hpp"
#include "proprio/study/session.hpp"

namespace proprio::study {
namespace fs = std::filesystem;
using nlohmann::json;

Result<std::string> sidecar_kind(const fs::path& sidecar_json) {
  auto text = read_input_file(sidecar_json, "session sidecar");
  if (!text) return text.error();
  const json j = json::parse(*text, nullptr, false);
  if (j.is_discarded() || !j.is_object() || j.value("format", "") != "proprio-study-session") {
    return make_error(Errc::parse_error, fmt::format("{} is not a proprio study sidecar", sidecar_json.string()));
  }
  return j.value("kind", std::string("psychometric"));
}

namespace {

bool numeric_less(const std::string& a, const std::string& b) {
  char* ea = nullptr;
  char* eb = nullptr;
  const double x = std::strtod(a.c_str(), &ea), y = std::strtod(b.c_str(), &eb);
  if (*ea == '\0' && *eb == '\0' && !a.empty() && !b.empty()) return x < y;
  return a < b;
}

}  // namespace

Result<CompletionTimeAnalysis> analyze_completion_times(const std::vector<CsvTable>& tables,
                                                        const CompletionTimeOptions& o) {
  CompletionTimeAnalysis a;
  a.unit = o.unit;
  std::vector<CompletionTimeTrial> all;
  for (const CsvTable& t : tables) {
    a.files.push_back(t.source);
    auto tc = t.require_column(o.time_column);
    if (!tc) return tc.error();
    auto sc = t.require_column(o.setting_column);
    if (!sc) return sc.error();
    auto pc = t.require_column(o.participant_column);
    if (!pc) return pc.error();
    const auto rc = t.column(o.round_column);
    const auto fc = t.column(o.familiarisation_column);
    for (std::size_t r = 0; r < t.rows.size(); ++r) {
      if (fc && t.rows[r][*fc] == "1") {
        ++a.excluded_trials;
        continue;
      }
      auto time = t.number(r, *tc);
      if (!time) return time.error();
      if (*time <= 0.0) {
        return make_error(Errc::invalid_argument, fmt::format("{}:{}: {} must be positive, got {}", t.source, t.lines[r],
                                                              o.time_column, *time));
      }
      CompletionTimeTrial tr;
      tr.participant = t.rows[r][*pc];
      tr.setting = t.rows[r][*sc];
      tr.round = rc ? t.rows[r][*rc] : "1";
      tr.time_s = *time;
      if (tr.participant.empty() || tr.setting.empty()) {
        return make_error(Errc::invalid_argument,
                          fmt::format("{}:{}: empty participant or setting", t.source, t.lines[r]));
      }
      all.push_back(tr);
    }
  }
  if (all.empty()) {
    return make_error(Errc::not_found, "no analysed trials: every row was familiarisation, or the files are empty");
  }
  std::set<std::string> ps, ss;
  for (const auto& t : all) {
    ps.insert(t.participant);
    ss.insert(t.setting);
  }
  a.participants.assign(ps.begin(), ps.end());
  a.settings.assign(ss.begin(), ss.end());
  std::sort(a.settings.begin(), a.settings.end(), numeric_less);
  if (a.settings.size() < 2) return make_error(Errc::invalid_argument, "need at least two settings to compare");

  // Normalise by each participant's mean over the analysed trials.
  std::map<std::string, std::pair<double, int>> sums;
  for (const auto& t : all) {
    sums[t.participant].first += t.time_s;
    ++sums[t.participant].second;
  }
  for (const auto& [p, s] : sums) a.participant_mean_time_s[p] = s.first / s.second;
  for (auto& t : all) t.normalised = t.time_s / a.participant_mean_time_s[t.participant];
  a.trials = all;

  const auto setting_index = [&](const std::string& s) {
    return static_cast<std::size_t>(std::find(a.settings.begin(), a.settings.end(), s) - a.settings.begin());
  };
  const auto participant_index = [&](const std::string& p) {
    return static_cast<std::size_t>(std::find(a.participants.begin(), a.participants.end(), p) -
                                    a.participants.begin());
  };
  // Per setting, over trials.
  for (const std::string& s : a.settings) {
    std::vector<double> v, raw;
    for (const auto& t : all) {
      if (t.setting == s) {
        v.push_back(t.normalised);
        raw.push_back(t.time_s);
      }
    }
    a.summary.push_back({s, static_cast<int>(v.size()), mean(v), sample_sd(v), mean(raw)});
  }
  // Profiles and the participant-level ANOVA.
  std::vector<std::vector<std::vector<double>>> cells(a.participants.size(),
                                                      std::vector<std::vector<double>>(a.settings.size()));
  for (const auto& t : all) cells[participant_index(t.participant)][setting_index(t.setting)].push_back(t.normalised);
  a.profile.assign(a.participants.size(), std::vector<double>(a.settings.size(), std::nan("")));
  bool complete = true;
  for (std::size_t p = 0; p < cells.size(); ++p) {
    for (std::size_t s = 0; s < a.settings.size(); ++s) {
      if (cells[p][s].empty()) {
        complete = false;
      } else {
        a.profile[p][s] = mean(cells[p][s]);
      }
    }
  }
  if (!complete) {
    return make_error(Errc::invalid_argument,
                      "a participant has no analysed trial in some setting; a repeated-measures analysis needs every "
                      "participant in every setting");
  }
  if (a.participants.size() >= 2) {
    auto rm = repeated_measures_anova(a.profile);
    if (!rm) return rm.error().with_context("participant-level RM-ANOVA");
    a.anova_participants = *rm;
  }
  // Round-level: every (participant, round) holding each setting exactly once.
  std::map<std::pair<std::string, std::string>, std::vector<double>> rounds;
  std::map<std::pair<std::string, std::string>, std::vector<int>> seen;
  for (const auto& t : all) {
    auto key = std::make_pair(t.participant, t.round);
    rounds[key].resize(a.settings.size(), std::nan(""));
    seen[key].resize(a.settings.size(), 0);
    const std::size_t s = setting_index(t.setting);
    rounds[key][s] = t.normalised;
    ++seen[key][s];
  }
  std::vector<std::vector<double>> round_data;
  for (const auto& [key, row] : rounds) {
    const auto& count = seen[key];
    if (std::all_of(count.begin(), count.end(), [](int c) { return c == 1; })) round_data.push_back(row);
  }
  const bool rounds_ok = round_data.size() >= 2;
  if (rounds_ok) {
    auto rm = repeated_measures_anova(round_data);
    if (!rm) return rm.error().with_context("round-level RM-ANOVA");
    a.anova_rounds = *rm;
  }
  if (a.unit == CompletionTimeOptions::Unit::round && !rounds_ok) a.unit = CompletionTimeOptions::Unit::participant;
  const auto& data = a.unit == CompletionTimeOptions::Unit::round ? round_data : a.profile;
  if (data.size() >= 2) {
    std::vector<double> raw_p;
    for (std::size_t i = 0; i < a.settings.size(); ++i) {
      for (std::size_t j = i + 1; j < a.settings.size(); ++j) {
        std::vector<double> x, y;
        for (const auto& row : data) {
          x.push_back(row[i]);
          y.push_back(row[j]);
        }
        auto t = paired_t_test(x, y);
        if (!t) return t.error().with_context(fmt::format("paired t {} vs {}", a.settings[i], a.settings[j]));
        a.pairwise.push_back({a.settings[i], a.settings[j], *t, 1.0, 1.0});
        raw_p.push_back(t->p);
      }
    }
    const auto bon = bonferroni(raw_p), hol = holm(raw_p);
    for (std::size_t k = 0; k < a.pairwise.size(); ++k) {
      a.pairwise[k].p_bonferroni = bon[k];
      a.pairwise[k].p_holm = hol[k];
    }
  }
  return a;
}

Result<CompletionTimeAnalysis> analyze_completion_time_study(const fs::path& dir, const CompletionTimeOptions& o) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    return make_error(Errc::not_found, fmt::format("{} is not a folder; pass the folder holding the session CSVs",
                                                   dir.string()));
  }
  if (Status s = check_study_folder_not_in_use(dir); !s) return s.error();
  std::vector<fs::path> csvs;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    if (!e.is_regular_file() || e.path().extension() != ".csv") continue;
    fs::path sidecar = e.path();
    sidecar.replace_extension(".json");
    if (!fs::exists(sidecar)) continue;
    auto kind = sidecar_kind(sidecar);
    if (!kind) return kind.error();
    if (*kind == "completion-time") csvs.push_back(e.path());
  }
  std::sort(csvs.begin(), csvs.end());
  if (csvs.empty()) {
    return make_error(Errc::not_found, fmt::format("no completion-time sessions in {} (CSV + .json sidecar with kind "
                                                   "\"completion-time\")",
                                                   dir.string()));
  }
  std::vector<CsvTable> tables;
  SessionFileChecker checker(o.allow_incomplete);
  std::vector<std::string> notes;
  for (const fs::path& p : csvs) {
    auto t = read_csv(p);
    if (!t) return t.error();
    fs::path sidecar = p;
    sidecar.replace_extension(".json");
    if (Status s = checker.add(*t, sidecar); !s) return s.error();
    tables.push_back(std::move(*t));
  }
  if (Status s = checker.finish(notes); !s) return s.error();
  auto a = analyze_completion_times(tables, o);
  if (a) a->notes.insert(a->notes.end(), notes.begin(), notes.end());
  return a;
}

namespace {

std::string fmt_p(double p) { return p < 0.0001 ? fmt::format("{:.2e}", p) : fmt::format("{:.4f}", p); }

json anova_json(const RepeatedMeasuresAnova& r) {
  return {{"subjects", r.subjects},       {"conditions", r.conditions}, {"f", r.f},
          {"df_conditions", r.df_conditions}, {"df_error", r.df_error},   {"p", r.p},
          {"gg_epsilon", r.gg_epsilon},   {"gg_df_conditions", r.gg_df_conditions},
          {"gg_df_error", r.gg_df_error}, {"gg_p", r.gg_p},             {"partial_eta_squared", r.partial_eta_squared},
          {"testable", r.testable},       {"not_testable_reason", r.not_testable_reason}};
}

}  // namespace

std::string completion_time_json(const CompletionTimeAnalysis& a) {
  json j;
  j["kind"] = "completion-time";
  j["files"] = a.files;
  j["participants"] = a.participants;
  j["settings"] = a.settings;
  j["excluded_trials"] = a.excluded_trials;
  j["analysed_trials"] = a.trials.size();
  json summary = json::array();
  for (const auto& s : a.summary) {
    summary.push_back({{"setting", s.setting}, {"n", s.n}, {"mean_normalised", s.mean}, {"sd_normalised", s.sd},
                       {"mean_time_s", s.mean_time_s}});
  }
  j["per_setting"] = summary;
  json means = json::object();
  for (const auto& [p, m] : a.participant_mean_time_s) means[p] = m;
  j["participant_mean_time_s"] = means;
  json prof = json::object();
  for (std::size_t p = 0; p < a.participants.size(); ++p) prof[a.participants[p]] = a.profile[p];
  j["profiles"] = prof;
  j["rm_anova_rounds"] = anova_json(a.anova_rounds);
  j["rm_anova_participants"] = anova_json(a.anova_participants);
  j["post_hoc_unit"] = a.unit == CompletionTimeOptions::Unit::round ? "round" : "participant";
  json pw = json::array();
  for (const auto& c : a.pairwise) {
    pw.push_back({{"a", c.a}, {"b", c.b}, {"n", c.test.n}, {"mean_difference", c.test.mean_difference},
                  {"t", c.test.t}, {"df", c.test.df}, {"p", c.test.p}, {"p_bonferroni", c.p_bonferroni},
                  {"p_holm", c.p_holm}, {"cohen_dz", c.test.cohen_dz}, {"testable", c.test.testable},
                  {"not_testable_reason", c.test.not_testable_reason}});
  }
  j["notes"] = a.notes;
  j["pairwise"] = pw;
  return j.dump(2);
}

std::string completion_time_text(const CompletionTimeAnalysis& a) {
  std::ostringstream s;
  s << fmt::format("{} participants, {} analysed trials ({} familiarisation trials excluded)\n\n",
                   a.participants.size(), a.trials.size(), a.excluded_trials);
  s << fmt::format("{:<10} {:>6} {:>16} {:>10} {:>14}\n", "setting", "n", "normalised mean", "SD", "mean time (s)");
  for (const auto& r : a.summary) {
    s << fmt::format("{:<10} {:>6} {:>16.3f} {:>10.3f} {:>14.2f}\n", r.setting, r.n, r.mean, r.sd, r.mean_time_s);
  }
  const auto anova_line = [&](const char* what, const RepeatedMeasuresAnova& r) {
    if (r.subjects < 2) return;
    if (!r.testable) {
      s << fmt::format("\nRM-ANOVA ({}, {} subjects): not testable: {}\n", what, r.subjects, r.not_testable_reason);
      return;
    }
    s << fmt::format("\nRM-ANOVA ({}, {} subjects): F({:.0f}, {:.0f}) = {:.3f}, p = {}; Greenhouse-Geisser epsilon = "
                     "{:.3f}: F({:.3f}, {:.3f}), p = {}; partial eta^2 = {:.3f}\n",
                     what, r.subjects, r.df_conditions, r.df_error, r.f, fmt_p(r.p), r.gg_epsilon, r.gg_df_conditions,
                     r.gg_df_error, fmt_p(r.gg_p), r.partial_eta_squared);
  };
  anova_line("rounds: participant x repetition, as the thesis", a.anova_rounds);
  anova_line("participant means", a.anova_participants);
  s << fmt::format("\nPost hoc paired t-tests on {} ({} comparisons):\n",
                   a.unit == CompletionTimeOptions::Unit::round ? "rounds" : "participant means", a.pairwise.size());
  s << fmt::format("{:<8} {:>5} {:>12} {:>9} {:>12} {:>12} {:>12}\n", "pair", "n", "mean diff", "t", "p",
                   "Bonferroni", "Holm");
  for (const auto& c : a.pairwise) {
    if (!c.test.testable) {
      s << fmt::format("{:<8} {:>5} {:>12.4f}  not testable: {}\n", c.a + "-" + c.b, c.test.n, c.test.mean_difference,
                       c.test.not_testable_reason);
      continue;
    }
    s << fmt::format("{:<8} {:>5} {:>12.4f} {:>9.3f} {:>12} {:>12} {:>12}\n", c.a + "-" + c.b, c.test.n,
                     c.test.mean_difference, c.test.t, fmt_p(c.test.p), fmt_p(c.p_bonferroni), fmt_p(c.p_holm));
  }
  for (const std::string& n : a.notes) s << "\nnote: " << n << "\n";
  return s.str();
}

std::string completion_time_svg(const CompletionTimeAnalysis& a, const std::string& title) {
  // Two panels like Fig. 3.8: mean +- SD per setting (left), each
  // participant's mean normalised time per setting (right).
  const double W = 900, H = 420, top = 50, bottom = 360, left1 = 70, right1 = 420, left2 = 520, right2 = 870;
  double ymax = 0.0;
  for (const auto& s : a.summary) ymax = std::max(ymax, s.mean + (std::isfinite(s.sd) ? s.sd : 0.0));
  for (const auto& row : a.profile) {
    for (double v : row) {
      if (std::isfinite(v)) ymax = std::max(ymax, v);
    }
  }
  ymax = std::ceil(std::max(ymax, 1.0) * 2.0 + 0.2) / 2.0;
  const auto y = [&](double v) { return bottom - (bottom - top) * v / ymax; };
  const std::size_t n = a.settings.size();
  const auto x1 = [&](std::size_t i) { return left1 + (right1 - left1) * (i + 0.5) / static_cast<double>(n); };
  const auto x2 = [&](std::size_t i) { return left2 + (right2 - left2) * (i + 0.5) / static_cast<double>(n); };
  std::ostringstream s;
  s << fmt::format(R"(<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}" font-family="sans-serif" font-size="12">)",
                   W, H)
    << "\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  s << fmt::format("<text x=\"{}\" y=\"24\" font-size=\"15\" text-anchor=\"middle\">{}</text>\n", W / 2, title);
  for (auto [l, r] : {std::pair{left1, right1}, std::pair{left2, right2}}) {
    s << fmt::format("<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"black\"/>\n", l, bottom, r, bottom);
    s << fmt::format("<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"black\"/>\n", l, top, l, bottom);
    for (double v = 0.0; v <= ymax + 1e-9; v += 0.5) {
      s << fmt::format("<line x1=\"{}\" y1=\"{:.1f}\" x2=\"{}\" y2=\"{:.1f}\" stroke=\"#ddd\"/>\n", l, y(v), r, y(v));
      s << fmt::format("<text x=\"{}\" y=\"{:.1f}\" text-anchor=\"end\">{:.1f}</text>\n", l - 6, y(v) + 4, v);
    }
    s << fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" transform=\"rotate(-90 {} {})\">normalised time</text>\n",
                     l - 45, (top + bottom) / 2, l - 45, (top + bottom) / 2);
  }
  for (std::size_t i = 0; i < n; ++i) {
    const SettingSummary& m = a.summary[i];
    const double bw = 0.5 * (right1 - left1) / static_cast<double>(n);
    s << fmt::format("<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" fill=\"#8fb3d9\" stroke=\"#345\"/>\n",
                     x1(i) - bw / 2, y(m.mean), bw, bottom - y(m.mean));
    if (std::isfinite(m.sd)) {
      s << fmt::format("<line x1=\"{0:.1f}\" y1=\"{1:.1f}\" x2=\"{0:.1f}\" y2=\"{2:.1f}\" stroke=\"black\"/>\n", x1(i),
                       y(std::max(0.0, m.mean - m.sd)), y(m.mean + m.sd));
      for (double v : {std::max(0.0, m.mean - m.sd), m.mean + m.sd}) {
        s << fmt::format("<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" stroke=\"black\"/>\n", x1(i) - 6,
                         y(v), x1(i) + 6, y(v));
      }
    }
    s << fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\">{:.3f}</text>\n", x1(i), y(m.mean) - 6,
                     m.mean);
    for (double x : {x1(i), x2(i)}) {
      s << fmt::format("<text x=\"{:.1f}\" y=\"{}\" text-anchor=\"middle\">setting {}</text>\n", x, bottom + 18,
                       a.settings[i]);
    }
  }
  static const char* colours[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e",
                                  "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"};
  for (std::size_t p = 0; p < a.profile.size(); ++p) {
    std::string pts;
    for (std::size_t i = 0; i < n; ++i) pts += fmt::format("{:.1f},{:.1f} ", x2(i), y(a.profile[p][i]));
    const char* c = colours[p % 10];
    s << fmt::format("<polyline points=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\"/>\n", pts, c);
    for (std::size_t i = 0; i < n; ++i) {
      s << fmt::format("<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"3\" fill=\"{}\"/>\n", x2(i), y(a.profile[p][i]), c);
    }
    s << fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" fill=\"{}\" font-size=\"10\">{}</text>\n", x2(n - 1) + 8,
                     y(a.profile[p][n - 1]) + 3, c, a.participants[p]);
  }
  s << fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">mean +- SD over trials</text>\n", (left1 + right1) / 2,
                   bottom + 40);
  s << fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">per participant (mean)</text>\n", (left2 + right2) / 2,
                   bottom + 40);
  s << "</svg>\n";
  return s.str();
}

Result<std::vector<fs::path>> write_completion_time_report(const CompletionTimeAnalysis& a, const fs::path& out_dir,
                                                           const std::string& title) {
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) return make_error(Errc::io_error, fmt::format("cannot create {}: {}", out_dir.string(), ec.message()));
  std::vector<fs::path> files;
  const auto write = [&](const fs::path& name, const std::string& text) -> Status {
    const fs::path p = out_dir / name;
    if (Status s = write_file_atomic(p, text, "completion-time report"); !s) return s;
    files.push_back(p);
    return {};
  };
  std::ostringstream csv;
  csv << "participant,round,setting,time_s,normalised_time\n";
  for (const auto& t : a.trials) {
    csv << fmt::format("{},{},{},{:.4f},{:.6f}\n", csv_field(t.participant), csv_field(t.round), csv_field(t.setting),
                       t.time_s, t.normalised);
  }
  for (auto [name, text] : {std::pair<const char*, std::string>{"summary.json", completion_time_json(a)},
                            {"normalised_times.csv", csv.str()},
                            {"anova.txt", completion_time_text(a)},
                            {"normalised_time.svg", completion_time_svg(a, title)}}) {
    if (Status st = write(name, text); !st) return st.error();
  }
  return files;
}

}  // namespace proprio::study
