#version 420
// Never runs: the scatter pass draws with GL_RASTERIZER_DISCARD (a program still needs a fragment stage).
out vec4 frag;
void main() {
    frag = vec4(0.0);
}
