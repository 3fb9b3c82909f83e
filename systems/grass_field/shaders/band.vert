#version 330
#include "lit.glsl"
// Level 5: the visible sides of the 12-sided band around the viewer's cell (positions and atlas uv from the CPU).
uniform mat4 view_proj;
in vec3 in_position;
in vec2 in_uv;
out vec2 v_uv;
out float v_fog;  // fog factor (lit.glsl's fog) per corner: the band's sides lie at nearly one distance
void main() {
    v_uv = in_uv;
    v_fog = clamp(1.0 - exp(-length(camera_pos - in_position) * fog_density), 0.0, 1.0);
    gl_Position = view_proj * vec4(in_position, 1.0);
}
