#version 330
// Height-field terrain (engine/render/terrain.py).  Diffuse and ambient light times the albedo are baked per
// grid point into the `shade_map` texture at the field's full resolution, so a chunk drawn at a coarse level keeps
// its lighting detail; per vertex remain the small view-dependent specular term and the fog, which vary slowly
// (both folded into v_fogged, see terrain.frag).
//
// VERTEX_SHADE (chunks drawn at full detail, level 0): every vertex is a grid point, so the baked light is read
// here, once per vertex, and the whole colour interpolated across the triangle (Gouraud) — no texture fetch
// per pixel, the larger part of the terrain's cost on a software rasteriser.
//
// TEXTURED (a Terrain with a ground texture): the lit albedo is multiplied per pixel by the tiled texture, so
// the varyings keep it apart from the specular.
//
// SHADOWS: the shadow map's look-up point, and the sun's share of the light per colour channel,
// sun·(n·l) / (sun·(n·l) + sky ambient): the albedo (and its slope darkening) multiplies both and cancels, so the
// baked texel need not hold it apart.
//
// TERRAIN_SHADOW (the field shadows part of itself, engine/render/terrain_shadow.py): the baked light already
// holds it; the texel's alpha, the sun's share past the hills, scales the per-vertex specular and the sun's part.
#include "lit.glsl"
#include "shadow.glsl"
uniform mat4 view_proj;
uniform mat4 model;
uniform vec2 uv_scale;   // local (x, z) -> shade texture coordinates, texel centres on the grid points
uniform vec2 uv_offset;
uniform float shade_scale;  // the shade texture's encoding scale (terrain.frag squares and scales)
in vec3 in_position;
in vec3 in_normal;
in float in_skirt;  // > 0 on skirt vertices: lowered by this much (hides LOD cracks), keeping the edge's shading
#ifdef TEXTURED
uniform float detail_scale;  // 1 / texture_size: local metres -> repeats of the ground texture
out vec2 v_detail_uv;
#endif
#if defined(VERTEX_SHADE) || defined(TERRAIN_SHADOW)
uniform sampler2D shade_map;    // rgba8: rgb sqrt(light / shade_scale), a the sun's share past the terrain
#endif
#ifdef VERTEX_SHADE
#ifdef TEXTURED
out vec3 v_lit;             // the lit, fogged albedo (times the ground texture per pixel, terrain.frag)
out vec3 v_add;             // plus the fogged specular
#else
out vec3 v_color;           // the fogged colour of this grid point
#endif
#else
out vec2 v_uv;
out vec4 v_fogged;   // rgb: mix(specular, sky_horizon, fog); a: shade_scale · (1 - fog)
#endif
#ifdef SHADOWS
out vec4 v_shadow;
#if defined(VERTEX_SHADE) && !defined(TEXTURED)
out vec3 v_sun;
#else
out vec3 v_sun_part;
out vec3 v_specular;
#endif
#endif
void main() {
    vec4 world = model * vec4(in_position, 1.0);
    vec3 n = normalize(mat3(model) * in_normal);
    vec2 uv = in_position.xz * uv_scale + uv_offset;
#if defined(VERTEX_SHADE) || defined(TERRAIN_SHADOW)
    ivec2 size = textureSize(shade_map, 0);
    vec4 texel = texelFetch(shade_map, clamp(ivec2(floor(uv * vec2(size))), ivec2(0), size - 1), 0);
#endif
#ifdef TERRAIN_SHADOW
    float ndl = max(dot(n, sun_dir), 0.0) * texel.a;
#else
    float ndl = max(dot(n, sun_dir), 0.0);
#endif
    vec3 h = normalize(normalize(camera_pos - world.xyz) + sun_dir);
    float spec = max(dot(n, h), 0.0);
    spec *= spec; spec *= spec; spec *= spec; spec *= spec;  // ^16, lit.glsl's shininess for terrain
    vec3 specular = sun_color * (spec * 0.03 * ndl);
    float fog = clamp(1.0 - exp(-length(camera_pos - world.xyz) * fog_density), 0.0, 1.0);
    vec4 fogged = vec4(mix(specular, sky_horizon, fog), shade_scale * (1.0 - fog));
#ifdef SHADOWS
    v_shadow = shadow_coord(world.xyz, n);
    vec3 sun = sun_color * ndl;
    vec3 hemi = mix(sky_horizon * 0.35, sky_top, n.y * 0.5 + 0.5) * ambient;  // as terrain.py's shade_texels
    vec3 sun_part = sun / max(sun + hemi, vec3(1e-6));
    vec3 specular_fogged = specular * (1.0 - fog);
#endif
#ifdef VERTEX_SHADE
    vec3 light = texel.rgb;
#ifdef TEXTURED
    v_lit = light * light * fogged.a;
    v_add = fogged.rgb;
#else
    v_color = light * light * fogged.a + fogged.rgb;
#ifdef SHADOWS
    v_sun = light * light * fogged.a * sun_part + specular_fogged;
#endif
#endif
#else
    v_fogged = fogged;
    v_uv = uv;
#endif
#if defined(SHADOWS) && !(defined(VERTEX_SHADE) && !defined(TEXTURED))
    v_sun_part = sun_part;
    v_specular = specular_fogged;
#endif
#ifdef TEXTURED
    v_detail_uv = in_position.xz * detail_scale;
#endif
    world.y -= in_skirt;
    gl_Position = view_proj * world;
}
