// Sessions: the trial loop, the per-trial CSV and sidecar, and resuming after
// a real crash (a child process killed with SIGKILL mid-session).
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <thread>

#include "proprio/core/file_io.hpp"
#include "proprio/study/csv.hpp"
#include "proprio/study/session.hpp"
#include "study/simulated_observer.hpp"

namespace proprio::study {
namespace {

namespace fs = std::filesystem;
using testing::SimulatedObserver;

const char* kConstant = R"(
[study]
name = "crash-test"
seed = 11
stimulus = "offset_cm"
extra_columns = ["note"]
[[factor]]
name = "haptics"
levels = ["none", "true_sphere"]
[blocks]
by = "haptics"
counterbalance = "abba"
[procedure]
type = "constant"
levels = [1.5, 3.0, 4.5, 6.0, 7.5]
repetitions = 6
)";

const char* kStaircase = R"(
[study]
name = "crash-stairs"
seed = 12
[[factor]]
name = "haptics"
levels = ["none", "true_sphere"]
[procedure]
type = "staircase"
interleave = 2
starts = [9.0, 1.0]
down = 2
steps = [1.0, 0.5]
min = 0.1
max = 12.0
trials = 25
)";

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("proprio_study_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

SessionOptions options_for(const fs::path& dir) {
  SessionOptions o;
  o.out_dir = dir;
  o.participant = "P01";
  o.participant_index = 1;
  o.device_json = R"({"hmd": "simulated"})";
  return o;
}

// Runs trials until the session ends (or `limit` trials), answering with the
// observer; `pause_us` slows it down so a parent can kill it mid-session.
Status run_trials(Session& s, const SimulatedObserver& obs, int limit = 1 << 30, int pause_us = 0) {
  for (int n = 0; n < limit && !s.finished(); ++n) {
    auto t = s.next_trial();
    if (!t) return t.error();
    Response r;
    r.correct = obs.respond(t->stimulus, static_cast<std::uint64_t>(t->index));
    r.response_time_s = 0.5;
    if (Status st = s.record(*t, r); !st) return st;
    if (pause_us > 0) ::usleep(static_cast<useconds_t>(pause_us));
  }
  return Status::success();
}

// Rows without the wall-clock column, for comparing runs.
std::vector<std::vector<std::string>> rows_without_time(const fs::path& csv) {
  auto t = read_csv(csv);
  EXPECT_TRUE(t) << (t ? "" : t.error().message);
  if (!t) return {};
  std::vector<std::vector<std::string>> out;
  for (auto row : t->rows) {
    row.pop_back();  // recorded_unix_ns
    out.push_back(row);
  }
  return out;
}

int count_lines(const fs::path& p) {
  std::ifstream in(p);
  std::string line;
  int n = 0;
  while (std::getline(in, line)) ++n;
  return n;
}

TEST(Session, WritesOneRowPerTrialAndASidecar) {
  auto d = StudyDesign::parse(kConstant);
  ASSERT_TRUE(d) << d.error().message;
  const fs::path dir = fresh_dir("rows");
  auto s = Session::open(*d, options_for(dir));
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_FALSE(s->resumed());
  EXPECT_EQ(s->planned_trials(), 60);
  // Asking again without recording gives the same trial ("need another look").
  auto t1 = s->next_trial();
  auto t2 = s->next_trial();
  ASSERT_TRUE(t1 && t2);
  EXPECT_EQ(t1->index, t2->index);
  EXPECT_EQ(t1->stimulus, t2->stimulus);
  Response bad;
  bad.extra["unknown"] = "x";
  EXPECT_FALSE(s->record(*t1, bad));
  Response ok;
  ok.correct = true;
  ok.extra["note"] = "first, with a comma";
  ASSERT_TRUE(s->record(*t1, ok));
  EXPECT_FALSE(s->record(*t1, ok)) << "recording the same trial twice must fail";
  // The row is on disk before record() returns.
  EXPECT_EQ(count_lines(s->csv_path()), 2);
  SimulatedObserver obs;
  ASSERT_TRUE(run_trials(*s, obs));
  EXPECT_TRUE(s->finished());
  EXPECT_FALSE(s->next_trial());

  auto table = read_csv(s->csv_path());
  ASSERT_TRUE(table) << table.error().message;
  ASSERT_EQ(table->rows.size(), 60u);
  EXPECT_EQ(table->rows[0][*table->column("note")], "first, with a comma");
  std::map<std::pair<std::string, std::string>, int> cells;
  for (std::size_t i = 0; i < table->rows.size(); ++i) {
    EXPECT_EQ(table->rows[i][*table->column("trial")], std::to_string(i));
    ++cells[{table->rows[i][*table->column("haptics")], table->rows[i][*table->column("offset_cm")]}];
  }
  EXPECT_EQ(cells.size(), 10u);
  for (const auto& [k, n] : cells) EXPECT_EQ(n, 6);
  // ABBA, participant index 1: reversed order, so the second level's block comes first.
  EXPECT_EQ(table->rows[0][*table->column("haptics")], "true_sphere");

  std::ifstream side(s->sidecar_path());
  const auto j = nlohmann::json::parse(side);
  EXPECT_EQ(j["status"], "complete");
  EXPECT_EQ(j["completed_trials"], 60);
  EXPECT_EQ(j["seed"], 11);
  EXPECT_EQ(j["participant_seed"], s->participant_seed());
  EXPECT_EQ(j["device"]["hmd"], "simulated");
  EXPECT_EQ(j["design_toml"], std::string(kConstant));
  EXPECT_EQ(j["block_order"], nlohmann::json::array({"true_sphere", "none"}));
  fs::remove_all(dir);
}

TEST(Session, SameSeedGivesTheSameTrialsInSeparateRuns) {
  auto d = StudyDesign::parse(kStaircase);
  ASSERT_TRUE(d);
  const fs::path a = fresh_dir("same_a"), b = fresh_dir("same_b");
  SimulatedObserver obs;
  {
    SessionOptions fast = options_for(a);
    fast.sync_each_trial = false;
    auto s = Session::open(*d, fast);
    ASSERT_TRUE(s);
    ASSERT_TRUE(run_trials(*s, obs));
  }
  {
    auto s = Session::open(*d, options_for(b));
    ASSERT_TRUE(s);
    ASSERT_TRUE(run_trials(*s, obs));
  }
  const auto ra = rows_without_time(session_csv_path(*d, options_for(a)));
  EXPECT_EQ(ra.size(), 100u);  // 2 cells x 2 tracks x 25
  EXPECT_EQ(ra, rows_without_time(session_csv_path(*d, options_for(b))));
  fs::remove_all(a);
  fs::remove_all(b);
}

// The child runs the session slowly; the parent kills it with SIGKILL once
// `kill_after` rows are on disk, resumes in-process and finishes. The result
// must equal an uninterrupted run: no trial lost, none repeated, the same
// stimuli (adaptive ones included) and responses.
void crash_and_resume(const char* design_text, const std::string& name, int kill_after) {
  auto d = StudyDesign::parse(design_text);
  ASSERT_TRUE(d) << d.error().message;
  SimulatedObserver obs;
  obs.seed = 4242;
  const fs::path reference = fresh_dir(name + "_ref"), crashed = fresh_dir(name + "_crash");
  {
    auto s = Session::open(*d, options_for(reference));
    ASSERT_TRUE(s);
    ASSERT_TRUE(run_trials(*s, obs));
  }
  const fs::path csv = session_csv_path(*d, options_for(crashed));
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    auto s = Session::open(*d, options_for(crashed));
    if (s) (void)run_trials(*s, obs, 1 << 30, 2000);
    ::_exit(0);  // not reached when the parent is in time
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (count_lines(csv) < 1 + kill_after && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  ASSERT_EQ(::kill(child, SIGKILL), 0);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status)) << "the child finished before it was killed; slow it down";
  const int rows_at_crash = count_lines(csv) - 1;
  ASSERT_GE(rows_at_crash, kill_after);

  auto s = Session::open(*d, options_for(crashed));
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_TRUE(s->resumed());
  EXPECT_EQ(s->recovered_trials(), rows_at_crash);
  ASSERT_FALSE(s->finished());
  EXPECT_EQ(s->next_trial()->index, rows_at_crash);
  ASSERT_TRUE(run_trials(*s, obs));

  const auto expected = rows_without_time(session_csv_path(*d, options_for(reference)));
  const auto actual = rows_without_time(csv);
  ASSERT_EQ(actual.size(), expected.size());
  std::set<std::string> indices;
  for (std::size_t i = 0; i < actual.size(); ++i) {
    EXPECT_EQ(actual[i], expected[i]) << "row " << i;
    indices.insert(actual[i][2]);
  }
  EXPECT_EQ(indices.size(), actual.size()) << "a trial index appears twice";
  std::ifstream side(s->sidecar_path());
  const auto j = nlohmann::json::parse(side);
  EXPECT_EQ(j["status"], "complete");
  ASSERT_EQ(j["resumes"].size(), 1u);
  EXPECT_EQ(j["resumes"][0]["recovered_trials"], rows_at_crash);
  fs::remove_all(reference);
  fs::remove_all(crashed);
}

TEST(SessionResume, ConstantStimuliAfterSigkill) { crash_and_resume(kConstant, "constant", 17); }

TEST(SessionResume, InterleavedStaircasesAfterSigkill) { crash_and_resume(kStaircase, "stairs", 33); }

TEST(SessionResume, CutsOffAHalfWrittenRowAndRunsThatTrialAgain) {
  auto d = StudyDesign::parse(kConstant);
  ASSERT_TRUE(d);
  const fs::path dir = fresh_dir("torn");
  SimulatedObserver obs;
  {
    auto s = Session::open(*d, options_for(dir));
    ASSERT_TRUE(s);
    ASSERT_TRUE(run_trials(*s, obs, 5));
  }
  const fs::path csv = session_csv_path(*d, options_for(dir));
  {
    std::ofstream out(csv, std::ios::app);
    out << "P01,1,5,0,true_sph";  // what a crash mid-write leaves
  }
  auto s = Session::open(*d, options_for(dir));
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_TRUE(s->repaired_torn_row());
  EXPECT_EQ(s->recovered_trials(), 5);
  EXPECT_EQ(s->next_trial()->index, 5);
  ASSERT_TRUE(run_trials(*s, obs));
  EXPECT_EQ(rows_without_time(csv).size(), 60u);
  fs::remove_all(dir);
}

TEST(SessionResume, RefusesAnEditedDesignOrAnotherParticipantIndex) {
  auto d = StudyDesign::parse(kConstant);
  ASSERT_TRUE(d);
  const fs::path dir = fresh_dir("refuse");
  SimulatedObserver obs;
  {
    auto s = Session::open(*d, options_for(dir));
    ASSERT_TRUE(s);
    ASSERT_TRUE(run_trials(*s, obs, 3));
  }
  std::string edited = kConstant;
  edited.replace(edited.find("repetitions = 6"), 15, "repetitions = 7");
  auto d2 = StudyDesign::parse(edited);
  ASSERT_TRUE(d2);
  auto s2 = Session::open(*d2, options_for(dir));
  ASSERT_FALSE(s2);
  EXPECT_NE(s2.error().message.find("design"), std::string::npos);
  SessionOptions other = options_for(dir);
  other.participant_index = 2;
  auto s3 = Session::open(*d, other);
  ASSERT_FALSE(s3);
  EXPECT_NE(s3.error().message.find("participant index"), std::string::npos);
  // A row edited by hand no longer matches the regenerated plan.
  const fs::path csv = session_csv_path(*d, options_for(dir));
  auto table = read_csv(csv);
  ASSERT_TRUE(table);
  std::ifstream in(csv);
  std::stringstream text;
  text << in.rdbuf();
  std::string content = text.str();
  const std::string stim = table->rows[1][*table->column("offset_cm")];
  const std::size_t line2 = content.find('\n', content.find('\n') + 1) + 1;
  const std::size_t at = content.find("," + stim + ",", line2);
  content.replace(at, stim.size() + 2, ",99,");
  std::ofstream(csv, std::ios::trunc) << content;
  auto s4 = Session::open(*d, options_for(dir));
  ASSERT_FALSE(s4);
  EXPECT_NE(s4.error().message.find("does not match"), std::string::npos) << s4.error().message;
  fs::remove_all(dir);
}

TEST(Session, RejectsBadOptions) {
  auto d = StudyDesign::parse(kConstant);
  ASSERT_TRUE(d);
  SessionOptions o = options_for(fresh_dir("bad"));
  o.participant = "P 01";
  EXPECT_FALSE(Session::open(*d, o));
  o.participant = "P01";
  o.device_json = "not json";
  auto s = Session::open(*d, o);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("JSON object"), std::string::npos);
  fs::remove_all(o.out_dir);
}

// Issue 23.1: two runs on one folder interleaved and duplicated trials. The
// folder is locked before anything in it is touched; a second holder (another
// process: a separate flock, as FolderLock takes it) is refused and the files
// stay as they are.
TEST(SessionLock, ASecondProcessOnTheFolderIsRefusedAndTouchesNothing) {
  auto d = StudyDesign::parse(kConstant);
  ASSERT_TRUE(d) << d.error().message;
  const fs::path dir = fresh_dir("lock");
  SimulatedObserver obs;
  {
    auto first = Session::open(*d, options_for(dir));
    ASSERT_TRUE(first) << first.error().message;
    ASSERT_TRUE(run_trials(*first, obs, 3));
  }
  const auto before = rows_without_time(dir / "crash-test_P01_s1.csv");
  ASSERT_EQ(before.size(), 3u);
  {
    auto other = FolderLock::acquire(dir, "study folder");  // what another process holds
    ASSERT_TRUE(other) << other.error().message;
    auto second = Session::open(*d, options_for(dir));
    ASSERT_FALSE(second) << "a second writer on a locked folder";
    EXPECT_EQ(second.error().code, Errc::unavailable);
    EXPECT_NE(second.error().message.find("in use by another process"), std::string::npos) << second.error().message;
    EXPECT_NE(second.error().message.find("pid " + std::to_string(::getpid())), std::string::npos)
        << second.error().message;
    auto another_participant = Session::open(*d, [&] {
      auto o = options_for(dir);
      o.participant = "P02";
      return o;
    }());
    EXPECT_FALSE(another_participant);
    EXPECT_FALSE(fs::exists(dir / "crash-test_P02_s1.csv"));
    EXPECT_FALSE(check_study_folder_not_in_use(dir)) << "an analysis must not read a study being written";
  }
  EXPECT_EQ(rows_without_time(dir / "crash-test_P01_s1.csv"), before);
  EXPECT_TRUE(check_study_folder_not_in_use(dir));
  // Released with the other holder: the session resumes.
  auto again = Session::open(*d, options_for(dir));
  ASSERT_TRUE(again) << again.error().message;
  EXPECT_EQ(again->recovered_trials(), 3);
  fs::remove_all(dir);
}

TEST(SessionLock, OneProcessMayRunParticipantsInParallelButNotOneSessionTwice) {
  auto d = StudyDesign::parse(kConstant);
  ASSERT_TRUE(d) << d.error().message;
  const fs::path dir = fresh_dir("lock_same");
  auto a = Session::open(*d, options_for(dir));
  ASSERT_TRUE(a) << a.error().message;
  auto twice = Session::open(*d, options_for(dir));
  ASSERT_FALSE(twice) << "two Session objects appending to one CSV";
  EXPECT_NE(twice.error().message.find("already open"), std::string::npos) << twice.error().message;
  auto o2 = options_for(dir);
  o2.participant = "P02";
  auto b = Session::open(*d, o2);
  EXPECT_TRUE(b) << b.error().message;
  EXPECT_TRUE(check_study_folder_not_in_use(dir)) << "this process's own lock does not block its analysis";
  // The lock is held while any session of this process lives, and no longer.
  a = Result<Session>(make_error(Errc::invalid_argument, "closed"));
  EXPECT_FALSE(FolderLock::acquire(dir, "study folder"));
  b = Result<Session>(make_error(Errc::invalid_argument, "closed"));
  EXPECT_TRUE(FolderLock::acquire(dir, "study folder"));
  fs::remove_all(dir);
}

TEST(SessionLock, ResumeListsTheRecordedTrialsWithTheirResponses) {
  auto d = StudyDesign::parse(kConstant);
  ASSERT_TRUE(d) << d.error().message;
  const fs::path dir = fresh_dir("recovered_list");
  std::vector<Trial> seen;
  {
    auto s = Session::open(*d, options_for(dir));
    ASSERT_TRUE(s) << s.error().message;
    for (int n = 0; n < 4; ++n) {
      auto t = s->next_trial();
      ASSERT_TRUE(t);
      Response r;
      r.correct = n % 2 == 0;
      r.response_time_s = 0.25 * n;
      r.extra["note"] = "n" + std::to_string(n);
      ASSERT_TRUE(s->record(*t, r));
      seen.push_back(*t);
    }
  }
  auto s = Session::open(*d, options_for(dir));
  ASSERT_TRUE(s) << s.error().message;
  const auto& list = s->recovered_trial_list();
  ASSERT_EQ(list.size(), 4u);
  for (int n = 0; n < 4; ++n) {
    EXPECT_EQ(list[n].trial.index, seen[n].index);
    EXPECT_EQ(list[n].trial.stimulus, seen[n].stimulus);
    EXPECT_EQ(list[n].trial.levels, seen[n].levels);
    EXPECT_EQ(list[n].response.correct, n % 2 == 0);
    EXPECT_EQ(list[n].response.response_time_s, 0.25 * n);
    EXPECT_EQ(list[n].response.extra.at("note"), "n" + std::to_string(n));
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace proprio::study
