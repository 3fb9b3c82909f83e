#version 330
// HDR -> display: exposure, ACES filmic fit (Narkowicz 2015), then sRGB gamma.
uniform sampler2D hdr;
uniform float exposure;
in vec2 v_uv;
out vec4 frag;
vec3 aces(vec3 x) {
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}
void main() {
    vec3 c = texture(hdr, v_uv).rgb * exposure;
    frag = vec4(pow(aces(c), vec3(1.0 / 2.2)), 1.0);
}
