# proprio::render: CPU-side unit tests (also under ASan), and the Vulkan tests
# on lavapipe (label render: golden images, overlay, allocation; main suite only).
if(PROPRIO_BUILD_TESTS AND TARGET proprio::render)
  proprio_add_test(render_geometry_tests
    SOURCES unit/render/test_render_geometry.cpp
    DEPS proprio::render)

  proprio_add_test(render_tests
    LABEL render
    SOURCES render/test_render.cpp render/test_skinned_hands.cpp
    DEPS proprio::render nlohmann_json::nlohmann_json)
  target_include_directories(render_tests PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/render)
  # The test replaces global operator new/delete (malloc/free) to count
  # allocations; GCC 12 then flags gtest's `new TestClass` as mismatched.
  target_compile_options(render_tests PRIVATE -Wno-mismatched-new-delete)
  target_compile_definitions(render_tests PRIVATE
    PROPRIO_GOLDEN_DIR="${CMAKE_CURRENT_SOURCE_DIR}/data/golden"
    PROPRIO_GOLDEN_OUT_DIR="${CMAKE_CURRENT_BINARY_DIR}/golden_out")
endif()

if(PROPRIO_BUILD_TESTS AND TARGET proprio::engine)
  proprio_add_test(engine_scene_tests
    SOURCES unit/runtime/engine/test_engine_scene.cpp unit/runtime/engine/test_recentred_hands.cpp
      unit/runtime/engine/test_wrist_calibration.cpp
    DEPS proprio::engine)

  proprio_add_test(engine_tests
    LABEL render
    SOURCES render/test_engine_headless.cpp
    DEPS proprio::engine)
  target_include_directories(engine_tests PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/render)
  target_compile_definitions(engine_tests PRIVATE
    PROPRIO_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    PROPRIO_GOLDEN_DIR="${CMAKE_CURRENT_SOURCE_DIR}/data/golden"
    PROPRIO_GOLDEN_OUT_DIR="${CMAKE_CURRENT_BINARY_DIR}/golden_out")
endif()

if(PROPRIO_BUILD_TESTS AND PROPRIO_BUILD_TOOLS AND TARGET proprio::engine)
  add_test(NAME cli.run_engine
    COMMAND ${CMAKE_COMMAND}
      -DPROPRIO=$<TARGET_FILE:proprio>
      -DWORK_DIR=${CMAKE_CURRENT_BINARY_DIR}/cli_run_work
      -P ${CMAKE_CURRENT_SOURCE_DIR}/cli/run_engine.cmake)
  set_tests_properties(cli.run_engine PROPERTIES LABELS "integration;render" TIMEOUT 300)
endif()

if(PROPRIO_BUILD_TESTS AND PROPRIO_BUILD_BENCHMARKS AND TARGET proprio_bench AND TARGET proprio::render)
  target_sources(proprio_bench PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/bench/bench_render.cpp)
  target_link_libraries(proprio_bench PRIVATE proprio::render)
endif()

if(PROPRIO_BUILD_TESTS AND TARGET proprio::engine AND TARGET proprio_mock_openxr_runtime)
  proprio_add_test(engine_xr_tests
    LABEL render
    SOURCES render/test_engine_xr.cpp
    DEPS proprio::engine)
  target_compile_definitions(engine_xr_tests PRIVATE
    PROPRIO_MOCK_RUNTIME_JSON="${PROPRIO_MOCK_RUNTIME_JSON}"
    PROPRIO_XR_CAPTURE_DIR="${CMAKE_CURRENT_BINARY_DIR}/golden_out/xr_captures"
    PROPRIO_LAYER_MANIFEST_DIR="${_layer_manifest_dir}")
  add_dependencies(engine_xr_tests proprio_mock_openxr_runtime XrApiLayer_proprio_hand_tracking)

  # `calibrate wrist` on the mock runtime's devices and moving hand: headless,
  # no Vulkan, so not label render.
  proprio_add_test(wrist_calibration_xr_tests
    LABEL integration
    SOURCES unit/runtime/engine/test_wrist_calibration_xr.cpp
    DEPS proprio::engine proprio::openxr_layer_support
    ENVIRONMENT "LSAN_OPTIONS=suppressions=${PROPRIO_OPENXR_LSAN_SUPPRESSIONS}")
  target_include_directories(wrist_calibration_xr_tests PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/openxr/mock_runtime)
  target_compile_definitions(wrist_calibration_xr_tests PRIVATE PROPRIO_MOCK_RUNTIME_JSON="${PROPRIO_MOCK_RUNTIME_JSON}")
  add_dependencies(wrist_calibration_xr_tests proprio_mock_openxr_runtime)
endif()
