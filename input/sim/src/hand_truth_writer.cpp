#include "proprio/sim/hand_truth_writer.hpp"

#include <cerrno>
#include <cstring>

#include "proprio/core/file_io.hpp"

namespace proprio::sim {

std::string HandTruthWriter::header() {
  std::string h = "time_ns,hand";
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    const std::string j = "j" + std::to_string(i) + "_";
    for (const char* c : {"px", "py", "pz", "qw", "qx", "qy", "qz"}) h += "," + j + c;
  }
  return h + "\n";
}

Result<std::unique_ptr<HandTruthWriter>> HandTruthWriter::open(const std::filesystem::path& path) {
  if (auto st = check_output_path(path, "ground-truth file"); !st) return st.error();
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) {
    return make_error(Errc::io_error, "cannot write the ground-truth file " + path.string() + ": " + std::strerror(errno));
  }
  auto w = std::unique_ptr<HandTruthWriter>(new HandTruthWriter(f, path));
  const std::string h = header();
  if (std::fwrite(h.data(), 1, h.size(), f) != h.size() || std::fflush(f) != 0) {
    return make_error(Errc::io_error, "cannot write the ground-truth file " + path.string() + ": " + std::strerror(errno));
  }
  return w;
}

HandTruthWriter::~HandTruthWriter() {
  flush();
  std::fclose(file_);
}

void HandTruthWriter::write(const HandPose& truth) noexcept {
  char row[26 * 7 * 16 + 64];
  int n = std::snprintf(row, sizeof row, "%lld,%s", static_cast<long long>(truth.time_ns),
                        truth.hand == Handedness::left ? "left" : "right");
  for (std::size_t i = 0; i < kHandJointCount && n > 0 && n < static_cast<int>(sizeof row); ++i) {
    const Pose& T = truth.T_world_joint[i];
    n += std::snprintf(row + n, sizeof row - static_cast<std::size_t>(n), ",%.6f,%.6f,%.6f,%.7f,%.7f,%.7f,%.7f",
                       T.p.x(), T.p.y(), T.p.z(), T.q.w(), T.q.x(), T.q.y(), T.q.z());
  }
  if (n <= 0 || n >= static_cast<int>(sizeof row) - 1) return;
  row[n++] = '\n';
  std::lock_guard lock(mutex_);
  if (!error_.empty()) return;
  if (std::fwrite(row, 1, static_cast<std::size_t>(n), file_) != static_cast<std::size_t>(n)) {
    error_ = path_.string() + ": " + std::strerror(errno);
    return;
  }
  const TimeNs now = MonotonicClock::instance().now_ns();
  if (now - last_flush_ns_ > kNsPerSecond) {
    last_flush_ns_ = now;
    if (std::fflush(file_) != 0) error_ = path_.string() + ": " + std::strerror(errno);
  }
}

void HandTruthWriter::flush() noexcept {
  std::lock_guard lock(mutex_);
  if (error_.empty() && std::fflush(file_) != 0) error_ = path_.string() + ": " + std::strerror(errno);
}

std::string HandTruthWriter::error() const {
  std::lock_guard lock(mutex_);
  return error_;
}

}  // namespace proprio::sim
