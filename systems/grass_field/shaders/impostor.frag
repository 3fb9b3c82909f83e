#version 330
#include "lit.glsl"
#include "common.glsl"
// Cached images are premultiplied (transparent background); alpha-tested with coverage-preserving mipmaps.
uniform sampler2D atlas_tex;
uniform int debug;
in vec2 v_uv_a;
in vec2 v_uv_b;
in float v_blend;
in vec3 v_fog_pos;
flat in int v_level;
out vec4 frag;
void main() {
    vec4 c = texture(atlas_tex, v_uv_a);
    if (v_blend > 0.0) c = mix(c, texture(atlas_tex, v_uv_b), v_blend);
    if (c.a < 0.5) discard;
    vec3 col = c.rgb / c.a;
    if (debug != 0) col = debug_tint(col, v_level);
    frag = vec4(fog(col, v_fog_pos), 1.0);
}
