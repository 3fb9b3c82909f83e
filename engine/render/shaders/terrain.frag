#version 330
// Baked light (terrain.vert) + the vertex's specular, fogged towards the horizon colour as lit.glsl's fog():
// mix(light² · shade_scale + specular, sky_horizon, fog) = light² · v_fogged.a + v_fogged.rgb, the fog folded
// into two per-vertex terms (one multiply-add per pixel on a software rasteriser instead of a mix).
uniform sampler2D shade;    // rgba8: sqrt(light / shade_scale)
in vec2 v_uv;
in vec4 v_fogged;           // rgb: mix(specular, sky_horizon, fog); a: shade_scale · (1 - fog)
out vec4 frag;
void main() {
    vec3 light = texture(shade, v_uv).rgb;
    frag = vec4(light * light * v_fogged.a + v_fogged.rgb, 1.0);
}
