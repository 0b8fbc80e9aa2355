// `proprio xr-probe --haptics` (xr_probe.hpp): checks a fingertip-haptics setup
// end to end through the system's loader, as any app sees it. It enables
// XR_PROPRIO_fingertip_haptics, lists each hand's devices, waits for the
// session to be FOCUSED (the layer drives the devices only then) and for the
// gates to ramp in, then presses each present finger in turn (0.5 N on the
// pad, +Y in the fingertip frame, baseSpace XR_NULL_HANDLE, submitted every
// frame for 0.3 s) and reads what the layer commanded and what the device
// measured, and whether each was gone within 0.2 s of the last submission.
// It runs on the probe's own session and frame loop (hooks).
#define XR_USE_TIMESPEC
#include <time.h>
// clang-format off
#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>
// clang-format on

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "proprio/core/log.hpp"
#include "proprio/engine/xr_probe.hpp"
#include "proprio/openxr/XR_PROPRIO_fingertip_haptics.h"
#include "xr_probe_hooks.hpp"
#include "xr_util.hpp"

namespace proprio::engine {

namespace {

constexpr double kPressN = 0.5;
constexpr double kFocusWaitS = 5.0;  // from the first frame to FOCUSED, at most
constexpr double kGateWaitS = 2.0;   // from focus to every gate ACTIVE (a ramp-in is 0.4 s), at most
constexpr double kPressS = 0.3;
constexpr double kReleaseS = 0.2;
constexpr float kReleasedN = 0.01f;
constexpr const char* kFingerNames[] = {"thumb", "index", "middle", "ring", "little"};

class HapticsCheck {
 public:
  explicit HapticsCheck(const XrProbeReport& report) : report_(report) {}

  detail::XrProbeHooks hooks() {
    detail::XrProbeHooks h;
    h.hand_tracking = false;
    h.extensions = [this](const std::vector<XrExtensionProperties>& offered, std::vector<const char*>& enable) -> Status {
      if (!detail::has_extension(offered, XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME)) {
        return make_error(Errc::unsupported,
                          "XR_PROPRIO_fingertip_haptics is not offered: enable Proprio's layer "
                          "(XR_ENABLE_API_LAYERS=XR_APILAYER_PROPRIO_hand_tracking, or --enable-layer)");
      }
      enable.push_back(XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME);
      return {};
    };
    h.instance_created = [this](XrInstance instance, XrSystemId system) { return on_instance(instance, system); };
    h.session_started = [this](XrSession session, XrSpace) { return on_session(session); };
    h.frame = [this](const detail::XrProbeFrame& frame) { return on_frame(frame); };
    h.session_ending = [this] { end_session(); };
    return h;
  }

  const std::vector<XrProbeHapticsFinger>& fingers() const { return fingers_; }
  bool finished() const { return finished_; }
  const std::optional<Error>& failure() const { return failure_; }

 private:
  template <typename F>
  Status load(XrInstance instance, const char* name, F& fn) {
    const XrResult r = xrGetInstanceProcAddr(instance, name, reinterpret_cast<PFN_xrVoidFunction*>(&fn));
    if (XR_FAILED(r)) return make_error(Errc::unsupported, fmt::format("{}: {}", name, xr_result_name(r)));
    return {};
  }

  Status on_instance(XrInstance instance, XrSystemId system) {
    for (Status s : {load(instance, "xrCreateFingertipHapticsPROPRIO", create_),
                     load(instance, "xrDestroyFingertipHapticsPROPRIO", destroy_),
                     load(instance, "xrGetFingertipHapticsPropertiesPROPRIO", properties_),
                     load(instance, "xrApplyFingertipForcesPROPRIO", apply_),
                     load(instance, "xrGetFingertipHapticsStatePROPRIO", state_)}) {
      if (!s) return s;
    }
    XrSystemFingertipHapticsPropertiesPROPRIO fp{XR_TYPE_SYSTEM_FINGERTIP_HAPTICS_PROPERTIES_PROPRIO};
    XrSystemProperties sp{XR_TYPE_SYSTEM_PROPERTIES};
    sp.next = &fp;
    if (const XrResult r = xrGetSystemProperties(instance, system, &sp); XR_FAILED(r)) {
      return make_error(Errc::io_error, fmt::format("xrGetSystemProperties: {}", xr_result_name(r)));
    }
    if (!fp.supportsFingertipHaptics) {
      return make_error(Errc::unsupported,
                        "the layer has no fingertip devices (supportsFingertipHaptics is false): its configuration "
                        "has no [haptics] table, or one it refused (its log says why; check with 'proprio layer "
                        "status', docs/openxr-layer.md)");
    }
    return {};
  }

  Status on_session(XrSession session) {
    XrFingertipHapticsCreateInfoPROPRIO info{XR_TYPE_FINGERTIP_HAPTICS_CREATE_INFO_PROPRIO};
    info.contactSimulation = XR_FALSE;
    if (const XrResult r = create_(session, &info, &haptics_); XR_FAILED(r)) {
      return make_error(Errc::unavailable,
                        fmt::format("xrCreateFingertipHapticsPROPRIO: {}; the layer's log says why (a device that "
                                    "did not open, a bad model file)",
                                    xr_result_name(r)));
    }
    fingers_.clear();
    absent_.clear();
    for (XrHandEXT hand : {XR_HAND_LEFT_EXT, XR_HAND_RIGHT_EXT}) {
      XrFingertipHapticsPropertiesPROPRIO p{XR_TYPE_FINGERTIP_HAPTICS_PROPERTIES_PROPRIO};
      if (const XrResult r = properties_(haptics_, hand, &p); XR_FAILED(r)) {
        return make_error(Errc::io_error, fmt::format("xrGetFingertipHapticsPropertiesPROPRIO: {}", xr_result_name(r)));
      }
      for (std::size_t f = 0; f < XR_FINGERTIP_COUNT_PROPRIO; ++f) {
        const XrFingertipDevicePropertiesPROPRIO& d = p.fingers[f];
        const XrProbeHand which = hand == XR_HAND_LEFT_EXT ? XrProbeHand::left : XrProbeHand::right;
        if (!d.present) {
          absent_.emplace_back(which, kFingerNames[f]);
          continue;
        }
        XrProbeHapticsFinger out;
        out.hand = which;
        out.finger = kFingerNames[f];
        out.finger_index = static_cast<int>(f);
        out.device = d.deviceName;
        out.connected = d.connected == XR_TRUE;
        out.force_dofs = d.forceDofCount;
        out.max_normal_n = d.maxNormalForce;
        out.max_shear_n = d.maxShearForce;
        fingers_.push_back(out);
      }
    }
    if (fingers_.empty()) return make_error(Errc::unavailable, "the layer lists no fingertip device on either hand");
    first_frame_s_ = focused_s_ = start_s_ = -1.0;
    return {};
  }

  // Waits for focus and the gates, then per finger: press, release; false
  // when every finger is done or the check failed.
  bool on_frame(const detail::XrProbeFrame& frame) {
    if (haptics_ == XR_NULL_HANDLE || failure_) return false;
    if (first_frame_s_ < 0.0) {
      first_frame_s_ = frame.t_s;
      if (report_) report_(XrProbeHapticsDevices{fingers_, absent_});  // after the probe has said which session runs
    }
    const bool focused = frame.state == XR_SESSION_STATE_FOCUSED;
    if (start_s_ < 0.0) return wait_until_ready(frame, focused);
    if (!focused) {
      failure_ = make_error(Errc::unavailable,
                            fmt::format("the session lost input focus during the presses (it is {} now): the layer "
                                        "drives the fingertip devices only while the app is FOCUSED",
                                        xr_session_state_name(frame.state)));
      return false;
    }
    const double t = frame.t_s - start_s_;
    const double slot = kPressS + kReleaseS;
    const auto finger = static_cast<std::size_t>(t / slot);
    if (finger >= fingers_.size()) {
      finished_ = true;
      return false;
    }
    XrProbeHapticsFinger& f = fingers_[finger];
    const XrHandEXT hand = f.hand == XrProbeHand::left ? XR_HAND_LEFT_EXT : XR_HAND_RIGHT_EXT;
    const bool pressing = t - static_cast<double>(finger) * slot < kPressS;
    // Release: nothing submitted, so the layer's fade to zero is what is checked.
    if (pressing) {
      XrFingertipForcesPROPRIO forces{XR_TYPE_FINGERTIP_FORCES_PROPRIO};
      forces.hand = hand;
      forces.baseSpace = XR_NULL_HANDLE;  // the fingertip frames
      forces.forces[f.finger_index] = {0.0f, static_cast<float>(kPressN), 0.0f};
      if (const XrResult r = apply_(haptics_, &forces); XR_FAILED(r)) {
        failure_ = make_error(Errc::io_error, fmt::format("xrApplyFingertipForcesPROPRIO: {}", xr_result_name(r)));
        return false;
      }
      last_submit_s_ = frame.t_s;
    }
    XrFingertipHapticsStatePROPRIO s{XR_TYPE_FINGERTIP_HAPTICS_STATE_PROPRIO};
    if (const XrResult r = state_(haptics_, hand, &s); XR_FAILED(r)) {
      failure_ = make_error(Errc::io_error, fmt::format("xrGetFingertipHapticsStatePROPRIO: {}", xr_result_name(r)));
      return false;
    }
    const XrFingertipStatePROPRIO& st = s.fingers[f.finger_index];
    f.peak_commanded_n = std::max(f.peak_commanded_n, static_cast<double>(st.commandedForce.y));
    f.peak_measured_n = std::max(f.peak_measured_n, static_cast<double>(st.measuredForce.y));
    if (!pressing) {
      const double since_last = frame.t_s - last_submit_s_;
      if (!f.released_after_s && std::abs(st.commandedForce.y) < kReleasedN) f.released_after_s = since_last;
      if (!f.measured_released_after_s && std::abs(st.measuredForce.y) < kReleasedN) {
        f.measured_released_after_s = since_last;
      }
    }
    return true;
  }

  // Before the presses: FOCUSED (within kFocusWaitS of the first frame), then
  // every present finger's gate ACTIVE (or kGateWaitS gone: the presses go
  // ahead and say what each device did).
  bool wait_until_ready(const detail::XrProbeFrame& frame, bool focused) {
    if (!focused) {
      if (focused_s_ >= 0.0) {
        failure_ = make_error(Errc::unavailable,
                              fmt::format("the session lost input focus before the presses (it is {} now): the "
                                          "layer drives the fingertip devices only while the app is FOCUSED",
                                          xr_session_state_name(frame.state)));
        return false;
      }
      if (frame.t_s - first_frame_s_ > kFocusWaitS) {
        failure_ = make_error(Errc::unavailable,
                              fmt::format("the session did not become FOCUSED within {:.0f} s (it stayed {}): the "
                                          "layer drives the fingertip devices only while the app has input focus; "
                                          "is another app or the runtime's own menu in front?",
                                          kFocusWaitS, xr_session_state_name(frame.state)));
        return false;
      }
      return true;
    }
    if (focused_s_ < 0.0) focused_s_ = frame.t_s;
    bool all_active = true;
    for (XrHandEXT hand : {XR_HAND_LEFT_EXT, XR_HAND_RIGHT_EXT}) {
      XrFingertipHapticsStatePROPRIO s{XR_TYPE_FINGERTIP_HAPTICS_STATE_PROPRIO};
      if (const XrResult r = state_(haptics_, hand, &s); XR_FAILED(r)) {
        failure_ = make_error(Errc::io_error, fmt::format("xrGetFingertipHapticsStatePROPRIO: {}", xr_result_name(r)));
        return false;
      }
      for (const XrProbeHapticsFinger& f : fingers_) {
        if ((f.hand == XrProbeHand::left) != (hand == XR_HAND_LEFT_EXT)) continue;
        all_active = all_active && s.fingers[f.finger_index].gateState == XR_FINGERTIP_GATE_STATE_ACTIVE_PROPRIO;
      }
    }
    const double waited = frame.t_s - focused_s_;
    if (!all_active && waited < kGateWaitS) return true;
    start_s_ = frame.t_s;
    if (report_) report_(XrProbeHapticsReady{focused_s_ - first_frame_s_, waited, all_active});
    return true;
  }

  void end_session() {
    if (haptics_ != XR_NULL_HANDLE && destroy_) destroy_(haptics_);
    haptics_ = XR_NULL_HANDLE;
  }

  const XrProbeReport& report_;
  PFN_xrCreateFingertipHapticsPROPRIO create_ = nullptr;
  PFN_xrDestroyFingertipHapticsPROPRIO destroy_ = nullptr;
  PFN_xrGetFingertipHapticsPropertiesPROPRIO properties_ = nullptr;
  PFN_xrApplyFingertipForcesPROPRIO apply_ = nullptr;
  PFN_xrGetFingertipHapticsStatePROPRIO state_ = nullptr;
  XrFingertipHapticsPROPRIO haptics_ = XR_NULL_HANDLE;
  std::vector<XrProbeHapticsFinger> fingers_;
  std::vector<std::pair<XrProbeHand, std::string>> absent_;
  double first_frame_s_ = -1.0;  // the frame loop's first frame
  double focused_s_ = -1.0;      // the first FOCUSED frame
  double start_s_ = -1.0;        // the presses' start
  double last_submit_s_ = 0.0;
  bool finished_ = false;
  std::optional<Error> failure_;
};

}  // namespace

bool XrProbeHapticsFinger::passed() const {
  return connected && peak_commanded_n > 0.8 * kPressN && peak_measured_n > 0.1 && released_after_s.has_value() &&
         measured_released_after_s.has_value();
}

double xr_probe_haptics_press_n() { return kPressN; }

Result<std::vector<XrProbeHapticsFinger>> run_xr_probe_haptics(const XrProbeOptions& options,
                                                               const XrProbeReport& report) {
  HapticsCheck check(report);
  XrProbeOptions probe = options;
  // Every present finger gets its slot; the duration only bounds the run (the
  // waits, up to 10 devices, and a second to spare).
  probe.duration_s = std::max(options.duration_s, kFocusWaitS + kGateWaitS + 10 * (kPressS + kReleaseS) + 1.0);
  auto summary = detail::run_xr_probe_hooked(probe, report, check.hooks());
  if (check.failure()) return *check.failure();
  if (!summary) return summary.error();
  if (!check.finished()) {
    return make_error(Errc::unavailable, summary->interrupted ? "stopped before every finger was pressed"
                                                              : "the session ended before every finger was pressed");
  }
  return check.fingers();
}

}  // namespace proprio::engine
