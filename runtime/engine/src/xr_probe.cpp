// The OpenXR probe (xr_probe.hpp). One Probe object holds one instance and
// session at a time; the headless-to-Vulkan fallback tears the first down and
// starts again.
#define XR_USE_GRAPHICS_API_VULKAN
#define XR_USE_TIMESPEC
#include <time.h>
#include <vulkan/vulkan.h>
// clang-format off
#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>
// clang-format on

#include "proprio/engine/xr_probe.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <thread>

#include "proprio/core/log.hpp"
#include "proprio/engine/xr_vulkan.hpp"
#include "proprio/core/xr_ext.hpp"
#include "proprio/openxr/XR_PROPRIO_hand_tracking_latency.h"
#include "proprio/render/context.hpp"
#include "xr_probe_hooks.hpp"
#include "xr_util.hpp"

namespace proprio::engine {

std::string_view to_string(XrProbeSession s) noexcept {
  switch (s) {
    case XrProbeSession::automatic: return "auto";
    case XrProbeSession::headless: return "headless";
    case XrProbeSession::vulkan: return "vulkan";
  }
  return "?";
}
std::string_view to_string(XrProbeHands h) noexcept {
  switch (h) {
    case XrProbeHands::left: return "left";
    case XrProbeHands::right: return "right";
    case XrProbeHands::both: return "both";
  }
  return "?";
}
std::string_view to_string(XrProbeSpace s) noexcept {
  switch (s) {
    case XrProbeSpace::view: return "view";
    case XrProbeSpace::local: return "local";
    case XrProbeSpace::stage: return "stage";
  }
  return "?";
}
double XrProbeLatency::quantile_ms(const std::vector<std::uint64_t>& bins, double bin_ms, double q) {
  std::uint64_t total = 0;
  for (auto c : bins) total += c;
  if (total == 0) return std::numeric_limits<double>::quiet_NaN();
  const double target = q * static_cast<double>(total);
  std::uint64_t seen = 0;
  for (std::size_t i = 0; i < bins.size(); ++i) {
    seen += bins[i];
    if (static_cast<double>(seen) >= target) return static_cast<double>(i + 1) * bin_ms;
  }
  return static_cast<double>(bins.size()) * bin_ms;
}

std::string_view to_string(XrProbeHand h) noexcept { return h == XrProbeHand::left ? "left" : "right"; }

Status XrProbeOptions::validate() const {
  if (!(duration_s >= 0.0 && duration_s <= 24.0 * 3600.0)) {
    return make_error(Errc::invalid_argument,
                      fmt::format("xr-probe duration {} s is out of range (0 to 86400 s)", duration_s));
  }
  if (api_layer.size() >= XR_MAX_API_LAYER_NAME_SIZE) {
    return make_error(Errc::invalid_argument, fmt::format("API layer name '{}' is longer than OpenXR allows ({} bytes)",
                                                          api_layer, XR_MAX_API_LAYER_NAME_SIZE - 1));
  }
  return {};
}

std::string XrProbeOptions::describe() const {
  return fmt::format("{} s, {} session, {} hand(s) in {} space{}{}", duration_s, to_string(session), to_string(hands),
                     to_string(space), api_layer.empty() ? "" : ", enabling " + api_layer,
                     data_source ? ", with XR_EXT_hand_tracking_data_source" : "");
}

bool XrProbeSummary::any_active() const {
  return std::any_of(hands.begin(), hands.end(), [](const auto& h) { return h.second.active > 0; });
}

namespace {

using detail::xr_result_name;
using detail::xr_session_state_name;

constexpr XrSpaceLocationFlags kAllLocationFlags =
    XR_SPACE_LOCATION_POSITION_VALID_BIT | XR_SPACE_LOCATION_ORIENTATION_VALID_BIT |
    XR_SPACE_LOCATION_POSITION_TRACKED_BIT | XR_SPACE_LOCATION_ORIENTATION_TRACKED_BIT;

struct HandProbe {
  XrProbeHand which = XrProbeHand::left;
  XrHandTrackerEXT tracker = XR_NULL_HANDLE;
  std::array<XrHandJointLocationEXT, XR_HAND_JOINT_COUNT_EXT> joints{};
  std::array<XrHandJointVelocityEXT, XR_HAND_JOINT_COUNT_EXT> velocities{};
  std::array<XrPosef, XR_HAND_JOINT_COUNT_EXT> previous{};
  bool have_previous = false;
  bool active = false;
  XrHandTrackingDataSourceStateEXT source_state{};
  XrProbeHandCounts window, total;

  const char* name() const { return which == XrProbeHand::left ? "left" : "right"; }
};

// Adds the current window to the run's totals and starts a new one.
void fold_window(HandProbe& h) {
  h.total.locates += h.window.locates;
  h.total.distinct += h.window.distinct;
  h.total.active += h.window.active;
  h.total.fully_tracked_joints += h.window.fully_tracked_joints;
  h.total.joints += h.window.joints;
  h.window = {};
}

// How a session's frame loop ended.
enum class LoopEnd {
  completed,         // the duration ran out, stop was set, or the runtime ended the session
  failed,            // a call failed (reported)
  headless_refused,  // a headless session could not run its first frame
};

// A headless session could not be created or run (the caller may fall back).
struct HeadlessRefused {};
using Step = std::variant<std::monostate, HeadlessRefused, Error>;
bool failed(const Step& s) { return !std::holds_alternative<std::monostate>(s); }

class Probe {
 public:
  Probe(const XrProbeOptions& options, const XrProbeReport& report, const detail::XrProbeHooks& hooks)
      : options_(options), report_(report), hooks_(hooks) {}
  ~Probe() { teardown(); }
  Result<XrProbeSummary> run();

 private:
  bool stopped() const { return options_.stop && options_.stop->load(); }
  void emit(XrProbeEvent event) {
    if (report_) report_(event);
  }
  std::string result_text(XrResult r) {
    char name[XR_MAX_RESULT_STRING_SIZE] = {};
    if (instance_ == XR_NULL_HANDLE || XR_FAILED(xrResultToString(instance_, r, name))) {
      std::snprintf(name, sizeof name, "%s", xr_result_name(r));
    }
    return name;
  }
  // A failed call, by the runtime's name for the result (the engine's error code for it).
  Error call_error(XrResult r, const char* what) {
    Error e = xr_call_error(XR_NULL_HANDLE, what, r);
    e.message = fmt::format("{} failed: {} ({})", what, result_text(r), static_cast<int>(r));
    return e;
  }
  // Logs a failed call; true when it succeeded.
  bool ok(XrResult r, const char* what) {
    if (XR_SUCCEEDED(r)) return true;
    logger().error("{}", call_error(r, what).message);
    return false;
  }
  template <typename Fn>
  Step load(const char* fn_name, Fn& fn) {
    const XrResult r = xrGetInstanceProcAddr(instance_, fn_name, reinterpret_cast<PFN_xrVoidFunction*>(&fn));
    if (XR_FAILED(r)) return call_error(r, fn_name);
    return {};
  }

  Step check_extensions();
  Step create_instance(XrProbeSessionKind kind);
  Step create_session(XrProbeSessionKind kind);
  Step create_vulkan_binding();
  LoopEnd run_frames();
  bool pump_events();  // false when the session ended or the instance is lost (then pump_error_ may say why)
  void log_pump_error();
  Step wait_for_ready(double timeout_s);
  XrTime now();
  bool locate(HandProbe& h, XrTime t);
  // Reports the window (unless !report) and adds it to the run's totals.
  void report_second(double t_s, double window_s, bool report = true);
  Result<XrProbeSummary> summarise(LoopEnd end);
  bool teardown();

  const XrProbeOptions& options_;
  const XrProbeReport& report_;
  const detail::XrProbeHooks& hooks_;
  std::vector<const char*> hook_extensions_;  // what hooks_.extensions asked to enable
  std::vector<XrExtensionProperties> offered_;
  bool has_headless_ext_ = false, has_vulkan_ext_ = false;
  bool reported_system_ = false;
  XrProbeSessionKind kind_ = XrProbeSessionKind::headless;
  XrInstance instance_ = XR_NULL_HANDLE;
  XrSystemId system_ = XR_NULL_SYSTEM_ID;
  XrSession session_ = XR_NULL_HANDLE;
  XrSpace space_ = XR_NULL_HANDLE;
  XrSessionState state_ = XR_SESSION_STATE_UNKNOWN;
  bool session_running_ = false, exiting_ = false;
  bool failed_ = false;  // a call failed or the runtime was lost: the run is an Error
  std::optional<Error> pump_error_;
  bool has_data_source_ext_ = false;
  XrViewConfigurationType view_config_ = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  XrEnvironmentBlendMode blend_mode_ = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
  std::vector<HandProbe> hands_;
  bool zero_display_time_reported_ = false;
  std::uint64_t frames_ = 0;
  double run_s_ = 0.0;
  // What a headless session's first failed frame call was, for the fallback message.
  std::string refused_call_;
  // The Vulkan session's device side: destroyed after the session, before the instance.
  std::unique_ptr<render::VulkanContext> vulkan_;
  XrGraphicsBindingVulkan2KHR vulkan_binding_{XR_TYPE_GRAPHICS_BINDING_VULKAN2_KHR};

  PFN_xrCreateHandTrackerEXT create_hand_tracker_ = nullptr;
  PFN_xrDestroyHandTrackerEXT destroy_hand_tracker_ = nullptr;
  PFN_xrLocateHandJointsEXT locate_hand_joints_ = nullptr;
  PFN_xrConvertTimespecTimeToTimeKHR convert_timespec_ = nullptr;
  bool has_latency_ext_ = false;
  PFN_xrGetHandTrackingLatencyPROPRIO get_latency_ = nullptr;
};

// Lists the instance extensions (the runtime's and the app-enabled layer's)
// and checks for the ones every session needs.
Step Probe::check_extensions() {
  uint32_t count = 0;
  if (const XrResult r = xrEnumerateInstanceExtensionProperties(nullptr, 0, &count, nullptr);
      !ok(r, "xrEnumerateInstanceExtensionProperties")) {
    return make_error(Errc::unavailable,
                      "the OpenXR loader found no usable runtime. Check 'proprio layer status' (Active runtime) or set "
                      "XR_RUNTIME_JSON; XR_LOADER_DEBUG=all shows what the loader tried");
  }
  offered_.assign(count, XrExtensionProperties{XR_TYPE_EXTENSION_PROPERTIES});
  if (const XrResult r = xrEnumerateInstanceExtensionProperties(nullptr, count, &count, offered_.data());
      XR_FAILED(r)) {
    return call_error(r, "xrEnumerateInstanceExtensionProperties");
  }
  offered_.resize(count);
  if (!options_.api_layer.empty()) {
    const char* layer = options_.api_layer.c_str();
    uint32_t n = 0;
    const std::string what = "xrEnumerateInstanceExtensionProperties(" + options_.api_layer + ")";
    if (!ok(xrEnumerateInstanceExtensionProperties(layer, 0, &n, nullptr), what.c_str())) {
      return make_error(Errc::not_found, fmt::format("--enable-layer: the loader does not find {}; run 'proprio layer "
                                                     "install' first",
                                                     options_.api_layer));
    }
    std::vector<XrExtensionProperties> more(n, XrExtensionProperties{XR_TYPE_EXTENSION_PROPERTIES});
    if (const XrResult r = xrEnumerateInstanceExtensionProperties(layer, n, &n, more.data()); XR_FAILED(r)) {
      return call_error(r, "xrEnumerateInstanceExtensionProperties");
    }
    offered_.insert(offered_.end(), more.begin(), more.begin() + n);
  }
  std::string list;
  for (const auto& e : offered_) list += (list.empty() ? "" : ", ") + std::string(e.extensionName);
  logger().debug("instance extensions offered: {}", list);
  // Before the probe's own checks, so a hook can say what its caller lacks first.
  hook_extensions_.clear();
  if (hooks_.extensions) {
    if (Status s = hooks_.extensions(offered_, hook_extensions_); !s) return s.error();
  }

  if (hooks_.hand_tracking && !detail::has_extension(offered_, XR_EXT_HAND_TRACKING_EXTENSION_NAME)) {
    return make_error(kXrProbeNoHandTracking,
                      "XR_EXT_hand_tracking is not offered by the active runtime or any enabled API layer. Enable "
                      "Proprio's layer: 'proprio layer status' says what the loader sees and what to do");
  }
  if (!detail::has_extension(offered_, XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME)) {
    return make_error(Errc::unavailable,
                      "the runtime does not offer XR_KHR_convert_timespec_time, which the probe needs to read the "
                      "monotonic clock in XrTime");
  }
  has_headless_ext_ = detail::has_extension(offered_, XR_MND_HEADLESS_EXTENSION_NAME);
  has_vulkan_ext_ = detail::has_extension(offered_, XR_KHR_VULKAN_ENABLE2_EXTENSION_NAME);
  has_data_source_ext_ =
      options_.data_source && detail::has_extension(offered_, XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME);
  has_latency_ext_ =
      hooks_.hand_tracking && detail::has_extension(offered_, XR_PROPRIO_HAND_TRACKING_LATENCY_EXTENSION_NAME);
  if (options_.data_source && !has_data_source_ext_) emit(XrProbeDataSourceNotOffered{});
  return {};
}

// The instance for one kind of session: headless enables XR_MND_headless,
// Vulkan enables XR_KHR_vulkan_enable2 and not XR_MND_headless (some Monado
// versions create no compositor for an instance that enabled it).
Step Probe::create_instance(XrProbeSessionKind kind) {
  std::vector<const char*> enabled = {
      XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME,
      kind == XrProbeSessionKind::headless ? XR_MND_HEADLESS_EXTENSION_NAME : XR_KHR_VULKAN_ENABLE2_EXTENSION_NAME};
  if (hooks_.hand_tracking) enabled.push_back(XR_EXT_HAND_TRACKING_EXTENSION_NAME);
  enabled.insert(enabled.end(), hook_extensions_.begin(), hook_extensions_.end());
  if (has_data_source_ext_) enabled.push_back(XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME);
  if (has_latency_ext_) enabled.push_back(XR_PROPRIO_HAND_TRACKING_LATENCY_EXTENSION_NAME);
  const char* layers[] = {options_.api_layer.c_str()};

  XrInstanceCreateInfo ci{XR_TYPE_INSTANCE_CREATE_INFO};
  std::snprintf(ci.applicationInfo.applicationName, XR_MAX_APPLICATION_NAME_SIZE, "proprio xr-probe");
  ci.applicationInfo.applicationVersion = 1;
  std::snprintf(ci.applicationInfo.engineName, XR_MAX_ENGINE_NAME_SIZE, "proprio");
  ci.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
  ci.enabledExtensionCount = static_cast<uint32_t>(enabled.size());
  ci.enabledExtensionNames = enabled.data();
  if (!options_.api_layer.empty()) {
    ci.enabledApiLayerCount = 1;
    ci.enabledApiLayerNames = layers;
  }
  if (const XrResult r = xrCreateInstance(&ci, &instance_); XR_FAILED(r)) return call_error(r, "xrCreateInstance");

  XrInstanceProperties ip{XR_TYPE_INSTANCE_PROPERTIES};
  if (const XrResult r = xrGetInstanceProperties(instance_, &ip); XR_FAILED(r)) {
    return call_error(r, "xrGetInstanceProperties");
  }
  if (!reported_system_) {
    emit(XrProbeRuntime{ip.runtimeName, XR_VERSION_MAJOR(ip.runtimeVersion), XR_VERSION_MINOR(ip.runtimeVersion),
                        XR_VERSION_PATCH(ip.runtimeVersion)});
  }
  Step loaded = load("xrConvertTimespecTimeToTimeKHR", convert_timespec_);
  if (hooks_.hand_tracking) {
    if (!failed(loaded)) loaded = load("xrCreateHandTrackerEXT", create_hand_tracker_);
    if (!failed(loaded)) loaded = load("xrDestroyHandTrackerEXT", destroy_hand_tracker_);
    if (!failed(loaded)) loaded = load("xrLocateHandJointsEXT", locate_hand_joints_);
  }
  if (failed(loaded)) return loaded;
  get_latency_ = nullptr;
  if (has_latency_ext_ && failed(load("xrGetHandTrackingLatencyPROPRIO", get_latency_))) {
    logger().warn("XR_PROPRIO_hand_tracking_latency is offered but its function is not: no latency histogram");
    get_latency_ = nullptr;
  }

  XrSystemGetInfo gi{XR_TYPE_SYSTEM_GET_INFO};
  gi.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  if (!ok(xrGetSystem(instance_, &gi, &system_), "xrGetSystem(HEAD_MOUNTED_DISPLAY)")) {
    return make_error(Errc::unavailable,
                      "the runtime has no head-mounted system right now: is the headset connected and the runtime's "
                      "service (e.g. monado-service) running?");
  }
  XrSystemHandTrackingPropertiesEXT ht{XR_TYPE_SYSTEM_HAND_TRACKING_PROPERTIES_EXT};
  XrSystemProperties sp{XR_TYPE_SYSTEM_PROPERTIES};
  sp.next = &ht;
  if (const XrResult r = xrGetSystemProperties(instance_, system_, &sp); XR_FAILED(r)) {
    return call_error(r, "xrGetSystemProperties");
  }
  if (!reported_system_) {
    emit(XrProbeSystem{sp.systemName, sp.vendorId, ht.supportsHandTracking == XR_TRUE, has_data_source_ext_});
    reported_system_ = true;
  }
  if (hooks_.hand_tracking && !ht.supportsHandTracking) {
    return make_error(kXrProbeNoHandTracking,
                      "the system reports supportsHandTracking = false: no hand tracker can be created. If Proprio's "
                      "layer is enabled, check its configuration and log ('proprio layer status')");
  }
  if (hooks_.instance_created) {
    if (Status s = hooks_.instance_created(instance_, system_); !s) return s.error();
  }
  return {};
}

// XR_KHR_vulkan_enable2: the runtime creates the Vulkan instance and device
// (adding what it needs), through the engine's hooks on the renderer's context.
Step Probe::create_vulkan_binding() {
  render::ContextOptions base;
  base.app_name = "proprio xr-probe";
  auto co = xr_vulkan_context_options(instance_, system_, std::move(base));
  if (!co) {
    return make_error(Errc::unavailable,
                      fmt::format("the Vulkan graphics binding could not be set up: {}", co.error().message));
  }
  auto ctx = render::VulkanContext::create(*co);
  if (!ctx) {
    return make_error(Errc::unavailable,
                      fmt::format("the Vulkan graphics binding could not be set up: {}", ctx.error().message));
  }
  vulkan_ = std::move(*ctx);
  vulkan_binding_ = XrGraphicsBindingVulkan2KHR{XR_TYPE_GRAPHICS_BINDING_VULKAN2_KHR};
  vulkan_binding_.instance = vulkan_->instance();
  vulkan_binding_.physicalDevice = vulkan_->physical_device();
  vulkan_binding_.device = vulkan_->device();
  vulkan_binding_.queueFamilyIndex = vulkan_->queue_family();
  vulkan_binding_.queueIndex = 0;
  return {};
}

Step Probe::create_session(XrProbeSessionKind kind) {
  // PRIMARY_STEREO without asking for the runtime's list: every HMD runtime
  // has it, a headless session ignores it, and Debian's 1.0.20 loader crashes
  // on a function a runtime lacks.
  uint32_t n = 0;
  if (ok(xrEnumerateEnvironmentBlendModes(instance_, system_, view_config_, 0, &n, nullptr),
         "xrEnumerateEnvironmentBlendModes") &&
      n > 0) {
    std::vector<XrEnvironmentBlendMode> modes(n);
    if (ok(xrEnumerateEnvironmentBlendModes(instance_, system_, view_config_, n, &n, modes.data()),
           "xrEnumerateEnvironmentBlendModes")) {
      blend_mode_ = modes.front();
    }
  }

  XrSessionCreateInfo sci{XR_TYPE_SESSION_CREATE_INFO};
  sci.systemId = system_;
  std::string device;
  if (kind == XrProbeSessionKind::vulkan) {
    if (Step s = create_vulkan_binding(); failed(s)) return s;
    sci.next = &vulkan_binding_;
    device = vulkan_->device_name();
  }
  // Headless (XR_MND_headless): no graphics binding in the chain.
  const XrResult created = xrCreateSession(instance_, &sci, &session_);
  if (kind == XrProbeSessionKind::headless && XR_FAILED(created) && options_.session == XrProbeSession::automatic &&
      has_vulkan_ext_) {
    refused_call_ = "xrCreateSession: " + result_text(created);
    return HeadlessRefused{};
  }
  if (XR_FAILED(created)) {
    return call_error(created,
                      kind == XrProbeSessionKind::headless ? "xrCreateSession (headless)" : "xrCreateSession (Vulkan)");
  }

  if (Step s = wait_for_ready(10.0); failed(s)) return s;
  XrSessionBeginInfo bi{XR_TYPE_SESSION_BEGIN_INFO};
  bi.primaryViewConfigurationType = view_config_;
  if (const XrResult r = xrBeginSession(session_, &bi); XR_FAILED(r)) return call_error(r, "xrBeginSession");
  session_running_ = true;

  const XrReferenceSpaceType space_type = options_.space == XrProbeSpace::local   ? XR_REFERENCE_SPACE_TYPE_LOCAL
                                          : options_.space == XrProbeSpace::stage ? XR_REFERENCE_SPACE_TYPE_STAGE
                                                                                  : XR_REFERENCE_SPACE_TYPE_VIEW;
  n = 0;
  if (const XrResult r = xrEnumerateReferenceSpaces(session_, 0, &n, nullptr); XR_FAILED(r)) {
    return call_error(r, "xrEnumerateReferenceSpaces");
  }
  std::vector<XrReferenceSpaceType> spaces(n);
  if (const XrResult r = xrEnumerateReferenceSpaces(session_, n, &n, spaces.data()); XR_FAILED(r)) {
    return call_error(r, "xrEnumerateReferenceSpaces");
  }
  if (std::find(spaces.begin(), spaces.end(), space_type) == spaces.end()) {
    return make_error(
        Errc::unavailable,
        fmt::format("the runtime does not offer the {} reference space; try --space view or --space local",
                    to_string(options_.space)));
  }
  XrReferenceSpaceCreateInfo rci{XR_TYPE_REFERENCE_SPACE_CREATE_INFO};
  rci.referenceSpaceType = space_type;
  rci.poseInReferenceSpace.orientation.w = 1.0f;
  if (const XrResult r = xrCreateReferenceSpace(session_, &rci, &space_); XR_FAILED(r)) {
    return call_error(r, "xrCreateReferenceSpace");
  }

  auto add_hand = [&](XrProbeHand which) {
    hands_.emplace_back();
    hands_.back().which = which;
  };
  if (hooks_.hand_tracking && options_.hands != XrProbeHands::right) add_hand(XrProbeHand::left);
  if (hooks_.hand_tracking && options_.hands != XrProbeHands::left) add_hand(XrProbeHand::right);
  for (auto& h : hands_) {
    XrHandTrackingDataSourceEXT sources[] = {XR_HAND_TRACKING_DATA_SOURCE_UNOBSTRUCTED_EXT,
                                             XR_HAND_TRACKING_DATA_SOURCE_CONTROLLER_EXT};
    XrHandTrackingDataSourceInfoEXT dsi{XR_TYPE_HAND_TRACKING_DATA_SOURCE_INFO_EXT};
    dsi.requestedDataSourceCount = 2;
    dsi.requestedDataSources = sources;
    XrHandTrackerCreateInfoEXT hci{XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT};
    hci.next = has_data_source_ext_ ? &dsi : nullptr;
    hci.hand = h.which == XrProbeHand::left ? XR_HAND_LEFT_EXT : XR_HAND_RIGHT_EXT;
    hci.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
    if (const XrResult r = create_hand_tracker_(session_, &hci, &h.tracker); XR_FAILED(r)) {
      return call_error(r, fmt::format("xrCreateHandTrackerEXT({})", h.name()).c_str());
    }
  }
  if (hooks_.session_started) {
    if (Status s = hooks_.session_started(session_, space_); !s) return s.error();
  }
  emit(XrProbeSessionStarted{kind, device});
  return {};
}

bool Probe::pump_events() {
  while (true) {
    XrEventDataBuffer ev{XR_TYPE_EVENT_DATA_BUFFER};
    const XrResult r = xrPollEvent(instance_, &ev);
    if (r == XR_EVENT_UNAVAILABLE) return true;
    if (XR_FAILED(r)) {
      pump_error_ = call_error(r, "xrPollEvent");
      failed_ = true;
      return false;
    }
    switch (ev.type) {
      case XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED: {
        const auto& sc = reinterpret_cast<const XrEventDataSessionStateChanged&>(ev);
        state_ = sc.state;
        logger().debug("session state: {}", xr_session_state_name(state_));
        if (state_ == XR_SESSION_STATE_STOPPING && session_running_) {
          ok(xrEndSession(session_), "xrEndSession");
          session_running_ = false;
        }
        if (state_ == XR_SESSION_STATE_EXITING || state_ == XR_SESSION_STATE_LOSS_PENDING) {
          exiting_ = true;
          return false;
        }
        break;
      }
      case XR_TYPE_EVENT_DATA_INSTANCE_LOSS_PENDING:
        pump_error_ = make_error(Errc::unavailable, "the runtime is going away (instance loss pending)");
        exiting_ = true;
        failed_ = true;
        return false;
      case XR_TYPE_EVENT_DATA_EVENTS_LOST: logger().warn("the runtime dropped events"); break;
      default: break;
    }
  }
}

// Mid-run, a failure found while pumping events is reported where it happened.
void Probe::log_pump_error() {
  if (pump_error_) logger().error("{}", pump_error_->message);
  pump_error_.reset();
}

Step Probe::wait_for_ready(double timeout_s) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  bool ready = true;
  while (state_ != XR_SESSION_STATE_READY) {
    if (!pump_events() || stopped()) {
      ready = false;
      break;
    }
    if (state_ == XR_SESSION_STATE_READY) break;
    if (std::chrono::steady_clock::now() > deadline) {
      ready = false;
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  if (ready) return {};
  if (pump_error_) {
    Error e = *pump_error_;
    pump_error_.reset();
    return e;
  }
  // Stopped before the session started: nothing failed, nothing more to say.
  if (stopped()) return make_error(Errc::unavailable, "");
  return make_error(Errc::unavailable,
                    fmt::format("the session never became READY (last state {})", xr_session_state_name(state_)));
}

// The current time as XrTime; 0 when the conversion failed (reported).
XrTime Probe::now() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  XrTime t = 0;
  if (!ok(convert_timespec_(instance_, &ts, &t), "xrConvertTimespecTimeToTimeKHR")) return 0;
  return t;
}

// False when the call failed (reported).
bool Probe::locate(HandProbe& h, XrTime t) {
  XrHandJointVelocitiesEXT vel{XR_TYPE_HAND_JOINT_VELOCITIES_EXT};
  vel.jointCount = XR_HAND_JOINT_COUNT_EXT;
  vel.jointVelocities = h.velocities.data();
  h.source_state = XrHandTrackingDataSourceStateEXT{XR_TYPE_HAND_TRACKING_DATA_SOURCE_STATE_EXT};
  if (has_data_source_ext_) vel.next = &h.source_state;
  XrHandJointLocationsEXT loc{XR_TYPE_HAND_JOINT_LOCATIONS_EXT};
  loc.next = &vel;
  loc.jointCount = XR_HAND_JOINT_COUNT_EXT;
  loc.jointLocations = h.joints.data();
  XrHandJointsLocateInfoEXT li{XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT};
  li.baseSpace = space_;
  li.time = t;
  if (!ok(locate_hand_joints_(h.tracker, &li, &loc), fmt::format("xrLocateHandJointsEXT({})", h.name()).c_str())) {
    h.active = false;
    return false;
  }
  ++h.window.locates;
  h.active = loc.isActive;
  if (!loc.isActive) {
    h.have_previous = false;
    return true;
  }
  ++h.window.active;
  bool changed = !h.have_previous;
  for (std::size_t i = 0; i < h.joints.size(); ++i) {
    const auto& j = h.joints[i];
    if ((j.locationFlags & kAllLocationFlags) == kAllLocationFlags) ++h.window.fully_tracked_joints;
    ++h.window.joints;
    if (!changed && std::memcmp(&j.pose, &h.previous[i], sizeof(XrPosef)) != 0) changed = true;
    h.previous[i] = j.pose;
  }
  h.have_previous = true;
  if (changed) ++h.window.distinct;
  return true;
}

void Probe::report_second(double t_s, double window_s, bool report) {
  XrProbeSecond second{t_s, window_s, {}};
  for (auto& h : hands_) {
    if (!report) {
      fold_window(h);
      continue;
    }
    XrProbeHandSecond s;
    s.hand = h.which;
    s.active = h.active;
    s.window = h.window;
    if (h.active) {
      const auto& wrist = h.joints[XR_HAND_JOINT_WRIST_EXT].pose.position;
      const auto& tip = h.joints[XR_HAND_JOINT_INDEX_TIP_EXT].pose.position;
      const auto& q = h.joints[XR_HAND_JOINT_PALM_EXT].pose.orientation;
      s.wrist_m = Vec3(wrist.x, wrist.y, wrist.z);
      s.index_tip_m = Vec3(tip.x, tip.y, tip.z);
      s.palm_orientation = Quat(q.w, q.x, q.y, q.z);
      // The palm joint's +Y points out of the back of the hand: the palm faces -Y.
      // (Products in float, as the runtime's values are.)
      s.palm_faces =
          Vec3(-2.0 * (q.x * q.y - q.w * q.z), -(1.0 - 2.0 * (q.x * q.x + q.z * q.z)), -2.0 * (q.y * q.z + q.w * q.x));
      const auto& v = h.velocities[XR_HAND_JOINT_INDEX_TIP_EXT];
      if (v.velocityFlags & XR_SPACE_VELOCITY_LINEAR_VALID_BIT) {
        s.index_tip_speed_m_s =
            std::sqrt(v.linearVelocity.x * v.linearVelocity.x + v.linearVelocity.y * v.linearVelocity.y +
                      v.linearVelocity.z * v.linearVelocity.z);
      }
      if (has_data_source_ext_ && h.source_state.isActive) {
        s.data_source_controller = h.source_state.dataSource == XR_HAND_TRACKING_DATA_SOURCE_CONTROLLER_EXT;
      }
    }
    second.hands.push_back(s);
    fold_window(h);
  }
  if (report) emit(std::move(second));
}

Result<XrProbeSummary> Probe::run() {
  if (Step s = check_extensions(); failed(s)) return std::get<Error>(s);
  if (options_.session == XrProbeSession::headless && !has_headless_ext_) {
    return make_error(Errc::unavailable, "--session headless: the runtime does not offer XR_MND_headless");
  }
  if (options_.session == XrProbeSession::vulkan && !has_vulkan_ext_) {
    return make_error(Errc::unavailable, "--session vulkan: the runtime does not offer XR_KHR_vulkan_enable2");
  }
  if (options_.session == XrProbeSession::automatic && !has_headless_ext_ && !has_vulkan_ext_) {
    return make_error(Errc::unavailable,
                      "the runtime offers neither XR_MND_headless nor XR_KHR_vulkan_enable2, so xr-probe cannot open a "
                      "session; test the layer with an app that uses the runtime's graphics API (e.g. hello_xr)");
  }
  kind_ = options_.session == XrProbeSession::vulkan                          ? XrProbeSessionKind::vulkan
          : options_.session == XrProbeSession::headless || has_headless_ext_ ? XrProbeSessionKind::headless
                                                                              : XrProbeSessionKind::vulkan;
  Step step = create_instance(kind_);
  if (!failed(step)) step = create_session(kind_);
  LoopEnd end = LoopEnd::failed;
  if (!failed(step)) end = run_frames();
  if (std::holds_alternative<HeadlessRefused>(step) || end == LoopEnd::headless_refused) {
    if (options_.session == XrProbeSession::automatic && has_vulkan_ext_) {
      emit(XrProbeHeadlessRefused{refused_call_});
      // Failures tearing down the refused session are reported, but the Vulkan
      // session is what counts: its own failures set failed_ again.
      teardown();
      failed_ = false;
      kind_ = XrProbeSessionKind::vulkan;
      step = create_instance(kind_);
      if (!failed(step)) step = create_session(kind_);
      if (!failed(step)) end = run_frames();
    } else {
      return make_error(
          Errc::unavailable,
          fmt::format("the runtime refuses frames in headless sessions ({}), as Monado does. {}", refused_call_,
                      options_.session == XrProbeSession::headless
                          ? "Run without --session headless (or with --session vulkan)"
                          : "It offers no XR_KHR_vulkan_enable2 to fall back to"));
    }
  }
  if (const Error* e = std::get_if<Error>(&step)) return *e;
  return summarise(end);
}

// Runs the frame loop for the duration, locating the hands every frame.
LoopEnd Probe::run_frames() {
  using clock = std::chrono::steady_clock;
  const auto start = clock::now();
  auto window_start = start, last_wait_return = start;
  frames_ = 0;
  // A headless session that cannot run its first frame may be refused by
  // design (Monado): the caller decides, so that failure is not reported here.
  auto first_frame_refused = [&](XrResult r, const char* call) {
    if (kind_ != XrProbeSessionKind::headless || frames_ > 0 || XR_SUCCEEDED(r)) return false;
    refused_call_ = std::string(call) + ": " + result_text(r);
    return true;
  };
  LoopEnd end = LoopEnd::completed;
  while (!stopped() && !exiting_) {
    if (!pump_events()) {
      log_pump_error();
      break;
    }
    const double elapsed = std::chrono::duration<double>(clock::now() - start).count();
    if (elapsed >= options_.duration_s) break;
    if (!session_running_) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      continue;
    }
    XrFrameWaitInfo fwi{XR_TYPE_FRAME_WAIT_INFO};
    XrFrameState fs{XR_TYPE_FRAME_STATE};
    const XrResult waited = xrWaitFrame(session_, &fwi, &fs);
    if (first_frame_refused(waited, "xrWaitFrame")) return LoopEnd::headless_refused;
    if (!ok(waited, "xrWaitFrame")) {
      end = LoopEnd::failed;
      break;
    }
    // A headless runtime may not block in xrWaitFrame: pace to its display period (or 90 Hz).
    const double period_s =
        fs.predictedDisplayPeriod > 0 ? static_cast<double>(fs.predictedDisplayPeriod) * 1e-9 : 1.0 / 90.0;
    const auto period = std::chrono::duration_cast<clock::duration>(std::chrono::duration<double>(period_s));
    if (frames_ > 0 && clock::now() - last_wait_return < period / 2) {
      std::this_thread::sleep_until(last_wait_return + period);
    }
    last_wait_return = clock::now();

    XrFrameBeginInfo fbi{XR_TYPE_FRAME_BEGIN_INFO};
    const XrResult begun = xrBeginFrame(session_, &fbi);
    if (first_frame_refused(begun, "xrBeginFrame")) return LoopEnd::headless_refused;
    if (!ok(begun, "xrBeginFrame")) {
      end = LoopEnd::failed;
      break;
    }
    XrTime t = fs.predictedDisplayTime;
    if (t <= 0) {
      if (!zero_display_time_reported_) {
        emit(XrProbeZeroDisplayTime{});
        zero_display_time_reported_ = true;
      }
      t = now();
      if (t <= 0) {
        end = LoopEnd::failed;
        break;
      }
    }
    bool located = true;
    for (auto& h : hands_) located = located && locate(h, t);
    if (!located) {
      end = LoopEnd::failed;
      break;
    }
    bool keep_going = true;
    if (hooks_.frame) {
      detail::XrProbeFrame frame{t, std::chrono::duration<double>(clock::now() - start).count(), session_, space_, {},
                                 state_};
      for (const auto& h : hands_) frame.hands.push_back({h.which, h.active, h.joints.data()});
      keep_going = hooks_.frame(frame);
    }
    XrFrameEndInfo fei{XR_TYPE_FRAME_END_INFO};
    fei.displayTime = t;
    fei.environmentBlendMode = blend_mode_;
    fei.layerCount = 0;
    const XrResult ended = xrEndFrame(session_, &fei);
    if (first_frame_refused(ended, "xrEndFrame")) return LoopEnd::headless_refused;
    if (!ok(ended, "xrEndFrame")) {
      end = LoopEnd::failed;
      break;
    }
    ++frames_;
    if (!keep_going) break;

    const double window_s = std::chrono::duration<double>(clock::now() - window_start).count();
    if (window_s >= 1.0) {
      report_second(std::chrono::duration<double>(clock::now() - start).count(), window_s);
      window_start = clock::now();
    }
  }
  if (failed_) end = LoopEnd::failed;
  run_s_ = std::chrono::duration<double>(clock::now() - start).count();
  const double tail_s = std::chrono::duration<double>(clock::now() - window_start).count();
  // A short tail is not worth a report of its own, but its locates count in the summary.
  report_second(run_s_, tail_s, tail_s > 0.2);
  return end;
}

Result<XrProbeSummary> Probe::summarise(LoopEnd end) {
  XrProbeSummary summary;
  summary.interrupted = stopped();
  summary.run_s = run_s_;
  summary.frames = frames_;
  summary.kind = kind_;
  for (const auto& h : hands_) summary.hands.emplace_back(h.which, h.total);
  for (const auto& h : hands_) {
    if (!get_latency_ || h.tracker == XR_NULL_HANDLE) continue;
    XrHandTrackingLatencyPROPRIO l{};
    l.type = XR_TYPE_HAND_TRACKING_LATENCY_PROPRIO;
    if (!ok(get_latency_(h.tracker, &l), "xrGetHandTrackingLatencyPROPRIO")) continue;
    XrProbeLatency out;
    out.poses = l.poseCount;
    out.bin_ms = l.binWidthMs;
    const std::size_t n = std::min<std::size_t>(l.binCount, XR_PROPRIO_LATENCY_BIN_COUNT);
    out.sample_to_ready.assign(l.sampleToReady, l.sampleToReady + n);
    out.age_at_locate.assign(l.ageAtLocate, l.ageAtLocate + n);
    out.max_sample_to_ready_ms = l.maxSampleToReadyMs;
    out.max_age_at_locate_ms = l.maxAgeAtLocateMs;
    summary.latency.emplace_back(h.which, std::move(out));
  }
  emit(summary);
  const bool torn_down = teardown();
  if (end == LoopEnd::failed || failed_ || !torn_down) {
    return make_error(Errc::io_error, "xr-probe stopped on the failed call above");
  }
  return summary;
}

// Ends and destroys the session, then the Vulkan objects, then the instance,
// and resets the per-session state (the fallback starts a new session).
// False when a call failed (reported).
bool Probe::teardown() {
  if (instance_ == XR_NULL_HANDLE) return true;
  bool all_ok = true;
  auto check = [&](XrResult r, const char* what) { all_ok = ok(r, what) && all_ok; };
  if (session_ != XR_NULL_HANDLE && session_running_) {
    // Ask the runtime to end the session, then follow its state changes to STOPPING.
    const XrResult requested = xrRequestExitSession(session_);
    check(requested, "xrRequestExitSession");
    if (XR_SUCCEEDED(requested)) {
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(3);
      while (session_running_ && !exiting_ && std::chrono::steady_clock::now() < deadline) {
        if (!pump_events()) {
          log_pump_error();
          break;
        }
        if (!session_running_) break;
        // Keep the frame loop turning while the runtime winds down.
        XrFrameWaitInfo fwi{XR_TYPE_FRAME_WAIT_INFO};
        XrFrameState fs{XR_TYPE_FRAME_STATE};
        if (XR_FAILED(xrWaitFrame(session_, &fwi, &fs))) break;
        XrFrameBeginInfo fbi{XR_TYPE_FRAME_BEGIN_INFO};
        if (XR_FAILED(xrBeginFrame(session_, &fbi))) break;
        XrFrameEndInfo fei{XR_TYPE_FRAME_END_INFO};
        fei.displayTime = fs.predictedDisplayTime > 0 ? fs.predictedDisplayTime : now();
        fei.environmentBlendMode = blend_mode_;
        if (XR_FAILED(xrEndFrame(session_, &fei))) break;
      }
    }
    if (session_running_) {
      check(xrEndSession(session_), "xrEndSession");
      session_running_ = false;
    }
  }
  if (hooks_.session_ending) hooks_.session_ending();
  for (auto& h : hands_) {
    if (h.tracker != XR_NULL_HANDLE) {
      check(destroy_hand_tracker_(h.tracker), "xrDestroyHandTrackerEXT");
      h.tracker = XR_NULL_HANDLE;
    }
  }
  hands_.clear();
  if (space_ != XR_NULL_HANDLE) {
    check(xrDestroySpace(space_), "xrDestroySpace");
    space_ = XR_NULL_HANDLE;
  }
  if (session_ != XR_NULL_HANDLE) {
    check(xrDestroySession(session_), "xrDestroySession");
    session_ = XR_NULL_HANDLE;
  }
  // The app destroys its Vulkan device and instance after the session, before the XrInstance.
  vulkan_.reset();
  check(xrDestroyInstance(instance_), "xrDestroyInstance");
  instance_ = XR_NULL_HANDLE;
  state_ = XR_SESSION_STATE_UNKNOWN;
  exiting_ = false;
  zero_display_time_reported_ = false;
  return all_ok;
}

}  // namespace

Result<XrProbeSummary> run_xr_probe(const XrProbeOptions& options, const XrProbeReport& report) {
  static const detail::XrProbeHooks kNoHooks;
  return detail::run_xr_probe_hooked(options, report, kNoHooks);
}

Result<XrProbeSummary> detail::run_xr_probe_hooked(const XrProbeOptions& options, const XrProbeReport& report,
                                                   const XrProbeHooks& hooks) {
  if (Status s = options.validate(); !s) return s.error();
  Probe probe(options, report, hooks);
  return probe.run();
}

}  // namespace proprio::engine
