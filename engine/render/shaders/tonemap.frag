#version 330
// HDR -> display (display_color.glsl: exposure, ACES filmic fit, sRGB gamma).
#include "display_color.glsl"
// The view's HDR image has the size of the rectangle written (tone mapping runs at the view's own size), so
// each pixel fetches its own texel: no filtering.  `origin`: the rectangle's lower-left corner in the target.
uniform sampler2D hdr;
uniform ivec2 origin;
out vec4 frag;
void main() {
    frag = vec4(hdr_to_display(texelFetch(hdr, ivec2(gl_FragCoord.xy) - origin, 0).rgb), 1.0);
}
