#version 330
// A triangle covering the viewport at the far plane (depth 1), so the sky only fills empty pixels.
// The view ray is computed here, per vertex: points of the far plane are an affine function of the window
// position (w is constant on it), so the interpolated ray is exact and the fragment shader only normalises it.
uniform mat4 inv_view_proj;
uniform vec3 camera_pos;
uniform bool ortho;
uniform vec3 camera_forward;
out vec3 v_dir;
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2) * 2.0 - 1.0;
    vec4 far = inv_view_proj * vec4(p, 1.0, 1.0);
    v_dir = ortho ? camera_forward : far.xyz / far.w - camera_pos;
    gl_Position = vec4(p, 1.0, 1.0);
}
