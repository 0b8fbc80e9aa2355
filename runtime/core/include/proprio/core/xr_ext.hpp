#pragma once
// OpenXR definitions newer than Debian's 1.0.20 headers, written from the
// OpenXR specification. Guarded so a newer SDK's own definitions win.
#include <openxr/openxr.h>
#include <time.h>

// XR_KHR_convert_timespec_time lives in the platform header behind this switch.
#ifndef XR_USE_TIMESPEC
#define XR_USE_TIMESPEC
#endif
#include <openxr/openxr_platform.h>

// A zeroed OpenXR struct with its type set: T s{XR_TYPE_...} would trip
// -Wmissing-field-initializers on every use.
template <typename T>
T xr_struct(XrStructureType type) {
  T s{};
  s.type = type;
  return s;
}

#ifndef XR_EXT_hand_tracking_data_source
#define XR_EXT_hand_tracking_data_source 1
#define XR_EXT_hand_tracking_data_source_SPEC_VERSION 1
#define XR_EXT_HAND_TRACKING_DATA_SOURCE_EXTENSION_NAME "XR_EXT_hand_tracking_data_source"

typedef enum XrHandTrackingDataSourceEXT {
  XR_HAND_TRACKING_DATA_SOURCE_UNOBSTRUCTED_EXT = 1,
  XR_HAND_TRACKING_DATA_SOURCE_CONTROLLER_EXT = 2,
  XR_HAND_TRACKING_DATA_SOURCE_MAX_ENUM_EXT = 0x7FFFFFFF
} XrHandTrackingDataSourceEXT;

// Chained to XrHandTrackerCreateInfoEXT.
typedef struct XrHandTrackingDataSourceInfoEXT {
  XrStructureType type;  // XR_TYPE_HAND_TRACKING_DATA_SOURCE_INFO_EXT
  const void* next;
  uint32_t requestedDataSourceCount;
  XrHandTrackingDataSourceEXT* requestedDataSources;
} XrHandTrackingDataSourceInfoEXT;

// Chained to XrHandJointLocationsEXT.
typedef struct XrHandTrackingDataSourceStateEXT {
  XrStructureType type;  // XR_TYPE_HAND_TRACKING_DATA_SOURCE_STATE_EXT
  void* next;
  XrBool32 isActive;
  XrHandTrackingDataSourceEXT dataSource;
} XrHandTrackingDataSourceStateEXT;

inline constexpr XrStructureType XR_TYPE_HAND_TRACKING_DATA_SOURCE_INFO_EXT = static_cast<XrStructureType>(1000428000);
inline constexpr XrStructureType XR_TYPE_HAND_TRACKING_DATA_SOURCE_STATE_EXT = static_cast<XrStructureType>(1000428001);
#endif
