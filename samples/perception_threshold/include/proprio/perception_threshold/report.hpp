#pragma once
// The thesis's analysis of the perception-threshold study (section 2.4.3 and
// Figs. 2.6, 2.8 and 2.9), on a folder of session CSVs:
//  - the detection threshold per haptic condition: the 75% point of a Weibull
//    fit for "none" (with a bootstrap CI) and the linear-interpolation
//    threshold for the two haptic conditions, whose curves need not start at
//    50% (as the thesis did); pooled and per participant;
//  - the "maximum allowable tracking error": the offset at which the sphere
//    with the haptic feedback is chosen half the time when the feedback is on
//    the false sphere (Fig. 2.9);
//  - one-way ANOVA across haptic conditions at each offset (as the thesis
//    reports) and the repeated-measures ANOVA (Greenhouse-Geisser) that suits
//    the within-participant design better, on the per-participant thresholds.
#include <filesystem>
#include <string>
#include <vector>

#include "proprio/study/analysis.hpp"

namespace proprio::perception {

struct PerceptionReportOptions {
  int bootstrap = 999;
  std::uint64_t seed = 1;
};

struct ChoiceCurve {
  std::string condition;                    // "true_sphere" or "false_sphere"
  std::vector<study::StimulusLevel> data;   // trials choosing the haptic sphere, per offset
};

struct PerceptionReport {
  study::StudyAnalysis analysis;            // proportion correct vs offset, per participant x condition
  // The thesis's thresholds, pooled over participants (cm; NaN when the data
  // never cross 75%), and the none condition's Weibull CI.
  double threshold_none_cm = 0, threshold_true_sphere_cm = 0, threshold_false_sphere_cm = 0;
  std::optional<study::ConfidenceInterval> threshold_none_ci;
  std::vector<ChoiceCurve> chose_haptic;    // pooled
  double max_allowable_error_cm = 0;        // NaN when the false-sphere curve never crosses 50%
  std::vector<std::pair<std::string, double>> max_allowable_error_by_participant;
  std::string summary_markdown;
};

Result<PerceptionReport> analyze_perception_study(const std::filesystem::path& dir,
                                                  const PerceptionReportOptions& options);
// summary.md, summary.json, thresholds.csv, the psychometric plots
// (all_participants.svg is the thesis's Fig. 2.8) and chose_haptic.svg (Fig. 2.9).
Result<std::vector<std::filesystem::path>> write_perception_report(const PerceptionReport& report,
                                                                   const std::filesystem::path& out_dir);

}  // namespace proprio::perception
