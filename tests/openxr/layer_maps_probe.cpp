// A bare OpenXR app for test_layer_source_plugins.cpp: run in a fresh process
// with the loader, mock runtime and layer config set in its environment, it
// creates an instance, a headless session and a tracker per hand (so the
// layer really starts its sources), locates the hands until both are active
// (or 5 s pass), then prints every shared object mapped into it. Argument:
// "both" (default) or "right": the hands that must become active.
//
// It links the OpenXR loader and nothing of Proprio, so whatever else it maps
// came in with the layer. Output lines: "active <left> <right>" and
// "mapped <path>". Exit: 0 done, 1 an OpenXR call failed, 2 no hand tracking.
#include <openxr/openxr.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <set>
#include <string>
#include <thread>

#include "mock_motion.hpp"

namespace {

template <typename T>
T xr(XrStructureType type) {
  T s{};
  s.type = type;
  return s;
}

bool ok(XrResult r, const char* what) {
  if (r == XR_SUCCESS) return true;
  std::fprintf(stderr, "%s failed: %d\n", what, static_cast<int>(r));
  return false;
}

void print_mapped() {
  std::ifstream maps("/proc/self/maps");
  std::set<std::string> seen;
  for (std::string line; std::getline(maps, line);) {
    const auto slash = line.find('/');
    if (slash == std::string::npos) continue;
    const std::string path = line.substr(slash);
    if (path.find(".so") != std::string::npos && seen.insert(path).second) std::printf("mapped %s\n", path.c_str());
  }
}

}  // namespace

int main(int argc, char** argv) {
  const bool need_left = !(argc > 1 && std::strcmp(argv[1], "right") == 0);
  const char* extensions[] = {XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_MND_HEADLESS_EXTENSION_NAME};
  auto info = xr<XrInstanceCreateInfo>(XR_TYPE_INSTANCE_CREATE_INFO);
  std::strcpy(info.applicationInfo.applicationName, "proprio layer maps probe");
  info.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
  info.enabledExtensionCount = 2;
  info.enabledExtensionNames = extensions;
  XrInstance instance = XR_NULL_HANDLE;
  if (!ok(xrCreateInstance(&info, &instance), "xrCreateInstance")) return 1;
  auto getinfo = xr<XrSystemGetInfo>(XR_TYPE_SYSTEM_GET_INFO);
  getinfo.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  if (!ok(xrGetSystem(instance, &getinfo, &system), "xrGetSystem")) return 1;
  auto ht = xr<XrSystemHandTrackingPropertiesEXT>(XR_TYPE_SYSTEM_HAND_TRACKING_PROPERTIES_EXT);
  auto props = xr<XrSystemProperties>(XR_TYPE_SYSTEM_PROPERTIES);
  props.next = &ht;
  if (!ok(xrGetSystemProperties(instance, system, &props), "xrGetSystemProperties")) return 1;
  if (!ht.supportsHandTracking) {
    std::printf("no hand tracking\n");
    print_mapped();
    return 2;
  }
  auto sinfo = xr<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  sinfo.systemId = system;
  XrSession session = XR_NULL_HANDLE;
  if (!ok(xrCreateSession(instance, &sinfo, &session), "xrCreateSession")) return 1;
  auto sp = xr<XrReferenceSpaceCreateInfo>(XR_TYPE_REFERENCE_SPACE_CREATE_INFO);
  sp.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_LOCAL;
  sp.poseInReferenceSpace = proprio::mock_xr::kIdentityPose;
  XrSpace local = XR_NULL_HANDLE;
  if (!ok(xrCreateReferenceSpace(session, &sp, &local), "xrCreateReferenceSpace")) return 1;
  PFN_xrVoidFunction f = nullptr;
  if (!ok(xrGetInstanceProcAddr(instance, "xrCreateHandTrackerEXT", &f), "xrGetInstanceProcAddr")) return 1;
  auto create_tracker = reinterpret_cast<PFN_xrCreateHandTrackerEXT>(f);
  if (!ok(xrGetInstanceProcAddr(instance, "xrLocateHandJointsEXT", &f), "xrGetInstanceProcAddr")) return 1;
  auto locate = reinterpret_cast<PFN_xrLocateHandJointsEXT>(f);
  XrHandTrackerEXT trackers[2]{};
  for (int h = 0; h < 2; ++h) {
    auto tinfo = xr<XrHandTrackerCreateInfoEXT>(XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT);
    tinfo.hand = h == 0 ? XR_HAND_LEFT_EXT : XR_HAND_RIGHT_EXT;
    tinfo.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
    if (!ok(create_tracker(session, &tinfo, &trackers[h]), "xrCreateHandTrackerEXT")) return 1;
  }
  int active[2] = {0, 0};
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (std::chrono::steady_clock::now() < until && ((need_left && active[0] == 0) || active[1] == 0)) {
    for (int h = 0; h < 2; ++h) {
      XrHandJointLocationEXT joints[XR_HAND_JOINT_COUNT_EXT];
      auto out = xr<XrHandJointLocationsEXT>(XR_TYPE_HAND_JOINT_LOCATIONS_EXT);
      out.jointCount = XR_HAND_JOINT_COUNT_EXT;
      out.jointLocations = joints;
      auto li = xr<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);
      li.baseSpace = local;
      li.time = proprio::mock_xr::xr_time_now();
      if (!ok(locate(trackers[h], &li, &out), "xrLocateHandJointsEXT")) return 1;
      if (out.isActive) ++active[h];
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  std::printf("active %d %d\n", active[0], active[1]);
  print_mapped();
  std::fflush(stdout);
  return ok(xrDestroyInstance(instance), "xrDestroyInstance") ? 0 : 1;
}
