// Proprio mock OpenXR runtime: a test fixture loaded by the real OpenXR loader
// (through XR_RUNTIME_JSON) so that the Proprio API layer, and Debian's
// core_validation layer above it, run against a runtime whose every answer a
// test can predict (see mock_motion.hpp). Sessions are headless
// (XR_MND_headless) or render through XR_KHR_vulkan_enable2 into swapchains
// whose images it can capture to PNG (see README.md).
//
// Its checks are real where a layer could get something wrong: handles are
// tracked per type and owner, structure types and output pointers are
// validated, and the session lifecycle and frame calls follow the spec's
// order. Every entry point runs behind `guarded`, so no exception crosses the
// C ABI, and behind one registry mutex, so any thread may call anything.
//
// Vulkan: the runtime never links the Vulkan loader (VK_NO_PROTOTYPES). Every
// Vulkan function is resolved through the vkGetInstanceProcAddr the app passed
// to xrCreateVulkanInstanceKHR, so the app's layers (validation) see the
// runtime's Vulkan calls too.
#include "mock_motion.hpp"

#include <proprio/openxr_layer/loader_interfaces.hpp>

// VK_NO_PROTOTYPES, XR_USE_GRAPHICS_API_VULKAN and XR_USE_TIMESPEC come from CMake.
#include <vulkan/vulkan.h>
// Vulkan must come first: the XR_KHR_vulkan_enable2 structures use its types.
#include <openxr/openxr_platform.h>
#include <openxr/openxr_reflection.h>

#include <stb_image_write.h>

#include <time.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <initializer_list>
#include <map>
#include <memory>
#include <mutex>
#include <new>
#include <optional>
#include <set>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <unordered_map>
#include <variant>
#include <vector>

namespace {
namespace mx = proprio::mock_xr;

constexpr char kRuntimeName[] = "Proprio mock runtime";
constexpr char kSystemName[] = "Proprio mock HMD (headless)";
constexpr XrSystemId kSystemId = 1;
constexpr uint32_t kMaxLayerCount = 16;

// PRIMARY_STEREO: two views, eyes 63 mm apart, a fixed symmetric field of view.
constexpr uint32_t kViewCount = 2;
constexpr uint32_t kDefaultViewWidth = 640;
constexpr uint32_t kDefaultViewHeight = 360;
constexpr uint32_t kMaxImageSize = 4096;
constexpr float kHalfIpdM = 0.0315f;
constexpr XrFovf kFov{-0.785f, 0.785f, 0.6f, -0.6f};  // left, right, up, down (radians)

// Swapchains: images per swapchain, and what a fresh image holds (opaque magenta,
// so a frame the app never drew is obvious in a capture).
constexpr uint32_t kSwapchainImageCount = 3;
constexpr VkClearColorValue kFreshImageColour{{1.0f, 0.0f, 1.0f, 1.0f}};
constexpr int64_t kSwapchainFormats[] = {VK_FORMAT_R8G8B8A8_SRGB, VK_FORMAT_B8G8R8A8_SRGB};
constexpr uint32_t kDefaultCaptureFrames = 2;

bool env_is_one(const char* name) {
  const char* value = std::getenv(name);
  return value != nullptr && std::string_view(value) == "1";
}

void warn(const char* format, ...) __attribute__((format(printf, 1, 2)));
void warn(const char* format, ...) {
  va_list args;
  va_start(args, format);
  std::fputs("[proprio-mock-xr] ", stderr);
  std::vfprintf(stderr, format, args);
  std::fputc('\n', stderr);
  va_end(args);
}

// A non-negative decimal integer from the environment; nullopt when unset or
// empty, `fallback` (with a warning) when malformed.
std::optional<uint32_t> env_uint(const char* name, uint32_t fallback) {
  const char* value = std::getenv(name);
  if (value == nullptr || value[0] == '\0') return std::nullopt;
  char* end = nullptr;
  errno = 0;
  const unsigned long n = std::strtoul(value, &end, 10);
  if (errno != 0 || *end != '\0' || value[0] == '-' || n > UINT32_MAX) {
    warn("%s=%s is not a non-negative integer; using %u", name, value, fallback);
    return fallback;
  }
  return static_cast<uint32_t>(n);
}

// "0" or "1" from the environment; `fallback` when unset or empty, and (with
// a warning) when malformed.
bool env_flag(const char* name, bool fallback) {
  const char* value = std::getenv(name);
  if (value == nullptr || value[0] == '\0') return fallback;
  const std::string_view v(value);
  if (v == "0" || v == "1") return v == "1";
  warn("%s=%s is neither 0 nor 1; using %d", name, value, fallback ? 1 : 0);
  return fallback;
}

// PROPRIO_MOCK_RUNTIME_VIEW_SIZE=WxH (each 1..4096); else 640x360.
XrExtent2Di view_size() {
  const char* value = std::getenv("PROPRIO_MOCK_RUNTIME_VIEW_SIZE");
  XrExtent2Di size{static_cast<int32_t>(kDefaultViewWidth), static_cast<int32_t>(kDefaultViewHeight)};
  if (value == nullptr || value[0] == '\0') return size;
  unsigned w = 0, h = 0;
  char tail = 0;
  if (std::sscanf(value, "%ux%u%c", &w, &h, &tail) == 2 && w >= 1 && h >= 1 && w <= kMaxImageSize &&
      h <= kMaxImageSize) {
    return {static_cast<int32_t>(w), static_cast<int32_t>(h)};
  }
  warn("PROPRIO_MOCK_RUNTIME_VIEW_SIZE=%s is not WxH with 1 <= W, H <= %u; using %dx%d", value, kMaxImageSize,
       size.width, size.height);
  return size;
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

// A Vulkan call the runtime made failed: guarded() reports it and answers
// XR_ERROR_RUNTIME_FAILURE.
struct VulkanError : std::runtime_error {
  VulkanError(const char* what, VkResult r) : std::runtime_error(what), result(r) {}
  VkResult result;
};
void check(VkResult result, const char* what) {
  if (result != VK_SUCCESS) throw VulkanError(what, result);
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
  } catch (const VulkanError& e) {
    warn("%s: %s failed with VkResult %d", function, e.what(), static_cast<int>(e.result));
    result = XR_ERROR_RUNTIME_FAILURE;
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
enum class Ext { none, convert_timespec_time, headless, hand_tracking, vulkan_enable2, vive_tracker };

// XR_HTCX_vive_tracker_interaction gained the wrist and ankle roles in
// revision 3; Debian's 1.0.20 header still says revision 1.
constexpr uint32_t kViveTrackerSpecVersion = 3;

// PROPRIO_MOCK_RUNTIME_HAND_TRACKING: "1" offers native hand tracking with
// fixed joints, "moving" with the analytic hand of mock_motion.hpp.
enum class HandTrackingMode { off, fixed, moving };
HandTrackingMode hand_tracking_mode() {
  const char* value = std::getenv("PROPRIO_MOCK_RUNTIME_HAND_TRACKING");
  if (value == nullptr) return HandTrackingMode::off;
  const std::string_view v(value);
  if (v == "1") return HandTrackingMode::fixed;
  if (v == "moving") return HandTrackingMode::moving;
  return HandTrackingMode::off;
}

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
      {XR_KHR_VULKAN_ENABLE2_EXTENSION_NAME, XR_KHR_vulkan_enable2_SPEC_VERSION, Ext::vulkan_enable2},
      {XR_HTCX_VIVE_TRACKER_INTERACTION_EXTENSION_NAME, kViveTrackerSpecVersion, Ext::vive_tracker},
  };
  if (hand_tracking_mode() != HandTrackingMode::off) {
    list.push_back({XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_EXT_hand_tracking_SPEC_VERSION, Ext::hand_tracking});
  }
  return list;
}

// ---- Vulkan, resolved through the app's vkGetInstanceProcAddr ----
#define PROPRIO_MOCK_VK_INSTANCE_FUNCTIONS(X) \
  X(vkEnumeratePhysicalDevices)               \
  X(vkGetPhysicalDeviceProperties)            \
  X(vkGetPhysicalDeviceQueueFamilyProperties) \
  X(vkGetPhysicalDeviceMemoryProperties)      \
  X(vkGetPhysicalDeviceImageFormatProperties) \
  X(vkCreateDevice)                           \
  X(vkGetDeviceProcAddr)

#define PROPRIO_MOCK_VK_DEVICE_FUNCTIONS(X) \
  X(vkGetDeviceQueue)                       \
  X(vkDeviceWaitIdle)                       \
  X(vkCreateImage)                          \
  X(vkDestroyImage)                         \
  X(vkGetImageMemoryRequirements)           \
  X(vkBindImageMemory)                      \
  X(vkCreateBuffer)                         \
  X(vkDestroyBuffer)                        \
  X(vkGetBufferMemoryRequirements)          \
  X(vkBindBufferMemory)                     \
  X(vkAllocateMemory)                       \
  X(vkFreeMemory)                           \
  X(vkMapMemory)                            \
  X(vkUnmapMemory)                          \
  X(vkCreateCommandPool)                    \
  X(vkDestroyCommandPool)                   \
  X(vkAllocateCommandBuffers)               \
  X(vkResetCommandBuffer)                   \
  X(vkBeginCommandBuffer)                   \
  X(vkEndCommandBuffer)                     \
  X(vkCmdPipelineBarrier)                   \
  X(vkCmdClearColorImage)                   \
  X(vkCmdCopyImageToBuffer)                 \
  X(vkCreateFence)                          \
  X(vkDestroyFence)                         \
  X(vkResetFences)                          \
  X(vkWaitForFences)                        \
  X(vkQueueSubmit)

#define PROPRIO_MOCK_VK_MEMBER(name) PFN_##name name = nullptr;
struct VkInstanceFunctions {
  PROPRIO_MOCK_VK_INSTANCE_FUNCTIONS(PROPRIO_MOCK_VK_MEMBER)
};
struct VkDeviceFunctions {
  PROPRIO_MOCK_VK_DEVICE_FUNCTIONS(PROPRIO_MOCK_VK_MEMBER)
};
#undef PROPRIO_MOCK_VK_MEMBER

// Each returns the name of the first function it could not resolve, or nullptr.
const char* load(VkInstanceFunctions& f, PFN_vkGetInstanceProcAddr gipa, VkInstance instance) {
#define PROPRIO_MOCK_VK_LOAD(name)                                      \
  f.name = reinterpret_cast<PFN_##name>(gipa(instance, #name));         \
  if (f.name == nullptr) return #name;
  PROPRIO_MOCK_VK_INSTANCE_FUNCTIONS(PROPRIO_MOCK_VK_LOAD)
#undef PROPRIO_MOCK_VK_LOAD
  return nullptr;
}
const char* load(VkDeviceFunctions& f, PFN_vkGetDeviceProcAddr gdpa, VkDevice device) {
#define PROPRIO_MOCK_VK_LOAD(name)                                      \
  f.name = reinterpret_cast<PFN_##name>(gdpa(device, #name));           \
  if (f.name == nullptr) return #name;
  PROPRIO_MOCK_VK_DEVICE_FUNCTIONS(PROPRIO_MOCK_VK_LOAD)
#undef PROPRIO_MOCK_VK_LOAD
  return nullptr;
}

// What xrCreateVulkanInstanceKHR / xrCreateVulkanDeviceKHR made for the app.
// The app owns (and destroys) them; the runtime only checks a graphics binding
// against them. Looked up newest first, as a destroyed handle's value can return.
struct VulkanInstanceRecord {
  VkInstance instance = VK_NULL_HANDLE;
  PFN_vkGetInstanceProcAddr get_instance_proc_addr = nullptr;
};
struct VulkanDeviceRecord {
  VkDevice device = VK_NULL_HANDLE;
  VkInstance instance = VK_NULL_HANDLE;
  VkPhysicalDevice physical_device = VK_NULL_HANDLE;
  std::vector<std::pair<uint32_t, uint32_t>> queues;  // (family, count) from VkDeviceCreateInfo
};

// ---- input devices: simple controllers and VIVE wrist trackers ----
enum class Device { left_controller, right_controller, left_tracker, right_tracker };
constexpr std::size_t kDeviceCount = 4;
constexpr const char* kDeviceNames[kDeviceCount] = {"left_controller", "right_controller", "left_tracker",
                                                    "right_tracker"};
constexpr bool is_tracker(Device d) { return d == Device::left_tracker || d == Device::right_tracker; }
constexpr mx::Hand hand_of(Device d) {
  return d == Device::left_controller || d == Device::left_tracker ? mx::Hand::left : mx::Hand::right;
}

constexpr std::string_view kSimpleControllerProfile = "/interaction_profiles/khr/simple_controller";
constexpr std::string_view kViveTrackerProfile = "/interaction_profiles/htc/vive_tracker_htcx";
constexpr std::string_view kHandPaths[] = {"/user/hand/left", "/user/hand/right"};
// Core top-level paths that have no device here but are valid subaction paths.
constexpr std::string_view kOtherTopLevelPaths[] = {"/user/head", "/user/gamepad"};
// XR_HTCX_vive_tracker_interaction revision 3.
constexpr std::string_view kTrackerRolePaths[] = {
    "/user/vive_tracker_htcx/role/handheld_object", "/user/vive_tracker_htcx/role/left_foot",
    "/user/vive_tracker_htcx/role/right_foot",      "/user/vive_tracker_htcx/role/left_shoulder",
    "/user/vive_tracker_htcx/role/right_shoulder",  "/user/vive_tracker_htcx/role/left_elbow",
    "/user/vive_tracker_htcx/role/right_elbow",     "/user/vive_tracker_htcx/role/left_knee",
    "/user/vive_tracker_htcx/role/right_knee",      "/user/vive_tracker_htcx/role/waist",
    "/user/vive_tracker_htcx/role/chest",           "/user/vive_tracker_htcx/role/camera",
    "/user/vive_tracker_htcx/role/keyboard",        "/user/vive_tracker_htcx/role/left_wrist",
    "/user/vive_tracker_htcx/role/right_wrist",     "/user/vive_tracker_htcx/role/left_ankle",
    "/user/vive_tracker_htcx/role/right_ankle"};
// The two trackers (left_tracker, right_tracker): persistent and role paths.
constexpr const char* kTrackerPersistentPaths[] = {"/devices/htc/vive_trackerLHR-MOCK0001",
                                                   "/devices/htc/vive_trackerLHR-MOCK0002"};
constexpr const char* kTrackerRoles[] = {"/user/vive_tracker_htcx/role/left_wrist",
                                         "/user/vive_tracker_htcx/role/right_wrist"};

// Where each device sits and which profile drives it.
struct DeviceSlot {
  Device device;
  std::string_view top_level;
  std::string_view profile;
};
constexpr DeviceSlot kDeviceSlots[kDeviceCount] = {
    {Device::left_controller, kHandPaths[0], kSimpleControllerProfile},
    {Device::right_controller, kHandPaths[1], kSimpleControllerProfile},
    {Device::left_tracker, kTrackerRoles[0], kViveTrackerProfile},
    {Device::right_tracker, kTrackerRoles[1], kViveTrackerProfile},
};

enum class InputKind { boolean, scalar, vector2, pose, haptic };
struct InputSource {
  std::string_view subpath;  // below the top-level path, e.g. "input/select/click"
  InputKind kind;
};
constexpr InputSource kSimpleControllerInputs[] = {
    {"input/select/click", InputKind::boolean}, {"input/menu/click", InputKind::boolean},
    {"input/grip/pose", InputKind::pose},       {"input/aim/pose", InputKind::pose},
    {"output/haptic", InputKind::haptic},
};
constexpr InputSource kViveTrackerInputs[] = {
    {"input/system/click", InputKind::boolean},   {"input/menu/click", InputKind::boolean},
    {"input/trigger/click", InputKind::boolean},  {"input/squeeze/click", InputKind::boolean},
    {"input/trigger/value", InputKind::scalar},   {"input/trackpad", InputKind::vector2},
    {"input/trackpad/x", InputKind::scalar},      {"input/trackpad/y", InputKind::scalar},
    {"input/trackpad/click", InputKind::boolean}, {"input/trackpad/touch", InputKind::boolean},
    {"input/grip/pose", InputKind::pose},         {"output/haptic", InputKind::haptic},
};

struct Profile {
  std::string_view path;
  Ext ext;  // the extension an app must enable to use it
  std::span<const InputSource> inputs;
  std::span<const std::string_view> top_levels;
  const char* localized_name;
};
constexpr Profile kProfiles[] = {
    {kSimpleControllerProfile, Ext::none, kSimpleControllerInputs, kHandPaths, "Simple Controller"},
    {kViveTrackerProfile, Ext::vive_tracker, kViveTrackerInputs, kTrackerRolePaths, "VIVE Tracker"},
};

// A subpath the profile accepts in a binding: an input source, or an
// identifier without its component ("input/select" for "input/select/click").
bool is_binding_subpath(const Profile& profile, std::string_view subpath) {
  for (const InputSource& input : profile.inputs) {
    if (input.subpath == subpath) return true;
  }
  if (!subpath.starts_with("input/")) return false;
  for (const InputSource& input : profile.inputs) {
    if (input.subpath.size() > subpath.size() && input.subpath.starts_with(subpath) &&
        input.subpath[subpath.size()] == '/') {
      return true;
    }
  }
  return false;
}

struct BindingPath {
  std::string_view top_level;
  std::string_view subpath;
};
// A binding path of `profile` split at its top-level path; nullopt if the
// profile has no such binding.
std::optional<BindingPath> split_binding(const Profile& profile, std::string_view path) {
  for (std::string_view top : profile.top_levels) {
    if (path.size() > top.size() + 1 && path.starts_with(top) && path[top.size()] == '/') {
      const std::string_view subpath = path.substr(top.size() + 1);
      if (is_binding_subpath(profile, subpath)) return BindingPath{top, subpath};
      return std::nullopt;
    }
  }
  return std::nullopt;
}

constexpr bool compatible(InputKind kind, XrActionType type) {
  switch (type) {
    case XR_ACTION_TYPE_BOOLEAN_INPUT:
    case XR_ACTION_TYPE_FLOAT_INPUT:
      return kind == InputKind::boolean || kind == InputKind::scalar;
    case XR_ACTION_TYPE_VECTOR2F_INPUT:
      return kind == InputKind::vector2;
    case XR_ACTION_TYPE_POSE_INPUT:
      return kind == InputKind::pose;
    case XR_ACTION_TYPE_VIBRATION_OUTPUT:
      return kind == InputKind::haptic;
    default:
      return false;
  }
}

// The input source an action of `type` reads through a binding subpath: the
// source itself when compatible, else for an identifier the component the
// spec prefers (boolean: click then value; float: value then click; pose:
// pose). nullptr: incompatible, the binding is ignored.
const InputSource* resolve_input(const Profile& profile, std::string_view subpath, XrActionType type) {
  auto find = [&](std::string_view wanted) -> const InputSource* {
    for (const InputSource& input : profile.inputs) {
      if (input.subpath == wanted) return &input;
    }
    return nullptr;
  };
  if (const InputSource* exact = find(subpath); exact != nullptr && compatible(exact->kind, type)) return exact;
  static constexpr std::string_view kBoolean[] = {"click", "value"};
  static constexpr std::string_view kFloat[] = {"value", "click"};
  static constexpr std::string_view kPose[] = {"pose"};
  std::span<const std::string_view> components;
  if (type == XR_ACTION_TYPE_BOOLEAN_INPUT) components = kBoolean;
  if (type == XR_ACTION_TYPE_FLOAT_INPUT) components = kFloat;
  if (type == XR_ACTION_TYPE_POSE_INPUT) components = kPose;
  for (std::string_view component : components) {
    const std::string wanted = std::string(subpath) + "/" + std::string(component);
    if (const InputSource* child = find(wanted); child != nullptr && compatible(child->kind, type)) return child;
  }
  return nullptr;
}

// A suggested binding resolved for its action's type (at xrAttachSessionActionSets).
struct Source {
  std::string_view profile;
  std::string_view top_level;
  std::string_view subpath;  // the input source read (kProfiles' table)
  InputKind kind;
  std::string path;  // top_level + "/" + subpath
  std::optional<Device> device;  // none: a top-level path without a device (e.g. /user/vive_tracker_htcx/role/waist)
};

std::optional<Device> device_at(std::string_view profile, std::string_view top_level) {
  for (const DeviceSlot& slot : kDeviceSlots) {
    if (slot.profile == profile && slot.top_level == top_level) return slot.device;
  }
  return std::nullopt;
}

// What a source reads at `time` (booleans as 0 or 1): only select/click moves.
double source_value(const Source& source, XrTime time) {
  if (source.device && !is_tracker(*source.device) && source.subpath == "input/select/click") {
    return mx::select_pressed(hand_of(*source.device), time) ? 1.0 : 0.0;
  }
  return 0.0;
}

// A pose source's device motion in LOCAL.
mx::Motion device_motion(Device device, std::string_view subpath, XrTime time) {
  if (is_tracker(device)) return mx::tracker_pose(hand_of(device), time);
  if (subpath == "input/aim/pose") return mx::controller_aim(hand_of(device), time);
  return mx::controller_grip(hand_of(device), time);
}

// PROPRIO_MOCK_RUNTIME_CONTROLLERS, _TRACKERS and _DISCONNECT, read at
// xrCreateInstance and again at each xrCreateSession.
struct DisconnectWindow {
  Device device;
  int64_t from_ns;  // after DeviceConfig::origin
  int64_t to_ns;
};
struct DeviceConfig {
  bool controllers = true;
  bool trackers = true;
  std::vector<DisconnectWindow> disconnects;
  XrTime origin = 0;  // when the configuration was read: the script's t = 0
};

// PROPRIO_MOCK_RUNTIME_DISCONNECT=<device>:<from>-<to>[,...], seconds after
// the configuration was read; a malformed entry is skipped with a warning.
std::vector<DisconnectWindow> parse_disconnects(std::string_view text) {
  std::vector<DisconnectWindow> windows;
  while (!text.empty()) {
    const std::size_t comma = std::min(text.find(','), text.size());
    const std::string entry(text.substr(0, comma));
    text.remove_prefix(std::min(comma + 1, text.size()));
    const std::size_t colon = entry.find(':');
    std::optional<Device> device;
    for (std::size_t d = 0; d < kDeviceCount && colon != std::string::npos; ++d) {
      if (entry.compare(0, colon, kDeviceNames[d]) == 0) device = static_cast<Device>(d);
    }
    double from = 0, to = 0;
    char tail = 0;
    if (!device || std::sscanf(entry.c_str() + colon + 1, "%lf-%lf%c", &from, &to, &tail) != 2 ||
        !(from >= 0) || !(to > from) || to > 1e6) {
      warn("PROPRIO_MOCK_RUNTIME_DISCONNECT: '%s' is not <device>:<from>-<to> (seconds, 0 <= from < to, device "
           "one of left_controller, right_controller, left_tracker, right_tracker); ignored",
           entry.c_str());
      continue;
    }
    windows.push_back({*device, static_cast<int64_t>(from * 1e9), static_cast<int64_t>(to * 1e9)});
  }
  return windows;
}

DeviceConfig read_device_config() {
  DeviceConfig config;
  config.controllers = env_flag("PROPRIO_MOCK_RUNTIME_CONTROLLERS", true);
  config.trackers = env_flag("PROPRIO_MOCK_RUNTIME_TRACKERS", true);
  if (const char* script = std::getenv("PROPRIO_MOCK_RUNTIME_DISCONNECT"))
    config.disconnects = parse_disconnects(script);
  config.origin = mx::xr_time_now();
  return config;
}

// Queued for xrPollEvent.
using Event = std::variant<XrEventDataSessionStateChanged, XrEventDataInteractionProfileChanged,
                           XrEventDataViveTrackerConnectedHTCX>;

// xrSuggestInteractionProfileBindings, as given (validated).
struct SuggestedBinding {
  uint64_t action = 0;
  std::string path;
};

struct InstanceState {
  bool convert_timespec_time = false;
  bool headless = false;
  bool hand_tracking = false;
  bool vulkan_enable2 = false;
  bool vive_tracker = false;
  std::deque<Event> events;
  std::vector<std::string> paths;  // XrPath p names paths[p - 1]

  // Input: the latest suggestion per interaction profile, and the devices.
  std::map<std::string, std::vector<SuggestedBinding>, std::less<>> suggestions;
  DeviceConfig devices;
  std::array<bool, 2> tracker_seen{};  // each tracker connected at the last refresh_trackers
  // What XR_TYPE_EVENT_DATA_VIVE_TRACKER_CONNECTED_HTCX events point at; the
  // instance's node in the registry never moves, so neither do these.
  std::array<XrViveTrackerPathsHTCX, 2> tracker_paths{};

  // XR_KHR_vulkan_enable2
  bool vulkan_requirements_queried = false;
  std::vector<VulkanInstanceRecord> vulkan_instances;
  VkInstance graphics_device_instance = VK_NULL_HANDLE;  // the last xrGetVulkanGraphicsDevice2KHR answer
  VkPhysicalDevice graphics_device = VK_NULL_HANDLE;
  std::vector<VulkanDeviceRecord> vulkan_devices;

  const VulkanInstanceRecord* vulkan_instance(VkInstance instance) const {
    for (auto it = vulkan_instances.rbegin(); it != vulkan_instances.rend(); ++it) {
      if (it->instance == instance) return &*it;
    }
    return nullptr;
  }
  const VulkanDeviceRecord* vulkan_device(VkDevice device) const {
    for (auto it = vulkan_devices.rbegin(); it != vulkan_devices.rend(); ++it) {
      if (it->device == device) return &*it;
    }
    return nullptr;
  }

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
      case Ext::vulkan_enable2:
        return vulkan_enable2;
      case Ext::vive_tracker:
        return vive_tracker;
    }
    return false;
  }
};

// A Vulkan session's device side: the app's objects (not owned) and the
// runtime's own command pool, fence and capture buffer (owned).
struct VulkanSession {
  VkInstance instance = VK_NULL_HANDLE;
  VkPhysicalDevice physical_device = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  uint32_t queue_family = 0;
  uint32_t queue_index = 0;
  VkQueue queue = VK_NULL_HANDLE;
  VkInstanceFunctions vki;
  VkDeviceFunctions vkd;
  VkPhysicalDeviceMemoryProperties memory{};

  VkCommandPool pool = VK_NULL_HANDLE;
  VkCommandBuffer commands = VK_NULL_HANDLE;
  VkFence fence = VK_NULL_HANDLE;
  VkBuffer staging = VK_NULL_HANDLE;  // host-visible, coherent; grows as needed
  VkDeviceMemory staging_memory = VK_NULL_HANDLE;
  void* staging_data = nullptr;
  VkDeviceSize staging_size = 0;
};

// What xrGetActionState* report until the next xrSyncActions.
struct ActionValue {
  bool active = false;
  bool changed = false;
  XrTime last_change = 0;
  float x = 0, y = 0;  // boolean (x != 0), float (x) or vector2 (x, y)
  std::optional<std::size_t> pose_source;  // into AttachedAction::sources
};

struct AttachedAction {
  uint64_t set = 0;
  uint32_t priority = 0;
  XrActionType type = XR_ACTION_TYPE_BOOLEAN_INPUT;
  std::vector<std::string> subaction_paths;
  std::vector<Source> sources;  // compatible bindings, in suggestion order
  std::map<std::string, ActionValue, std::less<>> values;  // by subaction path, "" for XR_NULL_PATH
};

struct SessionState {
  uint64_t instance = 0;
  XrSessionState state = XR_SESSION_STATE_UNKNOWN;
  bool running = false;
  bool frame_waited = false;  // xrWaitFrame returned, xrBeginFrame not yet called
  bool frame_begun = false;   // xrBeginFrame returned, xrEndFrame not yet called
  std::shared_ptr<VulkanSession> vulkan;  // null for a headless session

  // Counters, and the environment as it was when the session was created.
  uint64_t frames_ended = 0;
  uint64_t projection_layers = 0;
  uint32_t frames_captured = 0;
  uint32_t exit_after_frames = 0;  // 0: never
  // PROPRIO_MOCK_RUNTIME_UNFOCUS_AFTER_FRAMES: after this many ended frames
  // the session goes FOCUSED -> VISIBLE and stays (0: begin stops at VISIBLE).
  std::optional<uint32_t> unfocus_after_frames;
  // PROPRIO_MOCK_RUNTIME_MONADO_HEADLESS=1 on a headless session: frames are
  // refused as Monado refuses them (see xrWaitFrame).
  bool monado_headless = false;
  std::string capture_dir;         // empty: no capture
  uint32_t capture_frames = kDefaultCaptureFrames;  // 0: every frame
  HandTrackingMode hand_tracking = HandTrackingMode::fixed;  // when the instance enabled it

  // Actions: a snapshot taken at xrAttachSessionActionSets (attached sets are
  // immutable, so it never goes stale), and the states of the last sync.
  bool attached = false;
  std::unordered_map<uint64_t, uint32_t> attached_sets;  // id -> priority
  std::unordered_map<uint64_t, AttachedAction> actions;  // by action id
  std::set<std::string, std::less<>> suggested_profiles;  // with a binding of an attached action
  std::map<std::string, std::string, std::less<>> current_profiles;  // top-level path -> profile
};

struct SwapchainState {
  uint64_t session = 0;
  VkFormat format = VK_FORMAT_UNDEFINED;
  uint32_t width = 0, height = 0, array_size = 1, mip_count = 1;
  std::vector<VkImage> images;
  std::vector<VkDeviceMemory> memory;
  uint32_t next = 0;                       // the image the next acquire returns
  std::optional<uint32_t> acquired;        // acquired and not yet released
  bool waited = false;                     // the acquired image was waited on
  std::optional<uint32_t> last_released;   // what a projection layer shows
};

struct SpaceState {
  uint64_t session = 0;
  XrReferenceSpaceType type = XR_REFERENCE_SPACE_TYPE_LOCAL;
  XrPosef offset = mx::kIdentityPose;  // poseInReferenceSpace or poseInActionSpace
  uint64_t action = 0;                 // an action space's pose action; 0 for a reference space
  std::string subaction;               // an action space's subaction path ("" for XR_NULL_PATH)
};

struct ActionSetRecord {
  uint64_t instance = 0;
  std::string name, localized_name;
  uint32_t priority = 0;
  bool attached = false;  // to any session: immutable from then on
};

struct ActionRecord {
  uint64_t instance = 0;
  uint64_t set = 0;
  std::string name, localized_name;
  XrActionType type = XR_ACTION_TYPE_BOOLEAN_INPUT;
  std::vector<std::string> subaction_paths;
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
  std::unordered_map<uint64_t, SwapchainState> swapchains;
  std::unordered_map<uint64_t, ActionSetRecord> action_sets;
  std::unordered_map<uint64_t, ActionRecord> actions;
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

// The path atom of `text` (well-formed), creating it if needed.
XrPath intern_path(InstanceState& state, std::string_view text) {
  auto it = std::find(state.paths.begin(), state.paths.end(), text);
  if (it == state.paths.end()) it = state.paths.insert(state.paths.end(), std::string(text));
  return static_cast<XrPath>(it - state.paths.begin()) + 1;
}
// The string of a path atom; nullopt if it is not one (XR_ERROR_PATH_INVALID).
std::optional<std::string_view> path_string(const InstanceState& state, XrPath path) {
  if (path == XR_NULL_PATH || path > state.paths.size()) return std::nullopt;
  return state.paths[path - 1];
}

bool device_connected(const InstanceState& state, Device device, XrTime time) {
  const bool present = is_tracker(device) ? state.vive_tracker && state.devices.trackers : state.devices.controllers;
  if (!present) return false;
  for (const DisconnectWindow& w : state.devices.disconnects) {
    if (w.device == device && time >= state.devices.origin + w.from_ns && time < state.devices.origin + w.to_ns) {
      return false;
    }
  }
  return true;
}

// Queues XR_TYPE_EVENT_DATA_VIVE_TRACKER_CONNECTED_HTCX for each tracker that
// connected since the last call. Called whenever an app could notice.
void refresh_trackers(InstanceState& state, XrTime now) {
  if (!state.vive_tracker) return;
  for (std::size_t i = 0; i < 2; ++i) {
    const bool connected = device_connected(state, i == 0 ? Device::left_tracker : Device::right_tracker, now);
    if (connected && !state.tracker_seen[i]) {
      XrViveTrackerPathsHTCX& paths = state.tracker_paths[i];
      paths = {XR_TYPE_VIVE_TRACKER_PATHS_HTCX, nullptr, intern_path(state, kTrackerPersistentPaths[i]),
               intern_path(state, kTrackerRoles[i])};
      XrEventDataViveTrackerConnectedHTCX event{};
      event.type = XR_TYPE_EVENT_DATA_VIVE_TRACKER_CONNECTED_HTCX;
      event.paths = &paths;
      state.events.push_back(event);
    }
    state.tracker_seen[i] = connected;
  }
}

// A space in LOCAL at `time`; nullopt when it is not tracked (an action space
// whose action had no active pose binding at the last sync, or whose device
// is disconnected at `time`). Callers hold the registry mutex.
std::optional<mx::Motion> space_in_local(const Registry& reg, const SpaceState& space, XrTime time) {
  if (space.action == 0) return mx::space_in_local(space.type, space.offset, time);
  const SessionState& session = reg.sessions.at(space.session);
  const auto action = session.actions.find(space.action);
  if (action == session.actions.end()) return std::nullopt;
  const auto value = action->second.values.find(space.subaction);
  if (value == action->second.values.end() || !value->second.pose_source) return std::nullopt;
  const Source& source = action->second.sources[*value->second.pose_source];
  if (!source.device || !device_connected(reg.instances.at(session.instance), *source.device, time)) {
    return std::nullopt;
  }
  return mx::attach(device_motion(*source.device, source.subpath, time), mx::from_xr(space.offset));
}

// ---------------------------------------------------- vulkan helpers --
// All run with the registry mutex held, on the session's queue (the app must
// not use that queue from another thread during the OpenXR call, as the spec says).

uint32_t memory_type(const VkPhysicalDeviceMemoryProperties& properties, uint32_t allowed,
                     VkMemoryPropertyFlags wanted) {
  for (uint32_t i = 0; i < properties.memoryTypeCount; ++i) {
    if ((allowed & (1u << i)) && (properties.memoryTypes[i].propertyFlags & wanted) == wanted) return i;
  }
  throw VulkanError("finding a memory type", VK_ERROR_OUT_OF_DEVICE_MEMORY);
}

// Records with `record`, submits on the session's queue and waits for it.
template <class Record>
void submit_and_wait(VulkanSession& vk, Record&& record) {
  const VkDeviceFunctions& f = vk.vkd;
  check(f.vkResetFences(vk.device, 1, &vk.fence), "vkResetFences");
  check(f.vkResetCommandBuffer(vk.commands, 0), "vkResetCommandBuffer");
  VkCommandBufferBeginInfo begin{};
  begin.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  check(f.vkBeginCommandBuffer(vk.commands, &begin), "vkBeginCommandBuffer");
  record(vk.commands);
  check(f.vkEndCommandBuffer(vk.commands), "vkEndCommandBuffer");
  VkSubmitInfo submit{};
  submit.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &vk.commands;
  check(f.vkQueueSubmit(vk.queue, 1, &submit, vk.fence), "vkQueueSubmit");
  check(f.vkWaitForFences(vk.device, 1, &vk.fence, VK_TRUE, UINT64_MAX), "vkWaitForFences");
}

VkImageMemoryBarrier image_barrier(VkImage image, VkImageLayout from, VkImageLayout to, VkAccessFlags src_access,
                                   VkAccessFlags dst_access) {
  VkImageMemoryBarrier barrier{};
  barrier.sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER;
  barrier.srcAccessMask = src_access;
  barrier.dstAccessMask = dst_access;
  barrier.oldLayout = from;
  barrier.newLayout = to;
  barrier.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  barrier.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  barrier.image = image;
  barrier.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, VK_REMAINING_MIP_LEVELS, 0, VK_REMAINING_ARRAY_LAYERS};
  return barrier;
}

void destroy_swapchain_images(VulkanSession& vk, SwapchainState& swapchain) {
  for (VkImage image : swapchain.images) vk.vkd.vkDestroyImage(vk.device, image, nullptr);
  for (VkDeviceMemory memory : swapchain.memory) vk.vkd.vkFreeMemory(vk.device, memory, nullptr);
  swapchain.images.clear();
  swapchain.memory.clear();
}

void destroy_staging(VulkanSession& vk) {
  if (vk.staging_data != nullptr) vk.vkd.vkUnmapMemory(vk.device, vk.staging_memory);
  if (vk.staging != VK_NULL_HANDLE) vk.vkd.vkDestroyBuffer(vk.device, vk.staging, nullptr);
  if (vk.staging_memory != VK_NULL_HANDLE) vk.vkd.vkFreeMemory(vk.device, vk.staging_memory, nullptr);
  vk.staging_data = nullptr;
  vk.staging = VK_NULL_HANDLE;
  vk.staging_memory = VK_NULL_HANDLE;
  vk.staging_size = 0;
}

// The runtime's own objects; the app's device, queue and instance stay.
void destroy_vulkan_session(VulkanSession& vk) {
  destroy_staging(vk);
  if (vk.fence != VK_NULL_HANDLE) vk.vkd.vkDestroyFence(vk.device, vk.fence, nullptr);
  if (vk.pool != VK_NULL_HANDLE) vk.vkd.vkDestroyCommandPool(vk.device, vk.pool, nullptr);  // frees `commands`
  vk.fence = VK_NULL_HANDLE;
  vk.pool = VK_NULL_HANDLE;
  vk.commands = VK_NULL_HANDLE;
}

void ensure_staging(VulkanSession& vk, VkDeviceSize size) {
  if (vk.staging_size >= size) return;
  destroy_staging(vk);
  const VkDeviceFunctions& f = vk.vkd;
  VkBufferCreateInfo info{};
  info.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO;
  info.size = size;
  info.usage = VK_BUFFER_USAGE_TRANSFER_DST_BIT;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  check(f.vkCreateBuffer(vk.device, &info, nullptr, &vk.staging), "vkCreateBuffer (capture)");
  VkMemoryRequirements requirements{};
  f.vkGetBufferMemoryRequirements(vk.device, vk.staging, &requirements);
  VkMemoryAllocateInfo allocate{};
  allocate.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
  allocate.allocationSize = requirements.size;
  allocate.memoryTypeIndex = memory_type(vk.memory, requirements.memoryTypeBits,
                                         VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
  check(f.vkAllocateMemory(vk.device, &allocate, nullptr, &vk.staging_memory), "vkAllocateMemory (capture)");
  check(f.vkBindBufferMemory(vk.device, vk.staging, vk.staging_memory, 0), "vkBindBufferMemory (capture)");
  check(f.vkMapMemory(vk.device, vk.staging_memory, 0, VK_WHOLE_SIZE, 0, &vk.staging_data), "vkMapMemory (capture)");
  vk.staging_size = size;
}

// Callers hold the registry mutex.
void destroy_session_locked(Registry& reg, uint64_t session_id) {
  std::erase_if(reg.spaces, [&](const auto& kv) { return kv.second.session == session_id; });
  std::erase_if(reg.hand_trackers, [&](const auto& kv) { return kv.second.session == session_id; });
  auto it = reg.sessions.find(session_id);
  if (it == reg.sessions.end()) return;
  if (VulkanSession* vk = it->second.vulkan.get()) {
    // The app's device must still exist (the spec has it outlive the session).
    vk->vkd.vkDeviceWaitIdle(vk->device);
    for (auto& [id, swapchain] : reg.swapchains) {
      if (swapchain.session == session_id) destroy_swapchain_images(*vk, swapchain);
    }
    destroy_vulkan_session(*vk);
  }
  std::erase_if(reg.swapchains, [&](const auto& kv) { return kv.second.session == session_id; });
  if (log_calls()) {
    const SessionState& s = it->second;
    warn("session 0x%llx destroyed: %llu frames ended, %llu projection layers, %u frames captured",
         static_cast<unsigned long long>(session_id), static_cast<unsigned long long>(s.frames_ended),
         static_cast<unsigned long long>(s.projection_layers), s.frames_captured);
  }
  if (InstanceState* instance = find(reg.instances, it->second.instance)) {
    const XrSession handle = to_handle<XrSession>(session_id);
    std::erase_if(instance->events, [&](const Event& e) {
      return std::visit(
          [&](const auto& event) {
            if constexpr (requires { event.session; }) {
              return event.session == handle;
            } else {
              return false;
            }
          },
          e);
    });
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

// Any graphics binding other than `except`.
bool chain_has_graphics_binding(const void* next, XrStructureType except = XR_TYPE_UNKNOWN) {
  for (auto* s = static_cast<const XrBaseInStructure*>(next); s != nullptr; s = s->next) {
    if (s->type == except) continue;
    const char* name = structure_type_name(s->type);
    if (name != nullptr && std::string_view(name).starts_with("XR_TYPE_GRAPHICS_BINDING_")) return true;
  }
  return false;
}

// The first XR_KHR_vulkan_enable(2) binding in a chain (same structure, same type value).
const XrGraphicsBindingVulkanKHR* find_vulkan_binding(const void* next) {
  for (auto* s = static_cast<const XrBaseInStructure*>(next); s != nullptr; s = s->next) {
    if (s->type == XR_TYPE_GRAPHICS_BINDING_VULKAN_KHR) return reinterpret_cast<const XrGraphicsBindingVulkanKHR*>(s);
  }
  return nullptr;
}

// Checks a Vulkan graphics binding against what this instance created, then
// sets up the runtime's side of the session. Callers hold the registry mutex.
XrResult create_vulkan_session(const InstanceState& instance, const XrGraphicsBindingVulkanKHR& binding,
                               std::shared_ptr<VulkanSession>& out) {
  const VulkanInstanceRecord* vk_instance = instance.vulkan_instance(binding.instance);
  if (vk_instance == nullptr) {
    if (log_calls()) warn("xrCreateSession: the VkInstance was not created with xrCreateVulkanInstanceKHR");
    return XR_ERROR_GRAPHICS_DEVICE_INVALID;
  }
  if (binding.physicalDevice == VK_NULL_HANDLE || binding.physicalDevice != instance.graphics_device ||
      binding.instance != instance.graphics_device_instance) {
    if (log_calls()) warn("xrCreateSession: the VkPhysicalDevice is not what xrGetVulkanGraphicsDevice2KHR returned");
    return XR_ERROR_GRAPHICS_DEVICE_INVALID;
  }
  const VulkanDeviceRecord* vk_device = instance.vulkan_device(binding.device);
  if (vk_device == nullptr || vk_device->physical_device != binding.physicalDevice ||
      vk_device->instance != binding.instance) {
    if (log_calls()) warn("xrCreateSession: the VkDevice was not created with xrCreateVulkanDeviceKHR on that device");
    return XR_ERROR_GRAPHICS_DEVICE_INVALID;
  }
  const bool queue_created = std::any_of(vk_device->queues.begin(), vk_device->queues.end(), [&](const auto& q) {
    return q.first == binding.queueFamilyIndex && binding.queueIndex < q.second;
  });
  if (!queue_created) {
    if (log_calls()) warn("xrCreateSession: the device has no queue %u in family %u", binding.queueIndex,
                          binding.queueFamilyIndex);
    return XR_ERROR_GRAPHICS_DEVICE_INVALID;
  }

  auto vk = std::make_shared<VulkanSession>();
  vk->instance = binding.instance;
  vk->physical_device = binding.physicalDevice;
  vk->device = binding.device;
  vk->queue_family = binding.queueFamilyIndex;
  vk->queue_index = binding.queueIndex;
  if (const char* missing = load(vk->vki, vk_instance->get_instance_proc_addr, binding.instance)) {
    warn("xrCreateSession: vkGetInstanceProcAddr has no %s", missing);
    return XR_ERROR_RUNTIME_FAILURE;
  }
  if (const char* missing = load(vk->vkd, vk->vki.vkGetDeviceProcAddr, binding.device)) {
    warn("xrCreateSession: vkGetDeviceProcAddr has no %s", missing);
    return XR_ERROR_RUNTIME_FAILURE;
  }
  uint32_t family_count = 0;
  vk->vki.vkGetPhysicalDeviceQueueFamilyProperties(binding.physicalDevice, &family_count, nullptr);
  std::vector<VkQueueFamilyProperties> families(family_count);
  vk->vki.vkGetPhysicalDeviceQueueFamilyProperties(binding.physicalDevice, &family_count, families.data());
  if (binding.queueFamilyIndex >= family_count ||
      (families[binding.queueFamilyIndex].queueFlags & VK_QUEUE_GRAPHICS_BIT) == 0) {
    if (log_calls()) warn("xrCreateSession: queue family %u is not a graphics family", binding.queueFamilyIndex);
    return XR_ERROR_GRAPHICS_DEVICE_INVALID;
  }
  vk->vki.vkGetPhysicalDeviceMemoryProperties(binding.physicalDevice, &vk->memory);
  vk->vkd.vkGetDeviceQueue(binding.device, binding.queueFamilyIndex, binding.queueIndex, &vk->queue);

  try {
    VkCommandPoolCreateInfo pool{};
    pool.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
    pool.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
    pool.queueFamilyIndex = binding.queueFamilyIndex;
    check(vk->vkd.vkCreateCommandPool(vk->device, &pool, nullptr, &vk->pool), "vkCreateCommandPool");
    VkCommandBufferAllocateInfo allocate{};
    allocate.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
    allocate.commandPool = vk->pool;
    allocate.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    allocate.commandBufferCount = 1;
    check(vk->vkd.vkAllocateCommandBuffers(vk->device, &allocate, &vk->commands), "vkAllocateCommandBuffers");
    VkFenceCreateInfo fence{};
    fence.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
    check(vk->vkd.vkCreateFence(vk->device, &fence, nullptr, &vk->fence), "vkCreateFence");
  } catch (...) {
    destroy_vulkan_session(*vk);
    throw;
  }
  out = std::move(vk);
  return XR_SUCCESS;
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

// ------------------------------------------------------ frame end checks --
// One projection layer of a Vulkan session. Callers hold the registry mutex.
XrResult check_projection_layer(Registry& reg, uint64_t session_id, const XrCompositionLayerProjection& layer) {
  const SpaceState* space = find(reg.spaces, id_of(layer.space));
  if (space == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (space->session != session_id) return XR_ERROR_VALIDATION_FAILURE;
  if (layer.viewCount != kViewCount || layer.views == nullptr) return XR_ERROR_VALIDATION_FAILURE;
  for (uint32_t v = 0; v < layer.viewCount; ++v) {
    const XrCompositionLayerProjectionView& view = layer.views[v];
    if (view.type != XR_TYPE_COMPOSITION_LAYER_PROJECTION_VIEW) return XR_ERROR_VALIDATION_FAILURE;
    if (!is_valid_pose(view.pose)) return XR_ERROR_POSE_INVALID;
    const XrSwapchainSubImage& sub = view.subImage;
    const SwapchainState* swapchain = find(reg.swapchains, id_of(sub.swapchain));
    if (swapchain == nullptr) return XR_ERROR_HANDLE_INVALID;
    if (swapchain->session != session_id) return XR_ERROR_VALIDATION_FAILURE;
    // The image shown is the last one released; none may still be held.
    if (!swapchain->last_released || swapchain->acquired) return XR_ERROR_LAYER_INVALID;
    const XrRect2Di& r = sub.imageRect;
    if (r.offset.x < 0 || r.offset.y < 0 || r.extent.width <= 0 || r.extent.height <= 0 ||
        int64_t{r.offset.x} + r.extent.width > int64_t{swapchain->width} ||
        int64_t{r.offset.y} + r.extent.height > int64_t{swapchain->height}) {
      return XR_ERROR_SWAPCHAIN_RECT_INVALID;
    }
    if (sub.imageArrayIndex >= swapchain->array_size) return XR_ERROR_VALIDATION_FAILURE;
  }
  return XR_SUCCESS;
}

// Copies each view's imageRect of its swapchain's last released image to
// <capture_dir>/frame_NNNN_view_V.png (NNNN: this xrEndFrame's index in the
// session, from 0). The app left the images in COLOR_ATTACHMENT_OPTIMAL; they
// go to TRANSFER_SRC_OPTIMAL for the copy and back. Callers hold the registry
// mutex and checked the layer.
XrResult capture_projection(Registry& reg, const SessionState& session, const XrCompositionLayerProjection& layer) {
  VulkanSession& vk = *session.vulkan;
  struct Region {
    VkImage image;
    VkFormat format;
    XrRect2Di rect;
    uint32_t array_layer;
    VkDeviceSize offset;
  };
  std::vector<Region> regions;
  std::vector<VkImage> images;  // each once: one layout transition per image
  VkDeviceSize total = 0;
  for (uint32_t v = 0; v < layer.viewCount; ++v) {
    const XrSwapchainSubImage& sub = layer.views[v].subImage;
    const SwapchainState& swapchain = reg.swapchains.at(id_of(sub.swapchain));
    const VkImage image = swapchain.images[*swapchain.last_released];
    regions.push_back({image, swapchain.format, sub.imageRect, sub.imageArrayIndex, total});
    total += VkDeviceSize{4} * static_cast<uint32_t>(sub.imageRect.extent.width) *
             static_cast<uint32_t>(sub.imageRect.extent.height);
    if (std::find(images.begin(), images.end(), image) == images.end()) images.push_back(image);
  }
  ensure_staging(vk, total);

  submit_and_wait(vk, [&](VkCommandBuffer commands) {
    const VkDeviceFunctions& f = vk.vkd;
    std::vector<VkImageMemoryBarrier> barriers;
    for (VkImage image : images) {
      barriers.push_back(image_barrier(image, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL,
                                       VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, VK_ACCESS_MEMORY_WRITE_BIT,
                                       VK_ACCESS_TRANSFER_READ_BIT));
    }
    f.vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, nullptr,
                           0, nullptr, static_cast<uint32_t>(barriers.size()), barriers.data());
    for (const Region& region : regions) {
      VkBufferImageCopy copy{};
      copy.bufferOffset = region.offset;
      copy.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, region.array_layer, 1};
      copy.imageOffset = {region.rect.offset.x, region.rect.offset.y, 0};
      copy.imageExtent = {static_cast<uint32_t>(region.rect.extent.width),
                          static_cast<uint32_t>(region.rect.extent.height), 1};
      f.vkCmdCopyImageToBuffer(commands, region.image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, vk.staging, 1, &copy);
    }
    barriers.clear();
    for (VkImage image : images) {
      barriers.push_back(image_barrier(image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL,
                                       VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL, 0,
                                       VK_ACCESS_MEMORY_READ_BIT | VK_ACCESS_MEMORY_WRITE_BIT));
    }
    VkBufferMemoryBarrier to_host{};
    to_host.sType = VK_STRUCTURE_TYPE_BUFFER_MEMORY_BARRIER;
    to_host.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    to_host.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    to_host.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    to_host.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    to_host.buffer = vk.staging;
    to_host.offset = 0;
    to_host.size = VK_WHOLE_SIZE;
    f.vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT,
                           VK_PIPELINE_STAGE_ALL_COMMANDS_BIT | VK_PIPELINE_STAGE_HOST_BIT, 0, 0, nullptr, 1, &to_host,
                           static_cast<uint32_t>(barriers.size()), barriers.data());
  });

  std::error_code ec;
  std::filesystem::create_directories(session.capture_dir, ec);
  if (ec) {
    warn("capture: cannot create %s: %s", session.capture_dir.c_str(), ec.message().c_str());
    return XR_ERROR_RUNTIME_FAILURE;
  }
  std::vector<unsigned char> rgba;
  for (uint32_t v = 0; v < regions.size(); ++v) {
    const Region& region = regions[v];
    const int w = region.rect.extent.width, h = region.rect.extent.height;
    const auto* pixels = static_cast<const unsigned char*>(vk.staging_data) + region.offset;
    rgba.assign(pixels, pixels + std::size_t{4} * static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
    if (region.format == VK_FORMAT_B8G8R8A8_SRGB) {
      for (std::size_t i = 0; i < rgba.size(); i += 4) std::swap(rgba[i], rgba[i + 2]);
    }
    char name[64];
    std::snprintf(name, sizeof name, "frame_%04llu_view_%u.png",
                  static_cast<unsigned long long>(session.frames_ended - 1), v);
    const std::string path = (std::filesystem::path(session.capture_dir) / name).string();
    if (stbi_write_png(path.c_str(), w, h, 4, rgba.data(), w * 4) == 0) {
      warn("capture: cannot write %s", path.c_str());
      return XR_ERROR_RUNTIME_FAILURE;
    }
  }
  return XR_SUCCESS;
}

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
      case Ext::vulkan_enable2:
        state.vulkan_enable2 = true;
        break;
      case Ext::vive_tracker:
        state.vive_tracker = true;
        break;
      case Ext::none:
        break;
    }
  }
  state.devices = read_device_config();

  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t id = reg.next_id++;
  InstanceState& created = reg.instances.emplace(id, std::move(state)).first->second;
  refresh_trackers(created, mx::xr_time_now());  // connected events point into `created`
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
  std::erase_if(reg.actions, [&](const auto& kv) { return kv.second.instance == id; });
  std::erase_if(reg.action_sets, [&](const auto& kv) { return kv.second.instance == id; });
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
  refresh_trackers(*state, mx::xr_time_now());
  if (state->events.empty()) return XR_EVENT_UNAVAILABLE;
  // The buffer is a union-like 4000 bytes; the event is copied over its start.
  std::visit(
      [&](const auto& event) {
        static_assert(sizeof event <= sizeof(XrEventDataBuffer));
        std::memcpy(static_cast<void*>(event_data), &event, sizeof event);
      },
      state->events.front());
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
  InstanceState* state = find(reg.instances, instance_id);
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || session == nullptr || info->type != XR_TYPE_SESSION_CREATE_INFO || info->createFlags != 0) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (info->systemId != kSystemId) return XR_ERROR_SYSTEM_INVALID;
  // A Vulkan binding when XR_KHR_vulkan_enable2 is enabled; else headless
  // (XR_MND_headless, no binding at all). Any other binding names a graphics
  // device this runtime does not have.
  const XrGraphicsBindingVulkanKHR* vulkan_binding = state->vulkan_enable2 ? find_vulkan_binding(info->next) : nullptr;
  std::shared_ptr<VulkanSession> vulkan;
  if (vulkan_binding != nullptr) {
    // A second binding of another API as well is not a Vulkan session.
    if (chain_has_graphics_binding(info->next, XR_TYPE_GRAPHICS_BINDING_VULKAN_KHR)) {
      return XR_ERROR_GRAPHICS_DEVICE_INVALID;
    }
    if (!state->vulkan_requirements_queried) return XR_ERROR_GRAPHICS_REQUIREMENTS_CALL_MISSING;
    if (const XrResult r = create_vulkan_session(*state, *vulkan_binding, vulkan); XR_FAILED(r)) return r;
  } else if (!state->headless || chain_has_graphics_binding(info->next)) {
    return XR_ERROR_GRAPHICS_DEVICE_INVALID;
  }

  SessionState session_state;
  session_state.instance = instance_id;
  session_state.vulkan = std::move(vulkan);
  session_state.exit_after_frames = env_uint("PROPRIO_MOCK_RUNTIME_EXIT_AFTER_FRAMES", 0).value_or(0);
  session_state.unfocus_after_frames = env_uint("PROPRIO_MOCK_RUNTIME_UNFOCUS_AFTER_FRAMES", 0);
  session_state.monado_headless =
      session_state.vulkan == nullptr && env_is_one("PROPRIO_MOCK_RUNTIME_MONADO_HEADLESS");
  if (const char* dir = std::getenv("PROPRIO_MOCK_RUNTIME_CAPTURE_DIR")) session_state.capture_dir = dir;
  session_state.capture_frames =
      env_uint("PROPRIO_MOCK_RUNTIME_CAPTURE_FRAMES", kDefaultCaptureFrames).value_or(kDefaultCaptureFrames);
  session_state.hand_tracking =
      hand_tracking_mode() == HandTrackingMode::moving ? HandTrackingMode::moving : HandTrackingMode::fixed;
  state->devices = read_device_config();
  refresh_trackers(*state, mx::xr_time_now());
  const uint64_t id = reg.next_id++;
  reg.sessions.emplace(id, std::move(session_state));
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
  reg.spaces.emplace(id, SpaceState{session_id, info->referenceSpaceType, info->poseInReferenceSpace, 0, {}});
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

// Action spaces are located only while tracked (see space_in_local); an
// untracked space, or base, gives no flags at all.
XrResult xrLocateSpace(XrSpace space, XrSpace base_space, XrTime time, XrSpaceLocation* location) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const SpaceState* a = find(reg.spaces, id_of(space));
  const SpaceState* b = find(reg.spaces, id_of(base_space));
  if (a == nullptr || b == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (a->session != b->session) return XR_ERROR_VALIDATION_FAILURE;  // must share a session
  if (location == nullptr || location->type != XR_TYPE_SPACE_LOCATION) return XR_ERROR_VALIDATION_FAILURE;
  if (time <= 0) return XR_ERROR_TIME_INVALID;

  const std::optional<mx::Motion> a_local = space_in_local(reg, *a, time);
  const std::optional<mx::Motion> b_local = space_in_local(reg, *b, time);
  const bool tracked = a_local && b_local;
  const mx::Located located = tracked ? mx::to_xr(mx::relative_motion(*a_local, *b_local)) : mx::Located{};
  location->locationFlags = tracked ? kAllLocationFlags : 0;
  location->pose = tracked ? located.pose : mx::kIdentityPose;
  for (auto* s = static_cast<XrBaseOutStructure*>(location->next); s != nullptr; s = s->next) {
    if (s->type == XR_TYPE_SPACE_VELOCITY) {
      auto* velocity = reinterpret_cast<XrSpaceVelocity*>(s);
      velocity->velocityFlags =
          tracked ? XR_SPACE_VELOCITY_LINEAR_VALID_BIT | XR_SPACE_VELOCITY_ANGULAR_VALID_BIT : 0;
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
  if (state->vulkan && info->primaryViewConfigurationType != XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO) {
    return XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED;
  }
  if (state->running) return XR_ERROR_SESSION_RUNNING;
  if (state->state != XR_SESSION_STATE_READY) return XR_ERROR_SESSION_NOT_READY;
  state->running = true;
  state->frame_waited = state->frame_begun = false;
  push_state(reg, id_of(session), XR_SESSION_STATE_SYNCHRONIZED);
  push_state(reg, id_of(session), XR_SESSION_STATE_VISIBLE);
  if (state->unfocus_after_frames != std::optional<uint32_t>(0)) push_state(reg, id_of(session), XR_SESSION_STATE_FOCUSED);
  return XR_SUCCESS;
}

// For a running session; callers hold the registry mutex.
void request_exit_locked(Registry& reg, uint64_t session_id) {
  const SessionState& state = reg.sessions.at(session_id);
  if (state.state == XR_SESSION_STATE_STOPPING) return;  // already on its way out
  // Step down the lifecycle as a real runtime does: FOCUSED -> VISIBLE -> SYNCHRONIZED -> STOPPING.
  if (state.state == XR_SESSION_STATE_FOCUSED) push_state(reg, session_id, XR_SESSION_STATE_VISIBLE);
  if (state.state == XR_SESSION_STATE_VISIBLE) push_state(reg, session_id, XR_SESSION_STATE_SYNCHRONIZED);
  push_state(reg, session_id, XR_SESSION_STATE_STOPPING);
}

XrResult xrRequestExitSession(XrSession session) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (!state->running) return XR_ERROR_SESSION_NOT_RUNNING;
  request_exit_locked(reg, id_of(session));
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
    if (state->monado_headless) {
      // Monado's headless session has no compositor: xrWaitFrame returns at
      // once without starting a frame (no display time, shouldRender false),
      // so the xrBeginFrame that follows fails with XR_ERROR_CALL_ORDER_INVALID
      // (frame_waited stays false) and so does xrEndFrame.
      frame_state->predictedDisplayTime = 0;
      frame_state->predictedDisplayPeriod = 0;
      frame_state->shouldRender = XR_FALSE;
      return XR_SUCCESS;
    }
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
  if (info->layerCount > 0 && state->vulkan == nullptr) return XR_ERROR_LAYER_INVALID;
  const uint64_t session_id = id_of(session);
  const XrCompositionLayerProjection* first_projection = nullptr;
  for (uint32_t i = 0; i < info->layerCount; ++i) {
    const XrCompositionLayerBaseHeader* layer = info->layers[i];
    if (layer == nullptr || layer->type != XR_TYPE_COMPOSITION_LAYER_PROJECTION) return XR_ERROR_LAYER_INVALID;
    const auto* projection = reinterpret_cast<const XrCompositionLayerProjection*>(layer);
    if (const XrResult r = check_projection_layer(reg, session_id, *projection); XR_FAILED(r)) return r;
    if (first_projection == nullptr) first_projection = projection;
  }
  state->frame_begun = false;
  ++state->frames_ended;
  state->projection_layers += info->layerCount;
  if (state->unfocus_after_frames && state->frames_ended == *state->unfocus_after_frames &&
      state->state == XR_SESSION_STATE_FOCUSED) {
    push_state(reg, session_id, XR_SESSION_STATE_VISIBLE);
  }
  if (state->exit_after_frames != 0 && state->frames_ended >= state->exit_after_frames) {
    request_exit_locked(reg, session_id);
  }
  if (first_projection != nullptr && !state->capture_dir.empty() &&
      (state->capture_frames == 0 || state->frames_captured < state->capture_frames)) {
    ++state->frames_captured;
    return capture_projection(reg, *state, *first_projection);
  }
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
  *path = intern_path(*state, text);
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

// ---- views: PRIMARY_STEREO ----
XrResult check_system(XrInstance instance, XrSystemId system_id) {
  if (!instance_exists(instance)) return XR_ERROR_HANDLE_INVALID;
  return system_id == kSystemId ? XR_SUCCESS : XR_ERROR_SYSTEM_INVALID;
}

XrResult xrEnumerateViewConfigurations(XrInstance instance, XrSystemId system_id, uint32_t capacity, uint32_t* count,
                                       XrViewConfigurationType* types) {
  if (const XrResult r = check_system(instance, system_id); XR_FAILED(r)) return r;
  return two_call(capacity, count, types, 1, [](XrViewConfigurationType& t, uint32_t) {
    t = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
    return XR_SUCCESS;
  });
}

XrResult xrGetViewConfigurationProperties(XrInstance instance, XrSystemId system_id, XrViewConfigurationType type,
                                          XrViewConfigurationProperties* properties) {
  if (const XrResult r = check_system(instance, system_id); XR_FAILED(r)) return r;
  if (type != XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO) return XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED;
  if (properties == nullptr || properties->type != XR_TYPE_VIEW_CONFIGURATION_PROPERTIES) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  properties->viewConfigurationType = type;
  properties->fovMutable = XR_FALSE;
  return XR_SUCCESS;
}

XrResult xrEnumerateViewConfigurationViews(XrInstance instance, XrSystemId system_id, XrViewConfigurationType type,
                                           uint32_t capacity, uint32_t* count, XrViewConfigurationView* views) {
  if (const XrResult r = check_system(instance, system_id); XR_FAILED(r)) return r;
  if (type != XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO) return XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED;
  const XrExtent2Di size = view_size();
  return two_call(capacity, count, views, kViewCount, [&](XrViewConfigurationView& view, uint32_t) {
    if (view.type != XR_TYPE_VIEW_CONFIGURATION_VIEW) return XR_ERROR_VALIDATION_FAILURE;
    view.recommendedImageRectWidth = static_cast<uint32_t>(size.width);
    view.recommendedImageRectHeight = static_cast<uint32_t>(size.height);
    view.maxImageRectWidth = kMaxImageSize;
    view.maxImageRectHeight = kMaxImageSize;
    view.recommendedSwapchainSampleCount = 1;
    view.maxSwapchainSampleCount = 1;
    return XR_SUCCESS;
  });
}

// Each eye is the VIEW space moved -/+ kHalfIpdM along its own x axis. In an
// untracked action space the views have identity poses and no flags.
XrResult xrLocateViews(XrSession session, const XrViewLocateInfo* info, XrViewState* view_state, uint32_t capacity,
                       uint32_t* count, XrView* views) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  if (find(reg.sessions, id_of(session)) == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || info->type != XR_TYPE_VIEW_LOCATE_INFO) return XR_ERROR_VALIDATION_FAILURE;
  const SpaceState* space = find(reg.spaces, id_of(info->space));
  if (space == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (space->session != id_of(session)) return XR_ERROR_VALIDATION_FAILURE;
  if (info->viewConfigurationType != XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO) {
    return XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED;
  }
  if (view_state == nullptr || view_state->type != XR_TYPE_VIEW_STATE) return XR_ERROR_VALIDATION_FAILURE;
  if (info->displayTime <= 0) return XR_ERROR_TIME_INVALID;
  const std::optional<mx::Motion> base = space_in_local(reg, *space, info->displayTime);
  const XrResult result = two_call(capacity, count, views, kViewCount, [&](XrView& view, uint32_t i) {
    if (view.type != XR_TYPE_VIEW) return XR_ERROR_VALIDATION_FAILURE;
    XrPosef eye = mx::kIdentityPose;
    eye.position.x = i == 0 ? -kHalfIpdM : kHalfIpdM;
    const mx::Motion eye_in_local = mx::space_in_local(XR_REFERENCE_SPACE_TYPE_VIEW, eye, info->displayTime);
    view.pose = base ? mx::to_xr(mx::relative_motion(eye_in_local, *base).pose) : mx::kIdentityPose;
    view.fov = kFov;
    return XR_SUCCESS;
  });
  if (XR_SUCCEEDED(result)) {
    view_state->viewStateFlags = base ? XR_VIEW_STATE_ORIENTATION_VALID_BIT | XR_VIEW_STATE_POSITION_VALID_BIT |
                                            XR_VIEW_STATE_ORIENTATION_TRACKED_BIT | XR_VIEW_STATE_POSITION_TRACKED_BIT
                                      : 0;
  }
  return result;
}

// ---- swapchains (Vulkan sessions only) ----
XrResult xrEnumerateSwapchainFormats(XrSession session, uint32_t capacity, uint32_t* count, int64_t* formats) {
  bool vulkan = false;
  {
    Registry& reg = registry();
    std::lock_guard lock(reg.mutex);
    const SessionState* state = find(reg.sessions, id_of(session));
    if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
    vulkan = state->vulkan != nullptr;
  }
  // A headless session has no formats at all.
  const auto n = vulkan ? static_cast<uint32_t>(std::size(kSwapchainFormats)) : 0u;
  return two_call(capacity, count, formats, n, [](int64_t& format, uint32_t i) {
    format = kSwapchainFormats[i];
    return XR_SUCCESS;
  });
}

XrResult xrCreateSwapchain(XrSession session, const XrSwapchainCreateInfo* info, XrSwapchain* swapchain) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t session_id = id_of(session);
  const SessionState* state = find(reg.sessions, session_id);
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || swapchain == nullptr || info->type != XR_TYPE_SWAPCHAIN_CREATE_INFO) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (state->vulkan == nullptr) return XR_ERROR_SWAPCHAIN_FORMAT_UNSUPPORTED;  // headless: no formats
  constexpr XrSwapchainCreateFlags kKnownFlags =
      XR_SWAPCHAIN_CREATE_PROTECTED_CONTENT_BIT | XR_SWAPCHAIN_CREATE_STATIC_IMAGE_BIT;
  if ((info->createFlags & ~kKnownFlags) != 0) return XR_ERROR_VALIDATION_FAILURE;
  if (info->createFlags != 0) return XR_ERROR_FEATURE_UNSUPPORTED;  // neither protected nor static images
  if (std::find(std::begin(kSwapchainFormats), std::end(kSwapchainFormats), info->format) ==
      std::end(kSwapchainFormats)) {
    return XR_ERROR_SWAPCHAIN_FORMAT_UNSUPPORTED;
  }
  if (info->sampleCount == 0 || info->width == 0 || info->height == 0 || info->faceCount == 0 ||
      info->arraySize == 0 || info->mipCount == 0 || info->width > kMaxImageSize || info->height > kMaxImageSize) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (info->sampleCount != 1 || info->faceCount != 1) return XR_ERROR_FEATURE_UNSUPPORTED;

  // Usage: what the app asks for, plus what the runtime needs itself: colour
  // attachment (the layout it hands images over in), transfer dst (the fresh
  // image clear) and transfer src (capture).
  constexpr XrSwapchainUsageFlags kKnownUsage =
      XR_SWAPCHAIN_USAGE_COLOR_ATTACHMENT_BIT | XR_SWAPCHAIN_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT |
      XR_SWAPCHAIN_USAGE_UNORDERED_ACCESS_BIT | XR_SWAPCHAIN_USAGE_TRANSFER_SRC_BIT |
      XR_SWAPCHAIN_USAGE_TRANSFER_DST_BIT | XR_SWAPCHAIN_USAGE_SAMPLED_BIT | XR_SWAPCHAIN_USAGE_MUTABLE_FORMAT_BIT;
  if ((info->usageFlags & ~kKnownUsage) != 0) return XR_ERROR_VALIDATION_FAILURE;  // input attachment: not offered
  if (info->usageFlags & XR_SWAPCHAIN_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT) return XR_ERROR_FEATURE_UNSUPPORTED;
  VkImageUsageFlags usage =
      VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT;
  if (info->usageFlags & XR_SWAPCHAIN_USAGE_UNORDERED_ACCESS_BIT) usage |= VK_IMAGE_USAGE_STORAGE_BIT;
  if (info->usageFlags & XR_SWAPCHAIN_USAGE_SAMPLED_BIT) usage |= VK_IMAGE_USAGE_SAMPLED_BIT;
  const VkImageCreateFlags flags =
      (info->usageFlags & XR_SWAPCHAIN_USAGE_MUTABLE_FORMAT_BIT) ? VK_IMAGE_CREATE_MUTABLE_FORMAT_BIT : 0;

  VulkanSession& vk = *state->vulkan;
  const auto format = static_cast<VkFormat>(info->format);
  VkImageFormatProperties limits{};
  if (vk.vki.vkGetPhysicalDeviceImageFormatProperties(vk.physical_device, format, VK_IMAGE_TYPE_2D,
                                                      VK_IMAGE_TILING_OPTIMAL, usage, flags, &limits) != VK_SUCCESS ||
      info->arraySize > limits.maxArrayLayers || info->mipCount > limits.maxMipLevels) {
    return XR_ERROR_FEATURE_UNSUPPORTED;
  }

  SwapchainState created;
  created.session = session_id;
  created.format = format;
  created.width = info->width;
  created.height = info->height;
  created.array_size = info->arraySize;
  created.mip_count = info->mipCount;
  try {
    const VkDeviceFunctions& f = vk.vkd;
    for (uint32_t i = 0; i < kSwapchainImageCount; ++i) {
      VkImageCreateInfo image_info{};
      image_info.sType = VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO;
      image_info.flags = flags;
      image_info.imageType = VK_IMAGE_TYPE_2D;
      image_info.format = format;
      image_info.extent = {info->width, info->height, 1};
      image_info.mipLevels = info->mipCount;
      image_info.arrayLayers = info->arraySize;
      image_info.samples = VK_SAMPLE_COUNT_1_BIT;
      image_info.tiling = VK_IMAGE_TILING_OPTIMAL;
      image_info.usage = usage;
      image_info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
      image_info.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
      VkImage image = VK_NULL_HANDLE;
      check(f.vkCreateImage(vk.device, &image_info, nullptr, &image), "vkCreateImage");
      created.images.push_back(image);
      VkMemoryRequirements requirements{};
      f.vkGetImageMemoryRequirements(vk.device, image, &requirements);
      VkMemoryAllocateInfo allocate{};
      allocate.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
      allocate.allocationSize = requirements.size;
      allocate.memoryTypeIndex =
          memory_type(vk.memory, requirements.memoryTypeBits, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
      VkDeviceMemory memory = VK_NULL_HANDLE;
      check(f.vkAllocateMemory(vk.device, &allocate, nullptr, &memory), "vkAllocateMemory (swapchain)");
      created.memory.push_back(memory);
      check(f.vkBindImageMemory(vk.device, image, memory, 0), "vkBindImageMemory");
    }
    // Every image starts cleared to kFreshImageColour, in COLOR_ATTACHMENT_OPTIMAL.
    submit_and_wait(vk, [&](VkCommandBuffer commands) {
      std::vector<VkImageMemoryBarrier> barriers;
      for (VkImage image : created.images) {
        barriers.push_back(image_barrier(image, VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 0,
                                         VK_ACCESS_TRANSFER_WRITE_BIT));
      }
      f.vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0,
                             nullptr, 0, nullptr, static_cast<uint32_t>(barriers.size()), barriers.data());
      const VkImageSubresourceRange all{VK_IMAGE_ASPECT_COLOR_BIT, 0, VK_REMAINING_MIP_LEVELS, 0,
                                        VK_REMAINING_ARRAY_LAYERS};
      for (VkImage image : created.images) {
        f.vkCmdClearColorImage(commands, image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, &kFreshImageColour, 1, &all);
      }
      barriers.clear();
      for (VkImage image : created.images) {
        barriers.push_back(image_barrier(image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                                         VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL, VK_ACCESS_TRANSFER_WRITE_BIT,
                                         VK_ACCESS_MEMORY_READ_BIT | VK_ACCESS_MEMORY_WRITE_BIT));
      }
      f.vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 0, 0,
                             nullptr, 0, nullptr, static_cast<uint32_t>(barriers.size()), barriers.data());
    });
  } catch (...) {
    vk.vkd.vkDeviceWaitIdle(vk.device);
    destroy_swapchain_images(vk, created);
    throw;
  }
  const uint64_t id = reg.next_id++;
  reg.swapchains.emplace(id, std::move(created));
  *swapchain = to_handle<XrSwapchain>(id);
  return XR_SUCCESS;
}

XrResult xrDestroySwapchain(XrSwapchain swapchain) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  auto it = reg.swapchains.find(id_of(swapchain));
  if (it == reg.swapchains.end()) return XR_ERROR_HANDLE_INVALID;
  // Destroying a session takes its swapchains along, so the session exists.
  VulkanSession& vk = *reg.sessions.at(it->second.session).vulkan;
  vk.vkd.vkDeviceWaitIdle(vk.device);
  destroy_swapchain_images(vk, it->second);
  reg.swapchains.erase(it);
  return XR_SUCCESS;
}

XrResult xrEnumerateSwapchainImages(XrSwapchain swapchain, uint32_t capacity, uint32_t* count,
                                    XrSwapchainImageBaseHeader* images) {
  std::vector<VkImage> list;
  {
    Registry& reg = registry();
    std::lock_guard lock(reg.mutex);
    const SwapchainState* state = find(reg.swapchains, id_of(swapchain));
    if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
    list = state->images;
  }
  // Only Vulkan sessions have swapchains: the array is XrSwapchainImageVulkan(2)KHR.
  auto* vulkan_images = reinterpret_cast<XrSwapchainImageVulkanKHR*>(images);
  return two_call(capacity, count, vulkan_images, static_cast<uint32_t>(list.size()),
                  [&](XrSwapchainImageVulkanKHR& image, uint32_t i) {
                    if (image.type != XR_TYPE_SWAPCHAIN_IMAGE_VULKAN_KHR) return XR_ERROR_VALIDATION_FAILURE;
                    image.image = list[i];
                    return XR_SUCCESS;
                  });
}

// Round robin, one image at a time: acquiring again before releasing is a
// call-order error here (stricter than the spec, which allows several).
XrResult xrAcquireSwapchainImage(XrSwapchain swapchain, const XrSwapchainImageAcquireInfo* info, uint32_t* index) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  SwapchainState* state = find(reg.swapchains, id_of(swapchain));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if ((info != nullptr && info->type != XR_TYPE_SWAPCHAIN_IMAGE_ACQUIRE_INFO) || index == nullptr) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (state->acquired) return XR_ERROR_CALL_ORDER_INVALID;
  state->acquired = state->next;
  state->waited = false;
  state->next = (state->next + 1) % static_cast<uint32_t>(state->images.size());
  *index = *state->acquired;
  return XR_SUCCESS;
}

// The image is ready at once (nothing else uses it), whatever the timeout.
XrResult xrWaitSwapchainImage(XrSwapchain swapchain, const XrSwapchainImageWaitInfo* info) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  SwapchainState* state = find(reg.swapchains, id_of(swapchain));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || info->type != XR_TYPE_SWAPCHAIN_IMAGE_WAIT_INFO) return XR_ERROR_VALIDATION_FAILURE;
  if (!state->acquired || state->waited) return XR_ERROR_CALL_ORDER_INVALID;
  state->waited = true;
  return XR_SUCCESS;
}

XrResult xrReleaseSwapchainImage(XrSwapchain swapchain, const XrSwapchainImageReleaseInfo* info) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  SwapchainState* state = find(reg.swapchains, id_of(swapchain));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info != nullptr && info->type != XR_TYPE_SWAPCHAIN_IMAGE_RELEASE_INFO) return XR_ERROR_VALIDATION_FAILURE;
  if (!state->acquired || !state->waited) return XR_ERROR_CALL_ORDER_INVALID;
  state->last_released = state->acquired;
  state->acquired.reset();
  state->waited = false;
  return XR_SUCCESS;
}

// ---- XR_KHR_vulkan_enable2 ----
// The instance, if it exists and enabled the extension (else `error` says why).
InstanceState* vulkan_instance_state(Registry& reg, XrInstance instance, XrResult& error) {
  InstanceState* state = find(reg.instances, id_of(instance));
  error = state == nullptr ? XR_ERROR_HANDLE_INVALID
                           : (state->vulkan_enable2 ? XR_SUCCESS : XR_ERROR_FUNCTION_UNSUPPORTED);
  return XR_SUCCEEDED(error) ? state : nullptr;
}

XrResult xrGetVulkanGraphicsRequirements2KHR(XrInstance instance, XrSystemId system_id,
                                             XrGraphicsRequirementsVulkanKHR* requirements) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  XrResult error = XR_SUCCESS;
  InstanceState* state = vulkan_instance_state(reg, instance, error);
  if (state == nullptr) return error;
  if (system_id != kSystemId) return XR_ERROR_SYSTEM_INVALID;
  if (requirements == nullptr || requirements->type != XR_TYPE_GRAPHICS_REQUIREMENTS_VULKAN2_KHR) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  requirements->minApiVersionSupported = XR_MAKE_VERSION(1, 1, 0);
  requirements->maxApiVersionSupported = XR_MAKE_VERSION(1, 3, 0);
  state->vulkan_requirements_queried = true;
  return XR_SUCCESS;
}

// The VkResult goes to *vulkan_result; the XrResult is about the OpenXR side
// (XR_SUCCESS even when vkCreateInstance failed: check both).
XrResult xrCreateVulkanInstanceKHR(XrInstance instance, const XrVulkanInstanceCreateInfoKHR* info,
                                   VkInstance* vulkan_instance, VkResult* vulkan_result) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  XrResult error = XR_SUCCESS;
  InstanceState* state = vulkan_instance_state(reg, instance, error);
  if (state == nullptr) return error;
  if (info == nullptr || vulkan_instance == nullptr || vulkan_result == nullptr ||
      info->type != XR_TYPE_VULKAN_INSTANCE_CREATE_INFO_KHR || info->createFlags != 0 ||
      info->pfnGetInstanceProcAddr == nullptr || info->vulkanCreateInfo == nullptr) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (info->systemId != kSystemId) return XR_ERROR_SYSTEM_INVALID;
  auto create = reinterpret_cast<PFN_vkCreateInstance>(info->pfnGetInstanceProcAddr(VK_NULL_HANDLE, "vkCreateInstance"));
  if (create == nullptr) {
    warn("xrCreateVulkanInstanceKHR: pfnGetInstanceProcAddr has no vkCreateInstance");
    return XR_ERROR_RUNTIME_FAILURE;
  }
  *vulkan_result = create(info->vulkanCreateInfo, info->vulkanAllocator, vulkan_instance);
  if (*vulkan_result == VK_SUCCESS) state->vulkan_instances.push_back({*vulkan_instance, info->pfnGetInstanceProcAddr});
  return XR_SUCCESS;
}

// Lavapipe (a CPU device) when there is one, else the first device.
XrResult xrGetVulkanGraphicsDevice2KHR(XrInstance instance, const XrVulkanGraphicsDeviceGetInfoKHR* info,
                                       VkPhysicalDevice* physical_device) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  XrResult error = XR_SUCCESS;
  InstanceState* state = vulkan_instance_state(reg, instance, error);
  if (state == nullptr) return error;
  if (info == nullptr || physical_device == nullptr || info->type != XR_TYPE_VULKAN_GRAPHICS_DEVICE_GET_INFO_KHR) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (info->systemId != kSystemId) return XR_ERROR_SYSTEM_INVALID;
  const VulkanInstanceRecord* record = state->vulkan_instance(info->vulkanInstance);
  if (record == nullptr) {
    if (log_calls()) warn("xrGetVulkanGraphicsDevice2KHR: the VkInstance was not created with xrCreateVulkanInstanceKHR");
    return XR_ERROR_VALIDATION_FAILURE;
  }
  auto enumerate = reinterpret_cast<PFN_vkEnumeratePhysicalDevices>(
      record->get_instance_proc_addr(record->instance, "vkEnumeratePhysicalDevices"));
  auto properties_of = reinterpret_cast<PFN_vkGetPhysicalDeviceProperties>(
      record->get_instance_proc_addr(record->instance, "vkGetPhysicalDeviceProperties"));
  if (enumerate == nullptr || properties_of == nullptr) {
    warn("xrGetVulkanGraphicsDevice2KHR: vkGetInstanceProcAddr has no vkEnumeratePhysicalDevices");
    return XR_ERROR_RUNTIME_FAILURE;
  }
  uint32_t count = 0;
  check(enumerate(record->instance, &count, nullptr), "vkEnumeratePhysicalDevices");
  std::vector<VkPhysicalDevice> devices(count);
  const VkResult listed = enumerate(record->instance, &count, devices.data());
  if (listed != VK_INCOMPLETE) check(listed, "vkEnumeratePhysicalDevices");
  devices.resize(count);
  if (devices.empty()) {
    warn("xrGetVulkanGraphicsDevice2KHR: no Vulkan physical device");
    return XR_ERROR_RUNTIME_FAILURE;
  }
  VkPhysicalDevice chosen = devices.front();
  for (VkPhysicalDevice device : devices) {
    VkPhysicalDeviceProperties properties{};
    properties_of(device, &properties);
    if (properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU) {
      chosen = device;
      break;
    }
  }
  state->graphics_device_instance = record->instance;
  state->graphics_device = chosen;
  *physical_device = chosen;
  return XR_SUCCESS;
}

// Like xrCreateVulkanInstanceKHR: the VkResult goes to *vulkan_result.
XrResult xrCreateVulkanDeviceKHR(XrInstance instance, const XrVulkanDeviceCreateInfoKHR* info, VkDevice* vulkan_device,
                                 VkResult* vulkan_result) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  XrResult error = XR_SUCCESS;
  InstanceState* state = vulkan_instance_state(reg, instance, error);
  if (state == nullptr) return error;
  if (info == nullptr || vulkan_device == nullptr || vulkan_result == nullptr ||
      info->type != XR_TYPE_VULKAN_DEVICE_CREATE_INFO_KHR || info->createFlags != 0 ||
      info->pfnGetInstanceProcAddr == nullptr || info->vulkanCreateInfo == nullptr) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (info->systemId != kSystemId) return XR_ERROR_SYSTEM_INVALID;
  if (info->vulkanPhysicalDevice == VK_NULL_HANDLE || info->vulkanPhysicalDevice != state->graphics_device) {
    if (log_calls())
      warn("xrCreateVulkanDeviceKHR: the VkPhysicalDevice is not what xrGetVulkanGraphicsDevice2KHR returned");
    return XR_ERROR_GRAPHICS_DEVICE_INVALID;
  }
  const VkInstance vk_instance = state->graphics_device_instance;
  auto create =
      reinterpret_cast<PFN_vkCreateDevice>(info->pfnGetInstanceProcAddr(vk_instance, "vkCreateDevice"));
  if (create == nullptr) {
    warn("xrCreateVulkanDeviceKHR: pfnGetInstanceProcAddr has no vkCreateDevice");
    return XR_ERROR_RUNTIME_FAILURE;
  }
  const VkDeviceCreateInfo& create_info = *info->vulkanCreateInfo;
  *vulkan_result = create(info->vulkanPhysicalDevice, &create_info, info->vulkanAllocator, vulkan_device);
  if (*vulkan_result == VK_SUCCESS) {
    VulkanDeviceRecord record{*vulkan_device, vk_instance, info->vulkanPhysicalDevice, {}};
    for (uint32_t i = 0; i < create_info.queueCreateInfoCount && create_info.pQueueCreateInfos != nullptr; ++i) {
      const VkDeviceQueueCreateInfo& queue = create_info.pQueueCreateInfos[i];
      record.queues.emplace_back(queue.queueFamilyIndex, queue.queueCount);
    }
    state->vulkan_devices.push_back(std::move(record));
  }
  return XR_SUCCESS;
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
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const HandTrackerState* tracker = find(reg.hand_trackers, id_of(hand_tracker));
  if (tracker == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || info->type != XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT) return XR_ERROR_VALIDATION_FAILURE;
  const SpaceState* base = find(reg.spaces, id_of(info->baseSpace));
  if (base == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (base->session != tracker->session) return XR_ERROR_VALIDATION_FAILURE;
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
  constexpr XrSpaceVelocityFlags kBothVelocities =
      XR_SPACE_VELOCITY_LINEAR_VALID_BIT | XR_SPACE_VELOCITY_ANGULAR_VALID_BIT;

  if (reg.sessions.at(tracker->session).hand_tracking == HandTrackingMode::fixed) {
    // The fixed, recognisable native pose (mock_motion.hpp), whatever the base space.
    locations->isActive = XR_TRUE;
    for (uint32_t i = 0; i < XR_HAND_JOINT_COUNT_EXT; ++i) {
      XrHandJointLocationEXT& joint = locations->jointLocations[i];
      joint.locationFlags = kAllLocationFlags;
      joint.pose = {{0.0f, 0.0f, 0.0f, 1.0f}, mx::kNativeJointPosition};
      joint.radius = mx::kNativeJointRadius;
      if (velocities != nullptr) {
        XrHandJointVelocityEXT& v = velocities->jointVelocities[i];
        v.velocityFlags = kBothVelocities;
        v.linearVelocity = {0.0f, 0.0f, 0.0f};
        v.angularVelocity = {0.0f, 0.0f, 0.0f};
      }
    }
    return XR_SUCCESS;
  }

  // "moving": the analytic hand, lost during its window (or in an untracked base).
  const mx::Hand hand = tracker->hand == XR_HAND_LEFT_EXT ? mx::Hand::left : mx::Hand::right;
  const std::optional<mx::Motion> base_in_local = space_in_local(reg, *base, info->time);
  const bool active = base_in_local && mx::native_hand_tracked(hand, info->time);
  locations->isActive = active ? XR_TRUE : XR_FALSE;
  for (uint32_t i = 0; i < XR_HAND_JOINT_COUNT_EXT; ++i) {
    XrHandJointLocationEXT& joint = locations->jointLocations[i];
    XrHandJointVelocityEXT* velocity = velocities != nullptr ? &velocities->jointVelocities[i] : nullptr;
    if (!active) {
      joint.locationFlags = 0;
      joint.pose = mx::kIdentityPose;
      joint.radius = 0.0f;
      if (velocity != nullptr) *velocity = {0, {0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.0f}};
      continue;
    }
    const mx::Located located = mx::to_xr(
        mx::relative_motion(mx::native_joint(hand, static_cast<XrHandJointEXT>(i), info->time), *base_in_local));
    joint.locationFlags = kAllLocationFlags;
    joint.pose = located.pose;
    joint.radius = static_cast<float>(mx::kNativeJointsRight[i].radius);
    if (velocity != nullptr) *velocity = {kBothVelocities, located.linear_velocity, located.angular_velocity};
  }
  return XR_SUCCESS;
}

// ---- actions ----
// A name in a fixed-size array; nullopt when it is not NUL-terminated there.
std::optional<std::string_view> fixed_string(const char* array, std::size_t size) {
  const std::size_t n = strnlen(array, size);
  if (n == size) return std::nullopt;
  return std::string_view(array, n);
}

// Action and action set names must be well-formed path components.
bool is_valid_name(std::string_view name) {
  return !name.empty() && name.find('/') == std::string_view::npos && is_well_formed_path("/" + std::string(name));
}

bool is_known_top_level(const InstanceState& state, std::string_view path) {
  for (std::string_view top : kHandPaths) {
    if (path == top) return true;
  }
  for (std::string_view top : kOtherTopLevelPaths) {
    if (path == top) return true;
  }
  if (state.vive_tracker) {
    for (std::string_view top : kTrackerRolePaths) {
      if (path == top) return true;
    }
  }
  return false;
}

// The interaction profile an instance may use, by path.
const Profile* find_profile(const InstanceState& state, std::string_view path) {
  for (const Profile& profile : kProfiles) {
    if (profile.path == path && state.enabled(profile.ext)) return &profile;
  }
  return nullptr;
}

XrResult xrCreateActionSet(XrInstance instance, const XrActionSetCreateInfo* info, XrActionSet* action_set) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t instance_id = id_of(instance);
  if (find(reg.instances, instance_id) == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || action_set == nullptr || info->type != XR_TYPE_ACTION_SET_CREATE_INFO) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  const auto name = fixed_string(info->actionSetName, XR_MAX_ACTION_SET_NAME_SIZE);
  const auto localized = fixed_string(info->localizedActionSetName, XR_MAX_LOCALIZED_ACTION_SET_NAME_SIZE);
  if (!name || !localized) return XR_ERROR_VALIDATION_FAILURE;
  if (!is_valid_name(*name)) return XR_ERROR_NAME_INVALID;
  if (localized->empty()) return XR_ERROR_LOCALIZED_NAME_INVALID;
  for (const auto& [id, set] : reg.action_sets) {
    if (set.instance != instance_id) continue;
    if (set.name == *name) return XR_ERROR_NAME_DUPLICATED;
    if (set.localized_name == *localized) return XR_ERROR_LOCALIZED_NAME_DUPLICATED;
  }
  const uint64_t id = reg.next_id++;
  reg.action_sets.emplace(id, ActionSetRecord{instance_id, std::string(*name), std::string(*localized),
                                              info->priority, false});
  *action_set = to_handle<XrActionSet>(id);
  return XR_SUCCESS;
}

// Its actions go with it. Sessions keep what they attached, and action spaces
// keep working, as the spec asks.
XrResult xrDestroyActionSet(XrActionSet action_set) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t id = id_of(action_set);
  if (reg.action_sets.erase(id) != 1) return XR_ERROR_HANDLE_INVALID;
  std::erase_if(reg.actions, [&](const auto& kv) { return kv.second.set == id; });
  return XR_SUCCESS;
}

XrResult xrCreateAction(XrActionSet action_set, const XrActionCreateInfo* info, XrAction* action) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t set_id = id_of(action_set);
  const ActionSetRecord* set = find(reg.action_sets, set_id);
  if (set == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || action == nullptr || info->type != XR_TYPE_ACTION_CREATE_INFO ||
      (info->countSubactionPaths > 0 && info->subactionPaths == nullptr)) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  switch (info->actionType) {
    case XR_ACTION_TYPE_BOOLEAN_INPUT:
    case XR_ACTION_TYPE_FLOAT_INPUT:
    case XR_ACTION_TYPE_VECTOR2F_INPUT:
    case XR_ACTION_TYPE_POSE_INPUT:
    case XR_ACTION_TYPE_VIBRATION_OUTPUT:
      break;
    default:
      return XR_ERROR_VALIDATION_FAILURE;
  }
  const auto name = fixed_string(info->actionName, XR_MAX_ACTION_NAME_SIZE);
  const auto localized = fixed_string(info->localizedActionName, XR_MAX_LOCALIZED_ACTION_NAME_SIZE);
  if (!name || !localized) return XR_ERROR_VALIDATION_FAILURE;
  if (set->attached) return XR_ERROR_ACTIONSETS_ALREADY_ATTACHED;
  if (!is_valid_name(*name)) return XR_ERROR_NAME_INVALID;
  if (localized->empty()) return XR_ERROR_LOCALIZED_NAME_INVALID;
  for (const auto& [id, other] : reg.actions) {
    if (other.set != set_id) continue;
    if (other.name == *name) return XR_ERROR_NAME_DUPLICATED;
    if (other.localized_name == *localized) return XR_ERROR_LOCALIZED_NAME_DUPLICATED;
  }
  const InstanceState& instance = reg.instances.at(set->instance);
  std::vector<std::string> subaction_paths;
  for (uint32_t i = 0; i < info->countSubactionPaths; ++i) {
    const auto path = path_string(instance, info->subactionPaths[i]);
    if (!path) return XR_ERROR_PATH_INVALID;
    if (!is_known_top_level(instance, *path)) return XR_ERROR_PATH_UNSUPPORTED;
    if (std::find(subaction_paths.begin(), subaction_paths.end(), *path) != subaction_paths.end()) {
      return XR_ERROR_PATH_UNSUPPORTED;  // listed twice
    }
    subaction_paths.emplace_back(*path);
  }
  const uint64_t id = reg.next_id++;
  reg.actions.emplace(id, ActionRecord{set->instance, set_id, std::string(*name), std::string(*localized),
                                       info->actionType, std::move(subaction_paths)});
  *action = to_handle<XrAction>(id);
  return XR_SUCCESS;
}

XrResult xrDestroyAction(XrAction action) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  return reg.actions.erase(id_of(action)) == 1 ? XR_SUCCESS : XR_ERROR_HANDLE_INVALID;
}

// Strict: only the profiles this runtime has devices for (the spec's other
// profiles are refused too), and a later call for a profile replaces its
// earlier suggestion. Bindings whose input does not suit the action's type
// are accepted and never bind (the spec defines no error for them).
XrResult xrSuggestInteractionProfileBindings(XrInstance instance, const XrInteractionProfileSuggestedBinding* info) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t instance_id = id_of(instance);
  InstanceState* state = find(reg.instances, instance_id);
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || info->type != XR_TYPE_INTERACTION_PROFILE_SUGGESTED_BINDING ||
      info->countSuggestedBindings == 0 || info->suggestedBindings == nullptr) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  const auto profile_path = path_string(*state, info->interactionProfile);
  if (!profile_path) return XR_ERROR_PATH_INVALID;
  const Profile* profile = find_profile(*state, *profile_path);
  if (profile == nullptr) return XR_ERROR_PATH_UNSUPPORTED;
  std::vector<SuggestedBinding> bindings;
  bool attached = false;
  for (uint32_t i = 0; i < info->countSuggestedBindings; ++i) {
    const XrActionSuggestedBinding& binding = info->suggestedBindings[i];
    const ActionRecord* action = find(reg.actions, id_of(binding.action));
    if (action == nullptr) return XR_ERROR_HANDLE_INVALID;
    if (action->instance != instance_id) return XR_ERROR_VALIDATION_FAILURE;
    const auto path = path_string(*state, binding.binding);
    if (!path) return XR_ERROR_PATH_INVALID;
    if (!split_binding(*profile, *path)) return XR_ERROR_PATH_UNSUPPORTED;
    attached |= reg.action_sets.at(action->set).attached;
    bindings.push_back({id_of(binding.action), std::string(*path)});
  }
  // The spec's rule: refused once the set of any action named was attached.
  if (attached) return XR_ERROR_ACTIONSETS_ALREADY_ATTACHED;
  state->suggestions.insert_or_assign(std::string(*profile_path), std::move(bindings));
  return XR_SUCCESS;
}

XrResult xrAttachSessionActionSets(XrSession session, const XrSessionActionSetsAttachInfo* info) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || info->type != XR_TYPE_SESSION_ACTION_SETS_ATTACH_INFO || info->countActionSets == 0 ||
      info->actionSets == nullptr) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  for (uint32_t i = 0; i < info->countActionSets; ++i) {
    const ActionSetRecord* set = find(reg.action_sets, id_of(info->actionSets[i]));
    if (set == nullptr) return XR_ERROR_HANDLE_INVALID;
    if (set->instance != state->instance) return XR_ERROR_VALIDATION_FAILURE;
  }
  if (state->attached) return XR_ERROR_ACTIONSETS_ALREADY_ATTACHED;

  const InstanceState& instance = reg.instances.at(state->instance);
  state->attached = true;
  for (uint32_t i = 0; i < info->countActionSets; ++i) {
    const uint64_t set_id = id_of(info->actionSets[i]);
    ActionSetRecord& set = reg.action_sets.at(set_id);
    set.attached = true;
    state->attached_sets.emplace(set_id, set.priority);
  }
  for (const auto& [action_id, record] : reg.actions) {
    const auto set = state->attached_sets.find(record.set);
    if (set == state->attached_sets.end()) continue;
    AttachedAction attached{record.set, set->second, record.type, record.subaction_paths, {}, {}};
    for (const auto& [profile_path, bindings] : instance.suggestions) {
      const Profile& profile = *find_profile(instance, profile_path);
      for (const SuggestedBinding& binding : bindings) {
        if (binding.action != action_id) continue;
        state->suggested_profiles.insert(profile_path);
        const BindingPath split = *split_binding(profile, binding.path);
        const InputSource* input = resolve_input(profile, split.subpath, record.type);
        if (input == nullptr) continue;
        attached.sources.push_back({profile.path, split.top_level, input->subpath, input->kind,
                                    std::string(split.top_level) + "/" + std::string(input->subpath),
                                    device_at(profile.path, split.top_level)});
      }
    }
    state->actions.emplace(action_id, std::move(attached));
  }
  return XR_SUCCESS;
}

// Input is sampled at the call's own time. A source is live when its set is
// active for its top-level path, the session is focused and its device is
// connected; a live source is dropped when an active set of higher priority
// binds the same input source. Then, per subaction path ("" for all): booleans
// OR, floats and vectors take the largest magnitude, poses the first source
// in suggestion order.
XrResult xrSyncActions(XrSession session, const XrActionsSyncInfo* info) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t session_id = id_of(session);
  SessionState* state = find(reg.sessions, session_id);
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || info->type != XR_TYPE_ACTIONS_SYNC_INFO ||
      (info->countActiveActionSets > 0 && info->activeActionSets == nullptr)) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  InstanceState& instance = reg.instances.at(state->instance);
  std::unordered_map<uint64_t, std::vector<std::string>> filters;  // set -> subaction paths ("" for all)
  for (uint32_t i = 0; i < info->countActiveActionSets; ++i) {
    const XrActiveActionSet& active = info->activeActionSets[i];
    const uint64_t set_id = id_of(active.actionSet);
    if (find(reg.action_sets, set_id) == nullptr) return XR_ERROR_HANDLE_INVALID;
    if (!state->attached_sets.contains(set_id)) return XR_ERROR_ACTIONSET_NOT_ATTACHED;
    std::string filter;
    if (active.subactionPath != XR_NULL_PATH) {
      const auto path = path_string(instance, active.subactionPath);
      if (!path) return XR_ERROR_PATH_INVALID;
      const bool declared = std::any_of(state->actions.begin(), state->actions.end(), [&](const auto& kv) {
        const AttachedAction& a = kv.second;
        return a.set == set_id &&
               std::find(a.subaction_paths.begin(), a.subaction_paths.end(), *path) != a.subaction_paths.end();
      });
      if (!declared) return XR_ERROR_PATH_UNSUPPORTED;
      filter = *path;
    }
    filters[set_id].push_back(std::move(filter));
  }

  const XrTime now = mx::xr_time_now();
  refresh_trackers(instance, now);
  const bool focused = state->state == XR_SESSION_STATE_FOCUSED;
  std::unordered_map<uint64_t, std::vector<bool>> live;
  std::map<std::string, uint32_t, std::less<>> top_priority;  // input source path -> highest live priority
  for (const auto& [action_id, action] : state->actions) {
    std::vector<bool>& flags = live[action_id];
    const auto filter = filters.find(action.set);
    for (const Source& source : action.sources) {
      const bool on = focused && filter != filters.end() &&
                      std::any_of(filter->second.begin(), filter->second.end(),
                                  [&](const std::string& f) { return f.empty() || f == source.top_level; }) &&
                      source.device && device_connected(instance, *source.device, now);
      flags.push_back(on);
      if (on) {
        auto [it, inserted] = top_priority.try_emplace(source.path, action.priority);
        if (!inserted) it->second = std::max(it->second, action.priority);
      }
    }
  }
  for (auto& [action_id, action] : state->actions) {
    std::vector<bool>& flags = live[action_id];
    for (std::size_t i = 0; i < flags.size(); ++i) {
      if (flags[i] && top_priority.at(action.sources[i].path) > action.priority) flags[i] = false;
    }
    std::vector<std::string> keys{""};
    keys.insert(keys.end(), action.subaction_paths.begin(), action.subaction_paths.end());
    for (const std::string& key : keys) {
      ActionValue& value = action.values[key];
      ActionValue next;
      for (std::size_t i = 0; i < flags.size(); ++i) {
        const Source& source = action.sources[i];
        if (!flags[i] || (!key.empty() && source.top_level != key)) continue;
        const float v = static_cast<float>(source_value(source, now));
        if (action.type == XR_ACTION_TYPE_BOOLEAN_INPUT) {
          if (v > 0.5f) next.x = 1.0f;
        } else if (std::abs(v) > std::abs(next.x)) {
          next.x = v;  // float; a vector2 source reads (0, 0)
        }
        if (action.type == XR_ACTION_TYPE_POSE_INPUT && !next.pose_source) next.pose_source = i;
        next.active = true;
      }
      if (next.active) {
        next.changed = next.x != value.x || next.y != value.y;
        next.last_change = next.changed ? now : value.last_change;
      }
      value = next;
    }
  }

  // The current profile of each device's top-level path; a change is announced.
  bool profiles_changed = false;
  for (const DeviceSlot& slot : kDeviceSlots) {
    const bool bound = device_connected(instance, slot.device, now) && state->suggested_profiles.contains(slot.profile);
    const std::string profile = bound ? std::string(slot.profile) : std::string();
    std::string& current = state->current_profiles[std::string(slot.top_level)];
    profiles_changed |= current != profile;
    current = profile;
  }
  if (profiles_changed) {
    XrEventDataInteractionProfileChanged event{};
    event.type = XR_TYPE_EVENT_DATA_INTERACTION_PROFILE_CHANGED;
    event.session = session;
    instance.events.push_back(event);
  }
  return focused ? XR_SUCCESS : XR_SESSION_NOT_FOCUSED;
}

XrResult xrGetCurrentInteractionProfile(XrSession session, XrPath top_level_user_path,
                                        XrInteractionProfileState* interaction_profile) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (interaction_profile == nullptr || interaction_profile->type != XR_TYPE_INTERACTION_PROFILE_STATE) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (!state->attached) return XR_ERROR_ACTIONSET_NOT_ATTACHED;
  InstanceState& instance = reg.instances.at(state->instance);
  const auto path = path_string(instance, top_level_user_path);
  if (!path) return XR_ERROR_PATH_INVALID;
  if (!is_known_top_level(instance, *path)) return XR_ERROR_PATH_UNSUPPORTED;
  const auto current = state->current_profiles.find(*path);
  interaction_profile->interactionProfile = current == state->current_profiles.end() || current->second.empty()
                                                ? XR_NULL_PATH
                                                : intern_path(instance, current->second);
  return XR_SUCCESS;
}

// The checks every call naming an action of a session shares; on success
// `out` is the session's attached action and `key` its subaction path.
XrResult attached_action(Registry& reg, const SessionState& session, XrAction action, XrPath subaction,
                         std::initializer_list<XrActionType> types, AttachedAction*& out, std::string& key) {
  const uint64_t action_id = id_of(action);
  const ActionRecord* record = find(reg.actions, action_id);
  if (record == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (record->instance != session.instance) return XR_ERROR_VALIDATION_FAILURE;
  if (std::find(types.begin(), types.end(), record->type) == types.end()) return XR_ERROR_ACTION_TYPE_MISMATCH;
  if (!session.attached_sets.contains(record->set)) return XR_ERROR_ACTIONSET_NOT_ATTACHED;
  key.clear();
  if (subaction != XR_NULL_PATH) {
    const auto path = path_string(reg.instances.at(session.instance), subaction);
    if (!path) return XR_ERROR_PATH_INVALID;
    if (std::find(record->subaction_paths.begin(), record->subaction_paths.end(), *path) ==
        record->subaction_paths.end()) {
      return XR_ERROR_PATH_UNSUPPORTED;
    }
    key = *path;
  }
  out = &const_cast<SessionState&>(session).actions.at(action_id);
  return XR_SUCCESS;
}

// The state of the last sync (all zero before the first one).
template <class State, class Fill>
XrResult get_action_state(XrSession session, const XrActionStateGetInfo* info, State* out, XrStructureType type,
                          XrActionType action_type, Fill fill) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || info->type != XR_TYPE_ACTION_STATE_GET_INFO || out == nullptr || out->type != type) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  AttachedAction* action = nullptr;
  std::string key;
  if (const XrResult r = attached_action(reg, *state, info->action, info->subactionPath, {action_type}, action, key);
      XR_FAILED(r)) {
    return r;
  }
  const auto value = action->values.find(key);
  fill(*out, value == action->values.end() ? ActionValue{} : value->second);
  return XR_SUCCESS;
}

XrResult xrGetActionStateBoolean(XrSession session, const XrActionStateGetInfo* info, XrActionStateBoolean* state) {
  return get_action_state(session, info, state, XR_TYPE_ACTION_STATE_BOOLEAN, XR_ACTION_TYPE_BOOLEAN_INPUT,
                          [](XrActionStateBoolean& s, const ActionValue& v) {
                            s.currentState = v.x != 0.0f ? XR_TRUE : XR_FALSE;
                            s.changedSinceLastSync = v.changed ? XR_TRUE : XR_FALSE;
                            s.lastChangeTime = v.last_change;
                            s.isActive = v.active ? XR_TRUE : XR_FALSE;
                          });
}

XrResult xrGetActionStateFloat(XrSession session, const XrActionStateGetInfo* info, XrActionStateFloat* state) {
  return get_action_state(session, info, state, XR_TYPE_ACTION_STATE_FLOAT, XR_ACTION_TYPE_FLOAT_INPUT,
                          [](XrActionStateFloat& s, const ActionValue& v) {
                            s.currentState = v.x;
                            s.changedSinceLastSync = v.changed ? XR_TRUE : XR_FALSE;
                            s.lastChangeTime = v.last_change;
                            s.isActive = v.active ? XR_TRUE : XR_FALSE;
                          });
}

XrResult xrGetActionStateVector2f(XrSession session, const XrActionStateGetInfo* info,
                                  XrActionStateVector2f* state) {
  return get_action_state(session, info, state, XR_TYPE_ACTION_STATE_VECTOR2F, XR_ACTION_TYPE_VECTOR2F_INPUT,
                          [](XrActionStateVector2f& s, const ActionValue& v) {
                            s.currentState = {v.x, v.y};
                            s.changedSinceLastSync = v.changed ? XR_TRUE : XR_FALSE;
                            s.lastChangeTime = v.last_change;
                            s.isActive = v.active ? XR_TRUE : XR_FALSE;
                          });
}

XrResult xrGetActionStatePose(XrSession session, const XrActionStateGetInfo* info, XrActionStatePose* state) {
  return get_action_state(
      session, info, state, XR_TYPE_ACTION_STATE_POSE, XR_ACTION_TYPE_POSE_INPUT,
      [](XrActionStatePose& s, const ActionValue& v) { s.isActive = v.active ? XR_TRUE : XR_FALSE; });
}

// Allowed before xrAttachSessionActionSets; the space is tracked only while
// its action has an active pose binding (xrSyncActions) on a connected device.
XrResult xrCreateActionSpace(XrSession session, const XrActionSpaceCreateInfo* info, XrSpace* space) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const uint64_t session_id = id_of(session);
  const SessionState* state = find(reg.sessions, session_id);
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || space == nullptr || info->type != XR_TYPE_ACTION_SPACE_CREATE_INFO) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  const ActionRecord* action = find(reg.actions, id_of(info->action));
  if (action == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (action->instance != state->instance) return XR_ERROR_VALIDATION_FAILURE;
  if (action->type != XR_ACTION_TYPE_POSE_INPUT) return XR_ERROR_ACTION_TYPE_MISMATCH;
  std::string subaction;
  if (info->subactionPath != XR_NULL_PATH) {
    const auto path = path_string(reg.instances.at(state->instance), info->subactionPath);
    if (!path) return XR_ERROR_PATH_INVALID;
    if (std::find(action->subaction_paths.begin(), action->subaction_paths.end(), *path) ==
        action->subaction_paths.end()) {
      return XR_ERROR_PATH_UNSUPPORTED;
    }
    subaction = *path;
  }
  if (!is_valid_pose(info->poseInActionSpace)) return XR_ERROR_POSE_INVALID;
  const uint64_t id = reg.next_id++;
  reg.spaces.emplace(id, SpaceState{session_id, XR_REFERENCE_SPACE_TYPE_LOCAL, info->poseInActionSpace,
                                    id_of(info->action), std::move(subaction)});
  *space = to_handle<XrSpace>(id);
  return XR_SUCCESS;
}

// The action's sources in the current interaction profiles (as of the last sync).
XrResult xrEnumerateBoundSourcesForAction(XrSession session, const XrBoundSourcesForActionEnumerateInfo* info,
                                          uint32_t capacity, uint32_t* count, XrPath* sources) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || info->type != XR_TYPE_BOUND_SOURCES_FOR_ACTION_ENUMERATE_INFO) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  AttachedAction* action = nullptr;
  std::string key;
  static constexpr std::initializer_list<XrActionType> kAnyType{
      XR_ACTION_TYPE_BOOLEAN_INPUT, XR_ACTION_TYPE_FLOAT_INPUT, XR_ACTION_TYPE_VECTOR2F_INPUT,
      XR_ACTION_TYPE_POSE_INPUT, XR_ACTION_TYPE_VIBRATION_OUTPUT};
  if (const XrResult r = attached_action(reg, *state, info->action, XR_NULL_PATH, kAnyType, action, key);
      XR_FAILED(r)) {
    return r;
  }
  InstanceState& instance = reg.instances.at(state->instance);
  std::vector<XrPath> bound;
  for (const Source& source : action->sources) {
    const auto current = state->current_profiles.find(source.top_level);
    if (current == state->current_profiles.end() || current->second != source.profile) continue;
    const XrPath path = intern_path(instance, source.path);
    if (std::find(bound.begin(), bound.end(), path) == bound.end()) bound.push_back(path);
  }
  return two_call(capacity, count, sources, static_cast<uint32_t>(bound.size()), [&](XrPath& p, uint32_t i) {
    p = bound[i];
    return XR_SUCCESS;
  });
}

// "Left Hand Simple Controller Select Click", or the parts asked for.
XrResult xrGetInputSourceLocalizedName(XrSession session, const XrInputSourceLocalizedNameGetInfo* info,
                                       uint32_t capacity, uint32_t* count, char* buffer) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  constexpr XrInputSourceLocalizedNameFlags kAllComponents = XR_INPUT_SOURCE_LOCALIZED_NAME_USER_PATH_BIT |
                                                             XR_INPUT_SOURCE_LOCALIZED_NAME_INTERACTION_PROFILE_BIT |
                                                             XR_INPUT_SOURCE_LOCALIZED_NAME_COMPONENT_BIT;
  if (info == nullptr || info->type != XR_TYPE_INPUT_SOURCE_LOCALIZED_NAME_GET_INFO || info->whichComponents == 0 ||
      (info->whichComponents & ~kAllComponents) != 0) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (!state->attached) return XR_ERROR_ACTIONSET_NOT_ATTACHED;
  const InstanceState& instance = reg.instances.at(state->instance);
  const auto path = path_string(instance, info->sourcePath);
  if (!path) return XR_ERROR_PATH_INVALID;
  const Profile* profile = nullptr;
  std::optional<BindingPath> split;
  for (const Profile& p : kProfiles) {
    if (!instance.enabled(p.ext)) continue;
    if ((split = split_binding(p, *path))) {
      profile = &p;
      break;
    }
  }
  if (profile == nullptr) return XR_ERROR_PATH_UNSUPPORTED;
  // Words of a path, capitalised: "input/select/click" -> "Select Click".
  auto words = [](std::string_view text) {
    std::string out;
    bool start = true;
    for (char c : text) {
      if (c == '/' || c == '_') {
        if (!out.empty() && out.back() != ' ') out += ' ';
        start = true;
      } else {
        out += start && c >= 'a' && c <= 'z' ? static_cast<char>(c - 'a' + 'A') : c;
        start = false;
      }
    }
    return out;
  };
  std::string name;
  auto add = [&](const std::string& part) { name += (name.empty() ? "" : " ") + part; };
  if (info->whichComponents & XR_INPUT_SOURCE_LOCALIZED_NAME_USER_PATH_BIT) {
    const std::string_view top = split->top_level;
    add(top.starts_with("/user/hand/") ? words(top.substr(11)) + " Hand" : words(top.substr(top.rfind('/') + 1)));
  }
  if (info->whichComponents & XR_INPUT_SOURCE_LOCALIZED_NAME_INTERACTION_PROFILE_BIT) add(profile->localized_name);
  if (info->whichComponents & XR_INPUT_SOURCE_LOCALIZED_NAME_COMPONENT_BIT) {
    std::string_view component = split->subpath;
    component.remove_prefix(component.find('/') + 1);  // drop "input/" or "output/"
    add(words(component));
  }
  return two_call(capacity, count, buffer, static_cast<uint32_t>(name.size() + 1), [&](char& c, uint32_t i) {
    c = i < name.size() ? name[i] : '\0';
    return XR_SUCCESS;
  });
}

// Haptics are checked and ignored.
XrResult haptic_call(XrSession session, const XrHapticActionInfo* info, const XrHapticBaseHeader* feedback,
                     bool apply) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  const SessionState* state = find(reg.sessions, id_of(session));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (info == nullptr || info->type != XR_TYPE_HAPTIC_ACTION_INFO ||
      (apply && (feedback == nullptr || feedback->type != XR_TYPE_HAPTIC_VIBRATION))) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  AttachedAction* action = nullptr;
  std::string key;
  const XrResult r =
      attached_action(reg, *state, info->action, info->subactionPath, {XR_ACTION_TYPE_VIBRATION_OUTPUT}, action, key);
  if (XR_FAILED(r)) {
    return r;
  }
  return state->state == XR_SESSION_STATE_FOCUSED ? XR_SUCCESS : XR_SESSION_NOT_FOCUSED;
}

XrResult xrApplyHapticFeedback(XrSession session, const XrHapticActionInfo* info, const XrHapticBaseHeader* feedback) {
  return haptic_call(session, info, feedback, true);
}

XrResult xrStopHapticFeedback(XrSession session, const XrHapticActionInfo* info) {
  return haptic_call(session, info, nullptr, false);
}

// ---- XR_HTCX_vive_tracker_interaction ----
// The trackers connected now.
XrResult xrEnumerateViveTrackerPathsHTCX(XrInstance instance, uint32_t capacity, uint32_t* count,
                                         XrViveTrackerPathsHTCX* paths) {
  Registry& reg = registry();
  std::lock_guard lock(reg.mutex);
  InstanceState* state = find(reg.instances, id_of(instance));
  if (state == nullptr) return XR_ERROR_HANDLE_INVALID;
  if (!state->vive_tracker) return XR_ERROR_FUNCTION_UNSUPPORTED;
  refresh_trackers(*state, mx::xr_time_now());
  std::vector<std::size_t> connected;
  for (std::size_t i = 0; i < 2; ++i) {
    if (state->tracker_seen[i]) connected.push_back(i);
  }
  return two_call(capacity, count, paths, static_cast<uint32_t>(connected.size()),
                  [&](XrViveTrackerPathsHTCX& p, uint32_t i) {
                    if (p.type != XR_TYPE_VIVE_TRACKER_PATHS_HTCX) return XR_ERROR_VALIDATION_FAILURE;
                    p.persistentPath = intern_path(*state, kTrackerPersistentPaths[connected[i]]);
                    p.rolePath = intern_path(*state, kTrackerRoles[connected[i]]);
                    return XR_SUCCESS;
                  });
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
      PROPRIO_MOCK_FUNCTION(xrEnumerateViewConfigurations, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrGetViewConfigurationProperties, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrEnumerateViewConfigurationViews, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrLocateViews, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrEnumerateSwapchainFormats, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrCreateSwapchain, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrDestroySwapchain, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrEnumerateSwapchainImages, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrAcquireSwapchainImage, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrWaitSwapchainImage, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrReleaseSwapchainImage, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrCreateActionSet, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrDestroyActionSet, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrCreateAction, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrDestroyAction, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrSuggestInteractionProfileBindings, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrAttachSessionActionSets, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrSyncActions, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrGetCurrentInteractionProfile, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrGetActionStateBoolean, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrGetActionStateFloat, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrGetActionStateVector2f, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrGetActionStatePose, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrCreateActionSpace, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrEnumerateBoundSourcesForAction, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrGetInputSourceLocalizedName, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrApplyHapticFeedback, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrStopHapticFeedback, Ext::none),
      PROPRIO_MOCK_FUNCTION(xrEnumerateViveTrackerPathsHTCX, Ext::vive_tracker),
      PROPRIO_MOCK_FUNCTION(xrConvertTimespecTimeToTimeKHR, Ext::convert_timespec_time),
      PROPRIO_MOCK_FUNCTION(xrConvertTimeToTimespecTimeKHR, Ext::convert_timespec_time),
      PROPRIO_MOCK_FUNCTION(xrCreateHandTrackerEXT, Ext::hand_tracking),
      PROPRIO_MOCK_FUNCTION(xrDestroyHandTrackerEXT, Ext::hand_tracking),
      PROPRIO_MOCK_FUNCTION(xrLocateHandJointsEXT, Ext::hand_tracking),
      PROPRIO_MOCK_FUNCTION(xrGetVulkanGraphicsRequirements2KHR, Ext::vulkan_enable2),
      PROPRIO_MOCK_FUNCTION(xrCreateVulkanInstanceKHR, Ext::vulkan_enable2),
      PROPRIO_MOCK_FUNCTION(xrGetVulkanGraphicsDevice2KHR, Ext::vulkan_enable2),
      PROPRIO_MOCK_FUNCTION(xrCreateVulkanDeviceKHR, Ext::vulkan_enable2),
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
