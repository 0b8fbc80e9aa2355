// proprio xr-probe: a minimal OpenXR app that asks the active runtime (and
// whatever API layers are enabled) for XR_EXT_hand_tracking joints and prints
// what comes back, once a second. It goes through the system's OpenXR loader,
// exactly like any other app.
#define XR_USE_TIMESPEC 1
#include <time.h>

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
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "proprio/core/log.hpp"
#include "proprio/openxr_layer/xr_ext.hpp"
#include "xr_loader_paths.hpp"

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
  bool enable_layer = false;
  bool data_source = false;
};

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

class Probe {
 public:
  explicit Probe(ProbeArgs args) : args_(std::move(args)) {}
  ~Probe() { teardown(); }
  int run();

 private:
  // Reports a failed call with the runtime's name for the result; true when it succeeded.
  bool ok(XrResult r, const char* what) {
    if (XR_SUCCEEDED(r)) return true;
    char name[XR_MAX_RESULT_STRING_SIZE] = {};
    if (instance_ == XR_NULL_HANDLE || XR_FAILED(xrResultToString(instance_, r, name))) {
      std::snprintf(name, sizeof name, "%s", result_name(r));
    }
    logger().error("{} failed: {} ({})", what, name, static_cast<int>(r));
    return false;
  }
  template <typename Fn>
  bool load(const char* fn_name, Fn& fn) {
    return ok(xrGetInstanceProcAddr(instance_, fn_name, reinterpret_cast<PFN_xrVoidFunction*>(&fn)), fn_name);
  }

  int create_instance();
  int create_session();
  bool pump_events();  // false when the session ended or the instance is lost
  bool wait_for_state(XrSessionState wanted, double timeout_s);
  XrTime now();
  void locate(HandProbe& h, XrTime t);
  void report_second(double t_s, double window_s);
  void teardown();

  ProbeArgs args_;
  XrInstance instance_ = XR_NULL_HANDLE;
  XrSystemId system_ = XR_NULL_SYSTEM_ID;
  XrSession session_ = XR_NULL_HANDLE;
  XrSpace space_ = XR_NULL_HANDLE;
  XrSessionState state_ = XR_SESSION_STATE_UNKNOWN;
  bool session_running_ = false, exiting_ = false;
  bool has_data_source_ext_ = false;
  XrViewConfigurationType view_config_ = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  XrEnvironmentBlendMode blend_mode_ = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
  std::vector<HandProbe> hands_;
  bool zero_display_time_reported_ = false;

  PFN_xrCreateHandTrackerEXT create_hand_tracker_ = nullptr;
  PFN_xrDestroyHandTrackerEXT destroy_hand_tracker_ = nullptr;
  PFN_xrLocateHandJointsEXT locate_hand_joints_ = nullptr;
  PFN_xrConvertTimespecTimeToTimeKHR convert_timespec_ = nullptr;
};

int Probe::create_instance() {
  uint32_t count = 0;
  if (!ok(xrEnumerateInstanceExtensionProperties(nullptr, 0, &count, nullptr), "xrEnumerateInstanceExtensionProperties")) {
    logger().error("the OpenXR loader found no usable runtime. Check 'proprio layer status' (Active runtime) or set "
                   "XR_RUNTIME_JSON; XR_LOADER_DEBUG=all shows what the loader tried");
    return kExitError;
  }
  std::vector<XrExtensionProperties> exts(count, make<XrExtensionProperties>(XR_TYPE_EXTENSION_PROPERTIES));
  if (!ok(xrEnumerateInstanceExtensionProperties(nullptr, count, &count, exts.data()),
          "xrEnumerateInstanceExtensionProperties")) {
    return kExitError;
  }
  // With --enable-layer the layer's own extensions count too.
  if (args_.enable_layer) {
    uint32_t n = 0;
    if (ok(xrEnumerateInstanceExtensionProperties(xr::kLayerName, 0, &n, nullptr),
           "xrEnumerateInstanceExtensionProperties(XR_APILAYER_PROPRIO_hand_tracking)")) {
      std::vector<XrExtensionProperties> more(n, make<XrExtensionProperties>(XR_TYPE_EXTENSION_PROPERTIES));
      if (ok(xrEnumerateInstanceExtensionProperties(xr::kLayerName, n, &n, more.data()), "xrEnumerateInstanceExtensionProperties")) {
        exts.insert(exts.end(), more.begin(), more.begin() + n);
      }
    } else {
      logger().error("--enable-layer: the loader does not find {}; run 'proprio layer install' first", xr::kLayerName);
      return kExitError;
    }
  }
  auto offered = [&](const char* name) {
    return std::any_of(exts.begin(), exts.end(), [&](const auto& e) { return std::strcmp(e.extensionName, name) == 0; });
  };
  std::string list;
  for (const auto& e : exts) list += (list.empty() ? "" : ", ") + std::string(e.extensionName);
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
  if (!offered(XR_MND_HEADLESS_EXTENSION_NAME)) {
    logger().error("the runtime does not offer XR_MND_headless, so a session needs a graphics binding. xr-probe only "
                   "supports headless runtimes for now (Monado, the test mock runtime); a Vulkan binding comes with "
                   "the engine");
    return kExitError;
  }
  // Opt-in: Debian's 1.0.20 core_validation layer predates XR_EXT_hand_tracking_data_source
  // and rejects its structs in a next chain.
  has_data_source_ext_ = args_.data_source && offered(XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME);
  if (args_.data_source && !has_data_source_ext_) {
    std::printf("(--data-source: XR_EXT_hand_tracking_data_source is not offered; continuing without it)\n");
  }

  std::vector<const char*> enabled = {XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME,
                                      XR_MND_HEADLESS_EXTENSION_NAME};
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
  std::printf("Runtime: %s %u.%u.%u\n", ip.runtimeName, XR_VERSION_MAJOR(ip.runtimeVersion),
              XR_VERSION_MINOR(ip.runtimeVersion), XR_VERSION_PATCH(ip.runtimeVersion));

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
  std::printf("System: %s (vendor %u)\n", sp.systemName, sp.vendorId);
  std::printf("supportsHandTracking: %s\n", ht.supportsHandTracking ? "true" : "false");
  if (has_data_source_ext_) std::printf("XR_EXT_hand_tracking_data_source: enabled\n");
  if (!ht.supportsHandTracking) {
    logger().error("the system reports supportsHandTracking = false: no hand tracker can be created. If Proprio's "
                   "layer is enabled, check its configuration and log ('proprio layer status')");
    return kExitNoHandTracking;
  }
  return kExitOk;
}

int Probe::create_session() {
  // XR_MND_headless: the primary view configuration is not used by a headless
  // session, so the probe does not ask for the list (the test mock runtime
  // does not implement xrEnumerateViewConfigurations, and Debian's 1.0.20
  // loader crashes on a function a runtime lacks).
  uint32_t n = 0;
  n = 0;
  if (ok(xrEnumerateEnvironmentBlendModes(instance_, system_, view_config_, 0, &n, nullptr),
         "xrEnumerateEnvironmentBlendModes") &&
      n > 0) {
    std::vector<XrEnvironmentBlendMode> modes(n);
    if (ok(xrEnumerateEnvironmentBlendModes(instance_, system_, view_config_, n, &n, modes.data()),
           "xrEnumerateEnvironmentBlendModes")) {
      blend_mode_ = modes.front();
    }
  }

  // Headless (XR_MND_headless): no graphics binding in the chain.
  auto sci = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  sci.systemId = system_;
  if (!ok(xrCreateSession(instance_, &sci, &session_), "xrCreateSession (headless)")) return kExitError;

  if (!wait_for_state(XR_SESSION_STATE_READY, 10.0)) {
    if (!g_sigint_stop.load()) logger().error("the session never became READY (last state {})", session_state_name(state_));
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
  std::printf("Headless session running; locating %s hand joints in %s space.\n\n", args_.hand.c_str(),
              args_.space.c_str());
  return kExitOk;
}

bool Probe::pump_events() {
  while (true) {
    auto ev = make<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
    const XrResult r = xrPollEvent(instance_, &ev);
    if (r == XR_EVENT_UNAVAILABLE) return true;
    if (!ok(r, "xrPollEvent")) return false;
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

XrTime Probe::now() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  XrTime t = 0;
  ok(convert_timespec_(instance_, &ts, &t), "xrConvertTimespecTimeToTimeKHR");
  return t;
}

void Probe::locate(HandProbe& h, XrTime t) {
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
    return;
  }
  ++h.window.locates;
  h.active = loc.isActive;
  if (!loc.isActive) {
    h.have_previous = false;
    return;
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
}

void Probe::report_second(double t_s, double window_s) {
  for (auto& h : hands_) {
    const HandWindow& w = h.window;
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
    h.total.locates += w.locates;
    h.total.distinct += w.distinct;
    h.total.active += w.active;
    h.total.fully_tracked_joints += w.fully_tracked_joints;
    h.total.joints += w.joints;
    h.window = {};
  }
  std::fflush(stdout);
}

int Probe::run() {
  if (int rc = create_instance(); rc != kExitOk) return rc;
  if (int rc = create_session(); rc != kExitOk) return rc;

  using clock = std::chrono::steady_clock;
  const auto start = clock::now();
  auto window_start = start, last_wait_return = start;
  std::uint64_t frames = 0;
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
    if (!ok(xrWaitFrame(session_, &fwi, &fs), "xrWaitFrame")) break;
    // A headless runtime may not block in xrWaitFrame: pace to its display period (or 90 Hz).
    const double period_s = fs.predictedDisplayPeriod > 0 ? static_cast<double>(fs.predictedDisplayPeriod) * 1e-9 : 1.0 / 90.0;
    const auto period = std::chrono::duration_cast<clock::duration>(std::chrono::duration<double>(period_s));
    if (frames > 0 && clock::now() - last_wait_return < period / 2) std::this_thread::sleep_until(last_wait_return + period);
    last_wait_return = clock::now();

    auto fbi = make<XrFrameBeginInfo>(XR_TYPE_FRAME_BEGIN_INFO);
    if (!ok(xrBeginFrame(session_, &fbi), "xrBeginFrame")) break;
    XrTime t = fs.predictedDisplayTime;
    if (t <= 0) {
      if (!zero_display_time_reported_) {
        std::printf("(the runtime's predictedDisplayTime is 0, as headless Monado does: locating at the current time)\n");
        zero_display_time_reported_ = true;
      }
      t = now();
    }
    for (auto& h : hands_) locate(h, t);
    auto fei = make<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
    fei.displayTime = t;
    fei.environmentBlendMode = blend_mode_;
    fei.layerCount = 0;
    if (!ok(xrEndFrame(session_, &fei), "xrEndFrame")) break;
    ++frames;

    const double window_s = std::chrono::duration<double>(clock::now() - window_start).count();
    if (window_s >= 1.0) {
      report_second(std::chrono::duration<double>(clock::now() - start).count(), window_s);
      window_start = clock::now();
    }
  }
  const double total_s = std::chrono::duration<double>(clock::now() - start).count();
  const double tail_s = std::chrono::duration<double>(clock::now() - window_start).count();
  if (tail_s > 0.2) report_second(total_s, tail_s);
  if (g_sigint_stop.load()) std::printf("\nInterrupted.\n");

  std::printf("\nSummary over %.1f s, %llu frames:\n", total_s, static_cast<unsigned long long>(frames));
  bool any_active = false;
  for (const auto& h : hands_) {
    const auto& t = h.total;
    any_active = any_active || t.active > 0;
    std::printf("  %-5s active in %llu of %llu locates, joints fully tracked %.1f%%, distinct data %.1f Hz\n", h.name,
                static_cast<unsigned long long>(t.active), static_cast<unsigned long long>(t.locates),
                t.joints ? 100.0 * static_cast<double>(t.fully_tracked_joints) / static_cast<double>(t.joints) : 0.0,
                total_s > 0 ? static_cast<double>(t.distinct) / total_s : 0.0);
  }
  teardown();
  if (!any_active) {
    std::printf("No hand was ever active. If Proprio's layer is meant to serve hands, check 'proprio layer status' "
                "and the app's log for the layer's messages.\n");
    return kExitNeverActive;
  }
  return kExitOk;
}

void Probe::teardown() {
  if (instance_ == XR_NULL_HANDLE) return;
  if (session_ != XR_NULL_HANDLE && session_running_) {
    // Ask the runtime to end the session, then follow its state changes to STOPPING.
    if (ok(xrRequestExitSession(session_), "xrRequestExitSession")) {
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
      ok(xrEndSession(session_), "xrEndSession");
      session_running_ = false;
    }
  }
  for (auto& h : hands_) {
    if (h.tracker != XR_NULL_HANDLE) {
      ok(destroy_hand_tracker_(h.tracker), "xrDestroyHandTrackerEXT");
      h.tracker = XR_NULL_HANDLE;
    }
  }
  if (space_ != XR_NULL_HANDLE) {
    ok(xrDestroySpace(space_), "xrDestroySpace");
    space_ = XR_NULL_HANDLE;
  }
  if (session_ != XR_NULL_HANDLE) {
    ok(xrDestroySession(session_), "xrDestroySession");
    session_ = XR_NULL_HANDLE;
  }
  ok(xrDestroyInstance(instance_), "xrDestroyInstance");
  instance_ = XR_NULL_HANDLE;
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
      "Be a minimal OpenXR app: through the system's OpenXR loader, open a headless session on the active runtime "
      "(XR_MND_headless), create hand trackers (XR_EXT_hand_tracking) and print once a second what they report: "
      "whether each hand is active, wrist and index-tip positions (mm), palm orientation, the share of joints with "
      "all location flags, how often joints were located and how often the data actually changed.\n"
      "Enabled API layers (Proprio's included, see 'proprio layer status') apply as for any app. Ctrl-C ends it "
      "cleanly.\n"
      "Exit status: 0 a hand was active, 1 error, 2 no hand tracking offered or supported, 3 no hand was ever "
      "active.");
  cmd->add_option("--seconds", args->seconds, "How long to run, s")->check(CLI::Range(0.0, 24.0 * 3600.0))->capture_default_str();
  cmd->add_option("--space", args->space, "Reference space to locate the joints in")
      ->check(CLI::IsMember({"view", "local", "stage"}))
      ->capture_default_str();
  cmd->add_option("--hand", args->hand, "Which hand trackers to create")
      ->check(CLI::IsMember({"left", "right", "both"}))
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
