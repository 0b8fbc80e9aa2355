#pragma once
// The OpenXR loader <-> layer/runtime negotiation interface. Debian's OpenXR
// SDK 1.0.20 does not ship openxr_loader_negotiation.h (or the older
// loader_interfaces.h), so these are written from the OpenXR loader
// specification ("API Layer Interaction" / "Runtime Interaction"). Layout must
// match the loader's exactly: plain C structs, same member order and types.
#include <openxr/openxr.h>

#include <cstddef>
#include <cstdint>

extern "C" {

#define PROPRIO_XR_CURRENT_LOADER_API_LAYER_VERSION 1
#define PROPRIO_XR_CURRENT_LOADER_RUNTIME_VERSION 1
#define PROPRIO_XR_LOADER_INFO_STRUCT_VERSION 1
#define PROPRIO_XR_API_LAYER_INFO_STRUCT_VERSION 1
#define PROPRIO_XR_RUNTIME_INFO_STRUCT_VERSION 1
#define PROPRIO_XR_API_LAYER_NEXT_INFO_STRUCT_VERSION 1
#define PROPRIO_XR_API_LAYER_CREATE_INFO_STRUCT_VERSION 1
#define PROPRIO_XR_API_LAYER_MAX_SETTINGS_PATH_SIZE 512

typedef enum XrLoaderInterfaceStructs {
  XR_LOADER_INTERFACE_STRUCT_UNINTIALIZED = 0,  // sic: the spelling of the spec
  XR_LOADER_INTERFACE_STRUCT_LOADER_INFO,
  XR_LOADER_INTERFACE_STRUCT_API_LAYER_REQUEST,
  XR_LOADER_INTERFACE_STRUCT_RUNTIME_REQUEST,
  XR_LOADER_INTERFACE_STRUCT_API_LAYER_CREATE_INFO,
  XR_LOADER_INTERFACE_STRUCT_API_LAYER_NEXT_INFO,
  XR_LOADER_INTERFACE_STRUCTS_MAX_ENUM = 0x7FFFFFFF
} XrLoaderInterfaceStructs;

typedef struct XrNegotiateLoaderInfo {
  XrLoaderInterfaceStructs structType;  // XR_LOADER_INTERFACE_STRUCT_LOADER_INFO
  uint32_t structVersion;               // PROPRIO_XR_LOADER_INFO_STRUCT_VERSION
  size_t structSize;                    // sizeof(XrNegotiateLoaderInfo)
  uint32_t minInterfaceVersion;
  uint32_t maxInterfaceVersion;
  XrVersion minApiVersion;
  XrVersion maxApiVersion;
} XrNegotiateLoaderInfo;

struct XrApiLayerCreateInfo;
typedef XrResult(XRAPI_PTR* PFN_xrCreateApiLayerInstance)(const XrInstanceCreateInfo* info,
                                                          const struct XrApiLayerCreateInfo* apiLayerInfo,
                                                          XrInstance* instance);

typedef struct XrNegotiateApiLayerRequest {
  XrLoaderInterfaceStructs structType;  // XR_LOADER_INTERFACE_STRUCT_API_LAYER_REQUEST
  uint32_t structVersion;               // PROPRIO_XR_API_LAYER_INFO_STRUCT_VERSION
  size_t structSize;                    // sizeof(XrNegotiateApiLayerRequest)
  uint32_t layerInterfaceVersion;       // filled by the layer
  XrVersion layerApiVersion;            // filled by the layer
  PFN_xrGetInstanceProcAddr getInstanceProcAddr;         // filled by the layer
  PFN_xrCreateApiLayerInstance createApiLayerInstance;  // filled by the layer
} XrNegotiateApiLayerRequest;

typedef struct XrNegotiateRuntimeRequest {
  XrLoaderInterfaceStructs structType;  // XR_LOADER_INTERFACE_STRUCT_RUNTIME_REQUEST
  uint32_t structVersion;               // PROPRIO_XR_RUNTIME_INFO_STRUCT_VERSION
  size_t structSize;                    // sizeof(XrNegotiateRuntimeRequest)
  uint32_t runtimeInterfaceVersion;     // filled by the runtime
  XrVersion runtimeApiVersion;          // filled by the runtime
  PFN_xrGetInstanceProcAddr getInstanceProcAddr;  // filled by the runtime
} XrNegotiateRuntimeRequest;

typedef struct XrApiLayerNextInfo {
  XrLoaderInterfaceStructs structType;  // XR_LOADER_INTERFACE_STRUCT_API_LAYER_NEXT_INFO
  uint32_t structVersion;               // PROPRIO_XR_API_LAYER_NEXT_INFO_STRUCT_VERSION
  size_t structSize;                    // sizeof(XrApiLayerNextInfo)
  char layerName[XR_MAX_API_LAYER_NAME_SIZE];  // name of the layer this describes
  PFN_xrGetInstanceProcAddr nextGetInstanceProcAddr;
  PFN_xrCreateApiLayerInstance nextCreateApiLayerInstance;
  struct XrApiLayerNextInfo* next;  // the info for the layer after that one
} XrApiLayerNextInfo;

typedef struct XrApiLayerCreateInfo {
  XrLoaderInterfaceStructs structType;  // XR_LOADER_INTERFACE_STRUCT_API_LAYER_CREATE_INFO
  uint32_t structVersion;               // PROPRIO_XR_API_LAYER_CREATE_INFO_STRUCT_VERSION
  size_t structSize;                    // sizeof(XrApiLayerCreateInfo)
  void* loaderInstance;                 // opaque; layers must not use it
  char settings_file_location[PROPRIO_XR_API_LAYER_MAX_SETTINGS_PATH_SIZE];
  XrApiLayerNextInfo* nextInfo;
} XrApiLayerCreateInfo;

typedef XrResult(XRAPI_PTR* PFN_xrNegotiateLoaderApiLayerInterface)(const XrNegotiateLoaderInfo* loaderInfo,
                                                                   const char* layerName,
                                                                   XrNegotiateApiLayerRequest* apiLayerRequest);
typedef XrResult(XRAPI_PTR* PFN_xrNegotiateLoaderRuntimeInterface)(const XrNegotiateLoaderInfo* loaderInfo,
                                                                  XrNegotiateRuntimeRequest* runtimeRequest);

}  // extern "C"
