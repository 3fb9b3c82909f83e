#version 330
#include "lit.glsl"
// Levels 0-3: the colour lit per vertex (plant.vert), fogged with the per-vertex factor under FOG.
// ATLAS_DEPTH (the LOD cache's bake): v_color is the albedo; the window depth in a second target, (z, 1) where
// grass is drawn, and the normal in a third, (n / 2 + 1 / 2, n.y^2), so that the atlas's mip levels (box-filtered)
// hold the coverage-weighted depth, normal and n.y^2, and the coverage (impostor.frag divides).
in vec3 v_color;
#ifdef ATLAS_DEPTH
in vec3 v_normal;
#endif
#ifdef FOG
in float v_fog;
#endif
out vec4 frag;
#ifdef ATLAS_DEPTH
layout(location = 1) out vec2 frag_depth;
layout(location = 2) out vec4 frag_normal;
#endif
void main() {
#ifdef ATLAS_DEPTH
    frag_depth = vec2(gl_FragCoord.z, 1.0);
    vec3 n = normalize(v_normal);
    frag_normal = vec4(n * 0.5 + 0.5, n.y * n.y);
#endif
#ifdef FOG
    frag = vec4(mix(v_color, sky_horizon, v_fog), 1.0);
#else
    frag = vec4(v_color, 1.0);
#endif
}
