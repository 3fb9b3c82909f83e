#version 330
// Additive radial-gradient billboard (section 3.1): white core fading to the glow colour, scaled by the remaining
// life (alpha). The particle buffer has no depth attachment (it is smaller than the view), so fragments behind the
// scene are rejected by comparing with the view's depth texture.
uniform sampler2D gradient;
uniform sampler2D scene_depth;
uniform vec2 target_size;
uniform vec3 color;
uniform vec3 core_color;
uniform float intensity;
in vec2 v_uv;
in float v_alpha;
out vec4 frag;

void main() {
    float g = texture(gradient, v_uv).r * v_alpha;
    float scene = texture(scene_depth, gl_FragCoord.xy / target_size).r;
    if (gl_FragCoord.z > scene) discard;
    frag = vec4(mix(color, core_color, g * g) * (g * intensity), 0.0);
}
