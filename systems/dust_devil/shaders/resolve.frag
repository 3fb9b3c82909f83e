#version 330
// PBVR resolve: divide the accumulated ensemble by R.  Blended with (ONE, ONE_MINUS_SRC_ALPHA) over the view:
// colour = sum_rgb / R + scene * (1 - coverage / R), the mean of the R ensemble images over the scene.
uniform sampler2D accumulation;
uniform float inv_repeats;
in vec2 v_uv;
out vec4 frag;
void main() {
    frag = texelFetch(accumulation, ivec2(gl_FragCoord.xy), 0) * inv_repeats;
}
