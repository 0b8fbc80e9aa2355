#pragma once
// Hooks into the OpenXR probe's instance, session and frame loop (xr_probe.cpp),
// so that another engine tool (wrist_calibration.cpp) runs its OpenXR work
// inside them instead of a second copy of the headless/Vulkan session
// fallback, the event pump and the frame pacing. Private to proprio::engine:
// the hooks see raw OpenXR handles. Include after <openxr/openxr.h>.
#include <openxr/openxr.h>

#include <functional>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/engine/xr_probe.hpp"

namespace proprio::engine::detail {

// One of the probe's hand trackers after this frame's locate.
struct XrProbeFrameHand {
  XrProbeHand which = XrProbeHand::left;
  bool active = false;
  const XrHandJointLocationEXT* joints = nullptr;  // XR_HAND_JOINT_COUNT_EXT entries, in the probe's space
};

// What a frame hook gets, between xrBeginFrame and xrEndFrame.
struct XrProbeFrame {
  XrTime time = 0;   // the frame's predicted display time (or now, when the runtime gave 0)
  double t_s = 0.0;  // since this session's frame loop started
  XrSession session = XR_NULL_HANDLE;
  XrSpace space = XR_NULL_HANDLE;  // the probe's reference space (XrProbeOptions::space)
  std::vector<XrProbeFrameHand> hands;
  // The session's state from the newest event before this frame (FOCUSED:
  // the app has input focus; the OpenXR layer drives haptics only then).
  XrSessionState state = XR_SESSION_STATE_UNKNOWN;
};

struct XrProbeHooks {
  // false: XR_EXT_hand_tracking is neither required nor enabled, and the
  // probe creates no hand trackers (XrProbeOptions::hands is ignored).
  bool hand_tracking = true;
  // Once the offered instance extensions are known: append the ones to
  // enable (pointers must outlive the run). An error ends the run with it.
  std::function<Status(const std::vector<XrExtensionProperties>& offered, std::vector<const char*>& enable)> extensions;
  // After each xrCreateInstance and xrGetSystem (the Vulkan fallback makes a
  // second instance): load functions, create action sets, suggest bindings.
  std::function<Status(XrInstance instance, XrSystemId system)> instance_created;
  // After xrBeginSession and the probe's space: spaces, xrAttachSessionActionSets.
  std::function<Status(XrSession session, XrSpace space)> session_started;
  // Every frame; false ends the frame loop as a completed run.
  std::function<bool(const XrProbeFrame& frame)> frame;
  // Before the probe destroys its session and instance, for each session
  // (also one that failed half-way): destroy what the hooks created.
  std::function<void()> session_ending;
};

// run_xr_probe with hooks.
Result<XrProbeSummary> run_xr_probe_hooked(const XrProbeOptions& options, const XrProbeReport& report,
                                           const XrProbeHooks& hooks);

}  // namespace proprio::engine::detail
