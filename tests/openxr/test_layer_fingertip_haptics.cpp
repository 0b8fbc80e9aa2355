// XR_PROPRIO_fingertip_haptics through Debian's loader and the mock runtime
// (issue 29): an app that knows only the extension's header drives six
// emulated fingertip devices (the layer's haptics plugin, the real wire
// bytes, the device models' safety gates).
//
// Times checked here are the layer's own: each state carries the time of the
// 1 kHz tick that wrote it, which is the time the emulated device received
// that command. Rules on them ("zero at any tick a watchdog period after the
// last submission") hold however loaded the machine is; the latency figure is
// printed, and only bounded loosely (a stall must not make CI fail).
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "layer_app_util.hpp"
#include "mock_motion.hpp"
#include "proprio/core/xr_ext.hpp"
#include "proprio/core/xr_interop.hpp"
#include "proprio/openxr/XR_PROPRIO_fingertip_haptics.h"

using namespace proprio;
namespace mx = proprio::mock_xr;

namespace layer_fingertip_test {

constexpr const char* kConfig = R"([[source]]
type = "sim"
hands = ["left", "right"]
space = "local"
[haptics]
devices = "emulated"
model = "platform_3dof"
left = ["thumb", "index", "middle"]
right = ["thumb", "index", "middle"]
)";

// The app: instance, session (FOCUSED), LOCAL and VIEW spaces, the functions.
struct App {
  XrInstance instance = XR_NULL_HANDLE;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  XrSession session = XR_NULL_HANDLE;
  XrSpace local = XR_NULL_HANDLE, view = XR_NULL_HANDLE;
  XrSessionState state = XR_SESSION_STATE_UNKNOWN;
  PFN_xrCreateFingertipHapticsPROPRIO create = nullptr;
  PFN_xrDestroyFingertipHapticsPROPRIO destroy = nullptr;
  PFN_xrGetFingertipHapticsPropertiesPROPRIO properties = nullptr;
  PFN_xrApplyFingertipForcesPROPRIO apply = nullptr;
  PFN_xrGetFingertipHapticsStatePROPRIO get_state = nullptr;
  PFN_xrCreateHapticColliderPROPRIO create_collider = nullptr;

  template <typename F>
  void get(const char* name, F& fn) {
    PFN_xrVoidFunction f = nullptr;
    ASSERT_EQ(xrGetInstanceProcAddr(instance, name, &f), XR_SUCCESS) << name;
    fn = reinterpret_cast<F>(f);
  }

  void start(XrSystemFingertipHapticsPropertiesPROPRIO* props) {
    const char* exts[] = {XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_MND_HEADLESS_EXTENSION_NAME,
                          XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME};
    auto info = xr_struct<XrInstanceCreateInfo>(XR_TYPE_INSTANCE_CREATE_INFO);
    std::strcpy(info.applicationInfo.applicationName, "proprio fingertip haptics test");
    info.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
    info.enabledExtensionCount = 3;
    info.enabledExtensionNames = exts;
    ASSERT_EQ(xrCreateInstance(&info, &instance), XR_SUCCESS);
    auto getinfo = xr_struct<XrSystemGetInfo>(XR_TYPE_SYSTEM_GET_INFO);
    getinfo.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
    ASSERT_EQ(xrGetSystem(instance, &getinfo, &system), XR_SUCCESS);
    auto sys = xr_struct<XrSystemProperties>(XR_TYPE_SYSTEM_PROPERTIES);
    *props = xr_struct<XrSystemFingertipHapticsPropertiesPROPRIO>(XR_TYPE_SYSTEM_FINGERTIP_HAPTICS_PROPERTIES_PROPRIO);
    sys.next = props;
    ASSERT_EQ(xrGetSystemProperties(instance, system, &sys), XR_SUCCESS);
    ASSERT_EQ(sys.next, props) << "the app's chain is given back as it was";
    get("xrCreateFingertipHapticsPROPRIO", create);
    get("xrDestroyFingertipHapticsPROPRIO", destroy);
    get("xrGetFingertipHapticsPropertiesPROPRIO", properties);
    get("xrApplyFingertipForcesPROPRIO", apply);
    get("xrGetFingertipHapticsStatePROPRIO", get_state);
    get("xrCreateHapticColliderPROPRIO", create_collider);
    auto sinfo = xr_struct<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
    sinfo.systemId = system;
    ASSERT_EQ(xrCreateSession(instance, &sinfo, &session), XR_SUCCESS);
    for (auto [type, space] : {std::pair{XR_REFERENCE_SPACE_TYPE_LOCAL, &local}, std::pair{XR_REFERENCE_SPACE_TYPE_VIEW, &view}}) {
      auto space_info = xr_struct<XrReferenceSpaceCreateInfo>(XR_TYPE_REFERENCE_SPACE_CREATE_INFO);
      space_info.referenceSpaceType = type;
      space_info.poseInReferenceSpace = mx::kIdentityPose;
      ASSERT_EQ(xrCreateReferenceSpace(session, &space_info, space), XR_SUCCESS);
    }
    for (int i = 0; i < 200 && state != XR_SESSION_STATE_FOCUSED; ++i) frame();
    ASSERT_EQ(state, XR_SESSION_STATE_FOCUSED);
  }

  // Events (begin the session when READY), then one frame.
  void frame() {
    auto event = xr_struct<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
    while (xrPollEvent(instance, &event) == XR_SUCCESS) {
      if (event.type == XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED) {
        state = reinterpret_cast<const XrEventDataSessionStateChanged&>(event).state;
        if (state == XR_SESSION_STATE_READY) {
          auto begin = xr_struct<XrSessionBeginInfo>(XR_TYPE_SESSION_BEGIN_INFO);
          begin.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
          EXPECT_EQ(xrBeginSession(session, &begin), XR_SUCCESS);
        }
        if (state == XR_SESSION_STATE_STOPPING) {
          EXPECT_EQ(xrEndSession(session), XR_SUCCESS);
        }
      }
      event = xr_struct<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
    }
    if (state != XR_SESSION_STATE_READY && state != XR_SESSION_STATE_SYNCHRONIZED &&
        state != XR_SESSION_STATE_VISIBLE && state != XR_SESSION_STATE_FOCUSED) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      return;
    }
    auto wait = xr_struct<XrFrameWaitInfo>(XR_TYPE_FRAME_WAIT_INFO);
    auto fs = xr_struct<XrFrameState>(XR_TYPE_FRAME_STATE);
    if (xrWaitFrame(session, &wait, &fs) != XR_SUCCESS) return;
    auto begin = xr_struct<XrFrameBeginInfo>(XR_TYPE_FRAME_BEGIN_INFO);
    EXPECT_EQ(xrBeginFrame(session, &begin), XR_SUCCESS);
    auto fe = xr_struct<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
    fe.displayTime = fs.predictedDisplayTime;
    fe.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
    EXPECT_EQ(xrEndFrame(session, &fe), XR_SUCCESS);
  }

  XrFingertipHapticsStatePROPRIO read(XrFingertipHapticsPROPRIO h, XrHandEXT hand) {
    auto s = xr_struct<XrFingertipHapticsStatePROPRIO>(XR_TYPE_FINGERTIP_HAPTICS_STATE_PROPRIO);
    EXPECT_EQ(get_state(h, hand, &s), XR_SUCCESS);
    return s;
  }

  XrResult push(XrFingertipHapticsPROPRIO h, XrHandEXT hand, const XrVector3f& f, std::size_t finger,
                XrSpace base = XR_NULL_HANDLE, XrTime time = 0) {
    auto forces = xr_struct<XrFingertipForcesPROPRIO>(XR_TYPE_FINGERTIP_FORCES_PROPRIO);
    forces.hand = hand;
    forces.baseSpace = base;
    forces.time = time;
    forces.forces[finger] = f;
    return apply(h, &forces);
  }

  ~App() {
    if (instance != XR_NULL_HANDLE) xrDestroyInstance(instance);
  }
};

class LayerFingertipHaptics : public layer_test::LayerAppTest {};

TimeNs mono(XrTime t) { return mx::monotonic_ns_from_xr_time(t); }

TEST_F(LayerFingertipHaptics, WithoutAHapticsTableTheFeatureIsUnsupported) {
  use_config("[[source]]\ntype = \"sim\"\nspace = \"local\"\n");
  App app;
  XrSystemFingertipHapticsPropertiesPROPRIO props{};
  ASSERT_NO_FATAL_FAILURE(app.start(&props));
  EXPECT_EQ(props.supportsFingertipHaptics, XR_FALSE);
  auto info = xr_struct<XrFingertipHapticsCreateInfoPROPRIO>(XR_TYPE_FINGERTIP_HAPTICS_CREATE_INFO_PROPRIO);
  XrFingertipHapticsPROPRIO h = XR_NULL_HANDLE;
  EXPECT_EQ(app.create(app.session, &info, &h), XR_ERROR_FEATURE_UNSUPPORTED);
}

TEST_F(LayerFingertipHaptics, ForcesRampInFadeAndStopWhenTheSessionLosesFocus) {
  use_config(kConfig);
  App app;
  XrSystemFingertipHapticsPropertiesPROPRIO props{};
  ASSERT_NO_FATAL_FAILURE(app.start(&props));
  ASSERT_EQ(props.supportsFingertipHaptics, XR_TRUE);
  EXPECT_EQ(props.supportsContactSimulation, XR_TRUE);

  auto info = xr_struct<XrFingertipHapticsCreateInfoPROPRIO>(XR_TYPE_FINGERTIP_HAPTICS_CREATE_INFO_PROPRIO);
  XrFingertipHapticsPROPRIO h = XR_NULL_HANDLE;
  ASSERT_EQ(app.create(app.session, &info, &h), XR_SUCCESS);
  XrFingertipHapticsPROPRIO second = XR_NULL_HANDLE;
  EXPECT_EQ(app.create(app.session, &info, &second), XR_ERROR_LIMIT_REACHED) << "one per session";

  auto p = xr_struct<XrFingertipHapticsPropertiesPROPRIO>(XR_TYPE_FINGERTIP_HAPTICS_PROPERTIES_PROPRIO);
  ASSERT_EQ(app.properties(h, XR_HAND_RIGHT_EXT, &p), XR_SUCCESS);
  for (std::size_t f = 0; f < XR_FINGERTIP_COUNT_PROPRIO; ++f) {
    EXPECT_EQ(p.fingers[f].present, f <= XR_FINGERTIP_MIDDLE_PROPRIO ? XR_TRUE : XR_FALSE) << "finger " << f;
  }
  const XrFingertipDevicePropertiesPROPRIO& index = p.fingers[XR_FINGERTIP_INDEX_PROPRIO];
  EXPECT_EQ(index.forceDofCount, 3u);
  EXPECT_FLOAT_EQ(index.maxNormalForce, 1.5f) << "config/haptics/platform_3dof.toml";
  EXPECT_EQ(index.watchdogPeriod, 50 * kNsPerMillisecond);
  EXPECT_NE(std::string(index.deviceName).find("platform_3dof"), std::string::npos) << index.deviceName;

  // Above the device's limit: rendered at the limit once ramped in.
  const XrVector3f press{0.0f, 5.0f, 0.0f};
  TimeNs last_push = 0;
  const auto run_for = [&](double seconds) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (std::chrono::steady_clock::now() < end) {
      last_push = mono(mx::xr_time_now());
      EXPECT_EQ(app.push(h, XR_HAND_RIGHT_EXT, press, XR_FINGERTIP_INDEX_PROPRIO), XR_SUCCESS);
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  };
  run_for(0.8);  // the ramp-in is 0.4 s
  auto s = app.read(h, XR_HAND_RIGHT_EXT);
  EXPECT_EQ(s.fingers[XR_FINGERTIP_INDEX_PROPRIO].gateState, XR_FINGERTIP_GATE_STATE_ACTIVE_PROPRIO);
  EXPECT_NEAR(s.fingers[XR_FINGERTIP_INDEX_PROPRIO].commandedForce.y, 1.5, 1e-3) << "clamped to max_normal_n";
  EXPECT_GT(s.fingers[XR_FINGERTIP_INDEX_PROPRIO].measuredForce.y, 1.0) << "the emulated device's force sensor";
  EXPECT_EQ(s.fingers[XR_FINGERTIP_THUMB_PROPRIO].commandedForce.y, 0.0f) << "only the index was pushed";
  EXPECT_EQ(app.read(h, XR_HAND_LEFT_EXT).fingers[XR_FINGERTIP_INDEX_PROPRIO].commandedForce.y, 0.0f);

  // The app stops: every tick a watchdog period (50 ms) after the last push
  // commands nothing (the gate's 50 N/s rate limit may trail by 2 ms).
  int late_ticks = 0, nonzero_late = 0;
  const auto stop_end = std::chrono::steady_clock::now() + std::chrono::milliseconds(150);
  while (std::chrono::steady_clock::now() < stop_end) {
    s = app.read(h, XR_HAND_RIGHT_EXT);
    if (mono(s.time) >= last_push + 52 * kNsPerMillisecond) {
      ++late_ticks;
      nonzero_late += s.fingers[XR_FINGERTIP_INDEX_PROPRIO].commandedForce.y > 1e-4f;
    }
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
  EXPECT_GT(late_ticks, 10);
  EXPECT_EQ(nonzero_late, 0) << "a force not submitted again is zero within the watchdog period";

  // Latency: from the call to the first tick whose command carries it (the
  // emulated device receives the command at that tick's time).
  std::vector<double> latency_ms;
  for (int trial = 0; trial < 60; ++trial) {
    EXPECT_EQ(app.push(h, XR_HAND_RIGHT_EXT, {0, 0, 0}, XR_FINGERTIP_INDEX_PROPRIO), XR_SUCCESS);
    std::this_thread::sleep_for(std::chrono::milliseconds(6));
    const TimeNs t0 = mono(mx::xr_time_now());
    EXPECT_EQ(app.push(h, XR_HAND_RIGHT_EXT, {0, 1, 0}, XR_FINGERTIP_INDEX_PROPRIO), XR_SUCCESS);
    for (int spin = 0; spin < 20000; ++spin) {
      s = app.read(h, XR_HAND_RIGHT_EXT);
      if (mono(s.time) >= t0 && s.fingers[XR_FINGERTIP_INDEX_PROPRIO].commandedForce.y > 1e-3f) {
        latency_ms.push_back(static_cast<double>(mono(s.time) - t0) * 1e-6);
        break;
      }
      std::this_thread::sleep_for(std::chrono::microseconds(50));
    }
  }
  ASSERT_EQ(latency_ms.size(), 60u) << "every step reached the device";
  std::sort(latency_ms.begin(), latency_ms.end());
  const double p50 = latency_ms[latency_ms.size() / 2];
  const double p99 = latency_ms[latency_ms.size() * 99 / 100];
  std::printf("XR_PROPRIO_fingertip_haptics: submitted force to device command, %zu steps: p50 %.2f ms, p99 %.2f ms, "
              "max %.2f ms (target p99 <= 2 ms)\n",
              latency_ms.size(), p50, p99, latency_ms.back());
  EXPECT_LT(p50, 20.0) << "no frame of buffering between the call and the 1 kHz thread";

  // Focus lost: the session stops and the devices stop pressing at once,
  // whatever the app keeps submitting.
  ASSERT_EQ(xrRequestExitSession(app.session), XR_SUCCESS);
  for (int i = 0; i < 100 && app.state != XR_SESSION_STATE_STOPPING && app.state != XR_SESSION_STATE_IDLE; ++i) {
    EXPECT_EQ(app.push(h, XR_HAND_RIGHT_EXT, press, XR_FINGERTIP_INDEX_PROPRIO), XR_SUCCESS);
    app.frame();
  }
  const TimeNs unfocused = mono(mx::xr_time_now());
  int after = 0, pressing = 0;
  for (int i = 0; i < 100; ++i) {
    EXPECT_EQ(app.push(h, XR_HAND_RIGHT_EXT, press, XR_FINGERTIP_INDEX_PROPRIO), XR_SUCCESS);
    s = app.read(h, XR_HAND_RIGHT_EXT);
    if (mono(s.time) > unfocused + 2 * kNsPerMillisecond) {
      ++after;
      pressing += s.fingers[XR_FINGERTIP_INDEX_PROPRIO].commandedForce.y != 0.0f;
      EXPECT_EQ(s.fingers[XR_FINGERTIP_INDEX_PROPRIO].gateState, XR_FINGERTIP_GATE_STATE_OFF_PROPRIO);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_GT(after, 20);
  EXPECT_EQ(pressing, 0) << "no force once the session left FOCUSED";

  EXPECT_EQ(app.destroy(h), XR_SUCCESS);
  EXPECT_EQ(app.destroy(h), XR_ERROR_HANDLE_INVALID);
  EXPECT_EQ(app.push(h, XR_HAND_RIGHT_EXT, press, 1), XR_ERROR_HANDLE_INVALID) << "calls after destroy";
}

// Hostile app input (NaN, inf, huge, wrong hands, frames and times, calls
// after destroy): every call answers a defined code and no tick ever
// commands or measures more than the device's limits.
TEST_F(LayerFingertipHaptics, FuzzedForcesNeverExceedTheDeviceLimits) {
  use_config(kConfig);
  App app;
  XrSystemFingertipHapticsPropertiesPROPRIO props{};
  ASSERT_NO_FATAL_FAILURE(app.start(&props));
  auto info = xr_struct<XrFingertipHapticsCreateInfoPROPRIO>(XR_TYPE_FINGERTIP_HAPTICS_CREATE_INFO_PROPRIO);
  XrFingertipHapticsPROPRIO h = XR_NULL_HANDLE;
  ASSERT_EQ(app.create(app.session, &info, &h), XR_SUCCESS);
  auto p = xr_struct<XrFingertipHapticsPropertiesPROPRIO>(XR_TYPE_FINGERTIP_HAPTICS_PROPERTIES_PROPRIO);
  ASSERT_EQ(app.properties(h, XR_HAND_RIGHT_EXT, &p), XR_SUCCESS);
  const float max_normal = p.fingers[1].maxNormalForce, max_shear = p.fingers[1].maxShearForce;
  const float mu = p.fingers[1].frictionCoefficient;
  ASSERT_GT(max_normal, 0.0f);

  std::mt19937 rng(29);
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  const float specials[] = {0.0f, 1.0f, -1.0f, 1e30f, -1e30f, inf, -inf, nan, 3.0f, 1e-30f};
  const auto value = [&] {
    return rng() % 3 == 0 ? specials[rng() % std::size(specials)]
                          : std::uniform_real_distribution<float>(-20.0f, 20.0f)(rng);
  };
  int checked = 0, over = 0, rejected = 0;
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  while (std::chrono::steady_clock::now() < end) {
    auto forces = xr_struct<XrFingertipForcesPROPRIO>(XR_TYPE_FINGERTIP_FORCES_PROPRIO);
    const int hand_pick = static_cast<int>(rng() % 8);
    forces.hand = hand_pick == 0 ? static_cast<XrHandEXT>(7) : (hand_pick % 2 ? XR_HAND_LEFT_EXT : XR_HAND_RIGHT_EXT);
    bool finite = true;
    for (auto& f : forces.forces) {
      f = {value(), value(), value()};
      finite &= std::isfinite(f.x) && std::isfinite(f.y) && std::isfinite(f.z);
    }
    const int frame_pick = static_cast<int>(rng() % 4);
    forces.baseSpace = frame_pick == 0 ? app.local : frame_pick == 1 ? app.view : XR_NULL_HANDLE;
    forces.time = frame_pick <= 1 && rng() % 5 != 0 ? mx::xr_time_now() : -static_cast<XrTime>(rng() % 2);
    if (rng() % 20 == 0) forces.type = XR_TYPE_HAND_JOINT_LOCATIONS_EXT;  // the wrong struct
    const XrResult r = app.apply(h, &forces);
    const bool bad_struct = forces.type != XR_TYPE_FINGERTIP_FORCES_PROPRIO || hand_pick == 0;
    if (bad_struct) {
      EXPECT_EQ(r, XR_ERROR_VALIDATION_FAILURE);
    } else if (forces.baseSpace != XR_NULL_HANDLE && forces.time <= 0) {
      EXPECT_EQ(r, XR_ERROR_TIME_INVALID);
    } else {
      EXPECT_EQ(r, finite ? XR_SUCCESS : XR_ERROR_VALIDATION_FAILURE);
    }
    rejected += r != XR_SUCCESS;
    for (XrHandEXT hand : {XR_HAND_LEFT_EXT, XR_HAND_RIGHT_EXT}) {
      const auto s = app.read(h, hand);
      for (std::size_t f = 0; f <= XR_FINGERTIP_MIDDLE_PROPRIO; ++f) {
        for (const XrVector3f& v : {s.fingers[f].commandedForce, s.fingers[f].measuredForce}) {
          const double shear = std::hypot(v.x, v.z);
          const bool ok = std::isfinite(v.y) && v.y >= -1e-4 && v.y <= max_normal * 1.02 + 1e-4 &&
                          shear <= max_shear * 1.02 + 1e-4;
          over += !ok;
          ++checked;
        }
        const XrVector3f& c = s.fingers[f].commandedForce;
        over += std::hypot(c.x, c.z) > mu * c.y + 1e-4;
      }
    }
    std::this_thread::sleep_for(std::chrono::microseconds(300));
  }
  std::printf("fuzzed %d checks of commanded and measured forces, %d calls rejected\n", checked, rejected);
  EXPECT_GT(checked, 1000);
  EXPECT_GT(rejected, 50);
  EXPECT_EQ(over, 0) << "a device commanded or measured beyond its limits";

  // Colliders need the contact simulation; this handle was made without it.
  auto ci = xr_struct<XrHapticColliderCreateInfoPROPRIO>(XR_TYPE_HAPTIC_COLLIDER_CREATE_INFO_PROPRIO);
  ci.shape = XR_HAPTIC_COLLIDER_SHAPE_SPHERE_PROPRIO;
  ci.radius = 0.03f;
  ci.friction = 0.8f;
  ci.poseInfo = xr_struct<XrHapticColliderPoseInfoPROPRIO>(XR_TYPE_HAPTIC_COLLIDER_POSE_INFO_PROPRIO);
  ci.poseInfo.space = app.local;
  ci.poseInfo.time = mx::xr_time_now();
  ci.poseInfo.pose = mx::kIdentityPose;
  XrHapticColliderPROPRIO collider = XR_NULL_HANDLE;
  EXPECT_EQ(app.create_collider(h, &ci, &collider), XR_ERROR_FEATURE_UNSUPPORTED);
  EXPECT_EQ(app.destroy(h), XR_SUCCESS);
  auto again = xr_struct<XrFingertipForcesPROPRIO>(XR_TYPE_FINGERTIP_FORCES_PROPRIO);
  again.hand = XR_HAND_RIGHT_EXT;
  EXPECT_EQ(app.apply(h, &again), XR_ERROR_HANDLE_INVALID);
  auto st = xr_struct<XrFingertipHapticsStatePROPRIO>(XR_TYPE_FINGERTIP_HAPTICS_STATE_PROPRIO);
  EXPECT_EQ(app.get_state(h, XR_HAND_RIGHT_EXT, &st), XR_ERROR_HANDLE_INVALID);
}


// An app's vibrations on a hand path press that hand's fingertips (and still
// reach the runtime); the extension is used here only to read the devices.
TEST_F(LayerFingertipHaptics, VibrationOnAHandPathPressesThatHandsFingertips) {
  use_config(kConfig);
  App app;
  XrSystemFingertipHapticsPropertiesPROPRIO props{};
  ASSERT_NO_FATAL_FAILURE(app.start(&props));
  auto info = xr_struct<XrFingertipHapticsCreateInfoPROPRIO>(XR_TYPE_FINGERTIP_HAPTICS_CREATE_INFO_PROPRIO);
  XrFingertipHapticsPROPRIO h = XR_NULL_HANDLE;
  ASSERT_EQ(app.create(app.session, &info, &h), XR_SUCCESS);

  XrPath hands[2];
  ASSERT_EQ(xrStringToPath(app.instance, "/user/hand/left", &hands[0]), XR_SUCCESS);
  ASSERT_EQ(xrStringToPath(app.instance, "/user/hand/right", &hands[1]), XR_SUCCESS);
  auto set_info = xr_struct<XrActionSetCreateInfo>(XR_TYPE_ACTION_SET_CREATE_INFO);
  std::strcpy(set_info.actionSetName, "app");
  std::strcpy(set_info.localizedActionSetName, "app");
  XrActionSet set = XR_NULL_HANDLE;
  ASSERT_EQ(xrCreateActionSet(app.instance, &set_info, &set), XR_SUCCESS);
  auto action_info = xr_struct<XrActionCreateInfo>(XR_TYPE_ACTION_CREATE_INFO);
  std::strcpy(action_info.actionName, "buzz");
  std::strcpy(action_info.localizedActionName, "buzz");
  action_info.actionType = XR_ACTION_TYPE_VIBRATION_OUTPUT;
  action_info.countSubactionPaths = 2;
  action_info.subactionPaths = hands;
  XrAction buzz = XR_NULL_HANDLE;
  ASSERT_EQ(xrCreateAction(set, &action_info, &buzz), XR_SUCCESS);
  XrPath profile, outputs[2];
  ASSERT_EQ(xrStringToPath(app.instance, "/interaction_profiles/khr/simple_controller", &profile), XR_SUCCESS);
  ASSERT_EQ(xrStringToPath(app.instance, "/user/hand/left/output/haptic", &outputs[0]), XR_SUCCESS);
  ASSERT_EQ(xrStringToPath(app.instance, "/user/hand/right/output/haptic", &outputs[1]), XR_SUCCESS);
  const XrActionSuggestedBinding bindings[] = {{buzz, outputs[0]}, {buzz, outputs[1]}};
  auto suggest = xr_struct<XrInteractionProfileSuggestedBinding>(XR_TYPE_INTERACTION_PROFILE_SUGGESTED_BINDING);
  suggest.interactionProfile = profile;
  suggest.countSuggestedBindings = 2;
  suggest.suggestedBindings = bindings;
  ASSERT_EQ(xrSuggestInteractionProfileBindings(app.instance, &suggest), XR_SUCCESS);
  auto attach = xr_struct<XrSessionActionSetsAttachInfo>(XR_TYPE_SESSION_ACTION_SETS_ATTACH_INFO);
  attach.countActionSets = 1;
  attach.actionSets = &set;
  ASSERT_EQ(xrAttachSessionActionSets(app.session, &attach), XR_SUCCESS);
  const XrActiveActionSet active{set, XR_NULL_PATH};
  auto sync = xr_struct<XrActionsSyncInfo>(XR_TYPE_ACTIONS_SYNC_INFO);
  sync.countActiveActionSets = 1;
  sync.activeActionSets = &active;
  for (int i = 0; i < 5; ++i) {
    app.frame();
    EXPECT_TRUE(XR_SUCCEEDED(xrSyncActions(app.session, &sync)));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(450));  // the gates' ramp-in after focus

  auto haptic = xr_struct<XrHapticActionInfo>(XR_TYPE_HAPTIC_ACTION_INFO);
  haptic.action = buzz;
  haptic.subactionPath = hands[1];
  auto vibration = xr_struct<XrHapticVibration>(XR_TYPE_HAPTIC_VIBRATION);
  vibration.amplitude = 1.0f;
  vibration.duration = 2 * kNsPerSecond;
  vibration.frequency = XR_FREQUENCY_UNSPECIFIED;
  ASSERT_EQ(xrApplyHapticFeedback(app.session, &haptic, reinterpret_cast<const XrHapticBaseHeader*>(&vibration)),
            XR_SUCCESS);
  std::this_thread::sleep_for(std::chrono::milliseconds(150));
  const auto right = app.read(h, XR_HAND_RIGHT_EXT), left = app.read(h, XR_HAND_LEFT_EXT);
  for (std::size_t f = 0; f <= XR_FINGERTIP_MIDDLE_PROPRIO; ++f) {
    // amplitude 1 x vibration_gain 0.5 x 1.5 N
    EXPECT_NEAR(right.fingers[f].commandedForce.y, 0.75, 0.01) << "right finger " << f;
    EXPECT_EQ(left.fingers[f].commandedForce.y, 0.0f) << "left finger " << f;
  }
  ASSERT_EQ(xrStopHapticFeedback(app.session, &haptic), XR_SUCCESS);
  std::this_thread::sleep_for(std::chrono::milliseconds(60));  // 0.75 N down at 50 N/s: 15 ms
  EXPECT_EQ(app.read(h, XR_HAND_RIGHT_EXT).fingers[XR_FINGERTIP_INDEX_PROPRIO].commandedForce.y, 0.0f);
}

}  // namespace layer_fingertip_test
