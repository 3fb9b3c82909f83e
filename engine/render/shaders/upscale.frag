#version 330
// Bilinear upscale of a display-referred (already tone-mapped) view into its window rectangle.
uniform sampler2D image;
in vec2 v_uv;
out vec4 frag;
void main() {
    frag = vec4(texture(image, v_uv).rgb, 1.0);
}
