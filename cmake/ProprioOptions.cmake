# Project-wide compile settings, applied through an INTERFACE target so that
# third-party headers are not affected and every module opts in explicitly.
add_library(proprio_options INTERFACE)
add_library(proprio::options ALIAS proprio_options)
target_compile_features(proprio_options INTERFACE cxx_std_20)
target_compile_options(proprio_options INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor -Woverloaded-virtual)
if(PROPRIO_WERROR)
  target_compile_options(proprio_options INTERFACE -Werror)
endif()

# Line tables only: sanitizer reports and backtraces keep file:line, and the
# build trees shrink by about 40 % (ASan tests: 2.0 to 1.2 GB). CI runners'
# disks are small and shared; one ran out in the middle of the ASan build.
if(PROPRIO_DEBUG_INFO STREQUAL "lines")
  add_compile_options(-g1)
elseif(NOT PROPRIO_DEBUG_INFO STREQUAL "full")
  message(FATAL_ERROR "PROPRIO_DEBUG_INFO is '${PROPRIO_DEBUG_INFO}': use full or lines")
endif()

if(PROPRIO_FUZZ)
  # Instrument every library for coverage so libFuzzer can steer into the
  # parsers; only the fuzz executables link the fuzzer runtime itself.
  add_compile_options(-fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer)
  add_link_options(-fsanitize=address,undefined)
elseif(PROPRIO_SANITIZE)
  list(JOIN PROPRIO_SANITIZE "," _proprio_san)
  add_compile_options(-fsanitize=${_proprio_san} -fno-omit-frame-pointer -fno-sanitize-recover=all)
  add_link_options(-fsanitize=${_proprio_san})
endif()

# Sanitizer builds are Debug (-O0), but a library that must keep pace with
# real time gets -O1 there. At -O0 every Eigen expression is a chain of calls:
# the emulated fingertip devices (Eigen kinematics in their plants) ran slower
# than real time under ASan, four of them on two cores, and two HID tests hung
# in CI. -O1 everywhere fixed that but took the ASan build from 411 to 686 s.
function(proprio_keep_real_time_under_sanitizers target)
  if(PROPRIO_SANITIZE)
    target_compile_options(${target} PRIVATE -O1)
  endif()
endfunction()

# Unity builds: a target compiles its sources 8 to a unit, so Eigen, spdlog and
# the project's headers are parsed once per 8 files instead of once per file.
# CI compiles everything up to four times (main, ASan, TSan, fuzz) on two
# cores; this is most of what keeps `./dev test` inside its budget. In return,
# file-local names must not collide within a target: give a file's helpers
# names of their own or a file-named namespace, and put fixtures in the same
# namespace as their TEST_Fs (GCC's -Wsubobject-linkage fires otherwise).
# Configure with -DPROPRIO_UNITY=OFF to compile each file on its own (e.g. to
# check a file for missing includes).
option(PROPRIO_UNITY "Compile libraries, tools, tests and benchmarks as unity builds" ON)
function(proprio_enable_unity target)
  if(PROPRIO_UNITY)
    set_target_properties(${target} PROPERTIES UNITY_BUILD ON UNITY_BUILD_BATCH_SIZE 8)
  endif()
endfunction()

# Helper: a library in the Proprio layout (include/proprio/<name>/, src/).
function(proprio_add_library name)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(proprio_${name} ${ARG_SOURCES})
  add_library(proprio::${name} ALIAS proprio_${name})
  target_include_directories(proprio_${name} PUBLIC
    $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>)
  target_link_libraries(proprio_${name} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE proprio::options ${ARG_PRIVATE_DEPS})
  set_target_properties(proprio_${name} PROPERTIES POSITION_INDEPENDENT_CODE ON)
  proprio_enable_unity(proprio_${name})
  file(RELATIVE_PATH folder ${PROJECT_SOURCE_DIR} ${CMAKE_CURRENT_SOURCE_DIR})
  set_property(GLOBAL APPEND PROPERTY PROPRIO_MODULES "${name}=${folder}")
endfunction()

# Writes <build>/module_graph.txt, one line per proprio_add_library module:
# "<name> <folder> <proprio modules it links, comma-separated>", read from the
# targets' final LINK_LIBRARIES (so links added after proprio_add_library count).
# tools/check_module_graph.py compares it with docs/architecture.md.
function(proprio_write_module_graph)
  get_property(modules GLOBAL PROPERTY PROPRIO_MODULES)
  set(text "")
  foreach(entry IN LISTS modules)
    string(REPLACE "=" ";" parts "${entry}")
    list(GET parts 0 name)
    list(GET parts 1 folder)
    get_target_property(links proprio_${name} LINK_LIBRARIES)
    set(deps "")
    foreach(link IN LISTS links)
      if(link MATCHES "^proprio::([a-z_0-9]+)$" AND NOT CMAKE_MATCH_1 STREQUAL "options")
        list(APPEND deps ${CMAKE_MATCH_1})
      elseif(link MATCHES "^proprio_([a-z_0-9]+)$")
        list(APPEND deps ${CMAKE_MATCH_1})
      endif()
    endforeach()
    list(REMOVE_DUPLICATES deps)
    list(SORT deps)
    list(JOIN deps "," deps)
    string(APPEND text "${name} ${folder} ${deps}\n")
  endforeach()
  file(WRITE ${CMAKE_BINARY_DIR}/module_graph.txt "${text}")
endfunction()
