#version 330
#include "lit.glsl"
// Level 5: the visible sides of the 12-sided band around the viewer's cell (positions and atlas uv from the CPU).
uniform mat4 view_proj;
in vec3 in_position;
in vec2 in_uv;
out vec2 v_uv;
#ifdef FOG
out vec3 v_position;  // the band's point: the ray from the capturing eye through it reaches the grass drawn there
#endif
void main() {
    v_uv = in_uv;
#ifdef FOG
    v_position = in_position;
#endif
    gl_Position = view_proj * vec4(in_position, 1.0);
}
