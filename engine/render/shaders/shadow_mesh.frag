#version 330
// Depth only: the shadow pass has no colour target.
void main() {
}
