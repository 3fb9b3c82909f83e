#version 330
// Water surface: world-space vertices of the re-triangulated mesh (grid + added points) with normals from the
// height field.
uniform mat4 view_proj;
in vec3 in_position;
in vec3 in_normal;
out vec3 v_pos;
out vec3 v_normal;
void main() {
    v_pos = in_position;
    v_normal = in_normal;
    gl_Position = view_proj * vec4(in_position, 1.0);
}
