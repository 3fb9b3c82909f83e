#version 330
// Additive radial-gradient billboard (section 3.1): white core fading to the glow colour, scaled by the remaining
// life (alpha). The particle buffer is smaller than the view and has no depth attachment, so a fragment behind the
// scene is rejected by comparing with the view's depth texture (texelFetch of the matching full-size pixel).
uniform sampler2D gradient;
uniform sampler2D scene_depth;
uniform float depth_scale;   // view pixels per particle-buffer pixel
uniform vec3 color;
uniform vec3 core_color;
uniform float intensity;
in vec2 v_uv;
in float v_alpha;
out vec4 frag;

void main() {
    float scene = texelFetch(scene_depth, ivec2(gl_FragCoord.xy * depth_scale), 0).r;
    if (gl_FragCoord.z > scene) discard;
    float g = texture(gradient, v_uv).r * v_alpha;
    frag = vec4(mix(color, core_color, g * g) * (g * intensity), 0.0);
}
