#version 330
#include "lit.glsl"
#include "common.glsl"
uniform sampler2D band_tex;
uniform int debug;
in vec2 v_uv;
in vec3 v_pos;
out vec4 frag;
void main() {
    vec4 c = texture(band_tex, v_uv);
    if (c.a < 0.5) discard;
    vec3 col = c.rgb / c.a;
    if (debug != 0) col = debug_tint(col, 5);
    frag = vec4(fog(col, v_pos), 1.0);
}
