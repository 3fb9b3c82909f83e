#version 330
// Adds the energy wave onto the view's HDR colour (additive blending): the particle buffer (upsampled) plus its
// blurred copy scaled by the glow strength (bloom).
uniform sampler2D particles;
uniform sampler2D glow;
uniform float glow_strength;
in vec2 v_uv;
out vec4 frag;
void main() {
    frag = vec4(texture(particles, v_uv).rgb + texture(glow, v_uv).rgb * glow_strength, 0.0);
}
