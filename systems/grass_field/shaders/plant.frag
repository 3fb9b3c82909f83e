#version 330
#include "lit.glsl"
// Levels 0-3: the colour lit per vertex (plant.vert), fogged with the per-vertex factor under FOG.
// ATLAS_DEPTH (the LOD cache's bake): the window depth in a second target, (z, 1) where grass is drawn, so that
// the atlas's mip levels (box-filtered) hold the coverage-weighted depth and the coverage (impostor.frag divides).
in vec3 v_color;
#ifdef FOG
in float v_fog;
#endif
out vec4 frag;
#ifdef ATLAS_DEPTH
layout(location = 1) out vec2 frag_depth;
#endif
void main() {
#ifdef ATLAS_DEPTH
    frag_depth = vec2(gl_FragCoord.z, 1.0);
#endif
#ifdef FOG
    frag = vec4(mix(v_color, sky_horizon, v_fog), 1.0);
#else
    frag = vec4(v_color, 1.0);
#endif
}
