// Smoke tests of the mock OpenXR runtime, driven through Debian's real OpenXR
// loader (XR_RUNTIME_JSON), and once more under Debian's core_validation layer.
// They also pin down mock_motion.hpp, which layer tests use for expectations.
#include "mock_motion.hpp"
#include "test_support.hpp"

#include <proprio/openxr_layer/loader_interfaces.hpp>

// Vulkan's headers only (VK_NO_PROTOTYPES): the structures of XR_KHR_vulkan_enable2.
#include <vulkan/vulkan.h>

#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>

#include <gtest/gtest.h>

#include <dlfcn.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <numbers>
#include <optional>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>

namespace {
namespace mx = proprio::mock_xr;
using namespace proprio::mock_xr::test;  // NOLINT(google-build-using-namespace): test helpers

// Every test runs against the mock runtime, with no layer unless it asks.
class MockRuntime : public ::testing::Test {
 protected:
  ScopedEnv runtime_{"XR_RUNTIME_JSON", PROPRIO_MOCK_RUNTIME_JSON};
  ScopedEnv layers_{"XR_ENABLE_API_LAYERS", nullptr};
  ScopedEnv hand_tracking_{"PROPRIO_MOCK_RUNTIME_HAND_TRACKING", nullptr};
  ScopedEnv monado_headless_{"PROPRIO_MOCK_RUNTIME_MONADO_HEADLESS", nullptr};
  ScopedEnv controllers_{"PROPRIO_MOCK_RUNTIME_CONTROLLERS", nullptr};
  ScopedEnv trackers_{"PROPRIO_MOCK_RUNTIME_TRACKERS", nullptr};
  ScopedEnv disconnect_{"PROPRIO_MOCK_RUNTIME_DISCONNECT", nullptr};
  ScopedEnv unfocus_{"PROPRIO_MOCK_RUNTIME_UNFOCUS_AFTER_FRAMES", nullptr};
};

void expect_near(const XrVector3f& a, const XrVector3f& b, float tol = 1e-5f) {
  EXPECT_NEAR(a.x, b.x, tol);
  EXPECT_NEAR(a.y, b.y, tol);
  EXPECT_NEAR(a.z, b.z, tol);
}
void expect_near(const XrPosef& a, const XrPosef& b, float tol = 1e-5f) {
  expect_near(a.position, b.position, tol);
  const XrQuaternionf &p = a.orientation, &q = b.orientation;
  const float dot = p.x * q.x + p.y * q.y + p.z * q.z + p.w * q.w;
  EXPECT_NEAR(std::abs(dot), 1.0f, tol) << "orientations differ";
}

// What a correct headless app does from start to end; asserts along the way.
void run_headless_app() {
  const auto extensions = instance_extensions();
  for (const char* wanted : {XR_MND_HEADLESS_EXTENSION_NAME, XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME}) {
    EXPECT_NE(std::find(extensions.begin(), extensions.end(), wanted), extensions.end()) << wanted;
  }
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME, XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME}, &instance),
            XR_SUCCESS);
  auto properties = make<XrInstanceProperties>(XR_TYPE_INSTANCE_PROPERTIES);
  ASSERT_EQ(xrGetInstanceProperties(instance, &properties), XR_SUCCESS);
  EXPECT_STREQ(properties.runtimeName, "Proprio mock runtime");

  auto system_info = make<XrSystemGetInfo>(XR_TYPE_SYSTEM_GET_INFO);
  system_info.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  ASSERT_EQ(xrGetSystem(instance, &system_info, &system), XR_SUCCESS);
  EXPECT_EQ(system, 1u);
  auto system_properties = make<XrSystemProperties>(XR_TYPE_SYSTEM_PROPERTIES);
  ASSERT_EQ(xrGetSystemProperties(instance, system, &system_properties), XR_SUCCESS);

  auto session_info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  session_info.systemId = system;
  XrSession session = XR_NULL_HANDLE;
  ASSERT_EQ(xrCreateSession(instance, &session_info, &session), XR_SUCCESS);
  EXPECT_EQ(drain_states(instance), (std::vector{XR_SESSION_STATE_IDLE, XR_SESSION_STATE_READY}));
  auto begin_info = make<XrSessionBeginInfo>(XR_TYPE_SESSION_BEGIN_INFO);
  begin_info.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  ASSERT_EQ(xrBeginSession(session, &begin_info), XR_SUCCESS);
  EXPECT_EQ(drain_states(instance),
            (std::vector{XR_SESSION_STATE_SYNCHRONIZED, XR_SESSION_STATE_VISIBLE, XR_SESSION_STATE_FOCUSED}));

  // "Now" as the architecture says: monotonic time through the extension.
  auto to_xr_time = get_proc<PFN_xrConvertTimespecTimeToTimeKHR>(instance, "xrConvertTimespecTimeToTimeKHR");
  auto to_timespec = get_proc<PFN_xrConvertTimeToTimespecTimeKHR>(instance, "xrConvertTimeToTimespecTimeKHR");
  ASSERT_TRUE(to_xr_time && to_timespec);
  timespec now_ts{};
  clock_gettime(CLOCK_MONOTONIC, &now_ts);
  XrTime now = 0;
  ASSERT_EQ(to_xr_time(instance, &now_ts, &now), XR_SUCCESS);
  EXPECT_EQ(now, mx::xr_time_from_monotonic_ns(int64_t{now_ts.tv_sec} * 1'000'000'000 + now_ts.tv_nsec));
  timespec back{};
  ASSERT_EQ(to_timespec(instance, now, &back), XR_SUCCESS);
  EXPECT_EQ(back.tv_sec, now_ts.tv_sec);
  EXPECT_EQ(back.tv_nsec, now_ts.tv_nsec);

  const XrSpace local = create_space(session, XR_REFERENCE_SPACE_TYPE_LOCAL);
  const XrSpace view = create_space(session, XR_REFERENCE_SPACE_TYPE_VIEW);
  const XrSpace stage = create_space(session, XR_REFERENCE_SPACE_TYPE_STAGE);
  const XrPosef offset{{0.0f, 0.38268343f, 0.0f, 0.92387953f}, {0.1f, -0.05f, -0.2f}};  // 45 deg about +Y
  const XrSpace view_offset = create_space(session, XR_REFERENCE_SPACE_TYPE_VIEW, offset);

  struct Case {
    XrSpace space, base;
    XrReferenceSpaceType space_type, base_type;
    XrPosef space_offset, base_offset;
  };
  const XrPosef id = mx::kIdentityPose;
  for (const Case& c : {Case{view, local, XR_REFERENCE_SPACE_TYPE_VIEW, XR_REFERENCE_SPACE_TYPE_LOCAL, id, id},
                        Case{local, view, XR_REFERENCE_SPACE_TYPE_LOCAL, XR_REFERENCE_SPACE_TYPE_VIEW, id, id},
                        Case{view, stage, XR_REFERENCE_SPACE_TYPE_VIEW, XR_REFERENCE_SPACE_TYPE_STAGE, id, id},
                        Case{view_offset, stage, XR_REFERENCE_SPACE_TYPE_VIEW, XR_REFERENCE_SPACE_TYPE_STAGE, offset, id},
                        Case{stage, view_offset, XR_REFERENCE_SPACE_TYPE_STAGE, XR_REFERENCE_SPACE_TYPE_VIEW, id, offset}}) {
    auto velocity = make<XrSpaceVelocity>(XR_TYPE_SPACE_VELOCITY);
    auto location = make<XrSpaceLocation>(XR_TYPE_SPACE_LOCATION);
    location.next = &velocity;
    ASSERT_EQ(xrLocateSpace(c.space, c.base, now, &location), XR_SUCCESS);
    const mx::Located expected = mx::locate(c.space_type, c.space_offset, c.base_type, c.base_offset, now);
    EXPECT_EQ(location.locationFlags, XrSpaceLocationFlags{0xF});
    EXPECT_EQ(velocity.velocityFlags, XrSpaceVelocityFlags{0x3});
    expect_near(location.pose, expected.pose);
    expect_near(velocity.linearVelocity, expected.linear_velocity);
    expect_near(velocity.angularVelocity, expected.angular_velocity);
  }
  // STAGE is the floor 1.6 m under LOCAL.
  auto stage_in_local = make<XrSpaceLocation>(XR_TYPE_SPACE_LOCATION);
  ASSERT_EQ(xrLocateSpace(stage, local, now, &stage_in_local), XR_SUCCESS);
  expect_near(stage_in_local.pose, XrPosef{{0, 0, 0, 1}, {0.0f, -1.6f, 0.0f}});

  // A few frames, paced at 90 Hz with display times in the future.
  for (int i = 0; i < 3; ++i) {
    auto frame = make<XrFrameState>(XR_TYPE_FRAME_STATE);
    ASSERT_EQ(xrWaitFrame(session, nullptr, &frame), XR_SUCCESS);
    EXPECT_GT(frame.predictedDisplayTime, mx::xr_time_now());
    EXPECT_EQ(frame.predictedDisplayPeriod, mx::kFramePeriodNs);
    EXPECT_TRUE(frame.shouldRender);
    ASSERT_EQ(xrBeginFrame(session, nullptr), XR_SUCCESS);
    auto end = make<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
    end.displayTime = frame.predictedDisplayTime;
    end.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
    ASSERT_EQ(xrEndFrame(session, &end), XR_SUCCESS);
  }

  ASSERT_EQ(xrRequestExitSession(session), XR_SUCCESS);
  EXPECT_EQ(drain_states(instance),
            (std::vector{XR_SESSION_STATE_VISIBLE, XR_SESSION_STATE_SYNCHRONIZED, XR_SESSION_STATE_STOPPING}));
  ASSERT_EQ(xrEndSession(session), XR_SUCCESS);
  EXPECT_EQ(drain_states(instance), (std::vector{XR_SESSION_STATE_IDLE, XR_SESSION_STATE_EXITING}));
  for (XrSpace s : {local, view, stage, view_offset}) EXPECT_EQ(xrDestroySpace(s), XR_SUCCESS);
  EXPECT_EQ(xrDestroySession(session), XR_SUCCESS);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

TEST_F(MockRuntime, HeadlessAppSeesTheMockMotion) { run_headless_app(); }

// The velocities in mock_motion.hpp are the derivatives of its poses.
TEST(MockMotion, VelocitiesAreDerivativesOfPoses) {
  const XrPosef offset{{0.1f, 0.2f, -0.3f, 0.92736185f}, {0.3f, -0.1f, 0.2f}};
  const XrPosef id = mx::kIdentityPose;
  const std::vector<std::pair<XrReferenceSpaceType, XrPosef>> spaces{
      {XR_REFERENCE_SPACE_TYPE_VIEW, id}, {XR_REFERENCE_SPACE_TYPE_VIEW, offset},
      {XR_REFERENCE_SPACE_TYPE_LOCAL, id}, {XR_REFERENCE_SPACE_TYPE_STAGE, offset}};
  const XrTime h = 1'000'000;  // 1 ms central differences
  for (XrTime t : {XrTime{5'000'000'000}, XrTime{123'456'789'012}, XrTime{86'400'000'000'000}}) {
    for (const auto& [a, a_off] : spaces) {
      for (const auto& [b, b_off] : spaces) {
        const mx::Motion m = mx::locate_motion(a, a_off, b, b_off, t);
        const mx::Motion plus = mx::locate_motion(a, a_off, b, b_off, t + h);
        const mx::Motion minus = mx::locate_motion(a, a_off, b, b_off, t - h);
        const double dt = 2e-9 * static_cast<double>(h);
        EXPECT_NEAR((plus.pose.p.x - minus.pose.p.x) / dt, m.linear_velocity.x, 1e-5);
        EXPECT_NEAR((plus.pose.p.y - minus.pose.p.y) / dt, m.linear_velocity.y, 1e-5);
        EXPECT_NEAR((plus.pose.p.z - minus.pose.p.z) / dt, m.linear_velocity.z, 1e-5);
        // dR R^T over 2h: the rotation q+ q-^* is about w * 2h (small angle).
        mx::Quat d = plus.pose.q * mx::conjugate(minus.pose.q);
        if (d.w < 0) d = {-d.x, -d.y, -d.z, -d.w};
        EXPECT_NEAR(2 * d.x / dt, m.angular_velocity.x, 1e-5);
        EXPECT_NEAR(2 * d.y / dt, m.angular_velocity.y, 1e-5);
        EXPECT_NEAR(2 * d.z / dt, m.angular_velocity.z, 1e-5);
      }
    }
  }
}

// The devices' velocities are the derivatives of their poses too, the left
// hand mirrors the right, and every device of a hand rides on its wrist.
TEST(MockMotion, DevicesFollowTheWrist) {
  using Fn = mx::Motion (*)(mx::Hand, XrTime);
  const Fn devices[] = {&mx::wrist_pose, &mx::controller_grip, &mx::controller_aim, &mx::tracker_pose,
                        [](mx::Hand h, XrTime t) { return mx::native_joint(h, XR_HAND_JOINT_INDEX_TIP_EXT, t); }};
  const XrTime h = 1'000'000;
  const double dt = 2e-9 * static_cast<double>(h);
  for (XrTime t : {XrTime{5'000'000'000}, XrTime{123'456'789'012}, XrTime{86'400'000'000'000}}) {
    for (const mx::Hand hand : {mx::Hand::left, mx::Hand::right}) {
      for (Fn device : devices) {
        const mx::Motion m = device(hand, t), plus = device(hand, t + h), minus = device(hand, t - h);
        EXPECT_NEAR((plus.pose.p.x - minus.pose.p.x) / dt, m.linear_velocity.x, 1e-5);
        EXPECT_NEAR((plus.pose.p.y - minus.pose.p.y) / dt, m.linear_velocity.y, 1e-5);
        EXPECT_NEAR((plus.pose.p.z - minus.pose.p.z) / dt, m.linear_velocity.z, 1e-5);
        mx::Quat d = plus.pose.q * mx::conjugate(minus.pose.q);
        if (d.w < 0) d = {-d.x, -d.y, -d.z, -d.w};
        EXPECT_NEAR(2 * d.x / dt, m.angular_velocity.x, 1e-5);
        EXPECT_NEAR(2 * d.y / dt, m.angular_velocity.y, 1e-5);
        EXPECT_NEAR(2 * d.z / dt, m.angular_velocity.z, 1e-5);
      }
    }
    // Mirror images: x flips, y and z stay.
    const mx::Motion l = mx::controller_grip(mx::Hand::left, t), r = mx::controller_grip(mx::Hand::right, t);
    EXPECT_NEAR(l.pose.p.x, -r.pose.p.x, 1e-12);
    EXPECT_NEAR(l.pose.p.y, r.pose.p.y, 1e-12);
    EXPECT_NEAR(l.pose.p.z, r.pose.p.z, 1e-12);
    EXPECT_GT(r.pose.p.x, 0.1);
    // wrist = tracker * tracker_to_wrist, grip = wrist * wrist_to_grip.
    for (const mx::Hand hand : {mx::Hand::left, mx::Hand::right}) {
      const XrPosef wrist = mx::to_xr(mx::wrist_pose(hand, t).pose);
      expect_near(mx::to_xr(mx::compose(mx::tracker_pose(hand, t).pose, mx::tracker_to_wrist(hand))), wrist);
      expect_near(mx::to_xr(mx::compose(mx::wrist_pose(hand, t).pose, mx::wrist_to_grip(hand))),
                  mx::to_xr(mx::controller_grip(hand, t).pose));
      expect_near(mx::to_xr(mx::native_joint(hand, XR_HAND_JOINT_WRIST_EXT, t).pose), wrist);
    }
  }
  // The right hand's palm faces inwards (-X): the wrist joint's +Y points to +X.
  const mx::Vec3 back = mx::rotate(mx::wrist_pose(mx::Hand::right, XrTime{5'000'000'000}).pose.q, {0, 1, 0});
  EXPECT_GT(back.x, 0.8);
}

TEST(MockMotion, SchedulesAreExact) {
  const XrTime t0 = 1'000'000'000'000;  // a whole number of 2 s periods
  EXPECT_TRUE(mx::select_pressed(mx::Hand::left, t0));
  EXPECT_TRUE(mx::select_pressed(mx::Hand::left, t0 + 999'999'999));
  EXPECT_FALSE(mx::select_pressed(mx::Hand::left, t0 + 1'000'000'000));
  EXPECT_FALSE(mx::select_pressed(mx::Hand::right, t0 + 499'999'999));
  EXPECT_TRUE(mx::select_pressed(mx::Hand::right, t0 + 500'000'000));
  EXPECT_EQ(mx::select_last_change(mx::Hand::left, t0 + 1'300'000'000), t0 + 1'000'000'000);
  EXPECT_EQ(mx::select_last_change(mx::Hand::right, t0 + 1'300'000'000), t0 + 500'000'000);
  // sin(2 pi 0.5 t) > 0 for the left hand, away from the edges.
  for (XrTime t = t0 + 50'000'000; t < t0 + 4'000'000'000; t += 100'000'000 + 7) {
    EXPECT_EQ(mx::select_pressed(mx::Hand::left, t), std::sin(std::numbers::pi * mx::seconds_from_xr_time(t)) > 0) << t;
  }
  // The native hand is lost for 0.5 s of every 4 s, the right one 2 s later.
  int lost = 0;
  for (XrTime t = t0; t < t0 + 4'000'000'000; t += 10'000'000)
    lost += mx::native_hand_tracked(mx::Hand::left, t) ? 0 : 1;
  EXPECT_EQ(lost, 50);
  EXPECT_FALSE(mx::native_hand_tracked(mx::Hand::left, t0 + 3'500'000'000));
  EXPECT_TRUE(mx::native_hand_tracked(mx::Hand::right, t0 + 3'500'000'000));
  EXPECT_FALSE(mx::native_hand_tracked(mx::Hand::right, t0 + 1'500'000'000));
}

TEST_F(MockRuntime, RejectsMisuse) {
  XrInstance instance = XR_NULL_HANDLE;
  EXPECT_EQ(create_instance({"XR_PROPRIO_no_such_extension"}, &instance), XR_ERROR_EXTENSION_NOT_PRESENT);
  ASSERT_EQ(create_instance({}, &instance), XR_SUCCESS);  // no XR_MND_headless

  auto system_info = make<XrSystemGetInfo>(XR_TYPE_SYSTEM_GET_INFO);
  system_info.formFactor = XR_FORM_FACTOR_HANDHELD_DISPLAY;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  EXPECT_EQ(xrGetSystem(instance, &system_info, &system), XR_ERROR_FORM_FACTOR_UNSUPPORTED);
  system_info.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  ASSERT_EQ(xrGetSystem(instance, &system_info, &system), XR_SUCCESS);

  auto session_info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  session_info.systemId = system;
  XrSession session = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateSession(instance, &session_info, &session), XR_ERROR_GRAPHICS_DEVICE_INVALID);

  PFN_xrVoidFunction f = nullptr;
  EXPECT_EQ(xrGetInstanceProcAddr(instance, "xrConvertTimespecTimeToTimeKHR", &f), XR_ERROR_FUNCTION_UNSUPPORTED);
  EXPECT_EQ(f, nullptr);
  EXPECT_EQ(xrGetInstanceProcAddr(instance, "xrCreateHandTrackerEXT", &f), XR_ERROR_FUNCTION_UNSUPPORTED);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);

  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  ASSERT_EQ(xrGetSystem(instance, &system_info, &system), XR_SUCCESS);
  ASSERT_EQ(xrCreateSession(instance, &session_info, &session), XR_SUCCESS);
  auto frame = make<XrFrameState>(XR_TYPE_FRAME_STATE);
  EXPECT_EQ(xrWaitFrame(session, nullptr, &frame), XR_ERROR_SESSION_NOT_RUNNING);
  EXPECT_EQ(xrEndSession(session), XR_ERROR_SESSION_NOT_RUNNING);
  auto space_info = make<XrReferenceSpaceCreateInfo>(XR_TYPE_REFERENCE_SPACE_CREATE_INFO);
  space_info.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_LOCAL;
  space_info.poseInReferenceSpace = {{0, 0, 0, 2}, {0, 0, 0}};  // not a unit quaternion
  XrSpace space = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateReferenceSpace(session, &space_info, &space), XR_ERROR_POSE_INVALID);
  const XrSpace local = create_space(session, XR_REFERENCE_SPACE_TYPE_LOCAL);
  XrExtent2Df bounds{};
  EXPECT_EQ(xrGetReferenceSpaceBoundsRect(session, XR_REFERENCE_SPACE_TYPE_STAGE, &bounds), XR_SPACE_BOUNDS_UNAVAILABLE);
  EXPECT_EQ(xrDestroySpace(local), XR_SUCCESS);
  EXPECT_EQ(xrDestroySpace(local), XR_ERROR_HANDLE_INVALID);
  XrPath path = XR_NULL_PATH;
  EXPECT_EQ(xrStringToPath(instance, "/user/hand/left", &path), XR_SUCCESS);
  char text[XR_MAX_PATH_LENGTH];
  uint32_t length = 0;
  EXPECT_EQ(xrPathToString(instance, path, 2, &length, text), XR_ERROR_SIZE_INSUFFICIENT);
  EXPECT_EQ(length, 16u);
  EXPECT_EQ(xrPathToString(instance, path, sizeof text, &length, text), XR_SUCCESS);
  EXPECT_STREQ(text, "/user/hand/left");
  EXPECT_EQ(xrStringToPath(instance, "/user//hand", &path), XR_ERROR_PATH_FORMAT_INVALID);
  // Destroying the instance takes its session and spaces with it.
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

TEST_F(MockRuntime, NativeHandTrackingOnlyWhenOffered) {
  auto has_hand_tracking = [] {
    const auto e = instance_extensions();
    return std::find(e.begin(), e.end(), XR_EXT_HAND_TRACKING_EXTENSION_NAME) != e.end();
  };
  XrInstance instance = XR_NULL_HANDLE;
  EXPECT_FALSE(has_hand_tracking());
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
  // The 1.0.20 loader keeps the runtime loaded, with the extension list it
  // read then, until an instance is destroyed: flip the variable only after that.
  ScopedEnv native("PROPRIO_MOCK_RUNTIME_HAND_TRACKING", "1");
  ASSERT_TRUE(has_hand_tracking());

  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME, XR_EXT_HAND_TRACKING_EXTENSION_NAME}, &instance),
            XR_SUCCESS);
  auto system_info = make<XrSystemGetInfo>(XR_TYPE_SYSTEM_GET_INFO);
  system_info.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  ASSERT_EQ(xrGetSystem(instance, &system_info, &system), XR_SUCCESS);
  auto hand_properties = make<XrSystemHandTrackingPropertiesEXT>(XR_TYPE_SYSTEM_HAND_TRACKING_PROPERTIES_EXT);
  auto properties = make<XrSystemProperties>(XR_TYPE_SYSTEM_PROPERTIES);
  properties.next = &hand_properties;
  ASSERT_EQ(xrGetSystemProperties(instance, system, &properties), XR_SUCCESS);
  EXPECT_TRUE(hand_properties.supportsHandTracking);

  auto session_info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  session_info.systemId = system;
  XrSession session = XR_NULL_HANDLE;
  ASSERT_EQ(xrCreateSession(instance, &session_info, &session), XR_SUCCESS);
  const XrSpace local = create_space(session, XR_REFERENCE_SPACE_TYPE_LOCAL);

  auto create = get_proc<PFN_xrCreateHandTrackerEXT>(instance, "xrCreateHandTrackerEXT");
  auto locate = get_proc<PFN_xrLocateHandJointsEXT>(instance, "xrLocateHandJointsEXT");
  auto destroy = get_proc<PFN_xrDestroyHandTrackerEXT>(instance, "xrDestroyHandTrackerEXT");
  ASSERT_TRUE(create && locate && destroy);
  auto tracker_info = make<XrHandTrackerCreateInfoEXT>(XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT);
  tracker_info.hand = XR_HAND_RIGHT_EXT;
  tracker_info.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
  XrHandTrackerEXT tracker = XR_NULL_HANDLE;
  ASSERT_EQ(create(session, &tracker_info, &tracker), XR_SUCCESS);

  auto locate_info = make<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);
  locate_info.baseSpace = local;
  locate_info.time = mx::xr_time_now();
  std::vector<XrHandJointLocationEXT> joints(XR_HAND_JOINT_COUNT_EXT);
  auto locations = make<XrHandJointLocationsEXT>(XR_TYPE_HAND_JOINT_LOCATIONS_EXT);
  locations.jointCount = XR_HAND_JOINT_COUNT_EXT;
  locations.jointLocations = joints.data();
  ASSERT_EQ(locate(tracker, &locate_info, &locations), XR_SUCCESS);
  EXPECT_TRUE(locations.isActive);
  for (const auto& joint : joints) {
    expect_near(joint.pose, XrPosef{{0, 0, 0, 1}, mx::kNativeJointPosition}, 0.0f);
    EXPECT_EQ(joint.radius, mx::kNativeJointRadius);
    EXPECT_EQ(joint.locationFlags, XrSpaceLocationFlags{0xF});
  }
  EXPECT_EQ(destroy(tracker), XR_SUCCESS);
  EXPECT_EQ(xrDestroySpace(local), XR_SUCCESS);
  EXPECT_EQ(xrDestroySession(session), XR_SUCCESS);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

TEST_F(MockRuntime, ConcurrentCallsFromEightThreads) {
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  auto system_info = make<XrSystemGetInfo>(XR_TYPE_SYSTEM_GET_INFO);
  system_info.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  ASSERT_EQ(xrGetSystem(instance, &system_info, &system), XR_SUCCESS);
  auto session_info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  session_info.systemId = system;
  XrSession session = XR_NULL_HANDLE;
  ASSERT_EQ(xrCreateSession(instance, &session_info, &session), XR_SUCCESS);
  const XrSpace local = create_space(session, XR_REFERENCE_SPACE_TYPE_LOCAL);

  std::atomic<int> failures{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 8; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < 200; ++i) {
        auto info = make<XrReferenceSpaceCreateInfo>(XR_TYPE_REFERENCE_SPACE_CREATE_INFO);
        info.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_VIEW;
        info.poseInReferenceSpace = mx::kIdentityPose;
        XrSpace view = XR_NULL_HANDLE;
        auto location = make<XrSpaceLocation>(XR_TYPE_SPACE_LOCATION);
        XrPath path = XR_NULL_PATH;
        const std::string name = "/thread/" + std::to_string(t);
        if (xrCreateReferenceSpace(session, &info, &view) != XR_SUCCESS ||
            xrLocateSpace(view, local, mx::xr_time_now(), &location) != XR_SUCCESS ||
            xrStringToPath(instance, name.c_str(), &path) != XR_SUCCESS || xrDestroySpace(view) != XR_SUCCESS) {
          ++failures;
        }
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(failures.load(), 0);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

TEST_F(MockRuntime, PrimaryStereoViews) {
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  const XrSystemId system = get_hmd(instance);

  uint32_t count = 0;
  XrViewConfigurationType types[2]{};
  ASSERT_EQ(xrEnumerateViewConfigurations(instance, system, 2, &count, types), XR_SUCCESS);
  ASSERT_EQ(count, 1u);
  EXPECT_EQ(types[0], XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO);
  auto properties = make<XrViewConfigurationProperties>(XR_TYPE_VIEW_CONFIGURATION_PROPERTIES);
  ASSERT_EQ(xrGetViewConfigurationProperties(instance, system, types[0], &properties), XR_SUCCESS);
  EXPECT_EQ(properties.viewConfigurationType, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO);
  EXPECT_FALSE(properties.fovMutable);
  EXPECT_EQ(xrGetViewConfigurationProperties(instance, system, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_MONO, &properties),
            XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED);

  auto views_of = [&] {
    std::vector views(2, make<XrViewConfigurationView>(XR_TYPE_VIEW_CONFIGURATION_VIEW));
    uint32_t n = 0;
    EXPECT_EQ(xrEnumerateViewConfigurationViews(instance, system, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO, 0, &n,
                                                nullptr),
              XR_SUCCESS);
    EXPECT_EQ(n, 2u);
    EXPECT_EQ(xrEnumerateViewConfigurationViews(instance, system, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO, 2, &n,
                                                views.data()),
              XR_SUCCESS);
    return views;
  };
  for (const auto& view : views_of()) {
    EXPECT_EQ(view.recommendedImageRectWidth, 640u);
    EXPECT_EQ(view.recommendedImageRectHeight, 360u);
    EXPECT_EQ(view.maxImageRectWidth, 4096u);
    EXPECT_EQ(view.maxImageRectHeight, 4096u);
    EXPECT_EQ(view.recommendedSwapchainSampleCount, 1u);
    EXPECT_EQ(view.maxSwapchainSampleCount, 1u);
  }
  {
    ScopedEnv size("PROPRIO_MOCK_RUNTIME_VIEW_SIZE", "800x600");
    EXPECT_EQ(views_of()[1].recommendedImageRectWidth, 800u);
    EXPECT_EQ(views_of()[1].recommendedImageRectHeight, 600u);
  }
  {
    ScopedEnv size("PROPRIO_MOCK_RUNTIME_VIEW_SIZE", "5000x10");  // too large: the default, with a warning
    EXPECT_EQ(views_of()[0].recommendedImageRectWidth, 640u);
  }

  // xrLocateViews: the VIEW pose moved -/+ 31.5 mm along its own x axis.
  auto session_info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  session_info.systemId = system;
  XrSession session = XR_NULL_HANDLE;
  ASSERT_EQ(xrCreateSession(instance, &session_info, &session), XR_SUCCESS);
  const XrSpace stage = create_space(session, XR_REFERENCE_SPACE_TYPE_STAGE);
  auto locate_info = make<XrViewLocateInfo>(XR_TYPE_VIEW_LOCATE_INFO);
  locate_info.viewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  locate_info.displayTime = XrTime{123'456'789'012};
  locate_info.space = stage;
  auto view_state = make<XrViewState>(XR_TYPE_VIEW_STATE);
  std::vector views(2, make<XrView>(XR_TYPE_VIEW));
  ASSERT_EQ(xrLocateViews(session, &locate_info, &view_state, 2, &count, views.data()), XR_SUCCESS);
  ASSERT_EQ(count, 2u);
  EXPECT_EQ(view_state.viewStateFlags, XrViewStateFlags{0xF});
  for (uint32_t i = 0; i < 2; ++i) {
    XrPosef eye = mx::kIdentityPose;
    eye.position.x = i == 0 ? -0.0315f : 0.0315f;
    const mx::Located expected = mx::locate(XR_REFERENCE_SPACE_TYPE_VIEW, eye, XR_REFERENCE_SPACE_TYPE_STAGE,
                                            mx::kIdentityPose, locate_info.displayTime);
    expect_near(views[i].pose, expected.pose);
    EXPECT_FLOAT_EQ(views[i].fov.angleLeft, -0.785f);
    EXPECT_FLOAT_EQ(views[i].fov.angleRight, 0.785f);
    EXPECT_FLOAT_EQ(views[i].fov.angleUp, 0.6f);
    EXPECT_FLOAT_EQ(views[i].fov.angleDown, -0.6f);
  }
  const mx::Located head = mx::locate(XR_REFERENCE_SPACE_TYPE_VIEW, XR_REFERENCE_SPACE_TYPE_STAGE,
                                      locate_info.displayTime);
  const XrVector3f& l = views[0].pose.position;
  const XrVector3f& r = views[1].pose.position;
  EXPECT_NEAR(std::hypot(r.x - l.x, r.y - l.y, r.z - l.z), 0.063f, 1e-5f);
  expect_near(XrVector3f{(l.x + r.x) / 2, (l.y + r.y) / 2, (l.z + r.z) / 2}, head.pose.position);

  views[1].type = XR_TYPE_SPACE_LOCATION;
  EXPECT_EQ(xrLocateViews(session, &locate_info, &view_state, 2, &count, views.data()), XR_ERROR_VALIDATION_FAILURE);
  EXPECT_EQ(xrLocateViews(session, &locate_info, &view_state, 1, &count, views.data()), XR_ERROR_SIZE_INSUFFICIENT);
  locate_info.viewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_MONO;
  EXPECT_EQ(xrLocateViews(session, &locate_info, &view_state, 0, &count, nullptr),
            XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

// A headless session has no swapchain formats, so no swapchain and no layer.
TEST_F(MockRuntime, HeadlessSessionHasNoSwapchains) {
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  auto session_info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  session_info.systemId = get_hmd(instance);
  XrSession session = XR_NULL_HANDLE;
  ASSERT_EQ(xrCreateSession(instance, &session_info, &session), XR_SUCCESS);
  uint32_t count = 99;
  EXPECT_EQ(xrEnumerateSwapchainFormats(session, 0, &count, nullptr), XR_SUCCESS);
  EXPECT_EQ(count, 0u);
  auto info = make<XrSwapchainCreateInfo>(XR_TYPE_SWAPCHAIN_CREATE_INFO);
  info.format = VK_FORMAT_R8G8B8A8_SRGB;
  info.usageFlags = XR_SWAPCHAIN_USAGE_COLOR_ATTACHMENT_BIT;
  info.sampleCount = info.faceCount = info.arraySize = info.mipCount = 1;
  info.width = info.height = 16;
  XrSwapchain swapchain = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateSwapchain(session, &info, &swapchain), XR_ERROR_SWAPCHAIN_FORMAT_UNSUPPORTED);
  EXPECT_EQ(xrDestroySwapchain(to_handle<XrSwapchain>(0xdead)), XR_ERROR_HANDLE_INVALID);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

// XR_KHR_vulkan_enable2 is always offered; its order rules and bindings are
// checked before any Vulkan object is touched (vulkan_session_test.cpp runs a
// whole session on lavapipe).
TEST_F(MockRuntime, VulkanEnable2OfferedAndChecked) {
  const auto extensions = instance_extensions();
  ASSERT_NE(std::find(extensions.begin(), extensions.end(), XR_KHR_VULKAN_ENABLE2_EXTENSION_NAME), extensions.end());

  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  PFN_xrVoidFunction f = nullptr;
  EXPECT_EQ(xrGetInstanceProcAddr(instance, "xrCreateVulkanInstanceKHR", &f), XR_ERROR_FUNCTION_UNSUPPORTED);
  // Headless without vulkan_enable2 ignores nothing: a binding is refused.
  auto binding = make<XrGraphicsBindingVulkan2KHR>(XR_TYPE_GRAPHICS_BINDING_VULKAN2_KHR);
  auto session_info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  session_info.systemId = get_hmd(instance);
  session_info.next = &binding;
  XrSession session = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateSession(instance, &session_info, &session), XR_ERROR_GRAPHICS_DEVICE_INVALID);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);

  ASSERT_EQ(create_instance({XR_KHR_VULKAN_ENABLE2_EXTENSION_NAME}, &instance), XR_SUCCESS);
  session_info.systemId = get_hmd(instance);
  EXPECT_EQ(xrCreateSession(instance, &session_info, &session), XR_ERROR_GRAPHICS_REQUIREMENTS_CALL_MISSING);
  auto requirements_of =
      get_proc<PFN_xrGetVulkanGraphicsRequirements2KHR>(instance, "xrGetVulkanGraphicsRequirements2KHR");
  ASSERT_NE(requirements_of, nullptr);
  auto requirements = make<XrGraphicsRequirementsVulkan2KHR>(XR_TYPE_GRAPHICS_REQUIREMENTS_VULKAN2_KHR);
  EXPECT_EQ(requirements_of(instance, session_info.systemId + 1, &requirements), XR_ERROR_SYSTEM_INVALID);
  ASSERT_EQ(requirements_of(instance, session_info.systemId, &requirements), XR_SUCCESS);
  EXPECT_EQ(requirements.minApiVersionSupported, XR_MAKE_VERSION(1, 1, 0));
  EXPECT_EQ(requirements.maxApiVersionSupported, XR_MAKE_VERSION(1, 3, 0));
  // Null handles: not a VkInstance this runtime created.
  EXPECT_EQ(xrCreateSession(instance, &session_info, &session), XR_ERROR_GRAPHICS_DEVICE_INVALID);
  // No binding and no XR_MND_headless: no session either.
  session_info.next = nullptr;
  EXPECT_EQ(xrCreateSession(instance, &session_info, &session), XR_ERROR_GRAPHICS_DEVICE_INVALID);

  auto device_of = get_proc<PFN_xrGetVulkanGraphicsDevice2KHR>(instance, "xrGetVulkanGraphicsDevice2KHR");
  ASSERT_NE(device_of, nullptr);
  auto get_info = make<XrVulkanGraphicsDeviceGetInfoKHR>(XR_TYPE_VULKAN_GRAPHICS_DEVICE_GET_INFO_KHR);
  get_info.systemId = session_info.systemId;
  VkPhysicalDevice physical_device = VK_NULL_HANDLE;
  EXPECT_EQ(device_of(instance, &get_info, &physical_device), XR_ERROR_VALIDATION_FAILURE);  // unknown VkInstance
  auto create_instance_vk = get_proc<PFN_xrCreateVulkanInstanceKHR>(instance, "xrCreateVulkanInstanceKHR");
  ASSERT_NE(create_instance_vk, nullptr);
  auto vk_info = make<XrVulkanInstanceCreateInfoKHR>(XR_TYPE_VULKAN_INSTANCE_CREATE_INFO_KHR);
  vk_info.systemId = session_info.systemId;
  VkInstance vk_instance = VK_NULL_HANDLE;
  VkResult vk_result = VK_SUCCESS;
  EXPECT_EQ(create_instance_vk(instance, &vk_info, &vk_instance, &vk_result), XR_ERROR_VALIDATION_FAILURE);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

// PROPRIO_MOCK_RUNTIME_EXIT_AFTER_FRAMES=N: the runtime asks to exit after N
// frames, so a plain frame loop ends by itself.
TEST_F(MockRuntime, ExitsAfterFrames) {
  ScopedEnv exit_after("PROPRIO_MOCK_RUNTIME_EXIT_AFTER_FRAMES", "3");
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  auto session_info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  session_info.systemId = get_hmd(instance);
  XrSession session = XR_NULL_HANDLE;
  ASSERT_EQ(xrCreateSession(instance, &session_info, &session), XR_SUCCESS);
  EXPECT_EQ(drain_states(instance), (std::vector{XR_SESSION_STATE_IDLE, XR_SESSION_STATE_READY}));
  auto begin_info = make<XrSessionBeginInfo>(XR_TYPE_SESSION_BEGIN_INFO);
  begin_info.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  ASSERT_EQ(xrBeginSession(session, &begin_info), XR_SUCCESS);
  EXPECT_EQ(drain_states(instance),
            (std::vector{XR_SESSION_STATE_SYNCHRONIZED, XR_SESSION_STATE_VISIBLE, XR_SESSION_STATE_FOCUSED}));
  int frames = 0;
  std::vector<XrSessionState> states;
  while (states.empty() && frames < 10) {
    auto frame_state = make<XrFrameState>(XR_TYPE_FRAME_STATE);
    ASSERT_EQ(xrWaitFrame(session, nullptr, &frame_state), XR_SUCCESS);
    ASSERT_EQ(xrBeginFrame(session, nullptr), XR_SUCCESS);
    auto end_info = make<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
    end_info.displayTime = frame_state.predictedDisplayTime;
    end_info.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
    ASSERT_EQ(xrEndFrame(session, &end_info), XR_SUCCESS);
    ++frames;
    states = drain_states(instance);
  }
  EXPECT_EQ(frames, 3);
  EXPECT_EQ(states,
            (std::vector{XR_SESSION_STATE_VISIBLE, XR_SESSION_STATE_SYNCHRONIZED, XR_SESSION_STATE_STOPPING}));
  ASSERT_EQ(xrEndSession(session), XR_SUCCESS);
  EXPECT_EQ(drain_states(instance), (std::vector{XR_SESSION_STATE_IDLE, XR_SESSION_STATE_EXITING}));
  EXPECT_EQ(xrDestroySession(session), XR_SUCCESS);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

// PROPRIO_MOCK_RUNTIME_UNFOCUS_AFTER_FRAMES: 0 keeps a begun session at
// VISIBLE; N takes it from FOCUSED to VISIBLE after the Nth frame, where it
// stays (an app that lost input focus), and exit still steps down from there.
TEST_F(MockRuntime, LosesOrNeverGetsFocus) {
  const auto run = [](const char* value, std::vector<XrSessionState> at_begin, int unfocus_frame) {
    ScopedEnv unfocus("PROPRIO_MOCK_RUNTIME_UNFOCUS_AFTER_FRAMES", value);
    XrInstance instance = XR_NULL_HANDLE;
    ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
    auto session_info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
    session_info.systemId = get_hmd(instance);
    XrSession session = XR_NULL_HANDLE;
    ASSERT_EQ(xrCreateSession(instance, &session_info, &session), XR_SUCCESS);
    drain_states(instance);
    auto begin_info = make<XrSessionBeginInfo>(XR_TYPE_SESSION_BEGIN_INFO);
    begin_info.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
    ASSERT_EQ(xrBeginSession(session, &begin_info), XR_SUCCESS);
    EXPECT_EQ(drain_states(instance), at_begin) << value;
    for (int frame = 1; frame <= 5; ++frame) {
      auto frame_state = make<XrFrameState>(XR_TYPE_FRAME_STATE);
      ASSERT_EQ(xrWaitFrame(session, nullptr, &frame_state), XR_SUCCESS);
      ASSERT_EQ(xrBeginFrame(session, nullptr), XR_SUCCESS);
      auto end_info = make<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
      end_info.displayTime = frame_state.predictedDisplayTime;
      end_info.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
      ASSERT_EQ(xrEndFrame(session, &end_info), XR_SUCCESS);
      EXPECT_EQ(drain_states(instance),
                frame == unfocus_frame ? std::vector{XR_SESSION_STATE_VISIBLE} : std::vector<XrSessionState>{})
          << value << ", frame " << frame;
    }
    ASSERT_EQ(xrRequestExitSession(session), XR_SUCCESS);
    EXPECT_EQ(drain_states(instance), (std::vector{XR_SESSION_STATE_SYNCHRONIZED, XR_SESSION_STATE_STOPPING}));
    ASSERT_EQ(xrEndSession(session), XR_SUCCESS);
    EXPECT_EQ(xrDestroySession(session), XR_SUCCESS);
    EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
  };
  run("0", {XR_SESSION_STATE_SYNCHRONIZED, XR_SESSION_STATE_VISIBLE}, -1);
  run("3", {XR_SESSION_STATE_SYNCHRONIZED, XR_SESSION_STATE_VISIBLE, XR_SESSION_STATE_FOCUSED}, 3);
}

// PROPRIO_MOCK_RUNTIME_MONADO_HEADLESS=1: a headless session refuses frames
// as Monado's does (xrWaitFrame returns at once without starting a frame, and
// xrBeginFrame answers XR_ERROR_CALL_ORDER_INVALID); the rest of the session
// (spaces, exit) still works. Without the variable the same calls succeed
// (ExitsAfterFrames).
TEST_F(MockRuntime, MonadoHeadlessRefusesFrames) {
  ScopedEnv monado("PROPRIO_MOCK_RUNTIME_MONADO_HEADLESS", "1");
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  auto session_info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  session_info.systemId = get_hmd(instance);
  XrSession session = XR_NULL_HANDLE;
  ASSERT_EQ(xrCreateSession(instance, &session_info, &session), XR_SUCCESS);
  auto begin_info = make<XrSessionBeginInfo>(XR_TYPE_SESSION_BEGIN_INFO);
  begin_info.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  ASSERT_EQ(xrBeginSession(session, &begin_info), XR_SUCCESS);
  drain_states(instance);
  for (int i = 0; i < 3; ++i) {
    auto frame_state = make<XrFrameState>(XR_TYPE_FRAME_STATE);
    frame_state.predictedDisplayTime = 123;  // overwritten with 0
    frame_state.shouldRender = XR_TRUE;
    ASSERT_EQ(xrWaitFrame(session, nullptr, &frame_state), XR_SUCCESS);
    EXPECT_EQ(frame_state.predictedDisplayTime, 0);
    EXPECT_EQ(frame_state.predictedDisplayPeriod, 0);
    EXPECT_EQ(frame_state.shouldRender, XR_FALSE);
    EXPECT_EQ(xrBeginFrame(session, nullptr), XR_ERROR_CALL_ORDER_INVALID);
    auto end_info = make<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
    end_info.displayTime = 1;
    end_info.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
    EXPECT_EQ(xrEndFrame(session, &end_info), XR_ERROR_CALL_ORDER_INVALID);
  }
  XrSpace view = create_space(session, XR_REFERENCE_SPACE_TYPE_VIEW);
  EXPECT_NE(view, XR_NULL_HANDLE);
  EXPECT_EQ(xrDestroySpace(view), XR_SUCCESS);
  ASSERT_EQ(xrRequestExitSession(session), XR_SUCCESS);
  EXPECT_EQ(drain_states(instance).back(), XR_SESSION_STATE_STOPPING);
  EXPECT_EQ(xrEndSession(session), XR_SUCCESS);
  EXPECT_EQ(xrDestroySession(session), XR_SUCCESS);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

// ---- actions, controllers, trackers and the moving native hand ----

XrPath to_path(XrInstance instance, const char* text) {
  XrPath path = XR_NULL_PATH;
  EXPECT_EQ(xrStringToPath(instance, text, &path), XR_SUCCESS) << text;
  return path;
}

std::string to_string(XrInstance instance, XrPath path) {
  char text[XR_MAX_PATH_LENGTH] = {};
  uint32_t length = 0;
  EXPECT_EQ(xrPathToString(instance, path, sizeof text, &length, text), XR_SUCCESS);
  return text;
}

XrResult create_action_set(XrInstance instance, const char* name, const char* localized, XrActionSet* set,
                           uint32_t priority = 0) {
  auto info = make<XrActionSetCreateInfo>(XR_TYPE_ACTION_SET_CREATE_INFO);
  std::snprintf(info.actionSetName, sizeof info.actionSetName, "%s", name);
  std::snprintf(info.localizedActionSetName, sizeof info.localizedActionSetName, "%s", localized);
  info.priority = priority;
  return xrCreateActionSet(instance, &info, set);
}

XrResult create_action(XrActionSet set, const char* name, XrActionType type, std::vector<XrPath> subaction_paths,
                       XrAction* action, const char* localized = nullptr) {
  auto info = make<XrActionCreateInfo>(XR_TYPE_ACTION_CREATE_INFO);
  std::snprintf(info.actionName, sizeof info.actionName, "%s", name);
  std::snprintf(info.localizedActionName, sizeof info.localizedActionName, "%s", localized ? localized : name);
  info.actionType = type;
  info.countSubactionPaths = static_cast<uint32_t>(subaction_paths.size());
  info.subactionPaths = subaction_paths.empty() ? nullptr : subaction_paths.data();
  return xrCreateAction(set, &info, action);
}

XrResult suggest(XrInstance instance, const char* profile, std::vector<std::pair<XrAction, const char*>> bindings) {
  std::vector<XrActionSuggestedBinding> list;
  for (const auto& [action, path] : bindings) list.push_back({action, to_path(instance, path)});
  auto info = make<XrInteractionProfileSuggestedBinding>(XR_TYPE_INTERACTION_PROFILE_SUGGESTED_BINDING);
  info.interactionProfile = to_path(instance, profile);
  info.countSuggestedBindings = static_cast<uint32_t>(list.size());
  info.suggestedBindings = list.data();
  return xrSuggestInteractionProfileBindings(instance, &info);
}

XrResult attach(XrSession session, std::vector<XrActionSet> sets) {
  auto info = make<XrSessionActionSetsAttachInfo>(XR_TYPE_SESSION_ACTION_SETS_ATTACH_INFO);
  info.countActionSets = static_cast<uint32_t>(sets.size());
  info.actionSets = sets.data();
  return xrAttachSessionActionSets(session, &info);
}

XrResult sync(XrSession session, std::vector<XrActiveActionSet> active) {
  auto info = make<XrActionsSyncInfo>(XR_TYPE_ACTIONS_SYNC_INFO);
  info.countActiveActionSets = static_cast<uint32_t>(active.size());
  info.activeActionSets = active.empty() ? nullptr : active.data();
  return xrSyncActions(session, &info);
}

XrSpace create_action_space(XrSession session, XrAction action, XrPath subaction,
                            XrPosef offset = mx::kIdentityPose) {
  auto info = make<XrActionSpaceCreateInfo>(XR_TYPE_ACTION_SPACE_CREATE_INFO);
  info.action = action;
  info.subactionPath = subaction;
  info.poseInActionSpace = offset;
  XrSpace space = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateActionSpace(session, &info, &space), XR_SUCCESS);
  return space;
}

template <class State>
State action_state(XrSession session, XrAction action, XrPath subaction, XrStructureType type,
                   XrResult expected = XR_SUCCESS) {
  auto info = make<XrActionStateGetInfo>(XR_TYPE_ACTION_STATE_GET_INFO);
  info.action = action;
  info.subactionPath = subaction;
  auto state = make<State>(type);
  XrResult result = XR_ERROR_RUNTIME_FAILURE;
  if constexpr (std::is_same_v<State, XrActionStateBoolean>) result = xrGetActionStateBoolean(session, &info, &state);
  if constexpr (std::is_same_v<State, XrActionStateFloat>) result = xrGetActionStateFloat(session, &info, &state);
  if constexpr (std::is_same_v<State, XrActionStatePose>) result = xrGetActionStatePose(session, &info, &state);
  EXPECT_EQ(result, expected);
  return state;
}
XrActionStateBoolean boolean_state(XrSession session, XrAction action, XrPath subaction) {
  return action_state<XrActionStateBoolean>(session, action, subaction, XR_TYPE_ACTION_STATE_BOOLEAN);
}
XrActionStatePose pose_state(XrSession session, XrAction action, XrPath subaction) {
  return action_state<XrActionStatePose>(session, action, subaction, XR_TYPE_ACTION_STATE_POSE);
}

struct Location {
  XrSpaceLocation location = make<XrSpaceLocation>(XR_TYPE_SPACE_LOCATION);
  XrSpaceVelocity velocity = make<XrSpaceVelocity>(XR_TYPE_SPACE_VELOCITY);
};
Location locate(XrSpace space, XrSpace base, XrTime time) {
  Location l;
  l.location.next = &l.velocity;
  EXPECT_EQ(xrLocateSpace(space, base, time, &l.location), XR_SUCCESS);
  l.location.next = nullptr;
  return l;
}
void expect_located(const Location& l, const mx::Located& expected) {
  EXPECT_EQ(l.location.locationFlags, XrSpaceLocationFlags{0xF});
  EXPECT_EQ(l.velocity.velocityFlags, XrSpaceVelocityFlags{0x3});
  expect_near(l.location.pose, expected.pose);
  expect_near(l.velocity.linearVelocity, expected.linear_velocity);
  expect_near(l.velocity.angularVelocity, expected.angular_velocity);
}

// A headless session, begun and FOCUSED, its state events drained.
XrSession begin_headless_session(XrInstance instance) {
  auto info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  info.systemId = get_hmd(instance);
  XrSession session = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateSession(instance, &info, &session), XR_SUCCESS);
  auto begin = make<XrSessionBeginInfo>(XR_TYPE_SESSION_BEGIN_INFO);
  begin.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  EXPECT_EQ(xrBeginSession(session, &begin), XR_SUCCESS);
  drain_states(instance);
  return session;
}

// Every queued event's type (tracker events: the paths they carry).
struct Events {
  std::vector<XrStructureType> types;
  std::vector<XrViveTrackerPathsHTCX> trackers;
};
Events drain_events(XrInstance instance) {
  Events events;
  auto event = make<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
  while (xrPollEvent(instance, &event) == XR_SUCCESS) {
    events.types.push_back(event.type);
    if (event.type == XR_TYPE_EVENT_DATA_VIVE_TRACKER_CONNECTED_HTCX) {
      events.trackers.push_back(*reinterpret_cast<const XrEventDataViveTrackerConnectedHTCX&>(event).paths);
    }
    event = make<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
  }
  return events;
}
bool contains(const std::vector<XrStructureType>& types, XrStructureType type) {
  return std::find(types.begin(), types.end(), type) != types.end();
}

// xrSyncActions at a time when no select/click edge lies between just before
// and just after it (edges are 0.5 s apart), so the state is predictable;
// returns the time just before.
XrTime sync_away_from_edges(XrSession session, std::vector<XrActiveActionSet> active,
                            XrResult expected = XR_SUCCESS) {
  for (int attempt = 0; attempt < 5; ++attempt) {
    const XrTime before = mx::xr_time_now();
    EXPECT_EQ(sync(session, active), expected);
    const XrTime after = mx::xr_time_now();
    if (mx::select_last_change(mx::Hand::left, after) <= before &&
        mx::select_last_change(mx::Hand::right, after) <= before) {
      return before;
    }
  }
  ADD_FAILURE() << "every sync straddled a select edge";
  return 0;
}

// The app's own actions on the simple controller: what the Proprio layer
// must leave working when it adds its own set.
TEST_F(MockRuntime, ActionsReadTheAnalyticControllers) {
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  const XrPath left = to_path(instance, "/user/hand/left"), right = to_path(instance, "/user/hand/right");
  XrActionSet set = XR_NULL_HANDLE;
  ASSERT_EQ(create_action_set(instance, "gameplay", "Gameplay", &set), XR_SUCCESS);
  XrAction select = XR_NULL_HANDLE, squeeze = XR_NULL_HANDLE, grip = XR_NULL_HANDLE, aim = XR_NULL_HANDLE,
           buzz = XR_NULL_HANDLE, unbound = XR_NULL_HANDLE;
  ASSERT_EQ(create_action(set, "select", XR_ACTION_TYPE_BOOLEAN_INPUT, {left, right}, &select), XR_SUCCESS);
  ASSERT_EQ(create_action(set, "squeeze", XR_ACTION_TYPE_FLOAT_INPUT, {left, right}, &squeeze), XR_SUCCESS);
  ASSERT_EQ(create_action(set, "grip", XR_ACTION_TYPE_POSE_INPUT, {left, right}, &grip), XR_SUCCESS);
  ASSERT_EQ(create_action(set, "aim", XR_ACTION_TYPE_POSE_INPUT, {}, &aim), XR_SUCCESS);
  ASSERT_EQ(create_action(set, "buzz", XR_ACTION_TYPE_VIBRATION_OUTPUT, {left, right}, &buzz), XR_SUCCESS);
  ASSERT_EQ(create_action(set, "unbound", XR_ACTION_TYPE_BOOLEAN_INPUT, {}, &unbound), XR_SUCCESS);
  const char* kSimple = "/interaction_profiles/khr/simple_controller";
  ASSERT_EQ(suggest(instance, kSimple,
                    {{select, "/user/hand/left/input/select/click"},
                     {select, "/user/hand/right/input/select"},  // the identifier: .../click
                     {squeeze, "/user/hand/left/input/select/click"},
                     {squeeze, "/user/hand/right/input/select/click"},
                     {grip, "/user/hand/left/input/grip/pose"},
                     {grip, "/user/hand/right/input/grip"},  // the identifier: .../pose
                     {aim, "/user/hand/right/input/aim/pose"},
                     {buzz, "/user/hand/left/output/haptic"},
                     {unbound, "/user/hand/left/input/grip/pose"}}),  // a pose for a boolean: never binds
            XR_SUCCESS);

  const XrSession session = begin_headless_session(instance);
  auto profile = make<XrInteractionProfileState>(XR_TYPE_INTERACTION_PROFILE_STATE);
  EXPECT_EQ(xrGetCurrentInteractionProfile(session, left, &profile), XR_ERROR_ACTIONSET_NOT_ATTACHED);
  const XrSpace grip_left = create_action_space(session, grip, left);  // before attach: allowed
  ASSERT_EQ(attach(session, {set}), XR_SUCCESS);
  const XrSpace grip_right = create_action_space(session, grip, right);
  const XrPosef offset{{0.0f, 0.38268343f, 0.0f, 0.92387953f}, {0.01f, -0.02f, 0.03f}};
  const XrSpace grip_right_offset = create_action_space(session, grip, right, offset);
  const XrSpace aim_any = create_action_space(session, aim, XR_NULL_PATH);
  const XrSpace local = create_space(session, XR_REFERENCE_SPACE_TYPE_LOCAL);
  const XrSpace stage = create_space(session, XR_REFERENCE_SPACE_TYPE_STAGE);

  // Nothing is active and nothing is located before the first sync.
  EXPECT_FALSE(boolean_state(session, select, XR_NULL_PATH).isActive);
  EXPECT_EQ(locate(grip_left, local, mx::xr_time_now()).location.locationFlags, 0u);
  ASSERT_EQ(xrGetCurrentInteractionProfile(session, left, &profile), XR_SUCCESS);
  EXPECT_EQ(profile.interactionProfile, XR_NULL_PATH);

  const XrTime synced = sync_away_from_edges(session, {{set, XR_NULL_PATH}});
  EXPECT_TRUE(contains(drain_events(instance).types, XR_TYPE_EVENT_DATA_INTERACTION_PROFILE_CHANGED));
  for (XrPath hand : {left, right}) {
    ASSERT_EQ(xrGetCurrentInteractionProfile(session, hand, &profile), XR_SUCCESS);
    EXPECT_EQ(to_string(instance, profile.interactionProfile), kSimple);
  }
  EXPECT_EQ(xrGetCurrentInteractionProfile(session, to_path(instance, "/user/hand"), &profile),
            XR_ERROR_PATH_UNSUPPORTED);

  // select/click follows the schedule, per hand and combined (OR).
  const bool pressed_left = mx::select_pressed(mx::Hand::left, synced);
  const bool pressed_right = mx::select_pressed(mx::Hand::right, synced);
  const auto select_left = boolean_state(session, select, left);
  const auto select_right = boolean_state(session, select, right);
  const auto select_any = boolean_state(session, select, XR_NULL_PATH);
  EXPECT_TRUE(select_left.isActive && select_right.isActive && select_any.isActive);
  EXPECT_EQ(select_left.currentState, XrBool32(pressed_left));
  EXPECT_EQ(select_right.currentState, XrBool32(pressed_right));
  EXPECT_EQ(select_any.currentState, XrBool32(pressed_left || pressed_right));
  EXPECT_EQ(select_left.changedSinceLastSync, XrBool32(pressed_left));  // from inactive (false)
  const auto squeeze_right = action_state<XrActionStateFloat>(session, squeeze, right, XR_TYPE_ACTION_STATE_FLOAT);
  EXPECT_TRUE(squeeze_right.isActive);
  EXPECT_EQ(squeeze_right.currentState, pressed_right ? 1.0f : 0.0f);
  EXPECT_FALSE(boolean_state(session, unbound, XR_NULL_PATH).isActive);
  EXPECT_TRUE(pose_state(session, grip, left).isActive);
  EXPECT_TRUE(pose_state(session, aim, XR_NULL_PATH).isActive);

  // Over a few syncs the state tracks the schedule, and changes are flagged.
  bool saw_change = false;
  for (int i = 0; i < 6 && !saw_change; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    const bool was = boolean_state(session, select, left).currentState;
    const XrTime t = sync_away_from_edges(session, {{set, XR_NULL_PATH}});
    const auto now_state = boolean_state(session, select, left);
    EXPECT_EQ(now_state.currentState, XrBool32(mx::select_pressed(mx::Hand::left, t)));
    EXPECT_EQ(now_state.changedSinceLastSync, XrBool32(now_state.currentState != was));
    if (now_state.changedSinceLastSync) {
      saw_change = true;
      EXPECT_GE(now_state.lastChangeTime, t);
    }
  }
  EXPECT_TRUE(saw_change) << "select/click toggles every second";

  // Grip and aim spaces are the analytic poses at whatever time is asked.
  for (XrTime t : {mx::xr_time_now(), synced + 123'456'789}) {
    expect_located(locate(grip_left, local, t), mx::to_xr(mx::controller_grip(mx::Hand::left, t)));
    expect_located(locate(grip_right, local, t), mx::to_xr(mx::controller_grip(mx::Hand::right, t)));
    expect_located(locate(grip_right, stage, t), mx::locate(mx::controller_grip(mx::Hand::right, t),
                                                            XR_REFERENCE_SPACE_TYPE_STAGE, t));
    expect_located(locate(grip_right_offset, local, t),
                   mx::to_xr(mx::attach(mx::controller_grip(mx::Hand::right, t), mx::from_xr(offset))));
    expect_located(locate(aim_any, local, t), mx::to_xr(mx::controller_aim(mx::Hand::right, t)));
    // An action space as the base: the left grip seen from the right one.
    expect_located(locate(grip_left, grip_right, t),
                   mx::to_xr(mx::relative_motion(mx::controller_grip(mx::Hand::left, t),
                                                 mx::controller_grip(mx::Hand::right, t))));
  }
  // Within 1e-5 of the header's values, and the hands are where the README says.
  const mx::Pose grip_now = mx::controller_grip(mx::Hand::left, synced).pose;
  EXPECT_NEAR(grip_now.p.z, -0.40, 0.1);
  EXPECT_NEAR(grip_now.p.y, -0.32, 0.1);
  EXPECT_LT(grip_now.p.x, 0.0);

  // Bound sources, and haptics (checked, ignored).
  auto bound_info = make<XrBoundSourcesForActionEnumerateInfo>(XR_TYPE_BOUND_SOURCES_FOR_ACTION_ENUMERATE_INFO);
  bound_info.action = select;
  uint32_t count = 0;
  XrPath sources[4]{};
  ASSERT_EQ(xrEnumerateBoundSourcesForAction(session, &bound_info, 4, &count, sources), XR_SUCCESS);
  ASSERT_EQ(count, 2u);
  EXPECT_EQ(to_string(instance, sources[0]), "/user/hand/left/input/select/click");
  EXPECT_EQ(to_string(instance, sources[1]), "/user/hand/right/input/select/click");
  auto name_info = make<XrInputSourceLocalizedNameGetInfo>(XR_TYPE_INPUT_SOURCE_LOCALIZED_NAME_GET_INFO);
  name_info.sourcePath = sources[0];
  name_info.whichComponents = XR_INPUT_SOURCE_LOCALIZED_NAME_USER_PATH_BIT |
                              XR_INPUT_SOURCE_LOCALIZED_NAME_INTERACTION_PROFILE_BIT |
                              XR_INPUT_SOURCE_LOCALIZED_NAME_COMPONENT_BIT;
  char name[128] = {};
  ASSERT_EQ(xrGetInputSourceLocalizedName(session, &name_info, sizeof name, &count, name), XR_SUCCESS);
  EXPECT_STREQ(name, "Left Hand Simple Controller Select Click");
  auto haptic_info = make<XrHapticActionInfo>(XR_TYPE_HAPTIC_ACTION_INFO);
  haptic_info.action = buzz;
  auto vibration = make<XrHapticVibration>(XR_TYPE_HAPTIC_VIBRATION);
  vibration.duration = XR_MIN_HAPTIC_DURATION;
  vibration.amplitude = 0.5f;
  EXPECT_EQ(xrApplyHapticFeedback(session, &haptic_info, reinterpret_cast<const XrHapticBaseHeader*>(&vibration)),
            XR_SUCCESS);
  EXPECT_EQ(xrStopHapticFeedback(session, &haptic_info), XR_SUCCESS);
  haptic_info.action = select;
  EXPECT_EQ(xrStopHapticFeedback(session, &haptic_info), XR_ERROR_ACTION_TYPE_MISMATCH);

  // Refused once attached: suggesting for an attached set's actions, attaching
  // again, adding an action to the attached set.
  EXPECT_EQ(suggest(instance, kSimple, {{select, "/user/hand/left/input/menu/click"}}),
            XR_ERROR_ACTIONSETS_ALREADY_ATTACHED);
  EXPECT_EQ(attach(session, {set}), XR_ERROR_ACTIONSETS_ALREADY_ATTACHED);
  XrAction late = XR_NULL_HANDLE;
  EXPECT_EQ(create_action(set, "late", XR_ACTION_TYPE_BOOLEAN_INPUT, {}, &late), XR_ERROR_ACTIONSETS_ALREADY_ATTACHED);
  // A set that was never attached cannot be synced or queried here.
  XrActionSet other = XR_NULL_HANDLE;
  XrAction other_action = XR_NULL_HANDLE;
  ASSERT_EQ(create_action_set(instance, "other", "Other", &other), XR_SUCCESS);
  ASSERT_EQ(create_action(other, "other_select", XR_ACTION_TYPE_BOOLEAN_INPUT, {}, &other_action), XR_SUCCESS);
  EXPECT_EQ(sync(session, {{other, XR_NULL_PATH}}), XR_ERROR_ACTIONSET_NOT_ATTACHED);
  EXPECT_EQ(sync(session, {{set, XR_NULL_PATH}, {other, XR_NULL_PATH}}), XR_ERROR_ACTIONSET_NOT_ATTACHED);
  action_state<XrActionStateBoolean>(session, other_action, XR_NULL_PATH, XR_TYPE_ACTION_STATE_BOOLEAN,
                                     XR_ERROR_ACTIONSET_NOT_ATTACHED);
  // Wrong type, undeclared subaction path, a subaction path of no action in the set.
  action_state<XrActionStateFloat>(session, select, XR_NULL_PATH, XR_TYPE_ACTION_STATE_FLOAT,
                                   XR_ERROR_ACTION_TYPE_MISMATCH);
  action_state<XrActionStatePose>(session, aim, left, XR_TYPE_ACTION_STATE_POSE, XR_ERROR_PATH_UNSUPPORTED);
  EXPECT_EQ(sync(session, {{set, to_path(instance, "/user/head")}}), XR_ERROR_PATH_UNSUPPORTED);

  // Syncing the set for the right hand only: the left hand goes inactive.
  EXPECT_EQ(sync(session, {{set, right}}), XR_SUCCESS);
  EXPECT_FALSE(boolean_state(session, select, left).isActive);
  EXPECT_TRUE(boolean_state(session, select, right).isActive);
  EXPECT_EQ(locate(grip_left, local, mx::xr_time_now()).location.locationFlags, 0u);
  EXPECT_EQ(locate(grip_right, local, mx::xr_time_now()).location.locationFlags, XrSpaceLocationFlags{0xF});
  // Syncing no set: everything inactive, nothing located.
  EXPECT_EQ(sync(session, {}), XR_SUCCESS);
  EXPECT_FALSE(boolean_state(session, select, XR_NULL_PATH).isActive);
  EXPECT_FALSE(pose_state(session, grip, right).isActive);
  EXPECT_EQ(locate(grip_right, local, mx::xr_time_now()).location.locationFlags, 0u);

  // Destroying the set takes its actions; the spaces stay valid handles.
  EXPECT_EQ(xrDestroyActionSet(set), XR_SUCCESS);
  EXPECT_EQ(xrDestroyAction(select), XR_ERROR_HANDLE_INVALID);
  EXPECT_EQ(xrDestroySpace(grip_left), XR_SUCCESS);
  EXPECT_EQ(xrDestroySession(session), XR_SUCCESS);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

TEST_F(MockRuntime, ActionNamesPathsAndProfilesAreChecked) {
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  XrActionSet set = XR_NULL_HANDLE, spare = XR_NULL_HANDLE;
  EXPECT_EQ(create_action_set(instance, "", "Empty", &spare), XR_ERROR_NAME_INVALID);
  EXPECT_EQ(create_action_set(instance, "Upper", "Upper", &spare), XR_ERROR_NAME_INVALID);
  EXPECT_EQ(create_action_set(instance, "a/b", "Slash", &spare), XR_ERROR_NAME_INVALID);
  EXPECT_EQ(create_action_set(instance, "nameless", "", &spare), XR_ERROR_LOCALIZED_NAME_INVALID);
  ASSERT_EQ(create_action_set(instance, "main", "Main", &set), XR_SUCCESS);
  EXPECT_EQ(create_action_set(instance, "main", "Main again", &spare), XR_ERROR_NAME_DUPLICATED);
  EXPECT_EQ(create_action_set(instance, "main2", "Main", &spare), XR_ERROR_LOCALIZED_NAME_DUPLICATED);

  const XrPath left = to_path(instance, "/user/hand/left");
  XrAction action = XR_NULL_HANDLE, spare_action = XR_NULL_HANDLE;
  ASSERT_EQ(create_action(set, "fire", XR_ACTION_TYPE_BOOLEAN_INPUT, {left}, &action, "Fire"), XR_SUCCESS);
  EXPECT_EQ(create_action(set, "fire", XR_ACTION_TYPE_BOOLEAN_INPUT, {}, &spare_action, "Other"),
            XR_ERROR_NAME_DUPLICATED);
  EXPECT_EQ(create_action(set, "shoot", XR_ACTION_TYPE_BOOLEAN_INPUT, {}, &spare_action, "Fire"),
            XR_ERROR_LOCALIZED_NAME_DUPLICATED);
  EXPECT_EQ(create_action(set, "bad name", XR_ACTION_TYPE_BOOLEAN_INPUT, {}, &spare_action), XR_ERROR_NAME_INVALID);
  EXPECT_EQ(create_action(set, "typeless", static_cast<XrActionType>(7), {}, &spare_action),
            XR_ERROR_VALIDATION_FAILURE);
  EXPECT_EQ(create_action(set, "twice", XR_ACTION_TYPE_BOOLEAN_INPUT, {left, left}, &spare_action),
            XR_ERROR_PATH_UNSUPPORTED);
  EXPECT_EQ(create_action(set, "nohand", XR_ACTION_TYPE_BOOLEAN_INPUT, {to_path(instance, "/user/hand")},
                          &spare_action),
            XR_ERROR_PATH_UNSUPPORTED);
  EXPECT_EQ(create_action(set, "input", XR_ACTION_TYPE_BOOLEAN_INPUT,
                          {to_path(instance, "/user/hand/left/input/select/click")}, &spare_action),
            XR_ERROR_PATH_UNSUPPORTED);
  EXPECT_EQ(create_action(set, "bogus", XR_ACTION_TYPE_BOOLEAN_INPUT, {XrPath{0xdead}}, &spare_action),
            XR_ERROR_PATH_INVALID);
  // Tracker roles are top-level paths only with XR_HTCX_vive_tracker_interaction.
  EXPECT_EQ(create_action(set, "tracker", XR_ACTION_TYPE_POSE_INPUT,
                          {to_path(instance, "/user/vive_tracker_htcx/role/left_wrist")}, &spare_action),
            XR_ERROR_PATH_UNSUPPORTED);
  ASSERT_EQ(create_action(set, "head", XR_ACTION_TYPE_BOOLEAN_INPUT, {to_path(instance, "/user/head")}, &spare_action),
            XR_SUCCESS);

  // Suggestions: known profiles and their bindings only.
  EXPECT_EQ(suggest(instance, "/interaction_profiles/valve/index_controller",
                    {{action, "/user/hand/left/input/trigger/click"}}),
            XR_ERROR_PATH_UNSUPPORTED);
  EXPECT_EQ(suggest(instance, "/interaction_profiles/htc/vive_tracker_htcx",
                    {{action, "/user/vive_tracker_htcx/role/left_wrist/input/menu/click"}}),
            XR_ERROR_PATH_UNSUPPORTED);
  const char* kSimple = "/interaction_profiles/khr/simple_controller";
  for (const char* wrong : {"/user/hand/left/input/trigger/click", "/user/hand/left/input/select/value",
                            "/user/hand/left/input", "/user/hand/left", "/user/head/input/select/click",
                            "/user/hand/left/output/haptic/foo"}) {
    EXPECT_EQ(suggest(instance, kSimple, {{action, wrong}}), XR_ERROR_PATH_UNSUPPORTED) << wrong;
  }
  auto empty = make<XrInteractionProfileSuggestedBinding>(XR_TYPE_INTERACTION_PROFILE_SUGGESTED_BINDING);
  empty.interactionProfile = to_path(instance, kSimple);
  EXPECT_EQ(xrSuggestInteractionProfileBindings(instance, &empty), XR_ERROR_VALIDATION_FAILURE);

  // A later suggestion for the same profile replaces the earlier one.
  ASSERT_EQ(suggest(instance, kSimple, {{action, "/user/hand/left/input/select/click"}}), XR_SUCCESS);
  ASSERT_EQ(suggest(instance, kSimple, {{action, "/user/hand/left/input/menu/click"}}), XR_SUCCESS);
  const XrSession session = begin_headless_session(instance);
  ASSERT_EQ(attach(session, {set}), XR_SUCCESS);
  ASSERT_EQ(sync(session, {{set, XR_NULL_PATH}}), XR_SUCCESS);
  auto bound_info = make<XrBoundSourcesForActionEnumerateInfo>(XR_TYPE_BOUND_SOURCES_FOR_ACTION_ENUMERATE_INFO);
  bound_info.action = action;
  uint32_t count = 0;
  XrPath sources[2]{};
  ASSERT_EQ(xrEnumerateBoundSourcesForAction(session, &bound_info, 2, &count, sources), XR_SUCCESS);
  ASSERT_EQ(count, 1u);
  EXPECT_EQ(to_string(instance, sources[0]), "/user/hand/left/input/menu/click");
  const auto menu = boolean_state(session, action, left);
  EXPECT_TRUE(menu.isActive);
  EXPECT_FALSE(menu.currentState);  // menu/click is never pressed

  // The spec's rule: refused for attached sets' actions, allowed for others.
  XrActionSet later = XR_NULL_HANDLE;
  XrAction later_action = XR_NULL_HANDLE;
  ASSERT_EQ(create_action_set(instance, "later", "Later", &later), XR_SUCCESS);
  ASSERT_EQ(create_action(later, "later_select", XR_ACTION_TYPE_BOOLEAN_INPUT, {}, &later_action), XR_SUCCESS);
  EXPECT_EQ(suggest(instance, kSimple, {{action, "/user/hand/left/input/select/click"}}),
            XR_ERROR_ACTIONSETS_ALREADY_ATTACHED);
  EXPECT_EQ(suggest(instance, kSimple, {{later_action, "/user/hand/left/input/select/click"}}), XR_SUCCESS);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

// xrSyncActions outside FOCUSED answers XR_SESSION_NOT_FOCUSED and leaves
// every action inactive.
TEST_F(MockRuntime, SyncNeedsFocus) {
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  XrActionSet set = XR_NULL_HANDLE;
  XrAction grip = XR_NULL_HANDLE;
  ASSERT_EQ(create_action_set(instance, "main", "Main", &set), XR_SUCCESS);
  ASSERT_EQ(create_action(set, "grip", XR_ACTION_TYPE_POSE_INPUT, {}, &grip), XR_SUCCESS);
  ASSERT_EQ(suggest(instance, "/interaction_profiles/khr/simple_controller",
                    {{grip, "/user/hand/left/input/grip/pose"}}),
            XR_SUCCESS);
  auto info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  info.systemId = get_hmd(instance);
  XrSession session = XR_NULL_HANDLE;
  ASSERT_EQ(xrCreateSession(instance, &info, &session), XR_SUCCESS);
  EXPECT_EQ(sync(session, {{set, XR_NULL_PATH}}), XR_ERROR_ACTIONSET_NOT_ATTACHED);
  ASSERT_EQ(attach(session, {set}), XR_SUCCESS);
  EXPECT_EQ(sync(session, {{set, XR_NULL_PATH}}), XR_SESSION_NOT_FOCUSED);  // READY
  EXPECT_FALSE(pose_state(session, grip, XR_NULL_PATH).isActive);
  auto begin = make<XrSessionBeginInfo>(XR_TYPE_SESSION_BEGIN_INFO);
  begin.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  ASSERT_EQ(xrBeginSession(session, &begin), XR_SUCCESS);
  EXPECT_EQ(sync(session, {{set, XR_NULL_PATH}}), XR_SUCCESS);
  EXPECT_TRUE(pose_state(session, grip, XR_NULL_PATH).isActive);
  ASSERT_EQ(xrRequestExitSession(session), XR_SUCCESS);  // down to STOPPING
  EXPECT_EQ(sync(session, {{set, XR_NULL_PATH}}), XR_SESSION_NOT_FOCUSED);
  EXPECT_FALSE(pose_state(session, grip, XR_NULL_PATH).isActive);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

// Of two active sets binding the same input source, the higher priority wins
// (the spec's rule a layer's own set must not trip over).
TEST_F(MockRuntime, HigherPrioritySetHidesASharedInput) {
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  XrActionSet low = XR_NULL_HANDLE, high = XR_NULL_HANDLE;
  ASSERT_EQ(create_action_set(instance, "low", "Low", &low, 0), XR_SUCCESS);
  ASSERT_EQ(create_action_set(instance, "high", "High", &high, 5), XR_SUCCESS);
  XrAction low_grip = XR_NULL_HANDLE, low_aim = XR_NULL_HANDLE, high_grip = XR_NULL_HANDLE;
  ASSERT_EQ(create_action(low, "grip", XR_ACTION_TYPE_POSE_INPUT, {}, &low_grip), XR_SUCCESS);
  ASSERT_EQ(create_action(low, "aim", XR_ACTION_TYPE_POSE_INPUT, {}, &low_aim), XR_SUCCESS);
  ASSERT_EQ(create_action(high, "grip", XR_ACTION_TYPE_POSE_INPUT, {}, &high_grip), XR_SUCCESS);
  ASSERT_EQ(suggest(instance, "/interaction_profiles/khr/simple_controller",
                    {{low_grip, "/user/hand/left/input/grip/pose"},
                     {low_aim, "/user/hand/left/input/aim/pose"},
                     {high_grip, "/user/hand/left/input/grip/pose"}}),
            XR_SUCCESS);
  const XrSession session = begin_headless_session(instance);
  ASSERT_EQ(attach(session, {low, high}), XR_SUCCESS);
  ASSERT_EQ(sync(session, {{low, XR_NULL_PATH}, {high, XR_NULL_PATH}}), XR_SUCCESS);
  EXPECT_FALSE(pose_state(session, low_grip, XR_NULL_PATH).isActive);
  EXPECT_TRUE(pose_state(session, low_aim, XR_NULL_PATH).isActive);
  EXPECT_TRUE(pose_state(session, high_grip, XR_NULL_PATH).isActive);
  ASSERT_EQ(sync(session, {{low, XR_NULL_PATH}}), XR_SUCCESS);  // the high set inactive: no conflict
  EXPECT_TRUE(pose_state(session, low_grip, XR_NULL_PATH).isActive);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

TEST_F(MockRuntime, ViveTrackersOnlyWithTheExtension) {
  const auto extensions = instance_extensions();
  ASSERT_NE(std::find(extensions.begin(), extensions.end(), XR_HTCX_VIVE_TRACKER_INTERACTION_EXTENSION_NAME),
            extensions.end());
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  PFN_xrVoidFunction f = nullptr;
  EXPECT_EQ(xrGetInstanceProcAddr(instance, "xrEnumerateViveTrackerPathsHTCX", &f), XR_ERROR_FUNCTION_UNSUPPORTED);
  EXPECT_FALSE(contains(drain_events(instance).types, XR_TYPE_EVENT_DATA_VIVE_TRACKER_CONNECTED_HTCX));
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);

  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME, XR_HTCX_VIVE_TRACKER_INTERACTION_EXTENSION_NAME},
                            &instance),
            XR_SUCCESS);
  // Both trackers announce themselves, with the paths they enumerate with.
  const Events events = drain_events(instance);
  ASSERT_EQ(events.trackers.size(), 2u);
  auto enumerate = get_proc<PFN_xrEnumerateViveTrackerPathsHTCX>(instance, "xrEnumerateViveTrackerPathsHTCX");
  ASSERT_NE(enumerate, nullptr);
  uint32_t count = 0;
  ASSERT_EQ(enumerate(instance, 0, &count, nullptr), XR_SUCCESS);
  ASSERT_EQ(count, 2u);
  std::vector paths(2, make<XrViveTrackerPathsHTCX>(XR_TYPE_VIVE_TRACKER_PATHS_HTCX));
  EXPECT_EQ(enumerate(instance, 1, &count, paths.data()), XR_ERROR_SIZE_INSUFFICIENT);
  ASSERT_EQ(enumerate(instance, 2, &count, paths.data()), XR_SUCCESS);
  EXPECT_EQ(to_string(instance, paths[0].persistentPath), "/devices/htc/vive_trackerLHR-MOCK0001");
  EXPECT_EQ(to_string(instance, paths[0].rolePath), "/user/vive_tracker_htcx/role/left_wrist");
  EXPECT_EQ(to_string(instance, paths[1].persistentPath), "/devices/htc/vive_trackerLHR-MOCK0002");
  EXPECT_EQ(to_string(instance, paths[1].rolePath), "/user/vive_tracker_htcx/role/right_wrist");
  for (std::size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(events.trackers[i].persistentPath, paths[i].persistentPath);
    EXPECT_EQ(events.trackers[i].rolePath, paths[i].rolePath);
  }

  // Tracker actions: the layer's own set, next to an app set that binds the controllers.
  const XrPath left_wrist = paths[0].rolePath, right_wrist = paths[1].rolePath;
  XrActionSet app = XR_NULL_HANDLE, layer = XR_NULL_HANDLE;
  ASSERT_EQ(create_action_set(instance, "app", "App", &app), XR_SUCCESS);
  ASSERT_EQ(create_action_set(instance, "proprio", "Proprio", &layer), XR_SUCCESS);
  XrAction app_grip = XR_NULL_HANDLE, wrist = XR_NULL_HANDLE;
  ASSERT_EQ(create_action(app, "grip", XR_ACTION_TYPE_POSE_INPUT, {}, &app_grip), XR_SUCCESS);
  ASSERT_EQ(create_action(layer, "wrist", XR_ACTION_TYPE_POSE_INPUT, {left_wrist, right_wrist}, &wrist), XR_SUCCESS);
  ASSERT_EQ(suggest(instance, "/interaction_profiles/khr/simple_controller",
                    {{app_grip, "/user/hand/right/input/grip/pose"}}),
            XR_SUCCESS);
  EXPECT_EQ(suggest(instance, "/interaction_profiles/htc/vive_tracker_htcx",
                    {{wrist, "/user/vive_tracker_htcx/role/left_wrist/input/aim/pose"}}),
            XR_ERROR_PATH_UNSUPPORTED);  // trackers have no aim
  ASSERT_EQ(suggest(instance, "/interaction_profiles/htc/vive_tracker_htcx",
                    {{wrist, "/user/vive_tracker_htcx/role/left_wrist/input/grip/pose"},
                     {wrist, "/user/vive_tracker_htcx/role/right_wrist/input/grip/pose"},
                     {wrist, "/user/vive_tracker_htcx/role/waist/input/grip/pose"}}),  // no such tracker
            XR_SUCCESS);
  const XrSession session = begin_headless_session(instance);
  ASSERT_EQ(attach(session, {app, layer}), XR_SUCCESS);
  const XrSpace left_space = create_action_space(session, wrist, left_wrist);
  const XrSpace right_space = create_action_space(session, wrist, right_wrist);
  const XrSpace app_space = create_action_space(session, app_grip, XR_NULL_PATH);
  const XrSpace local = create_space(session, XR_REFERENCE_SPACE_TYPE_LOCAL);
  ASSERT_EQ(sync(session, {{app, XR_NULL_PATH}, {layer, XR_NULL_PATH}}), XR_SUCCESS);
  EXPECT_TRUE(contains(drain_events(instance).types, XR_TYPE_EVENT_DATA_INTERACTION_PROFILE_CHANGED));
  auto profile = make<XrInteractionProfileState>(XR_TYPE_INTERACTION_PROFILE_STATE);
  ASSERT_EQ(xrGetCurrentInteractionProfile(session, left_wrist, &profile), XR_SUCCESS);
  EXPECT_EQ(to_string(instance, profile.interactionProfile), "/interaction_profiles/htc/vive_tracker_htcx");
  ASSERT_EQ(xrGetCurrentInteractionProfile(session, to_path(instance, "/user/vive_tracker_htcx/role/waist"), &profile),
            XR_SUCCESS);
  EXPECT_EQ(profile.interactionProfile, XR_NULL_PATH);
  EXPECT_TRUE(pose_state(session, wrist, left_wrist).isActive);
  EXPECT_TRUE(pose_state(session, app_grip, XR_NULL_PATH).isActive);
  for (XrTime t : {mx::xr_time_now(), mx::xr_time_now() + 987'654'321}) {
    expect_located(locate(left_space, local, t), mx::to_xr(mx::tracker_pose(mx::Hand::left, t)));
    expect_located(locate(right_space, local, t), mx::to_xr(mx::tracker_pose(mx::Hand::right, t)));
    expect_located(locate(app_space, local, t), mx::to_xr(mx::controller_grip(mx::Hand::right, t)));
    // The wrist is the tracker composed with tracker_to_wrist.
    const mx::Motion wrist_left = mx::wrist_pose(mx::Hand::left, t);
    const Location tracker = locate(left_space, local, t);
    expect_near(mx::to_xr(mx::compose(mx::from_xr(tracker.location.pose), mx::tracker_to_wrist(mx::Hand::left))),
                mx::to_xr(wrist_left.pose));
  }
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

// PROPRIO_MOCK_RUNTIME_CONTROLLERS=0, _TRACKERS=0 and _DISCONNECT.
TEST_F(MockRuntime, DevicesCanBeAbsentOrScripted) {
  auto app_with_grips = [](XrInstance instance, XrActionSet* set, XrAction* grip) {
    const XrPath left = to_path(instance, "/user/hand/left"), right = to_path(instance, "/user/hand/right");
    ASSERT_EQ(create_action_set(instance, "main", "Main", set), XR_SUCCESS);
    ASSERT_EQ(create_action(*set, "grip", XR_ACTION_TYPE_POSE_INPUT, {left, right}, grip), XR_SUCCESS);
    ASSERT_EQ(suggest(instance, "/interaction_profiles/khr/simple_controller",
                      {{*grip, "/user/hand/left/input/grip/pose"}, {*grip, "/user/hand/right/input/grip/pose"}}),
              XR_SUCCESS);
  };
  XrInstance instance = XR_NULL_HANDLE;
  XrActionSet set = XR_NULL_HANDLE;
  XrAction grip = XR_NULL_HANDLE;
  {
    ScopedEnv no_controllers("PROPRIO_MOCK_RUNTIME_CONTROLLERS", "0");
    ScopedEnv no_trackers("PROPRIO_MOCK_RUNTIME_TRACKERS", "0");
    ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME, XR_HTCX_VIVE_TRACKER_INTERACTION_EXTENSION_NAME},
                              &instance),
              XR_SUCCESS);
    EXPECT_TRUE(drain_events(instance).trackers.empty());
    auto enumerate = get_proc<PFN_xrEnumerateViveTrackerPathsHTCX>(instance, "xrEnumerateViveTrackerPathsHTCX");
    uint32_t count = 99;
    ASSERT_EQ(enumerate(instance, 0, &count, nullptr), XR_SUCCESS);
    EXPECT_EQ(count, 0u);
    app_with_grips(instance, &set, &grip);
    const XrSession session = begin_headless_session(instance);
    ASSERT_EQ(attach(session, {set}), XR_SUCCESS);
    const XrSpace space = create_action_space(session, grip, XR_NULL_PATH);
    const XrSpace local = create_space(session, XR_REFERENCE_SPACE_TYPE_LOCAL);
    ASSERT_EQ(sync(session, {{set, XR_NULL_PATH}}), XR_SUCCESS);
    EXPECT_FALSE(pose_state(session, grip, XR_NULL_PATH).isActive);
    EXPECT_EQ(locate(space, local, mx::xr_time_now()).location.locationFlags, 0u);
    EXPECT_FALSE(contains(drain_events(instance).types, XR_TYPE_EVENT_DATA_INTERACTION_PROFILE_CHANGED));
    EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
  }

  // The left controller is gone for the first 0.5 s after xrCreateSession and
  // the right one between 2 and 3 s; the left tracker for the first 0.3 s
  // after xrCreateInstance (and again after xrCreateSession).
  ScopedEnv script("PROPRIO_MOCK_RUNTIME_DISCONNECT",
                   "left_controller:0-0.5,right_controller:2-3,left_tracker:0-0.3,bogus:1-2");
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME, XR_HTCX_VIVE_TRACKER_INTERACTION_EXTENSION_NAME},
                            &instance),
            XR_SUCCESS);
  auto enumerate = get_proc<PFN_xrEnumerateViveTrackerPathsHTCX>(instance, "xrEnumerateViveTrackerPathsHTCX");
  EXPECT_EQ(drain_events(instance).trackers.size(), 1u);  // the right one
  app_with_grips(instance, &set, &grip);
  const XrTime before_session = mx::xr_time_now();
  const XrSession session = begin_headless_session(instance);
  const XrTime after_session = mx::xr_time_now();
  // The windows start somewhere in [before_session, after_session].
  ASSERT_LT(after_session - before_session, 400'000'000) << "too slow to see the scripted windows";
  ASSERT_EQ(attach(session, {set}), XR_SUCCESS);
  const XrPath left = to_path(instance, "/user/hand/left"), right = to_path(instance, "/user/hand/right");
  const XrSpace left_space = create_action_space(session, grip, left);
  const XrSpace right_space = create_action_space(session, grip, right);
  const XrSpace local = create_space(session, XR_REFERENCE_SPACE_TYPE_LOCAL);
  ASSERT_EQ(sync(session, {{set, XR_NULL_PATH}}), XR_SUCCESS);
  ASSERT_LT(mx::xr_time_now(), after_session + 400'000'000) << "too slow to see the scripted window";
  EXPECT_FALSE(pose_state(session, grip, left).isActive);
  EXPECT_TRUE(pose_state(session, grip, right).isActive);
  // Located at the time asked: the right controller is untracked inside its window.
  EXPECT_EQ(locate(right_space, local, after_session + 1'000'000'000).location.locationFlags,
            XrSpaceLocationFlags{0xF});
  EXPECT_EQ(locate(right_space, local, after_session + 2'500'000'000).location.locationFlags, 0u);
  EXPECT_EQ(locate(right_space, local, after_session + 3'000'000'000).location.locationFlags,
            XrSpaceLocationFlags{0xF});
  drain_events(instance);

  std::this_thread::sleep_for(std::chrono::milliseconds(550));
  ASSERT_EQ(sync(session, {{set, XR_NULL_PATH}}), XR_SUCCESS);
  EXPECT_TRUE(pose_state(session, grip, left).isActive);
  const XrTime now = mx::xr_time_now();
  expect_located(locate(left_space, local, now), mx::to_xr(mx::controller_grip(mx::Hand::left, now)));
  const Events events = drain_events(instance);
  EXPECT_TRUE(contains(events.types, XR_TYPE_EVENT_DATA_INTERACTION_PROFILE_CHANGED));  // the left hand came
  ASSERT_EQ(events.trackers.size(), 1u);  // the left tracker came back
  uint32_t count = 0;
  ASSERT_EQ(enumerate(instance, 0, &count, nullptr), XR_SUCCESS);
  EXPECT_EQ(count, 2u);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

// PROPRIO_MOCK_RUNTIME_HAND_TRACKING=moving: the native wrist follows
// mx::wrist_pose, the other joints ride on it, and the hand is lost for 0.5 s
// of every 4 s.
TEST_F(MockRuntime, MovingNativeHand) {
  ScopedEnv native("PROPRIO_MOCK_RUNTIME_HAND_TRACKING", "moving");
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME, XR_EXT_HAND_TRACKING_EXTENSION_NAME}, &instance),
            XR_SUCCESS);
  auto session_info = make<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  session_info.systemId = get_hmd(instance);
  XrSession session = XR_NULL_HANDLE;
  ASSERT_EQ(xrCreateSession(instance, &session_info, &session), XR_SUCCESS);
  const XrSpace local = create_space(session, XR_REFERENCE_SPACE_TYPE_LOCAL);
  const XrSpace view = create_space(session, XR_REFERENCE_SPACE_TYPE_VIEW);
  auto create = get_proc<PFN_xrCreateHandTrackerEXT>(instance, "xrCreateHandTrackerEXT");
  auto locate_joints = get_proc<PFN_xrLocateHandJointsEXT>(instance, "xrLocateHandJointsEXT");
  ASSERT_TRUE(create && locate_joints);

  for (const mx::Hand hand : {mx::Hand::left, mx::Hand::right}) {
    auto tracker_info = make<XrHandTrackerCreateInfoEXT>(XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT);
    tracker_info.hand = hand == mx::Hand::left ? XR_HAND_LEFT_EXT : XR_HAND_RIGHT_EXT;
    tracker_info.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
    XrHandTrackerEXT tracker = XR_NULL_HANDLE;
    ASSERT_EQ(create(session, &tracker_info, &tracker), XR_SUCCESS);
    std::vector<XrHandJointLocationEXT> joints(XR_HAND_JOINT_COUNT_EXT);
    std::vector<XrHandJointVelocityEXT> joint_velocities(XR_HAND_JOINT_COUNT_EXT);
    auto velocities = make<XrHandJointVelocitiesEXT>(XR_TYPE_HAND_JOINT_VELOCITIES_EXT);
    velocities.jointCount = XR_HAND_JOINT_COUNT_EXT;
    velocities.jointVelocities = joint_velocities.data();
    auto locations = make<XrHandJointLocationsEXT>(XR_TYPE_HAND_JOINT_LOCATIONS_EXT);
    locations.next = &velocities;
    locations.jointCount = XR_HAND_JOINT_COUNT_EXT;
    locations.jointLocations = joints.data();
    auto locate_info = make<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);

    // Times in the tracked part of the cycle, then in the lost window.
    const XrTime cycle = (mx::xr_time_now() / mx::kNativeHandPeriodNs + 10) * mx::kNativeHandPeriodNs +
                         mx::native_hand_phase_ns(hand);
    for (XrTime t : {cycle + 100'000'000, cycle + 1'700'000'000, cycle + 3'499'000'000}) {
      ASSERT_TRUE(mx::native_hand_tracked(hand, t));
      for (XrSpace base : {local, view}) {
        locate_info.baseSpace = base;
        locate_info.time = t;
        ASSERT_EQ(locate_joints(tracker, &locate_info, &locations), XR_SUCCESS);
        EXPECT_TRUE(locations.isActive);
        const XrReferenceSpaceType base_type =
            base == local ? XR_REFERENCE_SPACE_TYPE_LOCAL : XR_REFERENCE_SPACE_TYPE_VIEW;
        const mx::Located wrist = mx::locate(mx::wrist_pose(hand, t), base_type, t);
        expect_near(joints[XR_HAND_JOINT_WRIST_EXT].pose, wrist.pose);
        expect_near(joint_velocities[XR_HAND_JOINT_WRIST_EXT].linearVelocity, wrist.linear_velocity);
        expect_near(joint_velocities[XR_HAND_JOINT_WRIST_EXT].angularVelocity, wrist.angular_velocity);
        for (uint32_t j = 0; j < XR_HAND_JOINT_COUNT_EXT; ++j) {
          const mx::Located expected =
              mx::locate(mx::native_joint(hand, static_cast<XrHandJointEXT>(j), t), base_type, t);
          expect_near(joints[j].pose, expected.pose);
          EXPECT_EQ(joints[j].locationFlags, XrSpaceLocationFlags{0xF});
          EXPECT_GT(joints[j].radius, 0.0f);
          EXPECT_EQ(joint_velocities[j].velocityFlags, XrSpaceVelocityFlags{0x3});
        }
      }
    }
    // The index tip is about 17.5 cm from the wrist; the thumb on the inner side.
    locate_info.baseSpace = local;
    locate_info.time = cycle + 100'000'000;
    ASSERT_EQ(locate_joints(tracker, &locate_info, &locations), XR_SUCCESS);
    const XrVector3f& w = joints[XR_HAND_JOINT_WRIST_EXT].pose.position;
    const XrVector3f& tip = joints[XR_HAND_JOINT_INDEX_TIP_EXT].pose.position;
    EXPECT_NEAR(std::hypot(tip.x - w.x, tip.y - w.y, tip.z - w.z), 0.177, 0.005);
    for (XrTime t : {cycle + 3'500'000'000, cycle + 3'999'999'999}) {
      ASSERT_FALSE(mx::native_hand_tracked(hand, t));
      locate_info.time = t;
      ASSERT_EQ(locate_joints(tracker, &locate_info, &locations), XR_SUCCESS);
      EXPECT_FALSE(locations.isActive);
      for (uint32_t j = 0; j < XR_HAND_JOINT_COUNT_EXT; ++j) {
        EXPECT_EQ(joints[j].locationFlags, 0u);
        EXPECT_EQ(joint_velocities[j].velocityFlags, 0u);
      }
    }
  }
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
}

// The runtime's own contract, without the loader in between (the loader
// checks some of these itself, which would hide the runtime's answers).
TEST(MockRuntimeDirect, NegotiatesAndValidates) {
  void* module = dlopen(PROPRIO_MOCK_RUNTIME_LIBRARY, RTLD_NOW | RTLD_LOCAL);
  ASSERT_NE(module, nullptr) << dlerror();
  auto negotiate = reinterpret_cast<PFN_xrNegotiateLoaderRuntimeInterface>(
      dlsym(module, "xrNegotiateLoaderRuntimeInterface"));
  ASSERT_NE(negotiate, nullptr);
  EXPECT_EQ(dlsym(module, "xrGetInstanceProcAddr"), nullptr) << "only the negotiation function is exported";

  XrNegotiateLoaderInfo info{XR_LOADER_INTERFACE_STRUCT_LOADER_INFO, PROPRIO_XR_LOADER_INFO_STRUCT_VERSION,
                             sizeof(XrNegotiateLoaderInfo), 1, 1, XR_MAKE_VERSION(1, 0, 0),
                             XR_MAKE_VERSION(1, 0x3ff, 0xfff)};
  XrNegotiateRuntimeRequest request{XR_LOADER_INTERFACE_STRUCT_RUNTIME_REQUEST, PROPRIO_XR_RUNTIME_INFO_STRUCT_VERSION,
                                    sizeof(XrNegotiateRuntimeRequest), 0, 0, nullptr};
  info.minInterfaceVersion = 2;  // a loader this runtime is too old for
  info.maxInterfaceVersion = 3;
  EXPECT_EQ(negotiate(&info, &request), XR_ERROR_INITIALIZATION_FAILED);
  info.minInterfaceVersion = info.maxInterfaceVersion = 1;
  ASSERT_EQ(negotiate(&info, &request), XR_SUCCESS);
  EXPECT_EQ(request.runtimeInterfaceVersion, 1u);
  EXPECT_EQ(request.runtimeApiVersion, XR_CURRENT_API_VERSION);
  const PFN_xrGetInstanceProcAddr gipa = request.getInstanceProcAddr;
  ASSERT_NE(gipa, nullptr);

  PFN_xrVoidFunction f = nullptr;
  EXPECT_EQ(gipa(XR_NULL_HANDLE, "xrGetSystem", &f), XR_ERROR_HANDLE_INVALID);
  ASSERT_EQ(gipa(XR_NULL_HANDLE, "xrCreateInstance", &f), XR_SUCCESS);
  auto create = reinterpret_cast<PFN_xrCreateInstance>(f);
  auto info_ci = make<XrInstanceCreateInfo>(XR_TYPE_INSTANCE_CREATE_INFO);
  std::snprintf(info_ci.applicationInfo.applicationName, XR_MAX_APPLICATION_NAME_SIZE, "direct");
  info_ci.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
  XrInstance instance = XR_NULL_HANDLE;
  EXPECT_EQ(create(&info_ci, nullptr), XR_ERROR_VALIDATION_FAILURE);
  ASSERT_EQ(create(&info_ci, &instance), XR_SUCCESS);

  EXPECT_EQ(gipa(instance, "xrNoSuchFunction", &f), XR_ERROR_FUNCTION_UNSUPPORTED);
  EXPECT_EQ(f, nullptr);
  ASSERT_EQ(gipa(instance, "xrGetSystem", &f), XR_SUCCESS);
  auto get_system = reinterpret_cast<PFN_xrGetSystem>(f);
  auto system_info = make<XrSystemGetInfo>(XR_TYPE_SYSTEM_PROPERTIES);  // wrong type
  system_info.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  EXPECT_EQ(get_system(instance, &system_info, &system), XR_ERROR_VALIDATION_FAILURE);
  system_info.type = XR_TYPE_SYSTEM_GET_INFO;
  EXPECT_EQ(get_system(instance, &system_info, nullptr), XR_ERROR_VALIDATION_FAILURE);
  EXPECT_EQ(get_system(to_handle<XrInstance>(0xdead), &system_info, &system), XR_ERROR_HANDLE_INVALID);
  EXPECT_EQ(get_system(instance, &system_info, &system), XR_SUCCESS);

  ASSERT_EQ(gipa(instance, "xrDestroyInstance", &f), XR_SUCCESS);
  auto destroy = reinterpret_cast<PFN_xrDestroyInstance>(f);
  EXPECT_EQ(destroy(instance), XR_SUCCESS);
  EXPECT_EQ(destroy(instance), XR_ERROR_HANDLE_INVALID);
  EXPECT_EQ(get_system(instance, &system_info, &system), XR_ERROR_HANDLE_INVALID);
  dlclose(module);
}

// Debian's core_validation layer stacked on the mock runtime: the same app
// must raise no validation error, and deliberate misuse must raise one (so
// the check above is not vacuous).
class MockRuntimeUnderCoreValidation : public MockRuntime {
 protected:
  void SetUp() override {
    bool found = false;
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator(PROPRIO_XR_EXPLICIT_LAYER_DIR, ec)) {
      found |= entry.path().filename().string().starts_with("XrApiLayer_core_validation");
    }
    if (!found) GTEST_SKIP() << "openxr-layer-corevalidation is not installed in " PROPRIO_XR_EXPLICIT_LAYER_DIR;
    std::filesystem::remove(report_);
  }
  std::string report() const {
    std::ifstream in(report_);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  }

  std::filesystem::path report_ = std::filesystem::temp_directory_path() /
                                  ("mock_runtime_core_validation_" + std::to_string(getpid()) + ".txt");
  ScopedEnv layer_path_{"XR_API_LAYER_PATH", PROPRIO_XR_EXPLICIT_LAYER_DIR};
  ScopedEnv enable_{"XR_ENABLE_API_LAYERS", "XR_APILAYER_LUNARG_core_validation"};
  ScopedEnv export_type_{"XR_CORE_VALIDATION_EXPORT_TYPE", "text"};
  ScopedEnv file_{"XR_CORE_VALIDATION_FILE_NAME", report_.c_str()};
};

TEST_F(MockRuntimeUnderCoreValidation, HeadlessAppRaisesNoValidationError) {
  run_headless_app();
  const std::string text = report();
  EXPECT_EQ(text.find("VALID_ERROR"), std::string::npos) << text;
  EXPECT_EQ(text.find("VALID_WARNING"), std::string::npos) << text;
  std::filesystem::remove(report_);
}

TEST_F(MockRuntimeUnderCoreValidation, MisuseIsReported) {
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME}, &instance), XR_SUCCESS);
  auto wrong = make<XrSystemGetInfo>(XR_TYPE_SYSTEM_PROPERTIES);  // wrong structure type
  wrong.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  EXPECT_EQ(xrGetSystem(instance, &wrong, &system), XR_ERROR_VALIDATION_FAILURE);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
  EXPECT_NE(report().find("VALID_ERROR"), std::string::npos) << report();
  std::filesystem::remove(report_);
}

// An app's whole action setup, with trackers, raises nothing either.
TEST_F(MockRuntimeUnderCoreValidation, ActionAppRaisesNoValidationError) {
  XrInstance instance = XR_NULL_HANDLE;
  ASSERT_EQ(create_instance({XR_MND_HEADLESS_EXTENSION_NAME, XR_HTCX_VIVE_TRACKER_INTERACTION_EXTENSION_NAME},
                            &instance),
            XR_SUCCESS);
  const XrPath left = to_path(instance, "/user/hand/left");
  const XrPath wrist_path = to_path(instance, "/user/vive_tracker_htcx/role/left_wrist");
  XrActionSet set = XR_NULL_HANDLE;
  XrAction select = XR_NULL_HANDLE, grip = XR_NULL_HANDLE, wrist = XR_NULL_HANDLE;
  ASSERT_EQ(create_action_set(instance, "main", "Main", &set), XR_SUCCESS);
  ASSERT_EQ(create_action(set, "select", XR_ACTION_TYPE_BOOLEAN_INPUT, {left}, &select), XR_SUCCESS);
  ASSERT_EQ(create_action(set, "grip", XR_ACTION_TYPE_POSE_INPUT, {left}, &grip), XR_SUCCESS);
  ASSERT_EQ(create_action(set, "wrist", XR_ACTION_TYPE_POSE_INPUT, {wrist_path}, &wrist), XR_SUCCESS);
  ASSERT_EQ(suggest(instance, "/interaction_profiles/khr/simple_controller",
                    {{select, "/user/hand/left/input/select/click"}, {grip, "/user/hand/left/input/grip/pose"}}),
            XR_SUCCESS);
  ASSERT_EQ(suggest(instance, "/interaction_profiles/htc/vive_tracker_htcx",
                    {{wrist, "/user/vive_tracker_htcx/role/left_wrist/input/grip/pose"}}),
            XR_SUCCESS);
  const XrSession session = begin_headless_session(instance);
  ASSERT_EQ(attach(session, {set}), XR_SUCCESS);
  const XrSpace grip_space = create_action_space(session, grip, left);
  const XrSpace wrist_space = create_action_space(session, wrist, wrist_path);
  const XrSpace local = create_space(session, XR_REFERENCE_SPACE_TYPE_LOCAL);
  ASSERT_EQ(sync(session, {{set, XR_NULL_PATH}}), XR_SUCCESS);
  drain_events(instance);
  EXPECT_TRUE(boolean_state(session, select, left).isActive);
  EXPECT_TRUE(pose_state(session, grip, left).isActive);
  const XrTime now = mx::xr_time_now();
  expect_located(locate(grip_space, local, now), mx::to_xr(mx::controller_grip(mx::Hand::left, now)));
  expect_located(locate(wrist_space, local, now), mx::to_xr(mx::tracker_pose(mx::Hand::left, now)));
  EXPECT_EQ(xrDestroySession(session), XR_SUCCESS);
  EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
  const std::string text = report();
  EXPECT_EQ(text.find("VALID_ERROR"), std::string::npos) << text;
  std::filesystem::remove(report_);
}

}  // namespace
