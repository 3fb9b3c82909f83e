#version 330
// The real particles as opaque points (PBVR off).
uniform mat4 view_proj;
uniform float point_size;
in vec3 in_position;
void main() {
    gl_Position = view_proj * vec4(in_position, 1.0);
    gl_PointSize = point_size;
}
