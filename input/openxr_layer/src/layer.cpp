// XR_APILAYER_PROPRIO_hand_tracking: serves XR_EXT_hand_tracking (plus
// XR_EXT_hand_joints_motion_range and XR_EXT_hand_tracking_data_source) to any
// OpenXR app from Proprio's hand sources, on any runtime.
//
// Rules this file keeps (see docs/openxr-layer.md):
//  - No exception crosses the C ABI: every entry point goes through guarded().
//  - Hooks only what the app enabled; our extensions are stripped before the
//    runtime sees the instance create info.
//  - xrLocateHandJointsEXT takes a shared lock and never allocates.
#include "proprio/core/xr_ext.hpp"  // first: it switches on XR_USE_TIMESPEC

#include <pthread.h>

#include <array>
#include <cstring>
#include <ctime>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "proprio/core/log.hpp"
#include "proprio/core/xr_interop.hpp"
#include "proprio/hand_sources/hand_sources.hpp"
#include "proprio/openxr_layer/layer_config.hpp"
#include "proprio/openxr_layer/loader_interfaces.hpp"
#include "proprio/core/xr_ext.hpp"

namespace proprio::openxr_layer {
namespace {

constexpr const char* kLayerName = "XR_APILAYER_PROPRIO_hand_tracking";
constexpr std::array<std::string_view, 3> kOurExtensions = {
    XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_EXT_HAND_JOINTS_MOTION_RANGE_EXTENSION_NAME,
    XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME};

struct Downstream {
  PFN_xrGetInstanceProcAddr get_instance_proc_addr = nullptr;
  PFN_xrDestroyInstance destroy_instance = nullptr;
  PFN_xrGetSystemProperties get_system_properties = nullptr;
  PFN_xrCreateSession create_session = nullptr;
  PFN_xrDestroySession destroy_session = nullptr;
  PFN_xrCreateReferenceSpace create_reference_space = nullptr;
  PFN_xrDestroySpace destroy_space = nullptr;
  PFN_xrLocateSpace locate_space = nullptr;
  PFN_xrConvertTimeToTimespecTimeKHR convert_time_to_timespec = nullptr;
};

struct HandBinding {
  HandSource* source = nullptr;
  const SourceConfig* config = nullptr;
};

struct Instance {
  XrInstance handle = XR_NULL_HANDLE;
  Downstream next;
  bool hand_tracking = false;  // the app enabled XR_EXT_hand_tracking
  bool motion_range = false;
  bool data_source = false;
  bool serving = false;  // Proprio implements hand tracking for this instance
  LayerConfig config;
  std::vector<std::unique_ptr<HandSource>> sources;
  std::array<HandBinding, 2> hands{};  // indexed by Handedness

  bool any_hand() const { return hands[0].source || hands[1].source; }
};

struct Tracker {
  Instance* instance = nullptr;
  XrSession session = XR_NULL_HANDLE;
  Handedness hand = Handedness::right;
  HandBinding binding;
  XrSpace source_space = XR_NULL_HANDLE;  // the source origin, as a reference space with the configured offset
  bool unobstructed_requested = true;     // XR_EXT_hand_tracking_data_source
};

// A reader-writer lock that lets a waiting writer in. glibc's default (what
// std::shared_mutex uses) prefers readers, so eight threads locating in a
// loop starve xrDestroyHandTrackerEXT forever: the hang Ultraleap's layer once
// showed in the conformance suite. Not recursive: never re-lock on one thread.
class WriterFairSharedMutex {
 public:
  WriterFairSharedMutex() {
    pthread_rwlockattr_t attr;
    pthread_rwlockattr_init(&attr);
    pthread_rwlockattr_setkind_np(&attr, PTHREAD_RWLOCK_PREFER_WRITER_NONRECURSIVE_NP);
    pthread_rwlock_init(&lock_, &attr);
    pthread_rwlockattr_destroy(&attr);
  }
  ~WriterFairSharedMutex() { pthread_rwlock_destroy(&lock_); }
  WriterFairSharedMutex(const WriterFairSharedMutex&) = delete;
  WriterFairSharedMutex& operator=(const WriterFairSharedMutex&) = delete;
  void lock() { pthread_rwlock_wrlock(&lock_); }
  void unlock() { pthread_rwlock_unlock(&lock_); }
  void lock_shared() { pthread_rwlock_rdlock(&lock_); }
  void unlock_shared() { pthread_rwlock_unlock(&lock_); }

 private:
  pthread_rwlock_t lock_;
};

// All layer state. Lookups on the hot path take the shared lock only.
struct Registry {
  WriterFairSharedMutex mutex;
  std::unordered_map<XrInstance, std::unique_ptr<Instance>> instances;
  std::unordered_map<XrSession, Instance*> sessions;
  std::unordered_map<XrHandTrackerEXT, std::unique_ptr<Tracker>> trackers;
};
Registry& registry() {
  static Registry r;
  return r;
}

template <typename F>
XrResult guarded(const char* function, F&& body) noexcept {
  try {
    return body();
  } catch (const std::exception& e) {
    try { logger().error("Proprio layer: {}: internal error: {}", function, e.what()); } catch (...) {}
  } catch (...) {
    try { logger().error("Proprio layer: {}: unknown internal error", function); } catch (...) {}
  }
  return XR_ERROR_RUNTIME_FAILURE;
}

template <typename T>
T* find_in_chain(void* next, XrStructureType type) {
  for (auto* s = static_cast<XrBaseOutStructure*>(next); s; s = s->next) {
    if (s->type == type) return reinterpret_cast<T*>(s);
  }
  return nullptr;
}
template <typename T>
const T* find_in_chain(const void* next, XrStructureType type) {
  for (auto* s = static_cast<const XrBaseInStructure*>(next); s; s = s->next) {
    if (s->type == type) return reinterpret_cast<const T*>(s);
  }
  return nullptr;
}

XrReferenceSpaceType to_xr(ReferenceSpace s) {
  switch (s) {
    case ReferenceSpace::view: return XR_REFERENCE_SPACE_TYPE_VIEW;
    case ReferenceSpace::local: return XR_REFERENCE_SPACE_TYPE_LOCAL;
    case ReferenceSpace::stage: return XR_REFERENCE_SPACE_TYPE_STAGE;
  }
  return XR_REFERENCE_SPACE_TYPE_LOCAL;
}

// Loads the layer config and starts its sources. Failures are logged and
// leave the instance without sources: the app then sees no hand tracking.
void start_sources(Instance& inst) {
  const auto path = default_layer_config_path();
  auto cfg = load_layer_config(path);
  if (!cfg) {
    logger().error("Proprio layer: {}. Proprio serves no hands (a runtime's own hand tracking, "
                   "if any, passes through). Write a config with 'proprio layer init-config'.",
                   cfg.error().message);
    return;
  }
  inst.config = std::move(*cfg);
  for (const SourceConfig& sc : inst.config.sources) {
    auto started = hand_sources::start_hand_source(sc, inst.config.max_prediction_ns);
    if (!started) {
      logger().error("Proprio layer: {}: {}", inst.config.origin, started.error().message);
      continue;
    }
    std::unique_ptr<HandSource> source = std::move(*started);
    const SourceConfig* config = &sc;
    for (Handedness h : sc.hands) {
      auto& binding = inst.hands[static_cast<std::size_t>(h)];
      if (binding.source) {
        logger().warn("Proprio layer: the {} hand already has a source; the later one is ignored for it", to_string(h));
      } else if (source->available(h)) {
        binding = {source.get(), config};
      }
    }
    inst.sources.push_back(std::move(source));
  }
  logger().info("Proprio layer: {}", inst.config.describe());
}

Instance* find_instance_locked(XrInstance handle) {
  auto& r = registry();
  auto it = r.instances.find(handle);
  return it == r.instances.end() ? nullptr : it->second.get();
}

// The Instance outlives the call: only xrDestroyInstance removes it, and an
// app must not call into an instance while destroying it.
Instance* find_instance(XrInstance handle) {
  std::shared_lock lock(registry().mutex);
  return find_instance_locked(handle);
}

// ---- hooked functions ------------------------------------------------------

XRAPI_ATTR XrResult XRAPI_CALL layer_get_instance_proc_addr(XrInstance instance, const char* name,
                                                            PFN_xrVoidFunction* function);

XRAPI_ATTR XrResult XRAPI_CALL layer_get_system_properties(XrInstance instance, XrSystemId system,
                                                           XrSystemProperties* properties) {
  return guarded("xrGetSystemProperties", [&] {
    Instance* inst = find_instance(instance);
    if (!inst) return XR_ERROR_HANDLE_INVALID;
    if (!properties) return XR_ERROR_VALIDATION_FAILURE;
    // The runtime did not enable hand tracking for us, so take our struct out
    // of the chain while it fills the rest, then answer it ourselves.
    XrBaseOutStructure* before = reinterpret_cast<XrBaseOutStructure*>(properties);
    while (before->next && before->next->type != XR_TYPE_SYSTEM_HAND_TRACKING_PROPERTIES_EXT) before = before->next;
    auto* ours = reinterpret_cast<XrSystemHandTrackingPropertiesEXT*>(before->next);
    if (ours) before->next = reinterpret_cast<XrBaseOutStructure*>(ours->next);
    const XrResult r = inst->next.get_system_properties(instance, system, properties);
    if (ours) {
      before->next = reinterpret_cast<XrBaseOutStructure*>(ours);
      if (XR_SUCCEEDED(r)) ours->supportsHandTracking = inst->any_hand() ? XR_TRUE : XR_FALSE;
    }
    return r;
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_create_session(XrInstance instance, const XrSessionCreateInfo* info,
                                                    XrSession* session) {
  return guarded("xrCreateSession", [&] {
    Instance* inst = find_instance(instance);
    if (!inst) return XR_ERROR_HANDLE_INVALID;
    const XrResult r = inst->next.create_session(instance, info, session);
    if (XR_SUCCEEDED(r)) {
      std::unique_lock lock(registry().mutex);
      registry().sessions[*session] = inst;
    }
    return r;
  });
}

// Removes a tracker's downstream space. Caller holds the registry exclusively.
void release_tracker(Tracker& t) {
  if (t.source_space != XR_NULL_HANDLE) t.instance->next.destroy_space(t.source_space);
  t.source_space = XR_NULL_HANDLE;
}

// Child handles go with their parent (OpenXR handle lifetime rules). Caller
// holds the registry exclusively.
template <typename Pred>
void erase_trackers_if(Pred belongs) {
  auto& trackers = registry().trackers;
  for (auto t = trackers.begin(); t != trackers.end();) {
    if (belongs(*t->second)) {
      release_tracker(*t->second);
      t = trackers.erase(t);
    } else {
      ++t;
    }
  }
}

XRAPI_ATTR XrResult XRAPI_CALL layer_destroy_session(XrSession session) {
  return guarded("xrDestroySession", [&] {
    auto& r = registry();
    std::unique_lock lock(r.mutex);
    auto it = r.sessions.find(session);
    if (it == r.sessions.end()) return XR_ERROR_HANDLE_INVALID;
    Instance* inst = it->second;
    erase_trackers_if([&](const Tracker& t) { return t.session == session; });
    r.sessions.erase(it);
    return inst->next.destroy_session(session);
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_destroy_instance(XrInstance instance) {
  return guarded("xrDestroyInstance", [&] {
    auto& r = registry();
    std::unique_ptr<Instance> owned;
    {
      std::unique_lock lock(r.mutex);
      auto it = r.instances.find(instance);
      if (it == r.instances.end()) return XR_ERROR_HANDLE_INVALID;
      erase_trackers_if([&](const Tracker& t) { return t.instance == it->second.get(); });
      for (auto s = r.sessions.begin(); s != r.sessions.end();) {
        s = s->second == it->second.get() ? r.sessions.erase(s) : std::next(s);
      }
      owned = std::move(it->second);
      r.instances.erase(it);
    }
    // Sources (and their threads) stop outside the lock.
    const XrResult result = owned->next.destroy_instance(instance);
    owned.reset();
    return result;
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_create_hand_tracker(XrSession session, const XrHandTrackerCreateInfoEXT* info,
                                                         XrHandTrackerEXT* tracker) {
  return guarded("xrCreateHandTrackerEXT", [&] {
    auto& r = registry();
    Instance* inst;
    {
      std::shared_lock lock(r.mutex);
      auto it = r.sessions.find(session);
      if (it == r.sessions.end()) return XR_ERROR_HANDLE_INVALID;
      inst = it->second;
    }
    if (!info || info->type != XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT || !tracker) return XR_ERROR_VALIDATION_FAILURE;
    if (info->hand != XR_HAND_LEFT_EXT && info->hand != XR_HAND_RIGHT_EXT) return XR_ERROR_VALIDATION_FAILURE;
    if (info->handJointSet != XR_HAND_JOINT_SET_DEFAULT_EXT) return XR_ERROR_VALIDATION_FAILURE;
    if (!inst->any_hand()) return XR_ERROR_FEATURE_UNSUPPORTED;  // supportsHandTracking was false

    auto t = std::make_unique<Tracker>();
    t->instance = inst;
    t->session = session;
    t->hand = info->hand == XR_HAND_LEFT_EXT ? Handedness::left : Handedness::right;
    t->binding = inst->hands[static_cast<std::size_t>(t->hand)];
    if (inst->data_source) {
      if (const auto* ds = find_in_chain<XrHandTrackingDataSourceInfoEXT>(info->next, XR_TYPE_HAND_TRACKING_DATA_SOURCE_INFO_EXT)) {
        if (ds->requestedDataSourceCount == 0 || !ds->requestedDataSources) return XR_ERROR_VALIDATION_FAILURE;
        t->unobstructed_requested = false;
        for (uint32_t i = 0; i < ds->requestedDataSourceCount; ++i) {
          const auto s = ds->requestedDataSources[i];
          if (s != XR_HAND_TRACKING_DATA_SOURCE_UNOBSTRUCTED_EXT && s != XR_HAND_TRACKING_DATA_SOURCE_CONTROLLER_EXT) {
            return XR_ERROR_VALIDATION_FAILURE;
          }
          t->unobstructed_requested |= s == XR_HAND_TRACKING_DATA_SOURCE_UNOBSTRUCTED_EXT;
        }
      }
    }
    if (t->binding.source) {
      auto space_info = xr_struct<XrReferenceSpaceCreateInfo>(XR_TYPE_REFERENCE_SPACE_CREATE_INFO);
      space_info.referenceSpaceType = to_xr(t->binding.config->space);
      space_info.poseInReferenceSpace = proprio::to_xr(t->binding.config->T_space_source);
      const XrResult sr = inst->next.create_reference_space(session, &space_info, &t->source_space);
      if (XR_FAILED(sr)) {
        logger().error("Proprio layer: cannot create the {} reference space for the {} hand source ({})",
                       to_string(t->binding.config->space), to_string(t->hand), static_cast<int>(sr));
        return sr;
      }
    }
    auto handle = reinterpret_cast<XrHandTrackerEXT>(t.get());
    std::unique_lock lock(r.mutex);
    if (!r.sessions.count(session)) {  // destroyed meanwhile by another thread
      release_tracker(*t);
      return XR_ERROR_HANDLE_INVALID;
    }
    r.trackers[handle] = std::move(t);
    *tracker = handle;
    return XR_SUCCESS;
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_destroy_hand_tracker(XrHandTrackerEXT tracker) {
  return guarded("xrDestroyHandTrackerEXT", [&] {
    auto& r = registry();
    std::unique_lock lock(r.mutex);
    auto it = r.trackers.find(tracker);
    if (it == r.trackers.end()) return XR_ERROR_HANDLE_INVALID;
    release_tracker(*it->second);
    r.trackers.erase(it);
    return XR_SUCCESS;
  });
}

// Fills the outputs for "no hand": no valid bits anywhere.
void write_inactive(XrHandJointLocationsEXT* locations, XrHandJointVelocitiesEXT* velocities,
                    XrHandTrackingDataSourceStateEXT* data_source) {
  locations->isActive = XR_FALSE;
  for (uint32_t i = 0; i < locations->jointCount; ++i) locations->jointLocations[i].locationFlags = 0;
  if (velocities) {
    for (uint32_t i = 0; i < velocities->jointCount; ++i) velocities->jointVelocities[i].velocityFlags = 0;
  }
  if (data_source) data_source->isActive = XR_FALSE;
}

XRAPI_ATTR XrResult XRAPI_CALL layer_locate_hand_joints(XrHandTrackerEXT tracker, const XrHandJointsLocateInfoEXT* info,
                                                        XrHandJointLocationsEXT* locations) {
  return guarded("xrLocateHandJointsEXT", [&] {
    std::shared_lock lock(registry().mutex);
    auto& trackers = registry().trackers;
    const auto it = trackers.find(tracker);
    if (it == trackers.end()) return XR_ERROR_HANDLE_INVALID;
    const Tracker& t = *it->second;
    const Instance& inst = *t.instance;

    if (!info || info->type != XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT) return XR_ERROR_VALIDATION_FAILURE;
    if (!locations || locations->type != XR_TYPE_HAND_JOINT_LOCATIONS_EXT) return XR_ERROR_VALIDATION_FAILURE;
    if (info->baseSpace == XR_NULL_HANDLE) return XR_ERROR_HANDLE_INVALID;
    if (locations->jointCount != kHandJointCount || !locations->jointLocations) return XR_ERROR_VALIDATION_FAILURE;
    auto* velocities = find_in_chain<XrHandJointVelocitiesEXT>(locations->next, XR_TYPE_HAND_JOINT_VELOCITIES_EXT);
    if (velocities && (velocities->jointCount != kHandJointCount || !velocities->jointVelocities)) {
      return XR_ERROR_VALIDATION_FAILURE;
    }
    XrHandTrackingDataSourceStateEXT* data_source = nullptr;
    if (inst.data_source) {
      data_source = find_in_chain<XrHandTrackingDataSourceStateEXT>(locations->next, XR_TYPE_HAND_TRACKING_DATA_SOURCE_STATE_EXT);
    }
    if (inst.motion_range) {
      // Glove data is never obstructed by a controller: both ranges get the same joints.
      if (const auto* mr = find_in_chain<XrHandJointsMotionRangeInfoEXT>(info->next, XR_TYPE_HAND_JOINTS_MOTION_RANGE_INFO_EXT)) {
        if (mr->handJointsMotionRange != XR_HAND_JOINTS_MOTION_RANGE_UNOBSTRUCTED_EXT &&
            mr->handJointsMotionRange != XR_HAND_JOINTS_MOTION_RANGE_CONFORMING_TO_CONTROLLER_EXT) {
          return XR_ERROR_VALIDATION_FAILURE;
        }
      }
    }
    if (info->time <= 0) return XR_ERROR_TIME_INVALID;  // before touching any output

    if (!t.binding.source || !t.unobstructed_requested) {
      write_inactive(locations, velocities, data_source);
      return XR_SUCCESS;
    }

    // Where the source origin is in the app's base space at that time.
    auto space_velocity = xr_struct<XrSpaceVelocity>(XR_TYPE_SPACE_VELOCITY);
    auto space_location = xr_struct<XrSpaceLocation>(XR_TYPE_SPACE_LOCATION);
    space_location.next = &space_velocity;
    const XrResult lr = inst.next.locate_space(t.source_space, info->baseSpace, info->time, &space_location);
    if (XR_FAILED(lr)) return lr;
    constexpr XrSpaceLocationFlags kBothValid = XR_SPACE_LOCATION_ORIENTATION_VALID_BIT | XR_SPACE_LOCATION_POSITION_VALID_BIT;
    constexpr XrSpaceLocationFlags kBothTracked = XR_SPACE_LOCATION_ORIENTATION_TRACKED_BIT | XR_SPACE_LOCATION_POSITION_TRACKED_BIT;
    if ((space_location.locationFlags & kBothValid) != kBothValid) {
      write_inactive(locations, velocities, data_source);
      return XR_SUCCESS;
    }

    // XrTime -> CLOCK_MONOTONIC, the time base of every Proprio sample.
    TimeNs t_ns = info->time;
    if (inst.next.convert_time_to_timespec) {
      timespec ts{};
      if (XR_SUCCEEDED(inst.next.convert_time_to_timespec(inst.handle, info->time, &ts))) {
        t_ns = static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
      }
    }

    HandPose pose;
    const PoseLookup found = t.binding.source->lookup(t.hand, t_ns, pose);
    const bool fresh = is_usable(found);
    const bool stale_but_shown = found == PoseLookup::stale && t_ns - pose.time_ns <= inst.config.stale_timeout_ns;
    if ((!fresh && !stale_but_shown) || !pose.active) {
      write_inactive(locations, velocities, data_source);
      return XR_SUCCESS;
    }

    const Pose T_base_source = from_xr(space_location.pose);
    const bool space_tracked = (space_location.locationFlags & kBothTracked) == kBothTracked;
    const XrSpaceLocationFlags joint_flags = kBothValid | (fresh && space_tracked ? kBothTracked : 0);
    locations->isActive = XR_TRUE;
    for (std::size_t i = 0; i < kHandJointCount; ++i) {
      XrHandJointLocationEXT& out = locations->jointLocations[i];
      out.pose = proprio::to_xr(T_base_source * pose.T_world_joint[i]);
      out.radius = static_cast<float>(std::max(pose.radius_m[i], 1e-3));  // positive whenever valid
      out.locationFlags = joint_flags;
    }
    if (velocities) {
      constexpr XrSpaceVelocityFlags kBothVelocities = XR_SPACE_VELOCITY_LINEAR_VALID_BIT | XR_SPACE_VELOCITY_ANGULAR_VALID_BIT;
      const bool known = fresh && pose.has_velocity && (space_velocity.velocityFlags & kBothVelocities) == kBothVelocities;
      const Vec3 v_space = from_xr(space_velocity.linearVelocity);
      const Vec3 w_space = from_xr(space_velocity.angularVelocity);
      for (std::size_t i = 0; i < kHandJointCount; ++i) {
        XrHandJointVelocityEXT& out = velocities->jointVelocities[i];
        if (!known) {
          out.velocityFlags = 0;
          continue;
        }
        // A point fixed in a moving frame moves with it: v = v_o + w x r + R v_rel.
        const Vec3 r = from_xr(locations->jointLocations[i].pose.position) - T_base_source.p;
        out.linearVelocity = proprio::to_xr(Vec3(v_space + w_space.cross(r) + T_base_source.q * pose.linear_velocity_in_world[i]));
        out.angularVelocity = proprio::to_xr(Vec3(w_space + T_base_source.q * pose.angular_velocity_in_world[i]));
        out.velocityFlags = kBothVelocities;
      }
    }
    if (data_source) {
      data_source->isActive = XR_TRUE;
      data_source->dataSource = XR_HAND_TRACKING_DATA_SOURCE_UNOBSTRUCTED_EXT;
    }
    return XR_SUCCESS;
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_get_instance_proc_addr(XrInstance instance, const char* name,
                                                            PFN_xrVoidFunction* function) {
  return guarded("xrGetInstanceProcAddr", [&] {
    if (!name || !function) return XR_ERROR_VALIDATION_FAILURE;
    PFN_xrGetInstanceProcAddr next = nullptr;
    bool hook_hands = false, hook_system = false;
    {
      std::shared_lock lock(registry().mutex);
      const Instance* inst = find_instance_locked(instance);
      if (!inst) {
        *function = nullptr;
        return instance == XR_NULL_HANDLE ? XR_ERROR_FUNCTION_UNSUPPORTED : XR_ERROR_HANDLE_INVALID;
      }
      next = inst->next.get_instance_proc_addr;
      hook_system = inst->hand_tracking && inst->serving;
      hook_hands = hook_system;
    }
    const std::string_view n(name);
    auto ours = [&](auto fn) {
      *function = reinterpret_cast<PFN_xrVoidFunction>(fn);
      return XR_SUCCESS;
    };
    // Always ours, so our per-instance state lives exactly as long as the instance.
    if (n == "xrGetInstanceProcAddr") return ours(&layer_get_instance_proc_addr);
    if (n == "xrDestroyInstance") return ours(&layer_destroy_instance);
    if (hook_system) {
      if (n == "xrGetSystemProperties") return ours(&layer_get_system_properties);
      if (n == "xrCreateSession") return ours(&layer_create_session);
      if (n == "xrDestroySession") return ours(&layer_destroy_session);
    }
    if (hook_hands) {
      if (n == "xrCreateHandTrackerEXT") return ours(&layer_create_hand_tracker);
      if (n == "xrDestroyHandTrackerEXT") return ours(&layer_destroy_hand_tracker);
      if (n == "xrLocateHandJointsEXT") return ours(&layer_locate_hand_joints);
    }
    return next(instance, name, function);
  });
}

bool is_ours(std::string_view ext) {
  for (auto e : kOurExtensions) {
    if (ext == e) return true;
  }
  return false;
}

template <typename Fn>
Fn resolve(PFN_xrGetInstanceProcAddr gipa, XrInstance instance, const char* name) {
  PFN_xrVoidFunction f = nullptr;
  if (XR_FAILED(gipa(instance, name, &f))) return nullptr;
  return reinterpret_cast<Fn>(f);
}

XRAPI_ATTR XrResult XRAPI_CALL layer_create_api_layer_instance(const XrInstanceCreateInfo* info,
                                                               const XrApiLayerCreateInfo* layer_info,
                                                               XrInstance* instance) {
  return guarded("xrCreateApiLayerInstance", [&] {
    if (!info || !instance) return XR_ERROR_VALIDATION_FAILURE;
    if (!layer_info || layer_info->structType != XR_LOADER_INTERFACE_STRUCT_API_LAYER_CREATE_INFO ||
        layer_info->structVersion != PROPRIO_XR_API_LAYER_CREATE_INFO_STRUCT_VERSION ||
        layer_info->structSize != sizeof(XrApiLayerCreateInfo) || !layer_info->nextInfo) {
      logger().error("Proprio layer: the loader passed a malformed XrApiLayerCreateInfo");
      return XR_ERROR_INITIALIZATION_FAILED;
    }
    const XrApiLayerNextInfo* next_info = layer_info->nextInfo;
    if (next_info->structType != XR_LOADER_INTERFACE_STRUCT_API_LAYER_NEXT_INFO ||
        next_info->structVersion != PROPRIO_XR_API_LAYER_NEXT_INFO_STRUCT_VERSION ||
        next_info->structSize != sizeof(XrApiLayerNextInfo) || std::strcmp(next_info->layerName, kLayerName) != 0 ||
        !next_info->nextGetInstanceProcAddr || !next_info->nextCreateApiLayerInstance) {
      logger().error("Proprio layer: the loader passed a malformed XrApiLayerNextInfo");
      return XR_ERROR_INITIALIZATION_FAILED;
    }

    auto inst = std::make_unique<Instance>();
    bool app_convert_timespec = false;
    for (uint32_t i = 0; i < info->enabledExtensionCount; ++i) {
      const std::string_view e(info->enabledExtensionNames[i]);
      inst->hand_tracking |= e == XR_EXT_HAND_TRACKING_EXTENSION_NAME;
      inst->motion_range |= e == XR_EXT_HAND_JOINTS_MOTION_RANGE_EXTENSION_NAME;
      inst->data_source |= e == XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME;
      app_convert_timespec |= e == XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME;
    }
    if (inst->hand_tracking) start_sources(*inst);
    const RuntimeHandTracking mode = inst->config.runtime_hand_tracking;
    inst->serving = inst->hand_tracking && (mode == RuntimeHandTracking::override_it ||
                                            (mode == RuntimeHandTracking::automatic && !inst->sources.empty()));

    // What the rest of the chain sees: without our extensions when we serve
    // them, plus the time conversion we need.
    auto build = [&](bool strip_ours, bool add_timespec) {
      std::vector<const char*> names;
      for (uint32_t i = 0; i < info->enabledExtensionCount; ++i) {
        if (!(strip_ours && is_ours(info->enabledExtensionNames[i]))) names.push_back(info->enabledExtensionNames[i]);
      }
      if (add_timespec) names.push_back(XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME);
      return names;
    };
    XrApiLayerCreateInfo down_layer_info = *layer_info;
    down_layer_info.nextInfo = next_info->next;
    auto create = [&](const std::vector<const char*>& names) {
      XrInstanceCreateInfo down = *info;
      down.enabledExtensionCount = static_cast<uint32_t>(names.size());
      down.enabledExtensionNames = names.data();
      return next_info->nextCreateApiLayerInstance(&down, &down_layer_info, instance);
    };

    bool timespec = app_convert_timespec || inst->serving;
    XrResult r = create(build(inst->serving, timespec && !app_convert_timespec));
    if (r == XR_ERROR_EXTENSION_NOT_PRESENT && inst->hand_tracking && !inst->serving) {
      // The runtime may track hands without the two companion extensions.
      std::vector<const char*> names;
      for (const char* n : build(false, false)) {
        if (!is_ours(n) || std::string_view(n) == XR_EXT_HAND_TRACKING_EXTENSION_NAME) names.push_back(n);
      }
      r = create(names);
    }
    if (r == XR_ERROR_EXTENSION_NOT_PRESENT && inst->hand_tracking && !inst->serving) {
      // Pass-through was wanted but the runtime has no hand tracking: serve
      // ourselves (with no source, the app sees supportsHandTracking = false).
      inst->serving = true;
      timespec = true;
      r = create(build(true, !app_convert_timespec));
    }
    if (r == XR_ERROR_EXTENSION_NOT_PRESENT && timespec && !app_convert_timespec) {
      logger().warn("Proprio layer: the runtime lacks XR_KHR_convert_timespec_time; assuming XrTime is CLOCK_MONOTONIC ns");
      timespec = false;
      r = create(build(inst->serving, false));
    }
    if (XR_FAILED(r)) return r;

    inst->handle = *instance;
    const PFN_xrGetInstanceProcAddr gipa = next_info->nextGetInstanceProcAddr;
    Downstream& d = inst->next;
    d.get_instance_proc_addr = gipa;
    d.destroy_instance = resolve<PFN_xrDestroyInstance>(gipa, *instance, "xrDestroyInstance");
    d.get_system_properties = resolve<PFN_xrGetSystemProperties>(gipa, *instance, "xrGetSystemProperties");
    d.create_session = resolve<PFN_xrCreateSession>(gipa, *instance, "xrCreateSession");
    d.destroy_session = resolve<PFN_xrDestroySession>(gipa, *instance, "xrDestroySession");
    d.create_reference_space = resolve<PFN_xrCreateReferenceSpace>(gipa, *instance, "xrCreateReferenceSpace");
    d.destroy_space = resolve<PFN_xrDestroySpace>(gipa, *instance, "xrDestroySpace");
    d.locate_space = resolve<PFN_xrLocateSpace>(gipa, *instance, "xrLocateSpace");
    if (timespec) {
      d.convert_time_to_timespec = resolve<PFN_xrConvertTimeToTimespecTimeKHR>(gipa, *instance, "xrConvertTimeToTimespecTimeKHR");
    }
    if (!d.destroy_instance || !d.get_system_properties || !d.create_session || !d.destroy_session ||
        !d.create_reference_space || !d.destroy_space || !d.locate_space) {
      logger().error("Proprio layer: the next layer or runtime lacks core functions");
      if (d.destroy_instance) d.destroy_instance(*instance);
      return XR_ERROR_INITIALIZATION_FAILED;
    }
    if (inst->serving) {
      logger().info("Proprio layer: serving XR_EXT_hand_tracking ({} source(s))", inst->sources.size());
    } else if (inst->hand_tracking) {
      logger().info("Proprio layer: passing the runtime's own hand tracking through");
    }
    std::unique_lock lock(registry().mutex);
    registry().instances[*instance] = std::move(inst);
    return XR_SUCCESS;
  });
}

}  // namespace
}  // namespace proprio::openxr_layer

extern "C" __attribute__((visibility("default"))) XrResult XRAPI_CALL
xrNegotiateLoaderApiLayerInterface(const XrNegotiateLoaderInfo* loader_info, const char* layer_name,
                                   XrNegotiateApiLayerRequest* request) {
  using namespace proprio::openxr_layer;
  return guarded("xrNegotiateLoaderApiLayerInterface", [&] {
    if (!loader_info || !layer_name || !request) return XR_ERROR_INITIALIZATION_FAILED;
    if (loader_info->structType != XR_LOADER_INTERFACE_STRUCT_LOADER_INFO ||
        loader_info->structVersion != PROPRIO_XR_LOADER_INFO_STRUCT_VERSION ||
        loader_info->structSize != sizeof(XrNegotiateLoaderInfo)) {
      return XR_ERROR_INITIALIZATION_FAILED;
    }
    if (request->structType != XR_LOADER_INTERFACE_STRUCT_API_LAYER_REQUEST ||
        request->structVersion != PROPRIO_XR_API_LAYER_INFO_STRUCT_VERSION ||
        request->structSize != sizeof(XrNegotiateApiLayerRequest)) {
      return XR_ERROR_INITIALIZATION_FAILED;
    }
    if (std::strcmp(layer_name, kLayerName) != 0) return XR_ERROR_INITIALIZATION_FAILED;
    constexpr uint32_t kInterface = PROPRIO_XR_CURRENT_LOADER_API_LAYER_VERSION;
    if (loader_info->minInterfaceVersion > kInterface || loader_info->maxInterfaceVersion < kInterface) {
      return XR_ERROR_INITIALIZATION_FAILED;
    }
    // We implement OpenXR 1.0.x.
    if (XR_VERSION_MAJOR(loader_info->minApiVersion) > 1 || XR_VERSION_MAJOR(loader_info->maxApiVersion) < 1) {
      return XR_ERROR_INITIALIZATION_FAILED;
    }
    request->layerInterfaceVersion = kInterface;
    request->layerApiVersion = XR_CURRENT_API_VERSION;
    request->getInstanceProcAddr = &layer_get_instance_proc_addr;
    request->createApiLayerInstance = &layer_create_api_layer_instance;
    return XR_SUCCESS;
  });
}
