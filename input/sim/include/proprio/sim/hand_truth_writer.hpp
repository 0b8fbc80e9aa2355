#pragma once
// Ground truth of an emulated wearer, written as the emulation runs, so a test
// or a benchmark outside the process (an OpenXR app through the layer) can
// compare what the tracker served with where the hand really was. The
// tracker never reads it.
//
// CSV, one row per pose: time_ns (CLOCK_MONOTONIC), hand (left|right), then
// for each of the 26 XR joints px, py, pz (m), qw, qx, qy, qz of T_world_joint
// in the source's world frame (its tracking origin). Rows are buffered and
// flushed about once a second, so a reader sees whole rows only after a flush;
// a process that crashes loses at most the last second.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>

#include "proprio/core/hand_pose.hpp"
#include "proprio/core/result.hpp"

namespace proprio::sim {

class HandTruthWriter {
 public:
  // Creates (or truncates) the file; refuses what check_output_path refuses.
  static Result<std::unique_ptr<HandTruthWriter>> open(const std::filesystem::path& path);
  ~HandTruthWriter();
  HandTruthWriter(const HandTruthWriter&) = delete;
  HandTruthWriter& operator=(const HandTruthWriter&) = delete;

  // Thread-safe. A write error is remembered (error()) and later rows dropped:
  // the emulation goes on, only the truth is incomplete.
  void write(const HandPose& truth) noexcept;
  void flush() noexcept;
  // Empty while every row was written.
  std::string error() const;

  static std::string header();

 private:
  HandTruthWriter(std::FILE* file, std::filesystem::path path) : file_(file), path_(std::move(path)) {}
  mutable std::mutex mutex_;
  std::FILE* file_;
  std::filesystem::path path_;
  TimeNs last_flush_ns_ = 0;
  std::string error_;
};

}  // namespace proprio::sim
