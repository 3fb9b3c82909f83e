#version 330
// A colour layer added to a view's HDR colour by its own pass (engine.render.passes.add_color_layer; additive
// blending, scissored to the layer's region): layer_matrix · the layer's texture, sampled bilinearly (a smaller
// buffer upsampled).  The same sum as tonemap.frag ADD_LAYER, which adds it in the tone map instead when nothing
// is drawn over the layer.
uniform sampler2D layer;
uniform mat3 layer_matrix;
in vec2 v_uv;
out vec4 frag;
void main() {
    frag = vec4(layer_matrix * texture(layer, v_uv).rgb, 0.0);
}
