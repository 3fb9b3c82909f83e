// Cel colours are given as the colours the screen should show.  The engine's tone-mapping pass applies
// exposure, the ACES fit of Narkowicz (2015) y = (2.51x² + 0.03x) / (2.43x² + 0.59x + 0.14) and gamma 1/2.2;
// invert those so that a flat ramp colour reaches the screen unchanged.
uniform float exposure;
vec3 display_to_hdr(vec3 display) {
    vec3 y = clamp(pow(clamp(display, 0.0, 1.0), vec3(2.2)), 0.0, 0.99);
    vec3 a = 2.51 - 2.43 * y;
    vec3 b = 0.03 - 0.59 * y;
    vec3 c = -0.14 * y;
    vec3 x = (-b + sqrt(b * b - 4.0 * a * c)) / (2.0 * a);
    return x / max(exposure, 1e-4);
}
