// The layer's own cost in xrLocateHandJointsEXT. The downstream xrLocateSpace
// is the fake one of fake_next.hpp (a struct copy), so what is timed is the
// layer: handle lookup, validation, time conversion, pose lookup and the 26
// joint transforms. Reports median and p99 per call as counters.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <filesystem>
#include <fstream>

#include "fake_next.hpp"

namespace {

void BM_LayerLocateHandJoints(benchmark::State& state) {
  const auto cfg = std::filesystem::temp_directory_path() / "proprio_bench_layer.toml";
  std::ofstream(cfg) << "[[source]]\ntype = \"sim\"\nspace = \"local\"\nrate_hz = 90\n";
  ::setenv("PROPRIO_LAYER_CONFIG", cfg.c_str(), 1);

  fake_next::Chain chain;
  chain.negotiate();
  XrInstance instance;
  if (chain.create_instance({XR_EXT_HAND_TRACKING_EXTENSION_NAME}, &instance) != XR_SUCCESS) {
    state.SkipWithError("instance creation failed");
    return;
  }
  XrSession session;
  auto session_info = xr_struct<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  chain.get<PFN_xrCreateSession>(instance, "xrCreateSession")(instance, &session_info, &session);
  auto tracker_info = xr_struct<XrHandTrackerCreateInfoEXT>(XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT);
  tracker_info.hand = XR_HAND_RIGHT_EXT;
  tracker_info.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
  XrHandTrackerEXT tracker;
  chain.get<PFN_xrCreateHandTrackerEXT>(instance, "xrCreateHandTrackerEXT")(session, &tracker_info, &tracker);
  auto locate = chain.get<PFN_xrLocateHandJointsEXT>(instance, "xrLocateHandJointsEXT");

  std::array<XrHandJointLocationEXT, 26> joints{};
  std::array<XrHandJointVelocityEXT, 26> vel{};
  auto velocities = xr_struct<XrHandJointVelocitiesEXT>(XR_TYPE_HAND_JOINT_VELOCITIES_EXT);
  velocities.jointCount = 26;
  velocities.jointVelocities = vel.data();
  auto locations = xr_struct<XrHandJointLocationsEXT>(XR_TYPE_HAND_JOINT_LOCATIONS_EXT);
  locations.jointCount = 26;
  locations.jointLocations = joints.data();
  locations.next = state.range(0) ? &velocities : nullptr;
  auto info = xr_struct<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);
  info.baseSpace = reinterpret_cast<XrSpace>(0x4004);

  std::vector<double> ns;
  ns.reserve(1 << 20);
  for (auto _ : state) {
    info.time = fake_next::xr_now();  // "now": interpolation or short prediction, as an app asks
    const auto t0 = std::chrono::steady_clock::now();
    const XrResult r = locate(tracker, &info, &locations);
    const auto t1 = std::chrono::steady_clock::now();
    benchmark::DoNotOptimize(r);
    if (ns.size() < ns.capacity()) ns.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count());
  }
  if (!locations.isActive) state.SkipWithError("hand not active");
  std::sort(ns.begin(), ns.end());
  if (!ns.empty()) {
    state.counters["p50_us"] = ns[ns.size() / 2] * 1e-3;
    state.counters["p99_us"] = ns[ns.size() * 99 / 100] * 1e-3;
  }
  state.SetLabel(state.range(0) ? "with velocities" : "locations only");
  chain.get<PFN_xrDestroyInstance>(instance, "xrDestroyInstance")(instance);
}
BENCHMARK(BM_LayerLocateHandJoints)->Arg(0)->Arg(1)->MinTime(1.0);

}  // namespace
