// proprio xr-probe: a minimal OpenXR app that asks the active runtime (and
// whatever API layers are enabled) for XR_EXT_hand_tracking joints and prints
// what comes back, once a second. It goes through the system's OpenXR loader,
// exactly like any other app.
//
// Sessions: headless (XR_MND_headless) when the runtime offers it, since that
// needs no GPU. Monado offers the extension but refuses frames in headless
// sessions (xrBeginFrame: XR_ERROR_CALL_ORDER_INVALID), so when a headless
// session cannot run its first frame the probe starts again with a Vulkan
// graphics binding (XR_KHR_vulkan_enable2), as `hello_xr -g Vulkan2` would.
// Frames end with no layers, which the spec allows, so no swapchain is needed.
#define XR_USE_TIMESPEC 1
#include <time.h>

// Set by CMake when proprio::engine (Vulkan through OpenXR, the renderer's
// Vulkan context) is linked: the Vulkan session needs it.
#ifndef PROPRIO_XR_PROBE_VULKAN
#define PROPRIO_XR_PROBE_VULKAN 0
#endif
#if PROPRIO_XR_PROBE_VULKAN
// Before the OpenXR platform header: XR_KHR_vulkan_enable2's structures use Vulkan's types.
#define XR_USE_GRAPHICS_API_VULKAN 1
#include <vulkan/vulkan.h>
#endif

#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>
#include <openxr/openxr_reflection.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "proprio/core/log.hpp"
#include "proprio/openxr_layer/xr_ext.hpp"
#include "xr_loader_paths.hpp"
#if PROPRIO_XR_PROBE_VULKAN
#include "proprio/engine/xr_vulkan.hpp"
#include "proprio/render/context.hpp"
#endif

namespace proprio::cli {

namespace {

// Exit statuses, also listed in --help.
constexpr int kExitOk = 0;
constexpr int kExitError = 1;
constexpr int kExitNoHandTracking = 2;
constexpr int kExitNeverActive = 3;

struct ProbeArgs {
  double seconds = 5.0;
  std::string space = "view";
  std::string hand = "both";
  std::string session = "auto";  // auto | headless | vulkan
  bool enable_layer = false;
  bool data_source = false;
};

enum class SessionKind { headless, vulkan };

// XR_KHR_VULKAN_ENABLE2_EXTENSION_NAME, which the platform header defines only with Vulkan's headers.
constexpr const char* kVulkanEnable2Extension = "XR_KHR_vulkan_enable2";

const char* session_kind_name(SessionKind k) {
  return k == SessionKind::headless ? "headless (XR_MND_headless)" : "Vulkan graphics binding (XR_KHR_vulkan_enable2)";
}

// How a session's frame loop ended.
enum class LoopEnd {
  completed,         // --seconds ran out, Ctrl-C, or the runtime ended the session
  failed,            // a call failed (reported)
  headless_refused,  // a headless session could not run its first frame
};

// Internal: a headless session could not be created or run (the caller may fall back).
constexpr int kHeadlessRefused = -1;

// Names of XrResult values without an instance (xrResultToString needs one).
const char* result_name(XrResult r) {
  switch (r) {
#define PROPRIO_XR_RESULT_CASE(name, value) \
  case name:                                \
    return #name;
    XR_LIST_ENUM_XrResult(PROPRIO_XR_RESULT_CASE)
#undef PROPRIO_XR_RESULT_CASE
    default:
      return "unknown XrResult";
  }
}

const char* session_state_name(XrSessionState s) {
  switch (s) {
#define PROPRIO_XR_STATE_CASE(name, value) \
  case name:                               \
    return #name;
    XR_LIST_ENUM_XrSessionState(PROPRIO_XR_STATE_CASE)
#undef PROPRIO_XR_STATE_CASE
    default:
      return "unknown state";
  }
}

// An OpenXR struct, zeroed, with its type set.
template <typename T>
T make(XrStructureType type) {
  T s{};
  s.type = type;
  return s;
}

constexpr XrSpaceLocationFlags kAllLocationFlags =
    XR_SPACE_LOCATION_POSITION_VALID_BIT | XR_SPACE_LOCATION_ORIENTATION_VALID_BIT |
    XR_SPACE_LOCATION_POSITION_TRACKED_BIT | XR_SPACE_LOCATION_ORIENTATION_TRACKED_BIT;

// Per-hand statistics over the current one-second window and the whole run.
struct HandWindow {
  std::uint64_t locates = 0, distinct = 0, active = 0, fully_tracked_joints = 0, joints = 0;
};

struct HandProbe {
  XrHandEXT hand = XR_HAND_LEFT_EXT;
  const char* name = "left";
  XrHandTrackerEXT tracker = XR_NULL_HANDLE;
  std::array<XrHandJointLocationEXT, XR_HAND_JOINT_COUNT_EXT> joints{};
  std::array<XrHandJointVelocityEXT, XR_HAND_JOINT_COUNT_EXT> velocities{};
  std::array<XrPosef, XR_HAND_JOINT_COUNT_EXT> previous{};
  bool have_previous = false;
  bool active = false;
  XrHandTrackingDataSourceStateEXT source_state{};
  HandWindow window, total;
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

class Probe {
 public:
  explicit Probe(ProbeArgs args) : args_(std::move(args)) {}
  ~Probe() { teardown(); }
  int run();

 private:
  // Reports a failed call with the runtime's name for the result; true when it succeeded.
  bool ok(XrResult r, const char* what) {
    if (XR_SUCCEEDED(r)) return true;
    logger().error("{} failed: {} ({})", what, result_text(r), static_cast<int>(r));
    return false;
  }
  std::string result_text(XrResult r) {
    char name[XR_MAX_RESULT_STRING_SIZE] = {};
    if (instance_ == XR_NULL_HANDLE || XR_FAILED(xrResultToString(instance_, r, name))) {
      std::snprintf(name, sizeof name, "%s", result_name(r));
    }
    return name;
  }
  template <typename Fn>
  bool load(const char* fn_name, Fn& fn) {
    return ok(xrGetInstanceProcAddr(instance_, fn_name, reinterpret_cast<PFN_xrVoidFunction*>(&fn)), fn_name);
  }

  int check_extensions();
  int create_instance(SessionKind kind);
  int create_session(SessionKind kind);
  int create_vulkan_binding();
  LoopEnd run_frames();
  bool pump_events();  // false when the session ended or the instance is lost
  bool wait_for_state(XrSessionState wanted, double timeout_s);
  XrTime now();
  bool locate(HandProbe& h, XrTime t);
  // Prints the window's report (unless !print) and adds the window to the run's totals.
  void report_second(double t_s, double window_s, bool print = true);
  int summarise(LoopEnd end);
  bool teardown();

  ProbeArgs args_;
  std::vector<XrExtensionProperties> offered_;
  bool has_headless_ext_ = false, has_vulkan_ext_ = false;
  bool printed_system_ = false;
  SessionKind kind_ = SessionKind::headless;
  XrInstance instance_ = XR_NULL_HANDLE;
  XrSystemId system_ = XR_NULL_SYSTEM_ID;
  XrSession session_ = XR_NULL_HANDLE;
  XrSpace space_ = XR_NULL_HANDLE;
  XrSessionState state_ = XR_SESSION_STATE_UNKNOWN;
  bool session_running_ = false, exiting_ = false;
  bool failed_ = false;  // a call failed or the runtime was lost: exit status 1
  bool has_data_source_ext_ = false;
  XrViewConfigurationType view_config_ = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  XrEnvironmentBlendMode blend_mode_ = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
  std::vector<HandProbe> hands_;
  bool zero_display_time_reported_ = false;
  std::uint64_t frames_ = 0;
  double run_s_ = 0.0;
  // What a headless session's first failed frame call was, for the fallback message.
  std::string refused_call_;
#if PROPRIO_XR_PROBE_VULKAN
  // The Vulkan session's device side: destroyed after the session, before the instance.
  std::unique_ptr<render::VulkanContext> vulkan_;
  XrGraphicsBindingVulkan2KHR vulkan_binding_{};
#endif

  PFN_xrCreateHandTrackerEXT create_hand_tracker_ = nullptr;
  PFN_xrDestroyHandTrackerEXT destroy_hand_tracker_ = nullptr;
  PFN_xrLocateHandJointsEXT locate_hand_joints_ = nullptr;
  PFN_xrConvertTimespecTimeToTimeKHR convert_timespec_ = nullptr;
};

// Lists the instance extensions (the runtime's and, with --enable-layer, the
// layer's) and checks for the ones every session needs.
int Probe::check_extensions() {
  uint32_t count = 0;
  if (!ok(xrEnumerateInstanceExtensionProperties(nullptr, 0, &count, nullptr), "xrEnumerateInstanceExtensionProperties")) {
    logger().error("the OpenXR loader found no usable runtime. Check 'proprio layer status' (Active runtime) or set "
                   "XR_RUNTIME_JSON; XR_LOADER_DEBUG=all shows what the loader tried");
    return kExitError;
  }
  offered_.assign(count, make<XrExtensionProperties>(XR_TYPE_EXTENSION_PROPERTIES));
  if (!ok(xrEnumerateInstanceExtensionProperties(nullptr, count, &count, offered_.data()),
          "xrEnumerateInstanceExtensionProperties")) {
    return kExitError;
  }
  offered_.resize(count);
  // With --enable-layer the layer's own extensions count too.
  if (args_.enable_layer) {
    uint32_t n = 0;
    if (ok(xrEnumerateInstanceExtensionProperties(xr::kLayerName, 0, &n, nullptr),
           "xrEnumerateInstanceExtensionProperties(XR_APILAYER_PROPRIO_hand_tracking)")) {
      std::vector<XrExtensionProperties> more(n, make<XrExtensionProperties>(XR_TYPE_EXTENSION_PROPERTIES));
      if (!ok(xrEnumerateInstanceExtensionProperties(xr::kLayerName, n, &n, more.data()),
              "xrEnumerateInstanceExtensionProperties")) {
        return kExitError;
      }
      offered_.insert(offered_.end(), more.begin(), more.begin() + n);
    } else {
      logger().error("--enable-layer: the loader does not find {}; run 'proprio layer install' first", xr::kLayerName);
      return kExitError;
    }
  }
  auto offered = [&](const char* name) {
    return std::any_of(offered_.begin(), offered_.end(),
                       [&](const auto& e) { return std::strcmp(e.extensionName, name) == 0; });
  };
  std::string list;
  for (const auto& e : offered_) list += (list.empty() ? "" : ", ") + std::string(e.extensionName);
  logger().debug("instance extensions offered: {}", list);

  if (!offered(XR_EXT_HAND_TRACKING_EXTENSION_NAME)) {
    logger().error("XR_EXT_hand_tracking is not offered by the active runtime or any enabled API layer. Enable "
                   "Proprio's layer: 'proprio layer status' says what the loader sees and what to do");
    return kExitNoHandTracking;
  }
  if (!offered(XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME)) {
    logger().error("the runtime does not offer XR_KHR_convert_timespec_time, which the probe needs to read the "
                   "monotonic clock in XrTime");
    return kExitError;
  }
  has_headless_ext_ = offered(XR_MND_HEADLESS_EXTENSION_NAME);
  has_vulkan_ext_ = offered(kVulkanEnable2Extension);
  // Opt-in: Debian's 1.0.20 core_validation layer predates XR_EXT_hand_tracking_data_source
  // and rejects its structs in a next chain.
  has_data_source_ext_ = args_.data_source && offered(XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME);
  if (args_.data_source && !has_data_source_ext_) {
    std::printf("(--data-source: XR_EXT_hand_tracking_data_source is not offered; continuing without it)\n");
  }
  return kExitOk;
}

// The instance for one kind of session: headless enables XR_MND_headless,
// Vulkan enables XR_KHR_vulkan_enable2 and not XR_MND_headless (some Monado
// versions create no compositor for an instance that enabled it).
int Probe::create_instance(SessionKind kind) {
  std::vector<const char*> enabled = {XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME,
                                      kind == SessionKind::headless ? XR_MND_HEADLESS_EXTENSION_NAME
                                                                    : kVulkanEnable2Extension};
  if (has_data_source_ext_) enabled.push_back(XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME);
  const char* layers[] = {xr::kLayerName};

  auto ci = make<XrInstanceCreateInfo>(XR_TYPE_INSTANCE_CREATE_INFO);
  std::snprintf(ci.applicationInfo.applicationName, XR_MAX_APPLICATION_NAME_SIZE, "proprio xr-probe");
  ci.applicationInfo.applicationVersion = 1;
  std::snprintf(ci.applicationInfo.engineName, XR_MAX_ENGINE_NAME_SIZE, "proprio");
  ci.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
  ci.enabledExtensionCount = static_cast<uint32_t>(enabled.size());
  ci.enabledExtensionNames = enabled.data();
  if (args_.enable_layer) {
    ci.enabledApiLayerCount = 1;
    ci.enabledApiLayerNames = layers;
  }
  if (!ok(xrCreateInstance(&ci, &instance_), "xrCreateInstance")) return kExitError;

  auto ip = make<XrInstanceProperties>(XR_TYPE_INSTANCE_PROPERTIES);
  if (!ok(xrGetInstanceProperties(instance_, &ip), "xrGetInstanceProperties")) return kExitError;
  if (!printed_system_) {
    std::printf("Runtime: %s %u.%u.%u\n", ip.runtimeName, XR_VERSION_MAJOR(ip.runtimeVersion),
                XR_VERSION_MINOR(ip.runtimeVersion), XR_VERSION_PATCH(ip.runtimeVersion));
  }

  if (!load("xrCreateHandTrackerEXT", create_hand_tracker_) || !load("xrDestroyHandTrackerEXT", destroy_hand_tracker_) ||
      !load("xrLocateHandJointsEXT", locate_hand_joints_) ||
      !load("xrConvertTimespecTimeToTimeKHR", convert_timespec_)) {
    return kExitError;
  }

  auto gi = make<XrSystemGetInfo>(XR_TYPE_SYSTEM_GET_INFO);
  gi.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  if (!ok(xrGetSystem(instance_, &gi, &system_), "xrGetSystem(HEAD_MOUNTED_DISPLAY)")) {
    logger().error("the runtime has no head-mounted system right now: is the headset connected and the runtime's "
                   "service (e.g. monado-service) running?");
    return kExitError;
  }
  auto ht = make<XrSystemHandTrackingPropertiesEXT>(XR_TYPE_SYSTEM_HAND_TRACKING_PROPERTIES_EXT);
  auto sp = make<XrSystemProperties>(XR_TYPE_SYSTEM_PROPERTIES);
  sp.next = &ht;
  if (!ok(xrGetSystemProperties(instance_, system_, &sp), "xrGetSystemProperties")) return kExitError;
  if (!printed_system_) {
    std::printf("System: %s (vendor %u)\n", sp.systemName, sp.vendorId);
    std::printf("supportsHandTracking: %s\n", ht.supportsHandTracking ? "true" : "false");
    if (has_data_source_ext_) std::printf("XR_EXT_hand_tracking_data_source: enabled\n");
    printed_system_ = true;
  }
  if (!ht.supportsHandTracking) {
    logger().error("the system reports supportsHandTracking = false: no hand tracker can be created. If Proprio's "
                   "layer is enabled, check its configuration and log ('proprio layer status')");
    return kExitNoHandTracking;
  }
  return kExitOk;
}

#if PROPRIO_XR_PROBE_VULKAN
// XR_KHR_vulkan_enable2: the runtime creates the Vulkan instance and device
// (adding what it needs), through the engine's hooks on the renderer's context.
int Probe::create_vulkan_binding() {
  render::ContextOptions base;
  base.app_name = "proprio xr-probe";
  auto co = engine::xr_vulkan_context_options(instance_, system_, std::move(base));
  if (!co) {
    logger().error("the Vulkan graphics binding could not be set up: {}", co.error().message);
    return kExitError;
  }
  auto ctx = render::VulkanContext::create(*co);
  if (!ctx) {
    logger().error("the Vulkan graphics binding could not be set up: {}", ctx.error().message);
    return kExitError;
  }
  vulkan_ = std::move(*ctx);
  vulkan_binding_ = make<XrGraphicsBindingVulkan2KHR>(XR_TYPE_GRAPHICS_BINDING_VULKAN2_KHR);
  vulkan_binding_.instance = vulkan_->instance();
  vulkan_binding_.physicalDevice = vulkan_->physical_device();
  vulkan_binding_.device = vulkan_->device();
  vulkan_binding_.queueFamilyIndex = vulkan_->queue_family();
  vulkan_binding_.queueIndex = 0;
  return kExitOk;
}
#else
int Probe::create_vulkan_binding() {
  logger().error("this build of proprio has no engine (proprio::engine: Vulkan through OpenXR), so xr-probe cannot "
                 "open a Vulkan session");
  return kExitError;
}
#endif

int Probe::create_session(SessionKind kind) {
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

  auto sci = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  sci.systemId = system_;
  std::string device;
  if (kind == SessionKind::vulkan) {
    if (int rc = create_vulkan_binding(); rc != kExitOk) return rc;
#if PROPRIO_XR_PROBE_VULKAN
    sci.next = &vulkan_binding_;
    device = " on " + vulkan_->device_name();
#endif
  }
  // Headless (XR_MND_headless): no graphics binding in the chain.
  const XrResult created = xrCreateSession(instance_, &sci, &session_);
  if (kind == SessionKind::headless && XR_FAILED(created) && args_.session == "auto" && has_vulkan_ext_) {
    refused_call_ = "xrCreateSession: " + result_text(created);
    return kHeadlessRefused;
  }
  if (!ok(created, kind == SessionKind::headless ? "xrCreateSession (headless)" : "xrCreateSession (Vulkan)")) {
    return kExitError;
  }

  if (!wait_for_state(XR_SESSION_STATE_READY, 10.0)) {
    if (!g_sigint_stop.load() && !failed_) {
      logger().error("the session never became READY (last state {})", session_state_name(state_));
    }
    return kExitError;
  }
  auto bi = make<XrSessionBeginInfo>(XR_TYPE_SESSION_BEGIN_INFO);
  bi.primaryViewConfigurationType = view_config_;
  if (!ok(xrBeginSession(session_, &bi), "xrBeginSession")) return kExitError;
  session_running_ = true;

  const XrReferenceSpaceType space_type = args_.space == "local"   ? XR_REFERENCE_SPACE_TYPE_LOCAL
                                          : args_.space == "stage" ? XR_REFERENCE_SPACE_TYPE_STAGE
                                                                   : XR_REFERENCE_SPACE_TYPE_VIEW;
  n = 0;
  if (!ok(xrEnumerateReferenceSpaces(session_, 0, &n, nullptr), "xrEnumerateReferenceSpaces")) return kExitError;
  std::vector<XrReferenceSpaceType> spaces(n);
  if (!ok(xrEnumerateReferenceSpaces(session_, n, &n, spaces.data()), "xrEnumerateReferenceSpaces")) return kExitError;
  if (std::find(spaces.begin(), spaces.end(), space_type) == spaces.end()) {
    logger().error("the runtime does not offer the {} reference space; try --space view or --space local", args_.space);
    return kExitError;
  }
  auto rci = make<XrReferenceSpaceCreateInfo>(XR_TYPE_REFERENCE_SPACE_CREATE_INFO);
  rci.referenceSpaceType = space_type;
  rci.poseInReferenceSpace.orientation.w = 1.0f;
  if (!ok(xrCreateReferenceSpace(session_, &rci, &space_), "xrCreateReferenceSpace")) return kExitError;

  auto add_hand = [&](XrHandEXT hand, const char* name) {
    hands_.emplace_back();
    hands_.back().hand = hand;
    hands_.back().name = name;
  };
  if (args_.hand != "right") add_hand(XR_HAND_LEFT_EXT, "left");
  if (args_.hand != "left") add_hand(XR_HAND_RIGHT_EXT, "right");
  for (auto& h : hands_) {
    XrHandTrackingDataSourceEXT sources[] = {XR_HAND_TRACKING_DATA_SOURCE_UNOBSTRUCTED_EXT,
                                             XR_HAND_TRACKING_DATA_SOURCE_CONTROLLER_EXT};
    auto dsi = make<XrHandTrackingDataSourceInfoEXT>(XR_TYPE_HAND_TRACKING_DATA_SOURCE_INFO_EXT);
    dsi.requestedDataSourceCount = 2;
    dsi.requestedDataSources = sources;
    auto hci = make<XrHandTrackerCreateInfoEXT>(XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT);
    hci.next = has_data_source_ext_ ? &dsi : nullptr;
    hci.hand = h.hand;
    hci.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
    const std::string what = std::string("xrCreateHandTrackerEXT(") + h.name + ")";
    if (!ok(create_hand_tracker_(session_, &hci, &h.tracker), what.c_str())) return kExitError;
  }
  std::printf("Session: %s%s; locating %s hand joints in %s space.\n\n", session_kind_name(kind), device.c_str(),
              args_.hand.c_str(), args_.space.c_str());
  std::fflush(stdout);
  return kExitOk;
}

bool Probe::pump_events() {
  while (true) {
    auto ev = make<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
    const XrResult r = xrPollEvent(instance_, &ev);
    if (r == XR_EVENT_UNAVAILABLE) return true;
    if (!ok(r, "xrPollEvent")) {
      failed_ = true;
      return false;
    }
    switch (ev.type) {
      case XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED: {
        const auto& sc = reinterpret_cast<const XrEventDataSessionStateChanged&>(ev);
        state_ = sc.state;
        logger().debug("session state: {}", session_state_name(state_));
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
        logger().error("the runtime is going away (instance loss pending)");
        exiting_ = true;
        failed_ = true;
        return false;
      case XR_TYPE_EVENT_DATA_EVENTS_LOST:
        logger().warn("the runtime dropped events");
        break;
      default:
        break;
    }
  }
}

bool Probe::wait_for_state(XrSessionState wanted, double timeout_s) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (state_ != wanted) {
    if (!pump_events() || g_sigint_stop.load()) return false;
    if (state_ == wanted) break;
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
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
  auto vel = make<XrHandJointVelocitiesEXT>(XR_TYPE_HAND_JOINT_VELOCITIES_EXT);
  vel.jointCount = XR_HAND_JOINT_COUNT_EXT;
  vel.jointVelocities = h.velocities.data();
  h.source_state = make<XrHandTrackingDataSourceStateEXT>(XR_TYPE_HAND_TRACKING_DATA_SOURCE_STATE_EXT);
  if (has_data_source_ext_) vel.next = &h.source_state;
  auto loc = make<XrHandJointLocationsEXT>(XR_TYPE_HAND_JOINT_LOCATIONS_EXT);
  loc.next = &vel;
  loc.jointCount = XR_HAND_JOINT_COUNT_EXT;
  loc.jointLocations = h.joints.data();
  auto li = make<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);
  li.baseSpace = space_;
  li.time = t;
  const std::string what = std::string("xrLocateHandJointsEXT(") + h.name + ")";
  if (!ok(locate_hand_joints_(h.tracker, &li, &loc), what.c_str())) {
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

void Probe::report_second(double t_s, double window_s, bool print) {
  for (auto& h : hands_) {
    const HandWindow& w = h.window;
    if (!print) {
      fold_window(h);
      continue;
    }
    std::printf("t=%5.1f s %-5s %s", t_s, h.name, h.active ? "active  " : "INACTIVE");
    if (h.active) {
      const auto& wrist = h.joints[XR_HAND_JOINT_WRIST_EXT].pose.position;
      const auto& tip = h.joints[XR_HAND_JOINT_INDEX_TIP_EXT].pose.position;
      const auto& q = h.joints[XR_HAND_JOINT_PALM_EXT].pose.orientation;
      // The palm joint's +Y points out of the back of the hand: the palm faces -Y.
      const double fx = -2.0 * (q.x * q.y - q.w * q.z);
      const double fy = -(1.0 - 2.0 * (q.x * q.x + q.z * q.z));
      const double fz = -2.0 * (q.y * q.z + q.w * q.x);
      std::printf(" wrist (%7.1f %7.1f %7.1f) mm  index tip (%7.1f %7.1f %7.1f) mm\n", wrist.x * 1e3, wrist.y * 1e3,
                  wrist.z * 1e3, tip.x * 1e3, tip.y * 1e3, tip.z * 1e3);
      std::printf("                 palm q(xyzw) (%6.3f %6.3f %6.3f %6.3f), faces (%5.2f %5.2f %5.2f)", q.x, q.y, q.z,
                  q.w, fx, fy, fz);
      const auto& v = h.velocities[XR_HAND_JOINT_INDEX_TIP_EXT];
      if (v.velocityFlags & XR_SPACE_VELOCITY_LINEAR_VALID_BIT) {
        std::printf(", index tip speed %.3f m/s",
                    std::sqrt(v.linearVelocity.x * v.linearVelocity.x + v.linearVelocity.y * v.linearVelocity.y +
                              v.linearVelocity.z * v.linearVelocity.z));
      }
      if (has_data_source_ext_ && h.source_state.isActive) {
        std::printf(", source %s",
                    h.source_state.dataSource == XR_HAND_TRACKING_DATA_SOURCE_CONTROLLER_EXT ? "controller" : "unobstructed");
      }
      std::printf("\n                ");
    }
    std::printf(" joints fully tracked %5.1f%%, locate %6.1f Hz, distinct data %6.1f Hz\n",
                w.joints ? 100.0 * static_cast<double>(w.fully_tracked_joints) / static_cast<double>(w.joints) : 0.0,
                static_cast<double>(w.locates) / window_s, static_cast<double>(w.distinct) / window_s);
    fold_window(h);
  }
  std::fflush(stdout);
}

int Probe::run() {
  if (int rc = check_extensions(); rc != kExitOk) return rc;
  const bool vulkan_usable = has_vulkan_ext_ && PROPRIO_XR_PROBE_VULKAN;
  if (args_.session == "headless" && !has_headless_ext_) {
    logger().error("--session headless: the runtime does not offer XR_MND_headless");
    return kExitError;
  }
  if (args_.session == "vulkan" && !has_vulkan_ext_) {
    logger().error("--session vulkan: the runtime does not offer XR_KHR_vulkan_enable2");
    return kExitError;
  }
  if (args_.session == "auto" && !has_headless_ext_ && !has_vulkan_ext_) {
    logger().error("the runtime offers neither XR_MND_headless nor XR_KHR_vulkan_enable2, so xr-probe cannot open a "
                   "session; test the layer with an app that uses the runtime's graphics API (e.g. hello_xr)");
    return kExitError;
  }
  SessionKind kind = args_.session == "vulkan" ? SessionKind::vulkan
                     : args_.session == "headless" || has_headless_ext_ ? SessionKind::headless
                                                                        : SessionKind::vulkan;
  kind_ = kind;
  int rc = create_instance(kind);
  if (rc == kExitOk) rc = create_session(kind);
  LoopEnd end = LoopEnd::failed;
  if (rc == kExitOk) end = run_frames();
  if (rc == kHeadlessRefused || end == LoopEnd::headless_refused) {
    if (args_.session == "auto" && vulkan_usable) {
      std::printf("The runtime refuses frames in headless sessions (%s), as Monado does: starting again with a "
                  "Vulkan graphics binding, as hello_xr -g Vulkan2 does.\n",
                  refused_call_.c_str());
      std::fflush(stdout);
      // Failures tearing down the refused session are reported, but the Vulkan
      // session is what counts: its own failures set failed_ again.
      teardown();
      failed_ = false;
      kind = kind_ = SessionKind::vulkan;
      rc = create_instance(kind);
      if (rc == kExitOk) rc = create_session(kind);
      if (rc == kExitOk) end = run_frames();
    } else {
      logger().error("the runtime refuses frames in headless sessions ({}), as Monado does. {}", refused_call_,
                     args_.session == "headless" ? "Run without --session headless (or with --session vulkan)"
                     : !has_vulkan_ext_          ? "It offers no XR_KHR_vulkan_enable2 to fall back to"
                                                 : "This build of proprio has no Vulkan renderer to fall back to");
      return kExitError;
    }
  }
  if (rc != kExitOk) return rc == kHeadlessRefused ? kExitError : rc;
  return summarise(end);
}

// Runs the frame loop for --seconds, locating the hands every frame.
LoopEnd Probe::run_frames() {
  using clock = std::chrono::steady_clock;
  const auto start = clock::now();
  auto window_start = start, last_wait_return = start;
  frames_ = 0;
  // A headless session that cannot run its first frame may be refused by
  // design (Monado): the caller decides, so that failure is not reported here.
  auto first_frame_refused = [&](XrResult r, const char* call) {
    if (kind_ != SessionKind::headless || frames_ > 0 || XR_SUCCEEDED(r)) return false;
    refused_call_ = std::string(call) + ": " + result_text(r);
    return true;
  };
  LoopEnd end = LoopEnd::completed;
  while (!g_sigint_stop.load() && !exiting_) {
    if (!pump_events()) break;
    const double elapsed = std::chrono::duration<double>(clock::now() - start).count();
    if (elapsed >= args_.seconds) break;
    if (!session_running_) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      continue;
    }
    auto fwi = make<XrFrameWaitInfo>(XR_TYPE_FRAME_WAIT_INFO);
    auto fs = make<XrFrameState>(XR_TYPE_FRAME_STATE);
    const XrResult waited = xrWaitFrame(session_, &fwi, &fs);
    if (first_frame_refused(waited, "xrWaitFrame")) return LoopEnd::headless_refused;
    if (!ok(waited, "xrWaitFrame")) {
      end = LoopEnd::failed;
      break;
    }
    // A headless runtime may not block in xrWaitFrame: pace to its display period (or 90 Hz).
    const double period_s = fs.predictedDisplayPeriod > 0 ? static_cast<double>(fs.predictedDisplayPeriod) * 1e-9 : 1.0 / 90.0;
    const auto period = std::chrono::duration_cast<clock::duration>(std::chrono::duration<double>(period_s));
    if (frames_ > 0 && clock::now() - last_wait_return < period / 2) std::this_thread::sleep_until(last_wait_return + period);
    last_wait_return = clock::now();

    auto fbi = make<XrFrameBeginInfo>(XR_TYPE_FRAME_BEGIN_INFO);
    const XrResult begun = xrBeginFrame(session_, &fbi);
    if (first_frame_refused(begun, "xrBeginFrame")) return LoopEnd::headless_refused;
    if (!ok(begun, "xrBeginFrame")) {
      end = LoopEnd::failed;
      break;
    }
    XrTime t = fs.predictedDisplayTime;
    if (t <= 0) {
      if (!zero_display_time_reported_) {
        std::printf("(the runtime's predictedDisplayTime is 0: locating at the current time)\n");
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
    auto fei = make<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
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

int Probe::summarise(LoopEnd end) {
  if (g_sigint_stop.load()) std::printf("\nInterrupted.\n");
  std::printf("\nSummary over %.1f s, %llu frames, %s session:\n", run_s_, static_cast<unsigned long long>(frames_),
              kind_ == SessionKind::headless ? "headless" : "Vulkan");
  bool any_active = false;
  for (const auto& h : hands_) {
    const auto& t = h.total;
    any_active = any_active || t.active > 0;
    std::printf("  %-5s active in %llu of %llu locates, joints fully tracked %.1f%%, distinct data %.1f Hz\n", h.name,
                static_cast<unsigned long long>(t.active), static_cast<unsigned long long>(t.locates),
                t.joints ? 100.0 * static_cast<double>(t.fully_tracked_joints) / static_cast<double>(t.joints) : 0.0,
                run_s_ > 0 ? static_cast<double>(t.distinct) / run_s_ : 0.0);
  }
  std::fflush(stdout);
  const bool torn_down = teardown();
  if (end == LoopEnd::failed || failed_ || !torn_down) {
    logger().error("xr-probe stopped on the failed call above");
    return kExitError;
  }
  if (!any_active) {
    std::printf("No hand was ever active. If Proprio's layer is meant to serve hands, check 'proprio layer status' "
                "and the app's log for the layer's messages.\n");
    return kExitNeverActive;
  }
  return kExitOk;
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
        if (!pump_events()) break;
        if (!session_running_) break;
        // Keep the frame loop turning while the runtime winds down.
        auto fwi = make<XrFrameWaitInfo>(XR_TYPE_FRAME_WAIT_INFO);
        auto fs = make<XrFrameState>(XR_TYPE_FRAME_STATE);
        if (XR_FAILED(xrWaitFrame(session_, &fwi, &fs))) break;
        auto fbi = make<XrFrameBeginInfo>(XR_TYPE_FRAME_BEGIN_INFO);
        if (XR_FAILED(xrBeginFrame(session_, &fbi))) break;
        auto fei = make<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
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
#if PROPRIO_XR_PROBE_VULKAN
  // The app destroys its Vulkan device and instance after the session, before the XrInstance.
  vulkan_.reset();
#endif
  check(xrDestroyInstance(instance_), "xrDestroyInstance");
  instance_ = XR_NULL_HANDLE;
  state_ = XR_SESSION_STATE_UNKNOWN;
  exiting_ = false;
  zero_display_time_reported_ = false;
  return all_ok;
}

int run_xr_probe(const ProbeArgs& a) {
  g_sigint_stop.store(false);
  auto previous = std::signal(SIGINT, on_sigint_stop);
  int rc = kExitError;
  {
    Probe probe(a);
    rc = probe.run();
  }
  std::signal(SIGINT, previous);
  return rc;
}

}  // namespace

void add_xr_probe_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<ProbeArgs>();
  CLI::App* cmd = app.add_subcommand(
      "xr-probe",
      "Be a minimal OpenXR app: through the system's OpenXR loader, open a session on the active runtime, create "
      "hand trackers (XR_EXT_hand_tracking) and print once a second what they report: whether each hand is active, "
      "wrist and index-tip positions (mm), palm orientation, the share of joints with all location flags, how often "
      "joints were located and how often the data actually changed.\n"
      "The session is headless (XR_MND_headless) when the runtime offers it. When a headless session cannot run "
      "frames (Monado refuses xrBeginFrame there), or the runtime has no headless mode, the probe uses a Vulkan "
      "graphics binding (XR_KHR_vulkan_enable2) instead, and says which it used.\n"
      "Enabled API layers (Proprio's included, see 'proprio layer status') apply as for any app. Ctrl-C ends it "
      "cleanly.\n"
      "Exit status: 0 a hand was active and no call failed; 1 an error, including any failed OpenXR call (reported with its XrResult); "
      "2 XR_EXT_hand_tracking not offered, or supportsHandTracking false; 3 the run completed without a failed "
      "call but no hand was ever active.");
  cmd->add_option("--seconds", args->seconds, "How long to run, s")->check(CLI::Range(0.0, 24.0 * 3600.0))->capture_default_str();
  cmd->add_option("--space", args->space, "Reference space to locate the joints in")
      ->check(CLI::IsMember({"view", "local", "stage"}))
      ->capture_default_str();
  cmd->add_option("--hand", args->hand, "Which hand trackers to create")
      ->check(CLI::IsMember({"left", "right", "both"}))
      ->capture_default_str();
  cmd->add_option("--session", args->session,
                  "auto: headless when offered, else (or when the runtime refuses headless frames) a Vulkan graphics "
                  "binding; headless or vulkan: only that kind")
      ->check(CLI::IsMember({"auto", "headless", "vulkan"}))
      ->capture_default_str();
  cmd->add_flag("--enable-layer", args->enable_layer,
                "Enable XR_APILAYER_PROPRIO_hand_tracking from the app side (enabledApiLayerNames), as an app "
                "could, for an explicit install without XR_ENABLE_API_LAYERS");
  cmd->add_flag("--data-source", args->data_source,
                "Also enable XR_EXT_hand_tracking_data_source when offered, and report each hand's data source "
                "(Debian's 1.0.20 core_validation layer rejects this extension's structs)");
  cmd->callback([args, &exit_code] { exit_code = run_xr_probe(*args); });
}

}  // namespace proprio::cli
