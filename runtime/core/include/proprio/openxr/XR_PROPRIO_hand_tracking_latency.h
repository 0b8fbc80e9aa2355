/* XR_PROPRIO_hand_tracking_latency: how old the sensor data behind each hand
 * pose served by Proprio's OpenXR layer was. Provisional: the name, the
 * structure type value and the layout may change before it is registered.
 * Spec page: docs/xr-proprio-hand-tracking-latency.md.
 *
 * An app enables the extension at xrCreateInstance (the layer lists it when it
 * is active), gets the function with xrGetInstanceProcAddr and reads, per
 * XrHandTrackerEXT, two histograms over every xrLocateHandJointsEXT call that
 * returned an active hand since the tracker was created:
 *   sampleToReady: from the newest sensor sample behind the pose (an IMU or
 *     capacitance measurement, a camera frame's capture) to the moment the
 *     pose built from it could first be served;
 *   ageAtLocate: from that sample to the xrLocateHandJointsEXT call.
 * Times are CLOCK_MONOTONIC; bins are binWidthMs wide, the last one counts
 * everything at or beyond (binCount - 1) * binWidthMs. */
#ifndef XR_PROPRIO_HAND_TRACKING_LATENCY_H_
#define XR_PROPRIO_HAND_TRACKING_LATENCY_H_ 1

#include <openxr/openxr.h>

#ifdef __cplusplus
extern "C" {
#endif

#define XR_PROPRIO_hand_tracking_latency 1
#define XR_PROPRIO_hand_tracking_latency_SPEC_VERSION 1
#define XR_PROPRIO_HAND_TRACKING_LATENCY_EXTENSION_NAME "XR_PROPRIO_hand_tracking_latency"
/* Outside every registered range: Khronos assigns 1000000000 + 1000 * (n - 1) + k. */
#define XR_TYPE_HAND_TRACKING_LATENCY_PROPRIO ((XrStructureType)1999001000)
#define XR_PROPRIO_LATENCY_BIN_COUNT 128

typedef struct XrHandTrackingLatencyPROPRIO {
  XrStructureType type;
  void* XR_MAY_ALIAS next;
  uint32_t binCount;   /* out: XR_PROPRIO_LATENCY_BIN_COUNT */
  float binWidthMs;    /* out */
  uint64_t poseCount;  /* out: active poses returned */
  float maxSampleToReadyMs;
  float maxAgeAtLocateMs;
  uint64_t sampleToReady[XR_PROPRIO_LATENCY_BIN_COUNT];
  uint64_t ageAtLocate[XR_PROPRIO_LATENCY_BIN_COUNT];
} XrHandTrackingLatencyPROPRIO;

typedef XrResult(XRAPI_PTR* PFN_xrGetHandTrackingLatencyPROPRIO)(XrHandTrackerEXT handTracker,
                                                                  XrHandTrackingLatencyPROPRIO* latency);

#ifdef __cplusplus
}
#endif

#endif
