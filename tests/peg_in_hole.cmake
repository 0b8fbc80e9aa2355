# samples/peg_in_hole: the peg-in-hole study (docs/peg-in-hole.md).
if(PROPRIO_BUILD_TESTS AND TARGET proprio::peg_in_hole)
  add_executable(peg_probe peg_in_hole/probe.cpp)
  target_link_libraries(peg_probe PRIVATE proprio::peg_in_hole proprio::options)
endif()
