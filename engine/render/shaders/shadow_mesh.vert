#version 330
// Depth of instanced lit primitives seen from the sun (the shadow map's casters, MeshFeature).
uniform mat4 light_view_proj;
in vec3 in_position;
in vec4 m0;
in vec4 m1;
in vec4 m2;
in vec4 m3;
void main() {
    gl_Position = light_view_proj * (mat4(m0, m1, m2, m3) * vec4(in_position, 1.0));
}
