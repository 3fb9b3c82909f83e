#version 330
// engine.render.passes.add_texture (additive blending, scissored): layer_matrix · the texture, sampled
// bilinearly (a smaller buffer upsampled).  A colour layer's pass draws it onto a view's HDR colour; the same sum
// as tonemap.frag ADD_LAYER, which adds the layer in the tone map instead when nothing is drawn over it.
uniform sampler2D layer;
uniform mat3 layer_matrix;
in vec2 v_uv;
out vec4 frag;
void main() {
    frag = vec4(layer_matrix * texture(layer, v_uv).rgb, 0.0);
}
