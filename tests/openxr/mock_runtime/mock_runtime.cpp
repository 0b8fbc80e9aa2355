// Proprio mock OpenXR runtime: a test fixture loaded by the real OpenXR loader
// (through XR_RUNTIME_JSON) so that the Proprio API layer, and Debian's
// core_validation layer above it, run against a runtime whose every answer a
// test can predict (see mock_motion.hpp). It is headless only (XR_MND_headless).
//
// Its checks are real where a layer could get something wrong: handles are
// tracked per type and owner, structure types and output pointers are
// validated, and the session lifecycle and frame calls follow the spec's
// order. Every entry point runs behind `guarded`, so no exception crosses the
// C ABI, and behind one registry mutex, so any thread may call anything.
#include "mock_motion.hpp"

#include <proprio/openxr_layer/loader_interfaces.hpp>

#include <openxr/openxr_platform.h>  // XR_KHR_convert_timespec_time (XR_USE_TIMESPEC)
#include <openxr/openxr_reflection.h>

#include <time.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <initializer_list>
#include <mutex>
#include <new>
#include <string>
#include <string_view>
#include <type_traits>
#include <unordered_map>
#include <vector>

namespace {
namespace mx = proprio::mock_xr;

constexpr char kRuntimeName[] = "Proprio mock runtime";
constexpr char kSystemName[] = "Proprio mock HMD (headless)";
constexpr XrSystemId kSystemId = 1;
constexpr uint32_t kMaxLayerCount = 16;

bool env_is_one(const char* name) {
  const char* value = std::getenv(name);
  return value != nullptr && std::string_view(value) == "1";
}

// ---------------------------------------------------------------- strings --
const char* result_name(XrResult value) {
  switch (value) {
#define PROPRIO_MOCK_CASE(name, number) \
  case name:                            \
    return #name;
    XR_LIST_ENUM_XrResult(PROPRIO_MOCK_CASE)
#undef PROPRIO_MOCK_CASE
  }
  return nullptr;
}

const char* structure_type_name(XrStructureType value) {
  switch (value) {
#define PROPRIO_MOCK_CASE(name, number) \
  case name:                            \
    return #name;
    XR_LIST_ENUM_XrStructureType(PROPRIO_MOCK_CASE)
#undef PROPRIO_MOCK_CASE
  }
  return nullptr;
}

void copy_string(char* dst, std::size_t capacity, std::string_view src) {
  const std::size_t n = std::min(src.size(), capacity - 1);
  std::memcpy(dst, src.data(), n);
  dst[n] = '\0';
}

// ------------------------------------------------------- guarded entries --
bool log_calls() {
  static const bool enabled = env_is_one("PROPRIO_MOCK_RUNTIME_LOG");
  return enabled;
}

// `what`, if any, is shown with the function's name in the log.
template <class Body>
XrResult guarded(const char* function, Body&& body, const char* what = nullptr) noexcept {
  XrResult result = XR_ERROR_RUNTIME_FAILURE;
  try {
    result = body();
  } catch (const std::bad_alloc&) {
    result = XR_ERROR_OUT_OF_MEMORY;
  } catch (...) {
    result = XR_ERROR_RUNTIME_FAILURE;
  }
  if (log_calls()) {
    const char* name = result_name(result);
    std::fprintf(stderr, "[proprio-mock-xr] %s%s%s%s -> ", function, what ? "(" : "", what ? what : "",
                 what ? ")" : "");
    if (name != nullptr) {
      std::fprintf(stderr, "%s\n", name);
    } else {
      std::fprintf(stderr, "%d\n", static_cast<int>(result));
    }
  }
  return result;
}

// A function's name as a template argument, so each entry point's wrapper
// knows what to log.
template <std::size_t N>
struct FixedName {
  char text[N];
  constexpr FixedName(const char (&s)[N]) { std::copy_n(s, N, text); }  // NOLINT: implicit on purpose
};

// What the log adds to a call: the name asked of xrGetInstanceProcAddr, the
// string given to xrStringToPath.
template <class... Args>
const char* log_detail(const Args&...) {
  return nullptr;
}
template <class Out>
const char* log_detail(XrInstance, const char* text, Out*) {
  return text;
}

template <FixedName Name, auto Impl>
struct Entry;
template <FixedName Name, class... Args, XrResult (*Impl)(Args...)>
struct Entry<Name, Impl> {
  static XRAPI_ATTR XrResult XRAPI_CALL call(Args... args) {
    return guarded(Name.text, [&] { return Impl(args...); }, log_calls() ? log_detail(args...) : nullptr);
  }
};

// ---------------------------------------------------------------- state --
enum class Ext { none, convert_timespec_time, headless, hand_tracking };

struct ExtensionInfo {
  const char* name;
  uint32_t version;
  Ext ext;
};

// What xrEnumerateInstanceExtensionProperties offers right now. Native hand
// tracking is opt-in, so layer tests can run with and without it.
std::vector<ExtensionInfo> offered_extensions() {
  std::vector<ExtensionInfo> list{
      {XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME, XR_KHR_convert_timespec_time_SPEC_VERSION,
       Ext::convert_timespec_time},
      {XR_MND_HEADLESS_EXTENSION_NAME, XR_MND_headless_SPEC_VERSION, Ext::headless},
  };
  if (env_is_one("PROPRIO_MOCK_RUNTIME_HAND_TRACKING")) {
    list.push_back({XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_EXT_hand_tracking_SPEC_VERSION, Ext::hand_tracking});
  }
  return list;
}

struct InstanceState {
  bool convert_timespec_time = false;
  bool headless = false;
  bool hand_tracking = false;
  std::deque<XrEventDataSessionStateChanged> events;
  std::vector<std::string> paths;  // XrPath p names paths[p - 1]

  bool enabled(Ext ext) const {
    switch (ext) {
      case Ext::none:
        return true;
      case Ext::convert_timespec_time:
        return convert_timespec_time;
      case Ext::headless:
        return headless;
      case Ext::hand_tracking:
        return hand_tracking;
    }
    return false;
  }
};

struct SessionState {
  uint64_t instance = 0;
  XrSessionState state = XR_SESSION_STATE_UNKNOWN;
  bool running = false;
  bool frame_waited = false;  // xrWaitFrame returned, xrBeginFrame not yet called
  bool frame_begun = false;   // xrBeginFrame returned, xrEndFrame not yet called
};

struct SpaceState {
  uint64_t session = 0;
  XrReferenceSpaceType type = XR_REFERENCE_SPACE_TYPE_LOCAL;
  XrPosef offset = mx::kIdentityPose;
};

struct HandTrackerState {
  uint64_t session = 0;
  XrHandEXT hand = XR_HAND_LEFT_EXT;
};

struct Registry {
  std::mutex mutex;
  // One id sequence for every handle type: a handle of one type is never a
  // valid handle of another, and a destroyed handle is never reused.
  uint64_t next_id = 0x1000;
  std::unordered_map<uint64_t, InstanceState> instances;
  std::unordered_map<uint64_t, SessionState> sessions;
  std::unordered_map<uint64_t, SpaceState> spaces;
  std::unordered_map<uint64_t, HandTrackerState> hand_trackers;
};

Registry& registry() {
  static Registry r;
  return r;
}

template <class Handle>
Handle to_handle(uint64_t id) {
  return reinterpret_cast<Handle>(static_cast<std::uintptr_t>(id));
}
template <class Handle>
uint64_t id_of(Handle handle) {
  return static_cast<uint64_t>(reinterpret_cast<std::uintptr_t>(handle));
}
template <class Map>
auto* find(Map& map, uint64_t id) {
  auto it = map.find(id);
  return it == map.end() ? nullptr : &it->second;
}

// Queues a state-change event; the session's state is the last one queued.
void push_state(Registry& reg, uint64_t session_id, XrSessionState state) {
  SessionState& session = reg.sessions.at(session_id);
  session.state = state;
  XrEventDataSessionStateChanged event{};
  event.type = XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED;
  event.session = to_handle<XrSession>(session_id);
  event.state = state;
  event.time = mx::xr_time_now();
  reg.instances.at(session.instance).events.push_back(event);
}

// Callers hold the registry mutex.
void destroy_session_locked(Registry& reg, uint64_t session_id) {
  std::erase_if(reg.spaces, [&](const auto& kv) { return kv.second.session == session_id; });
  std::erase_if(reg.hand_trackers, [&](const auto& kv) { return kv.second.session == session_id; });
  auto it = reg.sessions.find(session_id);
  if (it == reg.sessions.end()) return;
  if (InstanceState* instance = find(reg.instances, it->second.instance)) {
    const XrSession handle = to_handle<XrSession>(session_id);
    std::erase_if(instance->events, [&](const auto& e) { return e.session == handle; });
  }
  reg.sessions.erase(it);
}

// The two-call idiom: report the count, fill only when capacity suffices.
template <class T, class Write>
XrResult two_call(uint32_t capacity, uint32_t* count_output, T* items, uint32_t count, Write write) {
  if (count_output == nullptr || (capacity > 0 && items == nullptr)) return XR_ERROR_VALIDATION_FAILURE;
  *count_output = count;
  if (capacity == 0) return XR_SUCCESS;
  if (capacity < count) return XR_ERROR_SIZE_INSUFFICIENT;
  for (uint32_t i = 0; i < count; ++i) {
    const XrResult result = write(items[i], i);
    if (XR_FAILED(result)) return result;
  }
  return XR_SUCCESS;
}

bool chain_has_graphics_binding(const void* next) {
  for (auto* s = static_cast<const XrBaseInStructure*>(next); s != nullptr; s = s->next) {
    const char* name = structure_type_name(s->type);
    if (name != nullptr && std::string_view(name).starts_with("XR_TYPE_GRAPHICS_BINDING_")) return true;
  }
  return false;
}

bool is_valid_pose(const XrPosef& pose) {
  const XrQuaternionf& q = pose.orientation;
  const XrVector3f& p = pose.position;
  for (float v : {q.x, q.y, q.z, q.w, p.x, p.y, p.z}) {
    if (!std::isfinite(v)) return false;
  }
  // The spec lets runtimes accept "close enough" unit quaternions.
  return std::abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0f) < 1e-2f;
}

// OpenXR path syntax: "/" then "/"-separated components of [a-z0-9-_.], no
// empty, "." or ".." component, no trailing "/".
bool is_well_formed_path(std::string_view path) {
  if (path.size() < 2 || path.size() >= XR_MAX_PATH_LENGTH || path.front() != '/' || path.back() == '/') return false;
  std::size_t start = 1;
  while (start <= path.size()) {
    const std::size_t end = std::min(path.find('/', start), path.size());
    const std::string_view component = path.substr(start, end - start);
    if (component.empty() || component == "." || component == "..") return false;
    for (char c : component) {
      const bool ok = (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' || c == '_' || c == '.';
      if (!ok) return false;
    }
    start = end + 1;
  }
  return true;
}

constexpr XrSpaceLocationFlags kAllLocationFlags =
    XR_SPACE_LOCATION_ORIENTATION_VALID_BIT | XR_SPACE_LOCATION_POSITION_VALID_BIT |
    XR_SPACE_LOCATION_ORIENTATION_TRACKED_BIT | XR_SPACE_LOCATION_POSITION_TRACKED_BIT;

}  // namespace

// ------------------------------------------------------------ functions --
// Named as the OpenXR functions they implement; Entry<> wraps each one.
namespace impl {
namespace {

XrResult xrGetInstanceProcAddr(XrInstance instance, const char* name, PFN_xrVoidFunction* function);

XrResult xrEnumerateApiLayerProperties(uint32_t capacity, uint32_t* count, XrApiLayerProperties* properties) {
  // A runtime has no API layers of its own.
  return two_call(capacity, count, properties, 0, [](XrApiLayerProperties&, uint32_t) { return XR_SUCCESS; });
}

XrResult xrEnumerateInstanceExtensionProperties(const char* layer_name, uint32_t capacity, uint32_t* count,
                                                XrExtensionProperties* properties) {
  if (layer_name != nullptr && layer_name[0] != '\0') return XR_ERROR_API_LAYER_NOT_PRESENT;
  const std::vector<ExtensionInfo> offered = offered_extensions();
  return two_call(capacity, count, properties, static_cast<uint32_t>(offered.size()),
                  [&](XrExtensionProperties& p, uint32_t i) {
                    if (p.type != XR_TYPE_EXTENSION_PROPERTIES) return XR_ERROR_VALIDATION_FAILURE;
                    copy_string(p.extensionName, XR_MAX_EXTENSION_NAME_SIZE, offered[i].name);
                    p.extensionVersion = offered[i].version;
                    return XR_SUCCESS;
                  });
}

XrResult xrCreateInstance(const XrInstanceCreateInfo* info, XrInstance* instance) {
  if (info == nullptr || instance == nullptr || info->type != XR_TYPE_INSTANCE_CREATE_INFO || info->createFlags != 0) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  const XrVersion api = info->applicationInfo.apiVersion;
  if (XR_VERSION_MAJOR(api) != 1 || XR_VERSION_MINOR(api) != 0) return XR_ERROR_API_VERSION_UNSUPPORTED;
  const std::size_t name_length = strnlen(info->applicationInfo.applicationName, XR_MAX_APPLICATION_NAME_SIZE);
  if (name_length == 0 || name_length == XR_MAX_APPLICATION_NAME_SIZE) return XR_ERROR_NAME_INVALID;
  if (info->enabledExtensionCount > 0 && info->enabledExtensionNames == nullptr) return XR_ERROR_VALIDATION_FAILURE;

  // API layer names are the loader's business: a runtime ignores them.
  InstanceState state;
  const std::vector<ExtensionInfo> offered = offered_extensions();
  for (uint32_t i = 0; i < info->enabledExtensionCount; ++i) {
    const char* requested = info->enabledExtensionNames[i];
    if (requested == nullptr) return XR_ERROR_VALIDATION_FAILURE;
    auto it = std::find_if(offered.begin(), offered.end(),
                           [&](const ExtensionInfo& e) { return std::string_view(e.name) == requested; });
    if (it == offered.end()) return XR_ERROR_EXTENSION_NOT_PRESENT;
    switch (it->ext) {
      case Ext::convert_timespec_time:
        state.convert_timespec_time = true;
        break;
      case Ext::headless:
        state.headless = true;
        break;
      case Ext::hand_tracking:
        state.hand_tracking = true;
        break;
      case Ext::none:
        break;
    }
  }

  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t id = reg.next_id++;
  reg.instances.emplace(id, std::move(state));
  *instance = to_handle<XrInstance>(id);
  return XR_SUCCESS;
}

XrResult xrDestroyInstance(XrInstance instance) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t id = id_of(instance);
  if (find(reg.instances, id) == nullptr) return XR_ERROR_HANDLE_INVALID;
  std::vector<uint64_t> owned;
  for (const auto& [session_id, session] : reg.sessions) {
    if (session.instance == id) owned.push_back(session_id);
  }
  for (uint64_t session_id : owned) destroy_session_locked(reg, session_id);
  reg.instances.erase(id);
  return XR_SUCCESS;
}

XrResult xrGetInstanceProperties(XrInstance instance, XrInstanceProperties* properties) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  if (find(reg.instances, id_of(instance)) == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (properties == nullptr || properties->type != XR_TYPE_INSTANCE_PROPERTIES) return XR_ERROR_VALIDATION_FAILURE;
  properties->runtimeVersion = XR_MAKE_VERSION(0, 1, 0);
  copy_string(properties->runtimeName, XR_MAX_RUNTIME_NAME_SIZE, kRuntimeName);
  return XR_SUCCESS;
}

XrResult xrPollEvent(XrInstance instance, XrEventDataBuffer* event_data) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  InstanceState* state = find(reg.instances, id_of(instance));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (event_data == nullptr || event_data->type != XR_TYPE_EVENT_DATA_BUFFER) return XR_ERROR_VALIDATION_FAILURE;
  if (state->events.empty()) return XR_EVENT_UNAVAILABLE;
  // The buffer is a union-like 4000 bytes; the event is copied over its start.
  static_assert(sizeof(XrEventDataSessionStateChanged) <= sizeof(XrEventDataBuffer));
  std::memcpy(static_cast<void*>(event_data), &state->events.front(), sizeof(XrEventDataSessionStateChanged));
  state->events.pop_front();
  return XR_SUCCESS;
}

bool instance_exists(XrInstance instance) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  return find(reg.instances, id_of(instance)) != nullptr;
}

XrResult xrResultToString(XrInstance instance, XrResult value, char buffer[XR_MAX_RESULT_STRING_SIZE]) {
  if (!instance_exists(instance)) return XR_ERROR_HANDLE_INVALID;
  if (buffer == nullptr) return XR_ERROR_VALIDATION_FAILURE;
  if (const char* name = result_name(value)) {
    copy_string(buffer, XR_MAX_RESULT_STRING_SIZE, name);
  } else {
    std::snprintf(buffer, XR_MAX_RESULT_STRING_SIZE, "XR_UNKNOWN_%s_%d", XR_SUCCEEDED(value) ? "SUCCESS" : "FAILURE",
                  static_cast<int>(value));
  }
  return XR_SUCCESS;
}

XrResult xrStructureTypeToString(XrInstance instance, XrStructureType value, char buffer[XR_MAX_STRUCTURE_NAME_SIZE]) {
  if (!instance_exists(instance)) return XR_ERROR_HANDLE_INVALID;
  if (buffer == nullptr) return XR_ERROR_VALIDATION_FAILURE;
  if (const char* name = structure_type_name(value)) {
    copy_string(buffer, XR_MAX_STRUCTURE_NAME_SIZE, name);
  } else {
    std::snprintf(buffer, XR_MAX_STRUCTURE_NAME_SIZE, "XR_UNKNOWN_STRUCTURE_TYPE_%d", static_cast<int>(value));
  }
  return XR_SUCCESS;
}

XrResult xrGetSystem(XrInstance instance, const XrSystemGetInfo* info, XrSystemId* system_id) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  if (find(reg.instances, id_of(instance)) == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || system_id == nullptr || info->type != XR_TYPE_SYSTEM_GET_INFO) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  switch (info->formFactor) {
    case XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY:
      *system_id = kSystemId;
      return XR_SUCCESS;
    case XR_FORM_FACTOR_HANDHELD_DISPLAY:
      return XR_ERROR_FORM_FACTOR_UNSUPPORTED;
    default:
      return XR_ERROR_VALIDATION_FAILURE;
  }
}

XrResult xrGetSystemProperties(XrInstance instance, XrSystemId system_id, XrSystemProperties* properties) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const InstanceState* state = find(reg.instances, id_of(instance));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (system_id != kSystemId) return XR_ERROR_SYSTEM_INVALID;
  if (properties == nullptr || properties->type != XR_TYPE_SYSTEM_PROPERTIES) return XR_ERROR_VALIDATION_FAILURE;
  properties->systemId = kSystemId;
  properties->vendorId = 0;
  copy_string(properties->systemName, XR_MAX_SYSTEM_NAME_SIZE, kSystemName);
  properties->graphicsProperties = {0, 0, kMaxLayerCount};
  properties->trackingProperties = {XR_TRUE, XR_TRUE};
  // Structures of extensions that are not enabled are ignored, like a runtime
  // that does not know them; so supportsHandTracking is written only when the
  // instance enabled native XR_EXT_hand_tracking.
  for (auto* s = static_cast<XrBaseOutStructure*>(properties->next); s != nullptr; s = s->next) {
    if (s->type == XR_TYPE_SYSTEM_HAND_TRACKING_PROPERTIES_EXT && state->hand_tracking) {
      reinterpret_cast<XrSystemHandTrackingPropertiesEXT*>(s)->supportsHandTracking = XR_TRUE;
    }
  }
  return XR_SUCCESS;
}

XrResult xrEnumerateEnvironmentBlendModes(XrInstance instance, XrSystemId system_id,
                                          XrViewConfigurationType view_configuration, uint32_t capacity,
                                          uint32_t* count, XrEnvironmentBlendMode* modes) {
  if (!instance_exists(instance)) return XR_ERROR_HANDLE_INVALID;
  if (system_id != kSystemId) return XR_ERROR_SYSTEM_INVALID;
  if (view_configuration != XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO) {
    return XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED;
  }
  return two_call(capacity, count, modes, 1, [](XrEnvironmentBlendMode& m, uint32_t) {
    m = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
    return XR_SUCCESS;
  });
}

XrResult xrCreateSession(XrInstance instance, const XrSessionCreateInfo* info, XrSession* session) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t instance_id = id_of(instance);
  const InstanceState* state = find(reg.instances, instance_id);
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || session == nullptr || info->type != XR_TYPE_SESSION_CREATE_INFO || info->createFlags != 0) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (info->systemId != kSystemId) return XR_ERROR_SYSTEM_INVALID;
  // Headless only: without XR_MND_headless, or with any graphics binding, the
  // session would need a graphics device this runtime does not have.
  if (!state->headless || chain_has_graphics_binding(info->next)) return XR_ERROR_GRAPHICS_DEVICE_INVALID;

  const uint64_t id = reg.next_id++;
  reg.sessions.emplace(id, SessionState{instance_id});
  push_state(reg, id, XR_SESSION_STATE_IDLE);
  push_state(reg, id, XR_SESSION_STATE_READY);
  *session = to_handle<XrSession>(id);
  return XR_SUCCESS;
}

XrResult xrDestroySession(XrSession session) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  if (find(reg.sessions, id_of(session)) == nullptr) return XR_ERROR_HANDLE_INVALID;
  destroy_session_locked(reg, id_of(session));
  return XR_SUCCESS;
}

XrResult xrEnumerateReferenceSpaces(XrSession session, uint32_t capacity, uint32_t* count,
                                    XrReferenceSpaceType* spaces) {
  {
    Registry& reg = registry();
    std::lock_guard lock(reg.mutex);
    if (find(reg.sessions, id_of(session)) == nullptr) return XR_ERROR_HANDLE_INVALID;
  }
  static constexpr XrReferenceSpaceType kTypes[] = {XR_REFERENCE_SPACE_TYPE_VIEW, XR_REFERENCE_SPACE_TYPE_LOCAL,
                                                    XR_REFERENCE_SPACE_TYPE_STAGE};
  return two_call(capacity, count, spaces, 3, [](XrReferenceSpaceType& t, uint32_t i) {
    t = kTypes[i];
    return XR_SUCCESS;
  });
}

XrResult xrCreateReferenceSpace(XrSession session, const XrReferenceSpaceCreateInfo* info, XrSpace* space) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t session_id = id_of(session);
  if (find(reg.sessions, session_id) == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || space == nullptr || info->type != XR_TYPE_REFERENCE_SPACE_CREATE_INFO) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (!mx::is_supported_reference_space(info->referenceSpaceType)) return XR_ERROR_REFERENCE_SPACE_UNSUPPORTED;
  if (!is_valid_pose(info->poseInReferenceSpace)) return XR_ERROR_POSE_INVALID;
  const uint64_t id = reg.next_id++;
  reg.spaces.emplace(id, SpaceState{session_id, info->referenceSpaceType, info->poseInReferenceSpace});
  *space = to_handle<XrSpace>(id);
  return XR_SUCCESS;
}

XrResult xrGetReferenceSpaceBoundsRect(XrSession session, XrReferenceSpaceType type, XrExtent2Df* bounds) {
  {
    Registry& reg = registry();
    std::lock_guard lock(reg.mutex);
    if (find(reg.sessions, id_of(session)) == nullptr) return XR_ERROR_HANDLE_INVALID;
  }
  if (bounds == nullptr) return XR_ERROR_VALIDATION_FAILURE;
  if (!mx::is_supported_reference_space(type)) return XR_ERROR_REFERENCE_SPACE_UNSUPPORTED;
  *bounds = {0.0f, 0.0f};
  return XR_SPACE_BOUNDS_UNAVAILABLE;
}

XrResult xrDestroySpace(XrSpace space) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  return reg.spaces.erase(id_of(space)) == 1 ? XR_SUCCESS : XR_ERROR_HANDLE_INVALID;
}

XrResult xrLocateSpace(XrSpace space, XrSpace base_space, XrTime time, XrSpaceLocation* location) {
  SpaceState a, b;
  {
    Registry& reg = registry();
    std::lock_guard lock(reg.mutex);
    const SpaceState* pa = find(reg.spaces, id_of(space));
    const SpaceState* pb = find(reg.spaces, id_of(base_space));
    if (pa == nullptr || pb == nullptr) return XR_ERROR_HANDLE_INVALID;
    a = *pa;
    b = *pb;
  }
  if (a.session != b.session) return XR_ERROR_VALIDATION_FAILURE;  // must share a session
  if (location == nullptr || location->type != XR_TYPE_SPACE_LOCATION) return XR_ERROR_VALIDATION_FAILURE;
  if (time <= 0) return XR_ERROR_TIME_INVALID;

  const mx::Located located = mx::locate(a.type, a.offset, b.type, b.offset, time);
  location->locationFlags = kAllLocationFlags;
  location->pose = located.pose;
  for (auto* s = static_cast<XrBaseOutStructure*>(location->next); s != nullptr; s = s->next) {
    if (s->type == XR_TYPE_SPACE_VELOCITY) {
      auto* velocity = reinterpret_cast<XrSpaceVelocity*>(s);
      velocity->velocityFlags = XR_SPACE_VELOCITY_LINEAR_VALID_BIT | XR_SPACE_VELOCITY_ANGULAR_VALID_BIT;
      velocity->linearVelocity = located.linear_velocity;
      velocity->angularVelocity = located.angular_velocity;
    }
  }
  return XR_SUCCESS;
}

XrResult xrBeginSession(XrSession session, const XrSessionBeginInfo* info) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  // XR_MND_headless: the primary view configuration is not used, so any value is accepted.
  if (info == nullptr || info->type != XR_TYPE_SESSION_BEGIN_INFO) return XR_ERROR_VALIDATION_FAILURE;
  if (state->running) return XR_ERROR_SESSION_RUNNING;
  if (state->state != XR_SESSION_STATE_READY) return XR_ERROR_SESSION_NOT_READY;
  state->running = true;
  state->frame_waited = state->frame_begun = false;
  push_state(reg, id_of(session), XR_SESSION_STATE_SYNCHRONIZED);
  push_state(reg, id_of(session), XR_SESSION_STATE_VISIBLE);
  push_state(reg, id_of(session), XR_SESSION_STATE_FOCUSED);
  return XR_SUCCESS;
}

XrResult xrRequestExitSession(XrSession session) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (!state->running) return XR_ERROR_SESSION_NOT_RUNNING;
  if (state->state == XR_SESSION_STATE_STOPPING) return XR_SUCCESS;  // already on its way out
  // Step down the lifecycle as a real runtime does: FOCUSED -> VISIBLE -> SYNCHRONIZED -> STOPPING.
  if (state->state == XR_SESSION_STATE_FOCUSED) push_state(reg, id_of(session), XR_SESSION_STATE_VISIBLE);
  if (state->state == XR_SESSION_STATE_VISIBLE) push_state(reg, id_of(session), XR_SESSION_STATE_SYNCHRONIZED);
  push_state(reg, id_of(session), XR_SESSION_STATE_STOPPING);
  return XR_SUCCESS;
}

XrResult xrEndSession(XrSession session) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (!state->running) return XR_ERROR_SESSION_NOT_RUNNING;
  if (state->state != XR_SESSION_STATE_STOPPING) return XR_ERROR_SESSION_NOT_STOPPING;
  state->running = false;
  // Only xrRequestExitSession leads to STOPPING here, so the session then exits.
  push_state(reg, id_of(session), XR_SESSION_STATE_IDLE);
  push_state(reg, id_of(session), XR_SESSION_STATE_EXITING);
  return XR_SUCCESS;
}

XrResult xrWaitFrame(XrSession session, const XrFrameWaitInfo* info, XrFrameState* frame_state) {
  {
    Registry& reg = registry();
    std::lock_guard lock(reg.mutex);
    const SessionState* state = find(reg.sessions, id_of(session));
    if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
    if ((info != nullptr && info->type != XR_TYPE_FRAME_WAIT_INFO) || frame_state == nullptr ||
        frame_state->type != XR_TYPE_FRAME_STATE) {
      return XR_ERROR_VALIDATION_FAILURE;
    }
    if (!state->running) return XR_ERROR_SESSION_NOT_RUNNING;
  }
  // Throttle to 90 Hz without holding the lock: other threads keep working.
  const int64_t tick = mx::next_frame_tick(mx::monotonic_now_ns());
  const int64_t wake_ns = mx::frame_tick_ns(tick);
  const timespec wake{static_cast<time_t>(wake_ns / 1'000'000'000), static_cast<long>(wake_ns % 1'000'000'000)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &wake, nullptr) == EINTR) {
  }

  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;  // destroyed while we slept
  if (!state->running) return XR_ERROR_SESSION_NOT_RUNNING;
  state->frame_waited = true;
  // The frame started now is shown one period later, at the following tick.
  frame_state->predictedDisplayTime = mx::xr_time_from_monotonic_ns(mx::frame_tick_ns(tick + 1));
  frame_state->predictedDisplayPeriod = mx::kFramePeriodNs;
  frame_state->shouldRender =
      (state->state == XR_SESSION_STATE_VISIBLE || state->state == XR_SESSION_STATE_FOCUSED) ? XR_TRUE : XR_FALSE;
  return XR_SUCCESS;
}

XrResult xrBeginFrame(XrSession session, const XrFrameBeginInfo* info) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info != nullptr && info->type != XR_TYPE_FRAME_BEGIN_INFO) return XR_ERROR_VALIDATION_FAILURE;
  if (!state->running) return XR_ERROR_SESSION_NOT_RUNNING;
  if (!state->frame_waited) return XR_ERROR_CALL_ORDER_INVALID;
  state->frame_waited = false;
  if (state->frame_begun) return XR_FRAME_DISCARDED;  // the previous begun frame is dropped
  state->frame_begun = true;
  return XR_SUCCESS;
}

XrResult xrEndFrame(XrSession session, const XrFrameEndInfo* info) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || info->type != XR_TYPE_FRAME_END_INFO || (info->layerCount > 0 && info->layers == nullptr)) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (!state->running) return XR_ERROR_SESSION_NOT_RUNNING;
  if (!state->frame_begun) return XR_ERROR_CALL_ORDER_INVALID;
  if (info->displayTime <= 0) return XR_ERROR_TIME_INVALID;
  if (info->environmentBlendMode != XR_ENVIRONMENT_BLEND_MODE_OPAQUE) {
    return XR_ERROR_ENVIRONMENT_BLEND_MODE_UNSUPPORTED;
  }
  if (info->layerCount > kMaxLayerCount) return XR_ERROR_LAYER_LIMIT_EXCEEDED;
  // A headless session has no swapchains, so no layer can be valid.
  if (info->layerCount > 0) return XR_ERROR_LAYER_INVALID;
  state->frame_begun = false;
  return XR_SUCCESS;
}

XrResult xrStringToPath(XrInstance instance, const char* path_string, XrPath* path) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  InstanceState* state = find(reg.instances, id_of(instance));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (path_string == nullptr || path == nullptr) return XR_ERROR_VALIDATION_FAILURE;
  const std::string_view text(path_string, strnlen(path_string, XR_MAX_PATH_LENGTH));
  if (!is_well_formed_path(text)) return XR_ERROR_PATH_FORMAT_INVALID;
  auto it = std::find(state->paths.begin(), state->paths.end(), text);
  if (it == state->paths.end()) it = state->paths.insert(state->paths.end(), std::string(text));
  *path = static_cast<XrPath>(it - state->paths.begin()) + 1;
  return XR_SUCCESS;
}

XrResult xrPathToString(XrInstance instance, XrPath path, uint32_t capacity, uint32_t* count, char* buffer) {
  std::string text;
  {
    Registry& reg = registry();
    std::lock_guard lock(reg.mutex);
    const InstanceState* state = find(reg.instances, id_of(instance));
    if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
    if (path == XR_NULL_PATH || path > state->paths.size()) return XR_ERROR_PATH_INVALID;
    text = state->paths[path - 1];
  }
  return two_call(capacity, count, buffer, static_cast<uint32_t>(text.size() + 1), [&](char& c, uint32_t i) {
    c = i < text.size() ? text[i] : '\0';
    return XR_SUCCESS;
  });
}

// ---- XR_KHR_convert_timespec_time ----
XrResult check_extension(XrInstance instance, Ext ext) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const InstanceState* state = find(reg.instances, id_of(instance));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  return state->enabled(ext) ? XR_SUCCESS : XR_ERROR_FUNCTION_UNSUPPORTED;
}

XrResult xrConvertTimespecTimeToTimeKHR(XrInstance instance, const struct timespec* timespec_time, XrTime* time) {
  if (const XrResult r = check_extension(instance, Ext::convert_timespec_time); XR_FAILED(r)) return r;
  if (timespec_time == nullptr || time == nullptr) return XR_ERROR_VALIDATION_FAILURE;
  const int64_t ns = int64_t{timespec_time->tv_sec} * 1'000'000'000 + timespec_time->tv_nsec;
  const XrTime converted = mx::xr_time_from_monotonic_ns(ns);
  if (converted <= 0) return XR_ERROR_TIME_INVALID;
  *time = converted;
  return XR_SUCCESS;
}

XrResult xrConvertTimeToTimespecTimeKHR(XrInstance instance, XrTime time, struct timespec* timespec_time) {
  if (const XrResult r = check_extension(instance, Ext::convert_timespec_time); XR_FAILED(r)) return r;
  if (timespec_time == nullptr) return XR_ERROR_VALIDATION_FAILURE;
  const int64_t ns = mx::monotonic_ns_from_xr_time(time);
  if (time <= 0 || ns < 0) return XR_ERROR_TIME_INVALID;
  timespec_time->tv_sec = static_cast<time_t>(ns / 1'000'000'000);
  timespec_time->tv_nsec = static_cast<long>(ns % 1'000'000'000);
  return XR_SUCCESS;
}

// ---- XR_EXT_hand_tracking (native; only when offered and enabled) ----
XrResult xrCreateHandTrackerEXT(XrSession session, const XrHandTrackerCreateInfoEXT* info,
                                XrHandTrackerEXT* hand_tracker) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t session_id = id_of(session);
  const SessionState* state = find(reg.sessions, session_id);
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (!reg.instances.at(state->instance).hand_tracking) return XR_ERROR_FUNCTION_UNSUPPORTED;
  if (info == nullptr || hand_tracker == nullptr || info->type != XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT ||
      (info->hand != XR_HAND_LEFT_EXT && info->hand != XR_HAND_RIGHT_EXT) ||
      info->handJointSet != XR_HAND_JOINT_SET_DEFAULT_EXT) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  const uint64_t id = reg.next_id++;
  reg.hand_trackers.emplace(id, HandTrackerState{session_id, info->hand});
  *hand_tracker = to_handle<XrHandTrackerEXT>(id);
  return XR_SUCCESS;
}

XrResult xrDestroyHandTrackerEXT(XrHandTrackerEXT hand_tracker) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  return reg.hand_trackers.erase(id_of(hand_tracker)) == 1 ? XR_SUCCESS : XR_ERROR_HANDLE_INVALID;
}

XrResult xrLocateHandJointsEXT(XrHandTrackerEXT hand_tracker, const XrHandJointsLocateInfoEXT* info,
                               XrHandJointLocationsEXT* locations) {
  {
    Registry& reg = registry();
    std::lock_guard lock(reg.mutex);
    const HandTrackerState* tracker = find(reg.hand_trackers, id_of(hand_tracker));
    if (tracker == nullptr) return XR_ERROR_HANDLE_INVALID;
    if (info == nullptr || info->type != XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT) return XR_ERROR_VALIDATION_FAILURE;
    const SpaceState* base = find(reg.spaces, id_of(info->baseSpace));
    if (base == nullptr) return XR_ERROR_HANDLE_INVALID;
    if (base->session != tracker->session) return XR_ERROR_VALIDATION_FAILURE;
  }
  if (locations == nullptr || locations->type != XR_TYPE_HAND_JOINT_LOCATIONS_EXT ||
      locations->jointCount != XR_HAND_JOINT_COUNT_EXT || locations->jointLocations == nullptr) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (info->time <= 0) return XR_ERROR_TIME_INVALID;

  XrHandJointVelocitiesEXT* velocities = nullptr;
  for (auto* s = static_cast<XrBaseOutStructure*>(locations->next); s != nullptr; s = s->next) {
    if (s->type == XR_TYPE_HAND_JOINT_VELOCITIES_EXT) velocities = reinterpret_cast<XrHandJointVelocitiesEXT*>(s);
  }
  if (velocities != nullptr &&
      (velocities->jointCount != XR_HAND_JOINT_COUNT_EXT || velocities->jointVelocities == nullptr)) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  // The fixed, recognisable native pose (mock_motion.hpp), whatever the base space.
  locations->isActive = XR_TRUE;
  for (uint32_t i = 0; i < XR_HAND_JOINT_COUNT_EXT; ++i) {
    XrHandJointLocationEXT& joint = locations->jointLocations[i];
    joint.locationFlags = kAllLocationFlags;
    joint.pose = {{0.0f, 0.0f, 0.0f, 1.0f}, mx::kNativeJointPosition};
    joint.radius = mx::kNativeJointRadius;
    if (velocities != nullptr) {
      XrHandJointVelocityEXT& v = velocities->jointVelocities[i];
      v.velocityFlags = XR_SPACE_VELOCITY_LINEAR_VALID_BIT | XR_SPACE_VELOCITY_ANGULAR_VALID_BIT;
      v.linearVelocity = {0.0f, 0.0f, 0.0f};
      v.angularVelocity = {0.0f, 0.0f, 0.0f};
    }
  }
  return XR_SUCCESS;
}

}  // namespace
}  // namespace impl

// ------------------------------------------------------- dispatch table --
namespace {

struct Function {
  const char* name;
  PFN_xrVoidFunction pointer;
  Ext ext;
};

// Checks at compile time that each implementation has exactly the PFN's type.
template <class Pfn, FixedName Name, auto Impl>
Function make_function(Ext ext) {
  static_assert(std::is_same_v<Pfn, decltype(&Entry<Name, Impl>::call)>, "signature differs from the PFN type");
  return {Name.text, reinterpret_cast<PFN_xrVoidFunction>(&Entry<Name, Impl>::call), ext};
}
#define PROPRIO_MOCK_FUNCTION(fn, ext) make_function<PFN_##fn, #fn, &impl::fn>(ext)

const std::vector<Function>& functions() {
  static const std::vector<Function> table{
      PROPRIO_MOCK_FUNCTION(xrGetInstanceProcAddr, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrEnumerateApiLayerProperties, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrEnumerateInstanceExtensionProperties, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrCreateInstance, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrDestroyInstance, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrGetInstanceProperties, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrPollEvent, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrResultToString, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrStructureTypeToString, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrGetSystem, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrGetSystemProperties, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrEnumerateEnvironmentBlendModes, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrCreateSession, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrDestroySession, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrEnumerateReferenceSpaces, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrCreateReferenceSpace, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrGetReferenceSpaceBoundsRect, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrDestroySpace, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrLocateSpace, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrBeginSession, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrEndSession, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrRequestExitSession, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrWaitFrame, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrBeginFrame, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrEndFrame, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrStringToPath, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrPathToString, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrConvertTimespecTimeToTimeKHR, Ext::convert_timespec_time),
      PROPRIO_MOCK_FUNCTION(xrConvertTimeToTimespecTimeKHR, Ext::convert_timespec_time),
      PROPRIO_MOCK_FUNCTION(xrCreateHandTrackerEXT, Ext::hand_tracking),
      PROPRIO_MOCK_FUNCTION(xrDestroyHandTrackerEXT, Ext::hand_tracking),
      PROPRIO_MOCK_FUNCTION(xrLocateHandJointsEXT, Ext::hand_tracking),
  };
  return table;
}
#undef PROPRIO_MOCK_FUNCTION

const Function* find_function(std::string_view name) {
  for (const Function& f : functions()) {
    if (name == f.name) return &f;
  }
  return nullptr;
}

}  // namespace

namespace impl {
namespace {
XrResult xrGetInstanceProcAddr(XrInstance instance, const char* name, PFN_xrVoidFunction* function) {
  if (function == nullptr) return XR_ERROR_VALIDATION_FAILURE;
  *function = nullptr;
  if (name == nullptr) return XR_ERROR_VALIDATION_FAILURE;
  const Function* f = find_function(name);
  if (instance == XR_NULL_HANDLE) {
    // Only these three exist before an instance does (spec: else HANDLE_INVALID).
    const std::string_view n(name);
    if (n != "xrEnumerateInstanceExtensionProperties" && n != "xrEnumerateApiLayerProperties" &&
        n != "xrCreateInstance") {
      return XR_ERROR_HANDLE_INVALID;
    }
    *function = f->pointer;
    return XR_SUCCESS;
  }
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const InstanceState* state = find(reg.instances, id_of(instance));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (f == nullptr || !state->enabled(f->ext)) return XR_ERROR_FUNCTION_UNSUPPORTED;
  *function = f->pointer;
  return XR_SUCCESS;
}
}  // namespace
}  // namespace impl

// ------------------------------------------------------------ negotiation --
namespace {
XrResult negotiate(const XrNegotiateLoaderInfo* info, XrNegotiateRuntimeRequest* request) {
  if (info == nullptr || request == nullptr) return XR_ERROR_INITIALIZATION_FAILED;
  if (info->structType != XR_LOADER_INTERFACE_STRUCT_LOADER_INFO ||
      info->structVersion != PROPRIO_XR_LOADER_INFO_STRUCT_VERSION ||
      info->structSize != sizeof(XrNegotiateLoaderInfo)) {
    return XR_ERROR_INITIALIZATION_FAILED;
  }
  if (request->structType != XR_LOADER_INTERFACE_STRUCT_RUNTIME_REQUEST ||
      request->structVersion != PROPRIO_XR_RUNTIME_INFO_STRUCT_VERSION ||
      request->structSize != sizeof(XrNegotiateRuntimeRequest)) {
    return XR_ERROR_INITIALIZATION_FAILED;
  }
  constexpr uint32_t kInterface = PROPRIO_XR_CURRENT_LOADER_RUNTIME_VERSION;
  if (info->minInterfaceVersion > kInterface || info->maxInterfaceVersion < kInterface) {
    return XR_ERROR_INITIALIZATION_FAILED;
  }
  // Compare major.minor only: any 1.0.x loader can drive this 1.0 runtime.
  constexpr auto major_minor = [](XrVersion v) { return XR_MAKE_VERSION(XR_VERSION_MAJOR(v), XR_VERSION_MINOR(v), 0); };
  const XrVersion ours = major_minor(XR_CURRENT_API_VERSION);
  if (major_minor(info->minApiVersion) > ours || major_minor(info->maxApiVersion) < ours) {
    return XR_ERROR_INITIALIZATION_FAILED;
  }
  request->runtimeInterfaceVersion = kInterface;
  request->runtimeApiVersion = XR_CURRENT_API_VERSION;
  request->getInstanceProcAddr = &Entry<"xrGetInstanceProcAddr", &impl::xrGetInstanceProcAddr>::call;
  return XR_SUCCESS;
}
}  // namespace

// The only exported symbol (see mock_runtime.map).
extern "C" __attribute__((visibility("default"))) XRAPI_ATTR XrResult XRAPI_CALL
xrNegotiateLoaderRuntimeInterface(const XrNegotiateLoaderInfo* loaderInfo, XrNegotiateRuntimeRequest* runtimeRequest) {
  return guarded("xrNegotiateLoaderRuntimeInterface", [&] { return negotiate(loaderInfo, runtimeRequest); });
}
