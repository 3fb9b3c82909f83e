#version 330
// Prepares the half-resolution particle target inside its rectangle: colour cleared to 0 and depth set to the
// view's depth at the full-size pixel the sprites used to compare with (texelFetch at gl_FragCoord * scale), so
// the sprites are occluded by the hardware depth test (early, before their fragment shader) instead of a fetch
// and a discard per sprite fragment.
uniform sampler2D scene_depth;
uniform float depth_scale;   // view pixels per particle-buffer pixel
out vec4 frag;
void main() {
    gl_FragDepth = texelFetch(scene_depth, ivec2(gl_FragCoord.xy * depth_scale), 0).r;
    frag = vec4(0.0);
}
