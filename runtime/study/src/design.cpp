#include "proprio/study/design.hpp"

#include <algorithm>
#include <cmath>
#include <fmt/format.h>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>

#include "proprio/core/config.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/core/random.hpp"

namespace proprio::study {
namespace {

#define STUDY_TRY(var, expr)              \
  auto var##_result = (expr);             \
  if (!var##_result) return var##_result.error(); \
  auto var = std::move(*var##_result)

// Seed streams derived from a participant's seed.
constexpr std::uint64_t kPlanStream = 1;

Error config_error(const Config& c, const std::string& key, const std::string& what) {
  return make_error(Errc::invalid_argument, fmt::format("{}: {}: {}", c.where(key), key, what));
}


bool is_identifier(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char ch) {
    return (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == '_' ||
           ch == '-';
  });
}

Result<StaircaseSettings> parse_staircase(const Config& p, bool weighted) {
  StaircaseSettings s;
  STUDY_TRY(down, p.get_int_or("down", weighted ? 1 : 2, 1, 10));
  STUDY_TRY(up, p.get_int_or("up", 1, 1, 10));
  s.down = static_cast<int>(down);
  s.up = static_cast<int>(up);
  if (p.contains("steps")) {
    STUDY_TRY(steps, p.get_doubles("steps"));
    s.steps = steps;
  } else {
    STUDY_TRY(step, p.get_double("step"));
    s.steps = {step};
  }
  STUDY_TRY(scale, p.get_string_or("step_scale", "linear"));
  if (scale != "linear" && scale != "log") return config_error(p, "step_scale", "must be \"linear\" or \"log\"");
  s.log_steps = scale == "log";
  STUDY_TRY(lo, p.get_double_or("min", -1e300, -1e300, 1e300));
  STUDY_TRY(hi, p.get_double_or("max", 1e300, -1e300, 1e300));
  s.min = lo;
  s.max = hi;
  STUDY_TRY(trials, p.get_int_or("trials", 50, 1, 100000));
  STUDY_TRY(reversals, p.get_int_or("reversals", 0, 0, 10000));
  STUDY_TRY(discard, p.get_int_or("discard_reversals", 2, 0, 10000));
  s.max_trials = static_cast<int>(trials);
  s.max_reversals = static_cast<int>(reversals);
  s.discard_reversals = static_cast<int>(discard);
  if (weighted) {
    STUDY_TRY(target, p.get_double("target"));
    if (!(target > 0.0 && target < 1.0)) return config_error(p, "target", "must lie in (0, 1), e.g. 0.75");
    s.up_ratio = weighted_up_ratio(target);
  }
  return s;
}

Result<QuestSettings> parse_quest(const Config& p) {
  QuestSettings q;
  STUDY_TRY(model_name, p.get_string_or("model", "weibull"));
  auto model = parse_psychometric_model(model_name);
  if (!model) return config_error(p, "model", model.error().message);
  q.model = *model;
  STUDY_TRY(beta, p.get_double_or("beta", 3.5, 1e-9, 1e9));
  STUDY_TRY(guess, p.get_double_or("guess", 0.5, 0.0, 0.999));
  STUDY_TRY(lapse, p.get_double_or("lapse", 0.01, 0.0, 0.5));
  STUDY_TRY(target, p.get_double_or("target", 0.75, 0.0, 1.0));
  STUDY_TRY(prior_mean, p.get_double("prior_mean"));
  STUDY_TRY(prior_sd, p.get_double("prior_sd"));
  STUDY_TRY(grid_min, p.get_double("min"));
  STUDY_TRY(grid_max, p.get_double("max"));
  STUDY_TRY(points, p.get_int_or("grid_points", 201, 3, 100000));
  STUDY_TRY(trials, p.get_int_or("trials", 40, 1, 100000));
  STUDY_TRY(stop_sd, p.get_double_or("stop_sd", 0.0, 0.0, 1e300));
  q.beta = beta;
  q.guess = guess;
  q.lapse = lapse;
  q.target = target;
  q.prior_mean = prior_mean;
  q.prior_sd = prior_sd;
  q.grid_min = grid_min;
  q.grid_max = grid_max;
  q.grid_points = static_cast<int>(points);
  q.max_trials = static_cast<int>(trials);
  q.stop_sd = stop_sd;
  return q;
}

// A grid given either as a list (`name`) or as `name_min`, `name_max`,
// `name_points` and optional `name_log`.
Result<std::vector<double>> parse_grid(const Config& p, const std::string& name) {
  if (p.contains(name)) return p.get_doubles(name);
  STUDY_TRY(lo, p.get_double(name + "_min"));
  STUDY_TRY(hi, p.get_double(name + "_max"));
  STUDY_TRY(n, p.get_int_or(name + "_points", 20, 2, 10000));
  STUDY_TRY(log, p.get_bool_or(name + "_log", false));
  if (!(lo < hi)) return config_error(p, name + "_min", fmt::format("must be below {}_max", name));
  if (log && lo <= 0.0) return config_error(p, name + "_min", "a log-spaced grid needs a positive minimum");
  return spaced(lo, hi, static_cast<int>(n), log);
}

Result<PsiSettings> parse_psi(const Config& p) {
  PsiSettings s;
  STUDY_TRY(model_name, p.get_string_or("model", "weibull"));
  auto model = parse_psychometric_model(model_name);
  if (!model) return config_error(p, "model", model.error().message);
  s.model = *model;
  STUDY_TRY(guess, p.get_double_or("guess", 0.5, 0.0, 0.999));
  STUDY_TRY(target, p.get_double_or("target", 0.75, 0.0, 1.0));
  STUDY_TRY(trials, p.get_int_or("trials", 40, 1, 100000));
  STUDY_TRY(alphas, parse_grid(p, "alpha"));
  STUDY_TRY(betas, parse_grid(p, "beta"));
  STUDY_TRY(stimuli, parse_grid(p, "stimulus"));
  s.guess = guess;
  s.target = target;
  s.max_trials = static_cast<int>(trials);
  s.alphas = alphas;
  s.betas = betas;
  s.stimuli = stimuli;
  if (p.contains("lapses")) {
    STUDY_TRY(lapses, p.get_doubles("lapses"));
    s.lapses = lapses;
  }
  return s;
}

Status check_columns(const StudyDesign& d, const std::string& where) {
  std::vector<std::string> names = {"participant", "session", "trial", "block", "track", "response_time_s",
                                    "recorded_unix_ns", d.stimulus_column, d.response_column};
  for (const Factor& f : d.factors) names.push_back(f.name);
  for (const std::string& e : d.extra_columns) names.push_back(e);
  std::set<std::string> seen;
  for (const std::string& n : names) {
    if (!is_identifier(n)) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{}: column name '{}' must use only letters, digits, '_' and '-'", where, n));
    }
    if (!seen.insert(n).second) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{}: the column name '{}' is used twice (factor, stimulus, response, extra "
                                    "columns and the fixed columns participant, session, trial, block, track, "
                                    "response_time_s, recorded_unix_ns must all differ)",
                                    where, n));
    }
  }
  return Status::success();
}

}  // namespace

const char* to_string(Counterbalance c) noexcept {
  switch (c) {
    case Counterbalance::none: return "none";
    case Counterbalance::latin_square: return "latin-square";
    case Counterbalance::abba: return "abba";
  }
  return "?";
}

const char* to_string(ProcedureKind k) noexcept {
  switch (k) {
    case ProcedureKind::constant_stimuli: return "constant";
    case ProcedureKind::staircase: return "staircase";
    case ProcedureKind::quest: return "quest";
    case ProcedureKind::psi: return "psi";
  }
  return "?";
}

int ProcedureDesign::max_trials_per_cell() const {
  switch (kind) {
    case ProcedureKind::constant_stimuli: return static_cast<int>(levels.size()) * repetitions;
    case ProcedureKind::staircase: return tracks * staircase.max_trials;
    case ProcedureKind::quest: return tracks * quest.max_trials;
    case ProcedureKind::psi: return tracks * psi.max_trials;
  }
  return 0;
}

Result<StudyDesign> StudyDesign::load_file(const std::filesystem::path& path) {
  auto text = read_input_file(path, "study design (examples in config/studies/)");
  if (!text) return text.error();
  return parse(*text, path.string());
}

Result<StudyDesign> StudyDesign::parse(const std::string& toml_text, const std::string& source_name) {
  STUDY_TRY(root, Config::parse(toml_text, source_name));
  if (Status s = root.check_keys("top level", {"study", "factor", "blocks", "procedure", "analysis"}); !s) {
    return s.error();
  }
  StudyDesign d;
  d.source_text = toml_text;
  d.source_name = source_name;

  STUDY_TRY(study, root.table("study"));
  if (Status s = study.check_keys("study", {"name", "kind", "description", "seed", "stimulus",
                                                  "stimulus_unit", "response", "extra_columns"});
      !s) {
    return s.error();
  }
  STUDY_TRY(name, study.get_string("name"));
  if (!is_identifier(name)) {
    return config_error(study, "name", "must use only letters, digits, '_' and '-' (it becomes part of file names)");
  }
  d.name = name;
  STUDY_TRY(kind, study.get_string_or("kind", "psychometric"));
  if (kind != "psychometric" && kind != "completion-time") {
    return config_error(study, "kind", "must be \"psychometric\" (threshold fits) or \"completion-time\" (timed tasks)");
  }
  d.kind = kind;
  STUDY_TRY(description, study.get_string_or("description", ""));
  d.description = description;
  STUDY_TRY(seed, study.get_int_or("seed", 1, 0, INT64_MAX));
  d.seed = static_cast<std::uint64_t>(seed);
  STUDY_TRY(stimulus, study.get_string_or("stimulus", "stimulus"));
  STUDY_TRY(unit, study.get_string_or("stimulus_unit", ""));
  STUDY_TRY(response, study.get_string_or("response", "correct"));
  d.stimulus_column = stimulus;
  d.stimulus_unit = unit;
  d.response_column = response;
  if (study.contains("extra_columns")) {
    STUDY_TRY(extra, study.get_strings("extra_columns"));
    d.extra_columns = extra;
  }

  if (root.contains("factor")) {
    STUDY_TRY(factors, root.tables("factor"));
    for (const Config& f : factors) {
      if (Status s = f.check_keys("[factor]", {"name", "levels"}); !s) return s.error();
      STUDY_TRY(fname, f.get_string("name"));
      auto levels = f.get_strings("levels");
      if (!levels) {
        return config_error(f, "levels",
                            "must be a list of strings (quote numbers: levels = [\"1\", \"2\"]): " +
                                levels.error().message);
      }
      if (levels->empty()) return config_error(f, "levels", "needs at least one level");
      std::set<std::string> unique(levels->begin(), levels->end());
      if (unique.size() != levels->size()) return config_error(f, "levels", "lists a level twice");
      for (const std::string& l : *levels) {
        if (l.empty() || l.find_first_of(",\"\n=") != std::string::npos) {
          return config_error(f, "levels", fmt::format("level '{}' must be non-empty and free of , \" = and line "
                                                       "breaks",
                                                       l));
        }
      }
      d.factors.push_back({fname, *levels});
    }
  }

  if (root.contains("blocks")) {
    STUDY_TRY(blocks, root.table("blocks"));
    if (Status s = blocks.check_keys("blocks", {"by", "counterbalance", "group"}); !s) return s.error();
    STUDY_TRY(by, blocks.get_string("by"));
    const auto factor = std::find_if(d.factors.begin(), d.factors.end(), [&](const Factor& f) { return f.name == by; });
    if (factor == d.factors.end()) {
      return config_error(blocks, "by", fmt::format("'{}' is not one of the [[factor]] names", by));
    }
    d.block_factor = by;
    if (blocks.contains("group")) {
      STUDY_TRY(groups, blocks.tables("group"));
      std::set<std::string> used;
      for (const Config& g : groups) {
        if (Status s = g.check_keys("[blocks.group]", {"name", "levels"}); !s) return s.error();
        STUDY_TRY(gname, g.get_string("name"));
        STUDY_TRY(glevels, g.get_strings("levels"));
        for (const std::string& l : glevels) {
          if (std::find(factor->levels.begin(), factor->levels.end(), l) == factor->levels.end()) {
            return config_error(g, "levels", fmt::format("'{}' is not a level of factor '{}'", l, by));
          }
          if (!used.insert(l).second) return config_error(g, "levels", fmt::format("level '{}' is in two groups", l));
        }
        if (glevels.empty()) return config_error(g, "levels", "a block group needs at least one level");
        d.block_groups.push_back({gname, glevels});
      }
      if (used.size() != factor->levels.size()) {
        return config_error(blocks, "group", fmt::format("every level of '{}' must be in one group", by));
      }
    } else {
      for (const std::string& l : factor->levels) d.block_groups.push_back({l, {l}});
    }
    STUDY_TRY(cb, blocks.get_string_or("counterbalance", "none"));
    if (cb == "none") {
      d.counterbalance = Counterbalance::none;
    } else if (cb == "latin-square") {
      d.counterbalance = Counterbalance::latin_square;
    } else if (cb == "abba") {
      d.counterbalance = Counterbalance::abba;
    } else {
      return config_error(blocks, "counterbalance", "must be \"none\", \"latin-square\" or \"abba\"");
    }
  }

  STUDY_TRY(proc, root.table("procedure"));
  STUDY_TRY(type, proc.get_string("type"));
  ProcedureDesign& pd = d.procedure;
  const std::string where = proc.where("type");
  if (type == "constant") {
    if (Status s = proc.check_keys("procedure", {"type", "levels", "repetitions"}); !s) return s.error();
    pd.kind = ProcedureKind::constant_stimuli;
    STUDY_TRY(levels, proc.get_doubles("levels"));
    if (levels.empty()) return config_error(proc, "levels", "needs at least one stimulus level");
    STUDY_TRY(reps, proc.get_int_or("repetitions", 1, 1, 100000));
    pd.levels = levels;
    pd.repetitions = static_cast<int>(reps);
  } else {
    STUDY_TRY(tracks, proc.get_int_or("interleave", 1, 1, 64));
    pd.tracks = static_cast<int>(tracks);
    if (proc.contains("starts")) {
      STUDY_TRY(starts, proc.get_doubles("starts"));
      if (static_cast<int>(starts.size()) != pd.tracks) {
        return config_error(proc, "starts", fmt::format("lists {} starts for {} interleaved tracks", starts.size(),
                                                        pd.tracks));
      }
      pd.starts = starts;
    }
    if (type == "staircase" || type == "weighted-staircase") {
      const bool weighted = type == "weighted-staircase";
      if (Status s = proc.check_keys("procedure",
                                     {"type", "start", "starts", "interleave", "up", "down", "step", "steps",
                                      "step_scale", "min", "max", "trials", "reversals", "discard_reversals",
                                      "target"});
          !s) {
        return s.error();
      }
      pd.kind = ProcedureKind::staircase;
      STUDY_TRY(sc, parse_staircase(proc, weighted));
      if (pd.starts.empty()) {
        STUDY_TRY(start, proc.get_double("start"));
        sc.start = start;
      } else {
        sc.start = pd.starts[0];
      }
      pd.staircase = sc;
      for (double st : pd.starts.empty() ? std::vector<double>{sc.start} : pd.starts) {
        StaircaseSettings check = sc;
        check.start = st;
        if (Status s = validate(check, where); !s) return s.error();
      }
    } else if (type == "quest") {
      if (Status s = proc.check_keys("procedure",
                                     {"type", "starts", "interleave", "model", "beta", "guess", "lapse", "target",
                                      "prior_mean", "prior_sd", "min", "max", "grid_points", "trials", "stop_sd"});
          !s) {
        return s.error();
      }
      pd.kind = ProcedureKind::quest;
      STUDY_TRY(q, parse_quest(proc));
      if (Status s = validate(q, where); !s) return s.error();
      pd.quest = q;
    } else if (type == "psi") {
      if (Status s = proc.check_keys("procedure",
                                     {"type", "interleave", "model", "guess", "target", "trials", "alpha",
                                      "alpha_min", "alpha_max", "alpha_points", "alpha_log", "beta", "beta_min",
                                      "beta_max", "beta_points", "beta_log", "stimulus", "stimulus_min",
                                      "stimulus_max", "stimulus_points", "stimulus_log", "lapses"});
          !s) {
        return s.error();
      }
      pd.kind = ProcedureKind::psi;
      STUDY_TRY(ps, parse_psi(proc));
      if (Status s = validate(ps, where); !s) return s.error();
      pd.psi = ps;
    } else {
      return config_error(proc, "type",
                          fmt::format("unknown procedure '{}': choose constant, staircase, weighted-staircase, quest "
                                      "or psi",
                                      type));
    }
  }

  if (root.contains("analysis")) {
    STUDY_TRY(a, root.table("analysis"));
    if (Status s = a.check_keys("analysis", {"model", "guess", "lapse", "lapse_max", "threshold"}); !s) {
      return s.error();
    }
    STUDY_TRY(model_name, a.get_string_or("model", "weibull"));
    auto model = parse_psychometric_model(model_name);
    if (!model) return config_error(a, "model", model.error().message);
    d.analysis.model = *model;
    STUDY_TRY(guess, a.get_double_or("guess", 0.5, 0.0, 0.999));
    STUDY_TRY(threshold, a.get_double_or("threshold", 0.75, 0.0, 1.0));
    d.analysis.guess = guess;
    d.analysis.threshold = threshold;
    if (a.contains("lapse") && a.contains("lapse_max")) {
      return config_error(a, "lapse_max", "give either a fixed lapse or lapse_max (a free lapse), not both");
    }
    if (a.contains("lapse_max")) {
      STUDY_TRY(lm, a.get_double_or("lapse_max", 0.06, 0.0, 0.5));
      d.analysis.lapse_free = true;
      d.analysis.lapse_max = lm;
    } else {
      STUDY_TRY(l, a.get_double_or("lapse", 0.0, 0.0, 0.5));
      d.analysis.lapse = l;
    }
  } else if (pd.kind == ProcedureKind::quest) {
    d.analysis.guess = pd.quest.guess;
    d.analysis.threshold = pd.quest.target;
  }
  if (Status s = check_columns(d, source_name); !s) return s.error();
  return d;
}

std::vector<ConditionCell> condition_cells(const StudyDesign& design) {
  std::vector<ConditionCell> cells(1);
  for (const Factor& f : design.factors) {
    std::vector<ConditionCell> next;
    for (const ConditionCell& c : cells) {
      for (const std::string& level : f.levels) {
        ConditionCell n = c;
        n.levels.push_back(level);
        next.push_back(std::move(n));
      }
    }
    cells = std::move(next);
  }
  for (std::size_t i = 0; i < cells.size(); ++i) {
    cells[i].index = static_cast<int>(i);
    std::string label;
    for (std::size_t f = 0; f < design.factors.size(); ++f) {
      label += (f ? "," : "") + design.factors[f].name + "=" + cells[i].levels[f];
    }
    cells[i].label = label.empty() ? "all" : label;
  }
  return cells;
}

std::vector<std::vector<int>> williams_latin_square(int k) {
  if (k <= 0) return {};
  // First row 0, 1, k-1, 2, k-2, ...; the others add r modulo k.
  std::vector<int> first;
  for (int j = 0, lo = 1, hi = k - 1; j < k; ++j) {
    if (j == 0) {
      first.push_back(0);
    } else if (j % 2 == 1) {
      first.push_back(lo++);
    } else {
      first.push_back(hi--);
    }
  }
  std::vector<std::vector<int>> rows;
  for (int r = 0; r < k; ++r) {
    std::vector<int> row;
    for (int v : first) row.push_back((v + r) % k);
    rows.push_back(row);
  }
  if (k % 2 == 1) {
    for (int r = 0; r < k; ++r) rows.emplace_back(rows[static_cast<std::size_t>(r)].rbegin(),
                                                   rows[static_cast<std::size_t>(r)].rend());
  }
  return rows;
}

std::vector<int> block_order(const StudyDesign& design, int participant_index) {
  const int k = std::max<int>(1, static_cast<int>(design.block_groups.size()));
  std::vector<int> order(static_cast<std::size_t>(k));
  for (int i = 0; i < k; ++i) order[static_cast<std::size_t>(i)] = i;
  if (design.block_factor.empty()) return order;
  const int p = std::max(participant_index, 0);
  switch (design.counterbalance) {
    case Counterbalance::none: break;
    case Counterbalance::latin_square: {
      const auto rows = williams_latin_square(k);
      order = rows[static_cast<std::size_t>(p) % rows.size()];
      break;
    }
    case Counterbalance::abba:
      if (p % 4 == 1 || p % 4 == 2) std::reverse(order.begin(), order.end());
      break;
  }
  return order;
}

std::vector<PlannedTrial> plan_trials(const StudyDesign& design, int participant_index,
                                      std::uint64_t participant_seed) {
  const std::vector<ConditionCell> cells = condition_cells(design);
  int block_factor_index = -1;
  for (std::size_t f = 0; f < design.factors.size(); ++f) {
    if (design.factors[f].name == design.block_factor) block_factor_index = static_cast<int>(f);
  }
  Rng rng(mix_seed(participant_seed, kPlanStream));
  std::vector<PlannedTrial> plan;
  const std::vector<int> order = block_order(design, participant_index);
  for (std::size_t b = 0; b < order.size(); ++b) {
    std::string label;
    const std::vector<std::string>* members = nullptr;
    if (block_factor_index >= 0) {
      const StudyDesign::BlockGroup& group = design.block_groups[static_cast<std::size_t>(order[b])];
      label = group.label;
      members = &group.levels;
    }
    std::vector<PlannedTrial> block;
    for (const ConditionCell& c : cells) {
      if (members != nullptr && std::find(members->begin(), members->end(),
                                          c.levels[static_cast<std::size_t>(block_factor_index)]) == members->end()) {
        continue;
      }
      if (design.procedure.kind == ProcedureKind::constant_stimuli) {
        for (double level : design.procedure.levels) {
          for (int r = 0; r < design.procedure.repetitions; ++r) {
            block.push_back({static_cast<int>(b), label, c.index, level});
          }
        }
      } else {
        for (int t = 0; t < design.procedure.max_trials_per_cell(); ++t) {
          block.push_back({static_cast<int>(b), label, c.index, std::numeric_limits<double>::quiet_NaN()});
        }
      }
    }
    rng.shuffle(block.begin(), block.end());
    plan.insert(plan.end(), block.begin(), block.end());
  }
  return plan;
}

std::vector<std::unique_ptr<Procedure>> make_procedures(const StudyDesign& design) {
  const ProcedureDesign& pd = design.procedure;
  std::vector<std::unique_ptr<Procedure>> out;
  for (std::size_t c = 0; c < condition_cells(design).size(); ++c) {
    if (pd.kind == ProcedureKind::constant_stimuli) {
      out.push_back(nullptr);
      continue;
    }
    std::vector<std::unique_ptr<Procedure>> tracks;
    for (int t = 0; t < pd.tracks; ++t) {
      const bool has_start = !pd.starts.empty();
      const double start = has_start ? pd.starts[static_cast<std::size_t>(t)] : 0.0;
      switch (pd.kind) {
        case ProcedureKind::staircase: {
          StaircaseSettings s = pd.staircase;
          if (has_start) s.start = start;
          tracks.push_back(std::make_unique<Staircase>(s));
          break;
        }
        case ProcedureKind::quest: {
          QuestSettings q = pd.quest;
          if (has_start) q.prior_mean = start;
          tracks.push_back(std::make_unique<Quest>(q));
          break;
        }
        case ProcedureKind::psi: tracks.push_back(std::make_unique<Psi>(pd.psi)); break;
        case ProcedureKind::constant_stimuli: break;
      }
    }
    out.push_back(std::make_unique<Interleaved>(std::move(tracks)));
  }
  return out;
}

std::uint64_t design_hash(const std::string& text) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (unsigned char c : text) {
    h ^= c;
    h *= 0x100000001b3ull;
  }
  return h;
}

}  // namespace proprio::study
