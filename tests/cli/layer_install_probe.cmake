# The OpenXR layer as a developer sets it up (docs/openxr-layer.md): write a
# config, install the manifest, check status, see simulated hands in
# xr-probe on the mock runtime, uninstall. Everything under a fake home.
# Invoked by ctest with -DPROPRIO=<cli> -DWORK_DIR=<dir> -DMOCK_RUNTIME_JSON=<json> -DLSAN_SUPP=<file>.
file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}/home")
set(ENV_ARGS
  HOME=${WORK_DIR}/home
  XDG_CONFIG_HOME=${WORK_DIR}/home/.config
  XDG_DATA_HOME=${WORK_DIR}/home/.local/share
  XR_RUNTIME_JSON=${MOCK_RUNTIME_JSON}
  XR_ENABLE_API_LAYERS=XR_APILAYER_PROPRIO_hand_tracking
  LSAN_OPTIONS=suppressions=${LSAN_SUPP})

function(run expected_rc)
  execute_process(COMMAND ${CMAKE_COMMAND} -E env --unset=XR_API_LAYER_PATH --unset=PROPRIO_LAYER_CONFIG ${ENV_ARGS}
                          ${PROPRIO} ${ARGN}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL expected_rc)
    message(FATAL_ERROR "proprio ${ARGN}: exit ${rc}, expected ${expected_rc}\n${out}\n${err}")
  endif()
  set(OUT "${out}${err}" PARENT_SCOPE)
endfunction()

function(expect_contains text needle)
  string(FIND "${text}" "${needle}" at)
  if(at EQUAL -1)
    message(FATAL_ERROR "expected '${needle}' in:\n${text}")
  endif()
endfunction()

# Before anything is installed the layer would not load.
run(1 layer status)

run(0 layer init-config)
if(NOT EXISTS "${WORK_DIR}/home/.config/proprio/layer.toml")
  message(FATAL_ERROR "init-config did not write ~/.config/proprio/layer.toml")
endif()
run(1 layer init-config)  # refuses to overwrite

run(0 layer install --user)
file(GLOB manifests "${WORK_DIR}/home/.local/share/openxr/1/api_layers/explicit.d/*.json")
list(LENGTH manifests n)
if(NOT n EQUAL 1)
  message(FATAL_ERROR "expected one installed explicit manifest, found: ${manifests}")
endif()
run(0 layer status)

run(0 xr-probe --seconds 1.5 --space local)
expect_contains("${OUT}" "Proprio mock runtime")
# The mock runs headless frames, so the probe stays headless (no Vulkan fallback).
expect_contains("${OUT}" "Session: headless (XR_MND_headless)")
expect_contains("${OUT}" "left")
expect_contains("${OUT}" "right")

run(0 layer uninstall --user)
run(1 layer status)
message(STATUS "layer install/probe/uninstall checks passed")
