# Fingertip device models and the safety gate (haptics/models.cmake).
if(PROPRIO_BUILD_TESTS)
  proprio_add_test(haptics_model_tests
    SOURCES
      unit/haptics/test_device_models.cpp
      unit/haptics/test_haptic_safety.cpp
    DEPS proprio::haptics)
  target_compile_definitions(haptics_model_tests PRIVATE PROPRIO_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
endif()
