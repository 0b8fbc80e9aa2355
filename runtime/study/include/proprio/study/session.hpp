#pragma once
// Running one participant's session of a study, crash-safely.
//
// The trial loop a sample (or a person at a keyboard) drives:
//
//   auto session = Session::open(design, options);      // starts, or resumes
//   while (!session->finished()) {
//     auto trial = session->next_trial();                // conditions + stimulus
//     Response r = present_and_ask(*trial);              // the caller's job
//     if (auto s = session->record(*trial, r); !s) ...   // row written + fsync'ed
//   }
//
// next_trial() returns the same trial until it is recorded, so "show me that
// again" is simply asking again. Every recorded trial is one CSV row, written
// with write(2) and fsync(2) before record() returns: a crash or power cut
// loses at most the trial in progress. Opening a session whose CSV already
// exists resumes it: the rows are replayed against the regenerated plan
// (adaptive procedures relearn from the recorded responses), then the session
// continues at the next trial with the same randomisation. Files and columns:
// docs/study.md.
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/study/design.hpp"
#include "proprio/study/procedure.hpp"

namespace proprio::study {

// Keeps other processes off a study folder while it lives: an exclusive
// FolderLock on <dir>/.lock (proprio/core/file_io.hpp), taken before anything
// in the folder is created, deleted or appended, and released when the last
// holder in this process goes away (or the process dies). Within one process
// the hold is shared, because one study runs several sessions in parallel
// (one per simulated participant) in the same folder. Session::open takes
// one; take one yourself to cover work around the sessions (deleting old
// sessions for --force, writing a report).
class StudyFolderLock {
 public:
  // Creates `dir` if missing. Errc::unavailable when another process holds it.
  static Result<StudyFolderLock> acquire(const std::filesystem::path& dir);

  StudyFolderLock() = default;
  StudyFolderLock(StudyFolderLock&& other) noexcept;
  StudyFolderLock& operator=(StudyFolderLock&& other) noexcept;
  StudyFolderLock(const StudyFolderLock&) = delete;
  StudyFolderLock& operator=(const StudyFolderLock&) = delete;
  ~StudyFolderLock();

  bool held() const noexcept { return id_ != 0; }

 private:
  friend class Session;
  void release() noexcept;
  std::uint64_t id_ = 0;  // the folder's entry in this process's table of held folders
};

// Errc::unavailable when a study is being run in `dir` by another process
// (its lock is held); success when none is, or when this process holds it.
// Creates nothing: for readers of a study folder.
Status check_study_folder_not_in_use(const std::filesystem::path& dir);

struct SessionOptions {
  std::filesystem::path out_dir;   // created if missing
  std::string participant;         // id: letters, digits, '_' and '-' ("P07")
  int participant_index = 0;       // 0-based position in the counterbalancing order
  int session = 1;
  // Free-form JSON objects from the caller, stored in the sidecar as given:
  // the devices used (HMD, fingertip device, serials) and calibrations
  // (e.g. the HMD-to-graphics transform). Empty means "{}".
  std::string device_json;
  std::string calibration_json;
  std::string software_version;    // empty: this library's version
  // fsync every row (and the sidecar) before record() returns. Turn it off
  // only for simulated participants: it saves a few ms of disk flush per
  // trial, and a crash then may lose rows the OS had not written yet.
  bool sync_each_trial = true;
};

struct Trial {
  int index = 0;                   // 0-based trial number within the session
  int block = 0;                   // position of the block in this participant's order
  std::string block_label;
  int cell = 0;                    // condition cell (condition_cells(design)[cell])
  std::vector<std::string> levels; // the cell's factor levels, in factor order
  double stimulus = 0.0;
  int track = 0;                   // interleaved track (adaptive procedures)
};

struct Response {
  bool correct = false;            // the binary response the procedure uses (the design's response column)
  double response_time_s = -1.0;   // < 0: not measured (written empty)
  // Values for the design's extra_columns; missing ones are written empty.
  std::map<std::string, std::string> extra;
};

class Session {
 public:
  // Starts a new session, or resumes the one whose files already exist.
  static Result<Session> open(const StudyDesign& design, const SessionOptions& options);

  Session(Session&&) noexcept;
  Session& operator=(Session&&) noexcept;
  ~Session();

  bool finished() const;
  // The trial to present now; an error once the session is finished.
  Result<Trial> next_trial();
  // Writes the trial's row and fsyncs it. `trial` must be the one
  // next_trial() returned.
  Status record(const Trial& trial, const Response& response);

  int completed_trials() const;
  int planned_trials() const;      // slots in the plan (adaptive procedures may finish early)
  bool resumed() const;
  int recovered_trials() const;    // rows found when the session was opened
  bool repaired_torn_row() const;  // a half-written last row (crash mid-write) was cut off on resume
  // The trials found on disk when the session was opened, in order, with the
  // responses recorded for them (response_time_s and extra as written). A
  // simulated participant replays them to be in the state it was in when
  // the earlier run stopped.
  struct RecordedTrial {
    Trial trial;
    Response response;
  };
  const std::vector<RecordedTrial>& recovered_trial_list() const;
  std::uint64_t participant_seed() const;
  const std::filesystem::path& csv_path() const;
  const std::filesystem::path& sidecar_path() const;
  // The cell's adaptive procedure (nullptr for constant stimuli).
  const Procedure* procedure(int cell) const;

  struct Impl;

 private:
  explicit Session(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// File names of a participant's session: <dir>/<study>_<participant>_s<session>.csv / .json.
std::filesystem::path session_csv_path(const StudyDesign& design, const SessionOptions& options);
std::filesystem::path session_sidecar_path(const StudyDesign& design, const SessionOptions& options);

}  // namespace proprio::study
