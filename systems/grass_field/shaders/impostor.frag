#version 330
#include "lit.glsl"
#include "common.glsl"
#include "shadow.glsl"
// The cached images hold the albedo, premultiplied (transparent background), alpha-tested with coverage-preserving
// mipmaps; the images beside them the depth of each texel's grass in its cached view and its normal (the bake:
// plant.vert's ATLAS_DEPTH).  Each texel is lit here with the light of the frame, as plant.vert lights a
// level-3 vertex (the leaves' small specular term left out), so a new sun or sky needs no new images.
// Variants (render.py): BLEND_VIEWS (cross-fade the two nearest views), DEBUG_LEVELS, FOG, BAND_DISTANCE (the
// band's capture: each texel's distance from the capturing eye into a second target, for band.frag's fog),
// TERRAIN_SHADOW (the terrain hides the sun from part of the field: its share of the sun on the ground, per
// corner; the band's capture keeps it, so the band needs nothing more), SHADOWS (the sun's shadow map, per pixel
// where the texel's grass stands; only the cells a caster's shadow may reach take it), GRASS_DEPTH (the
// fragment's depth is where the texel's grass stands, not the rectangle's: what stands inside the cell is hidden
// only by the grass in front).
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
// (window depth, 1) · coverage and (the normal / 2 + 1 / 2, its y^2) · coverage of the cached views, the normal in
// the layout's frame; mip levels box-filtered, so a texel holds the means over the grass it covers
uniform sampler2D atlas_depth;
uniform sampler2D atlas_normal;
flat in vec2 v_turn;
#if defined(SHADOWS) || defined(GRASS_DEPTH)
in vec3 v_grass;
flat in vec3 v_depth_dir;
#endif
#ifdef GRASS_DEPTH
in vec2 v_clip;
flat in vec2 v_clip_dir;
#endif
#ifdef BAND_DISTANCE
uniform vec3 eye;
in vec3 v_world;
layout(location = 1) out float frag_distance;
#endif
// A texel's grass: its mean normal (not normalised: shorter where its normals disagree) turned with the cell, and
// the mean of n.y^2, from the normal image's texel ``t`` and the coverage.
vec3 texel_normal(vec4 t, float coverage, out float y2) {
    vec3 n = t.rgb / coverage * 2.0 - 1.0;
    y2 = t.a / coverage;
    return vec3(n.x * v_turn.x - n.z * v_turn.y, n.y, n.x * v_turn.y + n.z * v_turn.x);
}
// The mean of max(n · l, 0) over the normals n a texel covers, from their mean m and the mean of n.y^2: the
// clamped cosine's Legendre series to the second band, 1/4 + (m · l) / 2 + 5/32 (3 E[(n · l)^2] - 1), with the
// second moment taken as isotropic about the vertical (E[n.x^2] = E[n.z^2], no cross terms: grass has no
// preferred azimuth); blended towards the exact max(m · l, 0) as the normals agree (|m| -> 1, the finest level).
// Against the per-texel lighting the images held before they were unlit: within 5 % at mip levels 1-3.
float sun_share(vec3 m, float y2, vec3 l) {
    float ml = dot(m, l);
    float side = 0.5 * (1.0 - y2);
    float second = side + (y2 - side) * l.y * l.y;
    float band2 = clamp(0.25 + 0.5 * ml + 0.15625 * (3.0 * second - 1.0), 0.0, 1.0);
    float agree = min(dot(m, m), 1.0);
    float single = max(ml, 0.0) * inversesqrt(max(agree, 1e-8));
    agree *= agree;
    return mix(band2, single, agree * agree);
}
void main() {
    // all three images are read before the discard, where implicit derivatives are defined: llvmpipe shades
    // whole blocks of pixels whether or not some are discarded, and its implicit level of detail (one per 2 x 2
    // pixels) costs less than textureGrad's (one per pixel): -0.3 ms of a 2.3 ms level-4 pass in the bench
    vec4 c = texture(atlas_tex, v_uv_a);
    vec2 depth = texture(atlas_depth, v_uv_a).rg;
    vec4 t = texture(atlas_normal, v_uv_a);
#ifdef BLEND_VIEWS
    c = mix(c, texture(atlas_tex, v_uv_b), v_blend);
    vec2 depth_b = texture(atlas_depth, v_uv_b).rg;
    vec4 t_b = texture(atlas_normal, v_uv_b);
#endif
    if (c.a < 0.5) discard;
    vec3 albedo = c.rgb / c.a;
    float y2;
    vec3 n = texel_normal(t, max(depth.g, 1e-3), y2);
#ifdef BLEND_VIEWS
    // as the colour: where only the second view has grass, the first's holds no depth (read as the near plane)
    float y2_b;
    vec3 n_b = texel_normal(t_b, max(depth_b.g, 1e-3), y2_b);
    n = mix(n, n_b, v_blend);
    y2 = mix(y2, y2_b, v_blend);
    depth = mix(depth, depth_b, v_blend);
#endif
#if defined(SHADOWS) || defined(GRASS_DEPTH)
    float texel_depth = depth.r / max(depth.g, 1e-4);
#endif
#ifdef GRASS_DEPTH
    vec2 zw = v_clip + texel_depth * v_clip_dir;
    gl_FragDepth = clamp(0.5 * zw.x / zw.y + 0.5, 0.0, 1.0);
#endif
    float ndl = sun_share(n, y2, sun_dir);
#ifdef TERRAIN_SHADOW
    ndl *= v_sun;
#endif
#ifdef SHADOWS
    ndl *= sun_visibility(shadow_coord(v_grass + texel_depth * v_depth_dir, vec3(0.0, 1.0, 0.0)));
#endif
    vec3 hemi = mix(sky_horizon * 0.35, sky_top, n.y * 0.5 + 0.5) * ambient;
    vec3 col = albedo * (sun_color * ndl + hemi);
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
