// Drives the layer's negotiation and dispatch directly, with the test as the
// loader and fake_next.hpp as the runtime. No OpenXR loader involved.
#include <gtest/gtest.h>

#include <cstdlib>
#include <new>

#include "fake_next.hpp"
#include "layer_test_util.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/core/xr_interop.hpp"
#include "proprio/openxr/XR_PROPRIO_fingertip_haptics.h"

using namespace proprio;

// Counts this thread's heap allocations, to hold the layer to "no allocation
// in xrLocateHandJointsEXT".
namespace {
thread_local std::size_t g_allocations = 0;
}
// GCC cannot see that these replace the global pair and warns on free().
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  ++g_allocations;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace {

using layer_test::recorded_pose;
using layer_test::TempDir;
using layer_test::write_still_recording;

class LayerDispatch : public ::testing::Test {
 protected:
  void use_config(const std::string& text) {
    ::setenv("PROPRIO_LAYER_CONFIG", dir_.write("layer.toml", text).c_str(), 1);
  }
  void use_replay(DurationNs span = 10 * kNsPerSecond, bool loop = true, const std::string& extra = "") {
    use_config("[layer]\n" + extra + "\n[[source]]\ntype = \"replay\"\nspace = \"local\"\npath = \"" +
               write_still_recording(dir_.path(), span).string() + "\"\nloop = " + (loop ? "true" : "false") + "\n");
  }
  void SetUp() override {
    fake_next::state().runtime_hand_tracking = false;
    fake_next::state().T_base_source = {{0.0f, 0.38941834f, 0.0f, 0.92106099f}, {0.5f, 1.0f, -2.0f}};
    ASSERT_EQ(chain_.negotiate(), XR_SUCCESS);
  }
  void TearDown() override {
    if (instance_ != XR_NULL_HANDLE) {
      EXPECT_EQ(chain_.get<PFN_xrDestroyInstance>(instance_, "xrDestroyInstance")(instance_), XR_SUCCESS);
    }
    EXPECT_EQ(fake_next::state().live_spaces.load(), 0) << "every space the layer created was destroyed";
  }
  XrResult create(std::vector<const char*> ext = {XR_EXT_HAND_TRACKING_EXTENSION_NAME}) {
    return chain_.create_instance(std::move(ext), &instance_);
  }
  XrSession session() {
    XrSession s = XR_NULL_HANDLE;
    auto info = xr_struct<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
    EXPECT_EQ(chain_.get<PFN_xrCreateSession>(instance_, "xrCreateSession")(instance_, &info, &s), XR_SUCCESS);
    return s;
  }
  bool supports_hand_tracking() {
    auto ht = xr_struct<XrSystemHandTrackingPropertiesEXT>(XR_TYPE_SYSTEM_HAND_TRACKING_PROPERTIES_EXT);
    auto props = xr_struct<XrSystemProperties>(XR_TYPE_SYSTEM_PROPERTIES);
    props.next = &ht;
    EXPECT_EQ(chain_.get<PFN_xrGetSystemProperties>(instance_, "xrGetSystemProperties")(instance_, 1, &props), XR_SUCCESS);
    EXPECT_EQ(props.next, &ht) << "our struct is back in the chain";
    return ht.supportsHandTracking == XR_TRUE;
  }
  XrResult create_tracker(XrHandEXT hand, XrHandTrackerEXT* t, const void* next = nullptr) {
    auto info = xr_struct<XrHandTrackerCreateInfoEXT>(XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT);
    info.hand = hand;
    info.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
    info.next = next;
    return chain_.get<PFN_xrCreateHandTrackerEXT>(instance_, "xrCreateHandTrackerEXT")(session(), &info, t);
  }
  XrResult locate(XrHandTrackerEXT t, XrTime time, XrHandJointLocationsEXT* out, const void* info_next = nullptr) {
    auto info = xr_struct<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);
    info.baseSpace = reinterpret_cast<XrSpace>(0x4004);
    info.time = time;
    info.next = info_next;
    return chain_.get<PFN_xrLocateHandJointsEXT>(instance_, "xrLocateHandJointsEXT")(t, &info, out);
  }

  TempDir dir_;
  fake_next::Chain chain_;
  XrInstance instance_ = XR_NULL_HANDLE;
  std::array<XrHandJointLocationEXT, kHandJointCount> joints_{};
  XrHandJointLocationsEXT locations_ = [this] {
    auto l = xr_struct<XrHandJointLocationsEXT>(XR_TYPE_HAND_JOINT_LOCATIONS_EXT);
    l.jointCount = kHandJointCount;
    l.jointLocations = joints_.data();
    return l;
  }();
};

TEST(LayerNegotiation, FillsTheRequestAndRejectsMalformedStructs) {
  fake_next::Chain chain;
  ASSERT_EQ(chain.negotiate(), XR_SUCCESS);
  EXPECT_EQ(chain.request.layerInterfaceVersion, 1u);
  EXPECT_NE(chain.request.getInstanceProcAddr, nullptr);
  EXPECT_NE(chain.request.createApiLayerInstance, nullptr);

  XrNegotiateLoaderInfo loader{XR_LOADER_INTERFACE_STRUCT_LOADER_INFO, PROPRIO_XR_LOADER_INFO_STRUCT_VERSION,
                               sizeof(XrNegotiateLoaderInfo), 1, 1, XR_MAKE_VERSION(1, 0, 0), XR_CURRENT_API_VERSION};
  XrNegotiateApiLayerRequest req{};
  req.structType = XR_LOADER_INTERFACE_STRUCT_API_LAYER_REQUEST;
  req.structVersion = PROPRIO_XR_API_LAYER_INFO_STRUCT_VERSION;
  req.structSize = sizeof req;
  EXPECT_EQ(xrNegotiateLoaderApiLayerInterface(&loader, "XR_APILAYER_someone_else", &req), XR_ERROR_INITIALIZATION_FAILED);
  auto bad = loader;
  bad.structSize = sizeof(XrNegotiateLoaderInfo) - 4;
  EXPECT_EQ(xrNegotiateLoaderApiLayerInterface(&bad, "XR_APILAYER_PROPRIO_hand_tracking", &req), XR_ERROR_INITIALIZATION_FAILED);
  bad = loader;
  bad.minInterfaceVersion = bad.maxInterfaceVersion = 2;
  EXPECT_EQ(xrNegotiateLoaderApiLayerInterface(&bad, "XR_APILAYER_PROPRIO_hand_tracking", &req), XR_ERROR_INITIALIZATION_FAILED);
  auto bad_req = req;
  bad_req.structType = XR_LOADER_INTERFACE_STRUCT_RUNTIME_REQUEST;
  EXPECT_EQ(xrNegotiateLoaderApiLayerInterface(&loader, "XR_APILAYER_PROPRIO_hand_tracking", &bad_req), XR_ERROR_INITIALIZATION_FAILED);
  EXPECT_EQ(xrNegotiateLoaderApiLayerInterface(nullptr, "XR_APILAYER_PROPRIO_hand_tracking", &req), XR_ERROR_INITIALIZATION_FAILED);
}

TEST_F(LayerDispatch, StripsOurExtensionsAndAddsTimeConversion) {
  use_replay();
  ASSERT_EQ(create({XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_EXT_HAND_JOINTS_MOTION_RANGE_EXTENSION_NAME,
                    XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME, XR_MND_HEADLESS_EXTENSION_NAME}),
            XR_SUCCESS);
  EXPECT_EQ(fake_next::state().enabled_extensions,
            (std::vector<std::string>{XR_MND_HEADLESS_EXTENSION_NAME, XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME}));
  EXPECT_TRUE(supports_hand_tracking());
}

TEST_F(LayerDispatch, HooksNothingWhenTheAppDidNotEnableHandTracking) {
  use_replay();
  ASSERT_EQ(create({XR_MND_HEADLESS_EXTENSION_NAME}), XR_SUCCESS);
  EXPECT_EQ(fake_next::state().enabled_extensions, (std::vector<std::string>{XR_MND_HEADLESS_EXTENSION_NAME}));
  PFN_xrVoidFunction f = nullptr;
  EXPECT_EQ(chain_.request.getInstanceProcAddr(instance_, "xrLocateHandJointsEXT", &f), XR_ERROR_FUNCTION_UNSUPPORTED);
  EXPECT_EQ(f, nullptr);
  EXPECT_EQ(chain_.request.getInstanceProcAddr(instance_, "xrGetSystemProperties", &f), XR_SUCCESS);
  EXPECT_EQ(reinterpret_cast<void*>(f), reinterpret_cast<void*>(&fake_next::get_system_properties)) << "not hooked";
}

TEST_F(LayerDispatch, BrokenOrMissingConfigMeansNoHandTrackingNotACrash) {
  use_config("[[source]]\ntype = \"sim\"\nsubject = 99\n");
  ASSERT_EQ(create(), XR_SUCCESS);
  EXPECT_FALSE(supports_hand_tracking());
  XrHandTrackerEXT t;
  EXPECT_EQ(create_tracker(XR_HAND_LEFT_EXT, &t), XR_ERROR_FEATURE_UNSUPPORTED);
}

TEST_F(LayerDispatch, MissingConfigFileMeansNoHandTracking) {
  ::setenv("PROPRIO_LAYER_CONFIG", (dir_.path() / "absent.toml").c_str(), 1);
  ASSERT_EQ(create(), XR_SUCCESS);
  EXPECT_FALSE(supports_hand_tracking());
}

TEST_F(LayerDispatch, LocatesRecordedJointsInTheBaseSpace) {
  use_replay();
  ASSERT_EQ(create(), XR_SUCCESS);
  for (XrHandEXT hand : {XR_HAND_LEFT_EXT, XR_HAND_RIGHT_EXT}) {
    XrHandTrackerEXT t;
    ASSERT_EQ(create_tracker(hand, &t), XR_SUCCESS);
    std::array<XrHandJointVelocityEXT, kHandJointCount> vel{};
    auto velocities = xr_struct<XrHandJointVelocitiesEXT>(XR_TYPE_HAND_JOINT_VELOCITIES_EXT);
    velocities.jointCount = kHandJointCount;
    velocities.jointVelocities = vel.data();
    locations_.next = &velocities;
    ASSERT_EQ(locate(t, fake_next::xr_now(), &locations_), XR_SUCCESS);
    ASSERT_TRUE(locations_.isActive);
    const Pose T_base_source = from_xr(fake_next::state().T_base_source);
    const HandPose expected = recorded_pose(hand == XR_HAND_LEFT_EXT ? Handedness::left : Handedness::right, 0);
    for (std::size_t i = 0; i < kHandJointCount; ++i) {
      const auto& j = joints_[i];
      EXPECT_EQ(j.locationFlags & 0x3u, 0x3u) << "both VALID bits on every joint";
      EXPECT_EQ(j.locationFlags & 0xCu, 0xCu) << "fresh data is tracked";
      EXPECT_GT(j.radius, 0.0f);
      const Pose truth = T_base_source * expected.T_world_joint[i];
      EXPECT_LT((from_xr(j.pose.position) - truth.p).norm(), 2e-6) << i;
      EXPECT_LT(angle_between(from_xr(j.pose.orientation), truth.q), 1e-5) << i;
      EXPECT_EQ(vel[i].velocityFlags, XR_SPACE_VELOCITY_LINEAR_VALID_BIT | XR_SPACE_VELOCITY_ANGULAR_VALID_BIT);
      EXPECT_LT(from_xr(vel[i].linearVelocity).norm(), 1e-6) << "a still hand in a still space";
    }
    EXPECT_EQ(chain_.get<PFN_xrDestroyHandTrackerEXT>(instance_, "xrDestroyHandTrackerEXT")(t), XR_SUCCESS);
  }
}

TEST_F(LayerDispatch, LocatingAllocatesNothing) {
  use_replay();
  ASSERT_EQ(create(), XR_SUCCESS);
  XrHandTrackerEXT t;
  ASSERT_EQ(create_tracker(XR_HAND_RIGHT_EXT, &t), XR_SUCCESS);
  std::array<XrHandJointVelocityEXT, kHandJointCount> vel{};
  auto velocities = xr_struct<XrHandJointVelocitiesEXT>(XR_TYPE_HAND_JOINT_VELOCITIES_EXT);
  velocities.jointCount = kHandJointCount;
  velocities.jointVelocities = vel.data();
  locations_.next = &velocities;
  auto locate_fn = chain_.get<PFN_xrLocateHandJointsEXT>(instance_, "xrLocateHandJointsEXT");
  auto info = xr_struct<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);
  info.baseSpace = reinterpret_cast<XrSpace>(0x4004);
  const XrTime now = fake_next::xr_now();
  const std::size_t counted = g_allocations;
  auto probe = std::make_unique<int>(1);  // the counter sees allocations at all
  ASSERT_EQ(g_allocations, counted + 1);
  const std::size_t before = g_allocations;
  for (int i = 0; i < 200; ++i) {
    info.time = now + i * 1'000'000;  // interpolated, then predicted, then stale: every path
    ASSERT_EQ(locate_fn(t, &info, &locations_), XR_SUCCESS);
  }
  info.time = 0;
  EXPECT_EQ(locate_fn(t, &info, &locations_), XR_ERROR_TIME_INVALID);
  EXPECT_EQ(g_allocations - before, 0u);
}

// XR_PROPRIO_fingertip_haptics' per-frame calls allocate nothing on the
// app's thread either: forces in fingertip frames and in a base space, a
// collider's pose, the proxy hand and the devices' state.
TEST_F(LayerDispatch, FingertipHapticsPerFrameCallsAllocateNothing) {
  use_config("[[source]]\ntype = \"replay\"\nspace = \"local\"\npath = \"" +
             write_still_recording(dir_.path(), 10 * kNsPerSecond).string() +
             "\"\n[haptics]\ndevices = \"emulated\"\nright = [\"index\", \"thumb\"]\n");
  ASSERT_EQ(create({XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME}), XR_SUCCESS);
  const XrSession s = session();
  const auto world = reinterpret_cast<XrSpace>(0x4004);
  auto create_info = xr_struct<XrFingertipHapticsCreateInfoPROPRIO>(XR_TYPE_FINGERTIP_HAPTICS_CREATE_INFO_PROPRIO);
  create_info.contactSimulation = XR_TRUE;
  create_info.worldSpace = world;
  XrFingertipHapticsPROPRIO h = XR_NULL_HANDLE;
  ASSERT_EQ(chain_.get<PFN_xrCreateFingertipHapticsPROPRIO>(instance_, "xrCreateFingertipHapticsPROPRIO")(s, &create_info, &h),
            XR_SUCCESS);
  auto collider_info = xr_struct<XrHapticColliderCreateInfoPROPRIO>(XR_TYPE_HAPTIC_COLLIDER_CREATE_INFO_PROPRIO);
  collider_info.shape = XR_HAPTIC_COLLIDER_SHAPE_BOX_PROPRIO;
  collider_info.halfExtents = {0.1f, 0.02f, 0.1f};
  collider_info.friction = 0.8f;
  collider_info.poseInfo = xr_struct<XrHapticColliderPoseInfoPROPRIO>(XR_TYPE_HAPTIC_COLLIDER_POSE_INFO_PROPRIO);
  collider_info.poseInfo.space = world;
  collider_info.poseInfo.time = fake_next::xr_now();
  collider_info.poseInfo.pose = {{0, 0, 0, 1}, {0, 0.9f, -0.3f}};
  XrHapticColliderPROPRIO collider = XR_NULL_HANDLE;
  ASSERT_EQ(chain_.get<PFN_xrCreateHapticColliderPROPRIO>(instance_, "xrCreateHapticColliderPROPRIO")(h, &collider_info, &collider),
            XR_SUCCESS);
  auto apply = chain_.get<PFN_xrApplyFingertipForcesPROPRIO>(instance_, "xrApplyFingertipForcesPROPRIO");
  auto move = chain_.get<PFN_xrSetHapticColliderPosePROPRIO>(instance_, "xrSetHapticColliderPosePROPRIO");
  auto proxy = chain_.get<PFN_xrLocateProxyHandJointsPROPRIO>(instance_, "xrLocateProxyHandJointsPROPRIO");
  auto state = chain_.get<PFN_xrGetFingertipHapticsStatePROPRIO>(instance_, "xrGetFingertipHapticsStatePROPRIO");
  auto forces = xr_struct<XrFingertipForcesPROPRIO>(XR_TYPE_FINGERTIP_FORCES_PROPRIO);
  forces.hand = XR_HAND_RIGHT_EXT;
  forces.forces[XR_FINGERTIP_INDEX_PROPRIO] = {0.0f, 0.5f, 0.0f};
  auto info = xr_struct<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);
  info.baseSpace = world;
  auto st = xr_struct<XrFingertipHapticsStatePROPRIO>(XR_TYPE_FINGERTIP_HAPTICS_STATE_PROPRIO);
  const std::size_t before = g_allocations;
  for (int i = 0; i < 200; ++i) {
    const XrTime t = fake_next::xr_now();
    forces.baseSpace = i % 2 ? world : XR_NULL_HANDLE;
    forces.time = t;
    ASSERT_EQ(apply(h, &forces), XR_SUCCESS);
    collider_info.poseInfo.time = t;
    collider_info.poseInfo.pose.position.y = 0.9f + 0.0001f * static_cast<float>(i);
    ASSERT_EQ(move(collider, &collider_info.poseInfo), XR_SUCCESS);
    info.time = t;
    ASSERT_EQ(proxy(h, XR_HAND_RIGHT_EXT, &info, &locations_), XR_SUCCESS);
    ASSERT_EQ(state(h, XR_HAND_RIGHT_EXT, &st), XR_SUCCESS);
  }
  EXPECT_EQ(g_allocations - before, 0u);
  EXPECT_EQ(chain_.get<PFN_xrDestroyFingertipHapticsPROPRIO>(instance_, "xrDestroyFingertipHapticsPROPRIO")(h), XR_SUCCESS);
  EXPECT_EQ(move(collider, &collider_info.poseInfo), XR_ERROR_HANDLE_INVALID) << "colliders go with their parent";
}

TEST_F(LayerDispatch, ValidationErrorsFollowTheSpec) {
  use_replay();
  ASSERT_EQ(create(), XR_SUCCESS);
  XrHandTrackerEXT t;
  EXPECT_EQ(create_tracker(static_cast<XrHandEXT>(3), &t), XR_ERROR_VALIDATION_FAILURE) << "bad hand enum";
  ASSERT_EQ(create_tracker(XR_HAND_RIGHT_EXT, &t), XR_SUCCESS);

  locations_.jointCount = 25;
  EXPECT_EQ(locate(t, fake_next::xr_now(), &locations_), XR_ERROR_VALIDATION_FAILURE);
  locations_.jointCount = kHandJointCount;

  std::array<XrHandJointVelocityEXT, kHandJointCount> vel{};
  auto velocities = xr_struct<XrHandJointVelocitiesEXT>(XR_TYPE_HAND_JOINT_VELOCITIES_EXT);
  velocities.jointCount = 27;
  velocities.jointVelocities = vel.data();
  locations_.next = &velocities;
  EXPECT_EQ(locate(t, fake_next::xr_now(), &locations_), XR_ERROR_VALIDATION_FAILURE) << "chained velocities count";
  locations_.next = nullptr;

  // time <= 0: XR_ERROR_TIME_INVALID and the output is untouched.
  for (auto& j : joints_) j.radius = -123.0f;
  locations_.isActive = 77;
  EXPECT_EQ(locate(t, 0, &locations_), XR_ERROR_TIME_INVALID);
  EXPECT_EQ(locate(t, -5, &locations_), XR_ERROR_TIME_INVALID);
  EXPECT_EQ(locations_.isActive, 77u);
  for (const auto& j : joints_) EXPECT_EQ(j.radius, -123.0f);

  auto destroy = chain_.get<PFN_xrDestroyHandTrackerEXT>(instance_, "xrDestroyHandTrackerEXT");
  ASSERT_EQ(destroy(t), XR_SUCCESS);
  EXPECT_EQ(locate(t, fake_next::xr_now(), &locations_), XR_ERROR_HANDLE_INVALID) << "destroyed tracker";
  EXPECT_EQ(destroy(t), XR_ERROR_HANDLE_INVALID);
}

TEST_F(LayerDispatch, DataSourceAndMotionRangeStructs) {
  use_replay();
  ASSERT_EQ(create({XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_EXT_HAND_JOINTS_MOTION_RANGE_EXTENSION_NAME,
                    XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME}),
            XR_SUCCESS);
  XrHandTrackingDataSourceEXT controller_only = XR_HAND_TRACKING_DATA_SOURCE_CONTROLLER_EXT;
  auto ds_info = xr_struct<XrHandTrackingDataSourceInfoEXT>(XR_TYPE_HAND_TRACKING_DATA_SOURCE_INFO_EXT);
  XrHandTrackerEXT t;
  EXPECT_EQ(create_tracker(XR_HAND_LEFT_EXT, &t, &ds_info), XR_ERROR_VALIDATION_FAILURE) << "zero requested sources";

  ds_info.requestedDataSourceCount = 1;
  ds_info.requestedDataSources = &controller_only;
  ASSERT_EQ(create_tracker(XR_HAND_LEFT_EXT, &t, &ds_info), XR_SUCCESS);
  auto state = xr_struct<XrHandTrackingDataSourceStateEXT>(XR_TYPE_HAND_TRACKING_DATA_SOURCE_STATE_EXT);
  locations_.next = &state;
  ASSERT_EQ(locate(t, fake_next::xr_now(), &locations_), XR_SUCCESS);
  EXPECT_FALSE(locations_.isActive) << "a glove is never a controller-conforming source";
  EXPECT_FALSE(state.isActive);
  for (const auto& j : joints_) EXPECT_EQ(j.locationFlags, 0u) << "inactive: no valid bits anywhere";

  XrHandTrackingDataSourceEXT both[] = {XR_HAND_TRACKING_DATA_SOURCE_CONTROLLER_EXT, XR_HAND_TRACKING_DATA_SOURCE_UNOBSTRUCTED_EXT};
  ds_info.requestedDataSourceCount = 2;
  ds_info.requestedDataSources = both;
  XrHandTrackerEXT t2;
  ASSERT_EQ(create_tracker(XR_HAND_LEFT_EXT, &t2, &ds_info), XR_SUCCESS);
  auto range = xr_struct<XrHandJointsMotionRangeInfoEXT>(XR_TYPE_HAND_JOINTS_MOTION_RANGE_INFO_EXT);
  range.handJointsMotionRange = XR_HAND_JOINTS_MOTION_RANGE_CONFORMING_TO_CONTROLLER_EXT;
  ASSERT_EQ(locate(t2, fake_next::xr_now(), &locations_, &range), XR_SUCCESS);
  EXPECT_TRUE(locations_.isActive);
  EXPECT_TRUE(state.isActive);
  EXPECT_EQ(state.dataSource, XR_HAND_TRACKING_DATA_SOURCE_UNOBSTRUCTED_EXT);
  range.handJointsMotionRange = static_cast<XrHandJointsMotionRangeEXT>(9);
  EXPECT_EQ(locate(t2, fake_next::xr_now(), &locations_, &range), XR_ERROR_VALIDATION_FAILURE);
}

TEST_F(LayerDispatch, StaleDataIsValidButUntrackedThenInactive) {
  use_replay(1 * kNsPerSecond, /*loop=*/false, "max_prediction_ms = 50\nstale_timeout_ms = 5000");
  ASSERT_EQ(create(), XR_SUCCESS);
  // The recording's 1 s span starts when the instance was created, somewhere
  // before `after`; the margins below hold however long creation took (< 0.7 s).
  const XrTime after = fake_next::xr_now();
  XrHandTrackerEXT t;
  ASSERT_EQ(create_tracker(XR_HAND_RIGHT_EXT, &t), XR_SUCCESS);
  ASSERT_EQ(locate(t, after + 200'000'000, &locations_), XR_SUCCESS);
  EXPECT_TRUE(locations_.isActive);
  EXPECT_EQ(joints_[0].locationFlags, 0xFu) << "inside the recording: tracked";
  ASSERT_EQ(locate(t, after + 1'500'000'000, &locations_), XR_SUCCESS);
  EXPECT_TRUE(locations_.isActive);
  EXPECT_EQ(joints_[0].locationFlags, 0x3u) << "past the prediction horizon: valid, not tracked";
  ASSERT_EQ(locate(t, after + 8'000'000'000, &locations_), XR_SUCCESS);
  EXPECT_FALSE(locations_.isActive) << "past the stale timeout: inactive";
  EXPECT_EQ(joints_[0].locationFlags, 0u);
}

TEST_F(LayerDispatch, PassThroughLeavesTheRuntimesHandTrackingAlone) {
  fake_next::state().runtime_hand_tracking = true;
  use_config("[layer]\nruntime_hand_tracking = \"passthrough\"\n[[source]]\ntype = \"sim\"\n");
  ASSERT_EQ(create(), XR_SUCCESS);
  EXPECT_EQ(fake_next::state().enabled_extensions, (std::vector<std::string>{XR_EXT_HAND_TRACKING_EXTENSION_NAME}));
  EXPECT_TRUE(supports_hand_tracking()) << "the runtime's answer, untouched";
  PFN_xrVoidFunction f = nullptr;
  EXPECT_EQ(chain_.request.getInstanceProcAddr(instance_, "xrLocateHandJointsEXT", &f), XR_ERROR_FUNCTION_UNSUPPORTED)
      << "resolved by the (fake) runtime, not by us";
}

TEST_F(LayerDispatch, OverrideServesOurHandsEvenWhenTheRuntimeHasSome) {
  fake_next::state().runtime_hand_tracking = true;
  use_replay();
  ASSERT_EQ(create(), XR_SUCCESS);
  EXPECT_EQ(fake_next::state().enabled_extensions,
            (std::vector<std::string>{XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME}));
  XrHandTrackerEXT t;
  ASSERT_EQ(create_tracker(XR_HAND_RIGHT_EXT, &t), XR_SUCCESS);
  ASSERT_EQ(locate(t, fake_next::xr_now(), &locations_), XR_SUCCESS);
  EXPECT_TRUE(locations_.isActive);
}

TEST_F(LayerDispatch, DestroyingTheSessionDestroysItsTrackers) {
  use_replay();
  ASSERT_EQ(create(), XR_SUCCESS);
  XrHandTrackerEXT t;
  ASSERT_EQ(create_tracker(XR_HAND_RIGHT_EXT, &t), XR_SUCCESS);
  EXPECT_EQ(fake_next::state().live_spaces.load(), 1);
  ASSERT_EQ(chain_.get<PFN_xrDestroySession>(instance_, "xrDestroySession")(fake_next::session_handle()), XR_SUCCESS);
  EXPECT_EQ(fake_next::state().live_spaces.load(), 0);
  EXPECT_EQ(locate(t, fake_next::xr_now(), &locations_), XR_ERROR_HANDLE_INVALID);
}

}  // namespace
