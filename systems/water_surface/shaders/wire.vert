#version 330
// Debug view of the re-triangulated mesh (fig. 3.2): every triangle edge, the body outline in its own colour.
uniform mat4 view_proj;
in vec3 in_position;
in vec3 in_color;
out vec3 v_color;
void main() {
    v_color = in_color;
    gl_Position = view_proj * vec4(in_position + vec3(0.0, 0.01, 0.0), 1.0);
}
