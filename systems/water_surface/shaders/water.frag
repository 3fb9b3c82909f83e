#version 330
#include "lit.glsl"
#include "sky_gradient.glsl"
#include "terrain_shadow.glsl"
// Water: sky reflection weighted by Schlick's Fresnel term (F0 = 0.02, water's index 1.33) with a sun glint, over
// a body colour tinted from shallow to deep by the light's path through the water down to the pool floor
// (Beer-Lambert: 1 - exp(-path / clarity)) and lit by the height field's normal; crests scatter a little more
// light than troughs. Output is premultiplied: the scene behind shows through by (1 - F)·exp(-path / clarity).
// Variant TERRAIN_SHADOW: where the terrain's hills hide the sun (terrain_shadow.glsl) the glint and the sun's
// light on the body go; the sky's reflection stays.
uniform vec3 shallow_color;
uniform vec3 deep_color;
uniform float clarity;
uniform float floor_y;
uniform float rest_y;
in vec3 v_pos;
in vec3 v_normal;
out vec4 frag;
const float F0 = 0.02;
// Powers with constant exponents as products (pow is exp2·log2 per pixel on a software rasteriser).
void main() {
    vec3 n = normalize(v_normal);
    vec3 v = normalize(camera_pos - v_pos);
    if (dot(n, v) < 0.0) n = normalize(n - 2.0 * dot(n, v) * v);  // seen edge-on: keep the normal facing us
    float cos_v = clamp(dot(n, v), 0.0, 1.0);
    float m = 1.0 - cos_v, m2 = m * m;
    float fresnel = F0 + (1.0 - F0) * (m2 * m2 * m);  // Schlick: (1 - cos)^5
    vec3 r = reflect(-v, n);
    float glint = max(dot(r, sun_dir), 0.0);
    float g2 = glint * glint, g4 = g2 * g2, g8 = g4 * g4, g16 = g8 * g8, g32 = g16 * g16;
    float g40 = g32 * g8, g80 = g40 * g40, g160 = g80 * g80, g400 = g160 * g160 * g80;  // glint^40, glint^400
    vec3 sun = sun_color * terrain_sun(v_pos);
    vec3 reflected = sky_gradient(r, sky_top, sky_horizon) + sun * (g400 * 8.0 + g40 * 0.5);
    float depth = max(v_pos.y - floor_y, 0.0);
    float path = depth / max(v.y, 0.2) + depth;  // down to the floor and back up
    float absorbed = 1.0 - exp(-path / clarity);
    float crest = clamp((v_pos.y - rest_y) * 12.0, -1.0, 1.0);
    vec3 tint = mix(shallow_color, deep_color, clamp(absorbed - 0.3 * crest, 0.0, 1.0));
    float light = 0.5 * ambient + 0.9 * max(dot(n, sun_dir), 0.0) * max(sun.g, 0.0);
    vec3 body = tint * light * (1.0 + 0.35 * crest);
    vec3 color = (1.0 - fresnel) * absorbed * body + fresnel * reflected
               + (1.0 - fresnel) * sun * g40 * 0.15;
    float alpha = clamp(1.0 - (1.0 - fresnel) * (1.0 - absorbed), 0.0, 1.0);
    float f = 1.0 - exp(-length(camera_pos - v_pos) * fog_density);
    color = mix(color, sky_horizon * alpha, clamp(f, 0.0, 1.0));
    frag = vec4(color, alpha);
}
