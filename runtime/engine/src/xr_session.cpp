// The OpenXR path of the app (hello_xr's frame loop, with Proprio's renderer):
// XR_KHR_vulkan_enable2 creates the Vulkan instance and device through the
// runtime, two swapchains (one per eye) become framebuffer sets, and each
// frame is waitFrame -> beginFrame -> locateViews -> render -> endFrame with
// one projection layer. Hands come from XR_EXT_hand_tracking when the app has
// no in-process source (so Proprio's own layer, or any hand-tracking runtime,
// feeds the engine).
#define XR_USE_GRAPHICS_API_VULKAN
#define XR_USE_TIMESPEC
#include <time.h>
#include <vulkan/vulkan.h>
// clang-format off
#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>
// clang-format on

#include <fmt/format.h>

#include <array>
#include <chrono>
#include <cstring>
#include <thread>

#include "app_impl.hpp"
#include "proprio/core/log.hpp"
#include "proprio/core/xr_interop.hpp"
#include "proprio/engine/xr_vulkan.hpp"
#include "xr_util.hpp"

namespace proprio::engine {
namespace {

using detail::has_extension;
using detail::xr_load;

std::vector<XrExtensionProperties> runtime_extensions() {
  std::uint32_t count = 0;
  if (XR_FAILED(xrEnumerateInstanceExtensionProperties(nullptr, 0, &count, nullptr))) return {};
  std::vector<XrExtensionProperties> exts(count, XrExtensionProperties{XR_TYPE_EXTENSION_PROPERTIES});
  if (XR_FAILED(xrEnumerateInstanceExtensionProperties(nullptr, count, &count, exts.data()))) return {};
  return exts;
}

// Every OpenXR handle the session makes, destroyed in reverse order. The
// instance outlives the Vulkan device (the app destroys that after the
// session), so it is destroyed separately, last.
struct XrObjects {
  XrInstance instance = XR_NULL_HANDLE;
  XrSession session = XR_NULL_HANDLE;
  XrSpace app_space = XR_NULL_HANDLE;
  std::array<XrSwapchain, 2> swapchains{XR_NULL_HANDLE, XR_NULL_HANDLE};
  std::array<XrHandTrackerEXT, 2> hand_trackers{XR_NULL_HANDLE, XR_NULL_HANDLE};
  PFN_xrDestroyHandTrackerEXT destroy_hand_tracker = nullptr;

  void destroy_session_objects() {
    for (auto& h : hand_trackers) {
      if (h != XR_NULL_HANDLE && destroy_hand_tracker) destroy_hand_tracker(h);
      h = XR_NULL_HANDLE;
    }
    for (auto& s : swapchains) {
      if (s != XR_NULL_HANDLE) xrDestroySwapchain(s);
      s = XR_NULL_HANDLE;
    }
    if (app_space != XR_NULL_HANDLE) xrDestroySpace(app_space);
    app_space = XR_NULL_HANDLE;
    if (session != XR_NULL_HANDLE) xrDestroySession(session);
    session = XR_NULL_HANDLE;
  }
  ~XrObjects() {
    destroy_session_objects();
    if (instance != XR_NULL_HANDLE) xrDestroyInstance(instance);
  }
};

}  // namespace

bool xr_runtime_available() {
  const auto exts = runtime_extensions();
  return has_extension(exts, XR_KHR_VULKAN_ENABLE2_EXTENSION_NAME);
}

Result<AppReport> App::Impl::run_xr() {
  const HapticsOffOnExit haptics_off{*this};
  const auto exts = runtime_extensions();
  if (exts.empty()) {
    return make_error(Errc::unavailable, "no OpenXR runtime (set XR_RUNTIME_JSON or install one, e.g. Monado)");
  }
  if (!has_extension(exts, XR_KHR_VULKAN_ENABLE2_EXTENSION_NAME)) {
    return make_error(Errc::unavailable, "the OpenXR runtime does not offer XR_KHR_vulkan_enable2");
  }
  std::vector<const char*> enabled{XR_KHR_VULKAN_ENABLE2_EXTENSION_NAME};
  const bool hand_tracking_ext = has_extension(exts, XR_EXT_HAND_TRACKING_EXTENSION_NAME);
  const bool timespec_ext = has_extension(exts, XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME);
  if (hand_tracking_ext) enabled.push_back(XR_EXT_HAND_TRACKING_EXTENSION_NAME);
  if (timespec_ext) enabled.push_back(XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME);

  XrObjects xr;
  XrInstanceCreateInfo ici{XR_TYPE_INSTANCE_CREATE_INFO};
  std::snprintf(ici.applicationInfo.applicationName, XR_MAX_APPLICATION_NAME_SIZE, "proprio");
  std::snprintf(ici.applicationInfo.engineName, XR_MAX_ENGINE_NAME_SIZE, "proprio");
  ici.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
  ici.enabledExtensionCount = static_cast<std::uint32_t>(enabled.size());
  ici.enabledExtensionNames = enabled.data();
  if (XrResult r = xrCreateInstance(&ici, &xr.instance); XR_FAILED(r)) {
    return xr_call_error(xr.instance, "xrCreateInstance", r);
  }
  XrSystemGetInfo sgi{XR_TYPE_SYSTEM_GET_INFO};
  sgi.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  if (XrResult r = xrGetSystem(xr.instance, &sgi, &system); XR_FAILED(r)) {
    Error e = xr_call_error(xr.instance, "xrGetSystem (HMD)", r);
    e.code = Errc::unavailable;
    return e;
  }

  auto to_timespec = timespec_ext
                         ? xr_load<PFN_xrConvertTimeToTimespecTimeKHR>(xr.instance, "xrConvertTimeToTimespecTimeKHR")
                         : nullptr;

  // Vulkan through the runtime.
  render::ContextOptions base;
  base.device = options.software_renderer ? render::DevicePreference::software : render::DevicePreference::automatic;
  base.validation = options.validation;
  auto co = xr_vulkan_context_options(xr.instance, system, std::move(base));
  if (!co) return co.error();
  auto ctx = render::VulkanContext::create(*co);
  if (!ctx) return ctx.error();
  // The session's objects go before the device; the instance after (XrObjects).
  struct SessionGuard {
    XrObjects& xr;
    ~SessionGuard() { xr.destroy_session_objects(); }
  };
  SessionGuard guard{xr};  // after the context, before the renderer: destroyed between them
  std::unique_ptr<render::Renderer> renderer;
  std::array<std::unique_ptr<render::FramebufferSet>, 2> eyes;
  {
    auto r = render::Renderer::create(**ctx);
    if (!r) return r.error();
    renderer = std::move(*r);
  }
  auto drawer = SceneDrawer::create(*renderer, scene, options, *hand_model, inputs.surfaces);
  if (!drawer) return drawer.error();

  XrGraphicsBindingVulkan2KHR binding{XR_TYPE_GRAPHICS_BINDING_VULKAN2_KHR};
  binding.instance = (*ctx)->instance();
  binding.physicalDevice = (*ctx)->physical_device();
  binding.device = (*ctx)->device();
  binding.queueFamilyIndex = (*ctx)->queue_family();
  binding.queueIndex = 0;
  XrSessionCreateInfo sci{XR_TYPE_SESSION_CREATE_INFO};
  sci.next = &binding;
  sci.systemId = system;
  if (XrResult r = xrCreateSession(xr.instance, &sci, &xr.session); XR_FAILED(r)) {
    return xr_call_error(xr.instance, "xrCreateSession", r);
  }

  // STAGE (floor-level, as the scenes are authored) when there is one.
  std::uint32_t space_count = 0;
  xrEnumerateReferenceSpaces(xr.session, 0, &space_count, nullptr);
  std::vector<XrReferenceSpaceType> spaces(space_count);
  xrEnumerateReferenceSpaces(xr.session, space_count, &space_count, spaces.data());
  XrReferenceSpaceCreateInfo rsci{XR_TYPE_REFERENCE_SPACE_CREATE_INFO};
  rsci.referenceSpaceType = std::find(spaces.begin(), spaces.end(), XR_REFERENCE_SPACE_TYPE_STAGE) != spaces.end()
                                ? XR_REFERENCE_SPACE_TYPE_STAGE
                                : XR_REFERENCE_SPACE_TYPE_LOCAL;
  rsci.poseInReferenceSpace.orientation.w = 1.0f;
  if (XrResult r = xrCreateReferenceSpace(xr.session, &rsci, &xr.app_space); XR_FAILED(r)) {
    return xr_call_error(xr.instance, "xrCreateReferenceSpace", r);
  }

  // One swapchain per eye at the recommended size.
  std::uint32_t view_count = 0;
  xrEnumerateViewConfigurationViews(xr.instance, system, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO, 0, &view_count,
                                    nullptr);
  if (view_count != 2) return make_error(Errc::unsupported, fmt::format("expected 2 stereo views, got {}", view_count));
  std::array<XrViewConfigurationView, 2> config_views{{{XR_TYPE_VIEW_CONFIGURATION_VIEW},
                                                       {XR_TYPE_VIEW_CONFIGURATION_VIEW}}};
  if (XrResult r = xrEnumerateViewConfigurationViews(xr.instance, system, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO, 2,
                                                     &view_count, config_views.data());
      XR_FAILED(r)) {
    return xr_call_error(xr.instance, "xrEnumerateViewConfigurationViews", r);
  }
  std::uint32_t format_count = 0;
  xrEnumerateSwapchainFormats(xr.session, 0, &format_count, nullptr);
  std::vector<std::int64_t> formats(format_count);
  xrEnumerateSwapchainFormats(xr.session, format_count, &format_count, formats.data());
  std::int64_t format = 0;
  for (std::int64_t preferred : {std::int64_t{VK_FORMAT_R8G8B8A8_SRGB}, std::int64_t{VK_FORMAT_B8G8R8A8_SRGB}}) {
    if (format == 0 && std::find(formats.begin(), formats.end(), preferred) != formats.end()) format = preferred;
  }
  if (format == 0) return make_error(Errc::unsupported, "the runtime offers no sRGB 8-bit swapchain format");
  std::array<VkExtent2D, 2> extents{};
  for (std::size_t e = 0; e < 2; ++e) {
    extents[e] = {config_views[e].recommendedImageRectWidth, config_views[e].recommendedImageRectHeight};
    XrSwapchainCreateInfo sc{XR_TYPE_SWAPCHAIN_CREATE_INFO};
    sc.usageFlags = XR_SWAPCHAIN_USAGE_COLOR_ATTACHMENT_BIT;
    sc.format = format;
    sc.sampleCount = 1;
    sc.width = extents[e].width;
    sc.height = extents[e].height;
    sc.faceCount = 1;
    sc.arraySize = 1;
    sc.mipCount = 1;
    if (XrResult r = xrCreateSwapchain(xr.session, &sc, &xr.swapchains[e]); XR_FAILED(r)) {
      return xr_call_error(xr.instance, "xrCreateSwapchain", r);
    }
    std::uint32_t image_count = 0;
    xrEnumerateSwapchainImages(xr.swapchains[e], 0, &image_count, nullptr);
    std::vector<XrSwapchainImageVulkan2KHR> images(image_count, {XR_TYPE_SWAPCHAIN_IMAGE_VULKAN2_KHR});
    if (XrResult r = xrEnumerateSwapchainImages(xr.swapchains[e], image_count, &image_count,
                                                reinterpret_cast<XrSwapchainImageBaseHeader*>(images.data()));
        XR_FAILED(r)) {
      return xr_call_error(xr.instance, "xrEnumerateSwapchainImages", r);
    }
    std::vector<VkImage> handles;
    for (const auto& i : images) handles.push_back(i.image);
    // OpenXR wants the images back in COLOR_ATTACHMENT_OPTIMAL at release.
    auto set = render::FramebufferSet::create(*renderer, handles, static_cast<VkFormat>(format), extents[e],
                                              VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL);
    if (!set) return set.error();
    eyes[e] = std::move(*set);
  }

  // Hands from the runtime when the caller brought none.
  PFN_xrLocateHandJointsEXT locate_hand = nullptr;
  if (!inputs.hands && hand_tracking_ext) {
    XrSystemHandTrackingPropertiesEXT htp{XR_TYPE_SYSTEM_HAND_TRACKING_PROPERTIES_EXT};
    XrSystemProperties sp{XR_TYPE_SYSTEM_PROPERTIES};
    sp.next = &htp;
    auto create_tracker = xr_load<PFN_xrCreateHandTrackerEXT>(xr.instance, "xrCreateHandTrackerEXT");
    locate_hand = xr_load<PFN_xrLocateHandJointsEXT>(xr.instance, "xrLocateHandJointsEXT");
    xr.destroy_hand_tracker = xr_load<PFN_xrDestroyHandTrackerEXT>(xr.instance, "xrDestroyHandTrackerEXT");
    if (XR_SUCCEEDED(xrGetSystemProperties(xr.instance, system, &sp)) && htp.supportsHandTracking && create_tracker &&
        locate_hand) {
      for (int h = 0; h < 2; ++h) {
        XrHandTrackerCreateInfoEXT hci{XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT};
        hci.hand = h == 0 ? XR_HAND_LEFT_EXT : XR_HAND_RIGHT_EXT;
        hci.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
        if (XrResult r = create_tracker(xr.session, &hci, &xr.hand_trackers[static_cast<std::size_t>(h)]); XR_FAILED(r)) {
          return xr_call_error(xr.instance, "xrCreateHandTrackerEXT", r);
        }
      }
    } else {
      locate_hand = nullptr;
    }
  }
  logger().info("OpenXR: {} per eye {}x{}, {} space, hands from {}", (*ctx)->describe(), extents[0].width,
                extents[0].height, rsci.referenceSpaceType == XR_REFERENCE_SPACE_TYPE_STAGE ? "STAGE" : "LOCAL",
                inputs.hands ? std::string(inputs.hands->name()) : (locate_hand ? "XR_EXT_hand_tracking" : "nowhere"));

  if (servo) {
    if (auto s = servo->start(); !s) return s.error();
  }
  auto xr_to_monotonic = [&](XrTime t) -> TimeNs {
    timespec ts{};
    if (to_timespec && XR_SUCCEEDED(to_timespec(xr.instance, t, &ts))) {
      return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
    }
    return MonotonicClock::instance().now_ns();
  };

  render::DrawList draws;
  std::array<XrHandJointLocationEXT, XR_HAND_JOINT_COUNT_EXT> joints{};
  XrSessionState state = XR_SESSION_STATE_UNKNOWN;
  bool running = false, exit_requested = false, done = false;
  int frame = 0;
  Pose head;  // the last located head; kept when a frame's views are not valid
  const TimeNs start = MonotonicClock::instance().now_ns();
  while (!done) {
    XrEventDataBuffer event{XR_TYPE_EVENT_DATA_BUFFER};
    while (xrPollEvent(xr.instance, &event) == XR_SUCCESS) {
      if (event.type == XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED) {
        state = reinterpret_cast<const XrEventDataSessionStateChanged&>(event).state;
        if (state == XR_SESSION_STATE_READY) {
          XrSessionBeginInfo bi{XR_TYPE_SESSION_BEGIN_INFO};
          bi.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
          if (XrResult r = xrBeginSession(xr.session, &bi); XR_FAILED(r)) {
            return xr_call_error(xr.instance, "xrBeginSession", r);
          }
          running = true;
        } else if (state == XR_SESSION_STATE_STOPPING) {
          xrEndSession(xr.session);
          running = false;
        } else if (state == XR_SESSION_STATE_EXITING || state == XR_SESSION_STATE_LOSS_PENDING) {
          done = true;
        }
      } else if (event.type == XR_TYPE_EVENT_DATA_INSTANCE_LOSS_PENDING) {
        done = true;
      }
      event = {XR_TYPE_EVENT_DATA_BUFFER};
    }
    const bool want_exit = stop->load() || (options.frames > 0 && frame >= options.frames);
    if (want_exit && !exit_requested && running) {
      xrRequestExitSession(xr.session);
      exit_requested = true;
    }
    if (done) break;
    if (!running) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      if (want_exit && !exit_requested && state != XR_SESSION_STATE_UNKNOWN && state <= XR_SESSION_STATE_READY) {
        done = true;  // never got going; nothing to end
      }
      continue;
    }

    XrFrameState fs{XR_TYPE_FRAME_STATE};
    if (XrResult r = xrWaitFrame(xr.session, nullptr, &fs); XR_FAILED(r)) {
      return xr_call_error(xr.instance, "xrWaitFrame", r);
    }
    if (XrResult r = xrBeginFrame(xr.session, nullptr); XR_FAILED(r)) {
      return xr_call_error(xr.instance, "xrBeginFrame", r);
    }
    const TimeNs t = xr_to_monotonic(fs.predictedDisplayTime);
    if (inputs.before_frame) inputs.before_frame(t);
    if (locate_hand) {
      const std::size_t h = options.hand == Handedness::left ? 0 : 1;
      XrHandJointsLocateInfoEXT li{XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT};
      li.baseSpace = xr.app_space;
      li.time = fs.predictedDisplayTime;
      XrHandJointLocationsEXT locations{XR_TYPE_HAND_JOINT_LOCATIONS_EXT};
      locations.jointCount = XR_HAND_JOINT_COUNT_EXT;
      locations.jointLocations = joints.data();
      tracked.active = false;
      if (XR_SUCCEEDED(locate_hand(xr.hand_trackers[h], &li, &locations)) && locations.isActive) {
        tracked.active = true;
        ++frames_with_hand;
        tracked.hand = options.hand;
        tracked.time_ns = t;
        for (std::size_t j = 0; j < kHandJointCount; ++j) {
          tracked.T_world_joint[j] = from_xr(joints[j].pose);
          tracked.radius_m[j] = joints[j].radius;
          tracked.flags[j] = static_cast<std::uint8_t>(joints[j].locationFlags & 0xF);
        }
        if (servo) servo->submit_tracked_hand(tracked);
      }
    } else {
      read_hands(t);
    }
    read_servo_snapshot();
    std::array<XrView, 2> xr_views{{{XR_TYPE_VIEW}, {XR_TYPE_VIEW}}};
    XrViewLocateInfo vli{XR_TYPE_VIEW_LOCATE_INFO};
    vli.viewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
    vli.displayTime = fs.predictedDisplayTime;
    vli.space = xr.app_space;
    XrViewState vs{XR_TYPE_VIEW_STATE};
    std::uint32_t located = 0;
    const bool views_ok = XR_SUCCEEDED(xrLocateViews(xr.session, &vli, &vs, 2, &located, xr_views.data())) &&
                          located == 2 && (vs.viewStateFlags & XR_VIEW_STATE_POSITION_VALID_BIT) &&
                          (vs.viewStateFlags & XR_VIEW_STATE_ORIENTATION_VALID_BIT);
    // The head is between the eyes, looking where they look.
    if (views_ok) {
      head = {from_xr(xr_views[0].pose).q,
              0.5 * (from_xr(xr_views[0].pose).p + from_xr(xr_views[1].pose).p)};
    }
    run_frame_hook(t, frame, head, {});
    compose(draws, *drawer, static_cast<double>(t - start) * 1e-9, extents[0].width, extents[0].height);
    std::array<XrCompositionLayerProjectionView, 2> projection_views{
        {{XR_TYPE_COMPOSITION_LAYER_PROJECTION_VIEW}, {XR_TYPE_COMPOSITION_LAYER_PROJECTION_VIEW}}};
    XrCompositionLayerProjection layer{XR_TYPE_COMPOSITION_LAYER_PROJECTION};
    const XrCompositionLayerBaseHeader* layers[] = {reinterpret_cast<XrCompositionLayerBaseHeader*>(&layer)};
    bool rendered = false;
    if (fs.shouldRender && views_ok) {
      std::array<render::View, 2> views;
      std::array<render::ViewTarget, 2> targets;
      for (std::size_t e = 0; e < 2; ++e) {
        std::uint32_t index = 0;
        XrSwapchainImageWaitInfo wi{XR_TYPE_SWAPCHAIN_IMAGE_WAIT_INFO};
        wi.timeout = XR_INFINITE_DURATION;
        if (XrResult r = xrAcquireSwapchainImage(xr.swapchains[e], nullptr, &index); XR_FAILED(r)) {
          return xr_call_error(xr.instance, "xrAcquireSwapchainImage", r);
        }
        if (XrResult r = xrWaitSwapchainImage(xr.swapchains[e], &wi); XR_FAILED(r)) {
          return xr_call_error(xr.instance, "xrWaitSwapchainImage", r);
        }
        views[e] = {from_xr(xr_views[e].pose), {xr_views[e].fov.angleLeft, xr_views[e].fov.angleRight,
                                                xr_views[e].fov.angleUp, xr_views[e].fov.angleDown}};
        targets[e] = {eyes[e].get(), index};
        projection_views[e].pose = xr_views[e].pose;
        projection_views[e].fov = xr_views[e].fov;
        projection_views[e].subImage.swapchain = xr.swapchains[e];
        projection_views[e].subImage.imageRect = {{0, 0},
                                                  {static_cast<std::int32_t>(extents[e].width),
                                                   static_cast<std::int32_t>(extents[e].height)}};
      }
      const auto t0 = std::chrono::steady_clock::now();
      auto s = renderer->render(draws, views, targets);
      for (std::size_t e = 0; e < 2; ++e) {
        XrSwapchainImageReleaseInfo ri{XR_TYPE_SWAPCHAIN_IMAGE_RELEASE_INFO};
        xrReleaseSwapchainImage(xr.swapchains[e], &ri);
      }
      if (!s) {
        return s.error();
      }
      render_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      layer.space = xr.app_space;
      layer.viewCount = 2;
      layer.views = projection_views.data();
      rendered = true;
    }
    XrFrameEndInfo fe{XR_TYPE_FRAME_END_INFO};
    fe.displayTime = fs.predictedDisplayTime;
    fe.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
    fe.layerCount = rendered ? 1 : 0;
    fe.layers = rendered ? layers : nullptr;
    if (XrResult r = xrEndFrame(xr.session, &fe); XR_FAILED(r)) {
      return xr_call_error(xr.instance, "xrEndFrame", r);
    }
    ++frame;
  }
  (void)renderer->wait_idle();
  shutdown_haptics();
  AppReport report_out = report(OutputMode::xr, (*ctx)->describe(), frame);
  if ((*ctx)->validation_errors() > 0) {
    return make_error(Errc::io_error, fmt::format("{} Vulkan validation errors; first: {}", (*ctx)->validation_errors(),
                                                  (*ctx)->validation_messages().front()));
  }
  return report_out;
}

}  // namespace proprio::engine
