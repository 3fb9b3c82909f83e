#version 330
// An opaque pseudo-particle: hidden behind the scene's depth, else the sand colour with coverage 1 in alpha.
uniform sampler2D scene_depth;
uniform vec3 color;
flat in float v_depth;
out vec4 frag;
void main() {
    if (v_depth > texelFetch(scene_depth, ivec2(gl_FragCoord.xy), 0).r) discard;
    frag = vec4(color, 1.0);
}
