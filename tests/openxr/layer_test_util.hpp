#pragma once
// Shared by the layer's dispatch and loader tests: a temp folder, and a
// recording of two still hands whose poses the tests know exactly.
#include <unistd.h>

#include <cstdlib>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>
#include <string>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/recording.hpp"
#include "support/temp_dir.hpp"

namespace layer_test {

namespace fs = std::filesystem;
using namespace proprio;

using proprio::testing_support::TempDir;

inline const HandModel& model() {
  static HandModel m(*HandShape::from_measurements(0.19, 0.10));
  return m;
}

// Each hand still, in a known pose, in the source's frame.
inline HandPose recorded_pose(Handedness hand, TimeNs t) {
  HandAngles a{};
  a[index_of(HandDof::index_mcp_flexion)] = 0.4;
  a[index_of(HandDof::thumb_cmc_abduction)] = 0.3;
  const Pose T_source_wrist{so3_exp(Vec3(0.2, 0.1, -0.3)), Vec3(hand == Handedness::left ? -0.1 : 0.1, -0.2, -0.4)};
  return model().forward(hand, a, T_source_wrist, t);
}

inline fs::path write_still_recording(const fs::path& dir, DurationNs span) {
  const fs::path file = dir / "still.prec";
  auto w = RecordingWriter::create(file, {.overwrite = true});
  auto s = w->add_stream(StreamKind::hand_pose, "hand/both/tracked");
  for (TimeNs t = 0; t <= span; t += 10 * kNsPerMillisecond) {
    (void)w->write(*s, recorded_pose(Handedness::left, t));
    (void)w->write(*s, recorded_pose(Handedness::right, t));
  }
  (void)w->close();
  return file;
}

// The process environment of a layer test on the mock runtime: the loader
// finds the mock runtime and this build's layer, nothing of the user's
// (config, data, mock-runtime switches) leaks in.
inline void use_mock_runtime_with_layer(const fs::path& home, const char* runtime_json, const char* layer_dir) {
  ::setenv("XR_RUNTIME_JSON", runtime_json, 1);
  ::setenv("XR_API_LAYER_PATH", layer_dir, 1);
  ::setenv("XR_ENABLE_API_LAYERS", "XR_APILAYER_PROPRIO_hand_tracking", 1);
  for (const char* v : {"PROPRIO_MOCK_RUNTIME_HAND_TRACKING", "PROPRIO_MOCK_RUNTIME_CONTROLLERS",
                        "PROPRIO_MOCK_RUNTIME_TRACKERS", "PROPRIO_MOCK_RUNTIME_DISCONNECT", "PROPRIO_PLUGIN_DIR"}) {
    ::unsetenv(v);
  }
  ::setenv("XDG_CONFIG_HOME", (home / "config").c_str(), 1);
  ::setenv("XDG_DATA_HOME", (home / "data").c_str(), 1);
}

// The CSV an emulated source writes (proprio/sim/hand_truth_writer.hpp): one
// HandPose per row, in the source's world frame, times on CLOCK_MONOTONIC.
inline std::vector<HandPose> read_truth(const fs::path& file) {
  std::vector<HandPose> rows;
  std::ifstream in(file);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::string cell;
    HandPose p;
    p.active = true;
    std::getline(ss, cell, ',');
    p.time_ns = std::stoll(cell);
    std::getline(ss, cell, ',');
    p.hand = cell == "left" ? Handedness::left : Handedness::right;
    double v[7];
    for (std::size_t j = 0; j < kHandJointCount; ++j) {
      for (double& x : v) {
        std::getline(ss, cell, ',');
        x = std::stod(cell);
      }
      p.T_world_joint[j] = Pose{Quat(v[3], v[4], v[5], v[6]), Vec3(v[0], v[1], v[2])};
    }
    rows.push_back(p);
  }
  return rows;
}

// The row nearest t_ns, or nullptr when none is within max_gap_ns.
inline const HandPose* nearest(const std::vector<HandPose>& rows, TimeNs t_ns, DurationNs max_gap_ns) {
  const HandPose* best = nullptr;
  for (const auto& r : rows) {
    if (std::llabs(r.time_ns - t_ns) <= max_gap_ns && (!best || std::llabs(r.time_ns - t_ns) < std::llabs(best->time_ns - t_ns))) {
      best = &r;
    }
  }
  return best;
}

}  // namespace layer_test
