// The engine's sky colour along a view direction, without the sun: a gradient from the horizon colour to the
// top colour (up^0.625, by square roots: a pow is exp2·log2 per pixel on a software rasteriser), darkened below
// the horizon.  Shared by the sky pass (sky.frag) and what reflects the sky (the water surface).
vec3 sky_gradient(vec3 dir, vec3 top, vec3 horizon) {
    float up = clamp(dir.y, 0.0, 1.0);
    float q = sqrt(sqrt(up));
    vec3 col = mix(horizon, top, q * q * sqrt(q));
    return mix(col, horizon * 0.55, clamp(-dir.y * 3.0, 0.0, 1.0));
}
