#version 330
// HDR -> display (display_color.glsl: exposure, ACES filmic fit, sRGB gamma).
#include "display_color.glsl"
// The view's HDR image has the size of the rectangle written (tone mapping runs at the view's own size), so
// each pixel fetches its own texel: no filtering.  `origin`: the rectangle's lower-left corner in the target.
// ADD_LAYER: a colour layer folded into the tone map (engine/render/feature.py ColorLayer): the HDR colour plus
// layer_matrix · layer, the layer's texture sampled bilinearly at the pixel's texture coordinates in the view (a
// smaller buffer upsampled), as the pass that would have added it samples it.
uniform sampler2D hdr;
uniform ivec2 origin;
#ifdef ADD_LAYER
uniform sampler2D layer;
uniform mat3 layer_matrix;
uniform vec2 view_size;
#endif
out vec4 frag;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy) - origin;
    vec3 c = texelFetch(hdr, p, 0).rgb;
#ifdef ADD_LAYER
    vec2 uv = (vec2(p) + 0.5) / view_size;
    c += layer_matrix * texture(layer, uv).rgb;
#endif
    frag = vec4(hdr_to_display(c), 1.0);
}
