#version 330
// Baked light (terrain.vert) + the vertex's specular, fogged towards the horizon colour as lit.glsl's fog():
// mix(light² · shade_scale + specular, sky_horizon, fog) = light² · v_fogged.a + v_fogged.rgb, the fog folded
// into two per-vertex terms (one multiply-add per pixel on a software rasteriser instead of a mix).
// VERTEX_SHADE: that sum was taken per vertex (full-detail chunks, see terrain.vert); only its interpolation
// remains here.
// TEXTURED: the lit albedo times the ground texture (rgba8, sqrt of the linear colour, mipmapped, tiled).
out vec4 frag;
#ifdef TEXTURED
uniform sampler2D detail_map;
in vec2 v_detail_uv;
#endif
#ifdef VERTEX_SHADE
#ifdef TEXTURED
in vec3 v_lit;
in vec3 v_add;
void main() {
    vec3 d = texture(detail_map, v_detail_uv).rgb;
    frag = vec4(v_lit * (d * d) + v_add, 1.0);
}
#else
in vec3 v_color;
void main() {
    frag = vec4(v_color, 1.0);
}
#endif
#else
uniform sampler2D shade_map;    // rgba8: sqrt(light / shade_scale)
in vec2 v_uv;
in vec4 v_fogged;           // rgb: mix(specular, sky_horizon, fog); a: shade_scale · (1 - fog)
void main() {
    vec3 light = texture(shade_map, v_uv).rgb;
#ifdef TEXTURED
    vec3 d = texture(detail_map, v_detail_uv).rgb;
    frag = vec4(light * light * v_fogged.a * (d * d) + v_fogged.rgb, 1.0);
#else
    frag = vec4(light * light * v_fogged.a + v_fogged.rgb, 1.0);
#endif
}
#endif
