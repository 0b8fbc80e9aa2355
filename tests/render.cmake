# proprio::render: CPU-side unit tests (also under ASan), and the Vulkan tests
# on lavapipe (label render: golden images, overlay, allocation; main suite only).
if(PROPRIO_BUILD_TESTS AND TARGET proprio::render)
  proprio_add_test(render_geometry_tests
    SOURCES unit/test_render_geometry.cpp
    DEPS proprio::render)

  proprio_add_test(render_tests
    LABEL render
    SOURCES render/test_render.cpp
    DEPS proprio::render)
  target_include_directories(render_tests PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/render)
  target_compile_definitions(render_tests PRIVATE
    PROPRIO_GOLDEN_DIR="${CMAKE_CURRENT_SOURCE_DIR}/data/golden"
    PROPRIO_GOLDEN_OUT_DIR="${CMAKE_CURRENT_BINARY_DIR}/golden_out")
endif()
