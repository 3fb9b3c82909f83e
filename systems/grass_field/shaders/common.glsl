// GrassField helpers shared by its shaders (same conventions as systems/grass_field/layout.py and impostor.py).

// Texel i of a data texture laid out row by row, DATA_WIDTH = 4096 texels a row (render.py's TEXTURE_WIDTH): a
// mask and a shift split the index (a division by a texture's run-time width is one scalar division per lane).
const int DATA_WIDTH_LOG2 = 12;
ivec2 data_texel(int i) {
    return ivec2(i & ((1 << DATA_WIDTH_LOG2) - 1), i >> DATA_WIDTH_LOG2);
}
vec4 fetch(sampler2D tex, int i) {
    return texelFetch(tex, data_texel(i), 0);
}

// Rotation by azimuth a in the xz plane: (x, z) -> (x cos a - z sin a, x sin a + z cos a).
vec3 rotate_xz(vec3 v, float a) {
    float c = cos(a), s = sin(a);
    return vec3(v.x * c - v.z * s, v.y, v.x * s + v.z * c);
}

// The frame of a level-4 rectangle facing azimuth az from elevation el (impostor.impostor_basis).
void impostor_basis(float az, float el, out vec3 right, out vec3 up, out vec3 normal) {
    float ca = cos(az), sa = sin(az), ce = cos(el), se = sin(el);
    right = vec3(sa, 0.0, -ca);
    up = vec3(-se * ca, ce, -se * sa);
    normal = vec3(ce * ca, se, ce * sa);
}

// Debug view: one colour per level (0 red, 1 orange, 2 yellow, 3 green, 4 cyan, 5 blue), shaded by luminance.
vec3 level_color(int level) {
    if (level == 0) return vec3(1.0, 0.15, 0.1);
    if (level == 1) return vec3(1.0, 0.55, 0.05);
    if (level == 2) return vec3(0.95, 0.95, 0.1);
    if (level == 3) return vec3(0.2, 0.9, 0.2);
    if (level == 4) return vec3(0.1, 0.85, 0.95);
    return vec3(0.25, 0.3, 1.0);
}
vec3 debug_tint(vec3 c, int level) {
    float l = dot(c, vec3(0.3, 0.6, 0.1));
    return level_color(level) * (0.35 + 1.5 * l);
}
