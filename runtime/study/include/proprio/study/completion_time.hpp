#pragma once
// Analysis of timed-task studies (design kind "completion-time", e.g. the
// peg-in-hole sample; Lee 2021 §3.3.3, Fig. 3.8):
//   * each trial's time normalised by that participant's mean time over the
//     analysed trials (so fast and slow participants weigh the same),
//   * mean and sample SD of the normalised time per setting,
//   * one-way repeated-measures ANOVA with the Greenhouse-Geisser correction,
//   * pairwise paired t-tests with Bonferroni and Holm adjustment,
//   * an SVG of the normalised time per setting (mean +- SD) with each
//     participant's profile beside it.
//
// The repeated-measures unit. The thesis's F(2.018, 78.684) with epsilon
// 0.672 has 117 = 3 x 39 error dfs: its subjects were the 40 rounds (10
// participants x 4 analysed repetitions, each round holding every setting
// once). `Unit::round` reproduces that; `Unit::participant` (participant
// means, 9 x 3 dfs for 10 people) is the conservative textbook choice. Both
// are reported; `unit` picks the one the post-hoc tests use.
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/study/csv.hpp"
#include "proprio/study/statistics.hpp"

namespace proprio::study {

struct CompletionTimeOptions {
  std::string time_column = "completion_time_s";
  std::string setting_column = "setting";
  std::string round_column = "round";                  // the repetition each trial belongs to
  std::string familiarisation_column = "familiarisation";  // 1 = not analysed; absent: all analysed
  std::string participant_column = "participant";
  enum class Unit { round, participant } unit = Unit::round;
  // Folder analyses: sessions with trials missing from their plan are refused
  // unless this is set (SessionFileChecker, analysis.hpp).
  bool allow_incomplete = false;
};

struct CompletionTimeTrial {
  std::string participant;
  std::string round;
  std::string setting;
  double time_s = 0.0;
  double normalised = 0.0;
};

struct SettingSummary {
  std::string setting;
  int n = 0;               // analysed trials
  double mean = 0.0, sd = 0.0;  // of the normalised time over those trials
  double mean_time_s = 0.0;     // raw, for reference
};

struct PairwiseComparison {
  std::string a, b;
  PairedT test;
  double p_bonferroni = 1.0, p_holm = 1.0;
};

struct CompletionTimeAnalysis {
  std::vector<std::string> files;
  std::vector<std::string> participants;  // sorted
  std::vector<std::string> settings;      // sorted
  std::vector<CompletionTimeTrial> trials;  // analysed trials only
  std::map<std::string, double> participant_mean_time_s;
  std::vector<SettingSummary> summary;     // one per setting, in `settings` order
  // profile[p][s]: participant p's mean normalised time in setting s.
  std::vector<std::vector<double>> profile;
  RepeatedMeasuresAnova anova_rounds;        // subjects = participant x round
  RepeatedMeasuresAnova anova_participants;  // subjects = participants (their means)
  CompletionTimeOptions::Unit unit = CompletionTimeOptions::Unit::round;
  std::vector<PairwiseComparison> pairwise;  // on `unit`
  int excluded_trials = 0;                   // familiarisation rows skipped
  std::vector<std::string> notes;            // incomplete sessions analysed anyway, ...
};

// From rows already read (one table per session file).
Result<CompletionTimeAnalysis> analyze_completion_times(const std::vector<CsvTable>& tables,
                                                        const CompletionTimeOptions& options = {});
// Every session in `dir` whose sidecar says kind "completion-time".
Result<CompletionTimeAnalysis> analyze_completion_time_study(const std::filesystem::path& dir,
                                                             const CompletionTimeOptions& options = {});

std::string completion_time_svg(const CompletionTimeAnalysis& a, const std::string& title);
std::string completion_time_json(const CompletionTimeAnalysis& a);
std::string completion_time_text(const CompletionTimeAnalysis& a);  // the tables a paper reports
// summary.json, normalised_times.csv, anova.txt, normalised_time.svg; returns the files written.
Result<std::vector<std::filesystem::path>> write_completion_time_report(const CompletionTimeAnalysis& a,
                                                                        const std::filesystem::path& out_dir,
                                                                        const std::string& title);

// The kind a session sidecar declares ("psychometric" when it has none).
Result<std::string> sidecar_kind(const std::filesystem::path& sidecar_json);

}  // namespace proprio::study
