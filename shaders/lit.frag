#version 450
// Two directional lights and a sky/ground ambient term, in world space (+Y up).
// Output is linear; the sRGB attachment encodes it.
layout(location = 0) in vec3 in_normal_in_world;
layout(location = 1) in vec4 in_color;
layout(location = 0) out vec4 out_color;

const vec3 kKeyLightTowards = normalize(vec3(0.35, 1.0, 0.55));
const vec3 kFillLightTowards = normalize(vec3(-0.6, 0.25, 0.3));
const vec3 kSky = vec3(0.42, 0.45, 0.52);
const vec3 kGround = vec3(0.20, 0.18, 0.16);

void main() {
  vec3 n = normalize(in_normal_in_world);
  if (!gl_FrontFacing) n = -n;
  float key = max(dot(n, kKeyLightTowards), 0.0);
  float fill = max(dot(n, kFillLightTowards), 0.0);
  vec3 ambient = mix(kGround, kSky, 0.5 + 0.5 * n.y);
  vec3 lit = in_color.rgb * (ambient + 0.75 * key + 0.25 * fill);
  out_color = vec4(lit, in_color.a);
}
