#version 330
// Added (blending ONE, ONE) onto the sky where the depth is still at the far plane: the disc of sky.frag's sun.
uniform vec3 sun_dir;
uniform vec3 sun_color;
in vec3 v_dir;
out vec4 frag;
void main() {
    float s = max(dot(normalize(v_dir), sun_dir), 0.0);
    frag = vec4(sun_color * (s > 0.98 ? pow(s, 900.0) * 30.0 : 0.0), 0.0);  // below 0.98 it adds < 1e-6
}
