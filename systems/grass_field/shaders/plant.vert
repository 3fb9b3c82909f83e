#version 330
#include "lit.glsl"
#include "shadow.glsl"
#include "common.glsl"
// Levels 0-3 (table 1), instanced: one instance per plant drawn at this level, its record (render.py's
// plant_records) a per-instance attribute, its variant's vertices (geometry.compact_mesh) per-vertex attributes:
// one indirect command per variant sets the base vertex and the base instance (render.py's _draw_plants).
// Lit per vertex (Gouraud, as the paper's OpenGL pipeline lit its plants), both faces of a leaf: the normal is
// turned towards the eye.  On llvmpipe the vertex work runs once per vertex while the fragment work runs per
// covered pixel on a handful of interpolated inputs, and the near plants cover far more pixels than they have
// vertices.  Lines and dots (levels 2-3) have no surface and take a fixed light.
// Variants (render.py): DEBUG_LEVELS (the debug view), FOG (the view has fog), TERRAIN_SHADOW (the view receives
// the terrain's shadow: i_p1.w scales the sun's light), SHADOWS / SHADOW_SOFT (the sun's shadow map, looked up
// per vertex: only the plants a caster's shadow may reach are drawn with it), ATLAS_DEPTH (the LOD cache's bake:
// no light; the albedo and the normal, for impostor.frag, which lights each texel as this shader lights a
// vertex).  llvmpipe runs both sides of every branch, so the lighting is computed once, with selects, and what a
// variant leaves out costs nothing.
uniform mat4 view_proj;
in vec4 in_a;  // the vertex: plant-local position, colour parameter (0 at the blade's root, 1 at the tip)
in vec4 in_b;  // normal, kind (0 tube, 1 leaf, 2 line or dot)
in vec4 i_p0;  // the plant: (x, y, z, scale)
in vec4 i_p1;  // (cos yaw, sin yaw, tint, the share of the sun the terrain's hills leave the plant)
uniform vec3 stem_color;
uniform vec3 leaf_base_color;
uniform vec3 leaf_tip_color;
#ifdef DEBUG_LEVELS
uniform int debug_level;  // the level to show
#endif
out vec3 v_color;
#ifdef ATLAS_DEPTH
uniform vec3 bake_normal;  // the cached view's camera looks down -bake_normal (impostor.impostor_basis)
out vec3 v_normal;         // the normal as the lighting below takes it (in the layout's frame)
#endif
#ifdef FOG
out float v_fog;  // lit.glsl's fog factor
#endif
void main() {
    vec4 p0 = i_p0, p1 = i_p1, a = in_a, b = in_b;
    // rotation by the plant's yaw in the xz plane (common.glsl's rotate_xz, cosine and sine given per plant)
    vec3 world = vec3(a.x * p1.x - a.z * p1.y, a.y, a.x * p1.y + a.z * p1.x) * p0.w + p0.xyz;
    vec3 n = normalize(vec3(b.x * p1.x - b.z * p1.y, b.y, b.x * p1.y + b.z * p1.x));
    float kind = b.w;  // 0 tube, 1 leaf, 2 line or dot
    vec3 albedo = (kind > 0.5 && kind < 1.5) ? mix(leaf_base_color, leaf_tip_color, a.w) : stem_color;
    albedo *= 1.0 + p1.z;
#ifdef ATLAS_DEPTH
    vec3 to_eye = bake_normal;  // the cached views are orthographic
#else
    vec3 to_eye = camera_pos - world;
#endif
    bool dots = kind > 1.5;
    n = dots ? vec3(0.0, 1.0, 0.0) : (dot(n, to_eye) < 0.0 ? -n : n);
#ifdef ATLAS_DEPTH
    // the cached image holds what the light acts on; impostor.frag lights it with the light of the frame drawn
    // (lines and dots: 80 % of the albedo, no specular term; the leaves' specular term is left out there)
    v_color = albedo * (dots ? 0.8 : 1.0);
    v_normal = n;
    gl_Position = view_proj * vec4(world, 1.0);
    return;
#endif
    // lit.glsl's shade() with shininess 16 as four squarings; lines and dots have no specular term (strength 0)
    // and are drawn at 80 %
    float strength = dots ? 0.0 : (kind > 0.5 ? 0.05 : 0.02);
    float ndl = max(dot(n, sun_dir), 0.0);
#ifdef TERRAIN_SHADOW
    ndl *= p1.w;
#endif
#ifdef SHADOWS
    ndl *= sun_visibility(shadow_coord(world, n));
#endif
    vec3 hemi = mix(sky_horizon * 0.35, sky_top, n.y * 0.5 + 0.5) * ambient;
    vec3 h = normalize(normalize(to_eye) + sun_dir);
    float spec = max(dot(n, h), 0.0);
    spec *= spec;
    spec *= spec;
    spec *= spec;
    spec *= spec;
    vec3 c = albedo * (sun_color * ndl + hemi) + sun_color * (spec * strength) * ndl;
    c *= dots ? 0.8 : 1.0;
#ifdef DEBUG_LEVELS
    c = debug_tint(c, debug_level);
#endif
#ifdef FOG
    v_fog = clamp(1.0 - exp(-length(to_eye) * fog_density), 0.0, 1.0);
#endif
    v_color = c;
    gl_Position = view_proj * vec4(world, 1.0);
}
