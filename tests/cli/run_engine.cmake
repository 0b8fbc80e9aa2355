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
