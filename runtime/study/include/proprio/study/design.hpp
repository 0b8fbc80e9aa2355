#pragma once
// An experiment's design, read from a TOML file (format: docs/study.md):
// within-participant factors crossed into condition cells, blocks (one per
// level of a blocking factor) whose order is counterbalanced across
// participants, and the procedure that picks each trial's stimulus (constant
// stimuli, or an adaptive procedure per cell).
//
// A participant's trial plan is a pure function of the design, the
// participant's index and the seed: the same inputs give the same plan on
// every platform (Fisher-Yates over mt19937_64 through proprio::Rng).
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/study/procedure.hpp"
#include "proprio/study/psychometric.hpp"

namespace proprio::study {

struct Factor {
  std::string name;
  std::vector<std::string> levels;
};

enum class Counterbalance {
  none,          // every participant gets the blocks in file order
  latin_square,  // balanced (Williams) Latin square: row = participant index mod rows
  abba,          // forward, reversed, reversed, forward, ... by participant index
};
const char* to_string(Counterbalance c) noexcept;

enum class ProcedureKind { constant_stimuli, staircase, quest, psi };
const char* to_string(ProcedureKind k) noexcept;

struct ProcedureDesign {
  ProcedureKind kind = ProcedureKind::constant_stimuli;
  // Constant stimuli: every level `repetitions` times per cell.
  std::vector<double> levels;
  int repetitions = 1;
  // Adaptive: one procedure per track, `tracks` tracks per cell interleaved
  // (starts[i] is track i's start where the procedure has one).
  int tracks = 1;
  std::vector<double> starts;
  StaircaseSettings staircase;
  QuestSettings quest;
  PsiSettings psi;
  // Trials per cell an adaptive procedure may use (its track trials summed).
  int max_trials_per_cell() const;
};

struct AnalysisDesign {
  PsychometricModel model = PsychometricModel::weibull;
  double guess = 0.5;
  bool lapse_free = false;
  double lapse = 0.0;
  double lapse_max = 0.06;
  double threshold = 0.75;  // proportion correct that defines the threshold
};

struct StudyDesign {
  std::string name;                 // [A-Za-z0-9_-]+, used in file names
  std::string description;
  // Which analysis `proprio study analyze` runs: "psychometric" (fits and
  // thresholds) or "completion-time" (timed tasks such as peg-in-hole).
  std::string kind = "psychometric";
  std::uint64_t seed = 1;           // the study's seed; participants get mix_seed(seed, index)
  std::string stimulus_column = "stimulus";
  std::string stimulus_unit;        // as the experimenter states it (e.g. "cm"), for reports
  std::string response_column = "correct";
  std::vector<std::string> extra_columns;  // further per-trial values the caller supplies
  std::vector<Factor> factors;      // within-participant, crossed
  std::string block_factor;         // empty: one block holding every cell
  // The blocks: each holds the cells whose block-factor level is in `levels`
  // (by default one block per level; [[blocks.group]] can pool levels, e.g.
  // two haptic conditions interleaved in one block).
  struct BlockGroup {
    std::string label;
    std::vector<std::string> levels;
  };
  std::vector<BlockGroup> block_groups;
  Counterbalance counterbalance = Counterbalance::none;
  ProcedureDesign procedure;
  AnalysisDesign analysis;
  std::string source_text;          // the TOML as read, copied into each sidecar
  std::string source_name;

  static Result<StudyDesign> load_file(const std::filesystem::path& path);
  static Result<StudyDesign> parse(const std::string& toml_text, const std::string& source_name = "<design>");
};

// One combination of factor levels.
struct ConditionCell {
  int index = 0;
  std::vector<std::string> levels;  // one per factor, in factor order
  std::string label;                // "haptics=none,exp=1"; "all" without factors
};
std::vector<ConditionCell> condition_cells(const StudyDesign& design);

// Balanced Latin square (Williams 1949): each condition follows every other
// equally often. k rows for even k, 2k rows (each row and its mirror) for odd k.
std::vector<std::vector<int>> williams_latin_square(int k);
// Block order (indices into block_groups) for a participant.
std::vector<int> block_order(const StudyDesign& design, int participant_index);

// One slot of a participant's plan. Constant stimuli fix the stimulus;
// adaptive slots name the cell and ask its procedure when they come up (a slot
// whose procedure has finished is skipped).
struct PlannedTrial {
  int block = 0;                    // position of the block in this participant's order
  std::string block_label;          // the block group's label ("" without blocks)
  int cell = 0;
  double stimulus = 0.0;            // constant stimuli only
};
std::vector<PlannedTrial> plan_trials(const StudyDesign& design, int participant_index, std::uint64_t participant_seed);

// The per-cell adaptive procedures, fresh (nullptr entries for constant stimuli).
std::vector<std::unique_ptr<Procedure>> make_procedures(const StudyDesign& design);

// 64-bit FNV-1a of the text: the sidecar records it so a resume can tell the
// design was edited since the session started.
std::uint64_t design_hash(const std::string& text);

}  // namespace proprio::study
