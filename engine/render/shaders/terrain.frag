#version 330
// Baked light (terrain.vert) + the vertex's specular, fogged towards the horizon colour as lit.glsl's fog().
uniform sampler2D shade;
uniform vec3 sky_horizon;
in vec2 v_uv;
in vec3 v_specular;
in float v_fog;
out vec4 frag;
void main() {
    frag = vec4(mix(texture(shade, v_uv).rgb + v_specular, sky_horizon, v_fog), 1.0);
}
