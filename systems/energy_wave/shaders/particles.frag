#version 330
// Additive radial-gradient billboard (section 3.1): white core fading to the glow colour, scaled by the remaining
// life (alpha). The gradient is evaluated, not sampled from a texture (a texture fetch costs more than the
// formula on llvmpipe): g(r) = (1 - r²)² · exp(-3 r²), 1 at the centre, 0 at the rim and beyond, with exp(-3 t)
// (t = r² in [0, 1]) replaced by its least-squares quartic weighted by (1 - t)²: |error of g| < 4e-4 (an exp is a
// polynomial plus exponent bit manipulation per fragment on a software rasteriser: ~12 % of this shader).
// Occlusion is the hardware depth test (no writes) against a half-resolution copy of the view's depth
// (depth_copy.frag), so hidden fragments are rejected before this shader runs.
uniform vec3 color;
uniform vec3 core_color;
uniform float intensity;
#ifndef POINTS
in vec2 v_corner;
#endif
in float v_alpha;
out vec4 frag;

void main() {
#ifdef POINTS
    vec2 v_corner = gl_PointCoord * 2.0 - 1.0;  // the point sprite's square, -1..1 (the gradient is symmetric)
#endif
    float r2 = dot(v_corner, v_corner);
    float rim = max(1.0 - r2, 0.0);
    float e = 0.999605 + r2 * (-2.979417 + r2 * (4.258832 + r2 * (-3.428027 + r2 * 1.235257)));
    float g = rim * rim * e * v_alpha;
#ifdef TWO_CHANNEL
    // one colour pair in the view (render.py): the colour below is linear in g and g³ with the pair's colours as
    // coefficients, mix(color, core, g²) · g·I = color · g·I + (core - color) · g³·I, so the buffer sums the two
    // weights and the composite applies the colours once per pixel (half the channels to blend)
    float gi = g * intensity;
    frag = vec4(gi, gi * g * g, 0.0, 0.0);
#else
    frag = vec4(mix(color, core_color, g * g) * (g * intensity), 0.0);
#endif
}
