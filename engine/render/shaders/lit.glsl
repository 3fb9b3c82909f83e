// Shared lighting: sun (Lambert + Blinn-Phong), hemisphere ambient and distance fog.
uniform vec3 sun_dir;
uniform vec3 sun_color;
uniform float ambient;
uniform vec3 sky_top;
uniform vec3 sky_horizon;
uniform vec3 camera_pos;
uniform float fog_density;
// max(n·h, 0)^shininess.  pow is exp2(log2(x)·y) per pixel on a software rasteriser; the exponents the engine
// uses are constants at their call sites, so after inlining only their chain of squarings remains.
float lobe(float x, float shininess) {
    float x2 = x * x, x4 = x2 * x2, x8 = x4 * x4, x16 = x8 * x8;
    if (shininess == 16.0) return x16;
    if (shininess == 32.0) return x16 * x16;
    if (shininess == 48.0) return x16 * x16 * x16;
    if (shininess == 64.0) return (x16 * x16) * (x16 * x16);
    return pow(x, shininess);
}
// sun_lit: how much of the sun reaches the point (shadow.glsl's sun_visibility; 1 without shadows).
vec3 shade_in_sun(vec3 albedo, vec3 n, vec3 pos, float shininess, float spec_strength, float sun_lit) {
    float ndl = max(dot(n, sun_dir), 0.0) * sun_lit;
    vec3 hemi = mix(sky_horizon * 0.35, sky_top, n.y * 0.5 + 0.5) * ambient;
    vec3 v = normalize(camera_pos - pos);
    vec3 h = normalize(v + sun_dir);
    float spec = lobe(max(dot(n, h), 0.0), shininess) * spec_strength;
    return albedo * (sun_color * ndl + hemi) + sun_color * spec * ndl;
}
vec3 shade(vec3 albedo, vec3 n, vec3 pos, float shininess, float spec_strength) {
    return shade_in_sun(albedo, n, pos, shininess, spec_strength, 1.0);
}
vec3 fog(vec3 color, vec3 pos) {
    float f = 1.0 - exp(-length(camera_pos - pos) * fog_density);
    return mix(color, sky_horizon, clamp(f, 0.0, 1.0));
}
