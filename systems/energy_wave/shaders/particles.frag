#version 330
// Additive radial-gradient billboard (section 3.1): white core fading to the glow colour, scaled by the remaining
// life (alpha). The gradient is evaluated, not sampled from a texture (a texture fetch costs more than the
// formula on llvmpipe): g(r) = (1 - r²)² · exp(-3 r²), 1 at the centre, 0 at the rim and beyond.
// The particle buffer is smaller than the view and has no depth attachment, so a fragment behind the scene is
// rejected by comparing with the view's depth texture (texelFetch of the matching full-size pixel).
uniform sampler2D scene_depth;
uniform float depth_scale;   // view pixels per particle-buffer pixel
uniform vec3 color;
uniform vec3 core_color;
uniform float intensity;
in vec2 v_corner;
in float v_alpha;
out vec4 frag;

void main() {
    float scene = texelFetch(scene_depth, ivec2(gl_FragCoord.xy * depth_scale), 0).r;
    if (gl_FragCoord.z > scene) discard;
    float r2 = dot(v_corner, v_corner);
    float rim = max(1.0 - r2, 0.0);
    float g = rim * rim * exp(-3.0 * r2) * v_alpha;
    frag = vec4(mix(color, core_color, g * g) * (g * intensity), 0.0);
}
