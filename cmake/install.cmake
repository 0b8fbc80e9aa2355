# Installing and packaging (docs/install.md): `cmake --install` and `cpack`.
# Included at the end of the top-level CMakeLists.txt, after every target exists.
#
#   <prefix>/bin/proprio                                 the CLI (tools/proprio installs it)
#   <prefix>/libexec/proprio/                            the CLI's helper programs (tools/proprio installs them)
#   <prefix>/<libdir>/proprio/libXrApiLayer_proprio_hand_tracking.so
#                                                        the OpenXR API layer
#   <prefix>/<libdir>/proprio/sources/                   the layer's source plugins (input/hand_sources installs them)
#   <prefix>/share/openxr/1/api_layers/explicit.d/XrApiLayer_proprio_hand_tracking.json
#                                                        the layer's manifest, where Debian's OpenXR loader looks
#   <prefix>/share/proprio/                              config/ (gloves, device models, pose networks, studies)
#   <prefix>/include/proprio/                            public headers (core, layer configuration, hand sources)
#   <prefix>/share/doc/proprio/                          README, install guide, licence
include(GNUInstallDirs)
# `install` and cpack install what is built and build nothing themselves: the
# dev and ci trees' `all` holds every test and benchmark, and both ./dev paths
# (package, test) build first.
set(CMAKE_SKIP_INSTALL_ALL_DEPENDENCY ON)

# --- data --------------------------------------------------------------------
# data_dir() (runtime/core) finds <prefix>/<datadir>/proprio by walking up from
# the binary it is linked into, so it needs the datadir relative to the prefix
# (an absolute one is taken as it is).
install(DIRECTORY ${PROJECT_SOURCE_DIR}/config/ DESTINATION ${CMAKE_INSTALL_DATADIR}/proprio)
# The training scripts `proprio train array` runs (the stretch array's import
# the stretch glove's), without their tests: <datadir>/proprio/tools/.
foreach(_proprio_tool stretch_array stretch_glove)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/tools/${_proprio_tool} DESTINATION ${CMAKE_INSTALL_DATADIR}/proprio/tools
          FILES_MATCHING PATTERN "*.py" PATTERN "README.md" PATTERN "tests" EXCLUDE PATTERN "__pycache__" EXCLUDE)
endforeach()
target_compile_definitions(proprio_core PRIVATE PROPRIO_INSTALL_DATADIR="${CMAKE_INSTALL_DATADIR}")

# --- the OpenXR layer ----------------------------------------------------------
# An explicit layer, as `proprio layer install` makes by default and as Debian
# ships its own (openxr-layer-corevalidation): apps load it only when they ask
# for it (XR_ENABLE_API_LAYERS or enabledApiLayerNames). An implicit layer in
# /usr/share would be injected into every OpenXR app on the machine.
set(PROPRIO_INSTALL_LAYER_DIR ${CMAKE_INSTALL_LIBDIR}/proprio)
set(PROPRIO_INSTALL_LAYER_MANIFEST_DIR ${CMAKE_INSTALL_DATADIR}/openxr/1/api_layers/explicit.d)
set(_proprio_layer XrApiLayer_proprio_hand_tracking)
if(TARGET ${_proprio_layer})
  install(TARGETS ${_proprio_layer} LIBRARY DESTINATION ${PROPRIO_INSTALL_LAYER_DIR})

  # The installed manifest names the library relative to itself (the loader
  # resolves a relative library_path against the manifest's folder), so an
  # installed tree can be moved or unpacked anywhere (tests/install/ runs one
  # unpacked with `dpkg -x`) and `cpack`'s /usr prefix needs no second build.
  if(IS_ABSOLUTE "${CMAKE_INSTALL_LIBDIR}" OR IS_ABSOLUTE "${CMAKE_INSTALL_DATADIR}")
    set(_proprio_layer_library_path "${CMAKE_INSTALL_FULL_LIBDIR}/proprio/$<TARGET_FILE_NAME:${_proprio_layer}>")
  else()
    file(RELATIVE_PATH _proprio_layer_rel "/${PROPRIO_INSTALL_LAYER_MANIFEST_DIR}" "/${PROPRIO_INSTALL_LAYER_DIR}")
    set(_proprio_layer_library_path "${_proprio_layer_rel}/$<TARGET_FILE_NAME:${_proprio_layer}>")
  endif()
  # Made from the build tree's template, so the extension list is written once;
  # explicit layers carry no disable_environment (as `layer install` writes them).
  get_target_property(_proprio_layer_src ${_proprio_layer} SOURCE_DIR)
  file(READ ${_proprio_layer_src}/manifest.json.in _proprio_manifest)
  string(CONFIGURE "${_proprio_manifest}" _proprio_manifest @ONLY)
  string(JSON _proprio_manifest SET "${_proprio_manifest}" api_layer library_path "\"${_proprio_layer_library_path}\"")
  string(JSON _proprio_has_disable ERROR_VARIABLE _proprio_json_error GET "${_proprio_manifest}" api_layer disable_environment)
  if(NOT _proprio_json_error)
    string(JSON _proprio_manifest REMOVE "${_proprio_manifest}" api_layer disable_environment)
  endif()
  set(_proprio_installed_manifest ${CMAKE_BINARY_DIR}/install/${_proprio_layer}.json)
  file(GENERATE OUTPUT ${_proprio_installed_manifest} CONTENT "${_proprio_manifest}\n")
  install(FILES ${_proprio_installed_manifest} DESTINATION ${PROPRIO_INSTALL_LAYER_MANIFEST_DIR})

  # The installed CLI reports and installs the installed layer; run from the
  # build tree (where these paths lead nowhere) it uses this build's layer.
  if(TARGET proprio)
    file(RELATIVE_PATH _proprio_cli_to_layer "/${CMAKE_INSTALL_BINDIR}" "/${PROPRIO_INSTALL_LAYER_DIR}")
    file(RELATIVE_PATH _proprio_cli_to_manifest "/${CMAKE_INSTALL_BINDIR}" "/${PROPRIO_INSTALL_LAYER_MANIFEST_DIR}")
    target_compile_definitions(proprio PRIVATE
      PROPRIO_INSTALLED_LAYER_LIBRARY="${_proprio_cli_to_layer}/$<TARGET_FILE_NAME:${_proprio_layer}>"
      PROPRIO_INSTALLED_LAYER_MANIFEST="${_proprio_cli_to_manifest}/${_proprio_layer}.json")
  endif()
endif()

# --- headers -------------------------------------------------------------------
# What an app or plugin needs to read Proprio's types and write a hand source:
# core (hand model, HandSource, recordings, Result), the layer's configuration
# and the hand-source factory. The libraries themselves are static and built
# in-tree, so they are not installed (docs/install.md).
foreach(_proprio_lib proprio_core proprio_openxr_layer_support proprio_hand_sources)
  if(TARGET ${_proprio_lib})
    get_target_property(_proprio_dir ${_proprio_lib} SOURCE_DIR)
    if(IS_DIRECTORY ${_proprio_dir}/include/proprio)
      install(DIRECTORY ${_proprio_dir}/include/proprio DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
    endif()
  endif()
endforeach()

# --- docs ------------------------------------------------------------------------
install(FILES ${PROJECT_SOURCE_DIR}/README.md ${PROJECT_SOURCE_DIR}/docs/install.md
  DESTINATION ${CMAKE_INSTALL_DOCDIR} OPTIONAL)
foreach(_proprio_licence LICENSE LICENSE.md COPYING)
  if(EXISTS ${PROJECT_SOURCE_DIR}/${_proprio_licence})
    # Debian keeps a package's licence in /usr/share/doc/<package>/copyright.
    install(FILES ${PROJECT_SOURCE_DIR}/${_proprio_licence} DESTINATION ${CMAKE_INSTALL_DOCDIR} RENAME copyright)
    break()
  endif()
endforeach()

# --- the .deb (cpack, or ./dev package) ---------------------------------------------
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME proprio)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_VENDOR "Proprio")
# The commit author of this repository; packagers set their own.
set(PROPRIO_PACKAGE_MAINTAINER "Proprio maintainers <maintainers@users.noreply.h-seed-2d465c1b.example>"
  CACHE STRING "Maintainer field of the .deb (cpack)")
set(CPACK_PACKAGE_CONTACT "${PROPRIO_PACKAGE_MAINTAINER}")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "instrumented hands for VR: OpenXR hand-tracking layer, haptics and study tools")
set(CPACK_PACKAGE_DESCRIPTION
  "Proprio turns sensor gloves (VIST, stretch-sensing) and simulated hands into OpenXR XR_EXT_hand_tracking joints
through an explicit OpenXR API layer (XR_APILAYER_PROPRIO_hand_tracking), simulates fingertip contact with MuJoCo,
drives cutaneous fingertip devices over USB HID, and runs psychophysics studies. This package holds the proprio CLI,
the layer with its manifest, the shipped data (glove descriptions, device models, pose networks, study designs) and
the public headers.")
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)  # proprio_<version>_<arch>.deb
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "${CPACK_PACKAGE_CONTACT}")
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
# The dependencies are the shared libraries the binaries link, as dpkg-shlibdeps
# finds them; the OpenXR loader is linked, so it comes along.
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
# The dev and ci trees build with debug info, which is most of each binary's size; packages carry none.
set(CPACK_STRIP_FILES ON)
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_DEBIAN_COMPRESSION_TYPE xz)
set(CPACK_OUTPUT_FILE_PREFIX ${CMAKE_BINARY_DIR}/package)
set(CPACK_PACKAGE_CHECKSUM SHA256)
include(CPack)
