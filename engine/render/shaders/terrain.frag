#version 330
// Baked light (terrain.vert) + the vertex's specular, fogged towards the horizon colour as lit.glsl's fog():
// mix(light² · shade_scale + specular, sky_horizon, fog) = light² · v_fogged.a + v_fogged.rgb, the fog folded
// into two per-vertex terms (one multiply-add per pixel on a software rasteriser instead of a mix).
// VERTEX_SHADE: that sum was taken per vertex (full-detail chunks, see terrain.vert); only its interpolation
// remains here.
// TEXTURED: the lit albedo times the ground texture (rgba8, sqrt of the linear colour, mipmapped, tiled).
// SHADOWS: where the shadow map hides the sun (shadow.glsl), the sun's part of the baked light (v_sun_part, per
// colour channel) and the specular go; the sky's ambient light stays.
#include "lit.glsl"
#include "shadow.glsl"
out vec4 frag;
#ifdef TEXTURED
uniform sampler2D detail_map;
in vec2 v_detail_uv;
#endif
#ifdef SHADOWS
in vec4 v_shadow;
#if defined(VERTEX_SHADE) && !defined(TEXTURED)
in vec3 v_sun;              // the fogged colour's sun part: diffuse and specular
#else
in vec3 v_sun_part;         // the fraction of the baked light that comes from the sun, per channel
in vec3 v_specular;         // the fogged specular
#endif
#endif
#ifdef VERTEX_SHADE
#ifdef TEXTURED
in vec3 v_lit;
in vec3 v_add;
void main() {
    vec3 d = texture(detail_map, v_detail_uv).rgb;
#ifdef SHADOWS
    float shade = 1.0 - sun_visibility(v_shadow);
    frag = vec4(v_lit * (1.0 - shade * v_sun_part) * (d * d) + v_add - shade * v_specular, 1.0);
#else
    frag = vec4(v_lit * (d * d) + v_add, 1.0);
#endif
}
#else
in vec3 v_color;
void main() {
#ifdef SHADOWS
    frag = vec4(v_color - (1.0 - sun_visibility(v_shadow)) * v_sun, 1.0);
#else
    frag = vec4(v_color, 1.0);
#endif
}
#endif
#else
uniform sampler2D shade_map;    // rgba8: sqrt(light / shade_scale)
in vec2 v_uv;
in vec4 v_fogged;           // rgb: mix(specular, sky_horizon, fog); a: shade_scale · (1 - fog)
void main() {
    vec3 light = texture(shade_map, v_uv).rgb;
    vec3 lit = light * light * v_fogged.a;
    vec3 add = v_fogged.rgb;
#ifdef SHADOWS
    float shade = 1.0 - sun_visibility(v_shadow);
    lit *= 1.0 - shade * v_sun_part;
    add -= shade * v_specular;
#endif
#ifdef TEXTURED
    vec3 d = texture(detail_map, v_detail_uv).rgb;
    lit *= d * d;
#endif
    frag = vec4(lit + add, 1.0);
}
#endif
