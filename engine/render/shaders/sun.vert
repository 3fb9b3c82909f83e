#version 330
// The sun disc, drawn over the sky as a rectangle (NDC `rect`) around the sun's direction that bounds the cone
// where the disc adds anything (sky.frag: cos angle > 0.98); the view ray as in sky.vert.
uniform mat4 inv_view_proj;
uniform vec3 camera_pos;
uniform bool ortho;
uniform vec3 camera_forward;
uniform vec4 rect;  // x0, y0, x1, y1 in normalised device coordinates
out vec3 v_dir;
void main() {
    vec2 p = mix(rect.xy, rect.zw, vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1)));
    vec4 far = inv_view_proj * vec4(p, 1.0, 1.0);
    v_dir = ortho ? camera_forward : far.xyz / far.w - camera_pos;
    gl_Position = vec4(p, 1.0, 1.0);
}
