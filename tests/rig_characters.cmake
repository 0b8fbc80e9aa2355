# Characters for the rig device (issue 31): glTF load/save of skinned
# characters with sample poses (proprio::render) and the three examples.
if(PROPRIO_BUILD_TESTS AND TARGET proprio::rig_characters)
  proprio_add_test(rig_characters_tests
    SOURCES
      unit/render/test_character_gltf.cpp
      unit/samples/rig_characters/test_examples.cpp
    DEPS proprio::rig_characters)
endif()
