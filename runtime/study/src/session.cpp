#include "proprio/study/session.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fmt/format.h>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <utility>

#include "proprio/core/file_io.hpp"
#include "proprio/core/random.hpp"
#include "proprio/study/csv.hpp"

#ifndef PROPRIO_STUDY_VERSION
#define PROPRIO_STUDY_VERSION "unknown"
#endif

namespace proprio::study {
namespace {

using nlohmann::json;

// Per-trial random streams (interleaving) are seeded by trial number, so a
// replay draws exactly what the original run drew.
constexpr std::uint64_t kTrialStreamBase = 1000;

std::int64_t unix_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::string errno_text() { return std::strerror(errno); }

// Shortest text that reads back to the same double, so a resume can compare
// the stimulus it regenerates with the one on disk exactly.
std::string format_number(double v) { return fmt::format("{}", v); }

Status write_all(int fd, const std::string& text, const std::filesystem::path& path, bool sync = true) {
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return make_error(Errc::io_error, fmt::format("writing {} failed: {}; check free disk space", path.string(),
                                                    errno_text()));
    }
    done += static_cast<std::size_t>(n);
  }
  if (sync && ::fsync(fd) != 0) {
    return make_error(Errc::io_error, fmt::format("fsync of {} failed: {}", path.string(), errno_text()));
  }
  return Status::success();
}

// After creating or renaming a file, fsync its folder so the name survives a crash.
void sync_directory(const std::filesystem::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (fd < 0) return;
  (void)::fsync(fd);
  ::close(fd);
}

// The sidecar is the session's own file, read on resume and replaced after
// every trial, atomically.
Status write_json_atomically(const std::filesystem::path& path, const json& j) {
  forget_input_file(path);
  return write_file_atomic(path, j.dump(2) + "\n", "session sidecar");
}

bool is_plain_identifier(const std::string& s) {
  return !s.empty() && s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-") ==
                           std::string::npos;
}

Result<json> parse_object(const std::string& text, const char* what) {
  if (text.empty()) return json::object();
  json j = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) {
    return make_error(Errc::invalid_argument, fmt::format("the {} info must be a JSON object, e.g. {{\"hmd\": "
                                                          "\"Vive Pro\"}}; got: {}",
                                                          what, text));
  }
  return j;
}

std::vector<std::string> columns_of(const StudyDesign& d) {
  std::vector<std::string> c = {"participant", "session", "trial", "block"};
  for (const Factor& f : d.factors) c.push_back(f.name);
  c.push_back("track");
  c.push_back(d.stimulus_column);
  c.push_back(d.response_column);
  c.push_back("response_time_s");
  for (const std::string& e : d.extra_columns) c.push_back(e);
  c.push_back("recorded_unix_ns");
  return c;
}

std::string hex64(std::uint64_t v) { return fmt::format("{:016x}", v); }

// The study folders this process holds, by device and inode (so "D", "./D"
// and a symlink to D are one folder), with the sessions open in each.
struct HeldFolder {
  dev_t dev = 0;
  ino_t ino = 0;
  FolderLock lock;
  int holders = 0;
  std::set<std::string> open_sessions;
};
std::mutex g_held_mutex;
std::map<std::uint64_t, HeldFolder>& held_folders() {
  static std::map<std::uint64_t, HeldFolder> held;
  return held;
}
std::uint64_t g_next_held_id = 1;

HeldFolder* held_folder_at(const struct stat& st) {
  for (auto& [id, h] : held_folders()) {
    if (h.dev == st.st_dev && h.ino == st.st_ino) return &h;
  }
  return nullptr;
}

}  // namespace

Result<StudyFolderLock> StudyFolderLock::acquire(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    return make_error(Errc::io_error, fmt::format("cannot create the output folder {}: {}", printable(dir.string()),
                                                  ec.message()));
  }
  struct stat st {};
  if (::stat(dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("{} is not a folder; choose another --out", printable(dir.string())));
  }
  std::lock_guard guard(g_held_mutex);
  StudyFolderLock out;
  for (auto& [id, h] : held_folders()) {
    if (h.dev == st.st_dev && h.ino == st.st_ino) {
      ++h.holders;
      out.id_ = id;
      return out;
    }
  }
  auto lock = FolderLock::acquire(dir, "study folder");
  if (!lock) return lock.error();
  const std::uint64_t id = g_next_held_id++;
  HeldFolder& h = held_folders()[id];
  h.dev = st.st_dev;
  h.ino = st.st_ino;
  h.lock = std::move(*lock);
  h.holders = 1;
  out.id_ = id;
  return out;
}

StudyFolderLock::StudyFolderLock(StudyFolderLock&& other) noexcept : id_(std::exchange(other.id_, 0)) {}
StudyFolderLock& StudyFolderLock::operator=(StudyFolderLock&& other) noexcept {
  if (this != &other) {
    release();
    id_ = std::exchange(other.id_, 0);
  }
  return *this;
}
StudyFolderLock::~StudyFolderLock() { release(); }

void StudyFolderLock::release() noexcept {
  if (id_ == 0) return;
  std::lock_guard guard(g_held_mutex);
  const auto it = held_folders().find(id_);
  if (it != held_folders().end() && --it->second.holders <= 0) held_folders().erase(it);
  id_ = 0;
}

Status check_study_folder_not_in_use(const std::filesystem::path& dir) {
  struct stat st {};
  if (::stat(dir.c_str(), &st) != 0) return Status::success();
  {
    std::lock_guard guard(g_held_mutex);
    if (held_folder_at(st) != nullptr) return Status::success();
  }
  const std::filesystem::path file = dir / FolderLock::kFileName;
  // Read-only and non-blocking: probing must neither create a file in the
  // data folder nor hang on a FIFO planted under the lock's name.
  const int fd = ::open(file.c_str(), O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return Status::success();  // no study has run here with a lock
  struct stat fst {};
  if (::fstat(fd, &fst) != 0 || !S_ISREG(fst.st_mode)) {
    ::close(fd);
    return Status::success();
  }
  Status result = Status::success();
  if (::flock(fd, LOCK_SH | LOCK_NB) != 0) {
    if (errno == EWOULDBLOCK) {
      char buf[32] = {};
      const ssize_t n = ::pread(fd, buf, sizeof buf - 1, 0);
      std::string owner = n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : std::string();
      while (!owner.empty() && (owner.back() == '\n' || owner.back() == ' ')) owner.pop_back();
      result = make_error(Errc::unavailable,
                          fmt::format("a study is running in {}{}: its files are still being written, so an "
                                      "analysis now would see a partial study; wait for it to finish",
                                      printable(dir.string()),
                                      owner.empty() ? std::string() : " (pid " + printable(owner, 20) + ")"));
    }
  } else {
    (void)::flock(fd, LOCK_UN);
  }
  ::close(fd);
  return result;
}

std::filesystem::path session_csv_path(const StudyDesign& design, const SessionOptions& o) {
  return o.out_dir / fmt::format("{}_{}_s{}.csv", design.name, o.participant, o.session);
}
std::filesystem::path session_sidecar_path(const StudyDesign& design, const SessionOptions& o) {
  return o.out_dir / fmt::format("{}_{}_s{}.json", design.name, o.participant, o.session);
}

struct Session::Impl {
  StudyDesign design;
  SessionOptions options;
  std::vector<ConditionCell> cells;
  std::vector<PlannedTrial> plan;
  std::vector<std::unique_ptr<Procedure>> procedures;
  std::vector<std::string> columns;
  std::uint64_t participant_seed = 0;
  std::size_t cursor = 0;  // the plan slot of the pending (or next) trial
  int completed = 0;
  std::optional<Trial> pending;
  StimulusRequest pending_request;
  int fd = -1;
  std::filesystem::path csv_path, sidecar_path;
  bool resumed = false, torn = false;
  int recovered = 0;
  std::vector<Session::RecordedTrial> recovered_list;
  json sidecar;
  StudyFolderLock folder_lock;  // destroyed last: the files are closed before the folder is released
  std::string claimed;          // this session's name in the held folder's open sessions

  ~Impl() {
    if (fd >= 0) ::close(fd);
    if (!claimed.empty()) {
      std::lock_guard guard(g_held_mutex);
      const auto it = held_folders().find(folder_lock.id_);
      if (it != held_folders().end()) it->second.open_sessions.erase(claimed);
    }
  }

  // Moves the cursor to the next slot that yields a trial (adaptive slots
  // whose procedure has finished are skipped); false when none is left.
  bool prepare_next() {
    if (pending) return true;
    while (cursor < plan.size()) {
      const PlannedTrial& slot = plan[cursor];
      Trial t;
      t.index = completed;
      t.block = slot.block;
      t.block_label = slot.block_label;
      t.cell = slot.cell;
      t.levels = cells[static_cast<std::size_t>(slot.cell)].levels;
      Procedure* proc = procedures[static_cast<std::size_t>(slot.cell)].get();
      if (proc == nullptr) {
        t.stimulus = slot.stimulus;
        pending_request = {slot.stimulus, 0};
      } else {
        if (proc->finished()) {
          ++cursor;
          continue;
        }
        Rng rng(mix_seed(participant_seed, kTrialStreamBase + static_cast<std::uint64_t>(completed)));
        pending_request = proc->next(rng);
        t.stimulus = pending_request.stimulus;
        t.track = pending_request.track;
      }
      pending = std::move(t);
      return true;
    }
    return false;
  }

  std::string row_for(const Trial& t, const Response& r) const {
    std::vector<std::string> f = {options.participant, std::to_string(options.session), std::to_string(t.index),
                                  std::to_string(t.block)};
    for (const std::string& l : t.levels) f.push_back(l);
    f.push_back(std::to_string(t.track));
    f.push_back(format_number(t.stimulus));
    f.push_back(r.correct ? "1" : "0");
    f.push_back(r.response_time_s >= 0.0 ? format_number(r.response_time_s) : "");
    for (const std::string& e : design.extra_columns) {
      const auto it = r.extra.find(e);
      f.push_back(it == r.extra.end() ? "" : it->second);
    }
    f.push_back(std::to_string(unix_ns()));
    std::string line;
    for (std::size_t i = 0; i < f.size(); ++i) line += (i ? "," : "") + csv_field(f[i]);
    return line + "\n";
  }

  void apply(bool correct) {
    if (Procedure* p = procedures[static_cast<std::size_t>(pending->cell)].get()) p->record(pending_request, correct);
    ++completed;
    ++cursor;
    pending.reset();
  }

  Status update_sidecar() {
    sidecar["completed_trials"] = completed;
    sidecar["status"] = prepare_next() ? "running" : "complete";
    return write_json_atomically(sidecar_path, sidecar);
  }

  // Replays the rows already on disk; any disagreement with the regenerated
  // plan means the file belongs to a different design, seed or participant.
  Status replay(const CsvTable& table) {
    if (table.header != columns) {
      std::string want;
      for (const std::string& c : columns) want += (want.empty() ? "" : ",") + c;
      return make_error(Errc::parse_error,
                        fmt::format("{}: the header does not match this design's columns ({}); was the design "
                                    "edited since the session started?",
                                    csv_path.string(), want));
    }
    const std::size_t stimulus_col = 5 + design.factors.size();
    for (std::size_t i = 0; i < table.rows.size(); ++i) {
      const std::vector<std::string>& row = table.rows[i];
      const std::string where = fmt::format("{}:{}", csv_path.string(), table.lines[i]);
      if (!prepare_next()) {
        return make_error(Errc::parse_error,
                          fmt::format("{}: more rows than the plan has trials; the file does not belong to this "
                                      "design and seed",
                                      where));
      }
      std::string expected = fmt::format("trial {}, block {}", pending->index, pending->block);
      bool same = row[0] == options.participant && row[1] == std::to_string(options.session) &&
                  row[2] == std::to_string(pending->index) && row[3] == std::to_string(pending->block) &&
                  row[4 + design.factors.size()] == std::to_string(pending->track) &&
                  row[stimulus_col] == format_number(pending->stimulus);
      for (std::size_t f = 0; f < design.factors.size(); ++f) {
        same = same && row[4 + f] == pending->levels[f];
        expected += fmt::format(", {}={}", design.factors[f].name, pending->levels[f]);
      }
      expected += fmt::format(", track {}, {}={}", pending->track, design.stimulus_column,
                              format_number(pending->stimulus));
      if (!same) {
        return make_error(Errc::parse_error,
                          fmt::format("{}: this row does not match the regenerated plan (expected {}); the design, "
                                      "seed or participant index differs from the session's",
                                      where, expected));
      }
      const std::string& response = row[stimulus_col + 1];
      if (response != "0" && response != "1") {
        return make_error(Errc::parse_error, fmt::format("{}: column '{}' must be 0 or 1, found '{}'", where,
                                                         design.response_column, response));
      }
      Session::RecordedTrial rec{*pending, {}};
      rec.response.correct = response == "1";
      const std::string& rt = row[stimulus_col + 2];
      if (!rt.empty()) {
        char* end = nullptr;
        const double v = std::strtod(rt.c_str(), &end);
        if (end != rt.c_str() && *end == '\0' && std::isfinite(v)) rec.response.response_time_s = v;
      }
      for (std::size_t e = 0; e < design.extra_columns.size(); ++e) {
        rec.response.extra[design.extra_columns[e]] = row[stimulus_col + 3 + e];
      }
      recovered_list.push_back(std::move(rec));
      apply(response == "1");
    }
    return Status::success();
  }
};

Session::Session(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Session::Session(Session&&) noexcept = default;
Session& Session::operator=(Session&&) noexcept = default;
Session::~Session() = default;

Result<Session> Session::open(const StudyDesign& design, const SessionOptions& options) {
  if (!is_plain_identifier(options.participant)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("participant id '{}' must be non-empty and use only letters, digits, '_' and '-'",
                                  options.participant));
  }
  if (options.participant_index < 0 || options.session < 1) {
    return make_error(Errc::invalid_argument, "participant index must be >= 0 and session >= 1");
  }
  auto device = parse_object(options.device_json, "device");
  if (!device) return device.error();
  auto calibration = parse_object(options.calibration_json, "calibration");
  if (!calibration) return calibration.error();

  auto impl = std::make_unique<Impl>();
  Impl& s = *impl;
  s.design = design;
  s.options = options;
  s.cells = condition_cells(design);
  s.participant_seed = mix_seed(mix_seed(design.seed, static_cast<std::uint64_t>(options.participant_index)),
                                static_cast<std::uint64_t>(options.session));
  s.plan = plan_trials(design, options.participant_index, s.participant_seed);
  s.procedures = make_procedures(design);
  s.columns = columns_of(design);
  s.csv_path = session_csv_path(design, options);
  s.sidecar_path = session_sidecar_path(design, options);

  // Before anything in the folder is read or written: a second process on
  // the same folder would interleave and duplicate trials.
  auto folder_lock = StudyFolderLock::acquire(options.out_dir);
  if (!folder_lock) return folder_lock.error();
  s.folder_lock = std::move(*folder_lock);
  {
    std::lock_guard guard(g_held_mutex);
    HeldFolder& h = held_folders().at(s.folder_lock.id_);
    const std::string name = s.csv_path.filename().string();
    if (!h.open_sessions.insert(name).second) {
      return make_error(Errc::unavailable,
                        fmt::format("session {} is already open in this process; record its trials through that "
                                    "Session object",
                                    printable(s.csv_path.string())));
    }
    s.claimed = name;
  }

  std::error_code ec;
  if (std::filesystem::exists(s.csv_path, ec) || std::filesystem::is_symlink(s.csv_path, ec)) {
    // Resume.
    if (!std::filesystem::exists(s.sidecar_path, ec)) {
      return make_error(Errc::not_found,
                        fmt::format("{} exists but its sidecar {} does not; move the CSV away to start over",
                                    s.csv_path.string(), s.sidecar_path.string()));
    }
    auto sidecar_text = read_input_file(s.sidecar_path, "session sidecar");
    if (!sidecar_text) return sidecar_text.error();
    s.sidecar = json::parse(*sidecar_text, nullptr, false);
    if (s.sidecar.is_discarded() || !s.sidecar.is_object()) {
      return make_error(Errc::parse_error, fmt::format("{} is not valid JSON", s.sidecar_path.string()));
    }
    if (s.sidecar.value("design_hash", "") != hex64(design_hash(design.source_text))) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{}: the design file differs from the one this session started with (its copy "
                                    "is in the sidecar's design_toml); resume with that design, or start a new "
                                    "session number",
                                    s.sidecar_path.string()));
    }
    if (s.sidecar.value("participant_index", -1) != options.participant_index) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{}: this session was started with participant index {}, not {}",
                                    s.sidecar_path.string(), s.sidecar.value("participant_index", -1),
                                    options.participant_index));
    }
    // A crash mid-write can leave a last row without its newline: cut it off
    // (that trial was never confirmed, so it is run again).
    auto csv_text = read_input_file(s.csv_path, "session CSV");
    if (!csv_text) return csv_text.error();
    std::string text = std::move(*csv_text);
    if (!text.empty() && text.back() != '\n') {
      const std::size_t keep = text.rfind('\n') == std::string::npos ? 0 : text.rfind('\n') + 1;
      if (::truncate(s.csv_path.c_str(), static_cast<off_t>(keep)) != 0) {
        return make_error(Errc::io_error, fmt::format("cannot cut the half-written last row off {}: {}",
                                                      s.csv_path.string(), errno_text()));
      }
      text.resize(keep);
      s.torn = true;
    }
    if (text.empty()) {
      // Crashed before the header was complete: write it again.
      const std::string header_line = [&] {
        std::string h;
        for (std::size_t i = 0; i < s.columns.size(); ++i) h += (i ? "," : "") + s.columns[i];
        return h + "\n";
      }();
      text = header_line;
      const int hfd = ::open(s.csv_path.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
      if (hfd < 0) return make_error(Errc::io_error, fmt::format("cannot open {}: {}", s.csv_path.string(), errno_text()));
      Status w = write_all(hfd, header_line, s.csv_path);
      ::close(hfd);
      if (!w) return w.error();
    }
    auto table = parse_csv(text, s.csv_path.string());
    if (!table) return table.error();
    if (Status r = s.replay(*table); !r) return r.error();
    s.resumed = true;
    s.recovered = s.completed;
    s.fd = ::open(s.csv_path.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
    if (s.fd < 0) {
      return make_error(Errc::io_error, fmt::format("cannot append to {}: {}", s.csv_path.string(), errno_text()));
    }
    s.sidecar["resumes"].push_back(
        {{"unix_ns", unix_ns()}, {"recovered_trials", s.recovered}, {"repaired_torn_row", s.torn}});
    if (Status st = s.update_sidecar(); !st) return st.error();
    return Session(std::move(impl));
  }

  // New session: the sidecar first, then the CSV with its header.
  json& j = s.sidecar;
  j["format"] = "proprio-study-session";
  j["format_version"] = 1;
  j["study"] = design.name;
  j["kind"] = design.kind;
  j["description"] = design.description;
  j["design_file"] = design.source_name;
  j["design_hash"] = hex64(design_hash(design.source_text));
  j["design_toml"] = design.source_text;
  j["seed"] = design.seed;
  j["participant_seed"] = s.participant_seed;
  j["seed_derivation"] = "participant_seed = mix_seed(mix_seed(seed, participant_index), session); plan shuffle: "
                         "mix_seed(participant_seed, 1); trial n's adaptive choices: mix_seed(participant_seed, "
                         "1000 + n) (proprio/core/random.hpp)";
  j["participant"] = options.participant;
  j["participant_index"] = options.participant_index;
  j["session"] = options.session;
  j["software"] = {{"name", "proprio"},
                   {"version", options.software_version.empty() ? PROPRIO_STUDY_VERSION : options.software_version}};
  j["device"] = *device;
  j["calibration"] = *calibration;
  json factors = json::array();
  for (const Factor& f : design.factors) factors.push_back({{"name", f.name}, {"levels", f.levels}});
  j["factors"] = factors;
  json order = json::array();
  if (!design.block_factor.empty()) {
    for (int b : block_order(design, options.participant_index)) {
      order.push_back(design.block_groups[static_cast<std::size_t>(b)].label);
    }
  }
  j["block_factor"] = design.block_factor;
  j["counterbalance"] = to_string(design.counterbalance);
  j["block_order"] = order;
  j["procedure"] = to_string(design.procedure.kind);
  j["columns"] = {{"all", s.columns},
                  {"stimulus", design.stimulus_column},
                  {"stimulus_unit", design.stimulus_unit},
                  {"response", design.response_column},
                  {"extra", design.extra_columns}};
  json analysis = {{"model", to_string(design.analysis.model)},
                   {"guess", design.analysis.guess},
                   {"threshold", design.analysis.threshold}};
  if (design.analysis.lapse_free) {
    analysis["lapse_max"] = design.analysis.lapse_max;
  } else {
    analysis["lapse"] = design.analysis.lapse;
  }
  j["analysis"] = analysis;
  j["planned_trials"] = s.plan.size();
  j["sync_each_trial"] = options.sync_each_trial;
  j["started_unix_ns"] = unix_ns();
  j["resumes"] = json::array();
  j["completed_trials"] = 0;
  j["status"] = "running";
  if (Status st = write_json_atomically(s.sidecar_path, j); !st) return st.error();

  s.fd = ::open(s.csv_path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_APPEND | O_CLOEXEC, 0644);
  if (s.fd < 0) {
    return make_error(Errc::io_error, fmt::format("cannot create {}: {}", s.csv_path.string(), errno_text()));
  }
  std::string header;
  for (std::size_t i = 0; i < s.columns.size(); ++i) header += (i ? "," : "") + s.columns[i];
  if (Status w = write_all(s.fd, header + "\n", s.csv_path); !w) return w.error();
  sync_directory(options.out_dir);
  return Session(std::move(impl));
}

bool Session::finished() const { return !impl_->prepare_next(); }

Result<Trial> Session::next_trial() {
  if (!impl_->prepare_next()) {
    return make_error(Errc::out_of_range,
                      fmt::format("the session is finished ({} trials recorded in {})", impl_->completed,
                                  impl_->csv_path.string()));
  }
  return *impl_->pending;
}

Status Session::record(const Trial& trial, const Response& response) {
  Impl& s = *impl_;
  if (!s.prepare_next() || trial.index != s.pending->index) {
    return make_error(Errc::invalid_argument,
                      fmt::format("record() got trial {}, but the trial in progress is {}; record the trial "
                                  "next_trial() returned",
                                  trial.index, s.pending ? std::to_string(s.pending->index) : "none"));
  }
  for (const auto& [key, value] : response.extra) {
    if (std::find(s.design.extra_columns.begin(), s.design.extra_columns.end(), key) ==
        s.design.extra_columns.end()) {
      return make_error(Errc::invalid_argument,
                        fmt::format("response value '{}' is not one of the design's extra_columns; declare it in "
                                    "[study] extra_columns",
                                    key));
    }
  }
  // Written from the pending trial, not the caller's copy, so the row always
  // matches what the plan and procedures hold.
  if (Status w = write_all(s.fd, s.row_for(*s.pending, response), s.csv_path, s.options.sync_each_trial); !w) {
    return w;
  }
  s.apply(response.correct);
  if (!s.prepare_next()) return s.update_sidecar();
  return Status::success();
}

int Session::completed_trials() const { return impl_->completed; }
int Session::planned_trials() const { return static_cast<int>(impl_->plan.size()); }
bool Session::resumed() const { return impl_->resumed; }
int Session::recovered_trials() const { return impl_->recovered; }
bool Session::repaired_torn_row() const { return impl_->torn; }
const std::vector<Session::RecordedTrial>& Session::recovered_trial_list() const { return impl_->recovered_list; }
std::uint64_t Session::participant_seed() const { return impl_->participant_seed; }
const std::filesystem::path& Session::csv_path() const { return impl_->csv_path; }
const std::filesystem::path& Session::sidecar_path() const { return impl_->sidecar_path; }
const Procedure* Session::procedure(int cell) const {
  if (cell < 0 || cell >= static_cast<int>(impl_->procedures.size())) return nullptr;
  return impl_->procedures[static_cast<std::size_t>(cell)].get();
}

}  // namespace proprio::study
