#version 330
// One direction of a separable 9-tap Gaussian blur (sigma = radius / 2) of the glow buffer.
uniform sampler2D source;
uniform vec2 step_uv;   // one texel along the blur direction, times the radius / 4
in vec2 v_uv;
out vec4 frag;
void main() {
    const float w[5] = float[](0.2270270270, 0.1945945946, 0.1216216216, 0.0540540541, 0.0162162162);
    vec3 c = texture(source, v_uv).rgb * w[0];
    for (int i = 1; i < 5; ++i) {
        c += texture(source, v_uv + step_uv * float(i)).rgb * w[i];
        c += texture(source, v_uv - step_uv * float(i)).rgb * w[i];
    }
    frag = vec4(c, 0.0);
}
