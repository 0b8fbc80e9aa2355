# The rig device's commands end to end (issue 31).
if(PROPRIO_BUILD_TESTS AND PROPRIO_BUILD_TOOLS AND NOT PROPRIO_SANITIZE AND TARGET proprio::rig_live)
  add_test(NAME cli.rig_plan_live
    COMMAND ${CMAKE_COMMAND} -DPROPRIO=$<TARGET_FILE:proprio> -DWORK_DIR=${CMAKE_CURRENT_BINARY_DIR}/cli_rig_work
            -P ${CMAKE_CURRENT_SOURCE_DIR}/cli/rig_plan_live.cmake)
  # rig live runs the emulated bus and the engine in real time.
  set_tests_properties(cli.rig_plan_live PROPERTIES LABELS integration TIMEOUT 300 RUN_SERIAL TRUE)
endif()
