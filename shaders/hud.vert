#version 450
// Head-locked overlay: positions in pixels of the target, top-left origin.
layout(location = 0) in vec2 in_position_px;
layout(location = 1) in vec4 in_color;
layout(push_constant) uniform Hud { vec2 target_size_px; } hud;
layout(location = 0) out vec4 out_color;

void main() {
  vec2 ndc = in_position_px / hud.target_size_px * 2.0 - 1.0;  // Vulkan NDC: +y is down, like pixels
  gl_Position = vec4(ndc, 0.0, 1.0);
  out_color = in_color;
}
