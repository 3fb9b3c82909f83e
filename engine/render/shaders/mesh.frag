#version 330
// Variant FOG (passes.py MeshFeature): distance fog, compiled in only when the view has fog.
#include "lit.glsl"
in vec3 v_pos;
in vec3 v_normal;
in vec4 v_color;
out vec4 frag;
void main() {
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;
    vec3 c = shade(v_color.rgb, n, v_pos, 48.0, 0.25) + v_color.rgb * v_color.a;
#ifdef FOG
    c = fog(c, v_pos);
#endif
    frag = vec4(c, 1.0);
}
