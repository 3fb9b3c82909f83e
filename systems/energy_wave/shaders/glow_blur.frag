#version 330
// One direction of the separable 9-tap Gaussian blur (sigma = radius / 2) of the glow buffer: taps j = -4..4 at
// j · radius / 4 destination texels, weights W_|j| (render.py GAUSS_9), each tap filtered bilinearly.
// The CPU gives the taps (render.py blur_taps): when the destination grid lines up with the source's (the same
// size, or exactly half), every output pixel sees the same texel phase, so the nine bilinear taps are one fixed
// discrete kernel over a few source texels; adjacent texels of that kernel are then paired into one bilinear
// fetch each (offset between them by their weights' ratio), which is the same sum with fewer fetches
// (radius 2: 5 instead of 9 downsampling from the particle buffer, 3 instead of 9 along y). Otherwise the nine taps.
// TAPS, the number of fetches, is compiled in (a variant per count): llvmpipe unrolls the constant loop, where a
// loop bounded by a uniform made 5 fetches slower than the 9 unrolled taps.
uniform sampler2D source;
uniform vec2 axis_uv;         // one source texel along the blur direction, in texture coordinates
uniform float offsets[TAPS];  // source texels from the output pixel's centre
uniform float weights[TAPS];
in vec2 v_uv;
out vec4 frag;
void main() {
    vec3 c = vec3(0.0);
    for (int i = 0; i < TAPS; ++i) {
        c += texture(source, v_uv + axis_uv * offsets[i]).rgb * weights[i];
    }
    frag = vec4(c, 0.0);
}
