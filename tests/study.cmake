# proprio::study: designs, procedures, crash-safe sessions, psychometric fits,
# statistics. Included from tests/CMakeLists.txt once the library exists.
if(PROPRIO_BUILD_TESTS AND TARGET proprio::study)
  proprio_add_test(study_tests
    SOURCES
      unit/runtime/study/test_study_psychometric.cpp
      unit/runtime/study/test_study_bootstrap.cpp
      unit/runtime/study/test_study_statistics.cpp
      unit/runtime/study/test_study_csv_plot.cpp
      unit/runtime/study/test_study_design.cpp
      unit/runtime/study/test_study_procedure.cpp
      unit/runtime/study/test_study_session.cpp
      unit/runtime/study/test_study_analysis.cpp
    DEPS proprio::study nlohmann_json::nlohmann_json)
  # The shipped example designs are read from the source tree.
  target_compile_definitions(study_tests PRIVATE PROPRIO_SOURCE_DIR="${PROJECT_SOURCE_DIR}")

  # Monte Carlo checks (bootstrap coverage over 100 simulated experiments):
  # seconds in the main build, minutes under ASan, so label "study", not "unit".
  proprio_add_test(study_accuracy_tests
    LABEL study
    SOURCES
      unit/runtime/study/test_study_coverage.cpp
    DEPS proprio::study)
endif()

# The CLI end to end (label integration): the fit against Palamedes' answers,
# the RM-ANOVA example, and `study analyze` on a demo study written by a
# helper with simulated observers.
if(PROPRIO_BUILD_TESTS AND TARGET proprio::study)
  add_executable(study_demo_sessions study/make_demo_sessions.cpp)
  target_link_libraries(study_demo_sessions PRIVATE proprio::study proprio::options)
endif()
if(PROPRIO_BUILD_TESTS AND TARGET proprio::study AND TARGET proprio)
  set(_study_data ${CMAKE_CURRENT_SOURCE_DIR}/study/data)
  add_test(NAME study_cli.psychometric_fit
    COMMAND proprio psychometric fit --data ${_study_data}/palamedes_demo.csv --model weibull --guess 0.5
            --lapse 0 --threshold 0.75 --bootstrap 200 --seed 3 --json)
  set_tests_properties(study_cli.psychometric_fit PROPERTIES LABELS integration
    PASS_REGULAR_EXPRESSION "\"alpha\": 0\\.06915[34]")
  add_test(NAME study_cli.rm_anova COMMAND proprio stats rm-anova --data ${_study_data}/rm_anova_example.csv --json)
  set_tests_properties(study_cli.rm_anova PROPERTIES LABELS integration
    PASS_REGULAR_EXPRESSION "\"gg_epsilon\": 0\\.64689")
  add_test(NAME study_cli.bad_csv COMMAND proprio psychometric fit --data ${_study_data}/rm_anova_example.csv)
  set_tests_properties(study_cli.bad_csv PROPERTIES LABELS integration WILL_FAIL TRUE)
  set(_demo_dir ${CMAKE_CURRENT_BINARY_DIR}/study_demo)
  add_test(NAME study_cli.demo_clean COMMAND ${CMAKE_COMMAND} -E rm -rf ${_demo_dir})
  add_test(NAME study_cli.demo_sessions
    COMMAND study_demo_sessions ${PROJECT_SOURCE_DIR}/config/studies/perception_threshold.toml ${_demo_dir} 4 1)
  add_test(NAME study_cli.analyze COMMAND proprio study analyze ${_demo_dir} --bootstrap 100)
  set_tests_properties(study_cli.demo_clean PROPERTIES LABELS integration FIXTURES_SETUP study_demo_clean)
  set_tests_properties(study_cli.demo_sessions PROPERTIES LABELS integration FIXTURES_REQUIRED study_demo_clean
    FIXTURES_SETUP study_demo)
  set_tests_properties(study_cli.analyze PROPERTIES LABELS integration FIXTURES_REQUIRED study_demo
    PASS_REGULAR_EXPRESSION "repeated-measures ANOVA")
endif()

# The CSV reader's fuzz target (tests/fuzz/fuzz_csv_reader.cpp, seeds in
# tests/fuzz/corpus/csv_reader/), built by the loop in tests/CMakeLists.txt.
if(TARGET proprio::study)
  list(APPEND PROPRIO_FUZZ_TARGETS csv_reader)
  set(PROPRIO_FUZZ_DEPS_csv_reader proprio::study)
endif()
