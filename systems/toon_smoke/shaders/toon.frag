#version 330
// mode 0: smoke, colour from the 1D toon ramp (nearest filtering: hard cel bands) at the interpolated c.
// mode 1: the sphere obstacle, two cel bands of its colour lit by the sun.
// The ramp and the two band colours arrive as HDR values that the tone map turns into the configured colours
// (render.py inverts the display transform once per colour).
// Output 1 (the edge buffer) holds the object id and the linear view depth for the outline pass.
uniform sampler2D ramp;
uniform int mode;
uniform vec3 lit_color;
uniform vec3 shade_color;
uniform vec3 sun_dir;
uniform vec3 camera_pos;
uniform vec3 camera_forward;
uniform float object_id;
in vec3 v_world;
in vec3 v_normal;
in float v_ramp;
layout(location = 0) out vec4 frag;
layout(location = 1) out vec2 edge;
void main() {
    vec3 hdr;
    if (mode == 0) {
        hdr = texture(ramp, vec2(v_ramp, 0.5)).rgb;
    } else {
        vec3 n = normalize(v_normal);
        hdr = dot(n, normalize(sun_dir)) > 0.15 ? lit_color : shade_color;
    }
    frag = vec4(hdr, 1.0);
    edge = vec2(object_id, dot(v_world - camera_pos, camera_forward));
}
