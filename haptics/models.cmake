# Fingertip device models (band_2dof, platform_3dof, force_vector), their TOML
# loading, and the safety gate. Included by haptics/CMakeLists.txt.
list(APPEND PROPRIO_HAPTICS_SOURCES
  ${CMAKE_CURRENT_SOURCE_DIR}/src/device_model.cpp
  ${CMAKE_CURRENT_SOURCE_DIR}/src/band_device.cpp
  ${CMAKE_CURRENT_SOURCE_DIR}/src/platform_device.cpp
  ${CMAKE_CURRENT_SOURCE_DIR}/src/force_vector_device.cpp
  ${CMAKE_CURRENT_SOURCE_DIR}/src/safety.cpp
)
