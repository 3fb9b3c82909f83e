#version 330
// Instanced lit primitives: one instance = a model matrix (4 columns) and colour + emissive.
// Variant SHADOWS: the sun shadow map's look-up point (shadow.glsl).
#include "lit.glsl"
#include "shadow.glsl"
uniform mat4 view_proj;
in vec3 in_position;
in vec3 in_normal;
in vec4 m0;
in vec4 m1;
in vec4 m2;
in vec4 m3;
in vec4 in_color;
out vec3 v_pos;
out vec3 v_normal;
out vec4 v_color;
#ifdef SHADOWS
out vec4 v_shadow;
#endif
void main() {
    mat4 model = mat4(m0, m1, m2, m3);
    vec4 world = model * vec4(in_position, 1.0);
    v_pos = world.xyz;
    // normal matrix of M = R·S without an inverse: (R·S)^-T n = R·S^-1 n = M (n / s²), s the column lengths
    vec3 s2 = vec3(dot(m0.xyz, m0.xyz), dot(m1.xyz, m1.xyz), dot(m2.xyz, m2.xyz));
    v_normal = mat3(model) * (in_normal / s2);
    v_color = in_color;
#ifdef SHADOWS
    v_shadow = shadow_coord(world.xyz, v_normal);
#endif
    gl_Position = view_proj * world;
}
