#version 330
#include "lit.glsl"
// Levels 0-3: the colour lit per vertex (plant.vert), fogged with the per-vertex factor under FOG.
in vec3 v_color;
#ifdef FOG
in float v_fog;
#endif
out vec4 frag;
void main() {
#ifdef FOG
    frag = vec4(mix(v_color, sky_horizon, v_fog), 1.0);
#else
    frag = vec4(v_color, 1.0);
#endif
}
