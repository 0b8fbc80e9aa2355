// The layer taking a glove's wrist from the runtime (docs/openxr-layer.md,
// "The wrist from the runtime"), through Debian's real loader on the mock
// runtime, whose devices move analytically (mock_motion.hpp): every expected
// value is computed from that truth, never from what the layer reports.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <thread>

#include "layer_app_util.hpp"
#include "mock_motion.hpp"
#include "proprio/core/xr_ext.hpp"
#include "proprio/core/xr_interop.hpp"
#include "proprio/openxr/XR_PROPRIO_hand_tracking_latency.h"

using namespace proprio;
using layer_test::TempDir;
namespace mx = proprio::mock_xr;

namespace wrist_test {

#ifndef XR_OK
#define XR_OK(call) ASSERT_EQ((call), XR_SUCCESS) << #call
#endif

mx::Hand mock_hand(Handedness h) { return h == Handedness::left ? mx::Hand::left : mx::Hand::right; }
Pose truth(const mx::Pose& p) { return from_xr(mx::to_xr(p)); }

// "[a, b, c]" for a TOML array.
std::string triple(const Vec3& v) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "[%.9f, %.9f, %.9f]", v.x(), v.y(), v.z());
  return buf;
}

// One replay source per hand (still recorded hands), each with its own wrist offset.
std::string wrist_sources(const std::string& recording, const std::string& wrist,
                          const std::array<Pose, 2>& T_device_wrist) {
  std::string s;
  for (Handedness h : {Handedness::left, Handedness::right}) {
    const Pose& T = T_device_wrist[static_cast<std::size_t>(h)];
    s += "[[source]]\ntype = \"replay\"\nspace = \"local\"\nhands = [\"" + std::string(to_string(h)) + "\"]\npath = \"" +
         recording + "\"\nwrist = \"" + wrist + "\"\n";
    if (wrist == "controller" || wrist == "tracker") {
      s += "wrist_offset_position_m = " + triple(T.p) + "\nwrist_offset_rotation_deg = " +
           triple(so3_log(T.q) * (180.0 / M_PI)) + "\n";
    }
  }
  return s;
}

// An app with a headless session, a LOCAL space and a hand tracker per hand;
// optionally its own actions (a select button and the grip pose per hand).
struct WristApp {
  XrInstance instance = XR_NULL_HANDLE;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  XrSession session = XR_NULL_HANDLE;
  XrSpace local = XR_NULL_HANDLE;
  std::array<XrHandTrackerEXT, 2> trackers{};
  PFN_xrLocateHandJointsEXT locate = nullptr;
  XrActionSet set = XR_NULL_HANDLE;
  XrAction select = XR_NULL_HANDLE, grip = XR_NULL_HANDLE;
  std::array<XrPath, 2> hand_paths{};
  std::array<XrSpace, 2> grip_spaces{};
  std::vector<XrStructureType> events_seen;

  ~WristApp() {
    if (instance != XR_NULL_HANDLE) {
      EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
    }
  }
  void create(std::vector<const char*> extensions) {
    extensions.push_back(XR_EXT_HAND_TRACKING_EXTENSION_NAME);
    extensions.push_back(XR_MND_HEADLESS_EXTENSION_NAME);
    auto info = xr_struct<XrInstanceCreateInfo>(XR_TYPE_INSTANCE_CREATE_INFO);
    std::strcpy(info.applicationInfo.applicationName, "proprio wrist test");
    info.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
    info.enabledExtensionCount = static_cast<uint32_t>(extensions.size());
    info.enabledExtensionNames = extensions.data();
    XR_OK(xrCreateInstance(&info, &instance));
    auto getinfo = xr_struct<XrSystemGetInfo>(XR_TYPE_SYSTEM_GET_INFO);
    getinfo.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
    XR_OK(xrGetSystem(instance, &getinfo, &system));
    auto sinfo = xr_struct<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
    sinfo.systemId = system;
    XR_OK(xrCreateSession(instance, &sinfo, &session));
    auto space = xr_struct<XrReferenceSpaceCreateInfo>(XR_TYPE_REFERENCE_SPACE_CREATE_INFO);
    space.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_LOCAL;
    space.poseInReferenceSpace = mx::kIdentityPose;
    XR_OK(xrCreateReferenceSpace(session, &space, &local));
    PFN_xrVoidFunction f = nullptr;
    XR_OK(xrGetInstanceProcAddr(instance, "xrCreateHandTrackerEXT", &f));
    auto create_tracker = reinterpret_cast<PFN_xrCreateHandTrackerEXT>(f);
    XR_OK(xrGetInstanceProcAddr(instance, "xrLocateHandJointsEXT", &f));
    locate = reinterpret_cast<PFN_xrLocateHandJointsEXT>(f);
    for (XrHandEXT hand : {XR_HAND_LEFT_EXT, XR_HAND_RIGHT_EXT}) {
      auto tinfo = xr_struct<XrHandTrackerCreateInfoEXT>(XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT);
      tinfo.hand = hand;
      tinfo.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
      XR_OK(create_tracker(session, &tinfo, &trackers[hand == XR_HAND_LEFT_EXT ? 0 : 1]));
    }
  }
  // The app's own input, as an engine sets it up: suggest, create spaces, attach.
  void add_actions() {
    XR_OK(xrStringToPath(instance, "/user/hand/left", &hand_paths[0]));
    XR_OK(xrStringToPath(instance, "/user/hand/right", &hand_paths[1]));
    auto set_info = xr_struct<XrActionSetCreateInfo>(XR_TYPE_ACTION_SET_CREATE_INFO);
    std::strcpy(set_info.actionSetName, "gameplay");
    std::strcpy(set_info.localizedActionSetName, "Gameplay");
    XR_OK(xrCreateActionSet(instance, &set_info, &set));
    auto action = [&](const char* name, XrActionType type, XrAction& out) {
      auto info = xr_struct<XrActionCreateInfo>(XR_TYPE_ACTION_CREATE_INFO);
      std::strcpy(info.actionName, name);
      std::strcpy(info.localizedActionName, name);
      info.actionType = type;
      info.countSubactionPaths = 2;
      info.subactionPaths = hand_paths.data();
      ASSERT_EQ(xrCreateAction(set, &info, &out), XR_SUCCESS) << name;
    };
    action("select", XR_ACTION_TYPE_BOOLEAN_INPUT, select);
    action("grip", XR_ACTION_TYPE_POSE_INPUT, grip);
    XrPath profile, paths[4];
    XR_OK(xrStringToPath(instance, "/interaction_profiles/khr/simple_controller", &profile));
    XR_OK(xrStringToPath(instance, "/user/hand/left/input/select/click", &paths[0]));
    XR_OK(xrStringToPath(instance, "/user/hand/right/input/select/click", &paths[1]));
    XR_OK(xrStringToPath(instance, "/user/hand/left/input/grip/pose", &paths[2]));
    XR_OK(xrStringToPath(instance, "/user/hand/right/input/grip/pose", &paths[3]));
    XrActionSuggestedBinding bindings[] = {{select, paths[0]}, {select, paths[1]}, {grip, paths[2]}, {grip, paths[3]}};
    auto suggested = xr_struct<XrInteractionProfileSuggestedBinding>(XR_TYPE_INTERACTION_PROFILE_SUGGESTED_BINDING);
    suggested.interactionProfile = profile;
    suggested.countSuggestedBindings = 4;
    suggested.suggestedBindings = bindings;
    XR_OK(xrSuggestInteractionProfileBindings(instance, &suggested));
    for (int h = 0; h < 2; ++h) {
      auto info = xr_struct<XrActionSpaceCreateInfo>(XR_TYPE_ACTION_SPACE_CREATE_INFO);
      info.action = grip;
      info.subactionPath = hand_paths[h];
      info.poseInActionSpace = mx::kIdentityPose;
      XR_OK(xrCreateActionSpace(session, &info, &grip_spaces[h]));
    }
    auto attach = xr_struct<XrSessionActionSetsAttachInfo>(XR_TYPE_SESSION_ACTION_SETS_ATTACH_INFO);
    attach.countActionSets = 1;
    attach.actionSets = &set;
    XR_OK(xrAttachSessionActionSets(session, &attach));
  }
  void pump() {
    auto event = xr_struct<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
    while (xrPollEvent(instance, &event) == XR_SUCCESS) {
      events_seen.push_back(event.type);
      if (event.type == XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED &&
          reinterpret_cast<const XrEventDataSessionStateChanged&>(event).state == XR_SESSION_STATE_READY) {
        auto begin = xr_struct<XrSessionBeginInfo>(XR_TYPE_SESSION_BEGIN_INFO);
        begin.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
        EXPECT_EQ(xrBeginSession(session, &begin), XR_SUCCESS);
      }
      event = xr_struct<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
    }
  }
  void frame() {
    pump();
    auto wait = xr_struct<XrFrameWaitInfo>(XR_TYPE_FRAME_WAIT_INFO);
    auto state = xr_struct<XrFrameState>(XR_TYPE_FRAME_STATE);
    ASSERT_EQ(xrWaitFrame(session, &wait, &state), XR_SUCCESS);
    auto begin = xr_struct<XrFrameBeginInfo>(XR_TYPE_FRAME_BEGIN_INFO);
    ASSERT_EQ(xrBeginFrame(session, &begin), XR_SUCCESS);
    auto end = xr_struct<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
    end.displayTime = state.predictedDisplayTime;
    end.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
    ASSERT_EQ(xrEndFrame(session, &end), XR_SUCCESS);
  }
  XrResult sync() {
    XrActiveActionSet active{set, XR_NULL_PATH};
    auto info = xr_struct<XrActionsSyncInfo>(XR_TYPE_ACTIONS_SYNC_INFO);
    info.countActiveActionSets = 1;
    info.activeActionSets = &active;
    return xrSyncActions(session, &info);
  }
};

struct WristJoints {
  std::array<XrHandJointLocationEXT, kHandJointCount> joints{};
  XrHandJointLocationsEXT locations = xr_struct<XrHandJointLocationsEXT>(XR_TYPE_HAND_JOINT_LOCATIONS_EXT);
  XrResult from(const WristApp& app, Handedness hand, XrTime time) {
    locations.jointCount = kHandJointCount;
    locations.jointLocations = joints.data();
    auto info = xr_struct<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);
    info.baseSpace = app.local;
    info.time = time;
    return app.locate(app.trackers[static_cast<std::size_t>(hand)], &info, &locations);
  }
  Pose joint(std::size_t i) const { return from_xr(joints[i].pose); }
};

// The recorded fingers, put on a wrist: what the layer must serve.
void expect_hand_on_wrist(const WristJoints& out, Handedness hand, const Pose& T_local_wrist, double tolerance_m,
                          const std::string& where) {
  const HandPose rec = layer_test::recorded_pose(hand, 0);
  const Pose T_local_source = T_local_wrist * rec.joint(HandJoint::wrist).inverse();
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    const Pose expected = T_local_source * rec.T_world_joint[i];
    EXPECT_LT((out.joint(i).p - expected.p).norm(), tolerance_m) << where << " " << to_string(joint_at(i));
    EXPECT_LT(angle_between(out.joint(i).q, expected.q), 1e-3) << where << " " << to_string(joint_at(i));
  }
}

class LayerWrist : public layer_test::LayerAppTest {
 protected:
  void SetUp() override {
    LayerAppTest::SetUp();
    recording_ = layer_test::write_still_recording(dir_.path(), 60 * kNsPerSecond).string();
  }
  std::string recording_;
};

TEST_F(LayerWrist, AControllerWristRidesAlongWithTheAppsOwnActions) {
  // The true wrist is the grip pose composed with the inverse of the mock's wrist-to-grip offset.
  use_config(wrist_sources(recording_, "controller",
                           {truth(mx::inverse(mx::wrist_to_grip(mx::Hand::left))),
                            truth(mx::inverse(mx::wrist_to_grip(mx::Hand::right)))}));
  WristApp app;
  app.create({});
  app.add_actions();
  int checked = 0, select_checked = 0;
  for (int frame = 0; frame < 60; ++frame) {
    app.frame();
    const XrTime before = mx::xr_time_now();
    const XrResult synced = app.sync();
    const XrTime after = mx::xr_time_now();
    if (synced != XR_SUCCESS) continue;  // not focused yet
    for (Handedness hand : {Handedness::left, Handedness::right}) {
      const auto h = static_cast<std::size_t>(hand);
      // The app's own actions read as they would without the layer.
      auto get = xr_struct<XrActionStateGetInfo>(XR_TYPE_ACTION_STATE_GET_INFO);
      get.action = app.select;
      get.subactionPath = app.hand_paths[h];
      auto state = xr_struct<XrActionStateBoolean>(XR_TYPE_ACTION_STATE_BOOLEAN);
      XR_OK(xrGetActionStateBoolean(app.session, &get, &state));
      EXPECT_TRUE(state.isActive);
      if (mx::select_pressed(mock_hand(hand), before) == mx::select_pressed(mock_hand(hand), after)) {
        EXPECT_EQ(state.currentState == XR_TRUE, mx::select_pressed(mock_hand(hand), before)) << "frame " << frame;
        ++select_checked;
      }
      const XrTime t = mx::xr_time_now();
      auto loc = xr_struct<XrSpaceLocation>(XR_TYPE_SPACE_LOCATION);
      XR_OK(xrLocateSpace(app.grip_spaces[h], app.local, t, &loc));
      ASSERT_EQ(loc.locationFlags & 0xF, 0xFu) << "the app's grip pose is tracked";
      EXPECT_LT((from_xr(loc.pose).p - truth(mx::controller_grip(mock_hand(hand), t).pose).p).norm(), 1e-5);

      WristJoints out;
      XR_OK(out.from(app, hand, t));
      ASSERT_TRUE(out.locations.isActive) << to_string(hand) << " frame " << frame;
      EXPECT_EQ(out.joints[0].locationFlags, 0xFu);
      expect_hand_on_wrist(out, hand, truth(mx::wrist_pose(mock_hand(hand), t).pose), 1e-4,
                           std::string(to_string(hand)) + " frame " + std::to_string(frame));
      ++checked;
    }
  }
  EXPECT_GT(checked, 40) << "the session reached FOCUSED and the hands were checked";
  EXPECT_GT(select_checked, 40);
}

TEST_F(LayerWrist, ATrackerWristWorksForAnAppWithoutActionsOrTheTrackerExtension) {
  use_config(wrist_sources(recording_, "tracker",
                           {truth(mx::tracker_to_wrist(mx::Hand::left)), truth(mx::tracker_to_wrist(mx::Hand::right))}));
  WristApp app;
  app.create({});  // no XR_HTCX_vive_tracker_interaction, no actions: the layer attaches its own after 90 frames
  int checked = 0;
  for (int frame = 0; frame < 130; ++frame) {
    app.frame();
    if (frame < 95) continue;
    const XrTime t = mx::xr_time_now();
    for (Handedness hand : {Handedness::left, Handedness::right}) {
      WristJoints out;
      XR_OK(out.from(app, hand, t));
      ASSERT_TRUE(out.locations.isActive) << to_string(hand) << " frame " << frame;
      expect_hand_on_wrist(out, hand, truth(mx::wrist_pose(mock_hand(hand), t).pose), 1e-4,
                           std::string(to_string(hand)) + " frame " + std::to_string(frame));
      ++checked;
    }
  }
  EXPECT_EQ(checked, 70);
  for (XrStructureType type : app.events_seen) {
    EXPECT_NE(type, XR_TYPE_EVENT_DATA_VIVE_TRACKER_CONNECTED_HTCX) << "an event of an extension the app did not enable";
  }
}

TEST_F(LayerWrist, ALostTrackerHoldsTheLastWristUntrackedThenTheHandGoesInactive) {
  ::setenv("PROPRIO_MOCK_RUNTIME_DISCONNECT", "right_tracker:1.5-60", 1);
  use_config("[layer]\nstale_timeout_ms = 300\n" +
             wrist_sources(recording_, "tracker",
                           {truth(mx::tracker_to_wrist(mx::Hand::left)), truth(mx::tracker_to_wrist(mx::Hand::right))}));
  WristApp app;
  app.create({});
  app.add_actions();
  XrTime last_tracked = 0;
  for (int frame = 0; frame < 400 && last_tracked == 0; ++frame) {
    app.frame();
    if (app.sync() != XR_SUCCESS) continue;
    WristJoints out, other;
    const XrTime t = mx::xr_time_now();
    XR_OK(other.from(app, Handedness::left, t));  // keeps the left replay streaming
    XR_OK(out.from(app, Handedness::right, t));
    if (out.locations.isActive && out.joints[0].locationFlags == 0xFu) continue;
    // The first untracked answer: the tracker just went.
    ASSERT_TRUE(out.locations.isActive) << "held first, not dropped at once";
    EXPECT_EQ(out.joints[0].locationFlags, 0x3u) << "valid, not tracked";
    last_tracked = t;
  }
  ASSERT_NE(last_tracked, 0) << "the scripted disconnect never showed";
  for (const XrTime until = mx::xr_time_now() + 450'000'000; mx::xr_time_now() < until;) {
    app.frame();
    ASSERT_EQ(app.sync(), XR_SUCCESS);
    WristJoints other;
    XR_OK(other.from(app, Handedness::left, mx::xr_time_now()));
  }
  WristJoints gone;
  XR_OK(gone.from(app, Handedness::right, mx::xr_time_now()));
  EXPECT_FALSE(gone.locations.isActive) << "past stale_timeout_ms the hand is inactive";
  WristJoints left;
  XR_OK(left.from(app, Handedness::left, mx::xr_time_now()));
  EXPECT_TRUE(left.locations.isActive) << "the other hand's tracker is still there";
}

TEST_F(LayerWrist, TheRuntimesOwnHandGivesTheWristAndTheGloveKeepsTheFingersWhenItIsLost) {
  ::setenv("PROPRIO_MOCK_RUNTIME_HAND_TRACKING", "moving", 1);
  use_config("[layer]\nstale_timeout_ms = 1000\n" + wrist_sources(recording_, "runtime_hand", {}));
  WristApp app;
  app.create({});
  // Wait for the right hand's next lost window (0.5 s of every 4 s) to begin.
  const auto hand = mx::Hand::right;
  XrTime now = mx::xr_time_now();
  XrTime lost_at = now;
  while (mx::native_hand_tracked(hand, lost_at) || lost_at - now < 200'000'000) lost_at += 5'000'000;
  // Tracked just before it: the runtime's wrist, tracked.
  const XrTime before = lost_at - 100'000'000;
  // The runtime tracks hands only in a running session; the replay streams while it is asked.
  while (mx::xr_time_now() < lost_at + 150'000'000) {
    app.frame();
    WristJoints warm;
    XR_OK(warm.from(app, Handedness::right, mx::xr_time_now()));
  }
  WristJoints tracked;
  XR_OK(tracked.from(app, Handedness::right, before));
  ASSERT_TRUE(tracked.locations.isActive);
  EXPECT_EQ(tracked.joints[0].locationFlags, 0xFu);
  expect_hand_on_wrist(tracked, Handedness::right, truth(mx::wrist_pose(hand, before).pose), 1e-4, "tracked");
  // Inside the window: the glove's fingers on the last wrist, valid but not tracked.
  const XrTime during = lost_at + 100'000'000;
  ASSERT_FALSE(mx::native_hand_tracked(hand, during));
  WristJoints held;
  XR_OK(held.from(app, Handedness::right, during));
  ASSERT_TRUE(held.locations.isActive) << "the glove keeps the fingers while the camera lost the hand";
  EXPECT_EQ(held.joints[0].locationFlags, 0x3u);
  expect_hand_on_wrist(held, Handedness::right, truth(mx::wrist_pose(hand, before).pose), 1e-4, "held");
}

TEST_F(LayerWrist, LatencyHistogramsCountEveryServedPose) {
  use_config("[[source]]\ntype = \"sim\"\nspace = \"local\"\nrate_hz = 200\n");
  WristApp app;
  app.create({XR_PROPRIO_HAND_TRACKING_LATENCY_EXTENSION_NAME});
  PFN_xrVoidFunction f = nullptr;
  XR_OK(xrGetInstanceProcAddr(app.instance, "xrGetHandTrackingLatencyPROPRIO", &f));
  auto get_latency = reinterpret_cast<PFN_xrGetHandTrackingLatencyPROPRIO>(f);
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  std::uint64_t active = 0;
  for (int k = 0; k < 20; ++k) {
    WristJoints out;
    XR_OK(out.from(app, Handedness::left, mx::xr_time_now()));
    active += out.locations.isActive ? 1 : 0;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  auto l = xr_struct<XrHandTrackingLatencyPROPRIO>(XR_TYPE_HAND_TRACKING_LATENCY_PROPRIO);
  XR_OK(get_latency(app.trackers[0], &l));
  EXPECT_GT(active, 0u);
  EXPECT_EQ(l.poseCount, active);
  EXPECT_EQ(l.binCount, static_cast<uint32_t>(XR_PROPRIO_LATENCY_BIN_COUNT));
  EXPECT_FLOAT_EQ(l.binWidthMs, 0.5f);
  std::uint64_t ready = 0, age = 0;
  for (uint32_t i = 0; i < l.binCount; ++i) ready += l.sampleToReady[i], age += l.ageAtLocate[i];
  EXPECT_EQ(ready, active);
  EXPECT_EQ(age, active);
  EXPECT_GE(l.maxAgeAtLocateMs, 0.0f);
  auto wrong = xr_struct<XrHandTrackingLatencyPROPRIO>(XR_TYPE_HAND_JOINT_LOCATIONS_EXT);
  EXPECT_EQ(get_latency(app.trackers[0], &wrong), XR_ERROR_VALIDATION_FAILURE);
  EXPECT_EQ(get_latency(app.trackers[0], nullptr), XR_ERROR_VALIDATION_FAILURE);
}

TEST_F(LayerWrist, TheLatencyFunctionNeedsTheExtension) {
  use_config("[[source]]\ntype = \"sim\"\nspace = \"local\"\n");
  WristApp app;
  app.create({});
  PFN_xrVoidFunction f = nullptr;
  EXPECT_EQ(xrGetInstanceProcAddr(app.instance, "xrGetHandTrackingLatencyPROPRIO", &f), XR_ERROR_FUNCTION_UNSUPPORTED);
  EXPECT_EQ(f, nullptr);
}

}  // namespace wrist_test
