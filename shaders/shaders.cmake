# GLSL -> SPIR-V at build time with glslangValidator, embedded as uint32_t
# arrays in generated headers (--vn). Ninja follows the depfile, so editing an
# #include'd file rebuilds the shader. The .spv never enters the source tree.
find_program(PROPRIO_GLSLANG glslangValidator REQUIRED)

# proprio_embed_shaders(TARGET target SHADERS a.vert b.frag ...): each shader
# becomes <build>/shaders/proprio_shaders/<name>_<stage>.h with an array named
# <name>_<stage>_spv, on TARGET's include path.
function(proprio_embed_shaders)
  cmake_parse_arguments(ARG "" "TARGET" "SHADERS" ${ARGN})
  set(out_dir ${CMAKE_CURRENT_BINARY_DIR}/shaders/proprio_shaders)
  file(MAKE_DIRECTORY ${out_dir})
  set(headers)
  foreach(shader ${ARG_SHADERS})
    get_filename_component(name ${shader} NAME_WE)
    get_filename_component(ext ${shader} EXT)
    string(SUBSTRING ${ext} 1 -1 stage)
    set(header ${out_dir}/${name}_${stage}.h)
    add_custom_command(
      OUTPUT ${header}
      COMMAND ${PROPRIO_GLSLANG} --target-env vulkan1.2 --quiet
              --depfile ${header}.d --vn ${name}_${stage}_spv -o ${header} ${shader}
      DEPENDS ${shader}
      DEPFILE ${header}.d
      COMMENT "glslangValidator ${name}.${stage}"
      VERBATIM)
    list(APPEND headers ${header})
  endforeach()
  target_sources(${ARG_TARGET} PRIVATE ${headers})
  target_include_directories(${ARG_TARGET} PRIVATE ${CMAKE_CURRENT_BINARY_DIR}/shaders)
endfunction()
