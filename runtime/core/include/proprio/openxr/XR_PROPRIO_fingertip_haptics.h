/* XR_PROPRIO_fingertip_haptics: calibrated fingertip forces, in newtons, on the
 * cutaneous fingertip devices Proprio's OpenXR layer drives. Provisional: the
 * name, the structure type values and the layouts may change before it is
 * registered. Spec page: docs/xr-proprio-fingertip-haptics.md.
 *
 * This header is all an app needs: it depends on <openxr/openxr.h> only and
 * every function is reached through xrGetInstanceProcAddr.
 *
 * Two levels:
 *   forces   the app submits, per hand, one 3-D force per finger (the force
 *            the virtual world exerts on the fingertip, in that fingertip
 *            joint's frame or in any XrSpace at an XrTime). The layer renders
 *            it through each device's model and safety gate (clamp, rate
 *            limit, ramp-in) on its own 1 kHz thread. A force not submitted
 *            again fades to zero within the device's watchdog period.
 *   contact  the app registers colliders (spheres, boxes, capsules,
 *            cylinders) and moves them each frame; the layer simulates a proxy
 *            hand coupled to each tracked hand (virtual coupling, both hands
 *            in one world) and renders the proxies' contact forces. The app
 *            locates the proxy hands, which never go through a collider, with
 *            the XR_EXT_hand_tracking structures.
 * Forces from both levels and from xrApplyHapticFeedback add up before the
 * safety gate; whatever the app submits, no device exceeds its limits.
 *
 * Frames: the fingertip frame is the XR_HAND_JOINT_*_TIP_EXT joint's (+Y out
 * of the nail, +Z back along the distal bone toward the wrist). A force that
 * presses on the pad points along +Y. */
#ifndef XR_PROPRIO_FINGERTIP_HAPTICS_H_
#define XR_PROPRIO_FINGERTIP_HAPTICS_H_ 1

#include <openxr/openxr.h>

#ifdef __cplusplus
extern "C" {
#endif

#define XR_PROPRIO_fingertip_haptics 1
#define XR_PROPRIO_fingertip_haptics_SPEC_VERSION 1
#define XR_PROPRIO_FINGERTIP_HAPTICS_EXTENSION_NAME "XR_PROPRIO_fingertip_haptics"

XR_DEFINE_HANDLE(XrFingertipHapticsPROPRIO)
XR_DEFINE_HANDLE(XrHapticColliderPROPRIO)

/* Outside every registered range, like XR_PROPRIO_hand_tracking_latency's. */
#define XR_TYPE_SYSTEM_FINGERTIP_HAPTICS_PROPERTIES_PROPRIO ((XrStructureType)1999002000)
#define XR_TYPE_FINGERTIP_HAPTICS_CREATE_INFO_PROPRIO ((XrStructureType)1999002001)
#define XR_TYPE_FINGERTIP_HAPTICS_PROPERTIES_PROPRIO ((XrStructureType)1999002002)
#define XR_TYPE_FINGERTIP_FORCES_PROPRIO ((XrStructureType)1999002003)
#define XR_TYPE_HAPTIC_COLLIDER_CREATE_INFO_PROPRIO ((XrStructureType)1999002004)
#define XR_TYPE_HAPTIC_COLLIDER_POSE_INFO_PROPRIO ((XrStructureType)1999002005)
#define XR_TYPE_FINGERTIP_HAPTICS_STATE_PROPRIO ((XrStructureType)1999002006)
#define XR_OBJECT_TYPE_FINGERTIP_HAPTICS_PROPRIO ((XrObjectType)1999002000)
#define XR_OBJECT_TYPE_HAPTIC_COLLIDER_PROPRIO ((XrObjectType)1999002001)

/* Fingers, thumb first: the index into every per-finger array below. */
#define XR_FINGERTIP_THUMB_PROPRIO 0
#define XR_FINGERTIP_INDEX_PROPRIO 1
#define XR_FINGERTIP_MIDDLE_PROPRIO 2
#define XR_FINGERTIP_RING_PROPRIO 3
#define XR_FINGERTIP_LITTLE_PROPRIO 4
#define XR_FINGERTIP_COUNT_PROPRIO 5
#define XR_MAX_FINGERTIP_DEVICE_NAME_SIZE_PROPRIO 64
/* The most colliders one XrFingertipHapticsPROPRIO holds at a time. */
#define XR_MAX_HAPTIC_COLLIDERS_PROPRIO 32

/* Chained to XrSystemProperties: whether the layer has fingertip devices
 * configured. When false, xrCreateFingertipHapticsPROPRIO returns
 * XR_ERROR_FEATURE_UNSUPPORTED. */
typedef struct XrSystemFingertipHapticsPropertiesPROPRIO {
  XrStructureType type;
  void* XR_MAY_ALIAS next;
  XrBool32 supportsFingertipHaptics;
  XrBool32 supportsContactSimulation;
} XrSystemFingertipHapticsPropertiesPROPRIO;

typedef struct XrFingertipHapticsCreateInfoPROPRIO {
  XrStructureType type;
  const void* XR_MAY_ALIAS next;
  /* XR_TRUE: run the contact simulation (level 2). */
  XrBool32 contactSimulation;
  /* Contact simulation only: a space that stays still in the world (a LOCAL
   * or STAGE reference space), where the colliders and the proxy hands
   * are. Ignored (may be XR_NULL_HANDLE) without the simulation. */
  XrSpace worldSpace;
} XrFingertipHapticsCreateInfoPROPRIO;

typedef struct XrFingertipDevicePropertiesPROPRIO {
  XrBool32 present;        /* a device is configured on this finger */
  XrBool32 connected;      /* ... and answering now */
  uint32_t forceDofCount;  /* 1: normal only; 2: normal + one shear axis; 3: normal + both shear axes */
  float maxNormalForce;    /* N, pressing on the pad */
  float maxShearForce;     /* N, across the pad */
  float maxForceRate;      /* N/s, per component */
  float frictionCoefficient; /* |shear| <= this x normal */
  XrDuration watchdogPeriod; /* ns: a force not submitted again is zero after this */
  char deviceName[XR_MAX_FINGERTIP_DEVICE_NAME_SIZE_PROPRIO];
} XrFingertipDevicePropertiesPROPRIO;

typedef struct XrFingertipHapticsPropertiesPROPRIO {
  XrStructureType type;
  void* XR_MAY_ALIAS next;
  XrFingertipDevicePropertiesPROPRIO fingers[XR_FINGERTIP_COUNT_PROPRIO];
} XrFingertipHapticsPropertiesPROPRIO;

/* Level 1. One force per finger; fingers without a device are ignored.
 * baseSpace XR_NULL_HANDLE: each force is in its own fingertip frame and time
 * is ignored. Otherwise each force is in baseSpace and the layer turns it
 * into the fingertip frame of the tracked hand at `time`. */
typedef struct XrFingertipForcesPROPRIO {
  XrStructureType type;
  const void* XR_MAY_ALIAS next;
  XrHandEXT hand;
  XrSpace baseSpace;
  XrTime time;
  XrVector3f forces[XR_FINGERTIP_COUNT_PROPRIO]; /* N, the force on the fingertip */
} XrFingertipForcesPROPRIO;

typedef enum XrHapticColliderShapePROPRIO {
  XR_HAPTIC_COLLIDER_SHAPE_SPHERE_PROPRIO = 1,    /* radius */
  XR_HAPTIC_COLLIDER_SHAPE_BOX_PROPRIO = 2,       /* halfExtents */
  XR_HAPTIC_COLLIDER_SHAPE_CAPSULE_PROPRIO = 3,   /* radius, halfLength of the segment along +Z */
  XR_HAPTIC_COLLIDER_SHAPE_CYLINDER_PROPRIO = 4,  /* radius, halfLength along +Z */
  XR_HAPTIC_COLLIDER_SHAPE_MAX_ENUM_PROPRIO = 0x7FFFFFFF
} XrHapticColliderShapePROPRIO;

/* Where a collider is: pose in space at time (the layer locates space in the
 * haptics object's worldSpace). */
typedef struct XrHapticColliderPoseInfoPROPRIO {
  XrStructureType type;
  const void* XR_MAY_ALIAS next;
  XrSpace space;
  XrTime time;
  XrPosef pose;
} XrHapticColliderPoseInfoPROPRIO;

typedef struct XrHapticColliderCreateInfoPROPRIO {
  XrStructureType type;
  const void* XR_MAY_ALIAS next;
  XrHapticColliderShapePROPRIO shape;
  float radius;           /* m: sphere, capsule, cylinder */
  float halfLength;       /* m: capsule, cylinder */
  XrVector3f halfExtents; /* m: box */
  float friction;         /* Coulomb coefficient against skin, 0..2; 0.8 is plastic */
  XrHapticColliderPoseInfoPROPRIO poseInfo;
} XrHapticColliderCreateInfoPROPRIO;

typedef enum XrFingertipGateStatePROPRIO {
  XR_FINGERTIP_GATE_STATE_OFF_PROPRIO = 0,       /* no device, or output disabled (focus lost) */
  XR_FINGERTIP_GATE_STATE_RAMPING_PROPRIO = 1,   /* ramping in after engaging */
  XR_FINGERTIP_GATE_STATE_ACTIVE_PROPRIO = 2,
  XR_FINGERTIP_GATE_STATE_FAULTED_PROPRIO = 3,   /* a non-finite force was submitted: zero until the next good one */
  XR_FINGERTIP_GATE_STATE_MAX_ENUM_PROPRIO = 0x7FFFFFFF
} XrFingertipGateStatePROPRIO;

typedef struct XrFingertipStatePROPRIO {
  XrFingertipGateStatePROPRIO gateState;
  XrBool32 connected;
  XrVector3f commandedForce; /* N, fingertip frame: what the gate let through */
  XrVector3f measuredForce;  /* N, fingertip frame: the device's force sensors, or its last command */
  XrVector3f contactForce;   /* N, fingertip frame: the proxy's contact force as the pad feels it */
} XrFingertipStatePROPRIO;

typedef struct XrFingertipHapticsStatePROPRIO {
  XrStructureType type;
  void* XR_MAY_ALIAS next;
  XrTime time; /* when the layer's 1 kHz thread wrote it */
  XrFingertipStatePROPRIO fingers[XR_FINGERTIP_COUNT_PROPRIO];
} XrFingertipHapticsStatePROPRIO;

typedef XrResult(XRAPI_PTR* PFN_xrCreateFingertipHapticsPROPRIO)(XrSession session,
                                                                  const XrFingertipHapticsCreateInfoPROPRIO* createInfo,
                                                                  XrFingertipHapticsPROPRIO* haptics);
typedef XrResult(XRAPI_PTR* PFN_xrDestroyFingertipHapticsPROPRIO)(XrFingertipHapticsPROPRIO haptics);
typedef XrResult(XRAPI_PTR* PFN_xrGetFingertipHapticsPropertiesPROPRIO)(XrFingertipHapticsPROPRIO haptics,
                                                                         XrHandEXT hand,
                                                                         XrFingertipHapticsPropertiesPROPRIO* properties);
typedef XrResult(XRAPI_PTR* PFN_xrApplyFingertipForcesPROPRIO)(XrFingertipHapticsPROPRIO haptics,
                                                                const XrFingertipForcesPROPRIO* forces);
typedef XrResult(XRAPI_PTR* PFN_xrCreateHapticColliderPROPRIO)(XrFingertipHapticsPROPRIO haptics,
                                                                const XrHapticColliderCreateInfoPROPRIO* createInfo,
                                                                XrHapticColliderPROPRIO* collider);
typedef XrResult(XRAPI_PTR* PFN_xrSetHapticColliderPosePROPRIO)(XrHapticColliderPROPRIO collider,
                                                                 const XrHapticColliderPoseInfoPROPRIO* poseInfo);
typedef XrResult(XRAPI_PTR* PFN_xrDestroyHapticColliderPROPRIO)(XrHapticColliderPROPRIO collider);
typedef XrResult(XRAPI_PTR* PFN_xrLocateProxyHandJointsPROPRIO)(XrFingertipHapticsPROPRIO haptics, XrHandEXT hand,
                                                                 const XrHandJointsLocateInfoEXT* locateInfo,
                                                                 XrHandJointLocationsEXT* locations);
typedef XrResult(XRAPI_PTR* PFN_xrGetFingertipHapticsStatePROPRIO)(XrFingertipHapticsPROPRIO haptics, XrHandEXT hand,
                                                                    XrFingertipHapticsStatePROPRIO* state);

#ifdef __cplusplus
}
#endif

#endif
