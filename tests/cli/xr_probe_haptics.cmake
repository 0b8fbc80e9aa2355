# `proprio xr-probe --haptics` as a user runs it (issue 29): Debian's loader,
# the mock runtime, this build's layer with tests/data/layer_fingertip_haptics.toml
# (six emulated fingertip devices). Every device is listed (ring and little
# without one), the presses wait for focus and the gates, each device is
# pressed (measured 0.1 N or more) and released (commanded and measured under
# 0.01 N within 0.2 s), and the command exits 0.
# Invoked by ctest with -DPROPRIO=<cli> -DMOCK_RUNTIME_JSON=... -DLAYER_DIR=... -DCONFIG=...
set(ENV{XR_RUNTIME_JSON} "${MOCK_RUNTIME_JSON}")
set(ENV{XR_API_LAYER_PATH} "${LAYER_DIR}")
set(ENV{XR_ENABLE_API_LAYERS} "XR_APILAYER_PROPRIO_hand_tracking")
set(ENV{PROPRIO_LAYER_CONFIG} "${CONFIG}")
foreach(v PROPRIO_MOCK_RUNTIME_HAND_TRACKING PROPRIO_MOCK_RUNTIME_CONTROLLERS PROPRIO_MOCK_RUNTIME_TRACKERS
          PROPRIO_MOCK_RUNTIME_DISCONNECT PROPRIO_PLUGIN_DIR)
  unset(ENV{${v}})
endforeach()
execute_process(COMMAND ${PROPRIO} xr-probe --haptics RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "xr-probe --haptics failed (${rc}):\n${out}\n${err}")
endif()
foreach(hand left right)
  foreach(finger thumb index middle)
    if(NOT out MATCHES "${hand} +${finger} +platform_3dof \\(emulated\\) +connected, 3 DoF, max normal 1\\.50 N, max shear 1\\.00 N")
      message(FATAL_ERROR "no device line for the ${hand} ${finger} in:\n${out}")
    endif()
    if(NOT out MATCHES "${hand} +${finger} +commanded 0\\.[45][0-9] N, measured [0-9]\\.[0-9][0-9] N, released after [0-9]+ ms \\(measured below 0\\.01 N after [0-9]+ ms\\): ok")
      message(FATAL_ERROR "no passing press for the ${hand} ${finger} in:\n${out}")
    endif()
  endforeach()
endforeach()
foreach(hand left right)
  if(NOT out MATCHES "${hand} +no device: ring, little")
    message(FATAL_ERROR "no 'no device' line for the ${hand} hand in:\n${out}")
  endif()
endforeach()
if(NOT out MATCHES "FOCUSED after [0-9.]+ s, gates active after [0-9.]+ s more")
  message(FATAL_ERROR "no focus/gates line in:\n${out}")
endif()
if(NOT out MATCHES "All 6 fingertip devices pressed and released")
  message(FATAL_ERROR "unexpected summary:\n${out}")
endif()
