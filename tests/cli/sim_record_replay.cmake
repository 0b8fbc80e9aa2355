# End-to-end check of the CLI as a user runs it: simulate, record, replay,
# determinism of the bytes, truncated-file recovery and clear errors.
# Invoked by ctest with -DPROPRIO=<cli> -DWORK_DIR=<scratch dir>.
file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")

function(run_ok)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "command failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
  set(OUT "${out}" PARENT_SCOPE)
  set(ERR "${err}" PARENT_SCOPE)
endfunction()

function(expect_contains text needle)
  string(FIND "${text}" "${needle}" at)
  if(at EQUAL -1)
    message(FATAL_ERROR "expected to find '${needle}' in:\n${text}")
  endif()
endfunction()

set(a "${WORK_DIR}/a.prec")
set(b "${WORK_DIR}/b.prec")
run_ok(${PROPRIO} sim-hand --subject 4 --protocol free-motion --seconds 7 --seed 9 --out ${a})
run_ok(${PROPRIO} sim-hand --subject 4 --protocol free-motion --seconds 7 --seed 9 --out ${b})
file(SHA256 "${a}" ha)
file(SHA256 "${b}" hb)
if(NOT ha STREQUAL hb)
  message(FATAL_ERROR "same seed gave different bytes")
endif()
run_ok(${PROPRIO} sim-hand --subject 4 --protocol free-motion --seconds 7 --seed 10 --out ${b} --force)
file(SHA256 "${b}" hb)
if(ha STREQUAL hb)
  message(FATAL_ERROR "different seeds gave identical files")
endif()

# Refuses to overwrite without --force, with a message that says so.
execute_process(COMMAND ${PROPRIO} sim-hand --seconds 1 --out ${a} RESULT_VARIABLE rc ERROR_VARIABLE err OUTPUT_QUIET)
if(rc EQUAL 0)
  message(FATAL_ERROR "sim-hand overwrote an existing file without --force")
endif()

run_ok(${PROPRIO} replay ${a} --summary --plot ${WORK_DIR}/a.svg --records 3)
expect_contains("${OUT}" "hand/right/ground_truth")
expect_contains("${OUT}" "Integrity: clean")
expect_contains("${OUT}" "90.0 Hz")
expect_contains("${OUT}" "refused")
expect_contains("${OUT}" " 0 refused")
if(NOT EXISTS "${WORK_DIR}/a.svg")
  message(FATAL_ERROR "no plot written")
endif()

# A crash mid-write: cut the file in the middle of a record. Replay must still
# read everything before the cut and say the file was truncated.
file(SIZE "${a}" size)
math(EXPR cut "${size} * 2 / 3 + 7")
execute_process(COMMAND head -c ${cut} "${a}" OUTPUT_FILE "${WORK_DIR}/cut.prec")
run_ok(${PROPRIO} replay ${WORK_DIR}/cut.prec --summary)
expect_contains("${OUT}" "Integrity: truncated")

# Garbage in: a clear error, non-zero exit.
file(WRITE "${WORK_DIR}/junk.prec" "this is not a recording at all")
execute_process(COMMAND ${PROPRIO} replay ${WORK_DIR}/junk.prec RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(rc EQUAL 0)
  message(FATAL_ERROR "replay accepted a junk file")
endif()
expect_contains("${err}" "not a Proprio recording")

# Bad arguments are refused with the valid range.
execute_process(COMMAND ${PROPRIO} sim-hand --subject 99 --out ${WORK_DIR}/x.prec RESULT_VARIABLE rc ERROR_VARIABLE err OUTPUT_QUIET)
if(rc EQUAL 0)
  message(FATAL_ERROR "sim-hand accepted subject 99")
endif()
message(STATUS "CLI end-to-end checks passed")
