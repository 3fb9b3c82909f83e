#version 330
// Baked light (terrain.vert) + the vertex's specular, fogged towards the horizon colour as lit.glsl's fog():
// mix(light² · shade_scale + specular, sky_horizon, fog) = light² · v_fogged.a + v_fogged.rgb, the fog folded
// into two per-vertex terms (one multiply-add per pixel on a software rasteriser instead of a mix).
// VERTEX_SHADE: that sum was taken per vertex (full-detail chunks, see terrain.vert); only its interpolation
// remains here.
out vec4 frag;
#ifdef VERTEX_SHADE
in vec3 v_color;
void main() {
    frag = vec4(v_color, 1.0);
}
#else
uniform sampler2D shade_map;    // rgba8: sqrt(light / shade_scale)
in vec2 v_uv;
in vec4 v_fogged;           // rgb: mix(specular, sky_horizon, fog); a: shade_scale · (1 - fog)
void main() {
    vec3 light = texture(shade_map, v_uv).rgb;
    frag = vec4(light * light * v_fogged.a + v_fogged.rgb, 1.0);
}
#endif
