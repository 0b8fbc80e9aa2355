// Whole simulated peg-in-hole sessions: a SIGKILLed study resumes without
// losing or repeating a trial, and the simulated user ranks the settings as
// the thesis found (setting 1 fastest, setting 4 slowest).
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <filesystem>
#include <set>
#include <thread>

#include "proprio/peg_in_hole/study_runner.hpp"
#include "proprio/study/completion_time.hpp"
#include "proprio/study/csv.hpp"

using namespace proprio;
using namespace proprio::peg_in_hole;
namespace fs = std::filesystem;

namespace {

fs::path fresh_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / fmt::format("proprio_{}_{}", name, ::getpid());
  fs::remove_all(d);
  return d;
}

int csv_rows(const fs::path& csv) {
  auto t = study::read_csv(csv);
  return t ? static_cast<int>(t->rows.size()) : 0;
}

}  // namespace

TEST(PegStudy, ASigkilledStudyResumesWithNoTrialLostOrRepeated) {
  PegInHoleConfig c;
  c.familiarisation.spring_phase_s = 0;
  c.familiarisation.ground_phase_s = 0;
  c.main_task.trial_timeout_s = 1.5;  // short trials: this test is about the bookkeeping
  c.recording.rate_hz = 50;
  const fs::path dir = fresh_dir("peg_resume");
  SimulatedStudyOptions o;
  o.out_dir = dir;
  o.participants = 1;
  o.seed = 9;
  o.threads = 1;
  const fs::path csv = dir / "peg-in-hole_sim01_s1.csv";

  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    auto r = run_simulated_study(c, o);
    ::_exit(r ? 0 : 1);
  }
  // Kill it mid-study, once a few rows are on disk.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (csv_rows(csv) < 5 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status)) << "the child finished before it was killed";
  const int before = csv_rows(csv);
  ASSERT_GE(before, 5);
  ASSERT_LT(before, 20);

  auto refused = run_simulated_study(c, o);
  EXPECT_FALSE(refused) << "existing data is neither overwritten nor resumed silently";
  o.resume = true;
  auto r = run_simulated_study(c, o);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->trials_recovered, before);
  EXPECT_EQ(r->trials_run, 20 - before);
  auto t = study::read_csv(csv);
  ASSERT_TRUE(t) << t.error().message;
  ASSERT_EQ(t->rows.size(), 20u);
  const auto trial = *t->require_column("trial");
  std::set<std::string> seen;
  for (const auto& row : t->rows) seen.insert(row[trial]);
  EXPECT_EQ(seen.size(), 20u) << "every trial exactly once";
  EXPECT_TRUE(fs::exists(dir / "recordings" / "sim01_trial20.prec"));
  fs::remove_all(dir);
}

// The session's files without what legitimately differs between runs: the
// CSV's wall-clock column and the sidecar's timestamps and resumes.
std::string csv_without_time(const fs::path& p) {
  auto t = study::read_csv(p);
  EXPECT_TRUE(t) << (t ? "" : t.error().message);
  std::string out;
  if (!t) return out;
  for (auto row : t->rows) {
    row.pop_back();  // recorded_unix_ns
    for (const auto& f : row) out += f + ",";
    out += "\n";
  }
  return out;
}
nlohmann::json sidecar_without_time(const fs::path& p) {
  std::ifstream in(p);
  nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  EXPECT_TRUE(j.is_object()) << p;
  if (!j.is_object()) return j;
  j.erase("started_unix_ns");
  j.erase("resumes");
  return j;
}
std::string file_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Issue 23.2: a resumed simulated participant started untrained (its
// familiarisation ran only without trials on disk), so the GG-corrected p
// changed from 0.005 to 0.07. It now relives its familiarisation and the
// recorded trials and continues exactly as an uninterrupted run.
TEST(PegStudy, AResumedStudyReproducesTheUninterruptedRunExactly) {
  PegInHoleConfig c;  // as tests/peg_in_hole/quick.toml: short phases, short trials
  c.familiarisation.spring_phase_s = 1;
  c.familiarisation.ground_phase_s = 1;
  c.main_task.trial_timeout_s = 1.5;
  c.recording.rate_hz = 10;
  SimulatedStudyOptions o;
  o.participants = 1;
  o.seed = 4;
  o.threads = 1;
  const fs::path ref_dir = fresh_dir("peg_exact_ref"), dir = fresh_dir("peg_exact");
  o.out_dir = ref_dir;
  auto ref = run_simulated_study(c, o);
  ASSERT_TRUE(ref) << ref.error().message;
  o.out_dir = dir;
  o.stop_after_trials = 4;
  auto stopped = run_simulated_study(c, o);
  ASSERT_TRUE(stopped) << stopped.error().message;
  ASSERT_EQ(stopped->trials_run, 4);
  o.stop_after_trials = -1;
  o.resume = true;
  auto resumed = run_simulated_study(c, o);
  ASSERT_TRUE(resumed) << resumed.error().message;
  EXPECT_EQ(resumed->trials_recovered, 4);
  EXPECT_EQ(resumed->trials_run, 16);
  const std::string name = "peg-in-hole_sim01_s1";
  EXPECT_EQ(csv_without_time(ref_dir / (name + ".csv")), csv_without_time(dir / (name + ".csv")));
  EXPECT_EQ(sidecar_without_time(ref_dir / (name + ".json")), sidecar_without_time(dir / (name + ".json")));
  for (const int trial : {1, 4, 5, 20}) {
    const std::string rec = fmt::format("recordings/sim01_trial{:02d}.prec", trial);
    EXPECT_EQ(file_bytes(ref_dir / rec), file_bytes(dir / rec)) << rec;
  }
  fs::remove_all(ref_dir);
  fs::remove_all(dir);
}

// The acceptance test of the simulated user: with the published protocol
// (3 + 3 min familiarisation, 20 trials, 120 s timeout, 10 participants) and
// its documented parameters, every study seed ranks the settings as the
// thesis found: setting 1 (haptics + AA) fastest, setting 4 (neither) slowest.
//
// DISABLED: not yet true for every seed, and each seed is a whole study
// (7-9 min on 2 cores), beyond the CI suite's budget. Two runs of seed 1 with
// today's model gave 0.69, 0.79, 1.22, 1.31 and 0.79, 0.77, 1.12, 1.32
// (setting 4 slowest in both, but 1 and 2 level in the second), the second
// after a change that only reordered MuJoCo's contacts: the simulation is
// chaotic, and AA's benefit is smaller than the spread between runs
// (docs/peg-in-hole.md, state items 12-14). Run it with
//   peg_in_hole_study_tests --gtest_also_run_disabled_tests --gtest_filter='*Rank*'
TEST(PegStudy, DISABLED_SimulatedUsersRankTheSettingsAsTheThesis) {
  PegInHoleConfig c;            // the published protocol
  c.recording.enabled = false;  // the only departure: no recordings to write
  for (const std::uint64_t seed : {1u, 2u, 3u}) {
    SCOPED_TRACE(fmt::format("study seed {}", seed));
    const fs::path dir = fresh_dir(fmt::format("peg_order_{}", seed));
    SimulatedStudyOptions o;
    o.out_dir = dir;
    o.participants = 10;
    o.seed = seed;
    o.threads = 2;
    auto r = run_simulated_study(c, o);
    ASSERT_TRUE(r) << r.error().message;
    auto a = study::analyze_completion_time_study(dir);
    ASSERT_TRUE(a) << a.error().message;
    ASSERT_EQ(a->summary.size(), 4u);
    std::string line;
    for (const auto& s : a->summary) line += fmt::format("  setting {}: {:.3f} +- {:.3f}", s.setting, s.mean, s.sd);
    std::printf("seed %llu (%.0f s wall):%s\n", static_cast<unsigned long long>(seed), r->wall_s, line.c_str());
    for (std::size_t k = 1; k < 4; ++k) EXPECT_LT(a->summary[0].mean, a->summary[k].mean) << line;
    for (std::size_t k = 0; k < 3; ++k) EXPECT_GT(a->summary[3].mean, a->summary[k].mean) << line;
    fs::remove_all(dir);
  }
}
