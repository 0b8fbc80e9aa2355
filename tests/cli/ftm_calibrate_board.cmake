# End-to-end check of `proprio calibrate ftm` and `proprio ftm-board`: the
# guided calibration of a simulated wearer, the same wearer behind the board
# emulator (the real bytes over the in-memory HID link, in real time), and the
# board's self-test. Hostile inputs are in tests/hostile/cases_ftm_cli.py.
# Invoked by ctest with -DPROPRIO=<cli> -DWORK_DIR=<scratch dir>.
file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")

function(run_ok)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "command failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
  set(OUT "${out}" PARENT_SCOPE)
endfunction()

function(expect_in text needle what)
  string(FIND "${text}" "${needle}" at)
  if(at EQUAL -1)
    message(FATAL_ERROR "${what}: expected '${needle}' in:\n${text}")
  endif()
endfunction()

# beta1 of one bend sensor from a calibration file.
function(read_beta1 file sensor var)
  file(READ "${file}" text)
  if(NOT text MATCHES "\\[bend\\.${sensor}\\][^[]*beta1_rad_per_pF = ([-0-9.e]+)")
    message(FATAL_ERROR "${file}: no beta1 for ${sensor}:\n${text}")
  endif()
  set(${var} "${CMAKE_MATCH_1}" PARENT_SCOPE)
endfunction()

# The simulated wearer, saved per user under XDG_CONFIG_HOME.
set(ENV{XDG_CONFIG_HOME} "${WORK_DIR}/config")
run_ok(${PROPRIO} calibrate ftm --subject 3 --user alice)
foreach(step "figure-eight done" "pose 1 taken" "pose 2 taken" "pose 3 taken" "residuals:" "Wrote")
  expect_in("${OUT}" "${step}" "calibrate ftm --subject 3")
endforeach()
set(sim_file "${WORK_DIR}/config/proprio/ftm/alice_right.toml")
if(NOT EXISTS "${sim_file}")
  message(FATAL_ERROR "calibrate ftm --user alice did not write ${sim_file}:\n${OUT}")
endif()
file(READ "${sim_file}" text)
expect_in("${text}" "subject = \"alice\"" "the per-user file")

# The same wearer behind the emulated board: the host reads the real bytes.
# A board carries no wrist tracker, so the dorsum mounting stays nominal, but
# the bend sensors' lines come from the same samples and must agree.
set(emu_file "${WORK_DIR}/emulated.toml")
run_ok(${PROPRIO} calibrate ftm --subject 3 --emulate --out ${emu_file})
expect_in("${OUT}" "no wrist tracker: kept nominal" "calibrate ftm --emulate")
foreach(sensor thumb_mcp index_pip middle_pip)
  read_beta1("${sim_file}" ${sensor} b_sim)
  read_beta1("${emu_file}" ${sensor} b_emu)
  # CMake has no floating-point arithmetic: awk checks |b_emu / b_sim - 1| < 2 %.
  execute_process(COMMAND awk -v a=${b_sim} -v b=${b_emu} "BEGIN { r = b / a - 1; exit (a != 0 && r < 0.02 && r > -0.02) ? 0 : 1 }"
                  RESULT_VARIABLE close)
  if(NOT close EQUAL 0)
    message(FATAL_ERROR "${sensor}: beta1 ${b_sim} (simulated) vs ${b_emu} (emulated board) differ by 2 % or more")
  endif()
endforeach()

# The board's own self-test, faults included.
run_ok(${PROPRIO} ftm-board emulate --seconds 2 --corrupt 0.01 --unplug 0.8:0.3)
expect_in("${OUT}" "self-test PASSED" "ftm-board emulate")
run_ok(${PROPRIO} ftm-board list)
