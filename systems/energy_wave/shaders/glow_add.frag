#version 330
// The bloom (the blurred quarter-resolution copy, upsampled) times the glow strength, added into the
// half-resolution particle buffer: the composite, or the view's tone map, then samples one texture at full
// resolution instead of two.
uniform sampler2D glow;
uniform float glow_strength;
in vec2 v_uv;
out vec4 frag;
void main() {
    frag = vec4(texture(glow, v_uv).rgb * glow_strength, 0.0);
}
