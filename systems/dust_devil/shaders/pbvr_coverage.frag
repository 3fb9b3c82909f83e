#version 420
// PBVR resolve for the scatter path: n = the number of repeats whose opaque ensemble image covers the pixel (set
// bits of its coverage words).  Blended with (ONE, ONE_MINUS_SRC_ALPHA) over the view:
// colour = colour_sand * n / R + scene * (1 - n / R), the mean of the R ensemble images over the scene.
layout(r32ui, binding = 0) uniform readonly uimage2D coverage;
uniform int view_height;
uniform int words;           // coverage words per pixel: 1 for R <= 32, else 2
uniform vec3 color;
uniform float inv_repeats;
out vec4 frag;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    int n = bitCount(imageLoad(coverage, p).r);
    if (words > 1) n += bitCount(imageLoad(coverage, p + ivec2(0, view_height)).r);
    if (n == 0) discard;
    float a = float(n) * inv_repeats;
    frag = vec4(color * a, a);
}
