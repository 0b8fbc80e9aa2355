# The rig device's bus (input/rig_bus, issue 31): message and report codec,
# the host's tracker, the emulated bus under faults (simulated time), the
# driver over the fake HID link (real time) and the benchmark's accounting.
# Included by tests/CMakeLists.txt at top level.
if(PROPRIO_BUILD_TESTS AND TARGET proprio::rig_bus)
  proprio_add_test(rig_bus_tests
    SOURCES
      unit/input/rig_bus/test_bus_protocol.cpp
      unit/input/rig_bus/test_bus_host.cpp
      unit/input/rig_bus/test_bus_emulator.cpp
      unit/input/rig_bus/test_bus_device.cpp
      unit/input/rig_bus/test_bus_bench.cpp
    DEPS proprio::rig_bus)
endif()
list(APPEND PROPRIO_FUZZ_TARGETS rig_bus_protocol)
set(PROPRIO_FUZZ_DEPS_rig_bus_protocol proprio::rig_bus)
