#pragma once
// Whole-study analysis of a folder of per-trial CSVs written by Session: per
// participant and condition, a psychometric fit with bootstrap CIs and the
// linear-interpolation threshold; per condition, a fit to the pooled data;
// across conditions, repeated-measures ANOVA (Greenhouse-Geisser) on the
// participants' thresholds with Holm-corrected paired t-tests, and at each
// stimulus level one-way and repeated-measures ANOVAs on the proportion
// correct (the thesis's analysis, section 2.4.3). Columns come from each
// file's sidecar unless the options name them.
#include <cstdint>
#include <filesystem>
#include <map>
#include <set>
#include <optional>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/study/csv.hpp"
#include "proprio/study/psychometric.hpp"
#include "proprio/study/statistics.hpp"

namespace proprio::study {

enum class ThresholdMethod { fit, interpolate };

struct StudyAnalysisOptions {
  // Overrides; unset values come from the sidecars' "analysis" section.
  std::optional<PsychometricModel> model;
  std::optional<double> guess;
  std::optional<double> lapse;      // fixed lapse
  std::optional<double> lapse_max;  // free lapse in [0, lapse_max]
  std::optional<double> threshold;  // proportion correct
  // Column overrides (empty: from the sidecar). With all three given, CSVs
  // without a sidecar are read too.
  std::string stimulus_column;
  std::string response_column;
  std::vector<std::string> condition_columns;
  bool conditions_given = false;    // condition_columns set explicitly (possibly to none)
  int bootstrap = 999;              // 0: no intervals
  std::uint64_t seed = 1;
  double coverage = 0.95;
  // Which per-participant threshold the between-condition statistics use.
  ThresholdMethod method = ThresholdMethod::fit;
  // Analyse sessions with trials missing from their plan (unfinished or
  // damaged) instead of refusing them; the notes then name what is missing.
  bool allow_incomplete = false;
};

struct CellAnalysis {
  std::string participant;          // "all" for the pooled fits
  std::string condition;            // "haptics=none", or "all"
  std::vector<StimulusLevel> data;  // pooled by level
  std::optional<PsychometricFit> fit;
  std::string fit_error;            // why there is no fit or threshold
  double threshold = 0.0;           // NaN when the fit has none
  std::optional<ConfidenceInterval> percentile_ci, bca_ci;
  double slope = 0.0;               // dpsi/dx at the threshold
  double interpolated_threshold = 0.0;  // NaN when the data never cross the criterion
  std::string interpolation_error;
};

struct ConditionComparison {
  std::string a, b;
  PairedT test;
  double p_holm = 1.0;
  double p_bonferroni = 1.0;
};

struct LevelAnova {
  double level = 0.0;
  std::optional<OneWayAnova> one_way;              // conditions as independent groups (as the thesis did)
  std::optional<RepeatedMeasuresAnova> repeated;   // participants as the repeated factor
};

struct StudyAnalysis {
  std::vector<std::filesystem::path> files;
  std::string stimulus_column, stimulus_unit, response_column;
  std::vector<std::string> condition_columns;
  std::vector<std::string> participants, conditions;
  FitOptions fit_options;
  double criterion = 0.75;
  ThresholdMethod method = ThresholdMethod::fit;
  int bootstrap = 0;
  std::uint64_t seed = 1;
  double coverage = 0.95;
  std::vector<CellAnalysis> cells;   // per participant x condition
  std::vector<CellAnalysis> pooled;  // per condition, all participants
  // On the per-participant thresholds (participants with all conditions).
  std::optional<RepeatedMeasuresAnova> threshold_anova;
  std::vector<std::string> anova_participants;
  std::vector<ConditionComparison> comparisons;
  std::vector<LevelAnova> level_anovas;
  std::vector<std::string> notes;    // skipped files, missing cells, ...
};

// The checks every analysis of session files makes before it counts a trial:
// each (participant, session, trial) in one row only, each session in one
// file only, and every trial of the session's plan present (from the sidecar:
// planned_trials, status). Refusals name the file and line; with
// allow_incomplete, missing trials become a note instead.
class SessionFileChecker {
 public:
  explicit SessionFileChecker(bool allow_incomplete) : allow_incomplete_(allow_incomplete) {}
  // `sidecar` may be empty (a CSV without one: only duplicates are checked).
  Status add(const CsvTable& table, const std::filesystem::path& sidecar);
  // After the last add(): the missing-trials verdict (an error, or with
  // allow_incomplete a note per incomplete session).
  Status finish(std::vector<std::string>& notes) const;

 private:
  struct Expected {
    std::string file, status;
    long long trials = 0;
    std::set<long long> present;
  };
  bool allow_incomplete_;
  std::vector<Expected> expected_;
  std::map<std::string, std::string> trial_at_;    // "participant\x1fsession\x1ftrial" -> file:line
  std::map<std::string, std::string> session_in_;  // "participant\x1fsession" -> file
};

Result<StudyAnalysis> analyze_study(const std::filesystem::path& dir, const StudyAnalysisOptions& options);

// The analysis as JSON text (thresholds, CIs, fits, statistics).
std::string study_analysis_json(const StudyAnalysis& analysis);
// Writes summary.json, thresholds.csv and SVG plots (one per participant, one
// with the pooled fits) into out_dir; returns the files written.
Result<std::vector<std::filesystem::path>> write_study_report(const StudyAnalysis& analysis,
                                                              const std::filesystem::path& out_dir);

// Aggregates per-trial rows into (level, correct, trials).
Result<std::vector<StimulusLevel>> levels_from_trials(const std::vector<double>& stimulus,
                                                      const std::vector<int>& correct);

}  // namespace proprio::study
