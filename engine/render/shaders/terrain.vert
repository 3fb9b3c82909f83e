#version 330
// Height-field terrain, lit per vertex (Gouraud): a terrain's normals vary smoothly, and per-vertex
// lighting costs the vertices of the chunks drawn (engine/render/terrain.py) instead of every covered pixel
// (about 3x cheaper on software rasterisers).  Colour ramp by normalised height, steep slopes darkened towards rock.
#include "lit.glsl"
uniform mat4 view_proj;
uniform mat4 model;
uniform vec3 ramp[8];
uniform int ramp_count;
uniform vec2 height_range;
in vec3 in_position;
in vec3 in_normal;
in float in_skirt;  // > 0 on skirt vertices: lowered by this much after shading (hides LOD cracks)
out vec3 v_color;
void main() {
    vec4 world = model * vec4(in_position, 1.0);
    vec3 n = normalize(mat3(model) * in_normal);
    float t = clamp((in_position.y - height_range.x) / max(height_range.y - height_range.x, 1e-4), 0.0, 1.0);
    float x = t * float(ramp_count - 1);
    int i = int(min(floor(x), float(ramp_count - 2)));
    vec3 albedo = mix(ramp[i], ramp[i + 1], x - float(i));
    albedo = mix(albedo * 0.7, albedo, smoothstep(0.55, 0.85, n.y));
    v_color = fog(shade(albedo, n, world.xyz, 16.0, 0.03), world.xyz);
    world.y -= in_skirt;
    gl_Position = view_proj * world;
}
