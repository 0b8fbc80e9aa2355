// `proprio calibrate wrist` (wrist_calibration.hpp): the still window and the
// offset's arithmetic, then the OpenXR side as hooks into the probe's session
// and frame loop (xr_probe_hooks.hpp).
#define XR_USE_TIMESPEC
#include <time.h>
// clang-format off
#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>
// clang-format on

#include "proprio/engine/wrist_calibration.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <cstring>

#include "proprio/core/log.hpp"
#include "proprio/core/xr_interop.hpp"
#include "proprio/openxr/XR_PROPRIO_hand_tracking_latency.h"
#include "xr_probe_hooks.hpp"
#include "xr_util.hpp"

namespace proprio::engine {

namespace {

constexpr double kRadToDeg = 180.0 / M_PI;
const Vec3 kUp(0.0, 1.0, 0.0);

constexpr std::array<std::string_view, 17> kViveTrackerRoles = {
    "handheld_object", "left_foot",  "right_foot",  "left_shoulder", "right_shoulder", "left_elbow",
    "right_elbow",     "left_knee",  "right_knee",  "waist",         "chest",          "camera",
    "keyboard",        "left_wrist", "right_wrist", "left_ankle",    "right_ankle"};

double angle_deg(const Quat& a, const Quat& b) { return so3_log(a.conjugate() * b).norm() * kRadToDeg; }

// The chordal mean: sign-aligned quaternions summed and normalised. Exact
// enough for the few degrees a still window spans.
Quat mean_rotation(std::span<const Quat> qs) {
  Eigen::Vector4d sum = Eigen::Vector4d::Zero();
  for (const Quat& q : qs) {
    Eigen::Vector4d v = q.coeffs();
    if (v.dot(qs.front().coeffs()) < 0.0) v = -v;
    sum += v;
  }
  Quat m;
  m.coeffs() = sum.normalized();
  return m;
}

std::string hand_name(Handedness h) { return std::string(to_string(h)); }

std::string device_description(const WristCalibrationOptions& o) {
  return o.device == WristDevice::tracker ? fmt::format("the VIVE tracker with role {} ({})", o.role(), o.device_path())
                                          : fmt::format("the {} controller ({})", hand_name(o.hand), o.device_path());
}

bool finite_in(double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; }

}  // namespace

std::string_view to_string(WristDevice d) noexcept { return d == WristDevice::tracker ? "tracker" : "controller"; }
std::string_view to_string(WristReference r) noexcept { return r == WristReference::pose ? "pose" : "runtime-hand"; }
std::span<const std::string_view> vive_tracker_roles() { return kViveTrackerRoles; }

Status StillnessLimits::validate() const {
  if (!finite_in(max_angular_speed_deg_s, 0.1, 360.0)) {
    return make_error(
        Errc::invalid_argument,
        fmt::format("stillness: max angular speed {} deg/s is out of range (0.1 to 360)", max_angular_speed_deg_s));
  }
  if (!finite_in(max_position_spread_m, 0.0005, 0.5)) {
    return make_error(
        Errc::invalid_argument,
        fmt::format("stillness: max position spread {} m is out of range (0.0005 to 0.5)", max_position_spread_m));
  }
  if (!finite_in(max_rotation_spread_deg, 0.1, 90.0)) {
    return make_error(
        Errc::invalid_argument,
        fmt::format("stillness: max rotation spread {} deg is out of range (0.1 to 90)", max_rotation_spread_deg));
  }
  return {};
}

std::string WristCalibrationOptions::role() const {
  return tracker_role.empty() ? hand_name(hand) + "_wrist" : tracker_role;
}

std::string WristCalibrationOptions::device_path() const {
  return device == WristDevice::tracker ? "/user/vive_tracker_htcx/role/" + role() : "/user/hand/" + hand_name(hand);
}

Status WristCalibrationOptions::validate() const {
  if (!finite_in(seconds, 0.5, 30.0)) {
    return make_error(Errc::invalid_argument, fmt::format("window {} s is out of range (0.5 to 30 s)", seconds));
  }
  if (!finite_in(timeout_s, seconds, 3600.0)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("timeout {} s is out of range (the window, {} s, to 3600 s)", timeout_s, seconds));
  }
  if (!finite_in(countdown_s, 0.0, 60.0)) {
    return make_error(Errc::invalid_argument, fmt::format("countdown {} s is out of range (0 to 60 s)", countdown_s));
  }
  if (!finite_in(wrist_below_device_m, -0.2, 0.2)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("wrist below the device {} m is out of range (-0.2 to 0.2 m)", wrist_below_device_m));
  }
  if (!finite_in(wrist_behind_grip_m, 0.0, 0.3)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("wrist behind the grip {} m is out of range (0 to 0.3 m)", wrist_behind_grip_m));
  }
  if (device == WristDevice::controller && !tracker_role.empty()) {
    return make_error(Errc::invalid_argument, "a tracker role applies only to the tracker device");
  }
  if (device == WristDevice::tracker &&
      std::find(kViveTrackerRoles.begin(), kViveTrackerRoles.end(), role()) == kViveTrackerRoles.end()) {
    std::string all;
    for (auto r : kViveTrackerRoles) all += (all.empty() ? "" : ", ") + std::string(r);
    return make_error(Errc::invalid_argument,
                      fmt::format("'{}' is not a XR_HTCX_vive_tracker_interaction role (one of {})", role(), all));
  }
  return still.validate();
}

std::string WristCalibrationOptions::describe() const {
  std::string s = fmt::format("{} hand, {}, reference {}, {} s still window, timeout {} s", hand_name(hand),
                              device_description(*this), to_string(reference), seconds, timeout_s);
  s += fmt::format("; still: <= {} deg/s, <= {} m, <= {} deg", still.max_angular_speed_deg_s,
                   still.max_position_spread_m, still.max_rotation_spread_deg);
  return s;
}

std::string Stillness::exceeded(const StillnessLimits& limits) const {
  if (peak_angular_speed_deg_s > limits.max_angular_speed_deg_s) {
    return fmt::format("turning at {:.1f} deg/s (limit {:.1f})", peak_angular_speed_deg_s,
                       limits.max_angular_speed_deg_s);
  }
  if (position_spread_m > limits.max_position_spread_m) {
    return fmt::format("moved {:.1f} mm (limit {:.1f})", position_spread_m * 1e3, limits.max_position_spread_m * 1e3);
  }
  if (rotation_spread_deg > limits.max_rotation_spread_deg) {
    return fmt::format("turned {:.1f} deg (limit {:.1f})", rotation_spread_deg, limits.max_rotation_spread_deg);
  }
  return {};
}

Stillness measure_stillness(std::span<const WristSample> window) {
  Stillness s;
  if (window.empty()) return s;
  Vec3 mean_p = Vec3::Zero();
  std::vector<Quat> qs;
  qs.reserve(window.size());
  for (const auto& w : window) {
    mean_p += w.T_local_device.p;
    qs.push_back(w.T_local_device.q);
  }
  mean_p /= static_cast<double>(window.size());
  const Quat mean_q = mean_rotation(qs);
  for (const auto& w : window) {
    s.position_spread_m = std::max(s.position_spread_m, (w.T_local_device.p - mean_p).norm());
    s.rotation_spread_deg = std::max(s.rotation_spread_deg, angle_deg(mean_q, w.T_local_device.q));
  }
  // Each sample against the first one at least the baseline later.
  std::size_t j = 0;
  for (std::size_t i = 0; i < window.size(); ++i) {
    j = std::max(j, i + 1);
    while (j < window.size() && window[j].t_s - window[i].t_s < kAngularSpeedBaselineS) ++j;
    if (j >= window.size()) break;
    const double dt = window[j].t_s - window[i].t_s;
    s.peak_angular_speed_deg_s =
        std::max(s.peak_angular_speed_deg_s, angle_deg(window[i].T_local_device.q, window[j].T_local_device.q) / dt);
  }
  return s;
}

Result<WristCalibrationResult> solve_wrist_calibration(std::span<const WristSample> window,
                                                       const WristCalibrationOptions& options) {
  if (window.size() < 3) {
    return make_error(Errc::invalid_argument,
                      fmt::format("a still window needs at least 3 poses, got {}", window.size()));
  }
  WristCalibrationResult r;
  r.samples = window.size();
  r.window_s = window.back().t_s - window.front().t_s;
  r.stillness = measure_stillness(window);

  if (options.reference == WristReference::runtime_hand) {
    std::vector<Pose> offsets;
    offsets.reserve(window.size());
    for (const auto& w : window) {
      if (!w.T_local_wrist) {
        return make_error(Errc::invalid_argument, "runtime-hand reference: a pose in the window has no wrist joint");
      }
      offsets.push_back(w.T_local_device.inverse() * *w.T_local_wrist);
    }
    Vec3 p = Vec3::Zero();
    std::vector<Quat> qs;
    for (const Pose& o : offsets) {
      p += o.p;
      qs.push_back(o.q);
    }
    p /= static_cast<double>(offsets.size());
    r.T_device_wrist = {mean_rotation(qs), p};
    double sp = 0.0, sr = 0.0;
    for (const Pose& o : offsets) {
      sp += (o.p - p).squaredNorm();
      const double a = angle_deg(r.T_device_wrist.q, o.q);
      sr += a * a;
    }
    r.offset_position_rms_m = std::sqrt(sp / static_cast<double>(offsets.size()));
    r.offset_rotation_rms_deg = std::sqrt(sr / static_cast<double>(offsets.size()));
    r.measured = fmt::format(
        "position and rotation: the mean of inv(device) * runtime wrist joint over {} poses (RMS scatter {:.1f} mm, "
        "{:.2f} deg)",
        r.samples, r.offset_position_rms_m * 1e3, r.offset_rotation_rms_deg);
    return r;
  }

  // The pose reference: the device's mean pose, and the hand's known orientation.
  Vec3 mean_p = Vec3::Zero(), forward = Vec3::Zero();
  std::vector<Quat> qs;
  for (const auto& w : window) {
    mean_p += w.T_local_device.p;
    qs.push_back(w.T_local_device.q);
    forward += w.T_local_view.q * Vec3(0.0, 0.0, -1.0);
  }
  mean_p /= static_cast<double>(window.size());
  forward /= static_cast<double>(window.size());
  forward.y() = 0.0;
  if (forward.norm() < 0.2) {
    return make_error(Errc::invalid_argument,
                      "the headset looked nearly straight up or down, so 'ahead' is not defined: look ahead, level, "
                      "while calibrating");
  }
  const Vec3 f = forward.normalized();  // horizontal, where the head looks
  const Vec3 right = f.cross(kUp);
  r.head_yaw_deg = std::atan2(-f.x(), -f.z()) * kRadToDeg;
  // The wrist's axes in LOCAL (XR_EXT_hand_tracking: +Y back of the hand, -Z to the fingers, X = Y x Z).
  Vec3 y_axis, z_axis = -f;
  if (options.device == WristDevice::tracker) {
    y_axis = kUp;  // flat, palm down, fingers ahead
  } else {
    y_axis = options.hand == Handedness::right ? right : Vec3(-right);  // thumb up, forearm ahead
  }
  Mat3 R_local_wrist;
  R_local_wrist.col(0) = y_axis.cross(z_axis);
  R_local_wrist.col(1) = y_axis;
  R_local_wrist.col(2) = z_axis;
  const Quat q_device = mean_rotation(qs);
  const Quat q_local_wrist(R_local_wrist);
  // The assumed wrist position in LOCAL, relative to the device's.
  const Vec3 wrist_from_device_local = options.device == WristDevice::tracker
                                           ? Vec3(-options.wrist_below_device_m * kUp)
                                           : Vec3(-options.wrist_behind_grip_m * f);
  r.T_device_wrist = {(q_device.conjugate() * q_local_wrist).normalized(),
                      q_device.conjugate() * wrist_from_device_local};
  r.measured = fmt::format(
      "rotation: the device's mean orientation over {} poses against the instructed hand pose ({}) with 'ahead' = "
      "the head's level forward direction (yaw {:.1f} deg); as good as the hand was held",
      r.samples,
      options.device == WristDevice::tracker ? "flat, palm down, fingers ahead"
                                             : "holding the controller, forearm level and ahead, thumb up",
      r.head_yaw_deg);
  r.assumed = options.device == WristDevice::tracker
                  ? fmt::format("position: the wrist joint centre {:.3f} m below the tracker origin (world -Y)",
                                options.wrist_below_device_m)
                  : fmt::format("position: the wrist joint centre {:.3f} m behind the grip point along the forearm",
                                options.wrist_behind_grip_m);
  return r;
}

// ---------------------------------------------------------------- calibrator --

WristCalibrator::WristCalibrator(WristCalibrationOptions options, WristCalibrationReport report)
    : options_(std::move(options)), report_(std::move(report)) {}

void WristCalibrator::fail(Error error) {
  if (!outcome_) outcome_ = Result<WristCalibrationResult>(std::move(error));
}

bool WristCalibrator::feed(double t_s, const WristSample* sample, std::string_view missing) {
  if (outcome_) return false;
  if (!start_s_) start_s_ = t_s;
  if (!measure_start_s_) {
    const double left_s = options_.countdown_s - (t_s - *start_s_);
    if (left_s > 0.0) {
      const int left = static_cast<int>(std::ceil(left_s));
      if (left != last_countdown_) emit(WristCalibrationCountdown{left});
      last_countdown_ = left;
      return true;
    }
    measure_start_s_ = t_s;
    emit(WristCalibrationMeasuring{});
  }

  if (sample == nullptr) {
    if (missing != last_missing_) emit(WristCalibrationWaiting{std::string(missing)});
    last_missing_ = std::string(missing);
    window_.clear();
    last_holding_report_ = 0.0;
  } else {
    ever_tracked_ = true;
    last_missing_.clear();
    window_.push_back(*sample);
    // Keep exactly the last `seconds`: the oldest sample is the last one at or before its start.
    while (window_.size() > 1 && window_[1].t_s <= t_s - options_.seconds) window_.erase(window_.begin());
    const Stillness still = measure_stillness(window_);
    if (std::string why = still.exceeded(options_.still); !why.empty()) {
      last_moved_ = why;
      if (!last_moved_report_s_ || t_s - *last_moved_report_s_ >= 1.0) {
        emit(WristCalibrationMoved{why});
        last_moved_report_s_ = t_s;
      }
      window_.erase(window_.begin(), window_.end() - 1);
      last_holding_report_ = 0.0;
    } else {
      const double held = window_.back().t_s - window_.front().t_s;
      longest_hold_s_ = std::max(longest_hold_s_, held);
      if (held >= options_.seconds) {
        outcome_ = solve_wrist_calibration(window_, options_);
        return false;
      }
      if (held - last_holding_report_ >= 0.5) {
        last_holding_report_ = std::floor(held / 0.5) * 0.5;
        emit(WristCalibrationHolding{held, options_.seconds});
      }
    }
  }

  if (t_s - *measure_start_s_ > options_.timeout_s) {
    if (!ever_tracked_) {
      fail(make_error(Errc::unavailable,
                      fmt::format("{} never became tracked within the {} s timeout ({}). Is it on, paired and in "
                                  "view of the tracking system?",
                                  device_description(options_), options_.timeout_s,
                                  last_missing_.empty() ? std::string("not tracked") : last_missing_)));
    } else {
      fail(make_error(
          Errc::unavailable,
          fmt::format("the device was not held still for {} s within the {} s timeout (the longest still stretch was "
                      "{:.1f} s; last: {}). Rest the arm, hold still and run it again, or raise --timeout",
                      options_.seconds, options_.timeout_s, longest_hold_s_,
                      !last_missing_.empty() ? last_missing_
                      : last_moved_.empty()  ? std::string("not tracked")
                                             : last_moved_)));
    }
    return false;
  }
  return true;
}

// ------------------------------------------------------------------ OpenXR --

namespace {

using detail::xr_result_name;

constexpr XrSpaceLocationFlags kTrackedFlags =
    XR_SPACE_LOCATION_POSITION_VALID_BIT | XR_SPACE_LOCATION_ORIENTATION_VALID_BIT |
    XR_SPACE_LOCATION_POSITION_TRACKED_BIT | XR_SPACE_LOCATION_ORIENTATION_TRACKED_BIT;
constexpr const char* kProprioLayerName = "XR_APILAYER_PROPRIO_hand_tracking";
constexpr const char* kProprioLayerDisableEnv = "DISABLE_XR_APILAYER_PROPRIO_HAND_TRACKING";
// How long a tracker role may take to show up in xrEnumerateViveTrackerPathsHTCX.
constexpr double kTrackerRoleGraceS = 3.0;

constexpr const char* kControllerProfiles[] = {
    "/interaction_profiles/khr/simple_controller",       "/interaction_profiles/oculus/touch_controller",
    "/interaction_profiles/valve/index_controller",      "/interaction_profiles/htc/vive_controller",
    "/interaction_profiles/microsoft/motion_controller",
};
constexpr const char* kTrackerProfile = "/interaction_profiles/htc/vive_tracker_htcx";

Error xr_error(XrResult r, const std::string& what) {
  return make_error(Errc::io_error, fmt::format("{} failed: {} ({})", what, xr_result_name(r), static_cast<int>(r)));
}

// Proprio's layer must not serve this process: the runtime's own devices and
// hands are what is measured. Its implicit install honours the disable
// variable; an explicit enable through XR_ENABLE_API_LAYERS is taken out.
void disable_proprio_layer() {
  ::setenv(kProprioLayerDisableEnv, "1", 1);
  const char* enabled = std::getenv("XR_ENABLE_API_LAYERS");
  if (enabled == nullptr) return;
  std::string kept, item;
  const std::string all(enabled);
  std::size_t start = 0;
  while (start <= all.size()) {
    const std::size_t end = std::min(all.find(':', start), all.size());
    item = all.substr(start, end - start);
    if (!item.empty() && item != kProprioLayerName) kept += (kept.empty() ? "" : ":") + item;
    start = end + 1;
  }
  if (kept != all) {
    logger().info("calibrate wrist: leaving {} out of XR_ENABLE_API_LAYERS for this process", kProprioLayerName);
    if (kept.empty()) {
      ::unsetenv("XR_ENABLE_API_LAYERS");
    } else {
      ::setenv("XR_ENABLE_API_LAYERS", kept.c_str(), 1);
    }
  }
}

// The device's pose action, the head and (tracker) the role check, inside the probe's session.
class XrWrist {
 public:
  XrWrist(const WristCalibrationOptions& options, WristCalibrator& calibrator)
      : options_(options), calibrator_(calibrator) {}

  detail::XrProbeHooks hooks() {
    detail::XrProbeHooks h;
    h.hand_tracking = options_.reference == WristReference::runtime_hand;
    h.extensions = [this](const auto& offered, auto& enable) { return hook_status(extensions(offered, enable)); };
    h.instance_created = [this](XrInstance i, XrSystemId s) { return hook_status(instance_created(i, s)); };
    h.session_started = [this](XrSession s, XrSpace local) { return hook_status(session_started(s, local)); };
    h.frame = [this](const detail::XrProbeFrame& f) { return frame(f); };
    h.session_ending = [this] { session_ending(); };
    return h;
  }
  bool hook_failed() const { return hook_failed_; }

 private:
  Status hook_status(Status s) {
    if (!s) hook_failed_ = true;
    return s;
  }
  Status extensions(const std::vector<XrExtensionProperties>& offered, std::vector<const char*>& enable);
  Status instance_created(XrInstance instance, XrSystemId system);
  Status suggest(const char* profile, const std::string& binding_path, bool& ok);
  Status session_started(XrSession session, XrSpace local);
  bool frame(const detail::XrProbeFrame& f);
  // Whether a tracker with the role is connected; an error when the list cannot be read.
  Result<bool> tracker_connected(std::string& connected_roles);
  void session_ending();

  const WristCalibrationOptions& options_;
  WristCalibrator& calibrator_;
  bool hook_failed_ = false;
  std::uint32_t tracker_ext_version_ = 0;
  XrInstance instance_ = XR_NULL_HANDLE;
  XrSession session_ = XR_NULL_HANDLE;
  XrSpace local_ = XR_NULL_HANDLE, device_space_ = XR_NULL_HANDLE, view_space_ = XR_NULL_HANDLE;
  XrActionSet action_set_ = XR_NULL_HANDLE;
  XrAction pose_action_ = XR_NULL_HANDLE;
  XrPath device_path_ = XR_NULL_PATH;
  PFN_xrEnumerateViveTrackerPathsHTCX enumerate_trackers_ = nullptr;
  bool tracker_seen_ = false;
  double next_tracker_check_s_ = 0.0;
};

Status XrWrist::extensions(const std::vector<XrExtensionProperties>& offered, std::vector<const char*>& enable) {
  if (options_.reference == WristReference::runtime_hand) {
    if (detail::has_extension(offered, XR_PROPRIO_HAND_TRACKING_LATENCY_EXTENSION_NAME)) {
      return make_error(Errc::unavailable,
                        "Proprio's OpenXR layer is still active in this process (XR_PROPRIO_hand_tracking_latency is "
                        "offered), so XR_EXT_hand_tracking would be Proprio's, not the runtime's: --reference "
                        "runtime-hand needs the runtime's own. Check 'proprio layer status'");
    }
    if (!detail::has_extension(offered, XR_EXT_HAND_TRACKING_EXTENSION_NAME)) {
      return make_error(Errc::unsupported,
                        "--reference runtime-hand: the runtime does not offer XR_EXT_hand_tracking itself (Proprio's "
                        "layer is disabled for this command), so there is no optical hand tracking to calibrate "
                        "against. Use --reference pose");
    }
  }
  if (options_.device == WristDevice::tracker) {
    const auto it = std::find_if(offered.begin(), offered.end(), [](const XrExtensionProperties& e) {
      return std::strcmp(e.extensionName, XR_HTCX_VIVE_TRACKER_INTERACTION_EXTENSION_NAME) == 0;
    });
    if (it == offered.end()) {
      return make_error(Errc::unsupported,
                        "the runtime does not offer XR_HTCX_vive_tracker_interaction, so VIVE trackers cannot be read "
                        "through OpenXR. Use --device controller, or a runtime that has it (SteamVR does)");
    }
    tracker_ext_version_ = it->extensionVersion;
    enable.push_back(XR_HTCX_VIVE_TRACKER_INTERACTION_EXTENSION_NAME);
  }
  return {};
}

Status XrWrist::suggest(const char* profile, const std::string& binding_path, bool& ok) {
  ok = false;
  XrPath profile_path = XR_NULL_PATH, binding = XR_NULL_PATH;
  if (XrResult r = xrStringToPath(instance_, profile, &profile_path); XR_FAILED(r)) {
    return xr_error(r, fmt::format("xrStringToPath({})", profile));
  }
  if (XrResult r = xrStringToPath(instance_, binding_path.c_str(), &binding); XR_FAILED(r)) {
    return xr_error(r, fmt::format("xrStringToPath({})", binding_path));
  }
  XrActionSuggestedBinding b{pose_action_, binding};
  XrInteractionProfileSuggestedBinding s{XR_TYPE_INTERACTION_PROFILE_SUGGESTED_BINDING};
  s.interactionProfile = profile_path;
  s.countSuggestedBindings = 1;
  s.suggestedBindings = &b;
  const XrResult r = xrSuggestInteractionProfileBindings(instance_, &s);
  ok = XR_SUCCEEDED(r);
  if (!ok) {
    logger().debug("xrSuggestInteractionProfileBindings({}, {}): {}", profile, binding_path, xr_result_name(r));
    if (options_.device == WristDevice::tracker) {
      return make_error(Errc::unsupported,
                        fmt::format("the runtime refused the binding {} for {} ({}). Its "
                                    "XR_HTCX_vive_tracker_interaction is version {}; the roles left_wrist, "
                                    "right_wrist, left_ankle and right_ankle need version 3: pick another --role "
                                    "(and assign it to the tracker in the runtime's tracker settings)",
                                    binding_path, profile, xr_result_name(r), tracker_ext_version_));
    }
  }
  return {};
}

Status XrWrist::instance_created(XrInstance instance, XrSystemId) {
  instance_ = instance;
  action_set_ = XR_NULL_HANDLE;
  pose_action_ = XR_NULL_HANDLE;
  tracker_seen_ = false;
  next_tracker_check_s_ = 0.0;
  if (options_.device == WristDevice::tracker) {
    enumerate_trackers_ =
        detail::xr_load<PFN_xrEnumerateViveTrackerPathsHTCX>(instance_, "xrEnumerateViveTrackerPathsHTCX");
    if (enumerate_trackers_ == nullptr) {
      return make_error(Errc::unsupported,
                        "the runtime offers XR_HTCX_vive_tracker_interaction but not its "
                        "xrEnumerateViveTrackerPathsHTCX");
    }
  }
  const std::string path = options_.device_path();
  if (XrResult r = xrStringToPath(instance_, path.c_str(), &device_path_); XR_FAILED(r)) {
    return xr_error(r, fmt::format("xrStringToPath({})", path));
  }
  XrActionSetCreateInfo si{XR_TYPE_ACTION_SET_CREATE_INFO};
  std::snprintf(si.actionSetName, sizeof si.actionSetName, "proprio_wrist_calibration");
  std::snprintf(si.localizedActionSetName, sizeof si.localizedActionSetName, "Proprio wrist calibration");
  if (XrResult r = xrCreateActionSet(instance_, &si, &action_set_); XR_FAILED(r)) {
    return xr_error(r, "xrCreateActionSet");
  }
  XrActionCreateInfo ai{XR_TYPE_ACTION_CREATE_INFO};
  std::snprintf(ai.actionName, sizeof ai.actionName, "device_pose");
  std::snprintf(ai.localizedActionName, sizeof ai.localizedActionName, "Tracked device pose");
  ai.actionType = XR_ACTION_TYPE_POSE_INPUT;
  ai.countSubactionPaths = 1;
  ai.subactionPaths = &device_path_;
  if (XrResult r = xrCreateAction(action_set_, &ai, &pose_action_); XR_FAILED(r)) {
    return xr_error(r, "xrCreateAction(device_pose)");
  }
  const std::string binding = path + "/input/grip/pose";
  if (options_.device == WristDevice::tracker) {
    bool ok = false;
    return suggest(kTrackerProfile, binding, ok);
  }
  int accepted = 0;
  for (const char* profile : kControllerProfiles) {
    bool ok = false;
    if (Status s = suggest(profile, binding, ok); !s) return s;
    accepted += ok ? 1 : 0;
  }
  if (accepted == 0) {
    return make_error(Errc::unsupported,
                      fmt::format("the runtime accepted none of the controller profiles Proprio suggests for {} "
                                  "(simple, Touch, Index, VIVE, Windows MR); --log-level debug lists its answers",
                                  binding));
  }
  return {};
}

Status XrWrist::session_started(XrSession session, XrSpace local) {
  session_ = session;
  local_ = local;
  XrSessionActionSetsAttachInfo attach{XR_TYPE_SESSION_ACTION_SETS_ATTACH_INFO};
  attach.countActionSets = 1;
  attach.actionSets = &action_set_;
  if (XrResult r = xrAttachSessionActionSets(session_, &attach); XR_FAILED(r)) {
    return xr_error(r, "xrAttachSessionActionSets");
  }
  XrActionSpaceCreateInfo asi{XR_TYPE_ACTION_SPACE_CREATE_INFO};
  asi.action = pose_action_;
  asi.subactionPath = device_path_;
  asi.poseInActionSpace.orientation.w = 1.0f;
  if (XrResult r = xrCreateActionSpace(session_, &asi, &device_space_); XR_FAILED(r)) {
    return xr_error(r, "xrCreateActionSpace");
  }
  XrReferenceSpaceCreateInfo rsi{XR_TYPE_REFERENCE_SPACE_CREATE_INFO};
  rsi.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_VIEW;
  rsi.poseInReferenceSpace.orientation.w = 1.0f;
  if (XrResult r = xrCreateReferenceSpace(session_, &rsi, &view_space_); XR_FAILED(r)) {
    return xr_error(r, "xrCreateReferenceSpace(VIEW)");
  }
  return {};
}

Result<bool> XrWrist::tracker_connected(std::string& connected_roles) {
  std::uint32_t n = 0;
  if (XrResult r = enumerate_trackers_(instance_, 0, &n, nullptr); XR_FAILED(r)) {
    return xr_error(r, "xrEnumerateViveTrackerPathsHTCX");
  }
  std::vector<XrViveTrackerPathsHTCX> paths(n, XrViveTrackerPathsHTCX{XR_TYPE_VIVE_TRACKER_PATHS_HTCX});
  if (n > 0) {
    if (XrResult r = enumerate_trackers_(instance_, n, &n, paths.data()); XR_FAILED(r)) {
      return xr_error(r, "xrEnumerateViveTrackerPathsHTCX");
    }
    paths.resize(n);
  }
  bool found = false;
  connected_roles.clear();
  for (const auto& p : paths) {
    if (p.rolePath == device_path_) found = true;
    std::string name = "(no role)";
    if (p.rolePath != XR_NULL_PATH) {
      char buf[XR_MAX_PATH_LENGTH] = {};
      std::uint32_t len = 0;
      if (XR_SUCCEEDED(xrPathToString(instance_, p.rolePath, sizeof buf, &len, buf))) {
        name = buf;
        const std::string_view prefix = "/user/vive_tracker_htcx/role/";
        if (name.starts_with(prefix)) name = name.substr(prefix.size());
      }
    }
    connected_roles += (connected_roles.empty() ? "" : ", ") + name;
  }
  return found;
}

bool XrWrist::frame(const detail::XrProbeFrame& f) {
  if (calibrator_.finished()) return false;
  auto fail = [&](Error e) {
    calibrator_.fail(std::move(e));
    return false;
  };
  XrActiveActionSet active{action_set_, XR_NULL_PATH};
  XrActionsSyncInfo sync{XR_TYPE_ACTIONS_SYNC_INFO};
  sync.countActiveActionSets = 1;
  sync.activeActionSets = &active;
  const XrResult synced = xrSyncActions(session_, &sync);
  if (XR_FAILED(synced)) return fail(xr_error(synced, "xrSyncActions"));

  std::string missing;
  XrActionStateGetInfo gi{XR_TYPE_ACTION_STATE_GET_INFO};
  gi.action = pose_action_;
  gi.subactionPath = device_path_;
  XrActionStatePose state{XR_TYPE_ACTION_STATE_POSE};
  if (XrResult r = xrGetActionStatePose(session_, &gi, &state); XR_FAILED(r)) {
    return fail(xr_error(r, "xrGetActionStatePose"));
  }
  WristSample sample;
  sample.t_s = f.t_s;
  if (synced == XR_SESSION_NOT_FOCUSED) {
    missing = "the session is not focused (another app has the input focus), so the runtime gives it no devices";
  } else if (!state.isActive) {
    missing =
        options_.device == WristDevice::tracker
            ? fmt::format("no pose from the tracker with role {} (not connected, or the role is not assigned)",
                          options_.role())
            : fmt::format("no pose from the {} controller (not connected or not bound)", hand_name(options_.hand));
  } else {
    XrSpaceLocation loc{XR_TYPE_SPACE_LOCATION};
    if (XrResult r = xrLocateSpace(device_space_, local_, f.time, &loc); XR_FAILED(r)) {
      return fail(xr_error(r, "xrLocateSpace(device, LOCAL)"));
    }
    if ((loc.locationFlags & kTrackedFlags) != kTrackedFlags) {
      missing = fmt::format("{} is not tracked", device_description(options_));
    } else {
      sample.T_local_device = from_xr(loc.pose);
      tracker_seen_ = true;
    }
  }
  if (missing.empty()) {
    XrSpaceLocation head{XR_TYPE_SPACE_LOCATION};
    if (XrResult r = xrLocateSpace(view_space_, local_, f.time, &head); XR_FAILED(r)) {
      return fail(xr_error(r, "xrLocateSpace(VIEW, LOCAL)"));
    }
    if (!(head.locationFlags & XR_SPACE_LOCATION_ORIENTATION_VALID_BIT)) {
      missing = "the headset's orientation is not known (is it tracked?)";
    } else {
      sample.T_local_view = from_xr(head.pose);
    }
  }
  if (missing.empty() && options_.reference == WristReference::runtime_hand) {
    const auto* joints = f.hands.empty() ? nullptr : f.hands.front().joints;
    if (f.hands.empty() || !f.hands.front().active ||
        (joints[XR_HAND_JOINT_WRIST_EXT].locationFlags & kTrackedFlags) != kTrackedFlags) {
      missing = fmt::format("the runtime does not track the {} hand (keep it in the headset's view)",
                            hand_name(options_.hand));
    } else {
      sample.T_local_wrist = from_xr(joints[XR_HAND_JOINT_WRIST_EXT].pose);
    }
  }
  // A tracker whose role nobody has: say so once the runtime had time to list it.
  if (options_.device == WristDevice::tracker && !tracker_seen_ && f.t_s >= next_tracker_check_s_) {
    next_tracker_check_s_ = f.t_s + 0.5;
    std::string roles;
    auto connected = tracker_connected(roles);
    if (!connected) return fail(connected.error());
    if (*connected) {
      tracker_seen_ = true;
    } else if (f.t_s >= std::min(kTrackerRoleGraceS, options_.countdown_s + options_.timeout_s)) {
      return fail(make_error(
          Errc::not_found,
          fmt::format("no VIVE tracker with the role {} is connected (connected trackers' roles: {}). Assign the role "
                      "in the runtime's tracker settings (SteamVR: Settings > Controllers > Manage Trackers), or "
                      "pass --role",
                      options_.role(), roles.empty() ? "none" : roles)));
    }
  }
  if (missing.empty()) return calibrator_.feed(f.t_s, &sample);
  return calibrator_.feed(f.t_s, nullptr, missing);
}

void XrWrist::session_ending() {
  for (XrSpace* s : {&device_space_, &view_space_}) {
    if (*s != XR_NULL_HANDLE) {
      if (XrResult r = xrDestroySpace(*s); XR_FAILED(r)) logger().error("{}", xr_error(r, "xrDestroySpace").message);
      *s = XR_NULL_HANDLE;
    }
  }
  if (action_set_ != XR_NULL_HANDLE) {
    if (XrResult r = xrDestroyActionSet(action_set_); XR_FAILED(r)) {
      logger().error("{}", xr_error(r, "xrDestroyActionSet").message);
    }
    action_set_ = XR_NULL_HANDLE;
    pose_action_ = XR_NULL_HANDLE;
  }
  session_ = XR_NULL_HANDLE;
}

}  // namespace

Result<WristCalibrationResult> run_wrist_calibration(const WristCalibrationOptions& options,
                                                     const WristCalibrationReport& report) {
  if (Status s = options.validate(); !s) return s.error();
  disable_proprio_layer();

  WristCalibrator calibrator(options, report);
  XrWrist xr(options, calibrator);
  const detail::XrProbeHooks hooks = xr.hooks();

  XrProbeOptions probe;
  // The calibrator's own timeout ends the run; this only bounds it.
  probe.duration_s = options.countdown_s + options.timeout_s + 5.0;
  probe.space = XrProbeSpace::local;
  probe.hands = options.hand == Handedness::left ? XrProbeHands::left : XrProbeHands::right;
  probe.session = options.session;
  probe.stop = options.stop;
  auto forward = [&report](const XrProbeEvent& e) {
    if (!report) return;
    if (const auto* r = std::get_if<XrProbeRuntime>(&e)) report(*r);
    if (const auto* h = std::get_if<XrProbeHeadlessRefused>(&e)) report(*h);
    if (const auto* s = std::get_if<XrProbeSessionStarted>(&e)) report(*s);
    if (const auto* z = std::get_if<XrProbeZeroDisplayTime>(&e)) report(*z);
  };
  auto summary = detail::run_xr_probe_hooked(probe, forward, hooks);

  if (calibrator.outcome()) return *calibrator.outcome();
  if (!summary) {
    Error e = summary.error();
    if (e.message.empty()) e.message = "stopped before the session started; nothing was measured";
    if (options.reference == WristReference::runtime_hand && e.code == kXrProbeNoHandTracking && !xr.hook_failed()) {
      e.message =
          "--reference runtime-hand: the runtime offers XR_EXT_hand_tracking but its system reports "
          "supportsHandTracking = false (no hand tracking on this device, or it is switched off). Use "
          "--reference pose";
    }
    return e;
  }
  if (summary->interrupted) return make_error(Errc::unavailable, "stopped before the calibration finished");
  return make_error(Errc::unavailable, "the runtime ended the session before the calibration finished");
}

}  // namespace proprio::engine
