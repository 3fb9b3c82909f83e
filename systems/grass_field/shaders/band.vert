#version 330
// Level 5: the visible sides of the 12-sided band around the viewer's cell (positions and atlas uv from the CPU).
uniform mat4 view_proj;
in vec3 in_position;
in vec2 in_uv;
out vec2 v_uv;
out vec3 v_pos;
void main() {
    v_uv = in_uv;
    v_pos = in_position;
    gl_Position = view_proj * vec4(in_position, 1.0);
}
