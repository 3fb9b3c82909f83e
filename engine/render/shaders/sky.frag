#version 330
// Sky gradient and the sun's halo, per pixel from the view ray of sky.vert (the disc: sun.frag, over its rectangle).
#include "sky_gradient.glsl"
uniform vec3 sky_top;
uniform vec3 sky_horizon;
uniform vec3 sun_dir;
uniform vec3 sun_color;
in vec3 v_dir;
out vec4 frag;
void main() {
    vec3 dir = normalize(v_dir);
    vec3 col = sky_gradient(dir, sky_top, sky_horizon);
    float s = max(dot(dir, sun_dir), 0.0);
    float s2 = s * s, s4 = s2 * s2;
    col += sun_color * (s4 * s4 * s4 * 0.25);  // halo: s^12 by squaring (a pow is exp2·log2 per pixel)
    frag = vec4(col, 1.0);
}
