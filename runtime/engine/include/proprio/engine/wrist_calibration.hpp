#pragma once
// `proprio calibrate wrist`: measures T_device_wrist, the wearer's wrist joint
// in a tracked device's grip-pose frame (a VIVE-style wrist tracker through
// XR_HTCX_vive_tracker_interaction, or a controller's grip pose), so that
// Proprio's OpenXR layer can put a glove's fingers on the right wrist
// (layer config: wrist = "tracker" | "controller", wrist_calibration = FILE).
// The wrist frame is XR_EXT_hand_tracking's: +Y out of the back of the hand,
// -Z toward the fingers. docs/wrist-calibration.md has the procedure.
//
// Two references for the wrist:
//  - pose: the user holds the hand in a known pose while the device is held
//    still; the wrist's orientation follows from that pose and the head's
//    horizontal forward direction (measured), its position from a documented
//    assumption (wrist_below_device_m, wrist_behind_grip_m).
//  - runtime_hand: the runtime's own optical hand tracking (XR_EXT_hand_tracking
//    offered by the runtime, Proprio's layer disabled in this process) gives
//    the wrist joint; T_device_wrist is the mean of inv(T_local_device) *
//    T_local_wrist over the still window. Fully measured.
//
// The OpenXR side runs inside the probe's session and frame loop (xr_probe.hpp)
// through its hooks; the arithmetic (WristCalibrator, solve_wrist_calibration)
// needs no OpenXR and is tested on its own.
#include <atomic>
#include <cstddef>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/engine/xr_probe.hpp"

namespace proprio::engine {

enum class WristDevice { tracker, controller };
enum class WristReference { pose, runtime_hand };
std::string_view to_string(WristDevice d) noexcept;     // "tracker", "controller"
std::string_view to_string(WristReference r) noexcept;  // "pose", "runtime-hand"

// The roles XR_HTCX_vive_tracker_interaction names (left_wrist, right_wrist,
// left_ankle and right_ankle since its version 3).
std::span<const std::string_view> vive_tracker_roles();

// When the device counts as held still: over the whole window, every one of these.
struct StillnessLimits {
  // Peak rotation rate, from orientations at least kAngularSpeedBaselineS apart
  // (tracking jitter over one frame would read as speed).
  double max_angular_speed_deg_s = 10.0;
  double max_position_spread_m = 0.01;   // largest distance of a position from the window's mean
  double max_rotation_spread_deg = 5.0;  // largest angle of an orientation from the window's mean
  Status validate() const;
};
inline constexpr double kAngularSpeedBaselineS = 0.1;

struct WristCalibrationOptions {
  Handedness hand = Handedness::right;
  WristDevice device = WristDevice::tracker;
  WristReference reference = WristReference::pose;
  std::string tracker_role;  // empty: "<hand>_wrist"
  double seconds = 2.0;      // the still window that is averaged
  double timeout_s = 30.0;   // to get one, from the end of the countdown
  double countdown_s = 5.0;  // before measuring; 0 starts at once (--non-interactive)
  // The pose reference's translation assumptions (not used by runtime_hand):
  double wrist_below_device_m = 0.03;  // tracker: the wrist joint centre below the tracker origin, along world -Y
  double wrist_behind_grip_m = 0.08;   // controller: the wrist behind the grip point along the forearm
  StillnessLimits still;
  XrProbeSession session = XrProbeSession::automatic;
  const std::atomic<bool>* stop = nullptr;  // polled; true ends the run (Ctrl-C). Not owned.

  std::string role() const;  // tracker_role, or the hand's default
  // The OpenXR top-level path of the device: /user/hand/<hand> or /user/vive_tracker_htcx/role/<role>.
  std::string device_path() const;
  Status validate() const;
  std::string describe() const;
};

// One frame's poses in LOCAL.
struct WristSample {
  double t_s = 0.0;
  Pose T_local_device;                // the device's grip pose
  Pose T_local_view;                  // the head (its -Z: where it looks)
  std::optional<Pose> T_local_wrist;  // runtime_hand: the runtime's wrist joint
};

struct Stillness {
  double peak_angular_speed_deg_s = 0.0;
  double position_spread_m = 0.0;
  double rotation_spread_deg = 0.0;
  // Why the window is not still (the first limit exceeded, with its numbers); empty when it is.
  std::string exceeded(const StillnessLimits& limits) const;
};
Stillness measure_stillness(std::span<const WristSample> window);

struct WristCalibrationResult {
  Pose T_device_wrist;
  std::string measured;  // what came from the poses
  std::string assumed;   // what came from an assumption; empty for runtime_hand
  std::size_t samples = 0;
  double window_s = 0.0;
  Stillness stillness;
  // runtime_hand: RMS scatter of the per-frame offsets about their mean.
  double offset_position_rms_m = 0.0, offset_rotation_rms_deg = 0.0;
  // pose: the head's horizontal forward direction the hand was aligned with
  // (yaw about +Y, 0 = LOCAL's -Z).
  double head_yaw_deg = 0.0;
};

// The offset from a still window (no OpenXR), by options.device and .reference.
Result<WristCalibrationResult> solve_wrist_calibration(std::span<const WristSample> window,
                                                       const WristCalibrationOptions& options);

// What the calibration reports while it runs (besides the probe's runtime and session events).
struct WristCalibrationCountdown {
  int seconds_left = 0;
};
struct WristCalibrationMeasuring {};  // the countdown is over: hold still now
struct WristCalibrationWaiting {      // something needed is not tracked this frame (reported when it changes)
  std::string what;
};
struct WristCalibrationHolding {  // still so far, about every 0.5 s
  double held_s = 0.0, needed_s = 0.0;
};
struct WristCalibrationMoved {  // the window was not still: starting it again (at most once a second)
  std::string why;
};
using WristCalibrationEvent = std::variant<XrProbeRuntime, XrProbeHeadlessRefused, XrProbeSessionStarted,
                                           XrProbeZeroDisplayTime, WristCalibrationCountdown, WristCalibrationMeasuring,
                                           WristCalibrationWaiting, WristCalibrationHolding, WristCalibrationMoved>;
using WristCalibrationReport = std::function<void(const WristCalibrationEvent&)>;

// The countdown, the still window and the timeout, one frame at a time.
class WristCalibrator {
 public:
  WristCalibrator(WristCalibrationOptions options, WristCalibrationReport report);
  // A frame at t_s (seconds, from any origin, not decreasing). sample nullptr:
  // something needed was not tracked; `missing` says what. False once finished.
  bool feed(double t_s, const WristSample* sample, std::string_view missing = {});
  // Ends it with an error found elsewhere (an OpenXR call, no tracker with the role).
  void fail(Error error);
  bool finished() const { return outcome_.has_value(); }
  const std::optional<Result<WristCalibrationResult>>& outcome() const { return outcome_; }

 private:
  void emit(WristCalibrationEvent e) const {
    if (report_) report_(e);
  }
  WristCalibrationOptions options_;
  WristCalibrationReport report_;
  std::optional<double> start_s_, measure_start_s_;
  int last_countdown_ = -1;
  std::vector<WristSample> window_;
  bool ever_tracked_ = false;
  std::string last_missing_;
  double longest_hold_s_ = 0.0;
  std::string last_moved_;
  std::optional<double> last_moved_report_s_;
  double last_holding_report_ = 0.0;
  std::optional<Result<WristCalibrationResult>> outcome_;
};

// Runs the whole calibration on the active OpenXR runtime: session (headless,
// else Vulkan), the device's pose action in LOCAL, the head, the still
// window. Disables Proprio's own layer in this process first
// (DISABLE_XR_APILAYER_PROPRIO_HAND_TRACKING, and its name taken out of
// XR_ENABLE_API_LAYERS): the runtime's devices and hands are what is measured.
Result<WristCalibrationResult> run_wrist_calibration(const WristCalibrationOptions& options,
                                                     const WristCalibrationReport& report);

}  // namespace proprio::engine
