#version 420
// PBVR resolve for the scatter path: n = the number of repeats whose opaque ensemble image covers the pixel (set
// bits of its coverage words).  Blended with (ONE, ONE_MINUS_SRC_ALPHA) over the view:
// colour = colour_sand * n / R + scene * (1 - n / R), the mean of the R ensemble images over the scene.
// The coverage image persists between frames: the resolve zeroes the words it read, so the next frame's scatter
// starts from an empty image without a clear pass (every word the scatter sets lies in the rectangle the resolve
// covers, and a pixel with n = 0 has no bit to clear).
#ifndef WORDS
#define WORDS 1              // coverage words per pixel: 1 for R <= 32, else 2 (render.py compiles both variants)
#endif
layout(r32ui, binding = 0) uniform uimage2D coverage;
uniform int view_height;
uniform vec3 color;
uniform float inv_repeats;
out vec4 frag;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    int n = bitCount(imageLoad(coverage, p).r);
#if WORDS > 1
    ivec2 q = p + ivec2(0, view_height);
    uint high = imageLoad(coverage, q).r;
    if (high != 0u) {
        imageStore(coverage, q, uvec4(0u));
        n += bitCount(high);
    }
#endif
    if (n == 0) discard;
    imageStore(coverage, p, uvec4(0u));
    float a = float(n) * inv_repeats;
    frag = vec4(color * a, a);
}
