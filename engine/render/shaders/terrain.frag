#version 330
// Baked light (terrain.vert) + the vertex's specular, fogged towards the horizon colour as lit.glsl's fog().
uniform sampler2D shade;    // rgba8: sqrt(light / shade_scale)
uniform float shade_scale;
uniform vec3 sky_horizon;
in vec2 v_uv;
in vec3 v_specular;
in float v_fog;
out vec4 frag;
void main() {
    vec3 light = texture(shade, v_uv).rgb;
    frag = vec4(mix(light * light * shade_scale + v_specular, sky_horizon, v_fog), 1.0);
}
