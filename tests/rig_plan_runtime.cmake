# The runtime side of a rig device plan (issue 31, thesis §3.2.2): pose-space
# interpolation, retargeting, plans as JSON, binding a live device, assembly
# instructions. Included by tests/CMakeLists.txt at top level.
if(PROPRIO_BUILD_TESTS AND TARGET proprio::rig_plan)
  proprio_add_test(rig_plan_runtime_tests
    SOURCES
      unit/input/rig_plan/test_pose_space.cpp
      unit/input/rig_plan/test_retarget.cpp
      unit/input/rig_plan/test_plan_io.cpp
      unit/input/rig_plan/test_binding.cpp
      unit/input/rig_plan/test_assembly.cpp
      unit/input/rig_plan/test_joint_ranges.cpp
    DEPS proprio::rig_plan nlohmann_json::nlohmann_json)
endif()
if(TARGET proprio::rig_plan)
  list(APPEND PROPRIO_FUZZ_TARGETS rig_plan_json)
  set(PROPRIO_FUZZ_DEPS_rig_plan_json proprio::rig_plan)
endif()
