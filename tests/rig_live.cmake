# The rig device live (issue 31): a plan's emulated device and the live source.
if(PROPRIO_BUILD_TESTS AND TARGET proprio::rig_live)
  # The live source's test runs the emulator and driver threads in real time.
  proprio_add_test(rig_live_tests
    SOURCES unit/input/rig_live/test_rig_live.cpp
    DEPS proprio::rig_live
    SERIAL "RigLiveSource.*")
endif()
