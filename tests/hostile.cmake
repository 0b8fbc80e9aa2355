# The hostile-input suite (tests/hostile): the built CLI and the OpenXR layer
# against malformed bytes, special files, NaN/inf, clashing processes and
# crashes; each tests/hostile/cases_*.py file is one ctest, labelled hostile.
# Main build only: it runs the release CLI as a user would.
if(PROPRIO_BUILD_TESTS AND PROPRIO_BUILD_TOOLS AND NOT PROPRIO_SANITIZE AND NOT PROPRIO_FUZZ)
  find_package(Python3 REQUIRED COMPONENTS Interpreter)
  file(GLOB _hostile_case_files CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/hostile/cases_*.py)
  get_property(_hostile_layer_manifest GLOBAL PROPERTY PROPRIO_LAYER_MANIFEST)
  set(_hostile_layer_dir "")
  if(_hostile_layer_manifest)
    get_filename_component(_hostile_layer_dir ${_hostile_layer_manifest} DIRECTORY)
  endif()
  foreach(_file ${_hostile_case_files})
    get_filename_component(_stem ${_file} NAME_WE)
    string(REPLACE "cases_" "" _area ${_stem})
    add_test(NAME hostile.${_area}
      COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/hostile/hostile.py
        --cli $<TARGET_FILE:proprio>
        --work ${CMAKE_CURRENT_BINARY_DIR}/hostile_work/${_area}
        --mock-runtime-json "${PROPRIO_MOCK_RUNTIME_JSON}"
        --layer-dir "${_hostile_layer_dir}"
        ${_file})
    set_tests_properties(hostile.${_area} PROPERTIES LABELS "hostile;integration" TIMEOUT 600)
  endforeach()
endif()
