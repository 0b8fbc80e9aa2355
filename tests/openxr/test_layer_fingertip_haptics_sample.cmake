# openxr.fingertip_haptics_sample: samples/xr_fingertip_haptics (a plain C OpenXR app) through Debian's real loader
# on the mock runtime, with this build's layer enabled and the configuration tests/data/layer_fingertip_haptics.toml
# (simulated hands bound to LOCAL, emulated fingertip devices, contact simulation on). The sample pushes 0.8 N on the
# right index for 0.5 s and checks it fades out, then keeps a sphere collider under the index pad and checks the
# contact and measured forces (--expect-contact; its output says what it saw).
#
# Included by samples/xr_fingertip_haptics/CMakeLists.txt at the end of the top-level CMakeLists (after tests/ has
# defined the mock runtime). Like every test, it runs what the last build made: build everything (or at least
# xr_fingertip_haptics, XrApiLayer_proprio_hand_tracking and proprio_mock_openxr_runtime) first. Exit status 2 from
# the sample means the layer does not offer XR_PROPRIO_fingertip_haptics, or offers it without devices: a failure
# here.
# Not in the sanitizer builds: they build only the sanitized test programs
# (./dev's ASAN_TARGETS), so the sample would be registered but never built.
if(NOT PROPRIO_BUILD_TESTS OR PROPRIO_SANITIZE OR NOT TARGET xr_fingertip_haptics
   OR NOT TARGET proprio_mock_openxr_runtime OR NOT TARGET XrApiLayer_proprio_hand_tracking)
  return()
endif()

get_property(_fth_runtime_json GLOBAL PROPERTY PROPRIO_MOCK_RUNTIME_JSON)
get_property(_fth_layer_manifest GLOBAL PROPERTY PROPRIO_LAYER_MANIFEST)
get_filename_component(_fth_layer_dir ${_fth_layer_manifest} DIRECTORY)
# XDG homes of its own: no user-installed (implicit) layer or user configuration leaks in.
set(_fth_home ${PROJECT_BINARY_DIR}/tests/openxr/fingertip_haptics_sample_home)
file(MAKE_DIRECTORY ${_fth_home}/config ${_fth_home}/data)

set(_fth_env
  XR_RUNTIME_JSON=${_fth_runtime_json}
  XR_API_LAYER_PATH=${_fth_layer_dir}
  XR_ENABLE_API_LAYERS=XR_APILAYER_PROPRIO_hand_tracking
  PROPRIO_LAYER_CONFIG=${PROJECT_SOURCE_DIR}/tests/data/layer_fingertip_haptics.toml
  XDG_CONFIG_HOME=${_fth_home}/config
  XDG_DATA_HOME=${_fth_home}/data
  LSAN_OPTIONS=suppressions=${PROJECT_SOURCE_DIR}/tests/openxr/mock_runtime/lsan.supp)
# As layer_test::use_mock_runtime_with_layer: none of the developer's mock-runtime switches or plugin override.
set(_fth_unset)
foreach(_v PROPRIO_MOCK_RUNTIME_HAND_TRACKING PROPRIO_MOCK_RUNTIME_CONTROLLERS PROPRIO_MOCK_RUNTIME_TRACKERS
           PROPRIO_MOCK_RUNTIME_DISCONNECT PROPRIO_MOCK_RUNTIME_EXIT_AFTER_FRAMES PROPRIO_MOCK_RUNTIME_MONADO_HEADLESS
           PROPRIO_PLUGIN_DIR)
  list(APPEND _fth_unset "${_v}=unset:")
endforeach()

add_test(NAME openxr.fingertip_haptics_sample COMMAND xr_fingertip_haptics --frames 400 --expect-contact)
set_tests_properties(openxr.fingertip_haptics_sample PROPERTIES
  LABELS integration
  TIMEOUT 120
  # Real time: the level-1 check times the force's fade on the wall clock, and the emulated devices and the contact
  # simulation run on the layer's 1 kHz thread. A machine starved by parallel tests changes the outcome.
  RUN_SERIAL TRUE
  ENVIRONMENT "${_fth_env}"
  ENVIRONMENT_MODIFICATION "${_fth_unset}")
