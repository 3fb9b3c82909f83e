#version 330
#include "lit.glsl"
#include "common.glsl"
// Cached images are premultiplied (transparent background); alpha-tested with coverage-preserving mipmaps.
// Variants (render.py): BLEND_VIEWS (cross-fade the two nearest views), DEBUG_LEVELS, FOG.
uniform sampler2D atlas_tex;
in vec2 v_uv_a;
in vec2 v_uv_b;
in float v_blend;
in float v_fog;
flat in int v_level;
out vec4 frag;
void main() {
    vec4 c = texture(atlas_tex, v_uv_a);
#ifdef BLEND_VIEWS
    c = mix(c, texture(atlas_tex, v_uv_b), v_blend);
#endif
    if (c.a < 0.5) discard;
    vec3 col = c.rgb / c.a;
#ifdef DEBUG_LEVELS
    col = debug_tint(col, v_level);
#endif
#ifdef FOG
    col = mix(col, sky_horizon, v_fog);
#endif
    frag = vec4(col, 1.0);
}
