#version 420
// PBVR ensemble, scatter form (2.3, seeds/004); needs GL 4.2 image load/store in the vertex stage.
// One invocation = one pseudo-particle: real particle gl_VertexID, sample gl_InstanceID = r * K + k of the R x K
// this frame draws.  Nothing is rasterised (GL_RASTERIZER_DISCARD): the shader projects the pseudo-particle, tests
// every pixel its opaque square point of `point_size` pixels covers against the scene's depth, and sets bit r of
// that pixel's coverage word.  A pixel thus counts each repeat at most once, however many of the repeat's
// pseudo-particles land on it: the R ensemble images, each opaque, kept as R bits per pixel.
uniform mat4 view_proj;
uniform int sub_particles;   // K
uniform uint frame_key;      // changes every frame: a new ensemble (pbvr_sample.glsl)
uniform float radius;        // metres: pseudo-particles are uniform in a ball of this radius
uniform float point_size;    // pixels
uniform ivec2 view_size;     // pixels; repeats 32..63 use the rows view_size.y.. of the coverage image
uniform sampler2D scene_depth;
layout(r32ui, binding = 0) uniform coherent uimage2D coverage;
in vec3 in_position;         // the real particle, world space
#ifndef POINT_SIDE
#define POINT_SIDE 1         // ceil(point_size): render.py compiles one variant per side
#endif

#include "pbvr_sample.glsl"

void main() {
    gl_Position = vec4(0.0, 0.0, 0.0, 1.0);  // never rasterised
    int sample_id = gl_InstanceID;
    vec3 offset = radius * ball_offset(particle_key(gl_VertexID, frame_key), sample_id);
    vec4 clip = view_proj * vec4(in_position + offset, 1.0);
    float ndc_z = clip.z / clip.w;
    if (clip.w <= 0.0 || ndc_z < -1.0 || ndc_z > 1.0) return;  // outside the near/far range: clipped away
    float depth = 0.5 * ndc_z + 0.5;
    vec2 window = (clip.xy / clip.w * 0.5 + 0.5) * vec2(view_size);
    // pixels whose centres lie in the point's square [window - size/2, window + size/2): [first, last), at most
    // POINT_SIDE = ceil(point_size) per axis (a constant, so the loops unroll)
    ivec2 first = ivec2(floor(window - 0.5 * point_size + 0.5));
    ivec2 last = min(ivec2(floor(window + 0.5 * point_size + 0.5)), view_size);
    int repeat_index = sample_id / sub_particles;
    uint bit = 1u << uint(repeat_index & 31);
    int row = (repeat_index >> 5) * view_size.y;
    for (int dy = 0; dy < POINT_SIDE; ++dy) {
        for (int dx = 0; dx < POINT_SIDE; ++dx) {
            ivec2 q = first + ivec2(dx, dy);
            ivec2 word = ivec2(q.x, q.y + row);
            // a plain load first: most pseudo-particles land on a pixel this repeat already covers, and an atomic
            // costs far more (the bits only ever get set in this pass, so a set bit stays set)
            if (all(lessThan(q, last)) && all(greaterThanEqual(q, ivec2(0)))
                    && (imageLoad(coverage, word).r & bit) == 0u
                    && depth <= texelFetch(scene_depth, q, 0).r) {  // opaque scene in front hides it
                imageAtomicOr(coverage, word, bit);
            }
        }
    }
}
