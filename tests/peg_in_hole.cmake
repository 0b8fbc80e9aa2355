# samples/peg_in_hole: the peg-in-hole study (docs/peg-in-hole.md).
if(PROPRIO_BUILD_TESTS AND TARGET proprio::peg_in_hole)
  # Rules, config, randomisation, the conditions through the servo loop, and
  # the completion-time analysis: seconds.
  proprio_add_test(peg_in_hole_tests
    SOURCES
      peg_in_hole/test_peg_rules.cpp
      peg_in_hole/test_completion_time.cpp
      peg_in_hole/test_peg_ftm.cpp
    DEPS proprio::peg_in_hole proprio::ftm_sim proprio::sim)
  # Whole simulated sessions: crash and resume, the settings' ordering over
  # seeds (label "study": a minute or more).
  proprio_add_test(peg_in_hole_study_tests
    LABEL study
    SOURCES
      peg_in_hole/test_peg_study.cpp
    DEPS proprio::peg_in_hole nlohmann_json::nlohmann_json)
  # Development aid: one traced simulated trial (setting, trial, seconds).
  add_executable(peg_probe peg_in_hole/probe.cpp)
  target_link_libraries(peg_probe PRIVATE proprio::peg_in_hole proprio::options)
endif()

# The CLI end to end: a simulated study with its analysis (integration; with
# quick.toml's 1.5 s timeout most trials time out, and data where every time is
# equal make the ANOVA "not testable" rather than a number), and a
# real-participant session rendered headless on lavapipe with the scripted
# touch hand (render).
if(PROPRIO_BUILD_TESTS AND TARGET proprio::peg_in_hole AND TARGET proprio)
  set(_peg_out ${CMAKE_CURRENT_BINARY_DIR}/peg_in_hole_cli)
  add_test(NAME peg_in_hole_cli.simulated_study
    COMMAND proprio run peg-in-hole --participant sim --participants 2 --seed 4 --force
            --design ${CMAKE_CURRENT_SOURCE_DIR}/peg_in_hole/quick.toml --out ${_peg_out}/sim)
  set_tests_properties(peg_in_hole_cli.simulated_study PROPERTIES LABELS integration
    PASS_REGULAR_EXPRESSION "RM-ANOVA \\(rounds.*(Greenhouse-Geisser|not testable)")
  add_test(NAME peg_in_hole_cli.live_headless
    COMMAND proprio run peg-in-hole --participant P01 --headless --software --size 320x180 --force
            --design ${CMAKE_CURRENT_SOURCE_DIR}/peg_in_hole/quick.toml --out ${_peg_out}/live)
  set_tests_properties(peg_in_hole_cli.live_headless PROPERTIES LABELS render
    PASS_REGULAR_EXPRESSION "20 trials recorded")
endif()
