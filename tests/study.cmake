# proprio::study: designs, procedures, crash-safe sessions, psychometric fits,
# statistics. Included from tests/CMakeLists.txt once the library exists.
if(PROPRIO_BUILD_TESTS AND TARGET proprio::study)
  proprio_add_test(study_tests
    SOURCES
      unit/test_study_psychometric.cpp
      unit/test_study_statistics.cpp
      unit/test_study_csv_plot.cpp
      unit/test_study_design.cpp
      unit/test_study_procedure.cpp
      unit/test_study_session.cpp
    DEPS proprio::study nlohmann_json::nlohmann_json)
  # The shipped example designs are read from the source tree.
  target_compile_definitions(study_tests PRIVATE PROPRIO_SOURCE_DIR="${PROJECT_SOURCE_DIR}")

  # Monte Carlo checks (bootstrap coverage over 100 simulated experiments):
  # seconds in the main build, minutes under ASan, so label "study", not "unit".
  proprio_add_test(study_accuracy_tests
    LABEL study
    SOURCES
      unit/test_study_coverage.cpp
    DEPS proprio::study)
endif()
