# The stretch array's offline chain as a user runs it (issue 30): a few
# simulated seconds written as a dataset, the three regressors trained
# (--tiny: seconds), and every one of them benchmarked on the test sessions
# through OpenCV DNN and ARAP. Each model must have run on every test session
# with finite errors, and the speed case must have run; the numbers themselves
# are read by people (docs/benchmarks.md), never asserted here.
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
run(sim-array --motion elbow --train-minutes 0.15 --test-minutes 0.05 --out ${WORK_DIR}/elbow --threads 2)
run(train array ${WORK_DIR}/elbow --out ${WORK_DIR}/models --tiny --threads 1)
foreach(kind dnn lr svm)
  if(NOT EXISTS ${WORK_DIR}/models/${kind}/model.onnx OR NOT EXISTS ${WORK_DIR}/models/${kind}/model.json)
    message(FATAL_ERROR "train array wrote no ${kind} model")
  endif()
endforeach()
run(bench array --cases none --dataset ${WORK_DIR}/elbow --models ${WORK_DIR}/models --json)
string(JSON rows LENGTH "${out}" dataset)
# Two test sessions (the same donning and the re-donned one) per model.
if(NOT rows EQUAL 6)
  message(FATAL_ERROR "expected 3 models x 2 test sessions, got ${rows}:\n${out}")
endif()
math(EXPR last "${rows} - 1")
foreach(i RANGE ${last})
  string(JSON ran GET "${out}" dataset ${i} ran)
  string(JSON markers GET "${out}" dataset ${i} marker_error_mm mean)
  string(JSON vertices GET "${out}" dataset ${i} vertex_error_mm mean)
  if(NOT ran OR NOT markers GREATER 0 OR NOT markers LESS 1000 OR NOT vertices GREATER 0 OR NOT vertices LESS 1000)
    message(FATAL_ERROR "dataset row ${i}: ran ${ran}, markers ${markers} mm, vertices ${vertices} mm:\n${out}")
  endif()
endforeach()
string(JSON speed_ran GET "${out}" speed ran)
string(JSON uniaxial_ran GET "${out}" uniaxial ran)
if(NOT speed_ran OR uniaxial_ran)
  message(FATAL_ERROR "speed must have run and the flat cases not (--cases none):\n${out}")
endif()
