# The rig device's modules (issue 31): kit files, the Hall joint simulator,
# its calibration and the joint accuracy benchmark's function.
if(PROPRIO_BUILD_TESTS)
  proprio_add_test(rig_device_tests
    SOURCES
      unit/input/rig_device/test_joint_kinematics.cpp
      unit/input/rig_device/test_kit.cpp
      unit/input/rig_device/test_hall_joint.cpp
      unit/input/rig_device/test_joint_calibration.cpp
      unit/input/rig_device/test_joint_accuracy.cpp
    DEPS proprio::rig_device)
  target_compile_definitions(rig_device_tests PRIVATE PROPRIO_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
endif()

# The kit reader (parse_kit_toml) under arbitrary text.
list(APPEND PROPRIO_FUZZ_TARGETS rig_kit_toml)
set(PROPRIO_FUZZ_DEPS_rig_kit_toml proprio::rig_device)
