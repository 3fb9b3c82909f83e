#version 330
// Outline / silhouette pass (the paper's named future work): a pixel of an object is an outline pixel when a pixel
// within `width` of it shows another object (or nothing), or a surface farther away by more than `threshold`
// of its depth (inner contour lines where one lump of smoke overlaps another).  Outlines lie inside the
// silhouette, so whatever hides the smoke hides its outline too.
uniform sampler2D edges;
// The outline parameters of volumes first .. first + 63 (the pass runs once per 64 volumes drawn).
uniform int first;
uniform float widths[64];
uniform float thresholds[64];
uniform vec3 colors[64];  // HDR: the tone map turns them into the configured outline colours
out vec4 frag;
void main() {
    ivec2 size = textureSize(edges, 0);
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec2 e = texelFetch(edges, p, 0).rg;
    int id = int(e.r + 0.5);
    if (id == 0) discard;
    int volume = (id - 1) / 2 - first;
    if (volume < 0 || volume >= 64) discard;
    float w = widths[volume];
    if (w <= 0.0) discard;
    int reach = int(ceil(w));
    float far_limit = e.g * (1.0 + thresholds[volume]);
    bool outline = false;
    for (int dy = -reach; dy <= reach && !outline; ++dy) {
        for (int dx = -reach; dx <= reach; ++dx) {
            if (float(dx * dx + dy * dy) > w * w) continue;
            vec2 n = texelFetch(edges, clamp(p + ivec2(dx, dy), ivec2(0), size - 1), 0).rg;
            if (int(n.r + 0.5) != id || n.g > far_limit) { outline = true; break; }
        }
    }
    if (!outline) discard;
    frag = vec4(colors[volume], 1.0);
}
