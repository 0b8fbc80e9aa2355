if(PROPRIO_BUILD_TESTS)
  # The MuJoCo contact simulation, virtual coupling, force laws and the servo loop.
  proprio_add_test(haptics_sim_tests
    SOURCES
      unit/test_contact_sim.cpp
      unit/test_servo_loop.cpp
      unit/test_hid_channels.cpp
    DEPS proprio::haptics)
  target_compile_definitions(haptics_sim_tests PRIVATE PROPRIO_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
endif()
