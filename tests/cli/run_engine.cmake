# proprio run as a user runs it: headless PNG frames, and (when xvfb-run is
# there) a real window under a virtual X server. Both with Vulkan validation,
# which fails the run on any validation error.
file(REMOVE_RECURSE ${WORK_DIR})
file(MAKE_DIRECTORY ${WORK_DIR})
execute_process(
  COMMAND ${PROPRIO} run half-cylinder --headless --frames 12 --size 320x180 --software --validation
          --out ${WORK_DIR}/frames
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "proprio run --headless failed (${rc}):\n${out}\n${err}")
endif()
if(NOT EXISTS ${WORK_DIR}/frames/frame_0011.png OR EXISTS ${WORK_DIR}/frames/frame_0012.png)
  message(FATAL_ERROR "expected exactly 12 frames in ${WORK_DIR}/frames:\n${out}")
endif()
if(NOT out MATCHES "12 frames \\(headless\\)")
  message(FATAL_ERROR "unexpected report:\n${out}")
endif()

if(NOT out MATCHES "tracked hand in 12 of them")
  message(FATAL_ERROR "the scripted touch hand must be there in every frame:\n${out}")
endif()

# The skinned hand look, and the real-time sources the OpenXR layer also
# serves: the stretch glove's simulated wearer and a VIST session through the
# tracker. These run in real time, so the first frames may come before the
# first pose: most frames, not all, must have the hand.
execute_process(
  COMMAND ${PROPRIO} run half-cylinder --headless --frames 30 --size 160x90 --mono --software --hands glove
          --hand-look skinned --haptics none --out ${WORK_DIR}/glove
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0 OR NOT out MATCHES "tracked hand in ([0-9]+) of them")
  message(FATAL_ERROR "proprio run --hands glove failed (${rc}):\n${out}\n${err}")
endif()
if(CMAKE_MATCH_1 LESS 15)
  message(FATAL_ERROR "the simulated glove wearer's hand was in only ${CMAKE_MATCH_1} of 30 frames:\n${out}")
endif()

execute_process(
  COMMAND ${PROPRIO} sim-vist --subject 5 --seconds 4 --out ${WORK_DIR}/vist.prec --force
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "proprio sim-vist failed (${rc}):\n${out}\n${err}")
endif()
execute_process(
  COMMAND ${PROPRIO} run half-cylinder --headless --frames 40 --size 160x90 --mono --software
          --hands vist ${WORK_DIR}/vist.prec --haptics none --out ${WORK_DIR}/vist
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0 OR NOT out MATCHES "tracked hand in ([0-9]+) of them")
  message(FATAL_ERROR "proprio run --hands vist failed (${rc}):\n${out}\n${err}")
endif()
if(CMAKE_MATCH_1 LESS 10)
  message(FATAL_ERROR "the VIST-tracked hand was in only ${CMAKE_MATCH_1} of 40 frames:\n${out}")
endif()

# What a user gets wrong gets an error that says what to do.
foreach(case
    "--hands;vist|VIST session recording"
    "--hands;glove;device|--glove-calibration"
    "--hands;glove;bluetooth|choose sim"
    "--hand-look;skined|choose joints, skinned"
    "--haptics;hid;--hid-device;pinky=X|pinky")
  string(REPLACE "|" ";" parts "${case}")
  list(GET parts -1 expected)
  list(REMOVE_AT parts -1)
  execute_process(COMMAND ${PROPRIO} run half-cylinder --headless --frames 1 ${parts}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(rc EQUAL 0 OR NOT err MATCHES "${expected}")
    message(FATAL_ERROR "proprio run ${parts} must fail saying '${expected}' (${rc}):\n${out}\n${err}")
  endif()
endforeach()

execute_process(COMMAND ${PROPRIO} run nope.toml --headless RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(rc EQUAL 0 OR NOT err MATCHES "nope.toml")
  message(FATAL_ERROR "a missing scene file must fail naming it (${rc}):\n${err}")
endif()

find_program(XVFB_RUN xvfb-run)
if(XVFB_RUN)
  # 24-bit screen: xvfb-run's default 8-bit visual has no Vulkan-presentable format.
  execute_process(
    COMMAND ${XVFB_RUN} -a -s "-screen 0 1280x800x24"
            ${PROPRIO} run half-cylinder --window --frames 10 --size 480x270 --software --validation
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err TIMEOUT 120)
  if(NOT rc EQUAL 0 OR NOT out MATCHES "10 frames \\(window\\)")
    message(FATAL_ERROR "proprio run --window under Xvfb failed (${rc}):\n${out}\n${err}")
  endif()
else()
  message(STATUS "xvfb-run not installed: window smoke test skipped")
endif()
