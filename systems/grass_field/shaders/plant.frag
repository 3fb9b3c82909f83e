#version 330
#include "lit.glsl"
#include "common.glsl"
// Leaves are lit on both faces; lines and dots (levels 2-3) have no surface and take a fixed light.
uniform int debug_level;  // -1: normal colours; else the level to show (debug view)
in vec3 v_pos;
in vec3 v_normal;
in vec3 v_albedo;
flat in float v_kind;
out vec4 frag;
void main() {
    vec3 c;
    if (v_kind > 1.5) {
        c = shade(v_albedo, vec3(0.0, 1.0, 0.0), v_pos, 8.0, 0.0) * 0.8;
    } else {
        vec3 n = normalize(v_normal);
        if (dot(n, camera_pos - v_pos) < 0.0) n = -n;
        c = shade(v_albedo, n, v_pos, 16.0, v_kind > 0.5 ? 0.05 : 0.02);
    }
    if (debug_level >= 0) c = debug_tint(c, debug_level);
    frag = vec4(fog(c, v_pos), 1.0);
}
