// Whole-study analysis on sessions run by simulated observers whose
// thresholds are known and differ between conditions.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "proprio/core/file_io.hpp"
#include "proprio/core/random.hpp"
#include "proprio/study/analysis.hpp"
#include "proprio/study/session.hpp"
#include "study/simulated_observer.hpp"

namespace proprio::study {
namespace {

namespace fs = std::filesystem;
using testing::SimulatedObserver;

const char* kDesign = R"(
[study]
name = "analysis-test"
seed = 3
stimulus = "offset_cm"
stimulus_unit = "cm"
[[factor]]
name = "haptics"
levels = ["none", "true_sphere"]
[blocks]
by = "haptics"
counterbalance = "abba"
[procedure]
type = "constant"
levels = [1.5, 3.0, 4.5, 6.0, 7.5, 9.0]
repetitions = 30
[analysis]
model = "weibull"
guess = 0.5
lapse = 0.0
threshold = 0.75
)";

// Observer alpha per condition: the haptic cue halves the threshold.
double alpha_for(const std::string& condition) { return condition == "true_sphere" ? 3.0 : 6.0; }

TEST(StudyAnalysis, RecoversKnownThresholdsAndTheirDifference) {
  auto d = StudyDesign::parse(kDesign);
  ASSERT_TRUE(d) << d.error().message;
  const fs::path dir = fs::temp_directory_path() / ("proprio_study_analysis_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const int participants = 4;
  for (int p = 0; p < participants; ++p) {
    SessionOptions o;
    o.out_dir = dir;
    o.participant = "P" + std::to_string(p + 1);
    o.participant_index = p;
    o.sync_each_trial = false;  // simulated: no need to wait for the disk
    auto s = Session::open(*d, o);
    ASSERT_TRUE(s) << s.error().message;
    while (!s->finished()) {
      auto t = s->next_trial();
      ASSERT_TRUE(t);
      SimulatedObserver obs;
      obs.params = {alpha_for(t->levels[0]), 3.0, 0.5, 0.0};
      obs.seed = mix_seed(500, static_cast<std::uint64_t>(p));
      Response r;
      r.correct = obs.respond(t->stimulus, static_cast<std::uint64_t>(t->index));
      ASSERT_TRUE(s->record(*t, r));
    }
  }
  StudyAnalysisOptions opt;
  opt.bootstrap = 100;
  auto a = analyze_study(dir, opt);
  ASSERT_TRUE(a) << a.error().message;
  EXPECT_EQ(a->participants.size(), 4u);
  ASSERT_EQ(a->conditions, (std::vector<std::string>{"haptics=none", "haptics=true_sphere"}));
  EXPECT_EQ(a->stimulus_unit, "cm");
  ASSERT_EQ(a->cells.size(), 8u);
  int covered = 0;
  for (const CellAnalysis& c : a->cells) {
    const double truth = alpha_for(c.condition == "haptics=none" ? "none" : "true_sphere") *
                         std::pow(std::log(2.0), 1.0 / 3.0);
    ASSERT_TRUE(std::isfinite(c.threshold)) << c.fit_error;
    EXPECT_NEAR(c.threshold, truth, 0.3 * truth) << c.participant << " " << c.condition;
    ASSERT_TRUE(c.percentile_ci);
    covered += c.percentile_ci->lower <= truth && truth <= c.percentile_ci->upper ? 1 : 0;
    EXPECT_TRUE(std::isfinite(c.interpolated_threshold)) << c.interpolation_error;
  }
  EXPECT_GE(covered, 6) << "95% intervals should cover most of 8 known thresholds";
  ASSERT_EQ(a->pooled.size(), 2u);
  EXPECT_LT(a->pooled[1].threshold, a->pooled[0].threshold);
  // A halved threshold in every participant: the ANOVA sees it.
  ASSERT_TRUE(a->threshold_anova);
  EXPECT_LT(a->threshold_anova->p, 0.01);
  ASSERT_EQ(a->comparisons.size(), 1u);
  EXPECT_GT(a->comparisons[0].test.mean_difference, 0.0);
  EXPECT_FALSE(a->level_anovas.empty());

  auto files = write_study_report(*a, dir / "report");
  ASSERT_TRUE(files) << files.error().message;
  EXPECT_EQ(files->size(), 2u + 1u + 4u);
  for (const fs::path& f : *files) EXPECT_GT(fs::file_size(f), 100u) << f;
  // The report's own CSV has no sidecar and is skipped on a second run.
  auto again = analyze_study(dir, [] {
    StudyAnalysisOptions o;
    o.bootstrap = 0;
    return o;
  }());
  ASSERT_TRUE(again) << again.error().message;
  EXPECT_EQ(again->files.size(), 4u);
  EXPECT_DOUBLE_EQ(again->cells[0].threshold, a->cells[0].threshold);

  // A damaged row is reported with its file and line.
  const fs::path first = a->files.front();
  std::ofstream(first, std::ios::app) << "P1,1,999,0,none,0,not-a-number,1,,1\n";
  auto broken = analyze_study(dir, opt);
  ASSERT_FALSE(broken);
  EXPECT_NE(broken.error().message.find(first.filename().string() + ":"), std::string::npos)
      << broken.error().message;
  fs::remove_all(dir);
}

TEST(StudyAnalysis, ExplainsAnEmptyOrMissingFolder) {
  auto missing = analyze_study("/nonexistent/proprio", {});
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("not a folder"), std::string::npos);
  const fs::path dir = fs::temp_directory_path() / ("proprio_study_empty_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  auto empty = analyze_study(dir, {});
  ASSERT_FALSE(empty);
  EXPECT_NE(empty.error().message.find("no trials"), std::string::npos);
  fs::remove_all(dir);
}

// Sessions whose answers follow a fixed rule: everyone correct from 7.5 cm
// up (100 % there, in both conditions), alternating below.
fs::path rule_study(const std::string& name, int participants) {
  auto d = StudyDesign::parse(kDesign);
  EXPECT_TRUE(d) << d.error().message;
  const fs::path dir = fs::temp_directory_path() / ("proprio_study_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  for (int p = 0; p < participants; ++p) {
    SessionOptions o;
    o.out_dir = dir;
    o.participant = "P" + std::to_string(p + 1);
    o.participant_index = p;
    o.sync_each_trial = false;
    auto s = Session::open(*d, o);
    EXPECT_TRUE(s) << s.error().message;
    while (s && !s->finished()) {
      auto t = s->next_trial();
      Response r;
      r.correct = t->stimulus >= 7.5 || (t->index + p) % 3 != 0;
      EXPECT_TRUE(s->record(*t, r));
    }
  }
  return dir;
}

std::vector<std::string> lines_of(const fs::path& p) {
  std::ifstream in(p);
  std::vector<std::string> out;
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

void write_lines(const fs::path& p, const std::vector<std::string>& lines) {
  std::ofstream out(p, std::ios::trunc);
  for (const std::string& l : lines) out << l << "\n";
}

StudyAnalysisOptions quick() {
  StudyAnalysisOptions o;
  o.bootstrap = 0;
  return o;
}

// Issue 23.8: duplicated rows, missing trials and a session split across
// files were analysed without a word.
TEST(StudyAnalysis, RefusesADuplicatedTrialNamingBothPlaces) {
  const fs::path dir = rule_study("dup", 2);
  const fs::path csv = dir / "analysis-test_P1_s1.csv";
  auto lines = lines_of(csv);
  lines.push_back(lines[5]);  // the row of trial 4 again, as a second writer left it
  write_lines(csv, lines);
  auto a = analyze_study(dir, quick());
  ASSERT_FALSE(a);
  const std::string& m = a.error().message;
  EXPECT_NE(m.find("analysis-test_P1_s1.csv:" + std::to_string(lines.size())), std::string::npos) << m;
  EXPECT_NE(m.find("already at"), std::string::npos) << m;
  EXPECT_NE(m.find("analysis-test_P1_s1.csv:6"), std::string::npos) << m;
  fs::remove_all(dir);
}

TEST(StudyAnalysis, RefusesMissingTrialsUnlessAllowedAndThenSaysWhich) {
  const fs::path dir = rule_study("missing", 2);
  const fs::path csv = dir / "analysis-test_P2_s1.csv";
  auto lines = lines_of(csv);
  lines.erase(lines.begin() + 11, lines.begin() + 14);  // trials 10, 11 and 12
  write_lines(csv, lines);
  auto a = analyze_study(dir, quick());
  ASSERT_FALSE(a);
  EXPECT_NE(a.error().message.find("3 of 360 planned trials are missing (trial 10-12)"), std::string::npos)
      << a.error().message;
  EXPECT_NE(a.error().message.find("--allow-incomplete"), std::string::npos);
  auto o = quick();
  o.allow_incomplete = true;
  auto allowed = analyze_study(dir, o);
  ASSERT_TRUE(allowed) << allowed.error().message;
  bool noted = false;
  for (const std::string& n : allowed->notes) noted |= n.find("trial 10-12") != std::string::npos;
  EXPECT_TRUE(noted);
  fs::remove_all(dir);
}

TEST(StudyAnalysis, RefusesOneSessionSplitAcrossTwoFiles) {
  const fs::path dir = rule_study("split", 2);
  const fs::path csv = dir / "analysis-test_P1_s1.csv";
  auto lines = lines_of(csv);
  std::vector<std::string> second = {lines[0]};
  second.insert(second.end(), lines.begin() + 200, lines.end());
  lines.resize(200);
  write_lines(csv, lines);
  write_lines(dir / "analysis-test_P1_s1_part2.csv", second);
  fs::copy_file(dir / "analysis-test_P1_s1.json", dir / "analysis-test_P1_s1_part2.json");
  auto a = analyze_study(dir, quick());
  ASSERT_FALSE(a);
  EXPECT_NE(a.error().message.find("split across two files"), std::string::npos) << a.error().message;
  fs::remove_all(dir);
}

TEST(StudyAnalysis, RefusesOutOfRangeSettings) {
  const fs::path dir = rule_study("ranges", 2);
  for (auto set : std::vector<void (*)(StudyAnalysisOptions&)>{
           [](StudyAnalysisOptions& o) { o.guess = 1.0; }, [](StudyAnalysisOptions& o) { o.guess = -0.1; },
           [](StudyAnalysisOptions& o) { o.lapse = 1.5; }, [](StudyAnalysisOptions& o) { o.lapse_max = -1; },
           [](StudyAnalysisOptions& o) { o.threshold = 0.0; }, [](StudyAnalysisOptions& o) { o.threshold = 1.0; },
           [](StudyAnalysisOptions& o) { o.threshold = 0.4; },  // below the 2AFC guess rate
           [](StudyAnalysisOptions& o) {
             o.guess = 0.6;
             o.lapse = 0.5;
           }}) {
    auto o = quick();
    set(o);
    auto a = analyze_study(dir, o);
    EXPECT_FALSE(a) << "an out-of-range setting gave an (empty) analysis";
    if (!a) {
      EXPECT_EQ(a.error().code, Errc::invalid_argument) << a.error().message;
    }
  }
  // The message names the option that failed: a valid --lapse next to a bad
  // --lapse-max was reported as "--lapse 0.02".
  auto max = quick();
  max.lapse_max = 0.7;  // at or above 1 - guess: nothing left for the function
  auto a = analyze_study(dir, max);
  ASSERT_FALSE(a);
  EXPECT_NE(a.error().message.find("--lapse-max 0.7 is outside"), std::string::npos) << a.error().message;
  max.lapse = 0.02;
  a = analyze_study(dir, max);
  ASSERT_FALSE(a);
  EXPECT_EQ(a.error().message.find("--lapse 0.02"), std::string::npos) << a.error().message;
  EXPECT_NE(a.error().message.find("not both"), std::string::npos) << a.error().message;
  EXPECT_TRUE(analyze_study(dir, quick()));
  fs::remove_all(dir);
}

// Issue 23.9: a level where everyone scores 100 % came out "maximally
// significant"; it is not testable.
TEST(StudyAnalysis, LevelsWithoutVarianceAreNotTestable) {
  const fs::path dir = rule_study("ceiling", 3);
  auto a = analyze_study(dir, quick());
  ASSERT_TRUE(a) << a.error().message;
  int ceiling_levels = 0;
  for (const LevelAnova& l : a->level_anovas) {
    if (l.level < 7.5) continue;
    ++ceiling_levels;
    ASSERT_TRUE(l.one_way);
    EXPECT_FALSE(l.one_way->testable) << l.level;
    EXPECT_TRUE(std::isnan(l.one_way->p)) << l.level;
    if (l.repeated) {
      EXPECT_FALSE(l.repeated->testable) << l.level;
    }
  }
  EXPECT_EQ(ceiling_levels, 2);
  const std::string j = study_analysis_json(*a);
  EXPECT_NE(j.find("\"testable\": false"), std::string::npos);
  fs::remove_all(dir);
}

TEST(StudyAnalysis, RefusesAFolderAStudyIsWritingIn) {
  const fs::path dir = rule_study("busy", 2);
  auto other = FolderLock::acquire(dir, "study folder");  // as a running study in another process
  ASSERT_TRUE(other);
  auto a = analyze_study(dir, quick());
  ASSERT_FALSE(a);
  EXPECT_EQ(a.error().code, Errc::unavailable);
  EXPECT_NE(a.error().message.find("a study is running"), std::string::npos) << a.error().message;
  fs::remove_all(dir);
}

TEST(StudyAnalysis, LevelsFromTrialsPoolsEqualStimuli) {
  auto l = levels_from_trials({2.0, 1.0, 2.0, 1.0, 2.0}, {1, 0, 1, 1, 0});
  ASSERT_TRUE(l);
  ASSERT_EQ(l->size(), 2u);
  EXPECT_EQ((*l)[0].level, 1.0);
  EXPECT_EQ((*l)[0].correct, 1);
  EXPECT_EQ((*l)[0].trials, 2);
  EXPECT_EQ((*l)[1].correct, 2);
  EXPECT_EQ((*l)[1].trials, 3);
}

}  // namespace
}  // namespace proprio::study
