#version 330
// Energy-wave sprites (seeds/000, section 3.4), expanded on the GPU from one record per particle.
// Records live in an RGBA32F texture, three texels each: (position, alpha), (hit point P0, -), (direction d, -).
// Quads (POINTS below, the default: render.py point_sprites): no instancing (llvmpipe pays a fixed cost per instance): vertex v of a draw is corner v % 4 of sprite k = v / 4
// (an index buffer makes the quad's two triangles, so each corner is shaded once), and sprite k is sub-sprite
// j = k % sprites of particle first + k / sprites:
//   mode 0: one sprite at the particle (beam particles, grains);
//   mode 1: continuous trail, eq. 3.7: T_j = P0 + (P1 - P0) j / M, size shrinking towards P1;
//   mode 2: bar, eq. 3.8: U_j = Q + (-1)^(j+1) u j d, and tip size eq. 3.9: S_j = (N - j (1 - t)) / N S
// (j counted from 0 here, j - 1 in the thesis).
uniform sampler2D records;
uniform int records_per_row;
uniform mat4 view_proj;
uniform vec3 camera_right;
uniform vec3 camera_up;
uniform int first;
uniform int sprites;
uniform int mode;
uniform float size;          // S, metres
uniform float spacing;       // u * S, metres
uniform float roundness;     // t
uniform float trail_end;     // size factor of the last trail sprite
#ifdef POINTS
// Variant POINTS: one vertex a sprite, drawn as a point sprite.  A camera-facing square of half-size s projects
// to a screen square of side s · point_scale / w pixels (point_scale = proj[1][1] · target height; the square is
// parallel to the image plane, so w is constant over it): the quad's pixels, from one vertex instead of four
// and one point setup instead of two triangles (particles.frag takes the corner from gl_PointCoord).
uniform float point_scale;
#else
out vec2 v_corner;         // position in the sprite, -1..1 on each axis
#endif
out float v_alpha;

vec4 fetch(int particle, int texel) {
    return texelFetch(records, ivec2((particle % records_per_row) * 3 + texel, particle / records_per_row), 0);
}

void main() {
#ifdef POINTS
    int sprite = gl_VertexID;
#else
    int c = gl_VertexID & 3;  // corners (0 1 2) (2 1 3) make the quad's triangles (the index buffer)
    vec2 in_corner = vec2((c & 1) == 1 ? 1.0 : -1.0, (c & 2) == 2 ? 1.0 : -1.0);
    int sprite = gl_VertexID >> 2;
#endif
    int particle = first + sprite / sprites;
    int j = sprite % sprites;
    vec4 a = fetch(particle, 0);
    vec3 pos = a.xyz;
    float s = size;
    if (mode == 1) {
        vec3 p0 = fetch(particle, 1).xyz;
        pos = p0 + (a.xyz - p0) * (float(j) / float(sprites));
        s *= sprites > 1 ? mix(1.0, trail_end, float(j) / float(sprites - 1)) : 1.0;
    } else if (mode == 2) {
        vec3 d = fetch(particle, 2).xyz;
        float side = (j % 2 == 1) ? 1.0 : -1.0;
        pos = a.xyz + side * spacing * float(j) * d;
        s *= (float(sprites) - float(j) * (1.0 - roundness)) / float(sprites);
    }
    v_alpha = a.w;
#ifdef POINTS
    gl_Position = view_proj * vec4(pos, 1.0);
    float side = s * point_scale / gl_Position.w;
    // a point is at least one pixel: a smaller sprite is drawn as one pixel carrying its share of it (its area
    // side², the chance that a quad that small covers the pixel centre; the gradient at the pixel centre's
    // offset averages to the quad's), so far sprites neither flicker in and out nor brighten
    gl_PointSize = max(side, 1.0);
    v_alpha *= min(side * side, 1.0);
#else
    v_corner = in_corner;
    vec3 world = pos + (camera_right * in_corner.x + camera_up * in_corner.y) * s;
    gl_Position = view_proj * vec4(world, 1.0);
#endif
}
