#version 330
// A screen-space rectangle in pixels (origin bottom-left) for text and overlays.
uniform vec4 rect;
uniform vec2 screen;
out vec2 v_uv;
void main() {
    vec2 corner = vec2(gl_VertexID == 1 || gl_VertexID == 3 ? 1.0 : 0.0, gl_VertexID >= 2 ? 1.0 : 0.0);
    v_uv = vec2(corner.x, 1.0 - corner.y);
    vec2 pix = rect.xy + corner * rect.zw;
    gl_Position = vec4(pix / screen * 2.0 - 1.0, 0.0, 1.0);
}
