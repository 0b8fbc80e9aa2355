# samples/perception_threshold and samples/hmd_calibration: protocol geometry, cue, force law, observer
# model, the live frame hook (unit), and the simulated study end to end:
# resume after a crash and threshold recovery over seeds (label study).
if(PROPRIO_BUILD_TESTS AND TARGET proprio::perception_threshold)
  proprio_add_test(perception_tests
    SOURCES perception/test_perception.cpp perception/test_hmd_calibration.cpp
    DEPS proprio::perception_threshold proprio::hmd_calibration)
  target_compile_definitions(perception_tests PRIVATE PROPRIO_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    PROPRIO_TEST_OUT_DIR="${CMAKE_CURRENT_BINARY_DIR}/perception_out")
  proprio_add_test(perception_study_tests
    LABEL study
    SOURCES perception/test_perception_study.cpp
    DEPS proprio::perception_threshold nlohmann_json::nlohmann_json)
  target_compile_definitions(perception_study_tests PRIVATE PROPRIO_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    PROPRIO_TEST_OUT_DIR="${CMAKE_CURRENT_BINARY_DIR}/perception_out")
endif()
