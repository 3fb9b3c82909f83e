#version 330
#include "lit.glsl"
#include "common.glsl"
// Variants (render.py): DEBUG_LEVELS, FOG.
// FOG: each texel's grass is fogged at its own distance from the viewer (lit.glsl's fog), not at the band's: the
// capture stored its distance from the capturing eye `band_eye` (filtered like the colour, so divided by the
// coverage too), which places it on the ray from that eye through the band's point.
uniform sampler2D band_tex;
in vec2 v_uv;
out vec4 frag;
#ifdef FOG
uniform sampler2D band_distance;
uniform vec3 band_eye;
in vec3 v_position;
#endif
void main() {
    vec4 c = texture(band_tex, v_uv);
    if (c.a < 0.5) discard;
    vec3 col = c.rgb / c.a;
#ifdef DEBUG_LEVELS
    col = debug_tint(col, 5);
#endif
#ifdef FOG
    vec3 grass = band_eye + normalize(v_position - band_eye) * (texture(band_distance, v_uv).r / c.a);
    col = mix(col, sky_horizon, clamp(1.0 - exp(-length(camera_pos - grass) * fog_density), 0.0, 1.0));
#endif
    frag = vec4(col, 1.0);
}
