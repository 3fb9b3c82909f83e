#version 330
// HDR -> display (display_color.glsl: exposure, ACES filmic fit, sRGB gamma).
#include "display_color.glsl"
uniform sampler2D hdr;
in vec2 v_uv;
out vec4 frag;
void main() {
    frag = vec4(hdr_to_display(texture(hdr, v_uv).rgb), 1.0);
}
