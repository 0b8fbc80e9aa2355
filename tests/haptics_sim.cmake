if(PROPRIO_BUILD_TESTS)
  # The MuJoCo contact simulation, virtual coupling, force laws and the servo loop.
  proprio_add_test(haptics_sim_tests
    SOURCES
      unit/haptics/test_contact_sim.cpp
      unit/haptics/test_servo_loop.cpp
      unit/haptics/test_hid_channels.cpp
      unit/haptics/test_touch_script.cpp
    DEPS proprio::haptics)
  target_compile_definitions(haptics_sim_tests PRIVATE PROPRIO_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
endif()

# `proprio haptics sim`, the demo's press: the summary names the peak contact
# force (16 N, on the tip's end) and the peak commanded force, which is the
# band's 2 N limit, not the 0 N a pad-frame projection gave.
if(PROPRIO_BUILD_TESTS AND TARGET proprio)
  add_test(NAME haptics_sim_cli.tip_end_press_is_rendered COMMAND proprio haptics sim --seconds 2)
  set_tests_properties(haptics_sim_cli.tip_end_press_is_rendered PROPERTIES
    PASS_REGULAR_EXPRESSION "peak contact force 1[0-9]\\.[0-9][0-9] N[^\n]*\n[^\n]*\n  peak commanded force [0-9.]+ N \\(2\\.00 N normal")
endif()
