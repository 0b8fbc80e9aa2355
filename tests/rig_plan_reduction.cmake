# Rig reduction (issue 31, thesis §3.2.2 and App. A.2): the reachability fit,
# greedy joint placement, the splitter ILP and the device plan they produce.
if(PROPRIO_BUILD_TESTS AND TARGET proprio::rig_plan)
  proprio_add_test(rig_plan_reduction_tests
    SOURCES
      unit/input/rig_plan/test_plan.cpp
      unit/input/rig_plan/test_rig_fit.cpp
      unit/input/rig_plan/test_rig_reduction.cpp
      unit/input/rig_plan/test_splitter_ilp.cpp
    DEPS proprio::rig_plan)
endif()
