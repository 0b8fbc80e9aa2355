#version 450
// Lit meshes. Everything per draw travels in 128 bytes of push constants (the
// minimum every Vulkan device guarantees), so the pipeline needs no
// descriptor sets: the clip transform, the model transform's top three rows
// (world position and normals) and the colour.
layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;

layout(push_constant) uniform Draw {
  mat4 clip_from_object;
  vec4 world_row0;
  vec4 world_row1;
  vec4 world_row2;
  vec4 color;
} draw;

layout(location = 0) out vec3 out_normal_in_world;
layout(location = 1) out vec4 out_color;

void main() {
  gl_Position = draw.clip_from_object * vec4(in_position, 1.0);
  // The rows, taken as columns, form the transpose of the linear part M, and
  // the normal matrix inverse(M)^T equals inverse(M^T): bones are scaled
  // non-uniformly, so normals need it.
  mat3 normal_matrix = inverse(mat3(draw.world_row0.xyz, draw.world_row1.xyz, draw.world_row2.xyz));
  out_normal_in_world = normal_matrix * in_normal;
  out_color = draw.color;
}
