/* xr_fingertip_haptics: a minimal OpenXR app, in plain C11, that uses
 * XR_PROPRIO_fingertip_haptics (runtime/core/include/proprio/openxr/
 * XR_PROPRIO_fingertip_haptics.h, docs/xr-proprio-fingertip-haptics.md).
 *
 * It links the OpenXR loader and nothing else: every extension function comes
 * from xrGetInstanceProcAddr. Headless (XR_MND_headless) when the runtime
 * offers it, so it runs on the project's mock runtime without a GPU.
 *
 * What it does, on the right index finger:
 *   1. level 1 (forces): submits 0.8 N along the fingertip's +Y (pressing on
 *      the pad) every frame for 0.5 s, stops, and watches the commanded force
 *      fade out (the device's watchdog);
 *   2. level 2 (contact): registers a 3 cm sphere collider just under the
 *      tracked index fingertip's pad and moves it with the fingertip every
 *      frame, so the proxy fingertip keeps pressing on it.
 * Every few frames it prints the index's commanded, measured and contact
 * force (y, the pad normal), and at the end one line per check.
 *
 *   xr_fingertip_haptics [--frames N] [--print-every N] [--expect-contact]
 *
 * Exit status: 0 done (and, with --expect-contact, every check passed);
 * 1 an OpenXR call failed or a check failed; 2 the runtime and its layers do
 * not offer fingertip haptics (or hand tracking) here. */
#define _POSIX_C_SOURCE 200809L

#include <math.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <openxr/openxr.h>

#include "proprio/openxr/XR_PROPRIO_fingertip_haptics.h"

enum { kExitOk = 0, kExitFailed = 1, kExitUnsupported = 2 };

/* Level 1: the force submitted, for how long, and what must come of it. */
#define LEVEL1_FORCE_N 0.8f
#define LEVEL1_SECONDS 0.5
#define LEVEL1_PEAK_MIN_N 0.5f
#define LEVEL1_ZERO_N 0.01f
#define LEVEL1_DECAY_MAX_S 0.2
#define LEVEL1_WATCH_S 0.5 /* how long to watch for the fade before moving on */
#define CONNECT_WAIT_S 2.0 /* how long to wait for the index device before level 1 */
/* Level 2: the collider and the forces that show contact. */
#define COLLIDER_RADIUS_M 0.03f
#define COLLIDER_PAD_OFFSET_M 0.015f
#define COLLIDER_FRICTION 0.8f
#define CONTACT_MIN_N 0.05f

#define INDEX XR_FINGERTIP_INDEX_PROPRIO

typedef struct Options {
  long frames;
  long print_every;
  bool expect_contact;
} Options;

typedef enum Phase {
  PHASE_WAIT_DEVICE, /* until the right index device answers */
  PHASE_LEVEL1_PUSH, /* submitting LEVEL1_FORCE_N */
  PHASE_LEVEL1_FADE, /* submissions stopped: watching the force go */
  PHASE_CONTACT,     /* the collider under the index pad */
  PHASE_IDLE,        /* level 1 done and no contact simulation: nothing more to do */
} Phase;

static const char* phase_name(Phase p) {
  switch (p) {
    case PHASE_WAIT_DEVICE: return "wait";
    case PHASE_LEVEL1_PUSH: return "push";
    case PHASE_LEVEL1_FADE: return "fade";
    case PHASE_CONTACT: return "contact";
    case PHASE_IDLE: return "idle";
  }
  return "?";
}

typedef struct App {
  XrInstance instance;
  XrSystemId system;
  XrSession session;
  XrSpace local;
  XrHandTrackerEXT trackers[2]; /* left, right */
  XrFingertipHapticsPROPRIO haptics;
  XrHapticColliderPROPRIO collider;
  bool running;      /* between xrBeginSession and xrEndSession */
  bool exit_request; /* the runtime asked us to stop (or we did) */
  bool has_contact_simulation;

  PFN_xrCreateHandTrackerEXT xrCreateHandTrackerEXT;
  PFN_xrDestroyHandTrackerEXT xrDestroyHandTrackerEXT;
  PFN_xrLocateHandJointsEXT xrLocateHandJointsEXT;
  PFN_xrCreateFingertipHapticsPROPRIO xrCreateFingertipHapticsPROPRIO;
  PFN_xrDestroyFingertipHapticsPROPRIO xrDestroyFingertipHapticsPROPRIO;
  PFN_xrGetFingertipHapticsPropertiesPROPRIO xrGetFingertipHapticsPropertiesPROPRIO;
  PFN_xrApplyFingertipForcesPROPRIO xrApplyFingertipForcesPROPRIO;
  PFN_xrCreateHapticColliderPROPRIO xrCreateHapticColliderPROPRIO;
  PFN_xrSetHapticColliderPosePROPRIO xrSetHapticColliderPosePROPRIO;
  PFN_xrDestroyHapticColliderPROPRIO xrDestroyHapticColliderPROPRIO;
  PFN_xrLocateProxyHandJointsPROPRIO xrLocateProxyHandJointsPROPRIO;
  PFN_xrGetFingertipHapticsStatePROPRIO xrGetFingertipHapticsStatePROPRIO;
} App;

/* What the checks need, gathered over the run. */
typedef struct Results {
  bool level1_done;       /* the push phase ran its full length */
  float level1_peak_n;    /* max commandedForce.y while pushing */
  double level1_decay_s;  /* last submission to commanded |F| < LEVEL1_ZERO_N; < 0: not seen */
  long contact_frames;    /* frames with the collider in place */
  float contact_peak_n;   /* max contactForce.y with the collider */
  float measured_peak_n;  /* max measuredForce.y with the collider */
  double proxy_gap_sum_m; /* tracked-to-proxy index tip distance, summed over contact frames */
  long proxy_gap_count;
} Results;

/* ---- helpers --------------------------------------------------------------------------------------------------- */

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* Prints "<what> failed: XR_ERROR_... (-n)" and returns false when r failed. */
static bool xr_ok(const App* app, XrResult r, const char* what) {
  if (XR_SUCCEEDED(r)) return true;
  char name[XR_MAX_RESULT_STRING_SIZE] = "";
  if (app->instance == XR_NULL_HANDLE || XR_FAILED(xrResultToString(app->instance, r, name))) {
    snprintf(name, sizeof name, "XrResult");
  }
  fprintf(stderr, "xr_fingertip_haptics: %s failed: %s (%d)\n", what, name, (int)r);
  return false;
}

#define XR_CHECK(app, call, what)                    \
  do {                                               \
    if (!xr_ok((app), (call), (what))) return false; \
  } while (0)

/* kExitOk, kExitFailed, or kExitUnsupported when the instance has no such function (an extension that a layer's
 * manifest lists but its library does not implement). */
static int load_function(App* app, const char* name, PFN_xrVoidFunction* out) {
  *out = NULL;
  const XrResult r = xrGetInstanceProcAddr(app->instance, name, out);
  if (r == XR_ERROR_FUNCTION_UNSUPPORTED) {
    printf("%s not available: xrGetInstanceProcAddr(%s) gave XR_ERROR_FUNCTION_UNSUPPORTED\n",
           strstr(name, "PROPRIO") ? XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME : XR_EXT_HAND_TRACKING_EXTENSION_NAME,
           name);
    return kExitUnsupported;
  }
  if (!xr_ok(app, r, name)) return kExitFailed;
  if (*out == NULL) {
    fprintf(stderr, "xr_fingertip_haptics: xrGetInstanceProcAddr(%s) returned no function\n", name);
    return kExitFailed;
  }
  return kExitOk;
}

static XrVector3f rotate(XrQuaternionf q, XrVector3f v) {
  /* v + 2w (q x v) + 2 q x (q x v) */
  const XrVector3f t = {2.0f * (q.y * v.z - q.z * v.y), 2.0f * (q.z * v.x - q.x * v.z), 2.0f * (q.x * v.y - q.y * v.x)};
  const XrVector3f out = {v.x + q.w * t.x + (q.y * t.z - q.z * t.y), v.y + q.w * t.y + (q.z * t.x - q.x * t.z),
                          v.z + q.w * t.z + (q.x * t.y - q.y * t.x)};
  return out;
}

static float distance(XrVector3f a, XrVector3f b) {
  const float dx = a.x - b.x, dy = a.y - b.y, dz = a.z - b.z;
  return sqrtf(dx * dx + dy * dy + dz * dz);
}

static float norm(XrVector3f v) { return sqrtf(v.x * v.x + v.y * v.y + v.z * v.z); }

static bool pose_valid(const XrHandJointLocationEXT* j) {
  const XrSpaceLocationFlags need = XR_SPACE_LOCATION_POSITION_VALID_BIT | XR_SPACE_LOCATION_ORIENTATION_VALID_BIT;
  return (j->locationFlags & need) == need;
}

static const char* gate_name(XrFingertipGateStatePROPRIO g) {
  switch (g) {
    case XR_FINGERTIP_GATE_STATE_OFF_PROPRIO: return "off";
    case XR_FINGERTIP_GATE_STATE_RAMPING_PROPRIO: return "ramping";
    case XR_FINGERTIP_GATE_STATE_ACTIVE_PROPRIO: return "active";
    case XR_FINGERTIP_GATE_STATE_FAULTED_PROPRIO: return "faulted";
    default: return "?";
  }
}

static bool offered(const XrExtensionProperties* exts, uint32_t count, const char* name) {
  for (uint32_t i = 0; i < count; ++i) {
    if (strcmp(exts[i].extensionName, name) == 0) return true;
  }
  return false;
}

static bool parse_count(const char* s, long* out) {
  char* end = NULL;
  const long v = strtol(s, &end, 10);
  if (end == s || *end != '\0' || v < 1) return false;
  *out = v;
  return true;
}

static int parse_options(int argc, char** argv, Options* o) {
  o->frames = 400;
  o->print_every = 10;
  o->expect_contact = false;
  for (int i = 1; i < argc; ++i) {
    if (strcmp(argv[i], "--frames") == 0 && i + 1 < argc && parse_count(argv[i + 1], &o->frames)) {
      ++i;
    } else if (strcmp(argv[i], "--print-every") == 0 && i + 1 < argc && parse_count(argv[i + 1], &o->print_every)) {
      ++i;
    } else if (strcmp(argv[i], "--expect-contact") == 0) {
      o->expect_contact = true;
    } else if (strcmp(argv[i], "--help") == 0 || strcmp(argv[i], "-h") == 0) {
      printf(
          "usage: %s [--frames N] [--print-every N] [--expect-contact]\n"
          "  --frames N        frames to run (default 400, about 4.4 s at 90 Hz)\n"
          "  --print-every N   print the right index's forces every N frames (default 10)\n"
          "  --expect-contact  exit 1 unless level 1 and the contact simulation behaved\n",
          argv[0]);
      return -1;
    } else {
      fprintf(stderr, "xr_fingertip_haptics: unknown or malformed option '%s' (try --help)\n", argv[i]);
      return 1;
    }
  }
  return 0;
}

/* ---- instance, system, session ---------------------------------------------------------------------------------- */

/* Returns kExitOk, kExitFailed, or kExitUnsupported when an extension is missing. */
static int create_instance(App* app, bool* headless) {
  uint32_t count = 0;
  if (!xr_ok(app, xrEnumerateInstanceExtensionProperties(NULL, 0, &count, NULL),
             "xrEnumerateInstanceExtensionProperties")) {
    fprintf(stderr, "xr_fingertip_haptics: no usable OpenXR runtime (set XR_RUNTIME_JSON?)\n");
    return kExitFailed;
  }
  XrExtensionProperties* exts = calloc(count ? count : 1, sizeof *exts);
  if (!exts) return kExitFailed;
  for (uint32_t i = 0; i < count; ++i) exts[i].type = XR_TYPE_EXTENSION_PROPERTIES;
  if (!xr_ok(app, xrEnumerateInstanceExtensionProperties(NULL, count, &count, exts),
             "xrEnumerateInstanceExtensionProperties")) {
    free(exts);
    return kExitFailed;
  }
  const bool hand_tracking = offered(exts, count, XR_EXT_HAND_TRACKING_EXTENSION_NAME);
  const bool fingertips = offered(exts, count, XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME);
  *headless = offered(exts, count, XR_MND_HEADLESS_EXTENSION_NAME);
  free(exts);
  if (!hand_tracking || !fingertips) {
    printf(
        "%s not available: enable Proprio's layer (XR_ENABLE_API_LAYERS=XR_APILAYER_PROPRIO_hand_tracking) "
        "with a build that offers it\n",
        !fingertips ? XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME : XR_EXT_HAND_TRACKING_EXTENSION_NAME);
    return kExitUnsupported;
  }
  if (!*headless) {
    printf("note: the runtime does not offer %s; this sample has no graphics binding, so xrCreateSession may fail\n",
           XR_MND_HEADLESS_EXTENSION_NAME);
  }

  const char* enabled[3] = {XR_EXT_HAND_TRACKING_EXTENSION_NAME, XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME,
                            XR_MND_HEADLESS_EXTENSION_NAME};
  XrInstanceCreateInfo info = {.type = XR_TYPE_INSTANCE_CREATE_INFO};
  snprintf(info.applicationInfo.applicationName, sizeof info.applicationInfo.applicationName, "%s",
           "xr_fingertip_haptics");
  info.applicationInfo.applicationVersion = 1;
  info.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
  info.enabledExtensionCount = *headless ? 3u : 2u;
  info.enabledExtensionNames = enabled;
  const XrResult r = xrCreateInstance(&info, &app->instance);
  if (r == XR_ERROR_EXTENSION_NOT_PRESENT) {
    /* Listed (a layer's manifest names it) but refused: the layer's library does not implement it. */
    printf("%s not available: xrCreateInstance gave XR_ERROR_EXTENSION_NOT_PRESENT although it was listed\n",
           XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME);
    return kExitUnsupported;
  }
  if (!xr_ok(app, r, "xrCreateInstance")) return kExitFailed;

  int rc = kExitOk;
#define LOAD(fn) \
  if (rc == kExitOk) rc = load_function(app, #fn, (PFN_xrVoidFunction*)&app->fn)
  LOAD(xrCreateHandTrackerEXT);
  LOAD(xrDestroyHandTrackerEXT);
  LOAD(xrLocateHandJointsEXT);
  LOAD(xrCreateFingertipHapticsPROPRIO);
  LOAD(xrDestroyFingertipHapticsPROPRIO);
  LOAD(xrGetFingertipHapticsPropertiesPROPRIO);
  LOAD(xrApplyFingertipForcesPROPRIO);
  LOAD(xrCreateHapticColliderPROPRIO);
  LOAD(xrSetHapticColliderPosePROPRIO);
  LOAD(xrDestroyHapticColliderPROPRIO);
  LOAD(xrLocateProxyHandJointsPROPRIO);
  LOAD(xrGetFingertipHapticsStatePROPRIO);
#undef LOAD
  return rc;
}

/* Returns kExitOk, kExitFailed, or kExitUnsupported when the system has no fingertip devices. */
static int check_system(App* app) {
  XrSystemGetInfo get = {.type = XR_TYPE_SYSTEM_GET_INFO};
  get.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  if (!xr_ok(app, xrGetSystem(app->instance, &get, &app->system), "xrGetSystem")) return kExitFailed;

  XrSystemFingertipHapticsPropertiesPROPRIO fingertips = {.type = XR_TYPE_SYSTEM_FINGERTIP_HAPTICS_PROPERTIES_PROPRIO};
  XrSystemHandTrackingPropertiesEXT hands = {.type = XR_TYPE_SYSTEM_HAND_TRACKING_PROPERTIES_EXT};
  hands.next = &fingertips;
  XrSystemProperties props = {.type = XR_TYPE_SYSTEM_PROPERTIES};
  props.next = &hands;
  if (!xr_ok(app, xrGetSystemProperties(app->instance, app->system, &props), "xrGetSystemProperties")) {
    return kExitFailed;
  }
  printf("system: %s; hand tracking %s; fingertip haptics %s; contact simulation %s\n", props.systemName,
         hands.supportsHandTracking ? "yes" : "no", fingertips.supportsFingertipHaptics ? "yes" : "no",
         fingertips.supportsContactSimulation ? "yes" : "no");
  if (!hands.supportsHandTracking) {
    printf("%s not available: the system does not support hand tracking\n", XR_EXT_HAND_TRACKING_EXTENSION_NAME);
    return kExitUnsupported;
  }
  if (!fingertips.supportsFingertipHaptics) {
    printf(
        "%s not available: the system has no fingertip devices (check the layer configuration's [haptics] "
        "table)\n",
        XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME);
    return kExitUnsupported;
  }
  app->has_contact_simulation = fingertips.supportsContactSimulation == XR_TRUE;
  if (!app->has_contact_simulation) printf("note: no contact simulation on this system; level 1 only\n");
  return kExitOk;
}

static bool create_session_objects(App* app) {
  XrSessionCreateInfo sinfo = {.type = XR_TYPE_SESSION_CREATE_INFO};
  sinfo.systemId = app->system; /* headless: no graphics binding in next */
  XR_CHECK(app, xrCreateSession(app->instance, &sinfo, &app->session), "xrCreateSession");

  XrReferenceSpaceCreateInfo space = {.type = XR_TYPE_REFERENCE_SPACE_CREATE_INFO};
  space.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_LOCAL;
  space.poseInReferenceSpace.orientation.w = 1.0f;
  XR_CHECK(app, xrCreateReferenceSpace(app->session, &space, &app->local), "xrCreateReferenceSpace");

  for (int h = 0; h < 2; ++h) {
    XrHandTrackerCreateInfoEXT tinfo = {.type = XR_TYPE_HAND_TRACKER_CREATE_INFO_EXT};
    tinfo.hand = h == 0 ? XR_HAND_LEFT_EXT : XR_HAND_RIGHT_EXT;
    tinfo.handJointSet = XR_HAND_JOINT_SET_DEFAULT_EXT;
    XR_CHECK(app, app->xrCreateHandTrackerEXT(app->session, &tinfo, &app->trackers[h]), "xrCreateHandTrackerEXT");
  }
  return true;
}

/* Drains the event queue, beginning and ending the session as the runtime asks. */
static bool poll_events(App* app) {
  for (;;) {
    XrEventDataBuffer event = {.type = XR_TYPE_EVENT_DATA_BUFFER};
    const XrResult r = xrPollEvent(app->instance, &event);
    if (r == XR_EVENT_UNAVAILABLE) return true;
    XR_CHECK(app, r, "xrPollEvent");
    if (event.type == XR_TYPE_EVENT_DATA_INSTANCE_LOSS_PENDING) {
      fprintf(stderr, "xr_fingertip_haptics: instance loss pending\n");
      app->exit_request = true;
      continue;
    }
    if (event.type != XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED) continue;
    const XrEventDataSessionStateChanged* changed = (const XrEventDataSessionStateChanged*)&event;
    switch (changed->state) {
      case XR_SESSION_STATE_READY: {
        XrSessionBeginInfo begin = {.type = XR_TYPE_SESSION_BEGIN_INFO};
        begin.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
        XR_CHECK(app, xrBeginSession(app->session, &begin), "xrBeginSession");
        app->running = true;
        break;
      }
      case XR_SESSION_STATE_STOPPING:
        XR_CHECK(app, xrEndSession(app->session), "xrEndSession");
        app->running = false;
        app->exit_request = true;
        break;
      case XR_SESSION_STATE_EXITING:
      case XR_SESSION_STATE_LOSS_PENDING: app->exit_request = true; break;
      default: break;
    }
  }
}

static void print_properties(XrHandEXT hand, const XrFingertipHapticsPropertiesPROPRIO* p) {
  static const char* const kFinger[XR_FINGERTIP_COUNT_PROPRIO] = {"thumb", "index", "middle", "ring", "little"};
  for (int f = 0; f < XR_FINGERTIP_COUNT_PROPRIO; ++f) {
    const XrFingertipDevicePropertiesPROPRIO* d = &p->fingers[f];
    if (!d->present) {
      printf("  %s %-6s: no device\n", hand == XR_HAND_LEFT_EXT ? "left " : "right", kFinger[f]);
      continue;
    }
    printf(
        "  %s %-6s: \"%s\" %s, %u DoF, max normal %.2f N, max shear %.2f N, max rate %.1f N/s, "
        "friction %.2f, watchdog %.0f ms\n",
        hand == XR_HAND_LEFT_EXT ? "left " : "right", kFinger[f], d->deviceName,
        d->connected ? "connected" : "not connected", d->forceDofCount, (double)d->maxNormalForce,
        (double)d->maxShearForce, (double)d->maxForceRate, (double)d->frictionCoefficient,
        (double)d->watchdogPeriod * 1e-6);
  }
}

static bool create_haptics(App* app) {
  XrFingertipHapticsCreateInfoPROPRIO info = {.type = XR_TYPE_FINGERTIP_HAPTICS_CREATE_INFO_PROPRIO};
  info.contactSimulation = app->has_contact_simulation ? XR_TRUE : XR_FALSE;
  info.worldSpace = app->local;
  const double t0 = now_s();
  XR_CHECK(app, app->xrCreateFingertipHapticsPROPRIO(app->session, &info, &app->haptics),
           "xrCreateFingertipHapticsPROPRIO");
  /* With the contact simulation the layer builds the world for the tracked hands' sizes: a start-up cost. */
  printf("xrCreateFingertipHapticsPROPRIO (contact simulation %s) took %.1f ms\n",
         app->has_contact_simulation ? "on" : "off", (now_s() - t0) * 1e3);
  printf("fingertip devices:\n");
  for (int h = 0; h < 2; ++h) {
    const XrHandEXT hand = h == 0 ? XR_HAND_LEFT_EXT : XR_HAND_RIGHT_EXT;
    XrFingertipHapticsPropertiesPROPRIO props = {.type = XR_TYPE_FINGERTIP_HAPTICS_PROPERTIES_PROPRIO};
    XR_CHECK(app, app->xrGetFingertipHapticsPropertiesPROPRIO(app->haptics, hand, &props),
             "xrGetFingertipHapticsPropertiesPROPRIO");
    print_properties(hand, &props);
  }
  return true;
}

/* ---- per frame ------------------------------------------------------------------------------------------------ */

static bool locate(App* app, bool proxy, XrTime time, XrHandJointLocationEXT joints[XR_HAND_JOINT_COUNT_EXT],
                   bool* active) {
  XrHandJointsLocateInfoEXT info = {.type = XR_TYPE_HAND_JOINTS_LOCATE_INFO_EXT};
  info.baseSpace = app->local;
  info.time = time;
  XrHandJointLocationsEXT locations = {.type = XR_TYPE_HAND_JOINT_LOCATIONS_EXT};
  locations.jointCount = XR_HAND_JOINT_COUNT_EXT;
  locations.jointLocations = joints;
  if (proxy) {
    XR_CHECK(app, app->xrLocateProxyHandJointsPROPRIO(app->haptics, XR_HAND_RIGHT_EXT, &info, &locations),
             "xrLocateProxyHandJointsPROPRIO");
  } else {
    XR_CHECK(app, app->xrLocateHandJointsEXT(app->trackers[1], &info, &locations), "xrLocateHandJointsEXT");
  }
  *active = locations.isActive == XR_TRUE;
  return true;
}

/* The collider's pose: the index tip's, moved along the tip's -Y (into the pad). */
static XrPosef collider_pose(const XrHandJointLocationEXT* tip) {
  const XrVector3f down = {0.0f, -COLLIDER_PAD_OFFSET_M, 0.0f};
  const XrVector3f d = rotate(tip->pose.orientation, down);
  XrPosef pose = tip->pose;
  pose.position.x += d.x;
  pose.position.y += d.y;
  pose.position.z += d.z;
  return pose;
}

static bool place_collider(App* app, XrTime time, const XrHandJointLocationEXT* tip) {
  XrHapticColliderPoseInfoPROPRIO where = {.type = XR_TYPE_HAPTIC_COLLIDER_POSE_INFO_PROPRIO};
  where.space = app->local;
  where.time = time;
  where.pose = collider_pose(tip);
  if (app->collider == XR_NULL_HANDLE) {
    XrHapticColliderCreateInfoPROPRIO info = {.type = XR_TYPE_HAPTIC_COLLIDER_CREATE_INFO_PROPRIO};
    info.shape = XR_HAPTIC_COLLIDER_SHAPE_SPHERE_PROPRIO;
    info.radius = COLLIDER_RADIUS_M;
    info.friction = COLLIDER_FRICTION;
    info.poseInfo = where;
    XR_CHECK(app, app->xrCreateHapticColliderPROPRIO(app->haptics, &info, &app->collider),
             "xrCreateHapticColliderPROPRIO");
    printf("collider: sphere r=%.0f mm at (%.3f, %.3f, %.3f) m in LOCAL, %.0f mm under the index pad\n",
           (double)COLLIDER_RADIUS_M * 1e3, (double)where.pose.position.x, (double)where.pose.position.y,
           (double)where.pose.position.z, (double)COLLIDER_PAD_OFFSET_M * 1e3);
    return true;
  }
  XR_CHECK(app, app->xrSetHapticColliderPosePROPRIO(app->collider, &where), "xrSetHapticColliderPosePROPRIO");
  return true;
}

static bool push_index(App* app, XrTime time) {
  XrFingertipForcesPROPRIO forces = {.type = XR_TYPE_FINGERTIP_FORCES_PROPRIO};
  forces.hand = XR_HAND_RIGHT_EXT;
  forces.baseSpace = XR_NULL_HANDLE; /* each force in its own fingertip frame */
  forces.time = time;
  forces.forces[INDEX].y = LEVEL1_FORCE_N; /* +Y: pressing on the pad */
  XR_CHECK(app, app->xrApplyFingertipForcesPROPRIO(app->haptics, &forces), "xrApplyFingertipForcesPROPRIO");
  return true;
}

typedef struct Loop {
  Phase phase;
  double phase_start_s;
  double last_push_s;
} Loop;

static void enter(Loop* loop, Phase phase, double t) {
  loop->phase = phase;
  loop->phase_start_s = t;
}

/* One frame: wait, begin, the haptics work at predictedDisplayTime, end. */
static bool frame(App* app, long n, const Options* o, Loop* loop, Results* res) {
  XrFrameWaitInfo wait = {.type = XR_TYPE_FRAME_WAIT_INFO};
  XrFrameState fs = {.type = XR_TYPE_FRAME_STATE};
  XR_CHECK(app, xrWaitFrame(app->session, &wait, &fs), "xrWaitFrame");
  XrFrameBeginInfo begin = {.type = XR_TYPE_FRAME_BEGIN_INFO};
  XR_CHECK(app, xrBeginFrame(app->session, &begin), "xrBeginFrame");
  const XrTime t = fs.predictedDisplayTime;
  const double wall = now_s();

  XrHandJointLocationEXT tracked[XR_HAND_JOINT_COUNT_EXT];
  bool tracked_active = false;
  if (!locate(app, false, t, tracked, &tracked_active)) return false;
  const XrHandJointLocationEXT* tip = &tracked[XR_HAND_JOINT_INDEX_TIP_EXT];
  const bool tip_ok = tracked_active && pose_valid(tip);

  XrFingertipHapticsStatePROPRIO state = {.type = XR_TYPE_FINGERTIP_HAPTICS_STATE_PROPRIO};
  XR_CHECK(app, app->xrGetFingertipHapticsStatePROPRIO(app->haptics, XR_HAND_RIGHT_EXT, &state),
           "xrGetFingertipHapticsStatePROPRIO");
  const XrFingertipStatePROPRIO* index = &state.fingers[INDEX];

  switch (loop->phase) {
    case PHASE_WAIT_DEVICE:
      if (index->connected || wall - loop->phase_start_s > CONNECT_WAIT_S) {
        if (!index->connected) printf("note: the right index device is not connected; pushing anyway\n");
        enter(loop, PHASE_LEVEL1_PUSH, wall);
      }
      break;
    case PHASE_LEVEL1_PUSH:
      if (index->commandedForce.y > res->level1_peak_n) res->level1_peak_n = index->commandedForce.y;
      if (wall - loop->phase_start_s >= LEVEL1_SECONDS) {
        res->level1_done = true;
        enter(loop, PHASE_LEVEL1_FADE, wall);
      }
      break;
    case PHASE_LEVEL1_FADE:
      if (res->level1_decay_s < 0.0 && norm(index->commandedForce) < LEVEL1_ZERO_N) {
        res->level1_decay_s = wall - loop->last_push_s;
      }
      if (res->level1_decay_s >= 0.0 || wall - loop->phase_start_s >= LEVEL1_WATCH_S) {
        enter(loop, app->has_contact_simulation ? PHASE_CONTACT : PHASE_IDLE, wall);
      }
      break;
    case PHASE_CONTACT:
      if (app->collider != XR_NULL_HANDLE) {
        /* This frame's state comes after last frame's collider pose. */
        ++res->contact_frames;
        if (index->contactForce.y > res->contact_peak_n) res->contact_peak_n = index->contactForce.y;
        if (index->measuredForce.y > res->measured_peak_n) res->measured_peak_n = index->measuredForce.y;
      }
      if (tip_ok && !place_collider(app, t, tip)) return false;
      break;
    case PHASE_IDLE: break;
  }
  if (loop->phase == PHASE_LEVEL1_PUSH) {
    if (!push_index(app, t)) return false;
    loop->last_push_s = now_s();
  }

  /* The proxy hand: where the app would draw the hand, outside every collider. */
  XrHandJointLocationEXT proxy[XR_HAND_JOINT_COUNT_EXT];
  bool proxy_active = false;
  if (!locate(app, true, t, proxy, &proxy_active)) return false;
  float gap_mm = -1.0f;
  if (proxy_active && tip_ok && pose_valid(&proxy[XR_HAND_JOINT_INDEX_TIP_EXT])) {
    gap_mm = 1e3f * distance(proxy[XR_HAND_JOINT_INDEX_TIP_EXT].pose.position, tip->pose.position);
    if (app->collider != XR_NULL_HANDLE) {
      res->proxy_gap_sum_m += (double)gap_mm * 1e-3;
      ++res->proxy_gap_count;
    }
  }

  if (n % o->print_every == 0) {
    printf(
        "frame %4ld %-7s right index: commanded.y %6.3f N  measured.y %6.3f N  contact.y %6.3f N  gate %-7s  "
        "hand %s  proxy-tip gap %s",
        n, phase_name(loop->phase), (double)index->commandedForce.y, (double)index->measuredForce.y,
        (double)index->contactForce.y, gate_name(index->gateState), tracked_active ? "active" : "inactive",
        gap_mm >= 0.0f ? "" : "n/a\n");
    if (gap_mm >= 0.0f) printf("%.1f mm\n", (double)gap_mm);
  }

  XrFrameEndInfo end = {.type = XR_TYPE_FRAME_END_INFO};
  end.displayTime = t;
  end.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
  end.layerCount = 0; /* headless: nothing to show */
  XR_CHECK(app, xrEndFrame(app->session, &end), "xrEndFrame");
  return true;
}

/* ---- teardown ------------------------------------------------------------------------------------------------- */

/* Asks the runtime to stop and follows the session to EXITING (ending it on the way). */
static bool stop_session(App* app) {
  if (!app->running) return true;
  XR_CHECK(app, xrRequestExitSession(app->session), "xrRequestExitSession");
  for (int i = 0; i < 1000 && app->running; ++i) {
    if (!poll_events(app)) return false;
    if (!app->running) break;
    /* Still running: keep the frame loop going until the runtime says STOPPING. */
    XrFrameWaitInfo wait = {.type = XR_TYPE_FRAME_WAIT_INFO};
    XrFrameState fs = {.type = XR_TYPE_FRAME_STATE};
    XR_CHECK(app, xrWaitFrame(app->session, &wait, &fs), "xrWaitFrame");
    XrFrameBeginInfo begin = {.type = XR_TYPE_FRAME_BEGIN_INFO};
    XR_CHECK(app, xrBeginFrame(app->session, &begin), "xrBeginFrame");
    XrFrameEndInfo end = {.type = XR_TYPE_FRAME_END_INFO};
    end.displayTime = fs.predictedDisplayTime;
    end.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
    XR_CHECK(app, xrEndFrame(app->session, &end), "xrEndFrame");
  }
  if (app->running) {
    fprintf(stderr, "xr_fingertip_haptics: the session never reached STOPPING after xrRequestExitSession\n");
    return false;
  }
  return poll_events(app); /* IDLE, EXITING */
}

/* Destroys what exists, children first. Reports failures; returns false on any. */
static bool destroy_all(App* app) {
  bool ok = true;
  if (app->collider != XR_NULL_HANDLE) {
    ok = xr_ok(app, app->xrDestroyHapticColliderPROPRIO(app->collider), "xrDestroyHapticColliderPROPRIO") && ok;
    app->collider = XR_NULL_HANDLE;
  }
  if (app->haptics != XR_NULL_HANDLE) {
    ok = xr_ok(app, app->xrDestroyFingertipHapticsPROPRIO(app->haptics), "xrDestroyFingertipHapticsPROPRIO") && ok;
    app->haptics = XR_NULL_HANDLE;
  }
  if (app->session != XR_NULL_HANDLE && app->running) ok = stop_session(app) && ok;
  for (int h = 0; h < 2; ++h) {
    if (app->trackers[h] != XR_NULL_HANDLE) {
      ok = xr_ok(app, app->xrDestroyHandTrackerEXT(app->trackers[h]), "xrDestroyHandTrackerEXT") && ok;
      app->trackers[h] = XR_NULL_HANDLE;
    }
  }
  if (app->local != XR_NULL_HANDLE) {
    ok = xr_ok(app, xrDestroySpace(app->local), "xrDestroySpace") && ok;
    app->local = XR_NULL_HANDLE;
  }
  if (app->session != XR_NULL_HANDLE) {
    ok = xr_ok(app, xrDestroySession(app->session), "xrDestroySession") && ok;
    app->session = XR_NULL_HANDLE;
  }
  if (app->instance != XR_NULL_HANDLE) {
    ok = xr_ok(app, xrDestroyInstance(app->instance), "xrDestroyInstance") && ok;
    app->instance = XR_NULL_HANDLE;
  }
  return ok;
}

/* Prints one line per check; returns whether all passed. */
static bool report(const App* app, const Results* r) {
  bool pass = true;
  const bool peak_ok = r->level1_done && r->level1_peak_n > LEVEL1_PEAK_MIN_N;
  const bool decay_ok = r->level1_decay_s >= 0.0 && r->level1_decay_s <= LEVEL1_DECAY_MAX_S;
  printf("level 1: peak commanded.y %.3f N (need > %.2f): %s\n", (double)r->level1_peak_n, (double)LEVEL1_PEAK_MIN_N,
         !r->level1_done ? "FAIL (the push phase did not finish: more --frames)"
         : peak_ok       ? "PASS"
                         : "FAIL");
  if (r->level1_decay_s >= 0.0) {
    printf("level 1: commanded force below %.2f N %.3f s after the last submission (need <= %.1f s): %s\n",
           (double)LEVEL1_ZERO_N, r->level1_decay_s, LEVEL1_DECAY_MAX_S, decay_ok ? "PASS" : "FAIL");
  } else {
    printf("level 1: commanded force never fell below %.2f N after the last submission: FAIL\n", (double)LEVEL1_ZERO_N);
  }
  pass = peak_ok && decay_ok;
  if (app->has_contact_simulation) {
    const bool contact_ok = r->contact_frames > 0 && r->contact_peak_n > CONTACT_MIN_N;
    const bool measured_ok = r->contact_frames > 0 && r->measured_peak_n > CONTACT_MIN_N;
    printf(
        "contact: %ld frames with the collider; peak contact.y %.3f N, peak measured.y %.3f N (need > %.2f "
        "each): %s\n",
        r->contact_frames, (double)r->contact_peak_n, (double)r->measured_peak_n, (double)CONTACT_MIN_N,
        r->contact_frames == 0      ? "FAIL (no collider: the right hand was never tracked, or too few --frames)"
        : contact_ok && measured_ok ? "PASS"
                                    : "FAIL");
    if (r->proxy_gap_count > 0) {
      printf("contact: mean tracked-to-proxy index tip distance %.1f mm\n",
             1e3 * r->proxy_gap_sum_m / (double)r->proxy_gap_count);
    }
    pass = pass && contact_ok && measured_ok;
  } else {
    printf("contact: FAIL (the system has no contact simulation)\n");
    pass = false;
  }
  return pass;
}

int main(int argc, char** argv) {
  Options opts;
  const int parsed = parse_options(argc, argv, &opts);
  if (parsed != 0) return parsed < 0 ? kExitOk : kExitFailed;
  setvbuf(stdout, NULL, _IOLBF, 0);

  App app;
  memset(&app, 0, sizeof app);
  Results res;
  memset(&res, 0, sizeof res);
  res.level1_decay_s = -1.0;

  bool headless = false;
  int rc = create_instance(&app, &headless);
  if (rc == kExitOk) rc = check_system(&app);
  if (rc == kExitOk && !(create_session_objects(&app) && poll_events(&app) && create_haptics(&app))) {
    rc = kExitFailed;
  }
  if (rc != kExitOk) {
    destroy_all(&app);
    return rc;
  }

  Loop loop = {PHASE_WAIT_DEVICE, now_s(), 0.0};
  const double ready_deadline_s = now_s() + 5.0;
  long n = 0;
  bool ok = true;
  while (ok && n < opts.frames) {
    if (!poll_events(&app)) {
      ok = false;
      break;
    }
    if (app.exit_request) {
      printf("the runtime ended the session after %ld frames\n", n);
      break;
    }
    if (!app.running) { /* not READY yet: the runtime queues it right after xrCreateSession */
      if (now_s() > ready_deadline_s) {
        fprintf(stderr, "xr_fingertip_haptics: the session did not become READY within 5 s\n");
        ok = false;
        break;
      }
      struct timespec ms = {0, 1000000};
      nanosleep(&ms, NULL);
      continue;
    }
    ok = frame(&app, n, &opts, &loop, &res);
    ++n;
  }
  if (!ok) {
    destroy_all(&app);
    return kExitFailed;
  }

  const bool pass = report(&app, &res);
  if (!destroy_all(&app)) return kExitFailed;
  if (opts.expect_contact) {
    printf("RESULT: %s\n", pass ? "PASS" : "FAIL");
    return pass ? kExitOk : kExitFailed;
  }
  return kExitOk;
}
