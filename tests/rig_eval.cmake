# The rig device's simulated posing task (issue 31, thesis §3.3): included
# from tests/CMakeLists.txt once the library exists.
if(PROPRIO_BUILD_TESTS AND TARGET proprio::rig_eval)
  proprio_add_test(rig_eval_tests
    SOURCES
      unit/input/rig_eval/test_posing_device.cpp
      unit/input/rig_eval/test_simulated_user.cpp
      unit/input/rig_eval/test_posing_task.cpp
    DEPS proprio::rig_eval nlohmann_json::nlohmann_json)
endif()
