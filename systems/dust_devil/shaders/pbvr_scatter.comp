#version 430
// PBVR ensemble, scatter form (2.3, seeds/004) as a compute shader (GL 4.3): the same pseudo-particles and the
// same coverage words as pbvr_scatter.vert, but a dispatch is spread over the driver's worker threads, where a
// software rasteriser runs the vertex stage on the calling thread alone.
// One invocation = one real particle: it projects the particle once, then draws its R x K pseudo-particles
// (sample r * K + k, offset d from the ball table: clip = view_proj (p, 1) + view_proj (d, 0)) and, for each, tests
// every pixel of its opaque square point of `point_size` pixels against the scene's depth and sets bit r of that
// pixel's coverage word.  A pixel counts each repeat at most once, however many of the repeat's pseudo-particles
// land on it: the R ensemble images, each opaque, kept as R bits per pixel.
#ifndef LOCAL_SIZE
#define LOCAL_SIZE 64
#endif
#ifndef POINT_SIDE
#define POINT_SIDE 1         // ceil(point_size): render.py compiles one variant per side
#endif
layout(local_size_x = LOCAL_SIZE) in;
uniform mat4 view_proj;
uniform int particles;       // N
uniform int sub_particles;   // K
uniform int repeats;         // R
uniform uint frame_key;      // changes every frame: a new ensemble (pbvr_sample.glsl)
uniform float radius;        // metres: pseudo-particles are uniform in a ball of this radius
uniform float point_size;    // pixels
uniform ivec2 view_size;     // pixels; repeats 32..63 use the rows view_size.y.. of the coverage image
uniform sampler2D scene_depth;
layout(r32ui, binding = 0) uniform coherent uimage2D coverage;
layout(std430, binding = 0) readonly buffer Particles { float particle_xyz[]; };  // world space, 3 floats each

#include "pbvr_sample.glsl"

void main() {
    int particle = int(gl_GlobalInvocationID.x);
    if (particle >= particles) return;
    vec4 centre = view_proj * vec4(particle_xyz[3 * particle], particle_xyz[3 * particle + 1],
                                   particle_xyz[3 * particle + 2], 1.0);
    uint key = particle_key(particle, frame_key);
    for (int r = 0; r < repeats; ++r) {
        uint bit = 1u << uint(r & 31);
        int row = (r >> 5) * view_size.y;
        for (int k = 0; k < sub_particles; ++k) {
            vec4 clip = centre + view_proj * vec4(radius * ball_offset(key, r * sub_particles + k), 0.0);
            float ndc_z = clip.z / clip.w;
            if (clip.w <= 0.0 || ndc_z < -1.0 || ndc_z > 1.0) continue;  // outside the near/far range: clipped
            float depth = 0.5 * ndc_z + 0.5;
            vec2 window = (clip.xy / clip.w * 0.5 + 0.5) * vec2(view_size);
            // pixels whose centres lie in the point's square [window - size/2, window + size/2): [first, last),
            // at most POINT_SIDE = ceil(point_size) per axis (a constant, so the loops unroll)
            ivec2 first = ivec2(floor(window - 0.5 * point_size + 0.5));
            ivec2 last = min(ivec2(floor(window + 0.5 * point_size + 0.5)), view_size);
            for (int dy = 0; dy < POINT_SIDE; ++dy) {
                for (int dx = 0; dx < POINT_SIDE; ++dx) {
                    ivec2 q = first + ivec2(dx, dy);
                    ivec2 word = ivec2(q.x, q.y + row);
                    // a plain load first: most pseudo-particles land on a pixel this repeat already covers, and
                    // an atomic costs far more (the bits only ever get set in this pass, so a set bit stays set)
                    if (all(lessThan(q, last)) && all(greaterThanEqual(q, ivec2(0)))
                            && (imageLoad(coverage, word).r & bit) == 0u
                            && depth <= texelFetch(scene_depth, q, 0).r) {  // opaque scene in front hides it
                        imageAtomicOr(coverage, word, bit);
                    }
                }
            }
        }
    }
}
