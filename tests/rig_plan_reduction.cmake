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

# Planning time and error curves, run by hand (input/rig_plan/bench/reduction_bench.cpp); not a test.
if(PROPRIO_BUILD_BENCHMARKS AND TARGET proprio::rig_plan)
  add_executable(rig_reduction_bench ${PROJECT_SOURCE_DIR}/input/rig_plan/bench/reduction_bench.cpp)
  target_include_directories(rig_reduction_bench PRIVATE ${CMAKE_CURRENT_SOURCE_DIR})
  target_link_libraries(rig_reduction_bench PRIVATE proprio::rig_plan proprio::options)
  if(TARGET proprio::rig_characters)
    target_link_libraries(rig_reduction_bench PRIVATE proprio::rig_characters)
    target_compile_definitions(rig_reduction_bench PRIVATE PROPRIO_BENCH_WITH_CHARACTERS)
  endif()
endif()
