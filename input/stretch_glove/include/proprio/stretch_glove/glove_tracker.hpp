#pragma once
// The stretch glove's run-time pipeline from recovered cells to a hand
// (Glauser 2019, Sec. 5.2.1 and 5.3):
//
//   measurements ─► MatrixReadout (C_c = M⁺ C_m every 16 updates, 5-frame mean)   readout.hpp
//   C_c ─► MinMaxCalibration (per-user min-max to [-1, 1]) ─► 2x5x5 grid            calibration.hpp
//   grid ─► OnnxPoseModel (U-Net through OpenCV DNN) ─► 5x5 pose map                onnx_pose_model.hpp
//   pose map ─► 20 joint angles (clamped to the joint limits) ─► 1€ filter ─► HandModel FK ─► 26 joints
//
// The glove senses finger articulation only: the wrist pose comes from
// elsewhere (a tracker, a controller, or a fixed pose), through WristPoseProvider.
//
// Degradation. A cell that is NaN, saturated-out or dead is flagged by the
// read-out; its input is set to 0 (the middle of its calibrated range) and the
// joints of the finger it sits on lose TRACKED (dorsum and web cells: the
// fingers next to them). With more than max_invalid_fraction of the cells
// invalid, or a model output that is not finite, the last good angles are held
// and no joint is TRACKED. Poses stay VALID: the hand is still drawn.
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/hand_pose.hpp"
#include "proprio/core/one_euro_filter.hpp"
#include "proprio/glove_descriptions/stretch_glove_layout.hpp"
#include "proprio/stretch_glove/calibration.hpp"
#include "proprio/stretch_glove/onnx_pose_model.hpp"
#include "proprio/stretch_glove/readout.hpp"

namespace proprio::stretch_glove {

// Where the wrist is at time t; nullopt: unknown now (the hand is then
// reported at the last known wrist pose, not TRACKED).
using WristPoseProvider = std::function<std::optional<Pose>(TimeNs t_ns)>;

struct GloveTrackerOptions {
  Handedness hand = Handedness::right;
  // The wearer's hand, for the 26 joint positions (the network gives angles).
  double hand_length_m = 0.19;
  double hand_width_m = 0.10;
  // Wrist pose when no provider is set: 40 cm in front of and 30 cm below the
  // tracking origin, palm down, fingers pointing forward (-Z). Trusted as
  // tracked, since the user configured it.
  Pose T_world_wrist_fixed{Quat(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitX())), Vec3(0.0, -0.3, -0.4)};
  bool filter_output = true;
  OneEuroOptions one_euro{1.0, 0.5, 1.0};  // on joint angles: cutoff 1 Hz at rest, +0.5 Hz per rad/s
  double max_invalid_fraction = 0.25;

  Status validate() const;
  std::string describe() const;
};

struct GloveTrackerStats {
  std::uint64_t frames = 0;
  std::uint64_t frames_degraded = 0;  // some cells invalid
  std::uint64_t frames_held = 0;      // too many invalid cells, or a non-finite model output
  std::uint64_t inference_failures = 0;
  std::string describe() const;
};

class GloveTracker {
 public:
  static Result<GloveTracker> create(const StretchGloveLayout& layout, MinMaxCalibration calibration,
                                     OnnxPoseModel model, GloveTrackerOptions options = {});

  // One recovered frame to a hand pose at frame.time_ns. Returns false when
  // the angles were held (see the top of this file); `out` is filled anyway.
  bool process(const CellFrame& frame, HandPose& out);

  void set_wrist_provider(WristPoseProvider provider) { wrist_provider_ = std::move(provider); }
  void set_calibration(MinMaxCalibration calibration);
  // The newest angles after filtering, radians, HandDof order.
  const HandAngles& angles() const noexcept { return angles_; }
  // Per DoF: whether the cells it depends on were all valid in the last frame.
  const std::array<bool, kHandDofCount>& dof_tracked() const noexcept { return dof_tracked_; }
  const GloveTrackerStats& stats() const noexcept { return stats_; }
  const GloveTrackerOptions& options() const noexcept { return options_; }
  const MinMaxCalibration& calibration() const noexcept { return calibration_; }

 private:
  GloveTracker(const StretchGloveLayout& layout, MinMaxCalibration calibration, OnnxPoseModel model,
               GloveTrackerOptions options, HandModel hand);

  StretchGloveLayout layout_;
  MinMaxCalibration calibration_;
  OnnxPoseModel model_;
  GloveTrackerOptions options_;
  HandModel hand_model_;
  InputGrid grid_;
  OneEuroFilter filter_;
  WristPoseProvider wrist_provider_;
  Pose last_wrist_;
  // Per cell: the fingers whose DoFs it informs (bit f = Finger f).
  std::vector<std::uint8_t> cell_fingers_;
  std::vector<float> normalized_, input_;
  std::array<float, kPoseOutputSize> output_{};
  HandAngles angles_{};
  bool have_angles_ = false;
  std::array<bool, kHandDofCount> dof_tracked_{};
  GloveTrackerStats stats_;
};

}  // namespace proprio::stretch_glove
