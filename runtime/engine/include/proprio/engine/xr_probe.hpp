#pragma once
// The OpenXR probe behind `proprio xr-probe`: a minimal app that goes through
// the system's OpenXR loader (so enabled API layers, Proprio's included, apply
// as for any app), creates XR_EXT_hand_tracking trackers and reports once a
// second what they return.
//
// Sessions: headless (XR_MND_headless) when the runtime offers it, since that
// needs no GPU. Monado offers the extension but refuses frames in headless
// sessions (xrBeginFrame: XR_ERROR_CALL_ORDER_INVALID), so with
// XrProbeSession::automatic a headless session that cannot run its first
// frame is replaced by one with a Vulkan graphics binding
// (XR_KHR_vulkan_enable2, the engine's hooks on the renderer's context), as
// `hello_xr -g Vulkan2` would. Frames end with no layers, which the spec
// allows, so no swapchain is needed.
//
// Failed OpenXR calls along the way are logged (proprio::logger) as they
// happen; what the caller gets back is the conclusion.
#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"

namespace proprio::engine {

// Which session the probe opens. automatic: headless when offered, else (or
// when the runtime refuses headless frames) Vulkan.
enum class XrProbeSession { automatic, headless, vulkan };
// Which trackers it creates.
enum class XrProbeHands { left, right, both };
// The reference space the joints are located in.
enum class XrProbeSpace { view, local, stage };
std::string_view to_string(XrProbeSession s) noexcept;
std::string_view to_string(XrProbeHands h) noexcept;
std::string_view to_string(XrProbeSpace s) noexcept;

struct XrProbeOptions {
  double duration_s = 5.0;  // how long the frame loop runs (a fallback session starts its own)
  XrProbeSpace space = XrProbeSpace::view;
  XrProbeHands hands = XrProbeHands::both;
  XrProbeSession session = XrProbeSession::automatic;
  // An API layer the app enables itself (enabledApiLayerNames), as an app
  // could for an explicit install without XR_ENABLE_API_LAYERS; empty: none.
  // Its extensions count as offered.
  std::string api_layer;
  // Also enable XR_EXT_hand_tracking_data_source when offered and report each
  // hand's data source. Opt-in: Debian's 1.0.20 core_validation layer
  // predates the extension and rejects its structs in a next chain.
  bool data_source = false;
  // Polled; true ends the run early as a completed one (Ctrl-C). Not owned.
  const std::atomic<bool>* stop = nullptr;

  Status validate() const;
  std::string describe() const;
};

// The kind of session that ran.
enum class XrProbeSessionKind { headless, vulkan };

// Locate counts for one hand over a window (one second, or the whole run).
struct XrProbeHandCounts {
  std::uint64_t locates = 0;               // successful xrLocateHandJointsEXT calls
  std::uint64_t distinct = 0;              // ... whose joint poses differed from the previous active one
  std::uint64_t active = 0;                // ... with isActive
  std::uint64_t fully_tracked_joints = 0;  // joints of active locates with all four location flags
  std::uint64_t joints = 0;                // joints of active locates
};

enum class XrProbeHand { left, right };
std::string_view to_string(XrProbeHand h) noexcept;  // "left", "right"

// One hand at the end of a one-second window.
struct XrProbeHandSecond {
  XrProbeHand hand = XrProbeHand::left;
  bool active = false;  // the last locate's isActive
  // The last locate, when active, in the probe's reference space. The values
  // are the runtime's floats, widened.
  Vec3 wrist_m = Vec3::Zero();
  Vec3 index_tip_m = Vec3::Zero();
  Quat palm_orientation = Quat::Identity();
  // Where the palm faces: the palm joint's -Y (its +Y points out of the back of the hand).
  Vec3 palm_faces = Vec3::Zero();
  std::optional<double> index_tip_speed_m_s;  // when the runtime gave a valid linear velocity
  // XR_EXT_hand_tracking_data_source, when enabled and the state is active: true = a controller.
  std::optional<bool> data_source_controller;
  XrProbeHandCounts window;  // this window's counts
};

// What the probe reports while it runs, in order.
struct XrProbeDataSourceNotOffered {};  // options.data_source, but the extension is not offered
struct XrProbeRuntime {                 // once, after the first instance
  std::string name;
  std::uint32_t version_major = 0, version_minor = 0, version_patch = 0;
};
struct XrProbeSystem {  // once, after the first instance's system
  std::string name;
  std::uint32_t vendor_id = 0;
  bool supports_hand_tracking = false;
  bool data_source_enabled = false;
};
struct XrProbeHeadlessRefused {  // automatic: falling back to Vulkan
  std::string refused_call;      // e.g. "xrBeginFrame: XR_ERROR_CALL_ORDER_INVALID"
};
struct XrProbeSessionStarted {
  XrProbeSessionKind kind = XrProbeSessionKind::headless;
  std::string device;  // the Vulkan device's name; empty for headless
};
struct XrProbeZeroDisplayTime {};  // once per session: predictedDisplayTime was 0, locating at "now"
struct XrProbeSecond {             // a window ended (about once a second, and a tail over 0.2 s)
  double t_s = 0.0;                // since the frame loop started
  double window_s = 0.0;
  std::vector<XrProbeHandSecond> hands;
};
// XR_PROPRIO_hand_tracking_latency, when Proprio's layer serves the hand:
// histograms over the run (bins of bin_ms, the last one open-ended).
struct XrProbeLatency {
  std::uint64_t poses = 0;
  double bin_ms = 0.5;
  std::vector<std::uint64_t> sample_to_ready;  // newest sensor sample -> pose servable
  std::vector<std::uint64_t> age_at_locate;    // newest sensor sample -> xrLocateHandJointsEXT
  double max_sample_to_ready_ms = 0.0, max_age_at_locate_ms = 0.0;
  // The upper edge of the bin holding the q-quantile (0..1); NaN without counts.
  static double quantile_ms(const std::vector<std::uint64_t>& bins, double bin_ms, double q);
};

// The run's totals; reported before the session is torn down (a failed
// teardown still makes the run an Error).
struct XrProbeSummary {
  bool interrupted = false;  // options.stop ended it
  double run_s = 0.0;
  std::uint64_t frames = 0;
  XrProbeSessionKind kind = XrProbeSessionKind::headless;
  std::vector<std::pair<XrProbeHand, XrProbeHandCounts>> hands;
  // Per hand, when the layer offered XR_PROPRIO_hand_tracking_latency.
  std::vector<std::pair<XrProbeHand, XrProbeLatency>> latency;

  bool any_active() const;
};
// `xr-probe --haptics`: one fingertip device through XR_PROPRIO_fingertip_haptics.
struct XrProbeHapticsFinger {
  XrProbeHand hand = XrProbeHand::left;
  std::string finger;  // "thumb" .. "little"
  int finger_index = 0;
  std::string device;
  bool connected = false;
  std::uint32_t force_dofs = 0;
  double max_normal_n = 0.0, max_shear_n = 0.0;
  // The press (xr_probe_haptics_press_n() on the pad, +Y of the fingertip
  // frame, submitted every frame for 0.3 s): the largest commandedForce.y the
  // layer let through and measuredForce.y the device reported, and how long
  // after the last submission each was below 0.01 N (none: not within 0.2 s).
  double peak_commanded_n = 0.0, peak_measured_n = 0.0;
  std::optional<double> released_after_s;           // commandedForce.y
  std::optional<double> measured_released_after_s;  // measuredForce.y
  // Connected, commanded at least 80 % of the press, measured over 0.1 N,
  // both released within 0.2 s.
  bool passed() const;
};
double xr_probe_haptics_press_n();
struct XrProbeHapticsDevices {  // once the haptics object exists: every present finger, before the presses
  std::vector<XrProbeHapticsFinger> fingers;
  // Fingers without a device (XrFingertipDevicePropertiesPROPRIO::present false), per hand.
  std::vector<std::pair<XrProbeHand, std::string>> absent;
};
// --haptics: waiting for the session to be FOCUSED and every device's gate to
// ramp in, before the presses (reported once, when the wait is over).
struct XrProbeHapticsReady {
  double waited_for_focus_s = 0.0;  // from the first frame
  double waited_for_gates_s = 0.0;  // from focus
  bool all_gates_active = true;     // false: the wait timed out; the presses go ahead
};

using XrProbeEvent = std::variant<XrProbeDataSourceNotOffered, XrProbeRuntime, XrProbeSystem, XrProbeSessionStarted,
                                  XrProbeHeadlessRefused, XrProbeZeroDisplayTime, XrProbeSecond, XrProbeSummary,
                                  XrProbeHapticsDevices, XrProbeHapticsReady>;
using XrProbeReport = std::function<void(const XrProbeEvent&)>;

// Error codes of run_xr_probe: Errc::unsupported means only "no hand tracking"
// (XR_EXT_hand_tracking not offered, or supportsHandTracking false); every
// other failure has another code. An empty message means nothing is left to
// say: the run was stopped before its session became READY.
inline constexpr Errc kXrProbeNoHandTracking = Errc::unsupported;

// Runs the probe to its end. The summary is also reported (XrProbeSummary)
// before the session is torn down; a hand was seen when any_active().
Result<XrProbeSummary> run_xr_probe(const XrProbeOptions& options, const XrProbeReport& report);

// Checks the fingertip devices behind XR_PROPRIO_fingertip_haptics (no hand
// trackers): lists them, presses each in turn and reads the layer's state.
// Errc::unsupported: the extension is not offered or no devices are configured.
Result<std::vector<XrProbeHapticsFinger>> run_xr_probe_haptics(const XrProbeOptions& options,
                                                               const XrProbeReport& report);

}  // namespace proprio::engine
