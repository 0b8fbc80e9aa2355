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
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <optional>
#include <string>
#include <thread>
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

}  // namespace
