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
#include <optional>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
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
