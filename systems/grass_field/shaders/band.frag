#version 330
#include "lit.glsl"
#include "common.glsl"
// Variants (render.py): DEBUG_LEVELS, FOG.
uniform sampler2D band_tex;
in vec2 v_uv;
in float v_fog;
out vec4 frag;
void main() {
    vec4 c = texture(band_tex, v_uv);
    if (c.a < 0.5) discard;
    vec3 col = c.rgb / c.a;
#ifdef DEBUG_LEVELS
    col = debug_tint(col, 5);
#endif
#ifdef FOG
    col = mix(col, sky_horizon, v_fog);
#endif
    frag = vec4(col, 1.0);
}
