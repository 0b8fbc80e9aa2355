# `proprio bench haptics --json` as a user runs it (issue 29): every case runs
# as specified, or the command fails. The two-hand case must have the thumb
# and index of both hands pinching the peg in every timed tick. Timings are read
# by people (docs/benchmarks.md), never asserted here.
# Invoked by ctest with -DPROPRIO=<cli>.
execute_process(COMMAND ${PROPRIO} bench haptics --seconds 0.5 --no-realtime --json
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "proprio bench haptics failed (${rc}):\n${out}\n${err}")
endif()
foreach(key mujoco_step_us servo_tick_us two_hands_servo_tick_us)
  string(JSON value ERROR_VARIABLE missing GET "${out}" ${key} p50)
  if(missing OR NOT value GREATER 0)
    message(FATAL_ERROR "no ${key}.p50 in:\n${out}")
  endif()
endforeach()
string(JSON devices GET "${out}" two_hands_servo_tick_us devices)
string(JSON pressing GET "${out}" two_hands_servo_tick_us fingertips_pressing_the_peg)
string(JSON least GET "${out}" two_hands_servo_tick_us least_pad_force_n)
if(NOT devices EQUAL 6 OR NOT pressing EQUAL 4 OR NOT least GREATER 0.05)
  message(FATAL_ERROR "two-hand case: ${devices} devices, ${pressing} fingertips on the peg (least ${least} N):\n${out}")
endif()
