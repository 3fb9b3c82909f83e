// Shared lighting: sun (Lambert + Blinn-Phong), hemisphere ambient and distance fog.
uniform vec3 sun_dir;
uniform vec3 sun_color;
uniform float ambient;
uniform vec3 sky_top;
uniform vec3 sky_horizon;
uniform vec3 camera_pos;
uniform float fog_density;
vec3 shade(vec3 albedo, vec3 n, vec3 pos, float shininess, float spec_strength) {
    float ndl = max(dot(n, sun_dir), 0.0);
    vec3 hemi = mix(sky_horizon * 0.35, sky_top, n.y * 0.5 + 0.5) * ambient;
    vec3 v = normalize(camera_pos - pos);
    vec3 h = normalize(v + sun_dir);
    float spec = pow(max(dot(n, h), 0.0), shininess) * spec_strength;
    return albedo * (sun_color * ndl + hemi) + sun_color * spec * ndl;
}
vec3 fog(vec3 color, vec3 pos) {
    float f = 1.0 - exp(-length(camera_pos - pos) * fog_density);
    return mix(color, sky_horizon, clamp(f, 0.0, 1.0));
}
