#version 330
#include "lit.glsl"
in vec3 v_pos;
in vec3 v_normal;
in vec4 v_color;
out vec4 frag;
void main() {
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;
    vec3 c = shade(v_color.rgb, n, v_pos, 48.0, 0.25) + v_color.rgb * v_color.a;
    frag = vec4(fog(c, v_pos), 1.0);
}
