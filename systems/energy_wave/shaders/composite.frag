#version 330
// Adds the energy wave onto the view's HDR colour (additive blending): the particle buffer (upsampled), which
// holds the sprites and their bloom (glow_add.frag), turned into colour by layer_matrix (the identity for RGB
// buffers; for a colour pair's weights Σ g·I and Σ g³·I (particles.frag TWO_CHANNEL) its columns are the colour
// and core - colour).  The same sum as engine/render/shaders/tonemap.frag ADD_LAYER, which applies it in the
// tone map instead when nothing is drawn over the wave (engine.render.feature.ColorLayer).
uniform sampler2D particles;
uniform mat3 layer_matrix;
in vec2 v_uv;
out vec4 frag;
void main() {
    frag = vec4(layer_matrix * texture(particles, v_uv).rgb, 0.0);
}
