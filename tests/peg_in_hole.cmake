# samples/peg_in_hole: the peg-in-hole study (docs/peg-in-hole.md).
if(PROPRIO_BUILD_TESTS AND TARGET proprio::peg_in_hole)
  # Rules, config, randomisation, the conditions through the servo loop, and
  # the completion-time analysis: seconds.
  proprio_add_test(peg_in_hole_tests
    SOURCES
      peg_in_hole/test_peg_rules.cpp
      peg_in_hole/test_completion_time.cpp
    DEPS proprio::peg_in_hole)
  # Whole simulated sessions: crash and resume, the settings' ordering over
  # seeds (label "study": a minute or more).
  proprio_add_test(peg_in_hole_study_tests
    LABEL study
    SOURCES
      peg_in_hole/test_peg_study.cpp
    DEPS proprio::peg_in_hole)
  # Development aid: one traced simulated trial (setting, trial, seconds).
  add_executable(peg_probe peg_in_hole/probe.cpp)
  target_link_libraries(peg_probe PRIVATE proprio::peg_in_hole proprio::options)
endif()
