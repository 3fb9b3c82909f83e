#version 330
// Variant FOG (passes.py MeshFeature): distance fog, compiled in only when the view has fog.
// Variant SHADOWS: the sun's light is dimmed by the view's shadow map (shadow.glsl).
// Variant TERRAIN_SHADOW: and by the terrain's hills (terrain_shadow.glsl), looked up per pixel.
#include "lit.glsl"
#include "shadow.glsl"
#include "terrain_shadow.glsl"
in vec3 v_pos;
in vec3 v_normal;
in vec4 v_color;
#ifdef SHADOWS
in vec4 v_shadow;
#endif
out vec4 frag;
void main() {
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;
#ifdef SHADOWS
    float sun_lit = sun_visibility(v_shadow);
#else
    float sun_lit = 1.0;
#endif
    sun_lit *= terrain_sun(v_pos);
    vec3 c = shade_in_sun(v_color.rgb, n, v_pos, 48.0, 0.25, sun_lit) + v_color.rgb * v_color.a;
#ifdef FOG
    c = fog(c, v_pos);
#endif
    frag = vec4(c, 1.0);
}
