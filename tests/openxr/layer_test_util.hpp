#pragma once
// Shared by the layer's dispatch and loader tests: a temp folder, and a
// recording of two still hands whose poses the tests know exactly.
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
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

}  // namespace layer_test
