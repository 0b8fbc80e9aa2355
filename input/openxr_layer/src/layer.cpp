// XR_APILAYER_PROPRIO_hand_tracking: serves XR_EXT_hand_tracking (plus
// XR_EXT_hand_joints_motion_range and XR_EXT_hand_tracking_data_source) to any
// OpenXR app from Proprio's hand sources, on any runtime.
//
// Rules this file keeps (see docs/openxr-layer.md):
//  - No exception crosses the C ABI: every entry point goes through guarded().
//  - Hooks only what the app enabled; our extensions are stripped before the
//    runtime sees the instance create info.
//  - xrLocateHandJointsEXT takes a shared lock and never allocates.
//  - What the layer asks the runtime for itself (the headset's pose for a
//    head-mounted camera, a wrist from a controller, a tracker or the
//    runtime's own hand tracking) it asks only when a configured source needs
//    it, and never disturbs the app's own actions (RuntimeHeadProvider and
//    "the wrist actions" below).
#include "proprio/core/xr_ext.hpp"  // first: it switches on XR_USE_TIMESPEC

#include <pthread.h>

#include <array>
#include <atomic>
#include <cmath>
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
#include "proprio/hand_sources/plugin_loader.hpp"
#include "proprio/openxr/XR_PROPRIO_fingertip_haptics.h"
#include "proprio/openxr/XR_PROPRIO_hand_tracking_latency.h"
#include "proprio/openxr_layer/fingertip_haptics_service.hpp"
#include "proprio/openxr_layer/loader_interfaces.hpp"

namespace proprio::openxr_layer {
namespace {

constexpr const char* kLayerName = "XR_APILAYER_PROPRIO_hand_tracking";
constexpr std::array<std::string_view, 4> kOurExtensions = {
    XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_EXT_HAND_JOINTS_MOTION_RANGE_EXTENSION_NAME,
    XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME, XR_PROPRIO_HAND_TRACKING_LATENCY_EXTENSION_NAME};
// The layer's own action set: a name an app will not pick, the lowest priority.
constexpr const char* kActionSetName = "proprio_layer_wrist";

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
  PFN_xrConvertTimespecTimeToTimeKHR convert_timespec_to_time = nullptr;
  // Only resolved when a source takes its wrist from the runtime.
  PFN_xrStringToPath string_to_path = nullptr;
  PFN_xrCreateActionSet create_action_set = nullptr;
  PFN_xrCreateAction create_action = nullptr;
  PFN_xrSuggestInteractionProfileBindings suggest_bindings = nullptr;
  PFN_xrAttachSessionActionSets attach_action_sets = nullptr;
  PFN_xrSyncActions sync_actions = nullptr;
  PFN_xrCreateActionSpace create_action_space = nullptr;
  PFN_xrBeginFrame begin_frame = nullptr;
  PFN_xrPollEvent poll_event = nullptr;
  PFN_xrCreateHandTrackerEXT create_hand_tracker = nullptr;
  PFN_xrDestroyHandTrackerEXT destroy_hand_tracker = nullptr;
  PFN_xrLocateHandJointsEXT locate_hand_joints = nullptr;
  // Only resolved when [haptics] is configured.
  PFN_xrApplyHapticFeedback apply_haptic_feedback = nullptr;
  PFN_xrStopHapticFeedback stop_haptic_feedback = nullptr;
};

// The head pose for a source's head-mounted camera, from the app's runtime.
// Sources call it on their own threads; it finds its instance through the
// registry each time (never a raw pointer that could dangle), so it answers
// false before the instance exists, without a session, and after it is gone.
class RuntimeHeadProvider final : public TrackedPoseProvider {
 public:
  explicit RuntimeHeadProvider(std::size_t config_index) : config_index_(config_index) {}
  void bind(XrInstance instance) noexcept { instance_.store(instance, std::memory_order_release); }
  bool locate(TrackedPose what, TimeNs t_ns, Pose& T_world_x) noexcept override;

 private:
  std::size_t config_index_;
  std::atomic<XrInstance> instance_{XR_NULL_HANDLE};
};

// What the wrist of a source's hands comes from, resolved at start-up.
struct WristPlan {
  WristSource kind = WristSource::source;
  Pose T_device_wrist;
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
  bool latency = false;   // XR_PROPRIO_hand_tracking_latency
  bool fingertip = false;  // XR_PROPRIO_fingertip_haptics
  bool serving = false;  // Proprio implements hand tracking for this instance
  bool app_vive_tracker = false;    // the app itself enabled XR_HTCX_vive_tracker_interaction
  bool vive_tracker = false;        // enabled downstream (by the app or for a tracker wrist)
  bool runtime_hands = false;       // XR_EXT_hand_tracking enabled downstream for a runtime_hand wrist
  LayerConfig config;
  // Declared before the sources: a source may call its provider until it stops.
  std::vector<std::unique_ptr<RuntimeHeadProvider>> head_providers;
  std::vector<std::unique_ptr<HandSource>> sources;
  std::array<HandBinding, 2> hands{};  // indexed by Handedness
  std::array<WristPlan, 2> wrist{};    // per hand

  // The layer's wrist actions (controller and tracker wrists only).
  XrActionSet action_set = XR_NULL_HANDLE;
  XrAction grip_action = XR_NULL_HANDLE;     // subaction paths /user/hand/{left,right}
  XrAction tracker_action = XR_NULL_HANDLE;  // subaction paths: the trackers' role paths
  std::array<XrPath, 2> hand_paths{}, tracker_paths{};
  // Our suggested bindings per interaction profile, merged into the app's.
  std::vector<std::pair<XrPath, std::vector<XrActionSuggestedBinding>>> our_bindings;
  std::vector<XrPath> app_suggested;  // profiles the app suggested for (guarded by the registry lock)

  std::array<XrPath, 2> haptic_hand_paths{};  // /user/hand/{left,right}, for xrApplyHapticFeedback

  bool any_hand() const { return hands[0].source || hands[1].source; }
  // Sessions get the fingertip devices: for the extension, or for mapping
  // the app's vibrations.
  bool haptics_wanted() const {
    return config.haptics.enabled && (fingertip || config.haptics.vibration_gain > 0.0);
  }
  bool wants_actions() const { return action_set != XR_NULL_HANDLE; }
};

struct Session {
  XrSession handle = XR_NULL_HANDLE;
  Instance* instance = nullptr;
  XrSpace view_space = XR_NULL_HANDLE;
  std::vector<XrSpace> source_spaces;  // per configured source, the source origin
  std::array<XrSpace, 2> wrist_spaces{};  // per hand: the layer's action space for the wrist device
  bool attached = false;  // our action set went along with the app's
  // An app that attaches no action sets of its own within its first
  // kAttachAloneAfterFrames frames gets ours attached alone, synced each frame.
  std::atomic<std::uint32_t> frames{0};
  std::atomic<bool> app_attached{false};
  std::atomic<bool> attached_alone{false};
  // The fingertip devices ([haptics]), output on only while FOCUSED, and the
  // app's XrFingertipHapticsPROPRIO (one per session).
  std::unique_ptr<FingertipHapticsService> haptics;
  XrFingertipHapticsPROPRIO haptics_handle = XR_NULL_HANDLE;
  std::atomic<bool> haptics_creating{false};
};
constexpr std::uint32_t kAttachAloneAfterFrames = 90;

struct Tracker {
  Instance* instance = nullptr;
  XrSession session = XR_NULL_HANDLE;
  Handedness hand = Handedness::right;
  HandBinding binding;
  XrSpace source_space = XR_NULL_HANDLE;  // the source origin, as a reference space with the configured offset
  bool unobstructed_requested = true;     // XR_EXT_hand_tracking_data_source
  XrHandTrackerEXT runtime_hand = XR_NULL_HANDLE;  // the runtime's own tracker, for a runtime_hand wrist
  XrSpace wrist_space = XR_NULL_HANDLE;            // the session's action space for this hand's wrist device
  // The last wrist the runtime gave, shown (not tracked) while it is lost.
  mutable std::mutex wrist_mutex;
  mutable Pose last_T_base_wrist;
  mutable XrSpace last_wrist_base = XR_NULL_HANDLE;
  mutable TimeNs last_wrist_ns = 0;
  // XR_PROPRIO_hand_tracking_latency: lock-free, locate may run on many threads.
  mutable std::array<std::atomic<std::uint64_t>, XR_PROPRIO_LATENCY_BIN_COUNT> sample_to_ready{}, age_at_locate{};
  mutable std::atomic<std::uint64_t> pose_count{0};
  mutable std::atomic<std::int64_t> max_sample_to_ready_ns{0}, max_age_ns{0};
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
  std::unordered_map<XrSession, std::unique_ptr<Session>> sessions;
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

// Loads the layer config. A failure leaves the instance without sources or
// haptics: the app then sees no hand tracking. It is logged for an app that
// asked for what the config provides (quiet: an app that only might get its
// vibrations mapped, and must not see the layer at all otherwise).
bool load_config(Instance& inst, bool quiet) {
  const auto path = default_layer_config_path();
  auto cfg = load_layer_config(path);
  if (!cfg && quiet) return false;
  if (!cfg) {
    logger().error("Proprio layer: {}. Proprio serves no hands (a runtime's own hand tracking, "
                   "if any, passes through). Write a config with 'proprio layer init-config'.",
                   cfg.error().message);
    return false;
  }
  inst.config = std::move(*cfg);
  return true;
}

// Starts the configured sources.
void start_sources(Instance& inst) {
  for (std::size_t i = 0; i < inst.config.sources.size(); ++i) {
    SourceConfig& sc = inst.config.sources[i];
    if (!sc.wrist_calibration.empty()) {
      auto offset = load_wrist_calibration(sc.wrist_calibration);
      if (!offset) {
        logger().error("Proprio layer: {}: [[source]] #{}: {}", inst.config.origin, i + 1, offset.error().message);
        continue;
      }
      sc.T_device_wrist = *offset;
    }
    inst.head_providers.push_back(std::make_unique<RuntimeHeadProvider>(i));
    auto started = hand_sources::start_hand_source(sc, inst.config.max_prediction_ns, inst.head_providers.back().get());
    if (!started) {
      logger().error("Proprio layer: {}: {}", inst.config.origin, started.error().message);
      continue;
    }
    std::unique_ptr<HandSource> source = std::move(*started);
    for (Handedness h : sc.hands) {
      const auto hi = static_cast<std::size_t>(h);
      auto& binding = inst.hands[hi];
      if (binding.source) {
        logger().warn("Proprio layer: the {} hand already has a source; the later one is ignored for it", to_string(h));
      } else if (source->available(h)) {
        binding = {source.get(), &sc};
        inst.wrist[hi] = {sc.wrist, sc.T_device_wrist};
      }
    }
    inst.sources.push_back(std::move(source));
  }
  logger().info("Proprio layer: {}", inst.config.describe());
}

bool any_wrist(const Instance& inst, WristSource kind) {
  for (std::size_t h = 0; h < 2; ++h) {
    if (inst.hands[h].source && inst.wrist[h].kind == kind) return true;
  }
  return false;
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
    // The runtime did not enable hand tracking for us and knows nothing of
    // fingertip haptics, so take our structs out of the chain while it fills
    // the rest (restoring the app's chain as it was), then answer them.
    struct Taken {
      XrBaseOutStructure* before = nullptr;
      XrBaseOutStructure* ours = nullptr;
    };
    const auto take = [&](XrStructureType type) {
      Taken t;
      t.before = reinterpret_cast<XrBaseOutStructure*>(properties);
      while (t.before->next && t.before->next->type != type) t.before = t.before->next;
      t.ours = t.before->next;
      if (t.ours) t.before->next = t.ours->next;
      return t;
    };
    const Taken hands = inst->serving ? take(XR_TYPE_SYSTEM_HAND_TRACKING_PROPERTIES_EXT) : Taken{};
    const Taken fingertips = inst->fingertip ? take(XR_TYPE_SYSTEM_FINGERTIP_HAPTICS_PROPERTIES_PROPRIO) : Taken{};
    const XrResult r = inst->next.get_system_properties(instance, system, properties);
    for (const Taken* t : {&fingertips, &hands}) {  // put back in reverse order
      if (t->ours) t->before->next = t->ours;
    }
    if (XR_SUCCEEDED(r) && hands.ours) {
      reinterpret_cast<XrSystemHandTrackingPropertiesEXT*>(hands.ours)->supportsHandTracking =
          inst->any_hand() ? XR_TRUE : XR_FALSE;
    }
    if (XR_SUCCEEDED(r) && fingertips.ours) {
      auto* f = reinterpret_cast<XrSystemFingertipHapticsPropertiesPROPRIO*>(fingertips.ours);
      // Configured is what an app can know before a session starts the devices.
      f->supportsFingertipHaptics = inst->config.haptics.enabled ? XR_TRUE : XR_FALSE;
      f->supportsContactSimulation = inst->config.haptics.enabled && inst->config.haptics.contact ? XR_TRUE : XR_FALSE;
    }
    return r;
  });
}

// A reference space for the session, or XR_NULL_HANDLE (logged) if the runtime refuses.
XrSpace make_reference_space(const Instance& inst, XrSession session, XrReferenceSpaceType type, const Pose& pose,
                             const char* what) {
  auto info = xr_struct<XrReferenceSpaceCreateInfo>(XR_TYPE_REFERENCE_SPACE_CREATE_INFO);
  info.referenceSpaceType = type;
  info.poseInReferenceSpace = proprio::to_xr(pose);
  XrSpace space = XR_NULL_HANDLE;
  if (const XrResult r = inst.next.create_reference_space(session, &info, &space); XR_FAILED(r)) {
    logger().error("Proprio layer: the runtime refused the {} space ({})", what, static_cast<int>(r));
    return XR_NULL_HANDLE;
  }
  return space;
}

// A head-mounted camera needs to know where the head was at each capture.
bool needs_head(const SourceConfig& sc) { return sc.type == SourceType::vist && sc.input != "replay"; }

// The spaces the layer locates itself in a session: the head, each source's
// origin and the wrist devices' action spaces.
std::unique_ptr<Session> make_session(Instance& inst, XrSession handle) {
  auto s = std::make_unique<Session>();
  s->handle = handle;
  s->instance = &inst;
  if (std::any_of(inst.config.sources.begin(), inst.config.sources.end(), needs_head)) {
    s->view_space = make_reference_space(inst, handle, XR_REFERENCE_SPACE_TYPE_VIEW, Pose{}, "VIEW");
    for (const SourceConfig& sc : inst.config.sources) {
      s->source_spaces.push_back(make_reference_space(inst, handle, to_xr(sc.space), sc.T_space_source, "source origin"));
    }
  }
  for (std::size_t h = 0; h < 2 && inst.wants_actions(); ++h) {
    const WristSource kind = inst.wrist[h].kind;
    if (!inst.hands[h].source || (kind != WristSource::controller && kind != WristSource::tracker)) continue;
    const bool tracker = kind == WristSource::tracker;
    if (tracker && inst.tracker_action == XR_NULL_HANDLE) continue;  // the runtime has no trackers
    auto info = xr_struct<XrActionSpaceCreateInfo>(XR_TYPE_ACTION_SPACE_CREATE_INFO);
    info.action = tracker ? inst.tracker_action : inst.grip_action;
    info.subactionPath = tracker ? inst.tracker_paths[h] : inst.hand_paths[h];
    info.poseInActionSpace = proprio::to_xr(Pose{});
    if (const XrResult r = inst.next.create_action_space(handle, &info, &s->wrist_spaces[h]); XR_FAILED(r)) {
      logger().error("Proprio layer: the runtime refused the {} hand's wrist {} space ({})",
                     to_string(static_cast<Handedness>(h)), tracker ? "tracker" : "controller", static_cast<int>(r));
      s->wrist_spaces[h] = XR_NULL_HANDLE;
    }
  }
  return s;
}

void release_session(Session& s) {
  const Downstream& d = s.instance->next;
  auto drop = [&](XrSpace& space) {
    if (space != XR_NULL_HANDLE) d.destroy_space(space);
    space = XR_NULL_HANDLE;
  };
  drop(s.view_space);
  for (XrSpace& space : s.source_spaces) drop(space);
  for (XrSpace& space : s.wrist_spaces) drop(space);
}

// The session's fingertip devices, through the haptics plugin. A failure is
// logged; the app's xrCreateFingertipHapticsPROPRIO then returns
// XR_ERROR_FEATURE_UNSUPPORTED (supportsFingertipHaptics says only what is
// configured: it is asked before any session exists).
void start_haptics(const Instance& inst, Session& s) {
  auto plugin = hand_sources::load_plugin("haptics");
  if (plugin && (*plugin)->start_haptics == nullptr) {
    plugin = make_error(Errc::unsupported, "the haptics plugin has no start_haptics; reinstall Proprio");
  }
  if (!plugin) {
    logger().error("Proprio layer: no fingertip haptics: {}", plugin.error().message);
    return;
  }
  auto service = (*plugin)->start_haptics(inst.config.haptics);
  if (!service) {
    logger().error("Proprio layer: no fingertip haptics: {}: {}", inst.config.origin, service.error().message);
    return;
  }
  s.haptics = std::move(*service);
  s.haptics->set_output(false);  // until the session is FOCUSED
  logger().info("Proprio layer: fingertip haptics: {}", s.haptics->describe());
}

void erase_haptics_of(const Instance* inst, XrSession session);

XRAPI_ATTR XrResult XRAPI_CALL layer_create_session(XrInstance instance, const XrSessionCreateInfo* info,
                                                    XrSession* session) {
  return guarded("xrCreateSession", [&] {
    Instance* inst = find_instance(instance);
    if (!inst) return XR_ERROR_HANDLE_INVALID;
    const XrResult r = inst->next.create_session(instance, info, session);
    if (XR_SUCCEEDED(r)) {
      auto state = make_session(*inst, *session);
      if (inst->haptics_wanted()) start_haptics(*inst, *state);
      std::unique_lock lock(registry().mutex);
      registry().sessions[*session] = std::move(state);
    }
    return r;
  });
}

// Removes a tracker's downstream handles. Caller holds the registry exclusively.
void release_tracker(Tracker& t) {
  if (t.source_space != XR_NULL_HANDLE) t.instance->next.destroy_space(t.source_space);
  t.source_space = XR_NULL_HANDLE;
  if (t.runtime_hand != XR_NULL_HANDLE) t.instance->next.destroy_hand_tracker(t.runtime_hand);
  t.runtime_hand = XR_NULL_HANDLE;
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
    Instance* inst = it->second->instance;
    erase_trackers_if([&](const Tracker& t) { return t.session == session; });
    erase_haptics_of(nullptr, session);
    release_session(*it->second);
    it->second->haptics.reset();  // zero on every device, before the session goes
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
      erase_haptics_of(it->second.get(), XR_NULL_HANDLE);
      // The runtime destroys the sessions' children with the instance.
      for (auto s = r.sessions.begin(); s != r.sessions.end();) {
        s = s->second->instance == it->second.get() ? r.sessions.erase(s) : std::next(s);
      }
      owned = std::move(it->second);
      r.instances.erase(it);
    }
    // Sources (and their threads) stop outside the lock, before the runtime
    // goes: a head provider asking now finds no instance and answers false.
    owned->sources.clear();
    const XrResult result = owned->next.destroy_instance(instance);
    owned.reset();
    return result;
  });
}

// ---- the wrist actions -------------------------------------------------------
//
// The layer's action set rides along with the app's, as input-remapping
// layers do: its bindings are appended to the app's suggestion for the same
// interaction profile (a later suggestion for a profile replaces an earlier
// one, so suggesting separately would erase the app's or ours), suggested
// alone at attach time for profiles the app did not name, attached with the
// app's sets and synced with them. The app's actions, bindings and priorities
// are untouched. An app that never attaches action sets gets no
// controller or tracker wrist (the hand is shown at the source's own wrist).

Result<XrPath> to_path(const Instance& inst, const std::string& text) {
  XrPath path = XR_NULL_PATH;
  if (const XrResult r = inst.next.string_to_path(inst.handle, text.c_str(), &path); XR_FAILED(r)) {
    return make_error(Errc::invalid_argument, "the runtime refused the path " + text + " (" + std::to_string(r) + ")");
  }
  return path;
}

// Creates the action set and its pose actions, and plans the bindings. Errors
// leave the instance without actions (logged by the caller).
Status create_wrist_actions(Instance& inst) {
  const bool want_controller = any_wrist(inst, WristSource::controller);
  const bool want_tracker = any_wrist(inst, WristSource::tracker) && inst.vive_tracker;
  if (!want_controller && !want_tracker) return {};
  auto set_info = xr_struct<XrActionSetCreateInfo>(XR_TYPE_ACTION_SET_CREATE_INFO);
  std::snprintf(set_info.actionSetName, sizeof set_info.actionSetName, "%s", kActionSetName);
  std::snprintf(set_info.localizedActionSetName, sizeof set_info.localizedActionSetName, "Proprio glove wrist");
  set_info.priority = 0;
  if (const XrResult r = inst.next.create_action_set(inst.handle, &set_info, &inst.action_set); XR_FAILED(r)) {
    return make_error(Errc::unavailable, "the runtime refused the layer's action set (" + std::to_string(r) + ")");
  }
  auto make_action = [&](const char* name, const char* label, const std::array<XrPath, 2>& subactions,
                         XrAction& action) -> Status {
    auto info = xr_struct<XrActionCreateInfo>(XR_TYPE_ACTION_CREATE_INFO);
    std::snprintf(info.actionName, sizeof info.actionName, "%s", name);
    std::snprintf(info.localizedActionName, sizeof info.localizedActionName, "%s", label);
    info.actionType = XR_ACTION_TYPE_POSE_INPUT;
    info.countSubactionPaths = 2;
    info.subactionPaths = subactions.data();
    if (const XrResult r = inst.next.create_action(inst.action_set, &info, &action); XR_FAILED(r)) {
      return make_error(Errc::unavailable, std::string("the runtime refused the layer's ") + name + " action (" +
                                               std::to_string(r) + ")");
    }
    return {};
  };
  auto bind = [&](const std::string& profile, XrAction action, const std::string& binding) -> Status {
    auto profile_path = to_path(inst, profile);
    if (!profile_path) return profile_path.error();
    auto binding_path = to_path(inst, binding);
    if (!binding_path) return binding_path.error();
    for (auto& [p, list] : inst.our_bindings) {
      if (p == *profile_path) {
        list.push_back({action, *binding_path});
        return {};
      }
    }
    inst.our_bindings.push_back({*profile_path, {{action, *binding_path}}});
    return {};
  };
  const char* hand_names[2] = {"left", "right"};
  for (int h = 0; h < 2; ++h) {
    auto p = to_path(inst, std::string("/user/hand/") + hand_names[h]);
    if (!p) return p.error();
    inst.hand_paths[h] = *p;
  }
  if (want_controller) {
    if (auto st = make_action("wrist_grip", "Glove wrist (controller grip)", inst.hand_paths, inst.grip_action); !st) {
      return st;
    }
    // The grip pose of the profiles most runtimes bind (a runtime binds the
    // profiles it knows and ignores the rest).
    for (const char* profile : {"/interaction_profiles/khr/simple_controller", "/interaction_profiles/oculus/touch_controller",
                                "/interaction_profiles/valve/index_controller", "/interaction_profiles/htc/vive_controller"}) {
      for (int h = 0; h < 2; ++h) {
        if (auto st = bind(profile, inst.grip_action, std::string("/user/hand/") + hand_names[h] + "/input/grip/pose"); !st) {
          return st;
        }
      }
    }
  }
  if (want_tracker) {
    // Which hand's source uses which role; a hand without a tracker wrist
    // still needs a distinct subaction path, so it gets its configured role too.
    for (int h = 0; h < 2; ++h) {
      const SourceConfig* sc = inst.hands[h].config;
      const std::string role = sc ? sc->tracker_role[h] : (h == 0 ? "left_wrist" : "right_wrist");
      auto p = to_path(inst, "/user/vive_tracker_htcx/role/" + role);
      if (!p) return p.error();
      inst.tracker_paths[h] = *p;
    }
    if (inst.tracker_paths[0] == inst.tracker_paths[1]) {
      return make_error(Errc::invalid_argument, "both hands name the same tracker role");
    }
    if (auto st = make_action("wrist_tracker", "Glove wrist (tracker)", inst.tracker_paths, inst.tracker_action); !st) {
      return st;
    }
    for (int h = 0; h < 2; ++h) {
      if (!inst.hands[h].config) continue;
      const std::string role = inst.hands[h].config->tracker_role[h];
      if (auto st = bind("/interaction_profiles/htc/vive_tracker_htcx", inst.tracker_action,
                         "/user/vive_tracker_htcx/role/" + role + "/input/grip/pose");
          !st) {
        return st;
      }
    }
  }
  return {};
}

const std::vector<XrActionSuggestedBinding>* our_bindings_for(const Instance& inst, XrPath profile) {
  for (const auto& [p, list] : inst.our_bindings) {
    if (p == profile) return &list;
  }
  return nullptr;
}

XRAPI_ATTR XrResult XRAPI_CALL layer_suggest_bindings(XrInstance instance,
                                                      const XrInteractionProfileSuggestedBinding* suggested) {
  return guarded("xrSuggestInteractionProfileBindings", [&] {
    Instance* inst = find_instance(instance);
    if (!inst) return XR_ERROR_HANDLE_INVALID;
    if (!suggested || suggested->type != XR_TYPE_INTERACTION_PROFILE_SUGGESTED_BINDING ||
        (suggested->countSuggestedBindings > 0 && !suggested->suggestedBindings)) {
      return inst->next.suggest_bindings(instance, suggested);  // the runtime gives the exact error
    }
    const auto* ours = our_bindings_for(*inst, suggested->interactionProfile);
    XrResult r;
    if (!ours) {
      r = inst->next.suggest_bindings(instance, suggested);
    } else {
      std::vector<XrActionSuggestedBinding> merged(suggested->suggestedBindings,
                                                   suggested->suggestedBindings + suggested->countSuggestedBindings);
      merged.insert(merged.end(), ours->begin(), ours->end());
      XrInteractionProfileSuggestedBinding down = *suggested;
      down.countSuggestedBindings = static_cast<uint32_t>(merged.size());
      down.suggestedBindings = merged.data();
      r = inst->next.suggest_bindings(instance, &down);
      if (XR_FAILED(r) && r != XR_ERROR_ACTIONSETS_ALREADY_ATTACHED) {
        // Never let ours cost the app its bindings: try the app's alone.
        logger().warn("Proprio layer: the runtime refused the wrist bindings merged into the app's ({}); "
                      "the app's alone are suggested", static_cast<int>(r));
        r = inst->next.suggest_bindings(instance, suggested);
      }
    }
    if (XR_SUCCEEDED(r)) {
      std::unique_lock lock(registry().mutex);
      auto& list = inst->app_suggested;
      if (std::find(list.begin(), list.end(), suggested->interactionProfile) == list.end()) {
        list.push_back(suggested->interactionProfile);
      }
    }
    return r;
  });
}

// Suggests the layer's bindings for every profile the app did not name (a
// runtime refuses the profiles it does not know: that is no error here).
void suggest_ours_alone(const Instance& inst, const std::vector<XrPath>& app_profiles) {
  for (const auto& [profile, list] : inst.our_bindings) {
    if (std::find(app_profiles.begin(), app_profiles.end(), profile) != app_profiles.end()) continue;
    auto s = xr_struct<XrInteractionProfileSuggestedBinding>(XR_TYPE_INTERACTION_PROFILE_SUGGESTED_BINDING);
    s.interactionProfile = profile;
    s.countSuggestedBindings = static_cast<uint32_t>(list.size());
    s.suggestedBindings = list.data();
    if (const XrResult r = inst.next.suggest_bindings(inst.handle, &s); XR_FAILED(r)) {
      logger().debug("Proprio layer: the runtime refused the wrist bindings for a profile ({})", static_cast<int>(r));
    }
  }
}

XRAPI_ATTR XrResult XRAPI_CALL layer_attach_action_sets(XrSession session, const XrSessionActionSetsAttachInfo* info) {
  return guarded("xrAttachSessionActionSets", [&] {
    Instance* inst;
    std::vector<XrPath> app_profiles;
    {
      std::shared_lock lock(registry().mutex);
      auto it = registry().sessions.find(session);
      if (it == registry().sessions.end()) return XR_ERROR_HANDLE_INVALID;
      inst = it->second->instance;
      app_profiles = inst->app_suggested;
    }
    if (!info || info->type != XR_TYPE_SESSION_ACTION_SETS_ATTACH_INFO || info->countActionSets == 0 ||
        !info->actionSets) {
      return inst->next.attach_action_sets(session, info);
    }
    {
      std::shared_lock lock(registry().mutex);
      auto it = registry().sessions.find(session);
      if (it != registry().sessions.end() && it->second->attached_alone) {
        logger().error("Proprio layer: the app attaches its action sets after its first {} frames, when the layer "
                       "had attached its wrist actions alone; the runtime refuses a second attach",
                       kAttachAloneAfterFrames);
      }
    }
    // Profiles the app did not suggest for get ours alone (suggesting after an
    // attach is an error, so this is the last chance).
    suggest_ours_alone(*inst, app_profiles);
    std::vector<XrActionSet> sets(info->actionSets, info->actionSets + info->countActionSets);
    sets.push_back(inst->action_set);
    XrSessionActionSetsAttachInfo down = *info;
    down.countActionSets = static_cast<uint32_t>(sets.size());
    down.actionSets = sets.data();
    XrResult r = inst->next.attach_action_sets(session, &down);
    const bool ours = XR_SUCCEEDED(r);
    if (XR_FAILED(r) && r != XR_ERROR_ACTIONSETS_ALREADY_ATTACHED && r != XR_ERROR_HANDLE_INVALID) {
      logger().warn("Proprio layer: the runtime refused the app's action sets with the layer's ({}); "
                    "attaching the app's alone, without a controller or tracker wrist", static_cast<int>(r));
      r = inst->next.attach_action_sets(session, info);
    }
    {
      std::unique_lock lock(registry().mutex);
      if (auto it = registry().sessions.find(session); it != registry().sessions.end()) {
        it->second->attached = it->second->attached || ours;
        it->second->app_attached = true;
      }
    }
    return r;
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_sync_actions(XrSession session, const XrActionsSyncInfo* info) {
  return guarded("xrSyncActions", [&] {
    Instance* inst;
    bool attached;
    {
      std::shared_lock lock(registry().mutex);
      auto it = registry().sessions.find(session);
      if (it == registry().sessions.end()) return XR_ERROR_HANDLE_INVALID;
      inst = it->second->instance;
      attached = it->second->attached;
    }
    if (!attached || !info || info->type != XR_TYPE_ACTIONS_SYNC_INFO || info->countActiveActionSets == 0 ||
        !info->activeActionSets || info->countActiveActionSets > 64) {
      return inst->next.sync_actions(session, info);
    }
    // A fixed array: this runs every frame.
    std::array<XrActiveActionSet, 65> sets;
    std::copy(info->activeActionSets, info->activeActionSets + info->countActiveActionSets, sets.begin());
    sets[info->countActiveActionSets] = {inst->action_set, XR_NULL_PATH};
    XrActionsSyncInfo down = *info;
    down.countActiveActionSets = info->countActiveActionSets + 1;
    down.activeActionSets = sets.data();
    return inst->next.sync_actions(session, &down);
  });
}

// For apps without actions of their own: see Session::attached_alone.
XRAPI_ATTR XrResult XRAPI_CALL layer_begin_frame(XrSession session, const XrFrameBeginInfo* info) {
  return guarded("xrBeginFrame", [&] {
    Instance* inst;
    Session* state;
    {
      std::shared_lock lock(registry().mutex);
      auto it = registry().sessions.find(session);
      if (it == registry().sessions.end()) return XR_ERROR_HANDLE_INVALID;
      inst = it->second->instance;
      state = it->second.get();  // lives until xrDestroySession, which the app cannot call meanwhile
    }
    const XrResult r = inst->next.begin_frame(session, info);
    if (XR_FAILED(r) || state->app_attached) return r;
    if (!state->attached_alone && state->frames.fetch_add(1) + 1 == kAttachAloneAfterFrames) {
      auto attach = xr_struct<XrSessionActionSetsAttachInfo>(XR_TYPE_SESSION_ACTION_SETS_ATTACH_INFO);
      attach.countActionSets = 1;
      attach.actionSets = &inst->action_set;
      suggest_ours_alone(*inst, {});
      if (const XrResult ar = inst->next.attach_action_sets(session, &attach); XR_SUCCEEDED(ar)) {
        logger().info("Proprio layer: the app attached no action sets in its first {} frames; the layer's wrist "
                      "actions are attached alone", kAttachAloneAfterFrames);
        state->attached_alone = true;
      } else {
        logger().warn("Proprio layer: cannot attach the wrist actions alone ({})", static_cast<int>(ar));
      }
    }
    if (state->attached_alone) {
      XrActiveActionSet active{inst->action_set, XR_NULL_PATH};
      auto sync = xr_struct<XrActionsSyncInfo>(XR_TYPE_ACTIONS_SYNC_INFO);
      sync.countActiveActionSets = 1;
      sync.activeActionSets = &active;
      (void)inst->next.sync_actions(session, &sync);
    }
    return r;
  });
}

// Tracker connection events go to the app only if it enabled the extension
// itself. Session state changes switch the fingertip devices: they render
// only while the session is FOCUSED (a hidden or backgrounded app, a lost
// session or one on its way out presses nothing).
XRAPI_ATTR XrResult XRAPI_CALL layer_poll_event(XrInstance instance, XrEventDataBuffer* event) {
  return guarded("xrPollEvent", [&] {
    Instance* inst = find_instance(instance);
    if (!inst) return XR_ERROR_HANDLE_INVALID;
    const bool swallow_trackers = inst->vive_tracker && !inst->app_vive_tracker;
    for (;;) {
      const XrResult r = inst->next.poll_event(instance, event);
      if (r != XR_SUCCESS) return r;
      if (event->type == XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED) {
        const auto* e = reinterpret_cast<const XrEventDataSessionStateChanged*>(event);
        std::shared_lock lock(registry().mutex);
        auto it = registry().sessions.find(e->session);
        if (it != registry().sessions.end() && it->second->haptics) {
          it->second->haptics->set_output(e->state == XR_SESSION_STATE_FOCUSED);
        }
      }
      if (!swallow_trackers || event->type != XR_TYPE_EVENT_DATA_VIVE_TRACKER_CONNECTED_HTCX) return r;
      event->type = XR_TYPE_EVENT_DATA_BUFFER;  // swallowed; the next one, if any
    }
  });
}

bool RuntimeHeadProvider::locate(TrackedPose what, TimeNs t_ns, Pose& T_world_x) noexcept {
  if (what != TrackedPose::head) return false;
  const XrInstance handle = instance_.load(std::memory_order_acquire);
  if (handle == XR_NULL_HANDLE) return false;
  try {
    std::shared_lock lock(registry().mutex);
    const Instance* inst = find_instance_locked(handle);
    if (!inst) return false;
    // An instance has one session at a time in practice; take the first with a head.
    for (const auto& [h, s] : registry().sessions) {
      if (s->instance != inst || s->view_space == XR_NULL_HANDLE || config_index_ >= s->source_spaces.size() ||
          s->source_spaces[config_index_] == XR_NULL_HANDLE) {
        continue;
      }
      XrTime time = t_ns;
      if (inst->next.convert_timespec_to_time) {
        timespec ts{static_cast<time_t>(t_ns / kNsPerSecond), static_cast<long>(t_ns % kNsPerSecond)};
        if (XR_FAILED(inst->next.convert_timespec_to_time(inst->handle, &ts, &time))) return false;
      }
      auto loc = xr_struct<XrSpaceLocation>(XR_TYPE_SPACE_LOCATION);
      if (XR_FAILED(inst->next.locate_space(s->view_space, s->source_spaces[config_index_], time, &loc))) return false;
      constexpr XrSpaceLocationFlags kBoth = XR_SPACE_LOCATION_ORIENTATION_VALID_BIT | XR_SPACE_LOCATION_POSITION_VALID_BIT;
      if ((loc.locationFlags & kBoth) != kBoth) return false;
      T_world_x = from_xr(loc.pose);
      return true;
    }
  } catch (...) {
  }
  return false;
}

XRAPI_ATTR XrResult XRAPI_CALL layer_create_hand_tracker(XrSession session, const XrHandTrackerCreateInfoEXT* info,
                                                         XrHandTrackerEXT* tracker) {
  return guarded("xrCreateHandTrackerEXT", [&] {
    auto& r = registry();
    Instance* inst;
    XrSpace wrist_space = XR_NULL_HANDLE;
    bool runtime_hand_wanted = false;
    {
      std::shared_lock lock(r.mutex);
      auto it = r.sessions.find(session);
      if (it == r.sessions.end()) return XR_ERROR_HANDLE_INVALID;
      inst = it->second->instance;
      if (info && (info->hand == XR_HAND_LEFT_EXT || info->hand == XR_HAND_RIGHT_EXT)) {
        const std::size_t h = info->hand == XR_HAND_LEFT_EXT ? 0 : 1;
        wrist_space = it->second->wrist_spaces[h];
        runtime_hand_wanted = inst->hands[h].source && inst->wrist[h].kind == WristSource::runtime_hand;
      }
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
    t->wrist_space = wrist_space;
    if (runtime_hand_wanted && inst->runtime_hands) {
      // The runtime's own tracker for the same hand: its wrist, our fingers.
      auto down_info = *info;
      down_info.next = nullptr;
      if (const XrResult hr = inst->next.create_hand_tracker(session, &down_info, &t->runtime_hand); XR_FAILED(hr)) {
        logger().error("Proprio layer: the runtime refused its own {} hand tracker ({}); the hand is shown "
                       "at the source's wrist", to_string(t->hand), static_cast<int>(hr));
        t->runtime_hand = XR_NULL_HANDLE;
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
        release_tracker(*t);
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

constexpr XrSpaceLocationFlags kBothValid = XR_SPACE_LOCATION_ORIENTATION_VALID_BIT | XR_SPACE_LOCATION_POSITION_VALID_BIT;
constexpr XrSpaceLocationFlags kBothTracked = XR_SPACE_LOCATION_ORIENTATION_TRACKED_BIT | XR_SPACE_LOCATION_POSITION_TRACKED_BIT;
constexpr XrSpaceVelocityFlags kBothVelocities = XR_SPACE_VELOCITY_LINEAR_VALID_BIT | XR_SPACE_VELOCITY_ANGULAR_VALID_BIT;

// The source's frame in the app's base space at the requested time, and how
// it moves: v_anchor is the velocity of the point anchor_p, w the angular
// velocity (both in the base space).
struct Frame {
  Pose T_base_source;
  bool tracked = false;
  bool has_velocity = false;
  Vec3 anchor_p = Vec3::Zero(), v_anchor = Vec3::Zero(), w = Vec3::Zero();
};

// The source's configured origin (a reference space with its offset).
bool locate_source_origin(const Tracker& t, const XrHandJointsLocateInfoEXT& info, Frame& frame) {
  auto space_velocity = xr_struct<XrSpaceVelocity>(XR_TYPE_SPACE_VELOCITY);
  auto space_location = xr_struct<XrSpaceLocation>(XR_TYPE_SPACE_LOCATION);
  space_location.next = &space_velocity;
  if (XR_FAILED(t.instance->next.locate_space(t.source_space, info.baseSpace, info.time, &space_location))) return false;
  if ((space_location.locationFlags & kBothValid) != kBothValid) return false;
  frame.T_base_source = from_xr(space_location.pose);
  frame.tracked = (space_location.locationFlags & kBothTracked) == kBothTracked;
  frame.has_velocity = (space_velocity.velocityFlags & kBothVelocities) == kBothVelocities;
  frame.anchor_p = frame.T_base_source.p;
  frame.v_anchor = from_xr(space_velocity.linearVelocity);
  frame.w = from_xr(space_velocity.angularVelocity);
  return true;
}

// The runtime's wrist for this hand: a controller's or tracker's pose with
// the calibrated offset, or the runtime's own hand tracking. Lost, the last
// one is held (not tracked) for the stale timeout, in the same base space.
bool locate_runtime_wrist(const Tracker& t, const XrHandJointsLocateInfoEXT& info, TimeNs t_ns, const HandPose& pose,
                          Frame& frame) {
  const Instance& inst = *t.instance;
  const WristPlan& plan = inst.wrist[static_cast<std::size_t>(t.hand)];
  bool valid = false;
  Pose T_base_wrist;
  if (plan.kind == WristSource::runtime_hand && t.runtime_hand != XR_NULL_HANDLE) {
    std::array<XrHandJointLocationEXT, XR_HAND_JOINT_COUNT_EXT> joints{};
    std::array<XrHandJointVelocityEXT, XR_HAND_JOINT_COUNT_EXT> joint_velocities{};
    auto vels = xr_struct<XrHandJointVelocitiesEXT>(XR_TYPE_HAND_JOINT_VELOCITIES_EXT);
    vels.jointCount = XR_HAND_JOINT_COUNT_EXT;
    vels.jointVelocities = joint_velocities.data();
    auto locs = xr_struct<XrHandJointLocationsEXT>(XR_TYPE_HAND_JOINT_LOCATIONS_EXT);
    locs.next = &vels;
    locs.jointCount = XR_HAND_JOINT_COUNT_EXT;
    locs.jointLocations = joints.data();
    auto down = xr_struct<XrHandJointsLocateInfoEXT>(XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT);
    down.baseSpace = info.baseSpace;
    down.time = info.time;
    const XrHandJointLocationEXT& wj = joints[XR_HAND_JOINT_WRIST_EXT];
    if (XR_SUCCEEDED(inst.next.locate_hand_joints(t.runtime_hand, &down, &locs)) && locs.isActive &&
        (wj.locationFlags & kBothValid) == kBothValid) {
      valid = true;
      T_base_wrist = from_xr(wj.pose);
      frame.tracked = (wj.locationFlags & kBothTracked) == kBothTracked;
      const XrHandJointVelocityEXT& wv = joint_velocities[XR_HAND_JOINT_WRIST_EXT];
      frame.has_velocity = (wv.velocityFlags & kBothVelocities) == kBothVelocities;
      frame.v_anchor = from_xr(wv.linearVelocity);
      frame.w = from_xr(wv.angularVelocity);
    }
  } else if (t.wrist_space != XR_NULL_HANDLE) {
    auto space_velocity = xr_struct<XrSpaceVelocity>(XR_TYPE_SPACE_VELOCITY);
    auto space_location = xr_struct<XrSpaceLocation>(XR_TYPE_SPACE_LOCATION);
    space_location.next = &space_velocity;
    if (XR_SUCCEEDED(inst.next.locate_space(t.wrist_space, info.baseSpace, info.time, &space_location)) &&
        (space_location.locationFlags & kBothValid) == kBothValid) {
      valid = true;
      const Pose T_base_device = from_xr(space_location.pose);
      T_base_wrist = T_base_device * plan.T_device_wrist;
      frame.tracked = (space_location.locationFlags & kBothTracked) == kBothTracked;
      frame.has_velocity = (space_velocity.velocityFlags & kBothVelocities) == kBothVelocities;
      frame.w = from_xr(space_velocity.angularVelocity);
      frame.v_anchor = from_xr(space_velocity.linearVelocity) + frame.w.cross(T_base_wrist.p - T_base_device.p);
    }
  }
  {
    std::lock_guard lock(t.wrist_mutex);
    if (valid) {
      t.last_T_base_wrist = T_base_wrist;
      t.last_wrist_base = info.baseSpace;
      t.last_wrist_ns = t_ns;
    } else if (t.last_wrist_base == info.baseSpace && t.last_wrist_ns != 0 &&
               t_ns - t.last_wrist_ns <= inst.config.stale_timeout_ns) {
      valid = true;
      T_base_wrist = t.last_T_base_wrist;
      frame.tracked = false;
      frame.has_velocity = false;
    }
  }
  if (!valid) return false;
  // The source's frame is wherever it must be for its wrist to sit on the runtime's.
  frame.T_base_source = T_base_wrist * pose.joint(HandJoint::wrist).inverse();
  frame.anchor_p = T_base_wrist.p;
  return true;
}

void add_to_histogram(std::array<std::atomic<std::uint64_t>, XR_PROPRIO_LATENCY_BIN_COUNT>& bins,
                      std::atomic<std::int64_t>& max_ns, std::int64_t ns) {
  constexpr std::int64_t kBinNs = kNsPerMillisecond / 2;
  const std::int64_t bin = std::clamp<std::int64_t>(ns / kBinNs, 0, XR_PROPRIO_LATENCY_BIN_COUNT - 1);
  bins[static_cast<std::size_t>(bin)].fetch_add(1, std::memory_order_relaxed);
  std::int64_t seen = max_ns.load(std::memory_order_relaxed);
  while (ns > seen && !max_ns.compare_exchange_weak(seen, ns, std::memory_order_relaxed)) {
  }
}

void record_latency(const Tracker& t, const HandPose& pose, TimeNs now_ns) {
  t.pose_count.fetch_add(1, std::memory_order_relaxed);
  add_to_histogram(t.age_at_locate, t.max_age_ns, now_ns - pose.data_time_ns);
  if (pose.ready_time_ns > 0) {
    add_to_histogram(t.sample_to_ready, t.max_sample_to_ready_ns, pose.ready_time_ns - pose.data_time_ns);
  }
}

XRAPI_ATTR XrResult XRAPI_CALL layer_get_latency(XrHandTrackerEXT tracker, XrHandTrackingLatencyPROPRIO* out) {
  return guarded("xrGetHandTrackingLatencyPROPRIO", [&] {
    std::shared_lock lock(registry().mutex);
    const auto it = registry().trackers.find(tracker);
    if (it == registry().trackers.end()) return XR_ERROR_HANDLE_INVALID;
    if (!it->second->instance->latency) return XR_ERROR_FUNCTION_UNSUPPORTED;
    if (!out || out->type != XR_TYPE_HAND_TRACKING_LATENCY_PROPRIO) return XR_ERROR_VALIDATION_FAILURE;
    const Tracker& t = *it->second;
    out->binCount = XR_PROPRIO_LATENCY_BIN_COUNT;
    out->binWidthMs = 0.5f;
    out->poseCount = t.pose_count.load(std::memory_order_relaxed);
    out->maxSampleToReadyMs = static_cast<float>(t.max_sample_to_ready_ns.load(std::memory_order_relaxed) * 1e-6);
    out->maxAgeAtLocateMs = static_cast<float>(t.max_age_ns.load(std::memory_order_relaxed) * 1e-6);
    for (std::size_t i = 0; i < XR_PROPRIO_LATENCY_BIN_COUNT; ++i) {
      out->sampleToReady[i] = t.sample_to_ready[i].load(std::memory_order_relaxed);
      out->ageAtLocate[i] = t.age_at_locate[i].load(std::memory_order_relaxed);
    }
    return XR_SUCCESS;
  });
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

    // Where the source's frame is in the app's base space: its configured
    // origin, or wherever the runtime's wrist puts the source's wrist.
    // Without the means (the runtime lacks the extension, refused the
    // actions or the hand tracker), the source's own wrist: logged at start.
    Frame frame;
    const bool runtime_wrist = inst.wrist[static_cast<std::size_t>(t.hand)].kind != WristSource::source &&
                               (t.wrist_space != XR_NULL_HANDLE || t.runtime_hand != XR_NULL_HANDLE);
    const bool located = runtime_wrist ? locate_runtime_wrist(t, *info, t_ns, pose, frame)
                                       : locate_source_origin(t, *info, frame);
    if (!located) {
      write_inactive(locations, velocities, data_source);
      return XR_SUCCESS;
    }

    const XrSpaceLocationFlags joint_flags = kBothValid | (fresh && frame.tracked ? kBothTracked : 0);
    locations->isActive = XR_TRUE;
    for (std::size_t i = 0; i < kHandJointCount; ++i) {
      XrHandJointLocationEXT& out = locations->jointLocations[i];
      out.pose = proprio::to_xr(frame.T_base_source * pose.T_world_joint[i]);
      out.radius = static_cast<float>(std::max(pose.radius_m[i], 1e-3));  // positive whenever valid
      out.locationFlags = joint_flags;
    }
    if (velocities) {
      const bool known = fresh && pose.has_velocity && frame.has_velocity;
      // With the runtime's wrist, the source's own wrist motion is replaced:
      // only the joints' motion relative to it is kept.
      const bool rebased = runtime_wrist;
      const std::size_t w = index_of(HandJoint::wrist);
      const Vec3 p_ws = pose.T_world_joint[w].p;
      const Vec3 v_ws = rebased ? pose.linear_velocity_in_world[w] : Vec3(Vec3::Zero());
      const Vec3 w_ws = rebased ? pose.angular_velocity_in_world[w] : Vec3(Vec3::Zero());
      for (std::size_t i = 0; i < kHandJointCount; ++i) {
        XrHandJointVelocityEXT& out = velocities->jointVelocities[i];
        if (!known) {
          out.velocityFlags = 0;
          continue;
        }
        const Vec3 v_rel = pose.linear_velocity_in_world[i] - v_ws - w_ws.cross(pose.T_world_joint[i].p - p_ws);
        const Vec3 w_rel = pose.angular_velocity_in_world[i] - w_ws;
        // A point carried by a moving frame: v = v_anchor + w x (p - anchor) + R v_rel.
        const Vec3 r = from_xr(locations->jointLocations[i].pose.position) - frame.anchor_p;
        out.linearVelocity = proprio::to_xr(Vec3(frame.v_anchor + frame.w.cross(r) + frame.T_base_source.q * v_rel));
        out.angularVelocity = proprio::to_xr(Vec3(frame.w + frame.T_base_source.q * w_rel));
        out.velocityFlags = kBothVelocities;
      }
    }
    if (data_source) {
      data_source->isActive = XR_TRUE;
      data_source->dataSource = XR_HAND_TRACKING_DATA_SOURCE_UNOBSTRUCTED_EXT;
    }
    if (pose.data_time_ns > 0) record_latency(t, pose, MonotonicClock::instance().now_ns());
    return XR_SUCCESS;
  });
}

// ---- XR_PROPRIO_fingertip_haptics -------------------------------------------
//
// The devices live in the session's FingertipHapticsService (the `haptics`
// plugin, loaded only when a [haptics] table is configured). An app's
// XrFingertipHapticsPROPRIO binds them to its spaces: the hand sources'
// origins, located in the app's world space whenever the app hands the layer
// an XrTime, carry the tracked hands into the contact simulation's world.

// XrTime -> CLOCK_MONOTONIC, the time base of every Proprio sample.
TimeNs to_monotonic(const Instance& inst, XrTime time) {
  if (inst.next.convert_time_to_timespec) {
    timespec ts{};
    if (XR_SUCCEEDED(inst.next.convert_time_to_timespec(inst.handle, time, &ts))) {
      return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
    }
  }
  return time;
}

// `space` in `base` at `time`, when both position and orientation are valid.
bool locate_pose(const Instance& inst, XrSpace space, XrSpace base, XrTime time, Pose& T_base_space,
                 XrResult* error = nullptr) {
  auto loc = xr_struct<XrSpaceLocation>(XR_TYPE_SPACE_LOCATION);
  const XrResult r = inst.next.locate_space(space, base, time, &loc);
  if (error) *error = r;
  if (XR_FAILED(r) || (loc.locationFlags & kBothValid) != kBothValid) return false;
  T_base_space = from_xr(loc.pose);
  return true;
}

HandPose moved(const HandPose& p, const Pose& T_new_old) {
  HandPose out = p;
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    out.T_world_joint[i] = T_new_old * p.T_world_joint[i];
    out.linear_velocity_in_world[i] = T_new_old.q * p.linear_velocity_in_world[i];
    out.angular_velocity_in_world[i] = T_new_old.q * p.angular_velocity_in_world[i];
  }
  return out;
}

struct HapticsHandle final : TrackedHandFeed {
  Instance* instance = nullptr;
  Session* session = nullptr;
  FingertipHapticsService* service = nullptr;
  bool contact = false;
  XrSpace world_space = XR_NULL_HANDLE;
  std::array<XrSpace, 2> source_space{};  // per hand: its source's origin (our own reference spaces)
  std::vector<XrHapticColliderPROPRIO> colliders;  // registry lock

  // Where each hand's source origin is in world_space, as last located.
  std::mutex frame_mutex;
  std::array<Pose, 2> T_world_source{};
  std::array<bool, 2> located{};

  // The tracked hand in the world: for the service's feeder thread.
  bool tracked_hand(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override {
    const auto h = static_cast<std::size_t>(hand);
    HandSource* source = instance->hands[h].source;
    if (source == nullptr) return false;
    Pose T;
    {
      std::lock_guard lock(frame_mutex);
      if (!located[h]) return false;
      T = T_world_source[h];
    }
    HandPose pose;
    if (!is_usable(source->lookup(hand, t_ns, pose)) || !pose.active) return false;
    out = moved(pose, T);
    return true;
  }

  // Called with each XrTime the app gives (app threads).
  void relocate(XrTime time) {
    if (!contact || time <= 0) return;
    for (std::size_t h = 0; h < 2; ++h) {
      Pose T;
      if (source_space[h] == XR_NULL_HANDLE || !locate_pose(*instance, source_space[h], world_space, time, T)) continue;
      std::lock_guard lock(frame_mutex);
      T_world_source[h] = T;
      located[h] = true;
    }
  }
};

struct ColliderHandle {
  HapticsHandle* parent = nullptr;
  int id = -1;
};

// Guarded by the registry's lock, like the other handles.
std::unordered_map<XrFingertipHapticsPROPRIO, std::unique_ptr<HapticsHandle>>& haptics_handles() {
  static std::unordered_map<XrFingertipHapticsPROPRIO, std::unique_ptr<HapticsHandle>> m;
  return m;
}
std::unordered_map<XrHapticColliderPROPRIO, std::unique_ptr<ColliderHandle>>& collider_handles() {
  static std::unordered_map<XrHapticColliderPROPRIO, std::unique_ptr<ColliderHandle>> m;
  return m;
}

bool hand_of(XrHandEXT hand, Handedness& out) {
  if (hand != XR_HAND_LEFT_EXT && hand != XR_HAND_RIGHT_EXT) return false;
  out = hand == XR_HAND_LEFT_EXT ? Handedness::left : Handedness::right;
  return true;
}

bool finite_pose(const XrPosef& p) {
  const float v[] = {p.position.x, p.position.y, p.position.z, p.orientation.x, p.orientation.y, p.orientation.z,
                     p.orientation.w};
  for (float x : v) {
    if (!std::isfinite(x)) return false;
  }
  const double n2 = double(p.orientation.x) * p.orientation.x + double(p.orientation.y) * p.orientation.y +
                    double(p.orientation.z) * p.orientation.z + double(p.orientation.w) * p.orientation.w;
  return std::abs(n2 - 1.0) < 1e-2;  // OpenXR: a pose's orientation must be a unit quaternion
}

// Releases a haptics handle's colliders and spaces and stops its simulation.
// Caller holds the registry exclusively.
void release_haptics(HapticsHandle& hh) {
  for (XrHapticColliderPROPRIO c : hh.colliders) collider_handles().erase(c);
  hh.colliders.clear();
  hh.service->stop_contact();
  hh.service->clear_app_forces();
  for (XrSpace& s : hh.source_space) {
    if (s != XR_NULL_HANDLE) hh.instance->next.destroy_space(s);
    s = XR_NULL_HANDLE;
  }
  hh.session->haptics_handle = XR_NULL_HANDLE;
}

// Child handles go with their parent. Caller holds the registry exclusively.
void erase_haptics_of(const Instance* inst, XrSession session) {
  auto& m = haptics_handles();
  for (auto it = m.begin(); it != m.end();) {
    if (it->second->instance == inst || (session != XR_NULL_HANDLE && it->second->session->handle == session)) {
      release_haptics(*it->second);
      it = m.erase(it);
    } else {
      ++it;
    }
  }
}

XRAPI_ATTR XrResult XRAPI_CALL layer_create_fingertip_haptics(XrSession session,
                                                              const XrFingertipHapticsCreateInfoPROPRIO* info,
                                                              XrFingertipHapticsPROPRIO* out) {
  return guarded("xrCreateFingertipHapticsPROPRIO", [&] {
    auto& r = registry();
    auto hh = std::make_unique<HapticsHandle>();
    {
      std::shared_lock lock(r.mutex);
      auto it = r.sessions.find(session);
      if (it == r.sessions.end()) return XR_ERROR_HANDLE_INVALID;
      Session& s = *it->second;
      if (!info || info->type != XR_TYPE_FINGERTIP_HAPTICS_CREATE_INFO_PROPRIO || !out) return XR_ERROR_VALIDATION_FAILURE;
      if (info->contactSimulation != XR_FALSE && info->contactSimulation != XR_TRUE) return XR_ERROR_VALIDATION_FAILURE;
      hh->contact = info->contactSimulation == XR_TRUE;
      if (hh->contact && info->worldSpace == XR_NULL_HANDLE) return XR_ERROR_HANDLE_INVALID;
      if (!s.haptics) return XR_ERROR_FEATURE_UNSUPPORTED;  // supportsFingertipHaptics was false
      if (hh->contact && !s.haptics->contact_allowed()) return XR_ERROR_FEATURE_UNSUPPORTED;
      // One per session: the devices are one set. The flag also keeps two
      // threads from creating at once while the lock is released below.
      if (s.haptics_handle != XR_NULL_HANDLE || s.haptics_creating.exchange(true)) return XR_ERROR_LIMIT_REACHED;
      hh->instance = s.instance;
      hh->session = &s;
      hh->service = s.haptics.get();
    }
    // No registry lock from here to the insertion: starting the simulation
    // builds a MuJoCo world (about 0.1 s), and other threads keep locating
    // hands meanwhile. The session outlives the call: an app may not destroy
    // it while creating its children (OpenXR's external synchronization).
    Session& s = *hh->session;
    Instance& inst = *hh->instance;
    const auto fail = [&](XrResult code) {
      for (XrSpace& sp : hh->source_space) {
        if (sp != XR_NULL_HANDLE) inst.next.destroy_space(sp);
        sp = XR_NULL_HANDLE;
      }
      s.haptics_creating.store(false);
      return code;
    };
    hh->world_space = hh->contact ? info->worldSpace : XR_NULL_HANDLE;
    for (std::size_t h = 0; h < 2; ++h) {
      const HandBinding& b = inst.hands[h];
      if (!b.source) continue;
      if (inst.wrist[h].kind != WristSource::source) {
        // The runtime's wrist is only known inside xrLocateHandJointsEXT; forces
        // in a base space and the simulation need the source's own frame.
        logger().warn("Proprio layer: fingertip haptics: the {} hand's wrist comes from the runtime ({}); its "
                      "forces work only in fingertip frames and it has no proxy", to_string(static_cast<Handedness>(h)),
                      to_string(inst.wrist[h].kind));
        continue;
      }
      hh->source_space[h] = make_reference_space(inst, session, to_xr(b.config->space), b.config->T_space_source,
                                                 "fingertip haptics source origin");
    }
    if (hh->contact) {
      // Where the sources are now, so that the proxies can take the tracked
      // hands' sizes at once (the app's own calls keep it current).
      const TimeNs now = MonotonicClock::instance().now_ns();
      XrTime xr_now = now;
      if (inst.next.convert_timespec_to_time) {
        timespec ts{static_cast<time_t>(now / kNsPerSecond), static_cast<long>(now % kNsPerSecond)};
        if (XR_FAILED(inst.next.convert_timespec_to_time(inst.handle, &ts, &xr_now))) xr_now = now;
      }
      if (const XrSpace any = hh->source_space[0] ? hh->source_space[0] : hh->source_space[1]; any != XR_NULL_HANDLE) {
        Pose probe;
        XrResult located = XR_SUCCESS;
        locate_pose(inst, any, hh->world_space, xr_now, probe, &located);
        if (located == XR_ERROR_HANDLE_INVALID) return fail(XR_ERROR_HANDLE_INVALID);  // not a space of this session
      }
      hh->relocate(xr_now);
      if (auto st = s.haptics->start_contact(hh.get()); !st) {
        logger().error("Proprio layer: fingertip haptics: {}", st.error().message);
        return fail(XR_ERROR_RUNTIME_FAILURE);
      }
    }
    std::unique_lock lock(r.mutex);
    const auto handle = reinterpret_cast<XrFingertipHapticsPROPRIO>(hh.get());
    s.haptics_handle = handle;
    s.haptics_creating.store(false);
    haptics_handles()[handle] = std::move(hh);
    *out = handle;
    return XR_SUCCESS;
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_destroy_fingertip_haptics(XrFingertipHapticsPROPRIO haptics) {
  return guarded("xrDestroyFingertipHapticsPROPRIO", [&] {
    std::unique_lock lock(registry().mutex);
    auto it = haptics_handles().find(haptics);
    if (it == haptics_handles().end()) return XR_ERROR_HANDLE_INVALID;
    release_haptics(*it->second);
    haptics_handles().erase(it);
    return XR_SUCCESS;
  });
}

// The handle under the shared lock (held by the caller).
HapticsHandle* find_haptics_locked(XrFingertipHapticsPROPRIO h) {
  auto it = haptics_handles().find(h);
  return it == haptics_handles().end() ? nullptr : it->second.get();
}

XRAPI_ATTR XrResult XRAPI_CALL layer_get_fingertip_haptics_properties(XrFingertipHapticsPROPRIO haptics, XrHandEXT hand,
                                                                      XrFingertipHapticsPropertiesPROPRIO* out) {
  return guarded("xrGetFingertipHapticsPropertiesPROPRIO", [&] {
    std::shared_lock lock(registry().mutex);
    HapticsHandle* hh = find_haptics_locked(haptics);
    if (!hh) return XR_ERROR_HANDLE_INVALID;
    Handedness side;
    if (!hand_of(hand, side) || !out || out->type != XR_TYPE_FINGERTIP_HAPTICS_PROPERTIES_PROPRIO) {
      return XR_ERROR_VALIDATION_FAILURE;
    }
    FingertipHapticsReport report;
    const bool have_report = hh->service->report(side, report);
    const HandCapabilities& caps = hh->service->capabilities()[static_cast<std::size_t>(side)];
    for (std::size_t f = 0; f < kFingerCount; ++f) {
      const FingertipCapability& c = caps[f];
      XrFingertipDevicePropertiesPROPRIO& o = out->fingers[f];
      o = {};
      o.present = c.present ? XR_TRUE : XR_FALSE;
      o.connected = c.present && (have_report ? report.fingers[f].connected : c.connected) ? XR_TRUE : XR_FALSE;
      o.forceDofCount = static_cast<uint32_t>(c.force_dofs);
      o.maxNormalForce = static_cast<float>(c.max_normal_n);
      o.maxShearForce = static_cast<float>(c.max_shear_n);
      o.maxForceRate = static_cast<float>(c.max_rate_n_per_s);
      o.frictionCoefficient = static_cast<float>(c.friction_coefficient);
      o.watchdogPeriod = c.watchdog_ns;
      std::snprintf(o.deviceName, sizeof o.deviceName, "%s", c.device.c_str());
    }
    return XR_SUCCESS;
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_apply_fingertip_forces(XrFingertipHapticsPROPRIO haptics,
                                                            const XrFingertipForcesPROPRIO* forces) {
  return guarded("xrApplyFingertipForcesPROPRIO", [&] {
    std::shared_lock lock(registry().mutex);
    HapticsHandle* hh = find_haptics_locked(haptics);
    if (!hh) return XR_ERROR_HANDLE_INVALID;
    Handedness side;
    if (!forces || forces->type != XR_TYPE_FINGERTIP_FORCES_PROPRIO || !hand_of(forces->hand, side)) {
      return XR_ERROR_VALIDATION_FAILURE;
    }
    const TimeNs now = MonotonicClock::instance().now_ns();
    std::array<Vec3, kFingerCount> f_in_tip;
    for (std::size_t f = 0; f < kFingerCount; ++f) f_in_tip[f] = from_xr(forces->forces[f]);
    if (forces->baseSpace != XR_NULL_HANDLE) {
      if (forces->time <= 0) return XR_ERROR_TIME_INVALID;
      // Into each fingertip's frame: the tracked hand at that time, its
      // source origin located in the base space.
      const auto h = static_cast<std::size_t>(side);
      const Instance& inst = *hh->instance;
      HandPose pose;
      Pose T_base_source;
      XrResult located = XR_SUCCESS;
      const bool have_frame = hh->source_space[h] != XR_NULL_HANDLE &&
                              locate_pose(inst, hh->source_space[h], forces->baseSpace, forces->time, T_base_source, &located);
      if (located == XR_ERROR_HANDLE_INVALID) return XR_ERROR_HANDLE_INVALID;
      if (located == XR_ERROR_TIME_INVALID) return XR_ERROR_TIME_INVALID;
      const bool have_hand = have_frame && inst.hands[h].source &&
                             is_usable(inst.hands[h].source->lookup(side, to_monotonic(inst, forces->time), pose)) &&
                             pose.active;
      for (std::size_t f = 0; f < kFingerCount; ++f) {
        if (!have_hand) {
          // No hand to put the force on: nothing is rendered (non-finite input still counts below).
          f_in_tip[f] = f_in_tip[f].allFinite() ? Vec3::Zero() : f_in_tip[f];
          continue;
        }
        const Quat q_base_tip = T_base_source.q * pose.joint(tip_of(static_cast<Finger>(f))).q;
        f_in_tip[f] = q_base_tip.conjugate() * f_in_tip[f];
      }
      hh->relocate(forces->time);
    }
    return hh->service->apply_forces(side, f_in_tip, now) ? XR_SUCCESS : XR_ERROR_VALIDATION_FAILURE;
  });
}

// A pose info in the handle's world space (the app's space at its time).
XrResult collider_pose_in_world(const HapticsHandle& hh, const XrHapticColliderPoseInfoPROPRIO& p, Pose& T_world) {
  if (p.type != XR_TYPE_HAPTIC_COLLIDER_POSE_INFO_PROPRIO) return XR_ERROR_VALIDATION_FAILURE;
  if (p.space == XR_NULL_HANDLE) return XR_ERROR_HANDLE_INVALID;
  if (p.time <= 0) return XR_ERROR_TIME_INVALID;
  if (!finite_pose(p.pose)) return XR_ERROR_POSE_INVALID;
  Pose T_world_space;
  XrResult r = XR_SUCCESS;
  if (!locate_pose(*hh.instance, p.space, hh.world_space, p.time, T_world_space, &r)) {
    return XR_FAILED(r) ? r : XR_ERROR_POSE_INVALID;  // valid call, but the space is not located now
  }
  T_world = T_world_space * from_xr(p.pose);
  return XR_SUCCESS;
}

XRAPI_ATTR XrResult XRAPI_CALL layer_create_haptic_collider(XrFingertipHapticsPROPRIO haptics,
                                                            const XrHapticColliderCreateInfoPROPRIO* info,
                                                            XrHapticColliderPROPRIO* out) {
  return guarded("xrCreateHapticColliderPROPRIO", [&] {
    std::unique_lock lock(registry().mutex);
    HapticsHandle* hh = find_haptics_locked(haptics);
    if (!hh) return XR_ERROR_HANDLE_INVALID;
    if (!info || info->type != XR_TYPE_HAPTIC_COLLIDER_CREATE_INFO_PROPRIO || !out) return XR_ERROR_VALIDATION_FAILURE;
    if (!hh->contact) return XR_ERROR_FEATURE_UNSUPPORTED;  // created without the contact simulation
    ColliderSpec spec;
    switch (info->shape) {
      case XR_HAPTIC_COLLIDER_SHAPE_SPHERE_PROPRIO: spec.kind = ColliderKind::sphere; break;
      case XR_HAPTIC_COLLIDER_SHAPE_BOX_PROPRIO: spec.kind = ColliderKind::box; break;
      case XR_HAPTIC_COLLIDER_SHAPE_CAPSULE_PROPRIO: spec.kind = ColliderKind::capsule; break;
      case XR_HAPTIC_COLLIDER_SHAPE_CYLINDER_PROPRIO: spec.kind = ColliderKind::cylinder; break;
      default: return XR_ERROR_VALIDATION_FAILURE;
    }
    spec.radius_m = info->radius;
    spec.half_length_m = info->halfLength;
    spec.half_extents_m = from_xr(info->halfExtents);
    spec.friction = info->friction;
    Pose T_world;
    if (const XrResult pr = collider_pose_in_world(*hh, info->poseInfo, T_world); XR_FAILED(pr)) return pr;
    hh->relocate(info->poseInfo.time);
    const int id = hh->service->add_collider(spec, T_world);
    if (id == FingertipHapticsService::kCollidersFull) return XR_ERROR_LIMIT_REACHED;
    if (id < 0) return XR_ERROR_VALIDATION_FAILURE;  // sizes or friction out of range
    auto c = std::make_unique<ColliderHandle>();
    c->parent = hh;
    c->id = id;
    const auto handle = reinterpret_cast<XrHapticColliderPROPRIO>(c.get());
    collider_handles()[handle] = std::move(c);
    hh->colliders.push_back(handle);
    *out = handle;
    return XR_SUCCESS;
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_set_haptic_collider_pose(XrHapticColliderPROPRIO collider,
                                                              const XrHapticColliderPoseInfoPROPRIO* info) {
  return guarded("xrSetHapticColliderPosePROPRIO", [&] {
    std::shared_lock lock(registry().mutex);
    auto it = collider_handles().find(collider);
    if (it == collider_handles().end()) return XR_ERROR_HANDLE_INVALID;
    if (!info) return XR_ERROR_VALIDATION_FAILURE;
    HapticsHandle& hh = *it->second->parent;
    Pose T_world;
    if (const XrResult pr = collider_pose_in_world(hh, *info, T_world); XR_FAILED(pr)) return pr;
    hh.relocate(info->time);
    hh.service->move_collider(it->second->id, T_world);
    return XR_SUCCESS;
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_destroy_haptic_collider(XrHapticColliderPROPRIO collider) {
  return guarded("xrDestroyHapticColliderPROPRIO", [&] {
    std::unique_lock lock(registry().mutex);
    auto it = collider_handles().find(collider);
    if (it == collider_handles().end()) return XR_ERROR_HANDLE_INVALID;
    HapticsHandle& hh = *it->second->parent;
    hh.service->remove_collider(it->second->id);
    std::erase(hh.colliders, collider);
    collider_handles().erase(it);
    return XR_SUCCESS;
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_locate_proxy_hand_joints(XrFingertipHapticsPROPRIO haptics, XrHandEXT hand,
                                                              const XrHandJointsLocateInfoEXT* info,
                                                              XrHandJointLocationsEXT* locations) {
  return guarded("xrLocateProxyHandJointsPROPRIO", [&] {
    std::shared_lock lock(registry().mutex);
    HapticsHandle* hh = find_haptics_locked(haptics);
    if (!hh) return XR_ERROR_HANDLE_INVALID;
    Handedness side;
    if (!hand_of(hand, side)) return XR_ERROR_VALIDATION_FAILURE;
    if (!info || info->type != XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT) return XR_ERROR_VALIDATION_FAILURE;
    if (!locations || locations->type != XR_TYPE_HAND_JOINT_LOCATIONS_EXT) return XR_ERROR_VALIDATION_FAILURE;
    if (locations->jointCount != kHandJointCount || !locations->jointLocations) return XR_ERROR_VALIDATION_FAILURE;
    auto* velocities = find_in_chain<XrHandJointVelocitiesEXT>(locations->next, XR_TYPE_HAND_JOINT_VELOCITIES_EXT);
    if (velocities && (velocities->jointCount != kHandJointCount || !velocities->jointVelocities)) {
      return XR_ERROR_VALIDATION_FAILURE;
    }
    if (info->baseSpace == XR_NULL_HANDLE) return XR_ERROR_HANDLE_INVALID;
    if (info->time <= 0) return XR_ERROR_TIME_INVALID;
    if (!hh->contact) return XR_ERROR_FEATURE_UNSUPPORTED;
    hh->relocate(info->time);
    HandPose proxy;
    Pose T_base_world;
    XrResult r = XR_SUCCESS;
    const bool have_world = locate_pose(*hh->instance, hh->world_space, info->baseSpace, info->time, T_base_world, &r);
    if (r == XR_ERROR_HANDLE_INVALID || r == XR_ERROR_TIME_INVALID) return r;
    if (!have_world || !hh->service->proxy_hand(side, proxy)) {
      write_inactive(locations, velocities, nullptr);
      return XR_SUCCESS;
    }
    // The simulated proxy is where it is now: it has no history to look up
    // at other times (the layer's 1 kHz simulation lags the tracked hand by
    // the coupling's ~20 ms time constant, which is what makes it a proxy).
    locations->isActive = XR_TRUE;
    for (std::size_t i = 0; i < kHandJointCount; ++i) {
      XrHandJointLocationEXT& o = locations->jointLocations[i];
      o.pose = proprio::to_xr(T_base_world * proxy.T_world_joint[i]);
      o.radius = static_cast<float>(std::max(proxy.radius_m[i], 1e-3));
      o.locationFlags = kBothValid | kBothTracked;
    }
    if (velocities) {
      for (uint32_t i = 0; i < velocities->jointCount; ++i) velocities->jointVelocities[i].velocityFlags = 0;
    }
    return XR_SUCCESS;
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_get_fingertip_haptics_state(XrFingertipHapticsPROPRIO haptics, XrHandEXT hand,
                                                                 XrFingertipHapticsStatePROPRIO* state) {
  return guarded("xrGetFingertipHapticsStatePROPRIO", [&] {
    std::shared_lock lock(registry().mutex);
    HapticsHandle* hh = find_haptics_locked(haptics);
    if (!hh) return XR_ERROR_HANDLE_INVALID;
    Handedness side;
    if (!hand_of(hand, side) || !state || state->type != XR_TYPE_FINGERTIP_HAPTICS_STATE_PROPRIO) {
      return XR_ERROR_VALIDATION_FAILURE;
    }
    FingertipHapticsReport report;
    state->time = 0;
    for (auto& f : state->fingers) f = {};
    if (!hh->service->report(side, report)) return XR_SUCCESS;
    const Instance& inst = *hh->instance;
    XrTime t = report.time_ns;
    if (inst.next.convert_timespec_to_time) {
      timespec ts{static_cast<time_t>(report.time_ns / kNsPerSecond), static_cast<long>(report.time_ns % kNsPerSecond)};
      if (XR_FAILED(inst.next.convert_timespec_to_time(inst.handle, &ts, &t))) t = report.time_ns;
    }
    state->time = t;
    for (std::size_t f = 0; f < kFingerCount; ++f) {
      const FingertipReport& in = report.fingers[f];
      XrFingertipStatePROPRIO& o = state->fingers[f];
      switch (in.gate) {
        case FingertipGate::ramping: o.gateState = XR_FINGERTIP_GATE_STATE_RAMPING_PROPRIO; break;
        case FingertipGate::active: o.gateState = XR_FINGERTIP_GATE_STATE_ACTIVE_PROPRIO; break;
        case FingertipGate::faulted: o.gateState = XR_FINGERTIP_GATE_STATE_FAULTED_PROPRIO; break;
        default: o.gateState = XR_FINGERTIP_GATE_STATE_OFF_PROPRIO;
      }
      o.connected = in.connected ? XR_TRUE : XR_FALSE;
      o.commandedForce = proprio::to_xr(in.commanded_in_tip);
      o.measuredForce = proprio::to_xr(in.measured_in_tip);
      o.contactForce = proprio::to_xr(in.contact_in_tip);
    }
    return XR_SUCCESS;
  });
}

// xrApplyHapticFeedback on a hand path (or on no path: both hands) presses
// the fingertip devices of that hand; the call goes on to the runtime too,
// so controllers still buzz.
bool hands_of_haptic_action(const Instance& inst, const XrHapticActionInfo* info, std::array<bool, 2>& hands) {
  if (!info || info->type != XR_TYPE_HAPTIC_ACTION_INFO) return false;
  hands = {info->subactionPath == XR_NULL_PATH || info->subactionPath == inst.haptic_hand_paths[0],
           info->subactionPath == XR_NULL_PATH || info->subactionPath == inst.haptic_hand_paths[1]};
  return hands[0] || hands[1];
}

XRAPI_ATTR XrResult XRAPI_CALL layer_apply_haptic_feedback(XrSession session, const XrHapticActionInfo* info,
                                                           const XrHapticBaseHeader* feedback) {
  return guarded("xrApplyHapticFeedback", [&] {
    PFN_xrApplyHapticFeedback next = nullptr;
    {
      std::shared_lock lock(registry().mutex);
      auto it = registry().sessions.find(session);
      if (it == registry().sessions.end()) return XR_ERROR_HANDLE_INVALID;
      const Session& s = *it->second;
      next = s.instance->next.apply_haptic_feedback;
      std::array<bool, 2> hands{};
      if (s.haptics && feedback && feedback->type == XR_TYPE_HAPTIC_VIBRATION &&
          hands_of_haptic_action(*s.instance, info, hands)) {
        const auto* v = reinterpret_cast<const XrHapticVibration*>(feedback);
        const TimeNs now = MonotonicClock::instance().now_ns();
        for (std::size_t h = 0; h < 2; ++h) {
          if (hands[h]) s.haptics->vibrate(static_cast<Handedness>(h), v->amplitude, v->duration, now);
        }
      }
    }
    return next(session, info, feedback);
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_stop_haptic_feedback(XrSession session, const XrHapticActionInfo* info) {
  return guarded("xrStopHapticFeedback", [&] {
    PFN_xrStopHapticFeedback next = nullptr;
    {
      std::shared_lock lock(registry().mutex);
      auto it = registry().sessions.find(session);
      if (it == registry().sessions.end()) return XR_ERROR_HANDLE_INVALID;
      const Session& s = *it->second;
      next = s.instance->next.stop_haptic_feedback;
      std::array<bool, 2> hands{};
      if (s.haptics && hands_of_haptic_action(*s.instance, info, hands)) {
        for (std::size_t h = 0; h < 2; ++h) {
          if (hands[h]) s.haptics->stop_vibration(static_cast<Handedness>(h));
        }
      }
    }
    return next(session, info);
  });
}

XRAPI_ATTR XrResult XRAPI_CALL layer_get_instance_proc_addr(XrInstance instance, const char* name,
                                                            PFN_xrVoidFunction* function) {
  return guarded("xrGetInstanceProcAddr", [&] {
    if (!name || !function) return XR_ERROR_VALIDATION_FAILURE;
    PFN_xrGetInstanceProcAddr next = nullptr;
    bool hook_hands = false, hook_system = false, hook_actions = false, hook_events = false, latency = false;
    bool fingertip = false, haptics = false, vibration = false;
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
      hook_actions = hook_system && inst->wants_actions();
      hook_events = hook_system && inst->vive_tracker && !inst->app_vive_tracker;
      latency = hook_system && inst->latency;
      fingertip = inst->fingertip;
      haptics = inst->haptics_wanted();
      vibration = haptics && inst->next.apply_haptic_feedback && inst->next.stop_haptic_feedback;
    }
    const std::string_view n(name);
    auto ours = [&](auto fn) {
      *function = reinterpret_cast<PFN_xrVoidFunction>(fn);
      return XR_SUCCESS;
    };
    // Always ours, so our per-instance state lives exactly as long as the instance.
    if (n == "xrGetInstanceProcAddr") return ours(&layer_get_instance_proc_addr);
    if (n == "xrDestroyInstance") return ours(&layer_destroy_instance);
    if (hook_system || fingertip) {
      if (n == "xrGetSystemProperties") return ours(&layer_get_system_properties);
    }
    if (hook_system || haptics) {
      if (n == "xrCreateSession") return ours(&layer_create_session);
      if (n == "xrDestroySession") return ours(&layer_destroy_session);
    }
    if ((hook_events || haptics) && n == "xrPollEvent") return ours(&layer_poll_event);
    if (vibration) {
      if (n == "xrApplyHapticFeedback") return ours(&layer_apply_haptic_feedback);
      if (n == "xrStopHapticFeedback") return ours(&layer_stop_haptic_feedback);
    }
    if (n.ends_with("PROPRIO") && n != "xrGetHandTrackingLatencyPROPRIO") {
      using F = PFN_xrVoidFunction;
      struct Entry {
        std::string_view name;
        F fn;
      };
      static const Entry kFingertip[] = {
          {"xrCreateFingertipHapticsPROPRIO", reinterpret_cast<F>(&layer_create_fingertip_haptics)},
          {"xrDestroyFingertipHapticsPROPRIO", reinterpret_cast<F>(&layer_destroy_fingertip_haptics)},
          {"xrGetFingertipHapticsPropertiesPROPRIO", reinterpret_cast<F>(&layer_get_fingertip_haptics_properties)},
          {"xrApplyFingertipForcesPROPRIO", reinterpret_cast<F>(&layer_apply_fingertip_forces)},
          {"xrCreateHapticColliderPROPRIO", reinterpret_cast<F>(&layer_create_haptic_collider)},
          {"xrSetHapticColliderPosePROPRIO", reinterpret_cast<F>(&layer_set_haptic_collider_pose)},
          {"xrDestroyHapticColliderPROPRIO", reinterpret_cast<F>(&layer_destroy_haptic_collider)},
          {"xrLocateProxyHandJointsPROPRIO", reinterpret_cast<F>(&layer_locate_proxy_hand_joints)},
          {"xrGetFingertipHapticsStatePROPRIO", reinterpret_cast<F>(&layer_get_fingertip_haptics_state)},
      };
      for (const Entry& e : kFingertip) {
        if (n != e.name) continue;
        *function = fingertip ? e.fn : nullptr;
        return fingertip ? XR_SUCCESS : XR_ERROR_FUNCTION_UNSUPPORTED;
      }
    }
    if (hook_hands) {
      if (n == "xrCreateHandTrackerEXT") return ours(&layer_create_hand_tracker);
      if (n == "xrDestroyHandTrackerEXT") return ours(&layer_destroy_hand_tracker);
      if (n == "xrLocateHandJointsEXT") return ours(&layer_locate_hand_joints);
    }
    if (hook_actions) {
      if (n == "xrSuggestInteractionProfileBindings") return ours(&layer_suggest_bindings);
      if (n == "xrAttachSessionActionSets") return ours(&layer_attach_action_sets);
      if (n == "xrSyncActions") return ours(&layer_sync_actions);
      if (n == "xrBeginFrame") return ours(&layer_begin_frame);
    }
    if (n == "xrGetHandTrackingLatencyPROPRIO") {
      if (!latency) {
        *function = nullptr;
        return XR_ERROR_FUNCTION_UNSUPPORTED;
      }
      return ours(&layer_get_latency);
    }
    return next(instance, name, function);
  });
}

bool is_ours(std::string_view ext) noexcept {
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
      inst->latency |= e == XR_PROPRIO_HAND_TRACKING_LATENCY_EXTENSION_NAME;
      inst->fingertip |= e == XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME;
      inst->app_vive_tracker |= e == XR_HTCX_VIVE_TRACKER_INTERACTION_EXTENSION_NAME;
      app_convert_timespec |= e == XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME;
    }
    // The config is read for hand tracking, and for haptics even in an app
    // that tracks no hands (its vibrations can still reach the fingertips).
    // Sources start only for hand tracking or the fingertip extension (the
    // contact simulation follows the tracked hands).
    const bool asked = inst->hand_tracking || inst->fingertip;
    if (load_config(*inst, !asked) && asked) start_sources(*inst);
    const RuntimeHandTracking mode = inst->config.runtime_hand_tracking;
    inst->serving = inst->hand_tracking && (mode == RuntimeHandTracking::override_it ||
                                            (mode == RuntimeHandTracking::automatic && !inst->sources.empty()));

    // What the rest of the chain sees: without our extensions when we serve
    // them (XR_PROPRIO_* never goes down), plus what we need ourselves: the
    // time conversion, and for a runtime wrist the tracker extension or the
    // runtime's own hand tracking (each dropped again if the runtime lacks it).
    struct Extras {
      bool tracker = false;  // add XR_HTCX_vive_tracker_interaction
      bool hands = false;    // keep XR_EXT_hand_tracking
    };
    auto build = [&](bool strip_ours, bool add_timespec, Extras x = {}) {
      std::vector<const char*> names;
      for (uint32_t i = 0; i < info->enabledExtensionCount; ++i) {
        const std::string_view e(info->enabledExtensionNames[i]);
        if (e == XR_PROPRIO_HAND_TRACKING_LATENCY_EXTENSION_NAME || e == XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME) {
          continue;  // ours alone, never the runtime's
        }
        if (strip_ours && is_ours(e) && !(x.hands && e == XR_EXT_HAND_TRACKING_EXTENSION_NAME)) continue;
        names.push_back(info->enabledExtensionNames[i]);
      }
      if (add_timespec) names.push_back(XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME);
      if (x.tracker) names.push_back(XR_HTCX_VIVE_TRACKER_INTERACTION_EXTENSION_NAME);
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
    Extras extras;
    extras.tracker = inst->serving && !inst->app_vive_tracker && any_wrist(*inst, WristSource::tracker);
    extras.hands = inst->serving && any_wrist(*inst, WristSource::runtime_hand);
    XrResult r = create(build(inst->serving, timespec && !app_convert_timespec, extras));
    const Extras wanted = extras;
    if (r == XR_ERROR_EXTENSION_NOT_PRESENT && (wanted.tracker || wanted.hands)) {
      const Extras fallbacks[] = {{false, wanted.hands}, {wanted.tracker, false}, {false, false}};
      for (const Extras& x : fallbacks) {
        if (x.tracker == wanted.tracker && x.hands == wanted.hands) continue;  // the one that failed
        extras = x;
        r = create(build(inst->serving, timespec && !app_convert_timespec, extras));
        if (r != XR_ERROR_EXTENSION_NOT_PRESENT) break;
      }
    }
    inst->vive_tracker = inst->app_vive_tracker || extras.tracker;
    inst->runtime_hands = extras.hands;
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
    if (wanted.tracker && !extras.tracker) {
      logger().error("Proprio layer: the runtime lacks {}: a wrist = \"tracker\" source gets no tracker wrist",
                     XR_HTCX_VIVE_TRACKER_INTERACTION_EXTENSION_NAME);
    }
    if (wanted.hands && !extras.hands) {
      logger().error("Proprio layer: the runtime has no hand tracking of its own: a wrist = \"runtime_hand\" "
                     "source gets no wrist from it");
    }

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
      d.convert_timespec_to_time = resolve<PFN_xrConvertTimespecTimeToTimeKHR>(gipa, *instance, "xrConvertTimespecTimeToTimeKHR");
    }
    if (inst->runtime_hands) {
      d.create_hand_tracker = resolve<PFN_xrCreateHandTrackerEXT>(gipa, *instance, "xrCreateHandTrackerEXT");
      d.destroy_hand_tracker = resolve<PFN_xrDestroyHandTrackerEXT>(gipa, *instance, "xrDestroyHandTrackerEXT");
      d.locate_hand_joints = resolve<PFN_xrLocateHandJointsEXT>(gipa, *instance, "xrLocateHandJointsEXT");
      if (!d.create_hand_tracker || !d.destroy_hand_tracker || !d.locate_hand_joints) {
        logger().error("Proprio layer: the runtime lists hand tracking but lacks its functions: no runtime_hand wrist");
        inst->runtime_hands = false;
      }
    }
    d.poll_event = resolve<PFN_xrPollEvent>(gipa, *instance, "xrPollEvent");
    if (inst->haptics_wanted()) {
      d.apply_haptic_feedback = resolve<PFN_xrApplyHapticFeedback>(gipa, *instance, "xrApplyHapticFeedback");
      d.stop_haptic_feedback = resolve<PFN_xrStopHapticFeedback>(gipa, *instance, "xrStopHapticFeedback");
      const auto string_to_path = resolve<PFN_xrStringToPath>(gipa, *instance, "xrStringToPath");
      const char* const paths[2] = {"/user/hand/left", "/user/hand/right"};
      for (std::size_t h = 0; h < 2 && string_to_path; ++h) {
        if (XR_FAILED(string_to_path(*instance, paths[h], &inst->haptic_hand_paths[h]))) inst->haptic_hand_paths[h] = XR_NULL_PATH;
      }
    }
    if (inst->serving && (any_wrist(*inst, WristSource::controller) || any_wrist(*inst, WristSource::tracker))) {
      d.string_to_path = resolve<PFN_xrStringToPath>(gipa, *instance, "xrStringToPath");
      d.create_action_set = resolve<PFN_xrCreateActionSet>(gipa, *instance, "xrCreateActionSet");
      d.create_action = resolve<PFN_xrCreateAction>(gipa, *instance, "xrCreateAction");
      d.suggest_bindings = resolve<PFN_xrSuggestInteractionProfileBindings>(gipa, *instance, "xrSuggestInteractionProfileBindings");
      d.attach_action_sets = resolve<PFN_xrAttachSessionActionSets>(gipa, *instance, "xrAttachSessionActionSets");
      d.sync_actions = resolve<PFN_xrSyncActions>(gipa, *instance, "xrSyncActions");
      d.create_action_space = resolve<PFN_xrCreateActionSpace>(gipa, *instance, "xrCreateActionSpace");
      d.begin_frame = resolve<PFN_xrBeginFrame>(gipa, *instance, "xrBeginFrame");
      inst->handle = *instance;
      if (!d.string_to_path || !d.create_action_set || !d.create_action || !d.suggest_bindings ||
          !d.attach_action_sets || !d.sync_actions || !d.create_action_space || !d.begin_frame) {
        logger().error("Proprio layer: the runtime lacks the action functions: no controller or tracker wrist");
      } else if (auto st = create_wrist_actions(*inst); !st) {
        logger().error("Proprio layer: no controller or tracker wrist: {}", st.error().message);
        inst->action_set = XR_NULL_HANDLE;  // the runtime frees what was made with the instance
        inst->grip_action = inst->tracker_action = XR_NULL_HANDLE;
      }
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
    Instance* raw = inst.get();
    {
      std::unique_lock lock(registry().mutex);
      registry().instances[*instance] = std::move(inst);
    }
    for (auto& provider : raw->head_providers) provider->bind(*instance);
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
