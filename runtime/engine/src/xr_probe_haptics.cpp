// `proprio xr-probe --haptics` (xr_probe.hpp): checks a fingertip-haptics setup
// end to end through the system's loader, as any app sees it. It enables
// XR_PROPRIO_fingertip_haptics, lists each hand's devices, then presses each
// present finger in turn (0.5 N on the pad, in the fingertip frame, submitted
// every frame for 0.3 s) and reads what the layer commanded and what the
// device measured, and whether the force was gone 0.2 s after the last
// submission. It runs on the probe's own session and frame loop (hooks).
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
constexpr double kRampInS = 0.6;   // the gates ramp in over 0.4 s once the session is focused
constexpr double kPressS = 0.3;
constexpr double kReleaseS = 0.2;
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
                        "the layer has no fingertip devices: add a [haptics] table to its configuration "
                        "(docs/openxr-layer.md, 'proprio layer status')");
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
    for (XrHandEXT hand : {XR_HAND_LEFT_EXT, XR_HAND_RIGHT_EXT}) {
      XrFingertipHapticsPropertiesPROPRIO p{XR_TYPE_FINGERTIP_HAPTICS_PROPERTIES_PROPRIO};
      if (const XrResult r = properties_(haptics_, hand, &p); XR_FAILED(r)) {
        return make_error(Errc::io_error, fmt::format("xrGetFingertipHapticsPropertiesPROPRIO: {}", xr_result_name(r)));
      }
      for (std::size_t f = 0; f < XR_FINGERTIP_COUNT_PROPRIO; ++f) {
        const XrFingertipDevicePropertiesPROPRIO& d = p.fingers[f];
        if (!d.present) continue;
        XrProbeHapticsFinger out;
        out.hand = hand == XR_HAND_LEFT_EXT ? XrProbeHand::left : XrProbeHand::right;
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
    current_ = 0;
    return {};
  }

  // Ramp-in, then per finger: press, release; false when every finger is done.
  bool on_frame(const detail::XrProbeFrame& frame) {
    if (haptics_ == XR_NULL_HANDLE || failure_) return false;
    if (start_s_ < 0.0) {
      start_s_ = frame.t_s;
      if (report_) report_(XrProbeHapticsDevices{fingers_});  // after the probe has said which session runs
    }
    const double t = frame.t_s - start_s_ - kRampInS;
    if (t < 0.0) return true;
    const double slot = kPressS + kReleaseS;
    const auto finger = static_cast<std::size_t>(t / slot);
    if (finger >= fingers_.size()) {
      finished_ = true;
      return false;
    }
    XrProbeHapticsFinger& f = fingers_[finger];
    const XrHandEXT hand = f.hand == XrProbeHand::left ? XR_HAND_LEFT_EXT : XR_HAND_RIGHT_EXT;
    const double in_slot = t - static_cast<double>(finger) * slot;
    const bool pressing = in_slot < kPressS;
    XrFingertipForcesPROPRIO forces{XR_TYPE_FINGERTIP_FORCES_PROPRIO};
    forces.hand = hand;
    if (pressing) forces.forces[f.finger_index] = {0.0f, static_cast<float>(kPressN), 0.0f};
    // Release: nothing submitted, so the layer's fade to zero is what is checked.
    if (pressing || current_ != finger) {
      if (const XrResult r = apply_(haptics_, &forces); XR_FAILED(r)) {
        failure_ = make_error(Errc::io_error, fmt::format("xrApplyFingertipForcesPROPRIO: {}", xr_result_name(r)));
        return false;
      }
    }
    current_ = finger;
    XrFingertipHapticsStatePROPRIO s{XR_TYPE_FINGERTIP_HAPTICS_STATE_PROPRIO};
    if (const XrResult r = state_(haptics_, hand, &s); XR_FAILED(r)) {
      failure_ = make_error(Errc::io_error, fmt::format("xrGetFingertipHapticsStatePROPRIO: {}", xr_result_name(r)));
      return false;
    }
    const XrFingertipStatePROPRIO& st = s.fingers[f.finger_index];
    f.peak_commanded_n = std::max(f.peak_commanded_n, static_cast<double>(st.commandedForce.y));
    f.peak_measured_n = std::max(f.peak_measured_n, static_cast<double>(st.measuredForce.y));
    if (!pressing && !f.released_after_s && std::abs(st.commandedForce.y) < 0.01f) {
      f.released_after_s = in_slot - kPressS;
    }
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
  std::size_t current_ = 0;
  double start_s_ = -1.0;
  bool finished_ = false;
  std::optional<Error> failure_;
};

}  // namespace

bool XrProbeHapticsFinger::passed() const {
  return connected && peak_commanded_n > 0.8 * kPressN && peak_measured_n > 0.1 && released_after_s.has_value();
}

double xr_probe_haptics_press_n() { return kPressN; }

Result<std::vector<XrProbeHapticsFinger>> run_xr_probe_haptics(const XrProbeOptions& options,
                                                               const XrProbeReport& report) {
  HapticsCheck check(report);
  XrProbeOptions probe = options;
  // Every present finger gets its slot; the duration only bounds the run (up to 10 devices).
  probe.duration_s = std::max(options.duration_s, kRampInS + 10 * (kPressS + kReleaseS) + 2.0);
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
