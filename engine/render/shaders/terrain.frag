#version 330
#include "lit.glsl"
// Height-field terrain: colour ramp by normalised height, steep slopes darkened towards rock.
uniform vec3 ramp[8];
uniform int ramp_count;
uniform vec2 height_range;
in vec3 v_pos;
in vec3 v_normal;
in float v_height;
out vec4 frag;
void main() {
    vec3 n = normalize(v_normal);
    float t = clamp((v_height - height_range.x) / max(height_range.y - height_range.x, 1e-4), 0.0, 1.0);
    float x = t * float(ramp_count - 1);
    int i = int(min(floor(x), float(ramp_count - 2)));
    vec3 albedo = mix(ramp[i], ramp[i + 1], x - float(i));
    albedo = mix(albedo * 0.7, albedo, smoothstep(0.55, 0.85, n.y));
    frag = vec4(fog(shade(albedo, n, v_pos, 16.0, 0.03), v_pos), 1.0);
}
