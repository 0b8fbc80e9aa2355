# The rig device as a user runs it (issue 31): an example character written
# as glTF, a device planned for it (plan, instructions, pictures), the plan's
# device emulated on its bus with faults, the character posed live from it
# (headless, recorded, the recording read back), and the benchmark's quick
# run. What is asserted: every step ran and wrote what it says, the host saw
# the device's topology, the pose followed the device, each benchmark case
# ran; the numbers themselves are read by people (docs/benchmarks.md).
# Invoked by ctest with -DPROPRIO=<cli> -DWORK_DIR=<folder>.
file(REMOVE_RECURSE ${WORK_DIR})
file(MAKE_DIRECTORY ${WORK_DIR})
function(run)
  execute_process(COMMAND ${PROPRIO} ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "proprio ${ARGN} failed (${rc}):\n${out}\n${err}")
  endif()
  set(out "${out}" PARENT_SCOPE)
endfunction()

run(rig example quadruped --out ${WORK_DIR}/quadruped.gltf)
run(rig plan ${WORK_DIR}/quadruped.gltf --out ${WORK_DIR}/plan)
foreach(f plan.json assembly.txt assembly.svg error_curve.svg)
  if(NOT EXISTS ${WORK_DIR}/plan/${f})
    message(FATAL_ERROR "rig plan wrote no ${f}:\n${out}")
  endif()
endforeach()
file(READ ${WORK_DIR}/plan/assembly.svg svg)
if(NOT svg MATCHES "<svg" OR NOT svg MATCHES "id=\"module-1\"")
  message(FATAL_ERROR "assembly.svg is not the picture of the plan")
endif()
if(NOT out MATCHES "error reduction with 5 joints")
  message(FATAL_ERROR "rig plan printed no error curve:\n${out}")
endif()

run(rig emulate --plan ${WORK_DIR}/plan/plan.json --character ${WORK_DIR}/quadruped.gltf --seconds 3 --loss 0.02)
if(NOT out MATCHES "host: [0-9]+ components attached" OR NOT out MATCHES "matched the truth at")
  message(FATAL_ERROR "rig emulate showed no topology:\n${out}")
endif()

run(rig live --plan ${WORK_DIR}/plan/plan.json --character ${WORK_DIR}/quadruped.gltf --seconds 3 --fps 5
    --out ${WORK_DIR}/frames --record ${WORK_DIR}/live.prec --size 320x180)
if(NOT EXISTS ${WORK_DIR}/frames/frame_0000.png OR NOT EXISTS ${WORK_DIR}/live.prec)
  message(FATAL_ERROR "rig live wrote no frames or recording:\n${out}")
endif()
if(NOT out MATCHES "mean node position error against the animator")
  message(FATAL_ERROR "rig live compared nothing with the animator:\n${out}")
endif()
run(replay ${WORK_DIR}/live.prec)
foreach(stream rig/device_joints rig/pose rig/truth events)
  if(NOT out MATCHES "${stream}")
    message(FATAL_ERROR "the recording has no ${stream} stream:\n${out}")
  endif()
endforeach()

run(bench rig --quick --json --cases joints bus posing)
foreach(c joints bus posing)
  string(JSON ran GET "${out}" ${c} ran)
  if(NOT ran)
    message(FATAL_ERROR "bench rig: the ${c} case did not run:\n${out}")
  endif()
endforeach()
string(JSON mean GET "${out}" joints overall mean_deg)
if(NOT mean GREATER 0 OR NOT mean LESS 5)
  message(FATAL_ERROR "bench rig: joint error ${mean} deg is not a measurement:\n${out}")
endif()
