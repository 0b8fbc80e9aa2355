// The layer through Debian's real OpenXR loader, on the project's mock
// runtime, with and without Debian's core_validation layer stacked on top.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <cstring>
#include <thread>

#include "layer_test_util.hpp"
#include "mock_motion.hpp"
#include "proprio/core/xr_interop.hpp"
#include "proprio/core/xr_ext.hpp"

using namespace proprio;
using layer_test::TempDir;

namespace {

constexpr const char* kOurLayer = "XR_APILAYER_PROPRIO_hand_tracking";
constexpr const char* kCoreValidation = "XR_APILAYER_LUNARG_core_validation";

#define XR_OK(call) ASSERT_EQ((call), XR_SUCCESS) << #call

template <typename Fn>
Fn get(XrInstance instance, const char* name) {
  PFN_xrVoidFunction f = nullptr;
  EXPECT_EQ(xrGetInstanceProcAddr(instance, name, &f), XR_SUCCESS) << name;
  return reinterpret_cast<Fn>(f);
}

// One app: instance, headless session, LOCAL space, a tracker per hand.
struct App {
  XrInstance instance = XR_NULL_HANDLE;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  XrSession session = XR_NULL_HANDLE;
  XrSpace local = XR_NULL_HANDLE;
  std::array<XrHandTrackerEXT, 2> trackers{};
  PFN_xrCreateHandTrackerEXT create_tracker = nullptr;
  PFN_xrDestroyHandTrackerEXT destroy_tracker = nullptr;
  PFN_xrLocateHandJointsEXT locate = nullptr;

  XrResult create_instance(std::vector<const char*> extensions) {
    auto info = xr_struct<XrInstanceCreateInfo>(XR_TYPE_INSTANCE_CREATE_INFO);
    std::strcpy(info.applicationInfo.applicationName, "proprio layer test");
    info.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
    info.enabledExtensionCount = static_cast<uint32_t>(extensions.size());
    info.enabledExtensionNames = extensions.data();
    return xrCreateInstance(&info, &instance);
  }
  bool supports_hand_tracking() {
    auto getinfo = xr_struct<XrSystemGetInfo>(XR_TYPE_SYSTEM_GET_INFO);
    getinfo.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
    EXPECT_EQ(xrGetSystem(instance, &getinfo, &system), XR_SUCCESS);
    auto ht = xr_struct<XrSystemHandTrackingPropertiesEXT>(XR_TYPE_SYSTEM_HAND_TRACKING_PROPERTIES_EXT);
    auto props = xr_struct<XrSystemProperties>(XR_TYPE_SYSTEM_PROPERTIES);
    props.next = &ht;
    EXPECT_EQ(xrGetSystemProperties(instance, system, &props), XR_SUCCESS);
    return ht.supportsHandTracking == XR_TRUE;
  }
  void start(bool make_trackers = true) {
    ASSERT_TRUE(supports_hand_tracking());
    auto sinfo = xr_struct<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
    sinfo.systemId = system;
    XR_OK(xrCreateSession(instance, &sinfo, &session));
    auto space = xr_struct<XrReferenceSpaceCreateInfo>(XR_TYPE_REFERENCE_SPACE_CREATE_INFO);
    space.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_LOCAL;
    space.poseInReferenceSpace = proprio::mock_xr::kIdentityPose;
    XR_OK(xrCreateReferenceSpace(session, &space, &local));
    create_tracker = get<PFN_xrCreateHandTrackerEXT>(instance, "xrCreateHandTrackerEXT");
    destroy_tracker = get<PFN_xrDestroyHandTrackerEXT>(instance, "xrDestroyHandTrackerEXT");
    locate = get<PFN_xrLocateHandJointsEXT>(instance, "xrLocateHandJointsEXT");
    ASSERT_TRUE(create_tracker && destroy_tracker && locate);
    if (make_trackers) {
      for (XrHandEXT hand : {XR_HAND_LEFT_EXT, XR_HAND_RIGHT_EXT}) {
        auto tinfo = xr_struct<XrHandTrackerCreateInfoEXT>(XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT);
        tinfo.hand = hand;
        tinfo.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
        XR_OK(create_tracker(session, &tinfo, &trackers[hand == XR_HAND_LEFT_EXT ? 0 : 1]));
      }
    }
  }
  ~App() {
    if (instance != XR_NULL_HANDLE) {
      EXPECT_EQ(xrDestroyInstance(instance), XR_SUCCESS);
    }
  }
};

struct Located {
  std::array<XrHandJointLocationEXT, kHandJointCount> joints{};
  std::array<XrHandJointVelocityEXT, kHandJointCount> velocities{};
  XrHandJointVelocitiesEXT velocity_struct = xr_struct<XrHandJointVelocitiesEXT>(XR_TYPE_HAND_JOINT_VELOCITIES_EXT);
  XrHandJointLocationsEXT locations = xr_struct<XrHandJointLocationsEXT>(XR_TYPE_HAND_JOINT_LOCATIONS_EXT);
  Located() {
    velocity_struct.jointCount = kHandJointCount;
    velocity_struct.jointVelocities = velocities.data();
    locations.jointCount = kHandJointCount;
    locations.jointLocations = joints.data();
    locations.next = &velocity_struct;
  }
  XrResult from(const App& app, XrHandTrackerEXT tracker, XrTime time) {
    auto info = xr_struct<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);
    info.baseSpace = app.local;
    info.time = time;
    return app.locate(tracker, &info, &locations);
  }
};

// Param: stack Debian's core_validation layer above ours.
class LayerThroughLoader : public ::testing::TestWithParam<bool> {
 protected:
  void SetUp() override {
    ::setenv("XR_RUNTIME_JSON", PROPRIO_MOCK_RUNTIME_JSON, 1);
    std::string path = PROPRIO_LAYER_MANIFEST_DIR;
    std::string enable = kOurLayer;
    if (GetParam()) {
      path += std::string(":") + PROPRIO_XR_EXPLICIT_LAYER_DIR;
      enable = std::string(kCoreValidation) + ":" + enable;  // first = closest to the app
    }
    ::setenv("XR_API_LAYER_PATH", path.c_str(), 1);
    ::setenv("XR_ENABLE_API_LAYERS", enable.c_str(), 1);
    ::unsetenv("PROPRIO_MOCK_RUNTIME_HAND_TRACKING");
    // Pretend home, so no user-installed layer or config interferes.
    ::setenv("XDG_CONFIG_HOME", (dir_.path() / "config").c_str(), 1);
    ::setenv("XDG_DATA_HOME", (dir_.path() / "data").c_str(), 1);
  }
  // A still recorded hand pair bound to VIEW with an offset: what the app sees
  // is exactly T_local_view(t) * offset * recorded joint.
  void use_still_hands_in_view() {
    const auto rec = layer_test::write_still_recording(dir_.path(), 10 * kNsPerSecond);
    use_config("[[source]]\ntype = \"replay\"\nspace = \"view\"\noffset_position_m = [0.01, -0.02, 0.03]\n"
               "offset_rotation_deg = [0, 10, 0]\npath = \"" + rec.string() + "\"\n");
  }
  void use_config(const std::string& text) {
    ::setenv("PROPRIO_LAYER_CONFIG", dir_.write("layer.toml", text).c_str(), 1);
  }
  static std::vector<const char*> all_extensions() {
    return {XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_EXT_HAND_JOINTS_MOTION_RANGE_EXTENSION_NAME,
            XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME, XR_MND_HEADLESS_EXTENSION_NAME};
  }
  TempDir dir_;
};

XrTime now_xr() { return proprio::mock_xr::xr_time_now(); }

TEST_P(LayerThroughLoader, EnumeratesItsExtensions) {
  uint32_t n = 0;
  XR_OK(xrEnumerateInstanceExtensionProperties(kOurLayer, 0, &n, nullptr));
  std::vector<XrExtensionProperties> props(n, xr_struct<XrExtensionProperties>(XR_TYPE_EXTENSION_PROPERTIES));
  XR_OK(xrEnumerateInstanceExtensionProperties(kOurLayer, n, &n, props.data()));
  std::map<std::string, uint32_t> found;
  for (const auto& p : props) found[p.extensionName] = p.extensionVersion;
  EXPECT_EQ(found[XR_EXT_HAND_TRACKING_EXTENSION_NAME], 4u);
  EXPECT_EQ(found[XR_EXT_HAND_JOINTS_MOTION_RANGE_EXTENSION_NAME], 1u);
  EXPECT_EQ(found[XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME], 1u);
}

TEST_P(LayerThroughLoader, NoConfigMeansNoHandTrackingButAWorkingApp) {
  ::setenv("PROPRIO_LAYER_CONFIG", (dir_.path() / "absent.toml").c_str(), 1);
  App app;
  XR_OK(app.create_instance(all_extensions()));
  EXPECT_FALSE(app.supports_hand_tracking());
}

TEST_P(LayerThroughLoader, StillHandsFollowTheMovingViewSpace) {
  use_still_hands_in_view();
  App app;
  XR_OK(app.create_instance(all_extensions()));
  app.start();
  const XrPosef offset = proprio::to_xr(Pose{so3_exp(Vec3(0, 10 * M_PI / 180, 0)), Vec3(0.01, -0.02, 0.03)});
  for (int k = 0; k < 20; ++k) {
    const XrTime t = now_xr() + k * 37'000'000;
    const auto view = proprio::mock_xr::locate_motion(XR_REFERENCE_SPACE_TYPE_VIEW, offset, XR_REFERENCE_SPACE_TYPE_LOCAL,
                                                      proprio::mock_xr::kIdentityPose, t);
    const Pose T_local_source = from_xr(proprio::mock_xr::to_xr(view.pose));
    const Vec3 v_source = from_xr(proprio::mock_xr::to_xr(view.linear_velocity));
    const Vec3 w_source = from_xr(proprio::mock_xr::to_xr(view.angular_velocity));
    for (Handedness hand : {Handedness::left, Handedness::right}) {
      Located out;
      XR_OK(out.from(app, app.trackers[static_cast<std::size_t>(hand)], t));
      ASSERT_TRUE(out.locations.isActive);
      const HandPose truth = layer_test::recorded_pose(hand, 0);
      for (std::size_t i = 0; i < kHandJointCount; ++i) {
        const Pose expected = T_local_source * truth.T_world_joint[i];
        EXPECT_LT((from_xr(out.joints[i].pose.position) - expected.p).norm(), 1e-4) << to_string(joint_at(i));
        EXPECT_LT(angle_between(from_xr(out.joints[i].pose.orientation), expected.q), 1e-4);
        EXPECT_EQ(out.joints[i].locationFlags, 0xFu);
        EXPECT_NEAR(out.joints[i].radius, truth.radius_m[i], 1e-6);
        // A hand still in a moving frame moves with it.
        const Vec3 v_expected = v_source + w_source.cross(expected.p - T_local_source.p);
        ASSERT_EQ(out.velocities[i].velocityFlags, 0x3u);
        EXPECT_LT((from_xr(out.velocities[i].linearVelocity) - v_expected).norm(), 1e-3);
        EXPECT_LT((from_xr(out.velocities[i].angularVelocity) - w_source).norm(), 1e-3);
      }
    }
  }
}

TEST_P(LayerThroughLoader, SimulatedHandsObeyTheXrConventionsOnBothHands) {
  // A generous prediction horizon: a loaded CI machine may starve the 90 Hz sim thread.
  use_config("[layer]\nmax_prediction_ms = 500\n[[source]]\ntype = \"sim\"\nspace = \"local\"\nsubject = 5\n"
             "protocol = \"free-motion\"\n");
  App app;
  XR_OK(app.create_instance(all_extensions()));
  app.start();
  const HandModel subject(*HandShape::from_measurements(0.170 + 0.035 * 5 / 14.0, 0.090 + 0.020 * ((5 * 7) % 15) / 14.0));
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  for (int k = 0; k < 10; ++k) {
    for (Handedness hand : {Handedness::left, Handedness::right}) {
      Located out;
      XR_OK(out.from(app, app.trackers[static_cast<std::size_t>(hand)], now_xr()));
      ASSERT_TRUE(out.locations.isActive);
      HandPose p;
      p.hand = hand;
      p.active = true;
      for (std::size_t i = 0; i < kHandJointCount; ++i) {
        p.T_world_joint[i] = from_xr(out.joints[i].pose);
        ASSERT_EQ(out.joints[i].locationFlags & 0x3u, 0x3u);
        ASSERT_GT(out.joints[i].radius, 0.0f);
      }
      // +Z back along every bone toward the wrist.
      for (std::size_t f = 0; f < kFingerCount; ++f) {
        const auto fj = finger_joints(static_cast<Finger>(f));
        for (std::size_t j = 0; j + 1 < fj.count; ++j) {
          const Vec3 bone = p.joint(fj.joints[j]).p - p.joint(fj.joints[j + 1]).p;
          const Vec3 z = p.joint(fj.joints[j]).q * Vec3::UnitZ();
          EXPECT_GT(z.dot(bone.normalized()), std::cos(deg_to_rad(1.0)));
        }
      }
      // Against the simulator's ground truth: the located joints are a pose
      // of this subject's hand (IK residual), interpolated between samples.
      EXPECT_LT(subject.inverse(p).max_position_residual_m, 0.002) << to_string(hand);
      const Vec3 palm_mid = 0.5 * (p.joint(HandJoint::middle_metacarpal).p + p.joint(HandJoint::middle_proximal).p);
      EXPECT_LT((p.joint(HandJoint::palm).p - palm_mid).norm(), 0.001);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(23));
  }
}

TEST_P(LayerThroughLoader, ErrorCasesReachTheAppIntact) {
  use_still_hands_in_view();
  App app;
  XR_OK(app.create_instance(all_extensions()));
  app.start();
  Located out;
  out.locations.jointCount = 20;
  EXPECT_EQ(out.from(app, app.trackers[0], now_xr()), XR_ERROR_VALIDATION_FAILURE);
  out.locations.jointCount = kHandJointCount;
  out.velocity_struct.jointCount = 3;
  EXPECT_EQ(out.from(app, app.trackers[0], now_xr()), XR_ERROR_VALIDATION_FAILURE);
  out.velocity_struct.jointCount = kHandJointCount;
  out.joints[4].radius = -1.0f;
  EXPECT_EQ(out.from(app, app.trackers[0], 0), XR_ERROR_TIME_INVALID);
  EXPECT_EQ(out.joints[4].radius, -1.0f) << "untouched";

  auto tinfo = xr_struct<XrHandTrackerCreateInfoEXT>(XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT);
  tinfo.hand = static_cast<XrHandEXT>(7);
  tinfo.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
  XrHandTrackerEXT bad;
  EXPECT_EQ(app.create_tracker(app.session, &tinfo, &bad), XR_ERROR_VALIDATION_FAILURE);

  XR_OK(app.destroy_tracker(app.trackers[1]));
  EXPECT_EQ(out.from(app, app.trackers[1], now_xr()), XR_ERROR_HANDLE_INVALID);
}

TEST_P(LayerThroughLoader, DataSourceAndMotionRange) {
  use_still_hands_in_view();
  App app;
  XR_OK(app.create_instance(all_extensions()));
  app.start();
  Located out;
  auto state = xr_struct<XrHandTrackingDataSourceStateEXT>(XR_TYPE_HAND_TRACKING_DATA_SOURCE_STATE_EXT);
  // Debian's core_validation (1.0.20) predates XR_EXT_hand_tracking_data_source
  // and rejects its structs as unknown, before they reach us.
  const bool data_source = !GetParam();
  if (data_source) out.velocity_struct.next = &state;
  auto range = xr_struct<XrHandJointsMotionRangeInfoEXT>(XR_TYPE_HAND_JOINTS_MOTION_RANGE_INFO_EXT);
  range.handJointsMotionRange = XR_HAND_JOINTS_MOTION_RANGE_CONFORMING_TO_CONTROLLER_EXT;
  auto info = xr_struct<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);
  info.baseSpace = app.local;
  info.time = now_xr();
  info.next = &range;
  XR_OK(app.locate(app.trackers[0], &info, &out.locations));
  EXPECT_TRUE(out.locations.isActive);
  if (data_source) {
    EXPECT_TRUE(state.isActive);
    EXPECT_EQ(state.dataSource, XR_HAND_TRACKING_DATA_SOURCE_UNOBSTRUCTED_EXT);
  }
}

TEST_P(LayerThroughLoader, OverrideOrPassThroughTheRuntimesOwnHandTracking) {
  ::setenv("PROPRIO_MOCK_RUNTIME_HAND_TRACKING", "1", 1);
  for (const bool pass_through : {false, true}) {
    use_still_hands_in_view();
    if (pass_through) {
      const auto rec = dir_.path() / "still.prec";
      use_config("[layer]\nruntime_hand_tracking = \"passthrough\"\n[[source]]\ntype = \"replay\"\npath = \"" +
                 rec.string() + "\"\n");
    }
    App app;
    XR_OK(app.create_instance(all_extensions()));
    app.start();
    Located out;
    XR_OK(out.from(app, app.trackers[1], now_xr()));
    ASSERT_TRUE(out.locations.isActive);
    const bool native = out.joints[5].radius == proprio::mock_xr::kNativeJointRadius;
    EXPECT_EQ(native, pass_through) << (pass_through ? "passthrough" : "override");
  }
}

TEST_P(LayerThroughLoader, EightThreadsLocateWhileTrackersComeAndGo) {
  use_config("[[source]]\ntype = \"sim\"\nspace = \"view\"\nrate_hz = 120\n");
  App app;
  XR_OK(app.create_instance(all_extensions()));
  app.start();
  std::atomic<bool> stop{false};
  std::atomic<long> located{0}, unexpected{0};
  std::vector<std::thread> threads;
  for (int i = 0; i < 8; ++i) {
    threads.emplace_back([&, i] {
      Located out;
      while (!stop.load()) {
        const XrResult r = out.from(app, app.trackers[static_cast<std::size_t>(i % 2)], now_xr());
        if (r == XR_SUCCESS) ++located;
        else if (r != XR_ERROR_HANDLE_INVALID) ++unexpected;
      }
    });
  }
  // Churn: a third tracker created and destroyed over and over; the two
  // located ones stay (a destroyed handle may be reused by the allocator).
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  int churn = 0;
  while (std::chrono::steady_clock::now() < until) {
    auto tinfo = xr_struct<XrHandTrackerCreateInfoEXT>(XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT);
    tinfo.hand = (churn % 2) ? XR_HAND_LEFT_EXT : XR_HAND_RIGHT_EXT;
    tinfo.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
    XrHandTrackerEXT t;
    ASSERT_EQ(app.create_tracker(app.session, &tinfo, &t), XR_SUCCESS);
    Located out;
    EXPECT_EQ(out.from(app, t, now_xr()), XR_SUCCESS);
    ASSERT_EQ(app.destroy_tracker(t), XR_SUCCESS);
    ++churn;
  }
  stop = true;
  for (auto& t : threads) t.join();
  EXPECT_EQ(unexpected.load(), 0);
  EXPECT_GT(located.load(), 1000);
  EXPECT_GT(churn, 100);
}

TEST_P(LayerThroughLoader, RapidInstanceCreateDestroy) {
  use_config("[[source]]\ntype = \"sim\"\n");
  for (int i = 0; i < 15; ++i) {
    App app;
    XR_OK(app.create_instance(all_extensions()));
    app.start();
  }
}

INSTANTIATE_TEST_SUITE_P(Stack, LayerThroughLoader, ::testing::Values(false, true),
                         [](const auto& param_info) { return param_info.param ? "with_core_validation" : "alone"; });

TEST(ImplicitLayer, LoadsWithoutBeingEnabledAndHonoursItsDisableVariable) {
  TempDir dir;
  // The loader reads user layer manifests from $XDG_DATA_HOME, not $XDG_CONFIG_HOME.
  const auto implicit_dir = dir.path() / "data" / "openxr" / "1" / "api_layers" / "implicit.d";
  std::filesystem::create_directories(implicit_dir);
  std::filesystem::copy_file(std::string(PROPRIO_LAYER_MANIFEST_DIR) + "/XrApiLayer_proprio_hand_tracking.json",
                             implicit_dir / "XrApiLayer_proprio_hand_tracking.json");
  ::setenv("XR_RUNTIME_JSON", PROPRIO_MOCK_RUNTIME_JSON, 1);
  ::unsetenv("XR_API_LAYER_PATH");
  ::unsetenv("XR_ENABLE_API_LAYERS");
  ::setenv("XDG_CONFIG_HOME", (dir.path() / "config").c_str(), 1);
  ::setenv("XDG_DATA_HOME", (dir.path() / "data").c_str(), 1);
  ::setenv("PROPRIO_LAYER_CONFIG", dir.write("layer.toml", "[[source]]\ntype = \"sim\"\n").c_str(), 1);
  {
    App app;
    XR_OK(app.create_instance({XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_MND_HEADLESS_EXTENSION_NAME}));
    EXPECT_TRUE(app.supports_hand_tracking());
  }
  ::setenv("DISABLE_XR_APILAYER_PROPRIO_HAND_TRACKING", "1", 1);
  App app;
  EXPECT_EQ(app.create_instance({XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_MND_HEADLESS_EXTENSION_NAME}),
            XR_ERROR_EXTENSION_NOT_PRESENT);
  ::unsetenv("DISABLE_XR_APILAYER_PROPRIO_HAND_TRACKING");
}

}  // namespace
