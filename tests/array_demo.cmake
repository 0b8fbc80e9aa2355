# `proprio run array-demo` end to end (issue 30): the live stretch-array
# pipeline (simulated wearer, emulated board over the fake HID cable, read-out,
# tiny regressor, ARAP) drawn headless on lavapipe, a few small frames. The
# command fails (exit 1) when no frame was reconstructed.
if(PROPRIO_BUILD_TESTS AND TARGET proprio::engine AND TARGET proprio::stretch_array_eval AND TARGET proprio)
  add_test(NAME array_demo_cli.headless
    COMMAND proprio run array-demo --model ${CMAKE_CURRENT_SOURCE_DIR}/data/stretch_array_eval/tiny_p92.onnx
            --seconds 2 --rest-seconds 0.5 --fps 5 --size 160x90 --software
            --out ${CMAKE_CURRENT_BINARY_DIR}/array_demo_cli)
  set_tests_properties(array_demo_cli.headless PROPERTIES LABELS render TIMEOUT 60
    PASS_REGULAR_EXPRESSION "10 frames \\(headless\\).*array: [1-9][0-9]* frames")
endif()
