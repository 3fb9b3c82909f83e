#version 330
#include "lit.glsl"
#include "common.glsl"
#include "shadow.glsl"
// Cached images are premultiplied (transparent background); alpha-tested with coverage-preserving mipmaps.
// Variants (render.py): BLEND_VIEWS (cross-fade the two nearest views), DEBUG_LEVELS, FOG, BAND_DISTANCE (the
// band's capture: each texel's distance from the capturing eye into a second target, for band.frag's fog),
// TERRAIN_SHADOW (the terrain hides the sun from part of the field: the image, lit by the whole sun, is scaled
// towards its shaded colour; the band's capture keeps it, so the band needs nothing more), SHADOWS (the sun's
// shadow map, per pixel where the texel's grass stands: the atlas's second image holds its depth in the cached
// view; only the cells a caster's shadow may reach take it), GRASS_DEPTH (the fragment's depth is where the
// texel's grass stands, not the rectangle's: what stands inside the cell is hidden only by the grass in front).
uniform sampler2D atlas_tex;
in vec2 v_uv_a;
in vec2 v_uv_b;
in float v_blend;
in float v_fog;
flat in int v_level;
out vec4 frag;
#ifdef TERRAIN_SHADOW
in float v_sun;
#endif
#if defined(SHADOWS) || defined(GRASS_DEPTH)
uniform sampler2D atlas_depth;  // (window depth · coverage, coverage) of the cached views, mip levels box-filtered
in vec3 v_grass;
flat in vec3 v_depth_dir;
#endif
#ifdef GRASS_DEPTH
in vec2 v_clip;
flat in vec2 v_clip_dir;
#endif
#if defined(TERRAIN_SHADOW) || defined(SHADOWS)
// the cached images hold level-3 grass (dots, lit with an upward normal and no specular: plant.vert), so the
// shaded colour is the lit one times sky / (sun · sun_dir.y + sky) per channel (FieldGpu._shade_uniforms)
uniform vec3 shade_factor;
#endif
#ifdef BAND_DISTANCE
uniform vec3 eye;
in vec3 v_world;
layout(location = 1) out float frag_distance;
#endif
void main() {
    vec4 c = texture(atlas_tex, v_uv_a);
#ifdef BLEND_VIEWS
    c = mix(c, texture(atlas_tex, v_uv_b), v_blend);
#endif
#if defined(SHADOWS) || defined(GRASS_DEPTH)
    // the depth image is read after the discard below, where implicit derivatives are undefined: take them here
    // (the two views' tiles have the same scale)
    vec2 uv_dx = dFdx(v_uv_a), uv_dy = dFdy(v_uv_a);
#endif
    if (c.a < 0.5) discard;
    vec3 col = c.rgb / c.a;
#if defined(SHADOWS) || defined(GRASS_DEPTH)
    vec2 depth = textureGrad(atlas_depth, v_uv_a, uv_dx, uv_dy).rg;
#ifdef BLEND_VIEWS
    // as the colour: where only the second view has grass, the first's holds no depth (read as the near plane)
    depth = mix(depth, textureGrad(atlas_depth, v_uv_b, uv_dx, uv_dy).rg, v_blend);
#endif
    float texel_depth = depth.r / max(depth.g, 1e-4);
#endif
#ifdef GRASS_DEPTH
    vec2 zw = v_clip + texel_depth * v_clip_dir;
    gl_FragDepth = clamp(0.5 * zw.x / zw.y + 0.5, 0.0, 1.0);
#endif
#if defined(TERRAIN_SHADOW) || defined(SHADOWS)
    float sun = 1.0;
#ifdef TERRAIN_SHADOW
    sun = v_sun;
#endif
#ifdef SHADOWS
    sun *= sun_visibility(shadow_coord(v_grass + texel_depth * v_depth_dir, vec3(0.0, 1.0, 0.0)));
#endif
    col *= mix(shade_factor, vec3(1.0), sun);
#endif
#ifdef DEBUG_LEVELS
    col = debug_tint(col, v_level);
#endif
#ifdef FOG
    col = mix(col, sky_horizon, v_fog);
#endif
    frag = vec4(col, 1.0);
#ifdef BAND_DISTANCE
    frag_distance = length(v_world - eye);
#endif
}
