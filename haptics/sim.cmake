list(APPEND PROPRIO_HAPTICS_SOURCES
  ${CMAKE_CURRENT_SOURCE_DIR}/src/scene.cpp
  ${CMAKE_CURRENT_SOURCE_DIR}/src/contact_sim.cpp
  ${CMAKE_CURRENT_SOURCE_DIR}/src/force_laws.cpp
  ${CMAKE_CURRENT_SOURCE_DIR}/src/servo_loop.cpp
  ${CMAKE_CURRENT_SOURCE_DIR}/src/touch_script.cpp
  ${CMAKE_CURRENT_SOURCE_DIR}/src/emulated_fingertip.cpp
  ${CMAKE_CURRENT_SOURCE_DIR}/src/hid_channels.cpp
)
