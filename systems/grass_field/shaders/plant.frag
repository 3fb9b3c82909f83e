#version 330
#include "lit.glsl"
#include "common.glsl"
// Leaves are lit on both faces; lines and dots (levels 2-3) have no surface and take a fixed light.
// Variants (render.py): DEBUG_LEVELS (the debug view), FOG (the view has fog).  llvmpipe runs both sides of
// every branch, so the lighting is computed once, with selects, and what a variant leaves out costs nothing.
#ifdef DEBUG_LEVELS
uniform int debug_level;  // the level to show
#endif
in vec3 v_pos;
in vec3 v_normal;
in vec3 v_albedo;
flat in float v_kind;
out vec4 frag;
void main() {
    bool dots = v_kind > 1.5;
    vec3 n = normalize(v_normal);
    if (dot(n, camera_pos - v_pos) < 0.0) n = -n;
    n = dots ? vec3(0.0, 1.0, 0.0) : n;
    // lit.glsl's shade() with shininess 16 as four squarings (pow is exp2(log2(x) * y) on llvmpipe); lines
    // and dots have no specular term (strength 0) and are drawn at 80 %
    float strength = dots ? 0.0 : (v_kind > 0.5 ? 0.05 : 0.02);
    float ndl = max(dot(n, sun_dir), 0.0);
    vec3 hemi = mix(sky_horizon * 0.35, sky_top, n.y * 0.5 + 0.5) * ambient;
    vec3 h = normalize(normalize(camera_pos - v_pos) + sun_dir);
    float spec = max(dot(n, h), 0.0);
    spec *= spec;
    spec *= spec;
    spec *= spec;
    spec *= spec;
    vec3 c = v_albedo * (sun_color * ndl + hemi) + sun_color * (spec * strength) * ndl;
    c *= dots ? 0.8 : 1.0;
#ifdef DEBUG_LEVELS
    c = debug_tint(c, debug_level);
#endif
#ifdef FOG
    c = fog(c, v_pos);
#endif
    frag = vec4(c, 1.0);
}
