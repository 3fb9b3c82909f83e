#version 330
// Fast approximate anti-aliasing (FXAA, T. Lottes, NVIDIA 2009/2011; the "quality" variant with an edge search)
// over the composed, display-referred window image, before the HUD.  Per pixel:
//  1. local contrast of the luma of the pixel and its four neighbours; below the thresholds: unchanged;
//  2. sub-pixel aliasing: how far the pixel stands out from its 3 x 3 neighbourhood's low-pass;
//  3. the edge's orientation from second differences along rows and along columns, and the side of the pixel the
//     edge lies on (the steeper of the two gradients across it);
//  4. a search along the edge, half a texel off the pixel's centre so bilinear sampling averages both sides, in
//     both directions until the luma leaves the edge's average: the nearer end gives how far the pixel lies along
//     a staircase step, hence how much of the neighbour across the edge covers it;
//  5. one bilinear fetch shifted across the edge by the larger of the two blend amounts.
// The image is sRGB-encoded, so its luma is already perceptual, as FXAA wants.  Needs linear filtering and
// clamp-to-edge on `image`.
uniform sampler2D image;
uniform vec2 texel;  // 1 / the image's size in pixels
out vec4 frag;

const float CONTRAST_MIN = 0.0312;  // no anti-aliasing below this absolute luma range (dark regions)...
const float CONTRAST_REL = 0.125;   // ...nor below this fraction of the brightest luma of the five
const float SUBPIXEL = 0.75;        // strength of the sub-pixel blend (0: off, 1: softest)
const int STEPS = 10;               // edge search steps each way, growing: up to 23 pixels from the centre
const float STEP_SIZE[STEPS] = float[](1.0, 1.0, 1.0, 1.0, 1.5, 2.0, 2.0, 2.0, 4.0, 8.0);

float luma(vec3 c) { return dot(c, vec3(0.299, 0.587, 0.114)); }
float luma_at(vec2 uv) { return luma(textureLod(image, uv, 0.0).rgb); }
float luma_px(ivec2 p, ivec2 d) { return luma(texelFetch(image, clamp(p + d, ivec2(0), textureSize(image, 0) - 1), 0).rgb); }

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec3 center = texelFetch(image, p, 0).rgb;
    float m = luma(center);
    float n = luma_px(p, ivec2(0, 1)), s = luma_px(p, ivec2(0, -1));
    float e = luma_px(p, ivec2(1, 0)), w = luma_px(p, ivec2(-1, 0));
    float hi = max(max(max(n, s), max(e, w)), m);
    float lo = min(min(min(n, s), min(e, w)), m);
    float range = hi - lo;
    if (range < max(CONTRAST_MIN, hi * CONTRAST_REL)) {
        frag = vec4(center, 1.0);
        return;
    }
    float ne = luma_px(p, ivec2(1, 1)), nw = luma_px(p, ivec2(-1, 1));
    float se = luma_px(p, ivec2(1, -1)), sw = luma_px(p, ivec2(-1, -1));

    float low_pass = (2.0 * (n + s + e + w) + (ne + nw + se + sw)) / 12.0;
    float sub = clamp(abs(low_pass - m) / range, 0.0, 1.0);
    sub = (-2.0 * sub + 3.0) * sub * sub;  // smoothstep
    sub = sub * sub * SUBPIXEL;

    float along_rows = abs(nw + ne - 2.0 * n) + 2.0 * abs(w + e - 2.0 * m) + abs(sw + se - 2.0 * s);
    float along_columns = abs(nw + sw - 2.0 * w) + 2.0 * abs(n + s - 2.0 * m) + abs(ne + se - 2.0 * e);
    bool horizontal = along_rows >= along_columns;  // the edge runs along x: the blend goes across it, in y
    float a = horizontal ? s : w;                    // the neighbours on either side of the edge
    float b = horizontal ? n : e;
    float grad_a = abs(a - m), grad_b = abs(b - m);
    float across = horizontal ? texel.y : texel.x;   // signed step towards the edge's side
    float edge_luma;
    if (grad_a >= grad_b) {
        across = -across;
        edge_luma = 0.5 * (a + m);
    } else {
        edge_luma = 0.5 * (b + m);
    }
    float threshold = 0.25 * max(grad_a, grad_b);

    vec2 uv = (vec2(p) + 0.5) * texel;
    vec2 start = uv;
    vec2 along = horizontal ? vec2(texel.x, 0.0) : vec2(0.0, texel.y);
    if (horizontal) start.y += 0.5 * across; else start.x += 0.5 * across;
    vec2 uv_neg = start - along, uv_pos = start + along;
    float end_neg = luma_at(uv_neg) - edge_luma, end_pos = luma_at(uv_pos) - edge_luma;
    bool done_neg = abs(end_neg) >= threshold, done_pos = abs(end_pos) >= threshold;
    for (int i = 1; i < STEPS && !(done_neg && done_pos); ++i) {
        if (!done_neg) {
            uv_neg -= along * STEP_SIZE[i];
            end_neg = luma_at(uv_neg) - edge_luma;
            done_neg = abs(end_neg) >= threshold;
        }
        if (!done_pos) {
            uv_pos += along * STEP_SIZE[i];
            end_pos = luma_at(uv_pos) - edge_luma;
            done_pos = abs(end_pos) >= threshold;
        }
    }
    float d_neg = horizontal ? uv.x - uv_neg.x : uv.y - uv_neg.y;
    float d_pos = horizontal ? uv_pos.x - uv.x : uv_pos.y - uv.y;
    bool nearer_neg = d_neg < d_pos;
    float step_blend = 0.5 - min(d_neg, d_pos) / (d_neg + d_pos);
    // blend only where the centre's luma is on the other side of the edge's average than the nearer end's: at
    // the end of the step that covers this pixel, not at the far end of the one that starts here
    bool valid = ((nearer_neg ? end_neg : end_pos) < 0.0) != (m < edge_luma);
    float shift = max(valid ? step_blend : 0.0, sub);
    if (horizontal) uv.y += shift * across; else uv.x += shift * across;
    frag = vec4(textureLod(image, uv, 0.0).rgb, 1.0);
}
