#version 330
// Additive radial-gradient billboard (section 3.1): white core fading to the glow colour, scaled by the remaining
// life (alpha). The gradient is evaluated, not sampled from a texture (a texture fetch costs more than the
// formula on llvmpipe): g(r) = (1 - r²)² · exp(-3 r²), 1 at the centre, 0 at the rim and beyond.
// Occlusion is the hardware depth test (no writes) against a half-resolution copy of the view's depth
// (depth_copy.frag), so hidden fragments are rejected before this shader runs.
uniform vec3 color;
uniform vec3 core_color;
uniform float intensity;
in vec2 v_corner;
in float v_alpha;
out vec4 frag;

void main() {
    float r2 = dot(v_corner, v_corner);
    float rim = max(1.0 - r2, 0.0);
    float g = rim * rim * exp(-3.0 * r2) * v_alpha;
    frag = vec4(mix(color, core_color, g * g) * (g * intensity), 0.0);
}
