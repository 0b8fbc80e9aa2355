# Fingertip haptic devices over USB HID (haptics/fingertip_device): the wire protocol,
# the emulator with motor dynamics and the host driver. Included by
# tests/CMakeLists.txt at top level.
if(PROPRIO_BUILD_TESTS)
  proprio_add_test(fingertip_device_tests
    SOURCES
      unit/haptics/fingertip_device/test_fingertip_protocol.cpp
      unit/haptics/fingertip_device/test_fingertip_emulator.cpp
      unit/haptics/fingertip_device/test_fingertip_device.cpp
    DEPS proprio::fingertip_device)
endif()
list(APPEND PROPRIO_FUZZ_TARGETS fingertip_protocol)
set(PROPRIO_FUZZ_DEPS_fingertip_protocol proprio::fingertip_device)
