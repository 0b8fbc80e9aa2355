#pragma once
// Shared by the loader tests that drive live sources through the layer
// (test_layer_live_gloves.cpp, test_layer_ftm.cpp): an unmodified headless app
// on Debian's loader and the mock runtime that locates one hand every frame,
// and the comparison of what it was served with an emulated wearer's truth.
// Needs the OpenXR loader and the mock runtime's headers (openxr_loader_tests).
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <initializer_list>
#include <string>
#include <vector>

#include "layer_test_util.hpp"
#include "mock_motion.hpp"
#include "proprio/core/xr_ext.hpp"
#include "proprio/core/xr_interop.hpp"
#include "proprio/openxr/XR_PROPRIO_hand_tracking_latency.h"

namespace layer_test {

// A test of an app on Debian's loader and the mock runtime with this build's
// layer, and a layer configuration written per test.
class LayerAppTest : public ::testing::Test {
 protected:
  void SetUp() override { use_mock_runtime_with_layer(dir_.path(), PROPRIO_MOCK_RUNTIME_JSON, PROPRIO_LAYER_MANIFEST_DIR); }
  void TearDown() override { ::unsetenv("PROPRIO_LAYER_CONFIG"); }
  void use_config(const std::string& text) {
    ::setenv("PROPRIO_LAYER_CONFIG", dir_.write("layer.toml", text).c_str(), 1);
  }
  TempDir dir_;
};

struct Sample {
  TimeNs t_ns = 0;
  std::array<Pose, kHandJointCount> T_local_joint;
};

// Every frame: when, and whether the hand was active.
struct Frame {
  TimeNs t_ns = 0;
  bool active = false;
};

// When the hand was inactive, as offsets (s) from the first frame.
inline std::vector<double> inactive_after_start(const std::vector<Frame>& frames) {
  std::vector<double> out;
  for (const Frame& f : frames) {
    if (!f.active) out.push_back(static_cast<double>(f.t_ns - frames.front().t_ns) * 1e-9);
  }
  return out;
}

// Runs a headless app for `seconds`, locating `hand` each frame in LOCAL;
// returns the frames whose wrist was fully located.
inline std::vector<Sample> run_app(Handedness hand, double seconds, XrHandTrackingLatencyPROPRIO* latency,
                                   std::vector<Frame>* frames = nullptr) {
  namespace mx = proprio::mock_xr;
  std::vector<Sample> samples;
  XrInstance instance = XR_NULL_HANDLE;
  const char* exts[] = {XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_MND_HEADLESS_EXTENSION_NAME,
                        XR_PROPRIO_HAND_TRACKING_LATENCY_EXTENSION_NAME};
  auto info = xr_struct<XrInstanceCreateInfo>(XR_TYPE_INSTANCE_CREATE_INFO);
  std::strcpy(info.applicationInfo.applicationName, "proprio live glove test");
  info.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
  info.enabledExtensionCount = 3;
  info.enabledExtensionNames = exts;
  EXPECT_EQ(xrCreateInstance(&info, &instance), XR_SUCCESS);
  if (instance == XR_NULL_HANDLE) return samples;
  auto getinfo = xr_struct<XrSystemGetInfo>(XR_TYPE_SYSTEM_GET_INFO);
  getinfo.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  EXPECT_EQ(xrGetSystem(instance, &getinfo, &system), XR_SUCCESS);
  auto sinfo = xr_struct<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  sinfo.systemId = system;
  XrSession session = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateSession(instance, &sinfo, &session), XR_SUCCESS);
  auto space_info = xr_struct<XrReferenceSpaceCreateInfo>(XR_TYPE_REFERENCE_SPACE_CREATE_INFO);
  space_info.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_LOCAL;
  space_info.poseInReferenceSpace = mx::kIdentityPose;
  XrSpace local = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateReferenceSpace(session, &space_info, &local), XR_SUCCESS);
  PFN_xrVoidFunction f = nullptr;
  EXPECT_EQ(xrGetInstanceProcAddr(instance, "xrCreateHandTrackerEXT", &f), XR_SUCCESS);
  auto create_tracker = reinterpret_cast<PFN_xrCreateHandTrackerEXT>(f);
  EXPECT_EQ(xrGetInstanceProcAddr(instance, "xrLocateHandJointsEXT", &f), XR_SUCCESS);
  auto locate = reinterpret_cast<PFN_xrLocateHandJointsEXT>(f);
  EXPECT_EQ(xrGetInstanceProcAddr(instance, "xrGetHandTrackingLatencyPROPRIO", &f), XR_SUCCESS);
  auto get_latency = reinterpret_cast<PFN_xrGetHandTrackingLatencyPROPRIO>(f);
  auto tinfo = xr_struct<XrHandTrackerCreateInfoEXT>(XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT);
  tinfo.hand = hand == Handedness::left ? XR_HAND_LEFT_EXT : XR_HAND_RIGHT_EXT;
  tinfo.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
  XrHandTrackerEXT tracker = XR_NULL_HANDLE;
  EXPECT_EQ(create_tracker(session, &tinfo, &tracker), XR_SUCCESS);

  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    auto event = xr_struct<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
    while (xrPollEvent(instance, &event) == XR_SUCCESS) {
      if (event.type == XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED &&
          reinterpret_cast<const XrEventDataSessionStateChanged&>(event).state == XR_SESSION_STATE_READY) {
        auto begin = xr_struct<XrSessionBeginInfo>(XR_TYPE_SESSION_BEGIN_INFO);
        begin.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
        EXPECT_EQ(xrBeginSession(session, &begin), XR_SUCCESS);
      }
      event = xr_struct<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
    }
    auto wait = xr_struct<XrFrameWaitInfo>(XR_TYPE_FRAME_WAIT_INFO);
    auto state = xr_struct<XrFrameState>(XR_TYPE_FRAME_STATE);
    if (xrWaitFrame(session, &wait, &state) != XR_SUCCESS) break;
    auto begin = xr_struct<XrFrameBeginInfo>(XR_TYPE_FRAME_BEGIN_INFO);
    EXPECT_EQ(xrBeginFrame(session, &begin), XR_SUCCESS);
    // Locate at "now", so the truth covers the time asked for.
    const XrTime t = mx::xr_time_now();
    std::array<XrHandJointLocationEXT, kHandJointCount> joints{};
    auto locs = xr_struct<XrHandJointLocationsEXT>(XR_TYPE_HAND_JOINT_LOCATIONS_EXT);
    locs.jointCount = kHandJointCount;
    locs.jointLocations = joints.data();
    auto li = xr_struct<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);
    li.baseSpace = local;
    li.time = t;
    EXPECT_EQ(locate(tracker, &li, &locs), XR_SUCCESS);
    if (frames) frames->push_back({mx::monotonic_ns_from_xr_time(t), locs.isActive == XR_TRUE});
    if (locs.isActive && joints[0].locationFlags == 0xFu) {
      Sample s;
      s.t_ns = mx::monotonic_ns_from_xr_time(t);
      for (std::size_t i = 0; i < kHandJointCount; ++i) s.T_local_joint[i] = from_xr(joints[i].pose);
      samples.push_back(s);
    }
    auto fe = xr_struct<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
    fe.displayTime = state.predictedDisplayTime;
    fe.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
    EXPECT_EQ(xrEndFrame(session, &fe), XR_SUCCESS);
  }
  if (latency) {
    *latency = xr_struct<XrHandTrackingLatencyPROPRIO>(XR_TYPE_HAND_TRACKING_LATENCY_PROPRIO);
    EXPECT_EQ(get_latency(tracker, latency), XR_SUCCESS);
  }
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);  // stops the sources: the truth file is complete
  return samples;
}

// Fingertips relative to the wrist, served vs true: mean error, metres, over
// `tips` (default: all five) of the served frames that have a truth row
// within 5 ms. `compared` counts the tips compared.
inline double fingertip_error_m(const std::vector<Sample>& served, const std::vector<HandPose>& truth,
                                std::size_t& compared,
                                std::initializer_list<HandJoint> tips = {HandJoint::thumb_tip, HandJoint::index_tip,
                                                                         HandJoint::middle_tip, HandJoint::ring_tip,
                                                                         HandJoint::little_tip}) {
  double sum = 0.0;
  compared = 0;
  for (const Sample& s : served) {
    const HandPose* t = nearest(truth, s.t_ns, 5 * kNsPerMillisecond);
    if (!t) continue;
    const Pose served_wrist = s.T_local_joint[index_of(HandJoint::wrist)];
    for (HandJoint tip : tips) {
      const Vec3 a = served_wrist.inverse() * s.T_local_joint[index_of(tip)].p;
      const Vec3 b = t->joint(HandJoint::wrist).inverse() * t->joint(tip).p;
      sum += (a - b).norm();
      ++compared;
    }
  }
  return compared ? sum / static_cast<double>(compared) : 1e9;
}

// The config keys that put a source's wrist on the mock's right-hand tracker:
// its tracker-to-wrist offset, as TOML lines.
inline std::string tracker_wrist_offset_toml() {
  namespace mx = proprio::mock_xr;
  const proprio::Pose T_tracker_wrist = proprio::from_xr(mx::to_xr(mx::tracker_to_wrist(mx::Hand::right)));
  const proprio::Vec3 r = proprio::so3_log(T_tracker_wrist.q) * (180.0 / M_PI);
  char offsets[256];
  std::snprintf(offsets, sizeof offsets,
                "wrist_offset_position_m = [%.9f, %.9f, %.9f]\nwrist_offset_rotation_deg = [%.9f, %.9f, %.9f]\n",
                T_tracker_wrist.p.x(), T_tracker_wrist.p.y(), T_tracker_wrist.p.z(), r.x(), r.y(), r.z());
  return offsets;
}

}  // namespace layer_test
