// The engine's display transform and its inverse, shared by the tone-mapping pass and by effects that
// want a colour to reach the screen unchanged (UI-like colours in the 3D scene).  Colours constant over a draw
// are better inverted on the CPU (engine.render.passes.display_to_hdr, its twin), as the toon smoke does.
// Forward: exposure, the ACES fit of Narkowicz (2015) y = (2.51x² + 0.03x) / (2.43x² + 0.59x + 0.14),
// then gamma 1/2.2.  The inverse solves the quadratic for x.
// The forward gamma runs on every pixel of every frame: y^(1/2.2) is fitted (least squares on [0, 1], exact at
// 0 and 1, monotonic) by a y^(1/2) + b y^(3/8) + c y^(1/4) + d y, three square roots instead of a pow per channel
// (exp2 and log2, about 25 instructions on a software rasteriser); the error stays below 0.15 of an 8-bit step.
uniform float exposure;
vec3 hdr_to_display(vec3 hdr) {
    vec3 x = hdr * exposure;
    vec3 y = clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
    vec3 s = sqrt(y), q = sqrt(s);
    return 0.61941797 * s + 0.44379556 * q * sqrt(q) - 0.05531962 * q - 0.00789391 * y;
}
vec3 display_to_hdr(vec3 display) {
    vec3 y = clamp(pow(clamp(display, 0.0, 1.0), vec3(2.2)), 0.0, 0.99);
    vec3 a = 2.51 - 2.43 * y;
    vec3 b = 0.03 - 0.59 * y;
    vec3 c = -0.14 * y;
    vec3 x = (-b + sqrt(b * b - 4.0 * a * c)) / (2.0 * a);
    return x / max(exposure, 1e-4);
}
